"""verisplat.torch.rasterization (gsplat's signature) and the numpy-level pair
verisplat.raster: gradients against the f64 CPU reference (itself checked against finite
differences in the Rust tests), determinism, meta, refusals, and a small fit.

Tolerance: relative L2 error <= 1e-3 per parameter group between the Vulkan backward
(f32) and the f64 reference, the issue's figure; measured values are ~1e-6 here."""

import os
import subprocess
import sys

import numpy as np
import pytest

import verisplat
from verisplat import raster

if os.environ.get("VERISPLAT_REQUIRE_TORCH") == "1":
    import torch  # CI installs the torch extra: these tests must run there
else:
    torch = pytest.importorskip("torch")

from verisplat.torch import rasterization  # noqa: E402

W, H = 80, 56
GROUPS = ["means", "quats", "scales", "opacities", "colors"]


def scene(n=150, seed=0, degree=3):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    return dict(
        means=rng.uniform(-1, 1, (n, 3)).astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
        scales=rng.uniform(0.04, 0.2, (n, 3)).astype(np.float32),
        opacities=rng.uniform(0.2, 0.95, n).astype(np.float32),
        colors=(rng.normal(size=(n, k, 3)) * 0.4).astype(np.float32),
    )


def cameras(count=2):
    cams = [
        verisplat.look_at(eye=(0.3 * i, -0.2, -4.0), target=(0, 0, 0), width=W, height=H)
        for i in range(count)
    ]
    return cams


def tensors(s, grad=True):
    return {k: torch.tensor(v, requires_grad=grad) for k, v in s.items()}


def rel(a, b):
    a, b = np.asarray(a, np.float64).ravel(), np.asarray(b, np.float64).ravel()
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def test_gradients_equal_the_reference_for_two_cameras_rgb_and_depth():
    s = scene()
    cams = cameras(2)
    t = tensors(s)
    vm = torch.tensor(np.stack([c.viewmat for c in cams]))
    Ks = torch.tensor(np.stack([c.K for c in cams]))
    bg = torch.tensor([[0.1, 0.2, 0.3, 0.0], [0.0, 0.5, 0.0, 0.0]])
    out, alphas, meta = rasterization(
        t["means"], t["quats"], t["scales"], t["opacities"], t["colors"], vm, Ks, W, H,
        sh_degree=3, backgrounds=bg, render_mode="RGB+ED",
    )
    assert out.shape == (2, H, W, 4) and alphas.shape == (2, H, W, 1)
    rng = np.random.default_rng(5)
    wc = torch.tensor(rng.normal(size=out.shape).astype(np.float32))
    wa = torch.tensor(rng.normal(size=alphas.shape).astype(np.float32))
    ((out * wc).sum() + (alphas * wa).sum()).backward()
    # The same loss through the f64 reference, camera by camera.
    ref = raster.Rasterizer(backend="reference")
    total = {k: 0.0 for k in GROUPS}
    for c, cam in enumerate(cams):
        f = ref.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H, sh_degree=3,
                        background=bg[c, :3].numpy())
        assert np.abs(f.colors - out[c, ..., :3].detach().numpy()).max() < 1e-4
        g = ref.backward(f, grad_colors=wc[c, ..., :3].numpy(), grad_alphas=wa[c, ..., 0].numpy(),
                         grad_depths=wc[c, ..., 3].numpy())
        for k in GROUPS:
            total[k] = total[k] + g[k]
    for k in GROUPS:
        err = rel(t[k].grad.numpy(), total[k])
        assert err <= 1e-3, f"{k}: relative L2 error {err:.2e} against the reference"
    assert np.abs(t["colors"].grad.numpy()).sum() > 0


