"""gsplat's lenses through verisplat.torch.rasterization (issue 49, part 6): camera_model
"pinhole", "ortho" and "fisheye", with_ut, radial_coeffs and tangential_coeffs, as gsplat
1.5.3 takes them, and the lens of verisplat.Camera and raster.Rasterizer.forward.

The yardsticks are gsplat's own: its torch projections (``gsplat.cuda._torch_impl``:
``_fully_fused_projection`` with ``camera_model="ortho"``, ``_fisheye_proj``), and its
unscented transform written out here in torch (float64) from ``Cameras.cuh`` (the sigma
points and weights of ``world_gaussian_sigma_points``, the perfect and OpenCV pinhole and
OpenCV fisheye models' ``camera_ray_to_image_point``, every sigma point valid) and
``ProjectionUT3DGSFused.cu`` (eps2d, the opacity-aware box), blended densely as
test_gsplat_rules.py does (RasterizeToPixels3DGSFwd.cu). Their CUDA kernels are not
installed here. The scenes sit inside the image, where gsplat's margin rule (a Gaussian
with any sigma point more than a tenth of the image outside it is culled) and verisplat's
(culled when all are) agree.
"""

import math
import os

import numpy as np
import pytest

import verisplat
from verisplat import raster

if os.environ.get("VERISPLAT_REQUIRE_TORCH") == "1":
    import torch  # CI installs the torch extra and gsplat: these tests must run there
    from gsplat.cuda import _torch_impl as gs_torch
else:
    torch = pytest.importorskip("torch")
    gs_torch = pytest.importorskip("gsplat.cuda._torch_impl")

from verisplat.torch import rasterization  # noqa: E402

from test_torch import GROUPS, H, W, cameras, rel, scene, tensors  # noqa: E402

ALPHA_THRESHOLD = 1.0 / 255.0
RADIAL = [0.08, -0.02, 0.004, 0.01, -0.003, 0.001]
TANGENTIAL = [0.002, -0.0015]
FISHEYE_K = [0.03, -0.006, 0.001, -0.0001]


def cam_tensors(cams, ortho=False):
    vm = torch.tensor(np.stack([c.viewmat for c in cams]))
    Ks = torch.tensor(np.stack([c.K for c in cams]))
    if ortho:
        # Orthographic: fx, fy in pixels per world unit (the scene spans about 2 units).
        Ks[:, 0, 0], Ks[:, 1, 1] = 18.0, 17.0
    return vm, Ks


def lens_kwargs(case, C):
    """rasterization's keywords of a lens case."""
    rep = lambda v: torch.tensor([v] * C, dtype=torch.float32)  # noqa: E731
    return {
        "ortho": dict(camera_model="ortho"),
        "ortho-ut": dict(camera_model="ortho", with_ut=True),
        "fisheye": dict(camera_model="fisheye"),
        "pinhole-ut": dict(with_ut=True),
        "opencv-ut": dict(with_ut=True, radial_coeffs=rep(RADIAL), tangential_coeffs=rep(TANGENTIAL)),
        "fisheye-ut": dict(camera_model="fisheye", with_ut=True),
        "fisheye-k-ut": dict(camera_model="fisheye", with_ut=True, radial_coeffs=rep(FISHEYE_K)),
    }[case]


def rotations(quats):
    q = quats / quats.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], -1).reshape(quats.shape[:-1] + (3, 3))


