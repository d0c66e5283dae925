"""The renderer's projection in torch, for the gradients the device does not chain itself:
a camera's (``viewmats``, ``Ks``) and those of losses on ``meta`` (2D means, depths,
conics). It follows ``preprocess.comp`` and ``cpu::backward`` rule for rule (the original
3DGS rasterizer's): view-space mean ``v = R p + t``, the Jacobian at the position clamped
to 1.3 times the half field of view (``tan = W / (2 fx)``), 2D covariance ``T Sigma T^T``
with ``T = J R`` dilated by 0.3, conic its inverse, 2D mean ``f v / z + c`` (gsplat's pixel
convention), depth ``z``, and the SH colour ``max(SH(dir) + 0.5, 0)`` with ``dir`` from
the camera centre ``-R^T t`` to the mean. Under gsplat's rules (``rules="gsplat"``) the
clamp runs from ``-(cx / fx + 0.3 tan)`` to ``(W - cx) / fx + 0.3 tan`` and the antialiased
compensation's floor is 0. Through a lens other than the pinhole (``lens``, as
``verisplat.Camera`` takes it) the 2D mean and covariance are the unscented transform's
(``core::model::unscented``: gsplat's alpha 0.1, beta 2, kappa 0; the seven sigma points
through the lens's exact map, summed relative to the centre's pixel, in float64), and the
depth is the distance from the camera through a fisheye, else ``z``. Only used for the
gradient: the values rendered are the device's."""

from __future__ import annotations

import math
from typing import Any, Optional, Sequence, Tuple

import torch

# The renderer's own constants (src/core/rules.rs, src/core/model/sh.rs), from the extension: the
# smallest opacity compensation ratio, the 2D covariance's dilation, the SH bands'.
from ._native import ANTIALIAS_MIN_RATIO, COV2D_DILATION
from ._native import SH_C0 as C0
from ._native import SH_C1 as C1
from ._native import SH_C2 as C2
from ._native import SH_C3 as C3


def sh_basis(dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """The real SH basis of the original code at unit directions [n, 3]: [n, (d + 1)^2]."""
    x, y, z = dirs.unbind(-1)
    b = [torch.full_like(x, C0)]
    if degree > 0:
        b += [-C1 * y, C1 * z, -C1 * x]
    if degree > 1:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        b += [C2[0] * xy, C2[1] * yz, C2[2] * (2 * zz - xx - yy), C2[3] * xz, C2[4] * (xx - yy)]
        if degree > 2:
            b += [
                C3[0] * y * (3 * xx - yy),
                C3[1] * xy * z,
                C3[2] * y * (4 * zz - xx - yy),
                C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
                C3[4] * x * (4 * zz - xx - yy),
                C3[5] * z * (xx - yy),
                C3[6] * x * (xx - 3 * yy),
            ]
    return torch.stack(b, -1)


def _rotations(quats: torch.Tensor) -> torch.Tensor:
    w, x, y, z = (quats / quats.norm(dim=-1, keepdim=True)).unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], -1).reshape(quats.shape[:-1] + (3, 3))


# The unscented transform's parameters (gsplat's defaults, core::model::unscented).
UT_ALPHA, UT_BETA, UT_KAPPA = 0.1, 2.0, 0.0


def ut_weights() -> Tuple[float, float, float, float]:
    """The sigma points' spread sqrt(n + lambda), the centre's mean weight, every other
    point's weight, and the centre's covariance weight (``UnscentedParams::weights``)."""
    n = 3.0
    lam = UT_ALPHA * UT_ALPHA * (n + UT_KAPPA) - n
    centre = lam / (n + lam)
    return math.sqrt(n + lam), centre, 1.0 / (2.0 * (n + lam)), centre + 1.0 - UT_ALPHA ** 2 + UT_BETA


def lens_map(kind: str, values: Sequence[float], p: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """The pixel [..., 2] of camera-space points p [..., 3] through the lens (``Lens::project``
    for the points it images; the caller passes only those)."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    x, y, z = p.unbind(-1)
    if kind == "orthographic":
        u, v = x, y
    elif kind == "distorted":
        k1, k2, k3, k4, k5, k6, p1, p2 = values
        x, y = x / z, y / z
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        u = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        v = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    elif kind == "fisheye":
        k1, k2, k3, k4 = values[:4]
        r = torch.sqrt(x * x + y * y)
        # On the axis the radius over r is its limit 1 / z (r = 0 is kept out of the division).
        axis = r == 0
        safe = torch.where(axis, torch.ones_like(r), r)
        theta = torch.atan2(safe, z)
        t2 = theta * theta
        s = torch.where(axis, 1 / z, theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) / safe)
        u, v = x * s, y * s
    else:
        raise ValueError(f"the torch projection has no {kind} lens")
    return torch.stack([fx * u + cx, fy * v + cy], -1)


def _unscented(kind, values, v, axes, K):
    """The unscented transform of camera-space Gaussians (means v [n, 3], scaled axes as
    columns [n, 3, 3]) through the lens: 2D means [n, 2] and covariances (xx, xy, yy),
    summed relative to the centre's pixel as ``unscented::project`` does."""
    spread, _, side, centre_cov = ut_weights()
    d = spread * axes.transpose(1, 2)  # [n, 3 (axis), 3]
    points = torch.cat([v[:, None, :], v[:, None, :] + d, v[:, None, :] - d], 1)  # [n, 7, 3]
    pixels = lens_map(kind, values, points, K)
    offsets = pixels - pixels[:, :1]
    shift = side * offsets[:, 1:].sum(1)
    e = offsets - shift[:, None, :]
    w = torch.full((7,), side, dtype=v.dtype)
    w[0] = centre_cov
    cov = torch.einsum("j,nja,njb->nab", w, e, e)
    return pixels[:, 0] + shift, cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]


