"""gsplat's linearised fisheye (``camera_model="fisheye"``, ``with_ut=False``) for
``verisplat.torch.rasterization``: the 2D Gaussians are projected here in torch by
gsplat's rule (its ``_fisheye_proj``: the mean through the equidistant map without
distortion, the covariance ``J Sigma J^T`` with ``J`` at the mean), and the renderer draws
those 2D Gaussians as they are.

The renderer draws a 2D Gaussian exactly through its orthographic lens: the unscented
transform of a linear map is exact, so a Gaussian at ``(u, v, z)`` with scaled axes
``(e1, e2, sigma_z e3)`` in the plane seen by an orthographic camera with the identity
pose and ``fx = fy = 1``, ``cx = cy = 0`` lands at ``(u, v)`` with the covariance
``sum e_i e_i^T`` of its two in-plane axes, and ``z``, its depth, is what it is sorted by,
culled at the near plane by, and what the depth modes blend (gsplat's ``z``). Each 2D
covariance's eigenvectors give such a carrier's rotation about the axis and its scales.
Colours are evaluated here (SH with the real view direction, gsplat's ``max(SH + 0.5, 0)``)
and drawn as direct values.

Gradients: the device's backward pass of the carriers returns the gradients of the 2D
quantities (``screen``: 2D mean, conic, depth, the blended opacity; the colours'), which
torch chains back through the projection above to the Gaussians and the cameras.
"""

from __future__ import annotations

from typing import Dict, Tuple

import numpy as np
import torch

from . import _native, _projection
from ._passes import _meta, _pair_backward, _Passes, _stack, _to_layout

# The carriers' depth spread, relative to their depth: far too thin to matter, wide
# enough that every sigma point stays in front of the camera.
_THIN = 1e-4
# The carriers' smallest in-plane scale (pixels): a 2D covariance with a zero axis (a
# Gaussian seen edge on) is drawn dilated as gsplat draws it.
_TINY = 1e-6
_ORTHO_LENS = {"kind": "orthographic"}
_IDENTITY = np.eye(4, dtype=np.float32)
_UNIT_K = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], dtype=np.float32)


def fisheye_ewa(means, quats, scales, viewmat, K, near_plane=None):
    """gsplat 1.5.3's ``_fisheye_proj`` (and ``_world_to_cam``) of one camera, formula for
    formula: 2D means [N, 2], covariances (xx, xy, yy) [N, 3] before eps2d, depths z [N].
    A Gaussian at or behind ``near_plane`` (culled) is projected from a point in front
    instead, so that its values and derivatives stay finite (its gradient is 0)."""
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    v = means @ R.T + t
    if near_plane is not None:
        gone = (v[:, 2] <= near_plane).detach()[:, None]
        v = torch.where(gone, torch.tensor([0.0, 0.0, 1.0], dtype=v.dtype), v)
    m = _projection._rotations(quats) * scales[:, None, :]
    cov = R @ (m @ m.transpose(1, 2)) @ R.T
    x, y, z = v.unbind(-1)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    eps = 0.0000001
    # gsplat's (x^2 + y^2)^0.5 + eps; the 1e-30 keeps the square root's derivative finite
    # on the axis.
    xy_len = torch.sqrt(x * x + y * y + 1e-30) + eps
    theta = torch.atan2(xy_len, z + eps)
    means2d = torch.stack([x * fx * theta / xy_len + cx, y * fy * theta / xy_len + cy], -1)
    x2 = x * x + eps
    y2 = y * y
    xy = x * y
    x2y2 = x2 + y2
    x2y2z2_inv = 1.0 / (x2y2 + z * z)
    b = torch.atan2(xy_len, z) / xy_len / x2y2
    a = z * x2y2z2_inv / x2y2
    j0 = torch.stack([fx * (x2 * a + y2 * b), fx * xy * (a - b), -fx * x * x2y2z2_inv], -1)
    j1 = torch.stack([fy * xy * (a - b), fy * (y2 * a + x2 * b), -fy * y * x2y2z2_inv], -1)
    c00 = torch.einsum("ni,nij,nj->n", j0, cov, j0)
    c01 = torch.einsum("ni,nij,nj->n", j0, cov, j1)
    c11 = torch.einsum("ni,nij,nj->n", j1, cov, j1)
    depth = z if near_plane is None else (means @ R.T + t)[:, 2]
    return means2d, torch.stack([c00, c01, c11], -1), depth


def conics_of(cov, antialiased: bool, rules: str):
    """The renderer's conic (the inverse of the dilated covariance) [..., 3] and opacity
    compensation [...] of 2D covariances (xx, xy, yy) [..., 3]."""
    d = _native.COV2D_DILATION
    a, b, c = cov.unbind(-1)
    a2, c2 = a + d, c + d
    det = a2 * c2 - b * b
    conics = torch.stack([c2, -b, a2], -1) / det[..., None]
    comp = torch.ones_like(det)
    if antialiased:
        floor = 0.0 if rules == "gsplat" else _native.ANTIALIAS_MIN_RATIO
        comp = torch.sqrt(torch.clamp_min((a * c - b * b) / det, floor))
    return conics, comp