def gsplat_camera_point(model, p, K, width, height, radial=None, tangential=None, margin=0.1):
    """Cameras.cuh's camera_ray_to_image_point of camera-space points p [..., 3]: the
    pixel and whether it is valid."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    x, y, z = p.unbind(-1)
    valid = z > 0
    if model == "pinhole":
        u, v = x / z, y / z
        if radial is not None or tangential is not None:
            k = radial if radial is not None else [0.0] * 6
            t = tangential if tangential is not None else [0.0, 0.0]
            r2 = u * u + v * v
            icD = (1 + r2 * (k[0] + r2 * (k[1] + r2 * k[2]))) / (1 + r2 * (k[3] + r2 * (k[4] + r2 * k[5])))
            a1, a2, a3 = 2 * u * v, r2 + 2 * u * u, r2 + 2 * v * v
            du, dv = t[0] * a1 + t[1] * a2, t[0] * a3 + t[1] * a1
            valid = valid & (icD > 0.8)
            u, v = icD * u + du, icD * v + dv
    elif model == "fisheye":
        k = radial if radial is not None else [0.0] * 4
        norm = torch.sqrt(x * x + y * y).clamp_min(torch.finfo(p.dtype).eps)
        theta = torch.atan2(norm, z)
        t2 = theta * theta
        delta = theta * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])))) / norm
        valid = valid & (delta > 0)
        u, v = delta * x, delta * y
    elif model == "ortho":
        u, v = x, y
    px = torch.stack([fx * u + cx, fy * v + cy], -1)
    valid = valid & (px[..., 0] >= -margin * width) & (px[..., 0] <= (1 + margin) * width)
    valid = valid & (px[..., 1] >= -margin * height) & (px[..., 1] <= (1 + margin) * height)
    return px, valid


def gsplat_ut(means, quats, scales, viewmat, K, width, height, model, radial=None, tangential=None,
              alpha=0.1, beta=2.0, kappa=0.0):
    """gsplat's unscented transform (world_gaussian_to_image_gaussian_unscented_transform):
    2D means [N, 2], covariances [N, 2, 2], and whether every sigma point is valid."""
    D = 3
    lam = alpha * alpha * (D + kappa) - D
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    axes = rotations(quats) * scales[:, None, :]  # columns R[i] s_i
    delta = math.sqrt(D + lam) * axes.transpose(1, 2)  # [N, 3 (i), 3]
    pts = torch.cat([means[:, None], means[:, None] + delta, means[:, None] - delta], 1)
    cam = pts @ R.T + t
    px, valid = gsplat_camera_point(model, cam, K, width, height, radial, tangential)
    wm = torch.full((7,), 1 / (2 * (D + lam)), dtype=means.dtype)
    wc = wm.clone()
    wm[0] = lam / (D + lam)
    wc[0] = lam / (D + lam) + (1 - alpha * alpha + beta)
    mean = (wm[None, :, None] * px).sum(1)
    e = px - mean[:, None]
    cov = torch.einsum("j,nja,njb->nab", wc, e, e)
    return mean, cov, valid.all(-1), cam[:, 0]


def gsplat_finish(mean2d, cov2d, depth, opacities, width, height, near_plane=0.01, ut=True):
    """ProjectionUT3DGSFused.cu's (ut) or ProjectionEWA3DGSFused.cu's steps after the
    projection: eps2d, the conic, the culls and the opacity-aware box. Returns conics,
    radii [N, 2] and the kept mask."""
    a, b, c = cov2d[:, 0, 0] + 0.3, cov2d[:, 0, 1], cov2d[:, 1, 1] + 0.3
    det = a * c - b * b
    conic = torch.stack([c / det, -b / det, a / det], -1)
    with torch.no_grad():
        extend = torch.clamp_max(torch.sqrt(2.0 * torch.log(opacities / ALPHA_THRESHOLD)), 3.33)
        rx, ry = extend * torch.sqrt(a), extend * torch.sqrt(c)
        if ut:
            half = 0.5 * (a + c)
            r1 = extend * torch.sqrt(half + torch.sqrt(torch.clamp_min(half * half - det, 0.01)))
            rx, ry = torch.minimum(rx, r1), torch.minimum(ry, r1)
        rx, ry = torch.ceil(rx), torch.ceil(ry)
        keep = (depth >= near_plane) & (det > 0) & (opacities >= ALPHA_THRESHOLD)
        keep &= ~((mean2d[:, 0] + rx <= 0) | (mean2d[:, 0] - rx >= width)
                  | (mean2d[:, 1] + ry <= 0) | (mean2d[:, 1] - ry >= height))
        radii = torch.where(keep[:, None], torch.stack([rx, ry], -1), 0.0).long()
    return conic, radii, keep


def dense_blend(mean2d, conic, opacities, rgb, order, keep, width, height):
    """RasterizeToPixels3DGSFwd.cu at every pixel (gsplat's box cuts nothing): colours
    [H, W, 3] and alphas [H, W], front to back in ``order``'s ascending keys."""
    idx = torch.nonzero(keep).squeeze(1)
    idx = idx[torch.argsort(order[idx].detach(), stable=True)]
    py, px = torch.meshgrid(torch.arange(height, dtype=mean2d.dtype) + 0.5,
                            torch.arange(width, dtype=mean2d.dtype) + 0.5, indexing="ij")
    dx = mean2d[idx, 0][None, None, :] - px[..., None]
    dy = mean2d[idx, 1][None, None, :] - py[..., None]
    A, B, Cc = (conic[idx, k][None, None, :] for k in range(3))
    sigma = 0.5 * (A * dx * dx + Cc * dy * dy) + B * dx * dy
    alpha = torch.minimum(torch.full_like(sigma, 0.999), opacities[idx][None, None, :] * torch.exp(-sigma))
    active = (sigma >= 0) & (alpha >= ALPHA_THRESHOLD)
    alpha = torch.where(active, alpha, torch.zeros_like(alpha))
    T_before = torch.cumprod(torch.cat([torch.ones_like(alpha[..., :1]), 1 - alpha[..., :-1]], -1), -1)
    stop = active & (T_before * (1 - alpha) <= 1e-4)
    stopped = torch.cumsum(stop.long(), -1) > 0
    w = torch.where(stopped, torch.zeros_like(alpha), alpha * T_before)
    return (w[..., None] * rgb[idx][None, None, :, :]).sum(-2), w.sum(-1)


def sh_rgb(s, viewmat, degree):
    from verisplat._projection import sh_basis

    R, t = viewmat[:3, :3], viewmat[:3, 3]
    means = torch.tensor(s["means"], dtype=torch.float64)
    d = means + t @ R
    dirs = d / d.norm(dim=-1, keepdim=True)
    k = (degree + 1) ** 2
    sh = torch.tensor(s["colors"], dtype=torch.float64)[:, :k]
    return torch.clamp_min((sh * sh_basis(dirs, degree)[:, :, None]).sum(1) + 0.5, 0.0)


def f64(s, *keys):
    return [torch.tensor(s[k], dtype=torch.float64) for k in keys]


def ours(s, cams, case, degree=1, ortho=False):
    vm, Ks = cam_tensors(cams, ortho)
    t = tensors(s, grad=False)
    return rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=degree, packed=False,
                         rules="gsplat", **lens_kwargs(case, len(cams)))


