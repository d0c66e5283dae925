"""gsplat's rules as an option (issue 38, item 7): ``rules="gsplat"`` and
``verisplat.gsplat.rasterization``.

The yardstick is a dense rasterizer written here in torch (float64) from gsplat 1.5.3's
CUDA code, rule for rule: ``ProjectionEWA3DGSFused.cu`` (cull at ``z < near_plane``; the
guard band ``-(cx/fx + 0.3 tan) .. (W - cx)/fx + 0.3 tan``; eps2d 0.3; the antialiased
compensation ``sqrt(max(0, det / det_blur))``; cull below 1/255; the opacity-aware box
``ceil(min(3.33, sqrt(2 ln(255 o))) sqrt(cov_ii))`` and its image test) and
``RasterizeToPixels3DGSFwd.cu`` (pixel centres at +0.5, ``alpha = min(0.999, o exp(-s))``,
skip at ``s < 0`` or alpha < 1/255, end at ``T (1 - alpha) <= 1e-4``). It blends every
Gaussian at every pixel (no tiles): gsplat's box holds every pixel a splat reaches, so
tiles change nothing. Its gradients are torch autograd's.
"""

import math
import os

import numpy as np
import pytest

import verisplat
from verisplat import raster

if os.environ.get("VERISPLAT_REQUIRE_TORCH") == "1":
    import torch  # CI installs the torch extra: these tests must run there
    import gsplat.strategy as gs_strategy
else:
    torch = pytest.importorskip("torch")
    gs_strategy = pytest.importorskip("gsplat.strategy")

import verisplat.gsplat  # noqa: E402
from verisplat.torch import rasterization  # noqa: E402

from test_gsplat_dropin import splat_parameters  # noqa: E402
from test_torch import GROUPS, H, W, rel, scene  # noqa: E402

C0 = 0.28209479177387814
ALPHA_THRESHOLD = 1.0 / 255.0


def sh_colours(sh, dirs, degree):
    from verisplat._projection import sh_basis

    k = (degree + 1) ** 2
    raw = (sh[:, :k, :] * sh_basis(dirs, degree)[:, :, None]).sum(1)
    return torch.clamp_min(raw + 0.5, 0.0)


