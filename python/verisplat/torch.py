"""``verisplat.torch.rasterization``: gsplat's ``rasterization`` on any Vulkan device.

    from verisplat.torch import rasterization   # instead of: from gsplat import rasterization
    colors, alphas, meta = rasterization(means, quats, scales, opacities, colors,
                                         viewmats, Ks, width, height, sh_degree=3)

Differentiable with torch autograd with respect to ``means``, ``quats``, ``scales`` (of
either sign: the covariance is built from their squares, as gsplat's), ``opacities``,
``colors`` (SH coefficients, or any number of direct channels, shared by the cameras or
per camera), ``backgrounds``, ``viewmats`` and ``Ks`` (a camera pose is learned
through it); ``meta["means2d"]``, ``meta["depths"]`` and ``meta["conics"]`` are graph
tensors (a loss on them reaches the Gaussians and the cameras); ``meta["means2d"]``
receives dL/d(2D means) when it retains its gradient, and ``meta["means2d"].absgrad`` the sum of their absolute values
with ``absgrad=True`` (what densification reads), in gsplat's packed layout (``packed=True``,
its default: one row per visible camera-Gaussian pair, ``gaussian_ids``, ``camera_ids``)
or not ([C, N]). Leading batch dimensions are taken as gsplat takes them. CPU float32
tensors in and out. Gradients are bit-identical run after run (deterministic
accumulation; ``accumulation="float-atomics"`` trades that for speed).

The rasterizer's rules are an option, ``rules``. The default, ``"original"``, keeps the
original 3DGS rasterizer's (what scenes trained with the INRIA code need): near plane 0.2,
alpha clamp 0.99, a screen-space radius of 3 sigma of the larger axis, the guard band
symmetric about the image centre. ``rules="gsplat"`` takes gsplat's, so that a gsplat model
trains and renders the same here: near plane 0.01 (``near_plane`` when given), alpha clamp
0.999, a pixel ending at T <= 1e-4, a per-axis box of min(3.33, sqrt(2 ln(255 opacity)))
sigmas (no tail of a splat cut at a tile edge; ``meta["radii"]`` per axis), the guard band
around the principal point, the antialiased compensation's floor 0.
``verisplat.gsplat.rasterization`` is this function with ``rules="gsplat"``: with it, gsplat
code runs with only the import changed. ``near_plane`` may be any positive depth under
either rules. Neither has a far plane (gsplat's default 1e10 is accepted). gsplat's lenses
are taken as gsplat takes them: ``camera_model`` ``"pinhole"``, ``"ortho"`` or ``"fisheye"``,
``with_ut=True`` (the unscented transform through the exact lens, with ``radial_coeffs``
and ``tangential_coeffs``), ``"ortho"`` by either rule (the unscented transform is exact
for it), the fisheye with ``with_ut=False`` by gsplat's linearised rule (projected in
torch, the 2D Gaussians drawn as given: ``_carried``); docs/pytorch.md says where they
differ. Options verisplat does not implement are refused (``radius_clip``,
``camera_model="ftheta"``, ``thin_prism_coeffs``, ``covars``, ``with_eval3d=True``); those
needing them keep gsplat. ``rasterize_mode="antialiased"`` (opacities times sqrt(det(cov2d) / det(cov2d +
0.3 I)), Mip-Splatting's compensation) is differentiable as the classic mode is. The
argument table of ``docs/pytorch.md`` says, for each of gsplat's arguments and meta keys,
whether it is supported, supported with a difference, or refused.

The colour rule is one rule, gsplat's: SH coefficients give ``max(SH + 0.5, 0)``; direct
values (any number of channels) are blended as given, never clamped.
"""

from __future__ import annotations

import math
import numbers
from typing import Any, Dict, Optional, Tuple

import numpy as np
import torch

from . import _carried, _native, _projection
from . import raster as _raster
from ._passes import (
    _Call,
    _check_tensor,
    _from_layout,
    _Layout,
    _meta,
    _np,
    _pair_backward,
    _Passes,
    _stack,
    _to_layout,
)

__all__ = ["rasterization"]

_RASTERIZERS: Dict[Tuple[Any, str], "_raster.Rasterizer"] = {}


