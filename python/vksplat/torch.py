"""``vksplat.torch.rasterization``: gsplat's ``rasterization`` on any Vulkan device.

    from vksplat.torch import rasterization   # instead of: from gsplat import rasterization
    colors, alphas, meta = rasterization(means, quats, scales, opacities, colors,
                                         viewmats, Ks, width, height, sh_degree=3)

Differentiable with torch autograd with respect to ``means``, ``quats``, ``scales``,
``opacities`` and ``colors`` (SH coefficients, direct RGB, or 1 to 16 direct feature
channels, blended without a background); ``meta["means2d"]``
receives dL/d(2D means) when it retains its gradient, and ``meta["means2d"].absgrad``
the sum of their absolute values with ``absgrad=True`` (what densification reads).
CPU float32 tensors in and out. Gradients are bit-identical run after run
(deterministic accumulation; ``accumulation="float-atomics"`` trades that for speed).

Where the rules differ from gsplat's defaults, vksplat keeps the original 3DGS
rasterizer's (the rules scenes trained with the INRIA code need): near plane 0.2 (gsplat
0.01), alpha clamp 0.99 (gsplat 0.999), a screen-space radius of 3 sigma of the larger
axis (gsplat 3.33 per axis), no far plane. ``near_plane`` therefore defaults to 0.2 and
other values are refused, as are options vksplat does not implement (``rasterize_mode=
"antialiased"``, ``radius_clip``, other camera models, ``covars``); those needing them keep
gsplat. Direct RGB colours are blended through the SH path: negative values clamp at 0.
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import torch

from . import raster as _raster

__all__ = ["rasterization"]

_RASTERIZERS: Dict[Tuple[Any, str], "_raster.Rasterizer"] = {}


def _rasterizer(device: Any, accumulation: str) -> "_raster.Rasterizer":
    key = (device, accumulation)
    if key not in _RASTERIZERS:
        _RASTERIZERS[key] = _raster.Rasterizer(device=device, accumulation=accumulation)
    return _RASTERIZERS[key]


def _check_tensor(name: str, t: Any, shape: Tuple[Optional[int], ...]) -> torch.Tensor:
    if not isinstance(t, torch.Tensor):
        raise ValueError(f"{name} must be a torch.Tensor, got {type(t).__name__}")
    if t.device.type != "cpu":
        raise ValueError(
            f"{name} is on {t.device}; vksplat.torch takes CPU tensors (the Vulkan device is "
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


class _Project(torch.autograd.Function):
    """Runs the forward passes; returns the 2D means (an input of _Rasterize, so that
    ``meta["means2d"].grad`` is dL/d(2D means) as in gsplat). Its own backward passes
    nothing on: _Rasterize's gradients already include the path through the 2D means."""

    @staticmethod
    def forward(ctx, means, quats, scales, opacities, colors, state):  # type: ignore[override]
        r, cams, sh_degree, bgs, kernel = state["args"]
        fwds = []
        for c, (viewmat, K) in enumerate(cams):
            fwds.append(
                r.forward(
                    _np(means),
                    _np(quats),
                    _np(scales),
                    _np(opacities),
                    _np(colors),
                    viewmat,
                    K,
                    state["width"],
                    state["height"],
                    sh_degree=sh_degree,
                    background=None if bgs is None else bgs[c],
                    kernel=kernel,
                )
            )
        state["fwds"] = fwds
        return torch.from_numpy(np.stack([f.means2d for f in fwds]).astype(np.float32))

    @staticmethod
    def backward(ctx, grad_means2d):  # type: ignore[override]
        return None, None, None, None, None, None