def gsplat_dense(means, quats, scales, opacities, sh, viewmat, K, width, height, degree,
                 near_plane=0.01, antialiased=False):
    """gsplat 1.5.3's rasterization of one camera, dense, in the inputs' dtype: colours
    [H, W, 3], alphas [H, W], radii [N, 2] (int)."""
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    mean_c = means @ R.T + t
    x, y, z = mean_c.unbind(-1)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    # quat_scale_to_covar_preci
    q = quats / quats.norm(dim=-1, keepdim=True)
    w_, x_, y_, z_ = q.unbind(-1)
    rot = torch.stack([
        1 - 2 * (y_ * y_ + z_ * z_), 2 * (x_ * y_ - w_ * z_), 2 * (x_ * z_ + w_ * y_),
        2 * (x_ * y_ + w_ * z_), 1 - 2 * (x_ * x_ + z_ * z_), 2 * (y_ * z_ - w_ * x_),
        2 * (x_ * z_ - w_ * y_), 2 * (y_ * z_ + w_ * x_), 1 - 2 * (x_ * x_ + y_ * y_),
    ], -1).reshape(-1, 3, 3)
    m = rot * scales[:, None, :]
    covar = m @ m.transpose(1, 2)
    covar_c = R @ covar @ R.T
    # persp_proj
    tan_fovx, tan_fovy = 0.5 * width / fx, 0.5 * height / fy
    lim_x_pos, lim_x_neg = (width - cx) / fx + 0.3 * tan_fovx, cx / fx + 0.3 * tan_fovx
    lim_y_pos, lim_y_neg = (height - cy) / fy + 0.3 * tan_fovy, cy / fy + 0.3 * tan_fovy
    rz = 1.0 / z
    tx = z * torch.minimum(lim_x_pos, torch.maximum(-lim_x_neg, x * rz))
    ty = z * torch.minimum(lim_y_pos, torch.maximum(-lim_y_neg, y * rz))
    zero = torch.zeros_like(z)
    J = torch.stack([
        torch.stack([fx * rz, zero, -fx * tx * rz * rz], -1),
        torch.stack([zero, fy * rz, -fy * ty * rz * rz], -1),
    ], 1)
    cov2d = J @ covar_c @ J.transpose(1, 2)
    mean2d = torch.stack([fx * x * rz + cx, fy * y * rz + cy], -1)
    # add_blur
    det_orig = cov2d[:, 0, 0] * cov2d[:, 1, 1] - cov2d[:, 0, 1] * cov2d[:, 1, 0]
    a, c = cov2d[:, 0, 0] + 0.3, cov2d[:, 1, 1] + 0.3
    b = cov2d[:, 0, 1]
    det = a * c - b * b
    comp = torch.sqrt(torch.clamp_min(det_orig / det, 0.0))
    conic = torch.stack([c / det, -b / det, a / det], -1)
    opac = opacities * comp if antialiased else opacities
    # The culls, and the box (non-differentiable).
    with torch.no_grad():
        extend = torch.clamp_max(torch.sqrt(2.0 * torch.log(opac / ALPHA_THRESHOLD)), 3.33)
        rx, ry = torch.ceil(extend * torch.sqrt(a)), torch.ceil(extend * torch.sqrt(c))
        keep = (z >= near_plane) & (det > 0) & (opac >= ALPHA_THRESHOLD)
        keep &= ~((rx <= 0) & (ry <= 0))
        keep &= ~((mean2d[:, 0] + rx <= 0) | (mean2d[:, 0] - rx >= width)
                  | (mean2d[:, 1] + ry <= 0) | (mean2d[:, 1] - ry >= height))
        radii = torch.where(keep[:, None], torch.stack([rx, ry], -1), 0.0).long()
    idx = torch.nonzero(keep).squeeze(1)
    idx = idx[torch.argsort(z[idx].detach(), stable=True)]
    centre = -(t @ R)
    d = means[idx] - centre
    rgb = sh_colours(sh[idx], d / d.norm(dim=-1, keepdim=True), degree)
    # RasterizeToPixels3DGSFwd: every Gaussian at every pixel, front to back.
    py, px = torch.meshgrid(torch.arange(height, dtype=means.dtype) + 0.5,
                            torch.arange(width, dtype=means.dtype) + 0.5, indexing="ij")
    dx = mean2d[idx, 0][None, None, :] - px[..., None]
    dy = mean2d[idx, 1][None, None, :] - py[..., None]
    A, B, Cc = (conic[idx, k][None, None, :] for k in range(3))
    sigma = 0.5 * (A * dx * dx + Cc * dy * dy) + B * dx * dy
    alpha = torch.minimum(torch.full_like(sigma, 0.999), opac[idx][None, None, :] * torch.exp(-sigma))
    active = (sigma >= 0) & (alpha >= ALPHA_THRESHOLD)
    alpha = torch.where(active, alpha, torch.zeros_like(alpha))
    T_before = torch.cumprod(torch.cat([torch.ones_like(alpha[..., :1]), 1 - alpha[..., :-1]], -1), -1)
    with torch.no_grad():
        stop = active & (T_before * (1 - alpha) <= 1e-4)
        stopped = torch.cumsum(stop.long(), -1) > 0
    w = torch.where(stopped, torch.zeros_like(alpha), alpha * T_before)
    colours = (w[..., None] * rgb[None, None, :, :]).sum(-2)
    return colours, w.sum(-1), radii


def near_scene(cam, n=150, seed=31):
    """A random scene, a few Gaussians between gsplat's near plane and the original's, and
    two centred beyond the sides of gsplat's guard band, large enough to reach the frame."""
    s = scene(n=n, seed=seed, degree=2)
    R, t = cam.viewmat[:3, :3], cam.viewmat[:3, 3]
    to_world = lambda v: (np.asarray(v) - t) @ R  # noqa: E731  R^T (v - t)
    fx, fy, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
    xn = cx / fx + 0.3 * 0.5 * W / fx
    yp = (H - cy) / fy + 0.3 * 0.5 * H / fy
    extra = [(0.004, 0.003, 0.06), (-0.01, 0.006, 0.12), (0.015, -0.008, 0.17),
             (-1.25 * xn * 3.0, 0.1, 3.0), (-0.2, 1.25 * yp * 3.4, 3.4)]
    scales = [0.002, 0.003, 0.004, 0.5, 0.5]
    rng = np.random.default_rng(seed + 1)
    for v, sc in zip(extra, scales):
        s["means"] = np.vstack([s["means"], to_world(v)[None].astype(np.float32)])
        s["quats"] = np.vstack([s["quats"], rng.normal(size=(1, 4)).astype(np.float32)])
        s["scales"] = np.vstack([s["scales"], np.full((1, 3), sc, np.float32)])
        s["opacities"] = np.append(s["opacities"], np.float32(0.8))
        s["colors"] = np.concatenate([s["colors"], (rng.normal(size=(1, 9, 3)) * 0.4).astype(np.float32)])
    return s