def project(
    means: torch.Tensor,
    quats: torch.Tensor,
    scales: torch.Tensor,
    viewmat: torch.Tensor,
    K: torch.Tensor,
    width: int,
    height: int,
    sh: Optional[torch.Tensor] = None,
    sh_degree: Optional[int] = None,
    antialiased: bool = False,
    rules: str = "original",
    lens: Any = None,
) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, Optional[torch.Tensor], torch.Tensor]:
    """2D means [n, 2], conics [n, 3], depths [n], (with SH) colours [n, 3] and the
    opacity compensation [n] (``antialiased``: sqrt(max(det(cov2d) / det(cov2d + 0.3 I),
    2.5e-5)), else 1) of the Gaussians (all in front of the near plane: the caller passes
    the visible ones), through the pinhole or ``lens`` (see the module's docstring)."""
    from ._cameras import _lens_tuple

    kind, values = _lens_tuple(lens)
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    v = means @ R.T + t
    z = v[:, 2]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if kind != "pinhole":
        f64 = torch.float64
        axes = R.to(f64) @ (_rotations(quats.to(f64)) * scales.to(f64)[:, None, :])
        mean2d, a, b, c = _unscented(kind, values, v.to(f64), axes, K.to(f64))
        depth = v.to(f64).norm(dim=-1) if kind == "fisheye" else z
        return _finish(
            mean2d, a, b, c, depth, means, t, R, sh, sh_degree, antialiased, rules, quats.dtype)
    # The guard band (Rules::clamp_limits, whose factors are literals there too).
    if rules == "gsplat":
        bx, by = 0.3 * (0.5 * width / fx), 0.3 * (0.5 * height / fy)
        xn, xp = cx / fx + bx, (width - cx) / fx + bx
        yn, yp = cy / fy + by, (height - cy) / fy + by
    else:
        xp = xn = 1.3 * width / (2 * fx)
        yp = yn = 1.3 * height / (2 * fy)
    tx = torch.minimum(torch.maximum(v[:, 0] / z, -xn), xp) * z
    ty = torch.minimum(torch.maximum(v[:, 1] / z, -yn), yp) * z
    zero = torch.zeros_like(z)
    j0 = torch.stack([fx / z, zero, -fx * tx / (z * z)], -1)
    j1 = torch.stack([zero, fy / z, -fy * ty / (z * z)], -1)
    t0, t1 = j0 @ R, j1 @ R  # R^T j, as rows
    m = _rotations(quats) * scales[:, None, :]
    cov = m @ m.transpose(1, 2)
    a = torch.einsum("ni,nij,nj->n", t0, cov, t0)
    b = torch.einsum("ni,nij,nj->n", t0, cov, t1)
    c = torch.einsum("ni,nij,nj->n", t1, cov, t1)
    means2d = torch.stack([fx * v[:, 0] / z + cx, fy * v[:, 1] / z + cy], -1)
    return _finish(means2d, a, b, c, z, means, t, R, sh, sh_degree, antialiased, rules, quats.dtype)


def _finish(means2d, a, b, c, depth, means, t, R, sh, sh_degree, antialiased, rules, dtype):
    """The dilation, conic, compensation and SH colour of projected Gaussians (2D means,
    covariances (a, b, c) before the dilation, depths), in ``dtype``."""
    a, c = a + COV2D_DILATION, c + COV2D_DILATION
    det = a * c - b * b
    conics = torch.stack([c, -b, a], -1) / det[:, None]
    comp = torch.ones_like(det)
    if antialiased:
        det0 = (a - COV2D_DILATION) * (c - COV2D_DILATION) - b * b
        floor = 0.0 if rules == "gsplat" else ANTIALIAS_MIN_RATIO
        comp = torch.sqrt(torch.clamp_min(det0 / det, floor))
    colours = None
    if sh is not None and sh_degree is not None:
        centre = -(t @ R)  # -R^T t
        d = means - centre
        dirs = d / d.norm(dim=-1, keepdim=True)
        k = (sh_degree + 1) ** 2
        raw = (sh[:, :k, :] * sh_basis(dirs, sh_degree)[:, :, None]).sum(1)
        colours = torch.clamp_min(raw + 0.5, 0.0)
    return means2d.to(dtype), conics.to(dtype), depth.to(dtype), colours, comp.to(dtype)
