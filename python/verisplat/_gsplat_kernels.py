"""gsplat 1.5.3's CUDA kernels that its strategies call outside ``rasterization``, in torch.

gsplat's ``MCMCStrategy`` (through ``gsplat.strategy.ops``) calls two of gsplat's own CUDA
kernels: ``compute_relocation`` (``relocate`` and ``sample_add``) and
``quat_scale_to_covar_preci`` (``inject_noise_to_position``). Without gsplat's CUDA build
(AMD, Intel, Apple, CPU-only machines) neither can load. These are the same formulas,
written from gsplat 1.5.3's CUDA sources (``RelocationCUDA.cu``,
``QuatScaleToCovarCUDA.cu`` and ``quat_to_rotmat`` in ``include/Utils.cuh``), as torch
operations: they run on any device torch runs on, and their gradients come from autograd
(gsplat's hand-written backward computes the same derivative; its ``triu`` backward halves
the off-diagonal cotangents, which is what autograd of the symmetric packing gives).

``gsplat.strategy.ops`` never calls any other kernel: ``DefaultStrategy`` (``duplicate``,
``split``, ``remove``, ``reset_opa``) is pure torch. ``fused_ssim``: the SSIM kernel of the
separate ``fused_ssim`` package, which ``simple_trainer.py``'s default loss imports.
"""

from __future__ import annotations

from typing import Optional, Tuple

import torch
from torch import Tensor

__all__ = ["compute_relocation", "fused_ssim", "quat_scale_to_covar_preci", "quat_to_rotmat"]

# The row and column of each entry of gsplat's upper-triangle packing, in its order
# (QuatScaleToCovarCUDA.cu writes covar[0][0], [0][1], [0][2], [1][1], [1][2], [2][2]).
TRIU_ROWS = (0, 0, 0, 1, 1, 2)
TRIU_COLS = (0, 1, 2, 1, 2, 2)


def compute_relocation(
    opacities: Tensor, scales: Tensor, ratios: Tensor, binoms: Tensor
) -> Tuple[Tensor, Tensor]:
    """``gsplat.relocation.compute_relocation`` (Equation 9 of "3D Gaussian Splatting as
    Markov Chain Monte Carlo"): a Gaussian of opacity ``o`` and scales ``s`` replaced by
    ``n`` copies (``ratios``, clamped to ``[1, n_max]``, ``n_max`` = ``binoms.shape[0]``)
    gets opacity ``o' = 1 - (1 - o)^(1/n)`` and scales ``s * o / d`` with
    ``d = sum_{i=1..n} sum_{k=0..i-1} binoms[i-1, k] (-1)^k / sqrt(k+1) o'^(k+1)``.

    Unlike gsplat's wrapper, ``ratios`` is not clamped in place (gsplat's callers pass a
    temporary, so nothing they see changes). Returns ``(new_opacities [N], new_scales [N, 3])``.
    """
    n_gauss = opacities.shape[0]
    n_max = binoms.shape[0]
    if binoms.dim() != 2 or binoms.shape[1] != n_max:
        raise ValueError(f"binoms must be [n_max, n_max], got {tuple(binoms.shape)}")
    if scales.shape != (n_gauss, 3):
        raise ValueError(f"scales must be [{n_gauss}, 3], got {tuple(scales.shape)}")
    if ratios.shape != (n_gauss,):
        raise ValueError(f"ratios must be [{n_gauss}], got {tuple(ratios.shape)}")
    n = ratios.clamp(min=1, max=n_max).long()
    new_opacities = 1.0 - (1.0 - opacities) ** (1.0 / n.to(opacities.dtype))
    # coeff[m, k] = sum over i = k+1 .. m of binoms[i-1, k]: the double sum's terms in k
    # for a Gaussian with n = m (the kernel's loop reads only k <= i-1).
    b = binoms.to(opacities.dtype)
    lower = torch.tril(torch.ones(n_max, n_max, dtype=torch.bool, device=b.device))
    b = torch.where(lower, b, torch.zeros_like(b))
    coeff = torch.cat([torch.zeros_like(b[:1]), torch.cumsum(b, dim=0)])  # [n_max+1, n_max]
    k = torch.arange(n_max, device=opacities.device, dtype=opacities.dtype)
    sign = 1.0 - 2.0 * torch.remainder(k, 2.0)  # (-1)^k
    terms = (sign / torch.sqrt(k + 1.0)) * new_opacities[:, None] ** (k + 1.0)  # [N, n_max]
    denom = (coeff.to(opacities.device)[n] * terms).sum(dim=1)
    new_scales = (opacities / denom)[:, None] * scales
    return new_opacities, new_scales