def off_centre_camera():
    cam = verisplat.look_at(eye=(0.3, -0.2, -4.0), target=(0, 0, 0), width=W, height=H)
    K = cam.K.copy()
    K[0, 2] += 9.0
    K[1, 2] -= 6.0
    return cam.viewmat, K


class _Cam:
    def __init__(self, viewmat, K):
        self.viewmat, self.K = viewmat, K


@pytest.mark.parametrize("mode", ["classic", "antialiased"])
def test_gsplat_rules_equal_gsplats_code_dense_in_torch(mode):
    aa = mode == "antialiased"
    viewmat, K = off_centre_camera()
    s = near_scene(_Cam(viewmat, K))
    t = {k: torch.tensor(v, requires_grad=True) for k, v in s.items()}
    vm, Ks = torch.tensor(viewmat)[None], torch.tensor(K)[None]
    out, alphas, meta = verisplat.gsplat.rasterization(
        *[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=2, packed=False, rasterize_mode=mode)
    rng = np.random.default_rng(7)
    wc = torch.tensor(rng.normal(size=out.shape).astype(np.float32))
    wa = torch.tensor(rng.normal(size=alphas.shape).astype(np.float32))
    ((out * wc).sum() + (alphas * wa).sum()).backward()
    # The same loss through gsplat's rules, dense, in float64.
    d = {k: torch.tensor(v, dtype=torch.float64, requires_grad=True) for k, v in s.items()}
    colours, alpha_img, radii = gsplat_dense(
        d["means"], d["quats"], d["scales"], d["opacities"], d["colors"],
        torch.tensor(viewmat, dtype=torch.float64), torch.tensor(K, dtype=torch.float64),
        W, H, 2, antialiased=aa)
    ((colours * wc[0].double()).sum() + (alpha_img * wa[0, ..., 0].double()).sum()).backward()
    worst = (out[0].detach().double() - colours.detach()).abs().max().item()
    assert worst < 1e-4, f"image: largest difference {worst:.2e}"
    assert (alpha_img.detach() - alphas[0, ..., 0].detach().double()).abs().max() < 1e-4
    for k in GROUPS:
        err = rel(t[k].grad.numpy(), d[k].grad.numpy())
        assert err <= 1e-3, f"{k}: relative L2 error {err:.2e} against gsplat's rules"
    # The near Gaussians show (the original would cull them) and the radii are gsplat's.
    n = len(s["means"])
    assert (radii[n - 5:n - 2] > 0).all()
    got = meta["radii"][0].numpy()
    assert (got > 0).any(axis=-1).sum() > 50
    np.testing.assert_array_equal(got, radii.numpy())


def test_the_f64_reference_takes_the_rules_too():
    viewmat, K = off_centre_camera()
    s = near_scene(_Cam(viewmat, K))
    ref = raster.Rasterizer(backend="reference")
    f = ref.forward(**s, viewmat=viewmat, K=K, width=W, height=H, sh_degree=2, rules="gsplat")
    d = {k: torch.tensor(v, dtype=torch.float64) for k, v in s.items()}
    colours, alpha_img, _ = gsplat_dense(
        d["means"], d["quats"], d["scales"], d["opacities"], d["colors"],
        torch.tensor(viewmat, dtype=torch.float64), torch.tensor(K, dtype=torch.float64), W, H, 2)
    assert np.abs(f.colors - colours.numpy()).max() < 1e-6
    orig = ref.forward(**s, viewmat=viewmat, K=K, width=W, height=H, sh_degree=2)
    assert np.abs(orig.colors - f.colors).max() > 0.05, "the rules change nothing here"
    near = ref.forward(**s, viewmat=viewmat, K=K, width=W, height=H, sh_degree=2,
                       rules="gsplat", near_plane=0.2)
    # gsplat's rules with the original's near plane: the near Gaussians go.
    assert np.abs(near.colors - f.colors).max() > 0.05


def test_rules_and_near_plane_arguments():
    s = scene(n=40, seed=3, degree=1)
    cam = verisplat.look_at(eye=(0.3, -0.2, -4.0), target=(0, 0, 0), width=W, height=H)
    t = {k: torch.tensor(v) for k, v in s.items()}
    args = [t[k] for k in GROUPS] + [torch.tensor(cam.viewmat)[None], torch.tensor(cam.K)[None], W, H]
    # gsplat's simple_trainer passes near_plane=0.01: accepted under either rules.
    a, _, _ = rasterization(*args, sh_degree=1, near_plane=0.01)
    b, _, _ = rasterization(*args, sh_degree=1, near_plane=0.01, rules="gsplat")
    c, _, _ = verisplat.gsplat.rasterization(*args, sh_degree=1)
    assert torch.equal(b, c)
    assert not torch.equal(a, b)
    for bad, match in [(dict(rules="inria2"), "rules"), (dict(near_plane=0.0), "near_plane"),
                       (dict(near_plane=-1.0), "near_plane"), (dict(near_plane=float("nan")), "near_plane")]:
        with pytest.raises(ValueError, match=match):
            rasterization(*args, sh_degree=1, **bad)
    with pytest.raises(ValueError, match="rules"):
        raster.Rasterizer().forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H,
                                    sh_degree=1, rules="other")