def carriers(means2d: np.ndarray, cov: np.ndarray, depth: np.ndarray):
    """The Gaussians (means, quats, scales as float32) that the orthographic unit camera
    draws as the 2D Gaussians ``means2d`` [N, 2], ``cov`` (xx, xy, yy) [N, 3] at ``depth``."""
    a, b, c = (cov[:, i].astype(np.float64) for i in range(3))
    half = 0.5 * (a - c)
    r = np.hypot(half, b)
    mid = 0.5 * (a + c)
    angle = 0.5 * np.arctan2(b, half)  # of the first eigenvector (eigenvalue mid + r)
    scales = np.stack([
        np.sqrt(np.maximum(mid + r, _TINY ** 2)),
        np.sqrt(np.maximum(mid - r, _TINY ** 2)),
        np.maximum(np.abs(depth) * _THIN, _TINY),
    ], -1)
    quats = np.stack([np.cos(0.5 * angle), 0 * angle, 0 * angle, np.sin(0.5 * angle)], -1)
    # The 2D means are in gsplat's pixels (centres at +0.5), the renderer's continuous
    # image position too.
    means = np.concatenate([means2d, depth[:, None]], -1)
    f32 = lambda x: np.ascontiguousarray(x, dtype=np.float32)  # noqa: E731
    return f32(means), f32(quats), f32(scales)


def project_all(call, means, quats, scales, colors, viewmats, Ks):
    """The 2D means [B, C, N, 2], covariances [B, C, N, 3], depths [B, C, N] and colours
    [B, C, N, D] of every pair, as graph tensors."""
    layout = call.layout
    B, C, N = layout.B, layout.C, layout.N
    means, quats, scales = means.reshape(B, N, 3), quats.reshape(B, N, 4), scales.reshape(B, N, 3)
    vms, ks = viewmats.reshape(B, C, 4, 4), Ks.reshape(B, C, 3, 3)
    cols = colors.reshape((B,) + tuple(colors.shape[len(layout.batch):]))
    m2d, cov, depth, rgb = [], [], [], []
    for b in range(B):
        row = [fisheye_ewa(means[b], quats[b], scales[b], vms[b, c], ks[b, c], call.near_plane)
               for c in range(C)]
        m2d.append(torch.stack([r[0] for r in row]))
        cov.append(torch.stack([r[1] for r in row]))
        depth.append(torch.stack([r[2] for r in row]))
        per = []
        for c in range(C):
            col = cols[b, c] if layout.per_camera else cols[b]
            if layout.sh_degree is not None:
                R, t = vms[b, c, :3, :3], vms[b, c, :3, 3]
                d = means[b] + t @ R  # means - (-R^T t)
                # (A Gaussian at the camera's centre is culled: its direction is any.)
                dirs = d / d.norm(dim=-1, keepdim=True).clamp_min(1e-30)
                k = (layout.sh_degree + 1) ** 2
                raw = (col[:, :k, :] * _projection.sh_basis(dirs, layout.sh_degree)[:, :, None]).sum(1)
                col = torch.clamp_min(raw + 0.5, 0.0)
            per.append(col)
        rgb.append(torch.stack(per))
    return torch.stack(m2d), torch.stack(cov), torch.stack(depth), torch.stack(rgb)


def native_passes(call, m2d, cov, depth, opacities, colours):
    """The carriers' forward passes, per pair one per colour chunk (numpy in)."""
    layout = call.layout
    r = call.rasterizer
    fwds: Dict[Tuple[int, int], list] = {}
    for b, c in layout.pairs():
        # A Gaussian behind the near plane (whose projection may not be finite: at the
        # camera's centre) is culled there: its carrier is put behind the camera.
        gone = ~((depth[b, c] > call.near_plane) & np.isfinite(m2d[b, c]).all(-1)
                 & np.isfinite(cov[b, c]).all(-1))
        m, v, z = m2d[b, c].copy(), cov[b, c].copy(), depth[b, c].copy()
        m[gone], v[gone], z[gone] = 0.0, (1.0, 0.0, 1.0), -1.0
        means, quats, scales = carriers(m, v, z)
        fwds[(b, c)] = [
            r.forward(means, quats, scales, opacities[b],
                      np.ascontiguousarray(colours[b, c][:, ch]), _IDENTITY, _UNIT_K,
                      call.width, call.height, kernel=call.kernel, antialiased=call.antialiased,
                      rules=call.rules, near_plane=call.near_plane,
                      reproducible=call.reproducible, lens=_ORTHO_LENS)
            for ch in layout.chunks
        ]
    return fwds