# 1. gsplat's EWA rule (with_ut=False) through the orthographic lens (exact for a linear
# map, as the unscented transform with with_ut=True) and the fisheye (gsplat's linearised
# _fisheye_proj, drawn as given), against gsplat's torch projection and its blend.
@pytest.mark.parametrize("case", ["ortho", "ortho-ut", "fisheye"])
def test_ewa_lenses_equal_gsplats_torch_projection_and_its_picture(case):
    s = scene(n=120, seed=40, degree=1)
    cams = cameras(2)
    ortho = case.startswith("ortho")
    model = "ortho" if ortho else "fisheye"
    out, alphas, meta = ours(s, cams, case, ortho=ortho)
    vm, Ks = cam_tensors(cams, ortho=ortho)
    means, quats, scales, opac = f64(s, "means", "quats", "scales", "opacities")
    covars, _ = gs_torch._quat_scale_to_covar_preci(quats, scales, True, False, triu=False)
    radii, m2d, depths, conics, _ = gs_torch._fully_fused_projection(
        means, covars, vm.double(), Ks.double(), W, H, camera_model=model)
    worst = {"means2d": 0.0, "conics": 0.0, "image": 0.0}
    for c in range(2):
        vis = (meta["radii"][c, :, 0] > 0) & (radii[c, :, 0] > 0)
        assert int(vis.sum()) > 100
        worst["means2d"] = max(worst["means2d"], float((meta["means2d"][c, vis].double() - m2d[c, vis]).abs().max()))
        worst["conics"] = max(worst["conics"], rel(meta["conics"][c, vis], conics[c, vis]))
        assert torch.allclose(meta["depths"][c, vis].double(), depths[c, vis], rtol=1e-6)
        # gsplat's projection's covariance, its culls and box (the EWA path's), blended.
        proj = gs_torch._ortho_proj if ortho else gs_torch._fisheye_proj
        _, cov2d = proj(*(x[None] for x in (
            (means @ vm[c, :3, :3].double().T + vm[c, :3, 3].double()),
            vm[c, :3, :3].double() @ covars @ vm[c, :3, :3].double().T, Ks[c].double())), W, H)
        conic, _, keep = gsplat_finish(m2d[c], cov2d[0], depths[c], opac, W, H, ut=False)
        rgb, alpha = dense_blend(m2d[c], conic, opac, sh_rgb(s, vm[c].double(), 1), depths[c], keep, W, H)
        worst["image"] = max(worst["image"], float((out[c].double() - rgb).abs().max()),
                             float((alphas[c, ..., 0].double() - alpha).abs().max()))
    # Measured: means2d 3.3e-6 px, conics 2.1e-7 (relative L2), image 4.8e-7 (orthographic);
    # 3.4e-6 px, 2.3e-7, 7.8e-7 (fisheye).
    assert worst["means2d"] <= 1e-4 and worst["conics"] <= 1e-5 and worst["image"] <= 1e-4, worst


def test_linearised_fisheye_meta_packed_or_not_and_its_losses():
    s = scene(n=80, seed=51, degree=1)
    cams = cameras(2)
    vm, Ks = cam_tensors(cams)
    t = tensors(s)
    out_u, _, mu = rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=1,
                                 camera_model="fisheye", packed=False)
    out_p, _, mp = rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=1,
                                 camera_model="fisheye")
    assert torch.equal(out_u, out_p)
    c, g = mp["camera_ids"], mp["gaussian_ids"]
    assert len(g) == int((mu["radii"][..., 0] > 0).sum()) > 100
    for key in ("means2d", "depths", "conics", "opacities", "radii"):
        assert torch.equal(mp[key].detach(), mu[key].detach()[c, g]), key
    # A loss on meta reaches the Gaussians through gsplat's projection in torch.
    (mp["means2d"].sum() + mp["depths"].sum() + mp["conics"].sum()).backward()
    assert t["means"].grad.abs().sum() > 0 and t["scales"].grad.abs().sum() > 0


def test_linearised_fisheye_culls_gaussians_at_and_behind_the_camera():
    s = scene(n=40, seed=52, degree=1)
    cams = cameras(1)
    vm, Ks = cam_tensors(cams)
    centre = -(vm[0, :3, :3].T @ vm[0, :3, 3])
    s["means"][0] = centre.numpy()
    s["means"][1] = (centre - vm[0, 2, :3]).numpy()  # one unit behind
    t = tensors(s)
    _, _, meta = rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=1,
                               camera_model="fisheye", packed=False)
    assert (meta["radii"][0, :2] == 0).all() and (meta["radii"][0, 2:, 0] > 0).sum() > 20
    (meta["means2d"].sum() + meta["conics"].sum() + meta["depths"].sum()).backward()
    assert all(bool(torch.isfinite(t[k].grad).all()) for k in ("means", "quats", "scales"))