def _rasterizer(device: Any, accumulation: str) -> "_raster.Rasterizer":
    key = (device, accumulation)
    if key not in _RASTERIZERS:
        _RASTERIZERS[key] = _raster.Rasterizer(device=device, accumulation=accumulation)
    return _RASTERIZERS[key]


def _size(name: str, v: Any) -> int:
    """A positive integer size (Python or numpy integer, or an integral 0-d tensor)."""
    if isinstance(v, torch.Tensor) and v.dim() == 0 and not v.dtype.is_floating_point:
        v = int(v)
    if isinstance(v, bool) or not isinstance(v, numbers.Integral) or int(v) <= 0:
        raise ValueError(f"{name} must be a positive integer, got {v!r}")
    return int(v)


def _native_passes(call: _Call, arrays) -> Dict[Tuple[int, int], list]:
    """The forward passes, per (set, camera) pair a list of one per colour chunk."""
    means, quats, scales, opacities, colors = arrays
    r, layout = call.rasterizer, call.layout
    lenses = call.lenses
    cams, width, height = call.cams, call.width, call.height
    fwds: Dict[Tuple[int, int], list] = {}
    for b, c in layout.pairs():
        col = colors[b, c] if layout.per_camera else colors[b]
        viewmat, K = cams[b][c]
        fwds[(b, c)] = [
            r.forward(
                means[b],
                quats[b],
                scales[b],
                opacities[b],
                col if layout.sh_degree is not None else np.ascontiguousarray(col[:, ch]),
                viewmat,
                K,
                width,
                height,
                sh_degree=layout.sh_degree,
                kernel=call.kernel,
                antialiased=call.antialiased,
                rules=call.rules,
                near_plane=call.near_plane,
                reproducible=call.reproducible,
                lens=lenses[b][c],
            )
            for ch in layout.chunks
        ]
    return fwds


class _Project(torch.autograd.Function):
    """Runs the forward passes; returns the 2D means (an input of _Rasterize, so that
    ``meta["means2d"].grad`` is dL/d(2D means) as in gsplat), the depths, the conics and
    the blended opacities, then ``link`` and the ``_Passes`` handle, both only for
    _Rasterize. Its backward passes on what losses on the meta tensors add: the image's own
    gradients, which already include the path through the 2D means, are _Rasterize's, so
    the 2D means' gradient it receives less the image's part is what it chains. That part
    comes back through ``link`` (zeros, of the 2D means' shape), for which _Rasterize's
    backward returns minus it: the two gradients sum to the meta losses' alone."""

    @staticmethod
    def forward(ctx, means, quats, scales, opacities, colors, viewmats, Ks, call: _Call):  # type: ignore[override]
        layout = call.layout
        B, N = layout.B, layout.N
        arrays = (
            _np(means).reshape(B, N, 3),
            _np(quats).reshape(B, N, 4),
            _np(scales).reshape(B, N, 3),
            _np(opacities).reshape(B, N),
            _np(colors).reshape((B,) + tuple(colors.shape[len(layout.batch) :])),
        )
        fwds = _native_passes(call, arrays)
        radii = _stack(layout, fwds, lambda fs: fs[0].radii)  # [B, C, N]
        passes = _Passes(
            call=call,
            fwds=fwds,
            radii=radii,
            radii_xy=_stack(layout, fwds, lambda fs: fs[0].radii_xy),  # [B, C, N, 2]
            ids=np.nonzero(radii > 0) if layout.packed else None,
        )
        ctx.passes = passes
        ctx.inputs = [t.detach() for t in (means, quats, scales, opacities, viewmats, Ks)]
        # An output without a gradient (link when the image is not in the loss) is None.
        ctx.set_materialize_grads(False)
        outs = (
            _stack(layout, fwds, lambda fs: fs[0].means2d),
            _stack(layout, fwds, lambda fs: fs[0].gaussian_depths),
            _stack(layout, fwds, lambda fs: fs[0].conics),
            _stack(layout, fwds, lambda fs: fs[0].opacities),
        )
        means2d, depths, conics, blended = (torch.from_numpy(_to_layout(passes, o)) for o in outs)
        return means2d, depths, conics, blended, torch.zeros_like(means2d), passes

    @staticmethod
    def backward(ctx, g_means2d, g_depths, g_conics, g_opacities, g_link, _g_passes):  # type: ignore[override]
        passes: _Passes = ctx.passes
        if g_means2d is not None and g_link is not None:
            g_means2d = g_means2d + g_link  # g_link: minus the image's part
        grads = [_from_layout(passes, g) for g in (g_means2d, g_depths, g_conics, g_opacities)]
        wanted = [ctx.needs_input_grad[i] for i in (0, 1, 2, 3, 5, 6)]
        out = _meta_vjp(passes, ctx.inputs, grads, wanted)
        return out[0], out[1], out[2], out[3], None, out[4], out[5], None


