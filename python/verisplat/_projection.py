"""The renderer's projection in torch, for the gradients the device does not chain itself:
a camera's (``viewmats``, ``Ks``) and those of losses on ``meta`` (2D means, depths,
conics). It follows ``preprocess.comp`` and ``cpu::backward`` rule for rule (the original
3DGS rasterizer's): view-space mean ``v = R p + t``, the Jacobian at the position clamped
to 1.3 times the half field of view (``tan = W / (2 fx)``), 2D covariance ``T Sigma T^T``
with ``T = J R`` dilated by 0.3, conic its inverse, 2D mean ``f v / z + c`` (gsplat's pixel
convention), depth ``z``, and the SH colour ``max(SH(dir) + 0.5, 0)`` with ``dir`` from
the camera centre ``-R^T t`` to the mean. Under gsplat's rules (``rules="gsplat"``) the
clamp runs from ``-(cx / fx + 0.3 tan)`` to ``(W - cx) / fx + 0.3 tan`` and the antialiased
compensation's floor is 0. Only used for the gradient: the values rendered
are the device's."""

from __future__ import annotations

from typing import Optional, Tuple

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
) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, Optional[torch.Tensor], torch.Tensor]:
    """2D means [n, 2], conics [n, 3], depths [n], (with SH) colours [n, 3] and the
    opacity compensation [n] (``antialiased``: sqrt(max(det(cov2d) / det(cov2d + 0.3 I),
    2.5e-5)), else 1) of the Gaussians (all in front of the near plane: the caller passes
    the visible ones)."""
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    v = means @ R.T + t
    z = v[:, 2]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
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
    a = torch.einsum("ni,nij,nj->n", t0, cov, t0) + COV2D_DILATION
    b = torch.einsum("ni,nij,nj->n", t0, cov, t1)
    c = torch.einsum("ni,nij,nj->n", t1, cov, t1) + COV2D_DILATION
    det = a * c - b * b
    conics = torch.stack([c, -b, a], -1) / det[:, None]
    comp = torch.ones_like(det)
    if antialiased:
        det0 = (a - COV2D_DILATION) * (c - COV2D_DILATION) - b * b
        floor = 0.0 if rules == "gsplat" else ANTIALIAS_MIN_RATIO
        comp = torch.sqrt(torch.clamp_min(det0 / det, floor))
    means2d = torch.stack([fx * v[:, 0] / z + cx, fy * v[:, 1] / z + cy], -1)
    colours = None
    if sh is not None and sh_degree is not None:
        centre = -(t @ R)  # -R^T t
        d = means - centre
        dirs = d / d.norm(dim=-1, keepdim=True)
        k = (sh_degree + 1) ** 2
        raw = (sh[:, :k, :] * sh_basis(dirs, sh_degree)[:, :, None]).sum(1)
        colours = torch.clamp_min(raw + 0.5, 0.0)
    return means2d, conics, z, colours, comp