# 2. The unscented transform through gsplat's camera models, and the picture.
@pytest.mark.parametrize("case", ["pinhole-ut", "opencv-ut", "fisheye-ut", "fisheye-k-ut"])
def test_unscented_transform_equals_gsplats_and_its_picture(case):
    s = scene(n=120, seed=41, degree=1)
    cams = cameras(2)
    out, alphas, meta = ours(s, cams, case)
    vm, Ks = cam_tensors(cams)
    kw = lens_kwargs(case, 2)
    model = kw.get("camera_model", "pinhole")
    radial = RADIAL if case == "opencv-ut" else FISHEYE_K if case == "fisheye-k-ut" else None
    tangential = TANGENTIAL if case == "opencv-ut" else None
    means, quats, scales, opac = f64(s, "means", "quats", "scales", "opacities")
    worst = {"means2d": 0.0, "conics": 0.0, "image": 0.0}
    for c in range(2):
        m2d, cov2d, valid, mean_c = gsplat_ut(means, quats, scales, vm[c].double(), Ks[c].double(),
                                              W, H, model, radial, tangential)
        conic, radii, keep = gsplat_finish(m2d, cov2d, mean_c[:, 2], opac, W, H)
        keep &= valid
        vis = (meta["radii"][c, :, 0] > 0) & keep
        assert int(vis.sum()) > 100 and torch.equal(meta["radii"][c, :, 0] > 0, keep)
        worst["means2d"] = max(worst["means2d"], float((meta["means2d"][c, vis].double() - m2d[vis]).abs().max()))
        worst["conics"] = max(worst["conics"], rel(meta["conics"][c, vis], conic[vis]))
        # The depth: z, or through a fisheye the distance from the camera (a difference).
        depth = mean_c.norm(dim=-1) if model == "fisheye" else mean_c[:, 2]
        assert torch.allclose(meta["depths"][c, vis].double(), depth[vis], rtol=1e-6)
        rgb, alpha = dense_blend(m2d, conic, opac, sh_rgb(s, vm[c].double(), 1), depth, keep, W, H)
        diff = torch.cat([(out[c].double() - rgb).abs().ravel(),
                          (alphas[c, ..., 0].double() - alpha).abs().ravel()])
        worst["image"] = max(worst["image"], float(diff.max()))
        worst["mean"] = max(worst.get("mean", 0.0), float(diff.mean()))
    # Measured (f32 against f64): means2d 4.0e-5 (pinhole), 3.1e-4 (OpenCV), 9.6e-5 (fisheye)
    # px; conics 1.4e-6 to 2.4e-5; image 1.5e-5 to 9.4e-5, 3.1e-3 at one pixel of the
    # distorted fisheye (mean 2e-6).
    # A splat whose alpha crosses 1/255 between f32 and f64 moves a pixel by up to 1/255.
    assert worst["means2d"] <= 1e-3 and worst["conics"] <= 1e-4, worst
    assert worst["image"] <= 1.5 / 255 and worst["mean"] <= 1e-5, worst


# 3. Small Gaussians: the unscented transform tends to gsplat's linearised projections
# (its torch _fisheye_proj and _persp_proj), which checks the lens's conventions (the
# fisheye's fx theta x / r + cx, K) against gsplat's own functions.
@pytest.mark.parametrize("case, proj", [("fisheye-ut", "_fisheye_proj"), ("pinhole-ut", "_persp_proj")])
def test_small_gaussians_tend_to_gsplats_linearised_projection(case, proj):
    s = scene(n=80, seed=42, degree=1)
    s["scales"] = (s["scales"] * 0.02).astype(np.float32)
    cams = cameras(1)
    _, _, meta = ours(s, cams, case)
    vm, Ks = cam_tensors(cams)
    means, quats, scales = f64(s, "means", "quats", "scales")
    covars, _ = gs_torch._quat_scale_to_covar_preci(quats, scales, True, False, triu=False)
    R, t = vm[0, :3, :3].double(), vm[0, :3, 3].double()
    m2d, cov2d = getattr(gs_torch, proj)((means @ R.T + t)[None], (R @ covars @ R.T)[None],
                                          Ks[:1].double(), W, H)
    vis = meta["radii"][0, :, 0] > 0
    a, b, c = (cov2d[0, :, i, j] + (0.3 if i == j else 0.0) for i, j in ((0, 0), (0, 1), (1, 1)))
    det = a * c - b * b
    conic = torch.stack([c / det, -b / det, a / det], -1)
    d_mean = float((meta["means2d"][0, vis].double() - m2d[0, vis]).abs().max())
    d_conic = rel(meta["conics"][0, vis], conic[vis])
    # Measured: 1.2e-4 px and 1.7e-7 (fisheye), 5.8e-5 px and 3.1e-7 (pinhole).
    assert int(vis.sum()) > 60 and d_mean <= 1e-3 and d_conic <= 1e-4, (d_mean, d_conic)


# 4. The torch projection that chains the gradients of meta losses and cameras follows the
# renderer's through each lens.
@pytest.mark.parametrize("case", ["ortho", "opencv-ut", "fisheye-k-ut"])
def test_the_torch_projection_through_a_lens_equals_the_renderers(case):
    from verisplat import _projection
    from verisplat.torch import _lenses

    s = scene(n=100, seed=43, degree=2)
    cams = cameras(1)
    ortho = case.startswith("ortho")
    _, _, meta = ours(s, cams, case, degree=2, ortho=ortho)
    vm, Ks = cam_tensors(cams, ortho)
    kw = lens_kwargs(case, 1)
    layout = type("L", (), {"batch": (), "B": 1, "C": 1})()
    lens = _lenses(layout, kw.get("camera_model", "pinhole"), kw.get("with_ut", False),
                   kw.get("radial_coeffs"), kw.get("tangential_coeffs"))[0][0]
    vis = meta["radii"][0, :, 0] > 0
    t = tensors(s, grad=False)
    m2d, conic, depth, _, _ = _projection.project(
        t["means"][vis], t["quats"][vis], t["scales"][vis], vm[0], Ks[0], W, H, rules="gsplat",
        lens=lens)
    # The device's f32 against float64 here: measured 2.7e-4 px and 2.4e-5 at most.
    assert float((m2d - meta["means2d"][0, vis]).abs().max()) <= 2e-3
    assert rel(conic, meta["conics"][0, vis]) <= 2e-4
    assert torch.allclose(depth, meta["depths"][0, vis], rtol=1e-6)