def _meta_vjp(passes: _Passes, inputs, grads, wanted):
    """dL/d(means, quats, scales, opacities, viewmats, Ks) of losses on the meta 2D means,
    depths, conics and opacities (`grads`, [B, C, N, ...] or None), through the torch
    projection, pair by pair."""
    if all(g is None for g in grads) or not any(wanted):
        return [None] * 6
    call = passes.call
    layout = call.layout
    B, C, N = layout.B, layout.C, layout.N
    shapes = [(B, N, 3), (B, N, 4), (B, N, 3), (B, N), (B, C, 4, 4), (B, C, 3, 3)]
    flat = [t.reshape(shape) for t, shape in zip(inputs, shapes)]
    totals = [torch.zeros_like(t) if w else None for t, w in zip(flat, wanted)]
    with torch.enable_grad():
        for b, c in layout.pairs():
            vis = torch.from_numpy(passes.radii[b, c] > 0)
            if not bool(vis.any()):
                continue
            leaves = [t[b][vis] for t in flat[:4]] + [flat[4][b, c], flat[5][b, c]]
            leaves = [t.clone().requires_grad_(w) for t, w in zip(leaves, wanted)]
            p, q, s, o, vm, K = leaves
            m2d, conic, depth, _, comp = _projection.project(
                p, q, s, vm, K, call.width, call.height,
                antialiased=call.antialiased, rules=call.rules, lens=call.lenses[b][c])
            loss = torch.zeros(())
            for g, out in zip(grads, (m2d, depth, conic, o * comp)):
                if g is not None:
                    loss = loss + (torch.from_numpy(g[b, c][vis.numpy()]) * out).sum()
            need = [t for t, w in zip(leaves, wanted) if w]
            got = iter(torch.autograd.grad(loss, need, allow_unused=True))
            for i, w in enumerate(wanted):
                g = next(got) if w else None
                if g is None:
                    continue
                if i < 4:
                    totals[i][b][vis] += g
                else:
                    totals[i][b, c] += g
    return [None if t is None else t.reshape(i.shape) for t, i in zip(totals, inputs)]


def _camera_vjp(passes: _Passes, inputs, b, c, g2d, screen):
    """dL/d(viewmat, K) of pair (b, c) from its projected quantities' gradients (the
    device's), through the torch projection; zeros where the pair has nothing visible."""
    means, quats, scales, opacities, colors, viewmats, Ks = inputs
    call = passes.call
    layout = call.layout
    B, C, N = layout.B, layout.C, layout.N
    vm = viewmats.reshape(B, C, 4, 4)[b, c].clone().requires_grad_()
    K = Ks.reshape(B, C, 3, 3)[b, c].clone().requires_grad_()
    vis = torch.from_numpy(passes.radii[b, c] > 0)
    if not bool(vis.any()):
        return torch.zeros(4, 4), torch.zeros(3, 3)
    v = vis.numpy()
    sh = None
    if layout.sh_degree is not None:
        col = colors.reshape((B,) + tuple(colors.shape[len(layout.batch) :]))[b]
        sh = (col[c] if layout.per_camera else col)[vis]
    with torch.enable_grad():
        m2d, conic, depth, rgb, comp = _projection.project(
            means.reshape(B, N, 3)[b][vis], quats.reshape(B, N, 4)[b][vis],
            scales.reshape(B, N, 3)[b][vis], vm, K, call.width, call.height,
            sh, layout.sh_degree, call.antialiased, call.rules, call.lenses[b][c],
        )
        gs = torch.from_numpy(np.ascontiguousarray(screen[v]))
        loss = (torch.from_numpy(np.ascontiguousarray(g2d[v])) * m2d).sum()
        loss = loss + (gs[:, 0:3] * conic).sum() + (gs[:, 6] * depth).sum()
        if rgb is not None:
            loss = loss + (gs[:, 3:6] * rgb).sum()
        if call.antialiased:
            # The blended opacity, opacity times the compensation, depends on the camera.
            loss = loss + (gs[:, 7] * opacities.reshape(B, N)[b][vis] * comp).sum()
        g_vm, g_K = torch.autograd.grad(loss, [vm, K])
    return g_vm, g_K