def test_reproducible_mode_differentiates_as_the_reference_and_repeats_bit_for_bit():
    # The reproducible mode's blends (the CPU reference's exp, unfused arithmetic) through
    # the drop-in: the same gradients as the f64 reference, the same bits run after run,
    # and images within rounding of the default mode's.
    s = scene(seed=3)
    cam = cameras(1)[0]
    vm, Ks = torch.tensor(cam.viewmat)[None], torch.tensor(cam.K)[None]
    rng = np.random.default_rng(6)
    wc = torch.tensor(rng.normal(size=(1, H, W, 3)).astype(np.float32))

    def run(reproducible):
        t = tensors(s)
        out, _, _ = rasterization(t["means"], t["quats"], t["scales"], t["opacities"],
                                  t["colors"], vm, Ks, W, H, sh_degree=3,
                                  reproducible=reproducible)
        (out * wc).sum().backward()
        return out.detach().numpy(), {k: t[k].grad.numpy() for k in GROUPS}

    img, grads = run(True)
    again, grads_again = run(True)
    assert np.array_equal(img, again)
    for k in GROUPS:
        assert np.array_equal(grads[k], grads_again[k]), k
    plain, _ = run(False)
    assert np.abs(img - plain).max() < 1e-5
    ref = raster.Rasterizer(backend="reference")
    f = ref.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H, sh_degree=3)
    g = ref.backward(f, grad_colors=wc[0].numpy())
    for k in GROUPS:
        err = rel(grads[k], g[k])
        assert err <= 1e-3, f"{k}: relative L2 error {err:.2e} against the reference"


def test_means2d_gradient_and_absgrad_for_densification():
    s = scene(seed=1)
    cam = cameras(1)[0]
    t = tensors(s)
    out, alphas, meta = rasterization(
        t["means"], t["quats"], t["scales"], t["opacities"], t["colors"],
        torch.tensor(cam.viewmat)[None], torch.tensor(cam.K)[None], W, H, sh_degree=3,
        absgrad=True, packed=False,
    )
    meta["means2d"].retain_grad()
    (out ** 2).sum().backward()
    grad2d = meta["means2d"].grad
    assert grad2d.shape == (1, len(s["means"]), 2)
    assert meta["means2d"].absgrad.shape == (1, len(s["means"]), 2)
    # The numpy-level backward of the same loss gives the same 2D gradients.
    r = raster.Rasterizer()
    f = r.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H, sh_degree=3)
    g = r.backward(f, grad_colors=2 * f.colors)
    np.testing.assert_array_equal(grad2d[0].numpy(), g["means2d"])
    np.testing.assert_array_equal(meta["means2d"].absgrad[0].numpy(), g["absgrad"])
    assert (meta["means2d"].absgrad >= grad2d.abs() - 1e-6).all()
    visible = meta["radii"][0, :, 0] > 0
    assert visible.sum() > 10 and (grad2d[0][~visible] == 0).all()
    # gsplat's means2d: pixel centres at +0.5.
    assert meta["means2d"].shape == (1, len(s["means"]), 2)
    assert meta["depths"].shape == (1, len(s["means"]))


def test_gradients_are_bit_identical_run_after_run():
    s = scene(seed=2)
    cam = cameras(1)[0]
    grads = []
    for _ in range(2):
        t = tensors(s)
        out, alphas, _ = rasterization(
            t["means"], t["quats"], t["scales"], t["opacities"], t["colors"],
            torch.tensor(cam.viewmat)[None], torch.tensor(cam.K)[None], W, H, sh_degree=3,
        )
        (out.sum() + alphas.sum()).backward()
        grads.append([t[k].grad.numpy().tobytes() for k in GROUPS])
    assert grads[0] == grads[1]


def test_direct_rgb_colours_and_the_numpy_pair():
    s = scene(seed=3, degree=0)
    rng = np.random.default_rng(3)
    s["colors"] = rng.uniform(0.05, 1.0, (len(s["means"]), 3)).astype(np.float32)
    cam = cameras(1)[0]
    fwd = raster.rasterize(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H,
                           background=[1, 1, 1])
    assert fwd.colors.shape == (H, W, 3) and fwd.alphas.shape == (H, W)
    g = raster.rasterize_backward(fwd, grad_colors=np.ones((H, W, 3), np.float32))
    ref = raster.Rasterizer(backend="reference")
    f = ref.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H, background=[1, 1, 1])
    assert np.abs(f.colors - fwd.colors).max() < 1e-4
    gr = ref.backward(f, grad_colors=np.ones((H, W, 3)))
    for k in GROUPS:
        assert rel(g[k], gr[k]) <= 1e-3, k