class Rasterize(torch.autograd.Function):
    """The carriers' image (colours, alphas, expected depths) from the 2D Gaussians: its
    inputs are the meta 2D means (their layout: packed or not), the covariances, depths and
    colours of every pair and the opacities; its backward pass is the device's, returned
    as the gradients of those 2D quantities."""

    @staticmethod
    def forward(ctx, means2d, cov, depth, colours, opacities, passes):  # type: ignore[override]
        layout = passes.call.layout
        ctx.passes = passes
        ctx.means2d = means2d
        ctx.save_for_backward(cov, opacities)

        def image(get):
            out = torch.from_numpy(np.ascontiguousarray(_stack(layout, passes.fwds, get)))
            return out.reshape(layout.batch + tuple(out.shape[1:]))

        colors_out = image(lambda fs: np.concatenate([np.array(f.colors) for f in fs], axis=-1))
        alphas = image(lambda fs: np.array(fs[0].alphas))[..., None]
        depths = image(lambda fs: np.array(fs[0].depths))[..., None]
        return colors_out, alphas, depths

    @staticmethod
    def backward(ctx, g_colors, g_alphas, g_depths):  # type: ignore[override]
        passes = ctx.passes
        call = passes.call
        layout = call.layout
        B, C, N = layout.B, layout.C, layout.N
        cov, opacities = ctx.saved_tensors
        flat = lambda g: None if g is None else g.detach().numpy().reshape((B, C) + tuple(g.shape[-3:]))  # noqa: E731
        g_colors, g_alphas, g_depths = flat(g_colors), flat(g_alphas), flat(g_depths)
        g2d = np.zeros((B, C, N, 2), np.float32)
        abs2d = np.zeros((B, C, N, 2), np.float32)
        g_conic = np.zeros((B, C, N, 3), np.float32)
        g_depth = np.zeros((B, C, N), np.float32)
        g_blended = np.zeros((B, C, N), np.float32)
        g_colours = np.zeros((B, C, N, layout.D), np.float32)
        g_opac = np.zeros((B, N), np.float32)
        for b, c in reversed(layout.pairs()):
            g = _pair_backward(
                call.rasterizer, passes.fwds[(b, c)],
                None if g_colors is None else g_colors[b, c],
                None if g_alphas is None else g_alphas[b, c, ..., 0],
                None if g_depths is None else g_depths[b, c, ..., 0],
                layout, True)
            g2d[b, c], abs2d[b, c] = g["means2d"], g["absgrad"]
            g_conic[b, c], g_depth[b, c], g_blended[b, c] = g["screen"][:, 0:3], g["screen"][:, 6], g["screen"][:, 7]
            g_colours[b, c] = g["colors"]
            g_opac[b] += g["opacities"]
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))  # noqa: E731
        # The conic and the compensation (antialiased: the blended opacity's factor) from
        # the covariances, their gradients by autograd.
        with torch.enable_grad():
            leaf = cov.detach().requires_grad_()
            conics, comp = conics_of(leaf, call.antialiased, call.rules)
            loss = (t(g_conic) * conics).sum()
            o = opacities.detach().reshape(B, 1, N)
            if call.antialiased:
                loss = loss + (t(g_blended) * o * comp).sum()
            (g_cov,) = torch.autograd.grad(loss, [leaf], allow_unused=True)
        if call.absgrad:
            ctx.means2d.absgrad = t(_to_layout(passes, abs2d))
        return (t(_to_layout(passes, g2d)), g_cov, t(g_depth), t(g_colours),
                t(g_opac).reshape(opacities.shape), None)


def rasterize(call, means, quats, scales, opacities, colors, viewmats, Ks):
    """The colours, alphas and expected depths [..., C, H, W, ...] and the meta dict of
    gsplat's linearised fisheye (the module's docstring)."""
    layout = call.layout
    B, C, N = layout.B, layout.C, layout.N
    # The carriers blend direct colours in the layout's chunks (SH: the 3 channels).
    m2d, cov, depth, colours = project_all(call, means, quats, scales, colors, viewmats, Ks)
    n = lambda x: x.detach().numpy()  # noqa: E731
    opac = opacities.reshape(B, N)
    fwds = native_passes(call, n(m2d), n(cov), n(depth), n(opac), n(colours))
    radii = _stack(layout, fwds, lambda fs: fs[0].radii)
    passes = _Passes(
        call=call, fwds=fwds, radii=radii,
        radii_xy=_stack(layout, fwds, lambda fs: fs[0].radii_xy),
        ids=np.nonzero(radii > 0) if layout.packed else None,
    )

    def meta_layout(x):
        if layout.packed:
            return x[tuple(torch.from_numpy(i) for i in passes.ids)]
        return x.reshape(layout.batch + (C, N) + tuple(x.shape[3:]))

    means2d = meta_layout(m2d)
    conics, comp = conics_of(cov, call.antialiased, call.rules)
    blended = opac[:, None, :] * comp
    rgb, alphas, expected = Rasterize.apply(means2d, cov, depth, colours, opac, passes)
    meta = _meta(passes, (means2d, meta_layout(depth), meta_layout(conics), meta_layout(blended)))
    return rgb, alphas, expected, meta