class _Rasterize(torch.autograd.Function):
    """The image of _Project's forward passes (``passes``, the handle it returned): colours,
    alphas and expected depths. Its backward is the device's, for every input: the 2D means
    receive the image's part of their gradient, and ``link`` minus it (see _Project)."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx, means2d, link, means, quats, scales, opacities, colors, viewmats, Ks, passes: _Passes
    ):
        layout = passes.call.layout
        fwds = passes.fwds
        ctx.passes = passes
        ctx.means2d = means2d
        ctx.shapes = [tuple(t.shape) for t in (means, quats, scales, opacities, colors)]
        ctx.inputs = [t.detach() for t in (means, quats, scales, opacities, colors, viewmats, Ks)]

        def image(get):
            out = torch.from_numpy(np.ascontiguousarray(_stack(layout, fwds, get)))
            return out.reshape(layout.batch + tuple(out.shape[1:]))

        colors_out = image(lambda fs: np.concatenate([np.array(f.colors) for f in fs], axis=-1))
        alphas = image(lambda fs: np.array(fs[0].alphas))[..., None]
        depths = image(lambda fs: np.array(fs[0].depths))[..., None]
        return colors_out, alphas, depths

    @staticmethod
    def backward(ctx, g_colors, g_alphas, g_depths):  # type: ignore[override]
        passes: _Passes = ctx.passes
        layout = passes.call.layout
        B, C, N = layout.B, layout.C, layout.N
        camera = ctx.needs_input_grad[7] or ctx.needs_input_grad[8]
        flat = lambda g: None if g is None else _np(g).reshape((B, C) + tuple(g.shape[-3:]))  # noqa: E731
        g_colors, g_alphas, g_depths = flat(g_colors), flat(g_alphas), flat(g_depths)
        sums: Dict[str, np.ndarray] = {}
        full2d = np.zeros((B, C, N, 2), np.float32)
        abs2d = np.zeros((B, C, N, 2), np.float32)
        per_camera_colours: Dict[Tuple[int, int], np.ndarray] = {}
        g_vm = torch.zeros(B, C, 4, 4)
        g_K = torch.zeros(B, C, 3, 3)
        # The last pair's state is still on the device: its backward goes first.
        for b, c in reversed(layout.pairs()):
            g = _pair_backward(
                passes.call.rasterizer,
                passes.fwds[(b, c)],
                None if g_colors is None else g_colors[b, c],
                None if g_alphas is None else g_alphas[b, c, ..., 0],
                None if g_depths is None else g_depths[b, c, ..., 0],
                layout,
                camera,
            )
            full2d[b, c], abs2d[b, c] = g["means2d"], g["absgrad"]
            per_camera_colours[(b, c)] = g["colors"]
            for name in ("means", "quats", "scales", "opacities", "colors"):
                key = (name, b)
                sums[key] = g[name] if key not in sums else sums[key] + g[name]
            if camera:
                g_vm[b, c], g_K[b, c] = _camera_vjp(
                    passes, ctx.inputs, b, c, g["means2d"], g["screen"])
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))  # noqa: E731
        shapes = ctx.shapes
        groups = [
            t(np.stack([sums[(name, b)] for b in range(B)])).reshape(shape)
            for name, shape in zip(("means", "quats", "scales", "opacities"), shapes)
        ]
        if layout.per_camera:
            colours = [[per_camera_colours[(b, c)] for c in range(C)] for b in range(B)]
            colour_grad = np.stack([np.stack(row) for row in colours])
        else:
            colour_grad = np.stack([sums[("colors", b)] for b in range(B)])
        if layout.sh_degree is not None:
            colour_grad = _pad_sh(colour_grad, shapes[4])
        g2d = t(_to_layout(passes, full2d))
        if passes.call.absgrad:
            ctx.means2d.absgrad = t(_to_layout(passes, abs2d))
        cams = [None, None]
        if camera:
            cams = [g_vm.reshape(ctx.inputs[5].shape), g_K.reshape(ctx.inputs[6].shape)]
        # link: what _Project's backward takes out of its 2D means' gradient, the image's part.
        return (g2d, -g2d, *groups, t(colour_grad).reshape(shapes[4]), *cams, None)


def _pad_sh(grad: np.ndarray, shape: Tuple[int, ...]) -> np.ndarray:
    """SH coefficients past the degree rendered receive zero."""
    if grad.shape[-2] < shape[-2]:
        pad = np.zeros(grad.shape[:-2] + (shape[-2] - grad.shape[-2], 3), grad.dtype)
        grad = np.concatenate([grad, pad], axis=-2)
    return grad


# gsplat's keywords that verisplat takes only at the value that turns them off.
_OFF_KEYWORDS = {
    "with_eval3d": False,
    "ftheta_coeffs": None,
    "viewmats_rs": None,
}

# gsplat's camera models verisplat draws (gsplat's "ftheta" is refused).
_CAMERA_MODELS = ("pinhole", "ortho", "fisheye")


def _refuse(rules, near_plane, far_plane, radius_clip, eps2d, rasterize_mode, camera_model, covars,
            distributed, sparse_grad, segmented, rolling_shutter, channel_chunk, gsplat_kw):
    """ValueError for the first argument verisplat does not implement."""
    shutter = getattr(rolling_shutter, "name", rolling_shutter)
    refusals = [
        (
            isinstance(near_plane, bool) or not isinstance(near_plane, numbers.Real)
            or not (0.0 < float(near_plane) < float("inf")),
            f"near_plane must be a positive number, got {near_plane!r}",
        ),
        (rules not in ("original", "gsplat"), f"rules must be 'original' or 'gsplat', got {rules!r}"),
        (far_plane < 1e10, f"far_plane={far_plane}: verisplat has no far plane"),
        (radius_clip != 0.0, "radius_clip is not supported"),
        (
            eps2d != _native.COV2D_DILATION,
            f"eps2d={eps2d}: verisplat dilates 2D covariances by the original {_native.COV2D_DILATION}",
        ),
        (
            rasterize_mode not in ("classic", "antialiased"),
            f"rasterize_mode must be 'classic' or 'antialiased', got {rasterize_mode!r}",
        ),
        (
            camera_model == "ftheta",
            "camera_model='ftheta' is not supported: verisplat has no f-theta lens; the models "
            "are 'pinhole', 'ortho' and 'fisheye'",
        ),
        (
            camera_model not in _CAMERA_MODELS + ("ftheta",),
            f"camera_model must be 'pinhole', 'ortho' or 'fisheye', got {camera_model!r}",
        ),
        (covars is not None, "covars are not supported: pass quats and scales"),
        (distributed, "distributed rendering is not supported"),
        (sparse_grad, "sparse_grad is not supported"),
        (segmented, "segmented is not supported"),
        (shutter not in (None, "GLOBAL"), f"rolling_shutter={rolling_shutter!r}: only a global shutter"),
        (
            isinstance(channel_chunk, bool) or not isinstance(channel_chunk, numbers.Integral)
            or channel_chunk <= 0,
            f"channel_chunk must be a positive integer, got {channel_chunk!r}",
        ),
    ]
    for name, value in gsplat_kw.items():
        off = _OFF_KEYWORDS[name]
        bad = value is not None if off is None else bool(value)
        why = f"{name} is not supported: only {off!r} (got {value!r})"
        if name == "with_eval3d":
            why += ("; verisplat blends each Gaussian in 2D after its projection (gsplat's 3DGUT "
                    "pairs with_eval3d with with_ut=True, which is supported without it)")
        refusals.append((bad, why))
    for bad, why in refusals:
        if bad:
            raise ValueError(why)


def _gsplat_fisheye_max_theta(k: np.ndarray) -> float:
    """Half the field of view of gsplat's fisheye (``OpenCVFisheyeCameraModel``): where the
    radius ``theta (1 + k1 theta^2 + ... + k4 theta^8)`` first stops growing, and in front
    of the camera (gsplat's UT images no sigma point at ``z <= 0``). A Gaussian with a sigma
    point past it is culled (gsplat moves such a point back to the edge of its field of
    view)."""
    k1, k2, k3, k4 = (float(v) for v in k)
    # d/dtheta of the radius, a polynomial in x = theta^2: 1 + 3 k1 x + 5 k2 x^2 + ...
    slope = np.trim_zeros(np.array([9 * k4, 7 * k3, 5 * k2, 3 * k1, 1.0]), "f")
    roots = np.roots(slope) if len(slope) > 1 else np.array([])
    x = [r.real for r in roots if abs(r.imag) <= 1e-12 * max(1.0, abs(r)) and r.real > 0]
    return min(math.sqrt(min(x)) if x else math.inf, math.pi / 2)


def _lenses(layout: _Layout, camera_model, with_ut, radial, tangential):
    """Each camera's lens ([B][C], None: the pinhole's EWA projection, or the linearised
    fisheye's, which ``_carried`` draws) from gsplat's camera model, ``with_ut`` and
    distortion coefficients; ValueError for a combination gsplat does not draw or
    verisplat cannot."""
    given = [n for n, v in (("radial_coeffs", radial), ("tangential_coeffs", tangential))
             if v is not None]
    if given and camera_model == "ortho":
        raise ValueError(f"camera_model='ortho' has no distortion: {' and '.join(given)} must be None")
    if given and not with_ut:
        raise ValueError(
            f"{' and '.join(given)} need with_ut=True: as in gsplat, a distorted lens is "
            "projected by the unscented transform (the EWA rule has no distortion)"
        )
    if camera_model == "fisheye" and tangential is not None:
        raise ValueError(
            "tangential_coeffs: gsplat's fisheye (OpenCV's) has no tangential distortion and "
            "ignores them; pass None"
        )
    lead = layout.batch + (layout.C,)
    if radial is not None:
        want = 4 if camera_model == "fisheye" else 6
        _check_tensor("radial_coeffs", radial, lead + (None,))
        if radial.shape[-1] != want:
            names = "k1..k4" if want == 4 else "k1..k6"
            raise ValueError(
                f"radial_coeffs of camera_model={camera_model!r} must have shape "
                f"{lead + (want,)} ({names}), got {tuple(radial.shape)}"
            )
        radial = _np(radial).reshape(layout.B, layout.C, want).astype(np.float64)
    if tangential is not None:
        _check_tensor("tangential_coeffs", tangential, lead + (2,))
        tangential = _np(tangential).reshape(layout.B, layout.C, 2).astype(np.float64)

    def lens(b: int, c: int) -> Optional[Dict[str, Any]]:
        if camera_model == "fisheye" and not with_ut:
            return None  # gsplat's linearised fisheye, projected in torch (_carried)
        if camera_model == "ortho":
            return {"kind": "orthographic"}
        if camera_model == "fisheye":
            k = np.zeros(4) if radial is None else radial[b, c]
            return {"kind": "fisheye", "k": k.tolist(),
                    "max_theta": _gsplat_fisheye_max_theta(k)}
        if not with_ut:
            return None
        # The pinhole through the unscented transform, distorted or not (gsplat's UT with
        # its OpenCV or perfect pinhole model): the distorted lens, its coefficients 0 or not.
        return {"kind": "distorted",
                "radial": (np.zeros(6) if radial is None else radial[b, c]).tolist(),
                "tangential": (np.zeros(2) if tangential is None else tangential[b, c]).tolist()}

    return [[lens(b, c) for c in range(layout.C)] for b in range(layout.B)]


def _check_arguments(layout: _Layout, means, quats, scales, opacities, colors, Ks, sh_degree):
    bs, n = layout.batch, layout.N
    _check_tensor("means", means, bs + (n, 3))
    _check_tensor("quats", quats, bs + (n, 4))
    _check_tensor("scales", scales, bs + (n, 3))
    _check_tensor("opacities", opacities, bs + (n,))
    _check_tensor("colors", colors, layout.colour_shape())
    if sh_degree is not None:
        if isinstance(sh_degree, bool) or not isinstance(sh_degree, numbers.Integral):
            raise ValueError(f"sh_degree must be an integer 0..3 or None, got {sh_degree!r}")
    elif layout.D == 0:
        raise ValueError("colors must have at least one channel")
    _check_tensor("Ks", Ks, bs + (layout.C, 3, 3))


def _backgrounds(layout: _Layout, backgrounds, render_mode):
    """(colour background [B..., C, 1, 1, D] or None, depth background or None); gsplat
    ignores backgrounds for the depth-only modes, and so does this."""
    if backgrounds is None or render_mode in ("D", "ED"):
        return None, None
    d = layout.D
    plus_depth = render_mode in ("RGB+D", "RGB+ED")
    _check_tensor("backgrounds", backgrounds, layout.batch + (layout.C, None))
    got = backgrounds.shape[-1]
    if got != d and not (plus_depth and got == d + 1):
        want = f"{d}" + (f" (or {d + 1} with a depth background)" if plus_depth else "")
        raise ValueError(
            f"backgrounds must have {want} values per camera for colors of {d} channels and "
            f"render_mode {render_mode!r}, got shape {tuple(backgrounds.shape)}"
        )
    colour = backgrounds[..., :d][..., None, None, :]
    depth = backgrounds[..., d][..., None, None, None] if got == d + 1 else None
    return colour, depth


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
    near_plane: Optional[float] = None,
    far_plane: float = 1e10,
    radius_clip: float = 0.0,
    eps2d: float = _native.COV2D_DILATION,
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
    with_ut: bool = False,
    with_eval3d: bool = False,
    radial_coeffs: Optional[torch.Tensor] = None,
    tangential_coeffs: Optional[torch.Tensor] = None,
    thin_prism_coeffs: Optional[torch.Tensor] = None,
    ftheta_coeffs: Any = None,
    rolling_shutter: Any = None,
    viewmats_rs: Optional[torch.Tensor] = None,
    device: Any = None,
    accumulation: str = "deterministic",
    kernel: str = "gaussian",
    rules: str = "original",
    reproducible: bool = False,
    **unsupported: Any,
) -> Tuple[torch.Tensor, torch.Tensor, Dict[str, Any]]:
    """gsplat's ``rasterization`` (see the module's docstring for where the rules differ).

    ``means`` [..., N, 3], ``quats`` [..., N, 4] (w, x, y, z; normalised inside),
    ``scales`` [..., N, 3] (linear, either sign), ``opacities`` [..., N] (in [0, 1]),
    ``colors`` [..., (C,) N, K, 3] SH coefficients with ``sh_degree`` or [..., (C,) N, D]
    direct channels without (any D; more than 16 are blended 16 at a time), ``viewmats``
    [..., C, 4, 4] world-to-camera (OpenCV axes), ``Ks`` [..., C, 3, 3]; ``...`` are
    leading batch dimensions, the same for all. ``render_mode``: ``"RGB"``, ``"D"``
    (accumulated depth), ``"ED"`` (expected depth), ``"RGB+D"``, ``"RGB+ED"``.
    ``backgrounds`` [..., C, D] (or [..., C, D + 1] with a depth background for the
    ``+D`` modes; ignored by the depth-only modes, as gsplat does). ``tile_size`` and
    ``channel_chunk`` are gsplat's speed settings: accepted, verisplat uses its own.
    verisplat's own: ``device`` (Vulkan device index or name), ``accumulation``,
    ``kernel`` (``"power"``: the power-function falloff) and ``rules`` (``"original"``,
    the 3DGS rasterizer's, the default; ``"gsplat"``, gsplat's: see the module's
    docstring), ``reproducible`` (the blends with the CPU reference's exp and unfused
    arithmetic: the same bits on every device where the preprocess gives them;
    docs/reproducibility.md). ``near_plane``: None is the rules' (0.2; gsplat's 0.01).
    ``camera_model`` (``"pinhole"``, ``"ortho"``, ``"fisheye"``), ``with_ut``,
    ``radial_coeffs`` ([..., C, 6] for the pinhole, [..., C, 4] for the fisheye) and
    ``tangential_coeffs`` ([..., C, 2], the pinhole's): gsplat's lenses (the module's
    docstring).

    Returns ``(render_colors [..., C, H, W, D], render_alphas [..., C, H, W, 1], meta)``.
    meta, packed (the default): ``batch_ids``, ``camera_ids``, ``gaussian_ids`` [nnz]
    (int64: the visible pairs), ``radii`` [nnz, 2] (int32; per axis under gsplat's
    rules, else the one radius twice), ``means2d`` [nnz, 2],
    ``depths`` [nnz], ``conics`` [nnz, 3], ``opacities`` [nnz]; not packed: the same as
    [..., C, N, ...] (``radii`` 0 where culled) and the ids None. Also ``width``,
    ``height``, ``tile_size`` (verisplat's: 16), ``n_batches``, ``n_cameras``.
    """
    if unsupported:
        raise ValueError(f"verisplat.torch.rasterization does not support {sorted(unsupported)}")
    gsplat_kw = dict(with_eval3d=with_eval3d, ftheta_coeffs=ftheta_coeffs, viewmats_rs=viewmats_rs)
    if thin_prism_coeffs is not None:
        raise ValueError(
            "thin_prism_coeffs are not supported: verisplat's distorted lens is OpenCV's radial "
            "and tangential model without the thin-prism terms (s1..s4); pass None"
        )
    if near_plane is None:
        near_plane = _native.GSPLAT_NEAR_PLANE if rules == "gsplat" else _native.NEAR_PLANE
    _refuse(rules, near_plane, far_plane, radius_clip, eps2d, rasterize_mode, camera_model, covars,
            distributed, sparse_grad, segmented, rolling_shutter, channel_chunk, gsplat_kw)
    _size("tile_size", tile_size)
    modes = {"RGB", "D", "ED", "RGB+D", "RGB+ED"}
    if render_mode not in modes:
        raise ValueError(f"render_mode must be one of {sorted(modes)}, got {render_mode!r}")
    width, height = _size("width", width), _size("height", height)
    layout = _Layout(means, colors, viewmats, sh_degree, bool(packed))
    _check_arguments(layout, means, quats, scales, opacities, colors, Ks, sh_degree)
    sh_degree = None if sh_degree is None else int(sh_degree)
    layout.sh_degree = sh_degree
    bg_colour, bg_depth = _backgrounds(layout, backgrounds, render_mode)
    vm = _np(viewmats).reshape(layout.B, layout.C, 4, 4)
    ks = _np(Ks).reshape(layout.B, layout.C, 3, 3)
    cams = [[(vm[b, c], ks[b, c]) for c in range(layout.C)] for b in range(layout.B)]
    lenses = _lenses(layout, camera_model, bool(with_ut), radial_coeffs, tangential_coeffs)
    call = _Call(
        rasterizer=_rasterizer(device, accumulation),
        layout=layout,
        cams=cams,
        lenses=lenses,
        width=width,
        height=height,
        kernel=kernel,
        rules=rules,
        near_plane=float(near_plane),
        reproducible=bool(reproducible),
        antialiased=rasterize_mode == "antialiased",
        absgrad=absgrad,
    )
    # gsplat builds the covariance from the scales' squares: the sign is the gradient's.
    # A zero scale is the smallest normal float (its gradient is 0, as gsplat's is).
    unsigned = scales.abs().clamp_min(torch.finfo(torch.float32).tiny)
    if camera_model == "fisheye" and not with_ut:
        rgb, alphas, expected, meta = _carried.rasterize(
            call, means, quats, unsigned, opacities, colors, viewmats, Ks)
    else:
        means2d, depths, conics, blended, link, passes = _Project.apply(
            means, quats, unsigned, opacities, colors, viewmats, Ks, call)
        rgb, alphas, expected = _Rasterize.apply(
            means2d, link, means, quats, unsigned, opacities, colors, viewmats, Ks, passes)
        meta = _meta(passes, (means2d, depths, conics, blended))
    if bg_colour is not None:
        rgb = rgb + (1.0 - alphas) * bg_colour
    depth = expected * alphas if render_mode in ("D", "RGB+D") else expected
    if bg_depth is not None:
        depth = depth + (1.0 - alphas) * bg_depth
    if render_mode == "RGB":
        out = rgb
    elif render_mode in ("D", "ED"):
        out = depth
    else:
        out = torch.cat([rgb, depth], dim=-1)
    return out, alphas, meta