def test_feature_channels_on_the_device_equal_the_reference():
    s = scene(n=40, seed=4, degree=0)
    s["colors"] = np.random.default_rng(4).normal(size=(40, 6)).astype(np.float32)
    cam = cameras(1)[0]
    ref = raster.Rasterizer(backend="reference")
    f = ref.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H)
    assert f.colors.shape == (H, W, 6)
    g = ref.backward(f, grad_colors=np.ones((H, W, 6)))
    fv = raster.Rasterizer().forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H)
    assert np.abs(fv.colors - f.colors).max() < 1e-4
    gv = raster.Rasterizer().backward(fv, grad_colors=np.ones((H, W, 6), np.float32))
    assert g["colors"].shape == gv["colors"].shape == (40, 6)
    for k in GROUPS:
        assert rel(gv[k], g[k]) <= 1e-3, k
    # Through torch: [N, D] colours without sh_degree.
    t = tensors(s)
    out, _, _ = rasterization(*[t[k] for k in GROUPS], torch.tensor(cam.viewmat)[None],
                              torch.tensor(cam.K)[None], W, H)
    assert out.shape == (1, H, W, 6)
    out.sum().backward()
    assert rel(t["colors"].grad.numpy(), g["colors"]) <= 1e-3
    with pytest.raises(RuntimeError, match="at most 16"):
        s17 = dict(s, colors=np.zeros((40, 17), np.float32))
        raster.Rasterizer().forward(**s17, viewmat=cam.viewmat, K=cam.K, width=W, height=H)


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda a: a.update(means=a["means"].double()), "means must be float32"),
        (lambda a: a.update(quats=a["quats"][:-1]), r"quats must have shape \(150, 4\)"),
        (lambda a: a["scales"].data.__setitem__((3, 1), float("nan")), "scales holds NaN"),
        (lambda a: a.update(means=torch.empty(150, 3, device="meta")), "means is on meta"),
        (lambda a: a.update(Ks=a["Ks"][:, :2]), r"Ks must have shape"),
        (lambda a: a.update(near_plane=0.0), "near_plane must be a positive number"),
        (lambda a: a.update(render_mode="RGB+X"), "render_mode must be"),
        (lambda a: a.update(rasterize_mode="mip"), "rasterize_mode must be 'classic' or"),
    ],
)
def test_bad_arguments_are_value_errors_naming_them(change, match):
    s = scene()
    cam = cameras(1)[0]
    args = tensors(s, grad=False)
    args.update(viewmats=torch.tensor(cam.viewmat)[None], Ks=torch.tensor(cam.K)[None],
                width=W, height=H, sh_degree=3)
    change(args)
    with pytest.raises(ValueError, match=match):
        rasterization(**args)


def test_the_package_imports_without_torch(tmp_path):
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import verisplat, verisplat.raster\n"
        "try:\n    import verisplat.torch\nexcept ImportError:\n    print('no torch: ok')\n"
    )
    # From a folder where the source tree cannot shadow the installed package.
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "no torch: ok" in out.stdout


def test_fitting_gaussians_to_an_image_lowers_the_loss():
    # The README's example, checked: fit colours and opacities of a few Gaussians to a
    # target rendered from other values.
    s = scene(n=60, seed=6, degree=0)
    cam = cameras(1)[0]
    vm, K = torch.tensor(cam.viewmat)[None], torch.tensor(cam.K)[None]
    target, _, _ = rasterization(*[torch.tensor(s[k]) for k in GROUPS], vm, K, W, H, sh_degree=0)
    t = tensors(s)
    t["colors"].data.normal_(0, 0.5, generator=torch.Generator().manual_seed(0))
    opt = torch.optim.Adam([t["colors"], t["means"]], lr=0.02)
    losses = []
    for _ in range(40):
        opt.zero_grad()
        img, _, _ = rasterization(*[t[k] for k in GROUPS], vm, K, W, H, sh_degree=0)
        loss = (img - target).abs().mean()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.3 * losses[0], losses
