"""``verisplat.gsplat.rasterization``: ``verisplat.torch.rasterization`` with gsplat's rules.

    from verisplat.gsplat import rasterization   # instead of: from gsplat import rasterization

Everything as ``verisplat.torch.rasterization`` (its docstring lists what is supported), with
``rules="gsplat"`` unless given: near plane 0.01 (``near_plane`` when given), alpha clamp
0.999, a pixel ending at T <= 1e-4, the per-axis opacity-aware 3.33-sigma screen box, the
guard band around the principal point and the antialiased compensation's floor 0, so a
model trained with gsplat trains and renders here the way it does there.
"""

from __future__ import annotations

from typing import Any

from . import torch as _torch

__all__ = ["rasterization"]


def rasterization(*args: Any, rules: str = "gsplat", **kwargs: Any) -> Any:
    """``verisplat.torch.rasterization`` with gsplat's rules (``rules="gsplat"``)."""
    return _torch.rasterization(*args, rules=rules, **kwargs)