# 5. Losses on meta through a lens reach the Gaussians (the torch projection), against
# finite differences of the device's forward pass.
@pytest.mark.parametrize("case", ["ortho", "fisheye-k-ut"])
def test_meta_losses_through_a_lens_reach_the_gaussians(case):
    s = scene(n=60, seed=44, degree=1)
    cams = cameras(1)
    ortho = case == "ortho"
    vm, Ks = cam_tensors(cams, ortho)
    kw = lens_kwargs(case, 1)
    t = tensors(s)
    _, _, meta = rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=1, packed=False,
                               **kw)
    visible = meta["radii"][0, :, 0] > 0

    def loss_of(m):
        v = visible
        return (1e-3 * (m["means2d"][0, v].double() ** 2).sum() + m["depths"][0, v].double().sum()
                + 10 * m["conics"][0, v].double().sum())

    loss_of(meta).backward()
    rng = np.random.default_rng(44)
    for k in ("means", "quats", "scales"):
        analytic, numeric = [], []
        for _ in range(3):
            d = rng.normal(size=s[k].shape)
            eps = 1e-3
            f = []
            for sign in (1, -1):
                moved = dict(s, **{k: (s[k] + sign * eps * d).astype(np.float32)})
                tm = tensors(moved, grad=False)
                m = rasterization(*[tm[g] for g in GROUPS], vm, Ks, W, H, sh_degree=1,
                                  packed=False, **kw)[2]
                f.append(float(loss_of(m)))
            numeric.append((f[0] - f[1]) / (2 * eps))
            analytic.append(float((t[k].grad.double().numpy() * d).sum()))
        err = rel(analytic, numeric)
        # Measured: <= 4e-4 (central differences of the f32 forward pass).
        assert err <= 3e-3, f"{k}: relative error {err:.2e} against finite differences"


# 6. The lens in the numpy API and in camera files.
def test_the_numpy_rasterizer_takes_a_lens_and_equals_the_torch_function():
    s = scene(n=80, seed=45, degree=1)
    cams = cameras(1)
    out, alphas, meta = ours(s, cams, "fisheye-k-ut")
    lens = {"kind": "fisheye", "k": FISHEYE_K, "max_theta": math.pi / 2}
    f = raster.Rasterizer().forward(**s, viewmat=cams[0].viewmat, K=cams[0].K, width=W, height=H,
                                    sh_degree=1, rules="gsplat", lens=lens)
    assert np.array_equal(f.colors, out[0].numpy()) and np.array_equal(f.alphas, alphas[0, ..., 0].numpy())
    assert np.array_equal(f.means2d, meta["means2d"][0].numpy())
    # The f64 reference draws the same lens.
    ref = raster.Rasterizer(backend="reference").forward(
        **s, viewmat=cams[0].viewmat, K=cams[0].K, width=W, height=H, sh_degree=1, rules="gsplat",
        lens=lens)
    assert np.abs(ref.colors - f.colors).max() <= 1e-4


def test_a_cameras_lens_round_trips_through_camera_files(tmp_path):
    base = cameras(1)[0]
    lenses = [
        None,
        {"kind": "distorted", "radial": RADIAL, "tangential": TANGENTIAL},
        {"kind": "fisheye", "k": FISHEYE_K, "max_theta": 1.2},
        {"kind": "orthographic"},
        {"kind": "equirectangular", "longitude": [-1.0, 0.5], "latitude": [0.6, -0.4]},
    ]
    cams = [verisplat.Camera(base.viewmat, base.K, W, H, f"c{i}", lens) for i, lens in enumerate(lenses)]
    verisplat.save_cameras(tmp_path / "cameras.json", cams)
    back = verisplat.load_cameras(tmp_path / "cameras.json")
    assert [c.lens for c in back] == lenses
    fish = verisplat.Camera(base.viewmat, base.K, W, H, lens={"kind": "fisheye", "k": [0, 0, 0, 0]})
    assert fish.lens == {"kind": "fisheye", "k": [0.0] * 4}
    assert verisplat.Camera(base.viewmat, base.K, W, H, lens="orthographic").lens == {"kind": "orthographic"}


def test_the_renderer_draws_a_cameras_lens_as_the_cpu_reference(demo, renderer):
    cam = verisplat.default_camera(demo, 96, 64)
    fish = verisplat.Camera(cam.viewmat, cam.K, 96, 64, lens={"kind": "fisheye", "k": FISHEYE_K})
    gpu = renderer.render(demo, fish)["rgb"]
    cpu = verisplat.render_cpu(demo, fish)["rgb"]
    pin = renderer.render(demo, cam)["rgb"]
    assert np.abs(gpu.astype(np.float64) - cpu).max() <= 2e-3
    assert np.abs(gpu.astype(np.float64) - pin).max() > 0.05