def quat_to_rotmat(quats: Tensor) -> Tensor:
    """gsplat's ``quat_to_rotmat``: the rotation of the normalised quaternion ``(w, x, y, z)``
    (not normalised on input). ``[..., 4]`` -> ``[..., 3, 3]``."""
    q = quats / torch.linalg.vector_norm(quats, dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]
    return torch.stack(rows, dim=-1).reshape(quats.shape[:-1] + (3, 3))


def quat_scale_to_covar_preci(
    quats: Tensor,
    scales: Tensor,
    compute_covar: bool = True,
    compute_preci: bool = True,
    triu: bool = False,
) -> Tuple[Optional[Tensor], Optional[Tensor]]:
    """``gsplat.quat_scale_to_covar_preci``: covariance ``R S S R^T`` and precision
    ``R S^-1 S^-1 R^T`` of quaternions ``[..., 4]`` (normalised here) and scales ``[..., 3]``;
    ``[..., 3, 3]`` each, or their upper triangles ``[..., 6]`` (row by row) with ``triu``.
    A result not asked for is None. Differentiable."""
    batch = quats.shape[:-1]
    if quats.shape[-1:] != (4,) or scales.shape != batch + (3,):
        raise ValueError(
            f"quats must be [..., 4] and scales [..., 3] with the same leading dimensions, "
            f"got {tuple(quats.shape)} and {tuple(scales.shape)}"
        )
    rot = quat_to_rotmat(quats)

    def product(diagonal: Tensor) -> Tensor:
        m = rot * diagonal[..., None, :]
        out = m @ m.transpose(-1, -2)
        return out[..., TRIU_ROWS, TRIU_COLS] if triu else out

    covars = product(scales) if compute_covar else None
    precis = product(1.0 / scales) if compute_preci else None
    return covars, precis


def _ssim_window(dtype: torch.dtype, device: torch.device) -> Tensor:
    x = torch.arange(11, dtype=torch.float64) - 5
    g = torch.exp(-(x**2) / (2 * 1.5**2))
    g = g / g.sum()
    return g.to(dtype=dtype, device=device)


def fused_ssim(img1: Tensor, img2: Tensor, padding: str = "same", train: bool = True) -> Tensor:
    """The ``fused_ssim`` package's SSIM (the CUDA/MPS/XPU kernel gsplat's
    ``simple_trainer.py`` imports for its SSIM loss) in torch, for machines it does not
    load on: images ``[B, C, H, W]``; per channel the 11x11 Gaussian window of sigma 1.5
    with zeros outside the image, ``C1 = 0.01^2``, ``C2 = 0.03^2``, the variances floored
    at 0, each pixel's SSIM clamped to [-1, 1]; the mean over the map (``"valid"``: without
    its 5-pixel border). The gradient flows to ``img1`` only, as the package's
    (``img2`` is the target). ``train`` is accepted and changes nothing here."""
    if padding not in ("same", "valid"):
        raise ValueError(f"padding must be 'same' or 'valid', got {padding!r}")
    if img1.dim() != 4 or img1.shape != img2.shape:
        raise ValueError(
            f"img1 and img2 must be [B, C, H, W] of one shape, got {tuple(img1.shape)} "
            f"and {tuple(img2.shape)}")
    del train
    img2 = img2.detach()
    channels = img1.shape[1]
    g = _ssim_window(img1.dtype, img1.device)
    rows = g.view(1, 1, 11, 1).expand(channels, 1, 11, 1)
    cols = g.view(1, 1, 1, 11).expand(channels, 1, 1, 11)

    def blur(x: Tensor) -> Tensor:
        x = torch.nn.functional.conv2d(x, rows, padding=(5, 0), groups=channels)
        return torch.nn.functional.conv2d(x, cols, padding=(0, 5), groups=channels)

    mu1, mu2 = blur(img1), blur(img2)
    sigma1 = (blur(img1 * img1) - mu1 * mu1).clamp(min=0)
    sigma2 = (blur(img2 * img2) - mu2 * mu2).clamp(min=0)
    sigma12 = blur(img1 * img2) - mu1 * mu2
    c1, c2 = 0.01**2, 0.03**2
    ssim = ((2 * mu1 * mu2 + c1) * (2 * sigma12 + c2)) / (
        (mu1 * mu1 + mu2 * mu2 + c1) * (sigma1 + sigma2 + c2))
    ssim = ssim.clamp(-1.0, 1.0)
    if padding == "valid":
        ssim = ssim[:, :, 5:-5, 5:-5]
    return ssim.mean()
