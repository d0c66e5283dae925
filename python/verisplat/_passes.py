"""What one ``verisplat.torch.rasterization`` call is carried by, shared by its two paths
(``torch.py``'s projection on the device and ``_carried.py``'s linearised fisheye, projected
in torch): the arguments' layout, the call, the ``_Passes`` handle of its native forward
passes, and what both do with them (the images stacked pair by pair, a pair's backward
pass, the meta layout, the meta dict). Both modules import it; neither imports the other
for it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Tuple

import numpy as np
import torch

from . import _native

if TYPE_CHECKING:
    from . import raster as _raster

# Direct channels per native pass (the most the device's backward pass takes): more are
# blended in chunks of this many.
_CHUNK = _native.BACKWARD_CHANNELS
# verisplat's tiles (meta["tile_size"]; gsplat's tile_size is a speed setting).
_TILE = _native.TILE_SIZE


def _check_tensor(name: str, t: Any, shape: Tuple[Optional[int], ...]) -> torch.Tensor:
    if not isinstance(t, torch.Tensor):
        raise ValueError(f"{name} must be a torch.Tensor, got {type(t).__name__}")
    if t.device.type != "cpu":
        raise ValueError(
            f"{name} is on {t.device}; verisplat.torch takes CPU tensors (the Vulkan device is "
            "its own): pass {name}.cpu()".replace("{name}", name)
        )
    if t.dtype != torch.float32:
        raise ValueError(f"{name} must be float32, got {t.dtype}")
    if t.dim() != len(shape) or any(s is not None and s != d for s, d in zip(shape, t.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {tuple(t.shape)}")
    if not torch.isfinite(t).all():
        raise ValueError(f"{name} holds NaN or infinite values")
    return t


def _np(t: torch.Tensor) -> np.ndarray:
    return t.detach().cpu().numpy()


class _Layout:
    """How the arguments' shapes map onto native passes: B Gaussian sets (the leading batch
    dimensions ``batch`` flattened), C cameras each, N Gaussians; colours shared by the
    cameras or per camera; SH of ``sh_degree`` or D direct channels, in chunks."""

    def __init__(self, means, colors, viewmats, sh_degree, packed):
        if not isinstance(means, torch.Tensor) or means.dim() < 2:
            _check_tensor("means", means, (None, 3))
        self.batch = tuple(means.shape[:-2])
        self.B = int(np.prod(self.batch)) if self.batch else 1
        self.N = means.shape[-2]
        if not isinstance(viewmats, torch.Tensor) or viewmats.dim() != len(self.batch) + 3:
            _check_tensor("viewmats", viewmats, self.batch + (None, 4, 4))
        self.C = viewmats.shape[-3]
        self.sh_degree = sh_degree
        tail = 2 if sh_degree is not None else 1  # (K, 3) or (D,)
        if not isinstance(colors, torch.Tensor):
            _check_tensor("colors", colors, ())
        self.per_camera = colors.dim() == len(self.batch) + 2 + tail
        self.D = 3 if sh_degree is not None else (colors.shape[-1] if colors.dim() else 0)
        self.chunks = (
            [slice(0, 3)]
            if sh_degree is not None
            else [slice(i, min(i + _CHUNK, self.D)) for i in range(0, self.D, _CHUNK)]
        )
        self.packed = packed

    def pairs(self) -> List[Tuple[int, int]]:
        return [(b, c) for b in range(self.B) for c in range(self.C)]

    def colour_shape(self) -> Tuple[Optional[int], ...]:
        lead = self.batch + ((self.C,) if self.per_camera else ()) + (self.N,)
        return lead + ((None, 3) if self.sh_degree is not None else (None,))


@dataclass(frozen=True)
class _Call:
    """What one ``rasterization`` call asks for, beyond the tensors: the rasterizer, the
    shapes, the cameras (per set, per camera: viewmat and K as numpy) and the options."""

    rasterizer: "_raster.Rasterizer"
    layout: _Layout
    cams: List[List[Tuple[np.ndarray, np.ndarray]]]
    lenses: List[List[Optional[Dict[str, Any]]]]
    width: int
    height: int
    kernel: str
    rules: str
    near_plane: float
    reproducible: bool
    antialiased: bool
    absgrad: bool


@dataclass(frozen=True)
class _Passes:
    """The handle the two autograd Functions share, made by ``_Project``'s forward (one of
    its outputs, an input of ``_Rasterize``) and kept on each one's ``ctx``: the call, its
    native forward passes (per (set, camera) pair, one per colour chunk), the radii
    ([B, C, N] and per axis [B, C, N, 2]) and, packed, the visible (set, camera, Gaussian)
    triples. Nothing in it changes after the forward pass."""

    call: _Call
    fwds: Dict[Tuple[int, int], list]
    radii: np.ndarray
    radii_xy: np.ndarray
    ids: Optional[Tuple[np.ndarray, ...]]


def _stack(layout: _Layout, fwds, get) -> np.ndarray:
    """`get(forwards)` of each pair (its list of one forward pass per colour chunk), as
    [B, C, ...]."""
    rows = [np.stack([get(fwds[(b, c)]) for c in range(layout.C)]) for b in range(layout.B)]
    return np.stack(rows)


def _to_layout(passes: _Passes, full: np.ndarray) -> np.ndarray:
    """[B, C, N, ...] as meta holds it: packed rows of the visible pairs, or [..., C, N, ...]."""
    layout = passes.call.layout
    full = np.ascontiguousarray(full, dtype=np.float32)
    if layout.packed:
        return np.ascontiguousarray(full[passes.ids])
    return full.reshape(layout.batch + (layout.C, layout.N) + full.shape[3:])


def _from_layout(passes: _Passes, g: Optional[torch.Tensor]) -> Optional[np.ndarray]:
    """A meta tensor's gradient as [B, C, N, ...] (None: none)."""
    if g is None:
        return None
    layout = passes.call.layout
    g = _np(g).astype(np.float32)
    tail = g.shape[1:] if layout.packed else g.shape[len(layout.batch) + 2 :]
    full = np.zeros((layout.B, layout.C, layout.N) + tuple(tail), np.float32)
    if layout.packed:
        full[passes.ids] = g
    else:
        full[...] = g.reshape(full.shape)
    return full if full.any() else None


