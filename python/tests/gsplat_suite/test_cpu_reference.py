"""The CPU stand-ins that let gsplat's torch reference run without CUDA (cpu_reference.py),
against gsplat's own pure-torch tile intersection and a brute-force compositor written
from RasterizeToIndices3DGS.cu's per-pixel loop."""

import math
import os

import pytest

if os.environ.get("VERISPLAT_REQUIRE_TORCH") == "1":
    import torch
    import gsplat.cuda._torch_impl as gs_impl
else:
    torch = pytest.importorskip("torch")
    gs_impl = pytest.importorskip("gsplat.cuda._torch_impl")

from gsplat_suite import cpu_reference  # noqa: E402

W, H, TILE = 26, 19, 4


def projected(cameras=2, n=70, seed=0):
    g = torch.Generator().manual_seed(seed)
    means = torch.rand(n, 3, generator=g) * torch.tensor([2.0, 2.0, 3.0]) \
        + torch.tensor([-1.0, -1.0, 0.5])
    quats = torch.randn(n, 4, generator=g)
    scales = torch.rand(n, 3, generator=g) * 0.15 + 0.01
    opacities = torch.rand(n, generator=g)
    colors = torch.rand(cameras, n, 3, generator=g)
    viewmats = torch.eye(4).repeat(cameras, 1, 1)
    viewmats[1:, 0, 3] = 0.2
    Ks = torch.tensor([[20.0, 0, W / 2], [0, 20.0, H / 2], [0, 0, 1]]).repeat(cameras, 1, 1)
    covars, _ = gs_impl._quat_scale_to_covar_preci(quats, scales, True, False, triu=False)
    radii, means2d, depths, conics, _ = gs_impl._fully_fused_projection(
        means, covars, viewmats, Ks, W, H)
    return radii, means2d, depths, conics, opacities.expand(cameras, n), colors


def brute_force(radii, means2d, depths, conics, opacities, colors):
    """Every pixel on its own: the Gaussians whose tile rectangle holds the pixel's tile,
    nearest first, composited with gsplat's skip and stop rules."""
    cams, n = depths.shape
    out = torch.zeros(cams, H, W, 3, dtype=torch.float64)
    acc = torch.zeros(cams, H, W, 1, dtype=torch.float64)
    for c in range(cams):
        order = sorted(range(n), key=lambda g: (depths[c, g].item(), g))
        rect = []
        for g in order:
            if (radii[c, g] <= 0).any():
                continue
            mx, my = (means2d[c, g] / TILE).tolist()
            rx, ry = (radii[c, g].float() / TILE).tolist()
            rect.append((g, math.floor(mx - rx), math.ceil(mx + rx),
                         math.floor(my - ry), math.ceil(my + ry)))
        for i in range(H):
            for j in range(W):
                t, colour = 1.0, [0.0, 0.0, 0.0]
                for g, x0, x1, y0, y1 in rect:
                    if not (x0 <= j // TILE < x1 and y0 <= i // TILE < y1):
                        continue
                    a, b, cc = conics[c, g].tolist()
                    dx = means2d[c, g, 0].item() - (j + 0.5)
                    dy = means2d[c, g, 1].item() - (i + 0.5)
                    sigma = 0.5 * (a * dx * dx + cc * dy * dy) + b * dx * dy
                    alpha = min(0.999, opacities[c, g].item() * math.exp(-sigma))
                    if sigma < 0 or alpha < 1 / 255:
                        continue
                    if t * (1 - alpha) <= 1e-4:
                        break
                    for k in range(3):
                        colour[k] += alpha * t * colors[c, g, k].item()
                    t *= 1 - alpha
                out[c, i, j] = torch.tensor(colour)
                acc[c, i, j, 0] = 1 - t
    return out, acc


def test_tiles_equal_gsplats_torch_intersection():
    radii, means2d, depths, _, _, _ = projected()
    tw, th = math.ceil(W / TILE), math.ceil(H / TILE)
    ours = cpu_reference.isect_tiles(means2d, radii, depths, TILE, tw, th)
    theirs = gs_impl._isect_tiles(means2d, radii, depths, TILE, tw, th)
    assert ours[1].numel() > 100
    for a, b in zip(ours, theirs):
        assert torch.equal(a.long(), b.long())


def test_gsplats_torch_compositor_with_the_stand_ins_is_the_brute_force_one(monkeypatch):
    """One pass over every batch of a tile (gsplat's reference restarts a pixel that
    stopped in an earlier call of batches, so only the single call is a plain compositor)."""
    import gsplat.cuda._wrapper as gs_wrapper

    monkeypatch.setattr(gs_wrapper, "rasterize_to_indices_in_range",
                        cpu_reference.rasterize_to_indices_in_range)
    monkeypatch.setattr(gs_impl, "accumulate", cpu_reference.accumulate)
    radii, means2d, depths, conics, opacities, colors = projected()
    tw, th = math.ceil(W / TILE), math.ceil(H / TILE)
    _, isect_ids, flatten_ids = cpu_reference.isect_tiles(means2d, radii, depths, TILE, tw, th)
    offsets = cpu_reference.isect_offset_encode(isect_ids, 2, tw, th).reshape(2, th, tw)
    assert (offsets.reshape(2, -1).diff(dim=1) > TILE * TILE).any(), "one batch per tile"
    got, got_alpha = gs_impl._rasterize_to_pixels(
        means2d, conics, colors, opacities, W, H, TILE, offsets, flatten_ids,
        batch_per_iter=100)
    want, want_alpha = brute_force(radii, means2d, depths, conics, opacities, colors)
    assert want_alpha.max() > 0.99 and (want_alpha == 0).any(), "a scene with both"
    torch.testing.assert_close(got.double(), want, rtol=0, atol=2e-5)
    torch.testing.assert_close(got_alpha.double(), want_alpha, rtol=0, atol=2e-5)


def test_spherical_harmonics_zero_the_masked_gaussians():
    dirs, coeffs = torch.randn(5, 3), torch.randn(5, 16, 3)
    masks = torch.tensor([True, False, True, False, True])
    out = cpu_reference.spherical_harmonics(3, dirs, coeffs, masks=masks)
    assert torch.equal(out[~masks], torch.zeros(2, 3))
    assert torch.equal(out[masks], gs_impl._spherical_harmonics(3, dirs, coeffs)[masks])