# 7. Refusals: a sentence, never a wrong picture.
@pytest.mark.parametrize("kw, match", [
    (dict(camera_model="fisheye", radial_coeffs=torch.zeros(2, 4)), "radial_coeffs need with_ut=True"),
    (dict(camera_model="ftheta", with_ut=True), "camera_model='ftheta' is not supported"),
    (dict(camera_model="spherical"), "camera_model must be 'pinhole', 'ortho' or 'fisheye'"),
    (dict(radial_coeffs=torch.zeros(2, 6)), "radial_coeffs need with_ut=True"),
    (dict(tangential_coeffs=torch.zeros(2, 2)), "tangential_coeffs need with_ut=True"),
    (dict(with_ut=True, radial_coeffs=torch.zeros(2, 4)), r"must have shape \(2, 6\) \(k1..k6\)"),
    (dict(camera_model="fisheye", with_ut=True, radial_coeffs=torch.zeros(2, 6)),
     r"must have shape \(2, 4\) \(k1..k4\)"),
    (dict(camera_model="fisheye", with_ut=True, tangential_coeffs=torch.zeros(2, 2)),
     "fisheye .* has no tangential distortion"),
    (dict(camera_model="ortho", with_ut=True, radial_coeffs=torch.zeros(2, 6)),
     "camera_model='ortho' has no distortion"),
    (dict(with_ut=True, radial_coeffs=torch.zeros(1, 6)), r"must have shape \(2, N\)"),
    (dict(with_ut=True, tangential_coeffs=torch.zeros(2, 3)), r"must have shape \(2, 2\)"),
    (dict(with_ut=True, radial_coeffs=torch.zeros(2, 6, dtype=torch.float64)), "must be float32"),
    (dict(with_ut=True, radial_coeffs=torch.full((2, 6), float("nan"))), "NaN"),
    (dict(with_ut=True, thin_prism_coeffs=torch.zeros(2, 4)), "thin_prism_coeffs are not supported"),
    (dict(with_ut=True, with_eval3d=True), "with_eval3d is not supported"),
])
def test_bad_lens_arguments_are_sentences(kw, match):
    s = scene(n=10, seed=46, degree=1)
    vm, Ks = cam_tensors(cameras(2))
    t = tensors(s, grad=False)
    with pytest.raises(ValueError, match=match):
        rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=1, **kw)


@pytest.mark.parametrize("lens, match", [
    ({"kind": "fisheye", "k": [0.1, 0.0]}, r"'k' must hold 4 numbers, got 2"),
    ({"kind": "distorted", "radial": [0.1] * 6, "tangent": [0, 0]}, "unknown: tangent"),
    ({"kind": "barrel"}, "lens kind 'barrel' is unknown"),
    ({"kind": "fisheye", "k": [0.0] * 4, "max_theta": 4.0}, "field of view must be above 0 and at most 360"),
    ({"kind": "distorted"}, "needs 'radial'"),
    ({"kind": "equirectangular", "longitude": [0.0, 0.0]}, "spans 0 degrees of longitude"),
])
def test_bad_camera_lenses_are_sentences(lens, match):
    base = cameras(1)[0]
    with pytest.raises(ValueError, match=match):
        verisplat.Camera(base.viewmat, base.K, W, H, lens=lens)


# 8. Gradients through a lens: the device's backward pass against the f64 reference's, and
# torch's against the reference's backward pass (Gaussians) and its central differences
# (cameras); the linearised fisheye's against autograd of gsplat's picture.
@pytest.mark.parametrize("case", ["opencv-ut", "fisheye-k-ut", "ortho"])
def test_device_gradients_through_a_lens_equal_the_reference(case):
    s = scene(n=100, seed=47, degree=2)
    cam = cameras(1)[0]
    lens = {"opencv-ut": {"kind": "distorted", "radial": RADIAL, "tangential": TANGENTIAL},
            "fisheye-k-ut": {"kind": "fisheye", "k": FISHEYE_K, "max_theta": math.pi / 2},
            "ortho": "orthographic"}[case]
    K = cam.K.copy()
    if case == "ortho":
        K[0, 0], K[1, 1] = 18.0, 17.0
    grads = {}
    for backend in ("reference", "vulkan"):
        r = raster.Rasterizer(backend=backend)
        f = r.forward(**s, viewmat=cam.viewmat, K=K, width=W, height=H, sh_degree=2, lens=lens)
        wc = np.random.default_rng(1).normal(size=f.colors.shape)
        wa = np.random.default_rng(2).normal(size=f.alphas.shape)
        grads[backend] = r.backward(f, grad_colors=wc, grad_alphas=wa)
    for k in GROUPS:
        err = rel(grads["vulkan"][k], grads["reference"][k])
        # Measured: <= 1.3e-5 (OPENCV means), 6e-7 to 4e-6 elsewhere.
        assert err <= 1e-3, f"{k}: relative L2 error {err:.2e} against the reference"


