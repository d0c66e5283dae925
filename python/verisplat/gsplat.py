"""``verisplat.gsplat.rasterization``: ``verisplat.torch.rasterization`` with gsplat's rules.

    from verisplat.gsplat import rasterization   # instead of: from gsplat import rasterization

Everything as ``verisplat.torch.rasterization`` (its docstring lists what is supported), with
``rules="gsplat"`` unless given: near plane 0.01 (``near_plane`` when given), alpha clamp
0.999, a pixel ending at T <= 1e-4, the per-axis opacity-aware 3.33-sigma screen box, the
guard band around the principal point and the antialiased compensation's floor 0, so a
model trained with gsplat trains and renders here the way it does there.

    from verisplat.gsplat import MCMCStrategy, DefaultStrategy   # instead of: from gsplat...

gsplat's strategies (gsplat installed, its CUDA build not needed): ``MCMCStrategy`` is a
subclass of gsplat's whose methods run with the two CUDA kernels ``gsplat.strategy.ops``
calls (``compute_relocation``, ``quat_scale_to_covar_preci``) replaced by the torch ones of
``verisplat._gsplat_kernels`` (the same formulas), always, whatever the machine: they run
on CUDA tensors too, so one training script behaves the same with and without CUDA. The
replacement lasts only while one of its methods runs (``torch_kernels()``, below, for
calling gsplat's ``ops`` directly). ``DefaultStrategy`` is gsplat's own class: it calls no
CUDA kernel.

    from verisplat.gsplat import fused_ssim   # instead of: from fused_ssim import fused_ssim

the SSIM of the ``fused_ssim`` package (simple_trainer.py's SSIM loss) in torch.
"""

from __future__ import annotations

import contextlib
import functools
import threading
from typing import Any, Iterator

from . import torch as _torch
from ._gsplat_kernels import fused_ssim

__all__ = ["rasterization", "MCMCStrategy", "DefaultStrategy", "torch_kernels", "fused_ssim"]


def rasterization(*args: Any, rules: str = "gsplat", **kwargs: Any) -> Any:
    """``verisplat.torch.rasterization`` with gsplat's rules (``rules="gsplat"``)."""
    return _torch.rasterization(*args, rules=rules, **kwargs)


_SWAP_LOCK = threading.RLock()


def _gsplat_ops() -> Any:
    try:
        import gsplat.strategy.ops as ops
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "verisplat.gsplat's strategies are gsplat's: install gsplat (pip install gsplat; "
            f"its CUDA build is not needed): {e}"
        ) from e
    return ops


@contextlib.contextmanager
def torch_kernels() -> Iterator[None]:
    """While inside, ``gsplat.strategy.ops`` calls verisplat's torch ``compute_relocation``
    and ``quat_scale_to_covar_preci`` instead of gsplat's CUDA ones; on leaving, whatever
    was there before is put back. Nested uses are no-ops; a lock keeps two threads from
    interleaving the swap."""
    from . import _gsplat_kernels as kernels

    ops = _gsplat_ops()
    ours = {
        "compute_relocation": kernels.compute_relocation,
        "quat_scale_to_covar_preci": kernels.quat_scale_to_covar_preci,
    }
    with _SWAP_LOCK:
        before = {name: getattr(ops, name) for name in ours}
        try:
            for name, fn in ours.items():
                setattr(ops, name, fn)
            yield
        finally:
            for name, fn in before.items():
                setattr(ops, name, fn)


def _with_torch_kernels(method: Any) -> Any:
    @functools.wraps(method)
    def wrapped(self: Any, *args: Any, **kwargs: Any) -> Any:
        with torch_kernels():
            return method(self, *args, **kwargs)

    return wrapped


@functools.lru_cache(maxsize=None)
def _strategies() -> dict:
    _gsplat_ops()
    from gsplat.strategy import DefaultStrategy as GsDefault
    from gsplat.strategy import MCMCStrategy as GsMCMC

    class MCMCStrategy(GsMCMC):
        """gsplat's ``MCMCStrategy`` (same fields, same steps) with its relocation, its
        added Gaussians and its position noise computed by verisplat's torch kernels, so it
        runs without gsplat's CUDA build. ``isinstance(s, gsplat.strategy.MCMCStrategy)``
        holds."""

        step_post_backward = _with_torch_kernels(GsMCMC.step_post_backward)
        _relocate_gs = _with_torch_kernels(GsMCMC._relocate_gs)
        _add_new_gs = _with_torch_kernels(GsMCMC._add_new_gs)

    MCMCStrategy.__module__ = __name__
    return {"MCMCStrategy": MCMCStrategy, "DefaultStrategy": GsDefault}


def __getattr__(name: str) -> Any:
    # gsplat is imported on first use only: rasterization needs no gsplat.
    if name in ("MCMCStrategy", "DefaultStrategy"):
        return _strategies()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