class _Rasterize(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, means, quats, scales, opacities, colors, state):  # type: ignore[override]
        fwds = state["fwds"]
        ctx.state = state
        ctx.means2d = means2d
        ctx.color_shape = tuple(colors.shape)
        colors_out = torch.from_numpy(np.stack([np.array(f.colors) for f in fwds]))
        alphas = torch.from_numpy(np.stack([np.array(f.alphas) for f in fwds]))[..., None]
        depths = torch.from_numpy(np.stack([np.array(f.depths) for f in fwds]))[..., None]
        return colors_out, alphas, depths

    @staticmethod
    def backward(ctx, g_colors, g_alphas, g_depths):  # type: ignore[override]
        state = ctx.state
        r = state["args"][0]
        fwds = state["fwds"]
        totals: Dict[str, np.ndarray] = {}
        means2d_grads: List[Optional[np.ndarray]] = [None] * len(fwds)
        abs_grads: List[Optional[np.ndarray]] = [None] * len(fwds)
        # The last camera's state is still on the device: its backward goes first.
        for c in reversed(range(len(fwds))):
            g = r.backward(
                fwds[c],
                grad_colors=None if g_colors is None else _np(g_colors[c]),
                grad_alphas=None if g_alphas is None else _np(g_alphas[c, ..., 0]),
                grad_depths=None if g_depths is None else _np(g_depths[c, ..., 0]),
            )
            for name in ("means", "quats", "scales", "opacities", "colors"):
                totals[name] = g[name] if name not in totals else totals[name] + g[name]
            means2d_grads[c] = g["means2d"]
            abs_grads[c] = g["absgrad"]
        if state["absgrad"]:
            ctx.means2d.absgrad = torch.from_numpy(np.stack(abs_grads).astype(np.float32))
        colors = totals["colors"]
        if colors.ndim == 3 and colors.shape[1] < ctx.color_shape[1]:
            # SH coefficients past the degree rendered receive zero.
            pad = np.zeros((colors.shape[0], ctx.color_shape[1] - colors.shape[1], 3), colors.dtype)
            colors = np.concatenate([colors, pad], axis=1)
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))  # noqa: E731
        return (
            t(np.stack(means2d_grads)),
            t(totals["means"]),
            t(totals["quats"]),
            t(totals["scales"]),
            t(totals["opacities"]),
            t(colors).reshape(ctx.color_shape),
            None,
        )