@pytest.mark.parametrize("case", ["opencv-ut", "fisheye-k-ut"])
def test_torch_gradients_through_a_lens_equal_the_reference_and_finite_differences(case):
    s = scene(n=60, seed=48, degree=1)
    cams = cameras(1)
    vm, Ks = cam_tensors(cams)
    vm.requires_grad_()
    Ks.requires_grad_()
    t = tensors(s)
    out, alphas, _ = rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=1,
                                   **lens_kwargs(case, 1))
    g = torch.Generator().manual_seed(48)
    wc = torch.randn(out.shape, generator=g)
    wa = torch.randn(alphas.shape, generator=g)
    ((out * wc).sum() + (alphas * wa).sum()).backward()
    wc, wa = wc[0].double().numpy(), wa[0, ..., 0].double().numpy()
    lens = {"opencv-ut": {"kind": "distorted", "radial": RADIAL, "tangential": TANGENTIAL},
            "fisheye-k-ut": {"kind": "fisheye", "k": FISHEYE_K, "max_theta": math.pi / 2}}[case]
    ref = raster.Rasterizer(backend="reference")

    def loss(viewmat, K):
        f = ref.forward(**s, viewmat=viewmat, K=K, width=W, height=H, sh_degree=1, lens=lens)
        return float((f.colors * wc).sum() + (f.alphas * wa).sum()), f

    vms, ks = vm.detach().numpy().astype(np.float64)[0], Ks.detach().numpy().astype(np.float64)[0]
    # The Gaussians: against the f64 reference's backward pass.
    grads = ref.backward(loss(vms, ks)[1], grad_colors=wc, grad_alphas=wa)
    for k in GROUPS:
        err = rel(t[k].grad.numpy(), grads[k])
        # Measured: <= 2.4e-6.
        assert err <= 1e-3, f"{k}: relative L2 error {err:.2e} against the reference"
    # The camera: against central differences of the reference (as test_gsplat_dropin's).
    analytic, numeric = [], []
    for which, i, j in [("vm", i, j) for i in range(3) for j in range(4)] + [
            ("K", 0, 0), ("K", 1, 1), ("K", 0, 2), ("K", 1, 2)]:
        base = vms if which == "vm" else ks
        x = base[i, j]
        estimates = []
        for e in (2e-7, 5e-7, 1e-6):
            eps = e * max(1.0, abs(x))
            hi, lo = base.copy(), base.copy()
            # The renderer takes f32 cameras: divide by the step they hold.
            hi[i, j], lo[i, j] = np.float32(x + eps), np.float32(x - eps)
            step = float(np.float32(x + eps)) - float(np.float32(x - eps))
            pair = (lambda m: (m, ks)) if which == "vm" else (lambda m: (vms, m))
            estimates.append((loss(*pair(hi))[0] - loss(*pair(lo))[0]) / step)
        numeric.append(float(np.median(estimates)))
        analytic.append(float((vm.grad if which == "vm" else Ks.grad)[0, i, j]))
    err = rel(analytic, numeric)
    # Measured: <= 2.4e-6.
    assert err <= 1e-3, f"camera gradients: relative L2 error {err:.2e} against finite differences"
    assert np.abs(numeric).max() > 1.0


@pytest.mark.parametrize("mode", ["classic", "antialiased"])
def test_linearised_fisheye_gradients_equal_autograd_of_gsplats_picture(mode):
    # gsplat's linearised fisheye (with_ut=False): its picture written in torch (float64,
    # _fisheye_proj, the EWA culls and box, the dense blend) differentiated by autograd,
    # against verisplat's (the device's backward pass of the 2D Gaussians it draws, chained
    # in torch through the same projection), for the Gaussians and the cameras.
    aa = mode == "antialiased"
    s = scene(n=60, seed=50, degree=1)
    cams = cameras(2)
    vm, Ks = cam_tensors(cams)
    vm.requires_grad_()
    Ks.requires_grad_()
    t = tensors(s)
    out, alphas, _ = rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=1,
                                   camera_model="fisheye", rules="gsplat", rasterize_mode=mode)
    g = torch.Generator().manual_seed(50)
    wc = torch.randn(out.shape, generator=g, dtype=torch.float64)
    wa = torch.randn(alphas.shape[:-1], generator=g, dtype=torch.float64)
    ((out * wc).sum() + (alphas[..., 0] * wa).sum()).backward()
    leaves = {k: torch.tensor(s[k], dtype=torch.float64, requires_grad=True) for k in GROUPS}
    vm64 = vm.detach().double().requires_grad_()
    K64 = Ks.detach().double().requires_grad_()
    from verisplat._projection import sh_basis

    total = 0.0
    for c in range(2):
        R, tr = vm64[c, :3, :3], vm64[c, :3, 3]
        covars, _ = gs_torch._quat_scale_to_covar_preci(leaves["quats"], leaves["scales"], True,
                                                        False, triu=False)
        mean_c = leaves["means"] @ R.T + tr
        m2d, cov2d = gs_torch._fisheye_proj(mean_c[None], (R @ covars @ R.T)[None], K64[c:c + 1], W, H)
        opac = leaves["opacities"]
        if aa:
            cv = cov2d[0]
            det0 = cv[:, 0, 0] * cv[:, 1, 1] - cv[:, 0, 1] ** 2
            det = (cv[:, 0, 0] + 0.3) * (cv[:, 1, 1] + 0.3) - cv[:, 0, 1] ** 2
            opac = opac * torch.sqrt(torch.clamp_min(det0 / det, 0.0))
        conic, _, keep = gsplat_finish(m2d[0], cov2d[0], mean_c[:, 2], opac, W, H, ut=False)
        d = leaves["means"] + tr @ R
        dirs = d / d.norm(dim=-1, keepdim=True)
        rgb = torch.clamp_min((leaves["colors"][:, :4] * sh_basis(dirs, 1)[:, :, None]).sum(1) + 0.5, 0.0)
        img, alpha = dense_blend(m2d[0], conic, opac, rgb, mean_c[:, 2], keep, W, H)
        total = total + (img * wc[c]).sum() + (alpha * wa[c]).sum()
    total.backward()
    # Measured: <= 1.1e-6 (Gaussians and cameras, both modes).
    for k in GROUPS:
        err = rel(t[k].grad.numpy(), leaves[k].grad.numpy())
        assert err <= 1e-3, f"{k}: relative L2 error {err:.2e} against autograd of gsplat's picture"
    for name, ours_g, ref_g in (("viewmats", vm.grad, vm64.grad), ("Ks", Ks.grad, K64.grad)):
        mask = ref_g != 0
        err = rel(ours_g[mask].numpy(), ref_g[mask].numpy())
        assert err <= 1e-3, f"{name}: relative L2 error {err:.2e} against autograd of gsplat's picture"