def test_gsplats_simple_trainer_loop_runs_with_only_the_import_changed():
    # simple_trainer.py's rasterize_splats call and its DefaultStrategy, through
    # verisplat.gsplat.rasterization: log scales, logit opacities, sh0/shN, near_plane=0.01.
    s = scene(n=300, seed=41, degree=1)
    cams = [verisplat.look_at(eye=(0.4 * i - 0.4, -0.2, -4.0), target=(0, 0, 0), width=W, height=H)
            for i in range(3)]
    target_scene = scene(n=300, seed=42, degree=1)
    tt = {k: torch.tensor(v) for k, v in target_scene.items()}
    Ks = torch.tensor(np.stack([c.K for c in cams]))
    camtoworlds = torch.linalg.inv(torch.tensor(np.stack([c.viewmat for c in cams])))
    targets, _, _ = verisplat.gsplat.rasterization(
        *[tt[k] for k in GROUPS], torch.linalg.inv(camtoworlds), Ks, W, H, sh_degree=1)
    splats = splat_parameters(s)
    optimizers = {k: torch.optim.Adam([v], lr=0.01) for k, v in splats.items()}
    strategy = gs_strategy.DefaultStrategy(refine_start_iter=10, refine_every=10, reset_every=1000,
                                           verbose=False)
    strategy.check_sanity(splats, optimizers)
    state = strategy.initialize_state()
    losses = []
    for step in range(40):
        i = step % 3
        colors, alphas, info = verisplat.gsplat.rasterization(
            means=splats["means"], quats=splats["quats"], scales=torch.exp(splats["scales"]),
            opacities=torch.sigmoid(splats["opacities"]),
            colors=torch.cat([splats["sh0"], splats["shN"]], 1),
            viewmats=torch.linalg.inv(camtoworlds[i:i + 1]), Ks=Ks[i:i + 1], width=W, height=H,
            packed=True, absgrad=False, sparse_grad=False, rasterize_mode="classic",
            distributed=False, camera_model="pinhole", with_ut=False, with_eval3d=False,
            sh_degree=1, near_plane=0.01, far_plane=1e10, render_mode="RGB+ED")
        assert info["radii"].shape[-1] == 2
        loss = (colors[..., :3] - targets[i:i + 1]).abs().mean()
        strategy.step_pre_backward(splats, optimizers, state, step, info)
        loss.backward()
        for opt in optimizers.values():
            opt.step()
            opt.zero_grad(set_to_none=True)
        strategy.step_post_backward(splats, optimizers, state, step, info, packed=True)
        losses.append(float(loss.detach()))
    assert math.isfinite(losses[-1]) and losses[-1] < 0.8 * losses[0], losses
    assert len(splats["means"]) != 300, "the strategy densified or pruned nothing"