def rasterization(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    opacities: torch.Tensor,
    colors: torch.Tensor,
    viewmats: torch.Tensor,
    Ks: torch.Tensor,
    width: int,
    height: int,
    near_plane: float = 0.2,
    far_plane: float = 1e10,
    radius_clip: float = 0.0,
    eps2d: float = 0.3,
    sh_degree: Optional[int] = None,
    packed: bool = True,
    tile_size: int = 16,
    backgrounds: Optional[torch.Tensor] = None,
    render_mode: str = "RGB",
    sparse_grad: bool = False,
    absgrad: bool = False,
    rasterize_mode: str = "classic",
    channel_chunk: int = 32,
    distributed: bool = False,
    camera_model: str = "pinhole",
    segmented: bool = False,
    covars: Optional[torch.Tensor] = None,
    device: Any = None,
    accumulation: str = "deterministic",
    kernel: str = "gaussian",
    **unsupported: Any,
) -> Tuple[torch.Tensor, torch.Tensor, Dict[str, Any]]:
    """gsplat's ``rasterization`` (see the module's docstring for where the rules differ).

    ``means`` [N, 3], ``quats`` [N, 4] (w, x, y, z; normalised inside), ``scales`` [N, 3]
    (linear), ``opacities`` [N] (in [0, 1]), ``colors`` [N, K, 3] SH coefficients with
    ``sh_degree`` or [N, D] direct channels without (RGB, or 1 to 16 feature channels), ``viewmats`` [C, 4, 4] world-to-camera (OpenCV
    axes), ``Ks`` [C, 3, 3]. ``render_mode``: ``"RGB"``, ``"D"`` (accumulated depth),
    ``"ED"`` (expected depth), ``"RGB+D"``, ``"RGB+ED"``. ``backgrounds`` [C, 3] (or
    [C, 4] with a depth channel). vksplat's own: ``device`` (Vulkan device index or name),
    ``accumulation`` and ``kernel`` (``"power"``: the power-function falloff).

    Returns ``(render_colors [C, H, W, D], render_alphas [C, H, W, 1], meta)`` with meta
    ``radii`` [C, N, 2] (int32, 0 where culled), ``means2d`` [C, N, 2], ``depths`` [C, N],
    ``conics`` [C, N, 3], ``opacities`` [C, N], ``width``, ``height``, ``tile_size``,
    ``n_cameras``, ``camera_ids`` and ``gaussian_ids`` (None: not packed).
    """
    if unsupported:
        raise ValueError(f"vksplat.torch.rasterization does not support {sorted(unsupported)}")
    refusals = [
        (near_plane != 0.2, f"near_plane={near_plane}: vksplat culls at the original rasterizer's 0.2"),
        (far_plane < 1e10, f"far_plane={far_plane}: vksplat has no far plane"),
        (radius_clip != 0.0, "radius_clip is not supported"),
        (eps2d != 0.3, f"eps2d={eps2d}: vksplat dilates 2D covariances by the original 0.3"),
        (rasterize_mode != "classic", f"rasterize_mode={rasterize_mode!r}: only 'classic' has a backward pass"),
        (camera_model != "pinhole", f"camera_model={camera_model!r}: only 'pinhole' is supported"),
        (covars is not None, "covars are not supported: pass quats and scales"),
        (distributed, "distributed rendering is not supported"),
        (sparse_grad, "sparse_grad is not supported"),
        (segmented, "segmented is not supported"),
    ]
    for bad, why in refusals:
        if bad:
            raise ValueError(why)
    modes = {"RGB", "D", "ED", "RGB+D", "RGB+ED"}
    if render_mode not in modes:
        raise ValueError(f"render_mode must be one of {sorted(modes)}, got {render_mode!r}")
    if not (isinstance(width, int) and isinstance(height, int) and width > 0 and height > 0):
        raise ValueError(f"width and height must be positive integers, got {width!r}, {height!r}")
    _check_tensor("means", means, (None, 3))
    n = means.shape[0]
    _check_tensor("quats", quats, (n, 4))
    _check_tensor("scales", scales, (n, 3))
    _check_tensor("opacities", opacities, (n,))
    if sh_degree is None:
        _check_tensor("colors", colors, (n, None))
    else:
        _check_tensor("colors", colors, (n, None, 3))
    _check_tensor("viewmats", viewmats, (None, 4, 4))
    n_cams = viewmats.shape[0]
    _check_tensor("Ks", Ks, (n_cams, 3, 3))
    bgs = None
    depth_bg = None
    if backgrounds is not None:
        _check_tensor("backgrounds", backgrounds, (n_cams, None))
        d = backgrounds.shape[1]
        channels = 3 if sh_degree is not None else colors.shape[1]
        if channels != 3:
            raise ValueError(
                f"backgrounds: colors of {channels} channels are blended without a background"
            )
        want = 4 if render_mode in ("RGB+D", "RGB+ED") else 3
        if d not in (3, want) or (render_mode in ("D", "ED")):
            raise ValueError(
                f"backgrounds must have shape ({n_cams}, {want}) for render_mode {render_mode!r}, "
                f"got {tuple(backgrounds.shape)}"
            )
        bgs = [_np(backgrounds[c, :3]).astype(np.float64) for c in range(n_cams)]
        if d == 4:
            depth_bg = backgrounds[:, 3]
    cams = [(_np(viewmats[c]), _np(Ks[c])) for c in range(n_cams)]
    r = _rasterizer(device, accumulation)
    state: Dict[str, Any] = {
        "args": (r, cams, sh_degree, bgs, kernel),
        "width": width,
        "height": height,
        "absgrad": absgrad,
    }
    means2d = _Project.apply(means, quats, scales, opacities, colors, state)
    rgb, alphas, expected = _Rasterize.apply(means2d, means, quats, scales, opacities, colors, state)
    fwds = state["fwds"]
    if render_mode in ("D", "RGB+D"):
        depth = expected * alphas
    else:
        depth = expected
    if depth_bg is not None:
        depth = depth + (1.0 - alphas) * depth_bg[:, None, None, None]
    if render_mode == "RGB":
        out = rgb
    elif render_mode in ("D", "ED"):
        out = depth
    else:
        out = torch.cat([rgb, depth], dim=-1)
    radii = torch.from_numpy(np.stack([f.radii for f in fwds]))
    meta: Dict[str, Any] = {
        "radii": torch.stack([radii, radii], dim=-1),
        "means2d": means2d,
        "depths": torch.from_numpy(np.stack([f.gaussian_depths for f in fwds])),
        "conics": torch.from_numpy(np.stack([f.conics for f in fwds])),
        "opacities": opacities.detach().expand(n_cams, n).clone(),
        "width": width,
        "height": height,
        "tile_size": tile_size,
        "n_cameras": n_cams,
        "camera_ids": None,
        "gaussian_ids": None,
    }
    return out, alphas, meta