# 9. The chain rule the torch function applies through a lens (camera gradients, and meta
# losses), from the projected quantities' gradients: the f64 reference's backward pass
# gives those (its own chain through the sigma points, cpu/backward/lens.rs), and the torch
# unscented transform carried them to the Gaussians and the camera must agree with it and
# with central differences of the reference.
REFERENCE_LENSES = {
    "opencv-ut": {"kind": "distorted", "radial": RADIAL, "tangential": TANGENTIAL},
    "fisheye-k-ut": {"kind": "fisheye", "k": FISHEYE_K, "max_theta": math.pi / 2},
    "ortho": {"kind": "orthographic"},
}


@pytest.mark.parametrize("case", list(REFERENCE_LENSES))
def test_the_torch_lens_projection_chains_the_references_gradients(case):
    from verisplat import _projection

    s = scene(n=60, seed=49, degree=2)
    cam = cameras(1)[0]
    lens = REFERENCE_LENSES[case]
    ortho = case == "ortho"
    vm0, K0 = (x[0].double().numpy() for x in cam_tensors([cam], ortho))
    ref = raster.Rasterizer(backend="reference")
    rng = np.random.default_rng(49)
    wc, wa = rng.normal(size=(H, W, 3)), rng.normal(size=(H, W))

    def loss(params, viewmat, K):
        f = ref.forward(**params, viewmat=viewmat, K=K, width=W, height=H, sh_degree=2, lens=lens)
        return float((f.colors * wc).sum() + (f.alphas * wa).sum()), f

    _, f = loss(s, vm0, K0)
    g = ref.backward(f, grad_colors=wc, grad_alphas=wa, screen=True)
    touched = (np.abs(g["screen"]).sum(1) + np.abs(g["means2d"]).sum(1)) > 0
    assert touched.sum() > 30
    leaves = {k: torch.tensor(s[k][touched], dtype=torch.float64, requires_grad=True)
              for k in ("means", "quats", "scales", "colors")}
    vm = torch.tensor(vm0, requires_grad=True)
    K = torch.tensor(K0, requires_grad=True)
    m2d, conic, depth, rgb, _ = _projection.project(
        leaves["means"], leaves["quats"], leaves["scales"], vm, K, W, H, leaves["colors"], 2,
        lens=lens)
    gs = torch.tensor(g["screen"][touched])
    chained = ((torch.tensor(g["means2d"][touched]) * m2d).sum() + (gs[:, 0:3] * conic).sum()
               + (gs[:, 3:6] * rgb).sum() + (gs[:, 6] * depth).sum())
    chained.backward()
    # The Gaussians: the torch chain against the reference's own.
    for k in ("means", "quats", "scales"):
        err = rel(leaves[k].grad.numpy(), g[k][touched])
        # Measured: <= 1.3e-8 (two f64 chain rules from f32 parameters).
        assert err <= 1e-6, f"{k}: relative L2 error {err:.2e} against the reference's chain"
    # The camera: against central differences of the reference.
    analytic, numeric = [], []
    for which, i, j in [("vm", i, j) for i in range(3) for j in range(4)] + [
            ("K", 0, 0), ("K", 1, 1), ("K", 0, 2), ("K", 1, 2)]:
        base = vm0 if which == "vm" else K0
        x = base[i, j]
        estimates = []
        for e in (2e-7, 5e-7, 1e-6):
            eps = e * max(1.0, abs(x))
            hi, lo = base.copy(), base.copy()
            # The renderer takes f32 cameras: divide by the step they hold.
            hi[i, j], lo[i, j] = np.float32(x + eps), np.float32(x - eps)
            step = float(np.float32(x + eps)) - float(np.float32(x - eps))
            pair = (lambda m: (m, K0)) if which == "vm" else (lambda m: (vm0, m))
            estimates.append((loss(s, *pair(hi))[0] - loss(s, *pair(lo))[0]) / step)
        numeric.append(float(np.median(estimates)))
        analytic.append(float((vm.grad if which == "vm" else K.grad)[i, j]))
    err = rel(analytic, numeric)
    # Measured: <= 4e-8.
    assert err <= 1e-3, f"camera gradients: relative L2 error {err:.2e} against finite differences"
    assert np.abs(numeric).max() > 1.0