def _pair_backward(r, fwds, g_colors, g_alphas, g_depths, layout: _Layout, screen: bool):
    """One pair's gradients from its pixel gradients, summed over its colour chunks (the
    alpha and depth gradients go with the first chunk); colours joined along channels.
    With `screen` also the projected quantities' (``raster.Rasterizer.backward``)."""
    total: Dict[str, np.ndarray] = {}
    colour_parts: List[np.ndarray] = [None] * len(fwds)  # type: ignore[list-item]
    names = ("means", "quats", "scales", "opacities", "means2d", "absgrad")
    names += ("screen",) if screen else ()
    # The last chunk's state is still on the device: its backward goes first.
    for j in reversed(range(len(fwds))):
        ch = layout.chunks[j]
        g = r.backward(
            fwds[j],
            grad_colors=None if g_colors is None else np.ascontiguousarray(g_colors[..., ch]),
            grad_alphas=g_alphas if j == 0 else None,
            grad_depths=g_depths if j == 0 else None,
            screen=screen,
        )
        for name in names:
            total[name] = g[name] if name not in total else total[name] + g[name]
        colour_parts[j] = g["colors"]
    total["colors"] = colour_parts[0] if len(fwds) == 1 else np.concatenate(colour_parts, axis=1)
    return total


def _meta(passes: _Passes, projected) -> Dict[str, Any]:
    means2d, depths, conics, opacities = projected
    call = passes.call
    layout, width, height = call.layout, call.width, call.height
    radii = passes.radii_xy.astype(np.int32)
    bs, C, N = layout.batch, layout.C, layout.N
    meta: Dict[str, Any] = {
        "means2d": means2d,
        "depths": depths,
        "conics": conics,
        "opacities": opacities,
        "width": width,
        "height": height,
        "tile_size": _TILE,
        "n_batches": layout.B,
        "n_cameras": C,
    }
    if layout.packed:
        ids = [torch.from_numpy(i.astype(np.int64)) for i in passes.ids]
        r = torch.from_numpy(radii[passes.ids])
        meta.update(batch_ids=ids[0], camera_ids=ids[1], gaussian_ids=ids[2])
    else:
        r = torch.from_numpy(radii.reshape(bs + (C, N, 2)))
        meta.update(batch_ids=None, camera_ids=None, gaussian_ids=None)
    meta["radii"] = r
    return meta
