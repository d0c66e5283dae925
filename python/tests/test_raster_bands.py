"""A frame whose backward buffers pass one storage binding: 30,000 Gaussians at 1920x1080
through verisplat.raster make about 3.3 M (tile, Gaussian) pairs, whose 48-byte gradient
records (about 157 MB) exceed lavapipe's 128 MiB maxStorageBufferRange. The backward
refused this frame ("pair gradients needs 156520320 bytes in one storage buffer") while the
forward drew it; it now takes it in bands of pairs, bit-identical to one piece (the Rust
tests check that under emulated small bindings). Here: the gradients are finite, each group
has values, and a second pass gives the same bits."""

import numpy as np

import verisplat
from verisplat import raster

W, H = 1920, 1080
GROUPS = ["means", "quats", "scales", "opacities", "colors"]


def scene(n, seed):
    rng = np.random.default_rng(seed)
    return dict(
        means=rng.uniform(-1, 1, (n, 3)).astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
        scales=rng.uniform(0.04, 0.2, (n, 3)).astype(np.float32),
        opacities=rng.uniform(0.2, 0.95, n).astype(np.float32),
        colors=rng.uniform(0.05, 1.0, (n, 3)).astype(np.float32),
    )


def test_a_1080p_frame_whose_pair_gradients_pass_one_binding():
    s = scene(30_000, 61)
    cam = verisplat.look_at(eye=(0.3, -0.2, -4.0), target=(0, 0, 0), width=W, height=H)
    r = raster.Rasterizer()
    fwd = r.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H)
    assert fwd.colors.shape == (H, W, 3)
    rng = np.random.default_rng(62)
    gc = rng.normal(size=(H, W, 3)).astype(np.float32)
    g = r.backward(fwd, grad_colors=gc)
    stats = r.stats
    # More pair records than one binding holds: the backward ran in bands.
    assert stats["pairs"] * 48 > 128 << 20 and stats["backward_pair_bands"] >= 2, stats
    assert stats["backward_pixel_bands"] == 1, stats
    again = r.backward(fwd, grad_colors=gc)
    for k in GROUPS:
        assert np.isfinite(g[k]).all(), k
        assert np.abs(g[k]).sum() > 0, k
        assert g[k].tobytes() == again[k].tobytes(), k
