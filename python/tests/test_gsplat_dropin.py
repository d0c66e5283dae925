"""verisplat.torch.rasterization as a drop-in for gsplat's (issue 38): what gsplat's own
examples and strategies pass to it. gsplat (1.5.3, its pure-torch strategy code; CI
installs it without its CUDA build) drives densification through verisplat, packed and
not; its MCMC strategy through verisplat.gsplat.MCMCStrategy, whose relocation and
position noise use verisplat's torch kernels (gsplat's CUDA build is not installed)."""

import math
import os

import numpy as np
import pytest

from verisplat import raster

if os.environ.get("VERISPLAT_REQUIRE_TORCH") == "1":
    import torch  # CI installs the torch extra and gsplat: these tests must run there
    import gsplat.strategy as gs_strategy
else:
    torch = pytest.importorskip("torch")
    gs_strategy = pytest.importorskip("gsplat.strategy")

from verisplat.torch import rasterization  # noqa: E402

from test_torch import GROUPS, H, W, cameras, rel, scene, tensors  # noqa: E402


def cam_tensors(cams):
    return (torch.tensor(np.stack([c.viewmat for c in cams])),
            torch.tensor(np.stack([c.K for c in cams])))


def render(t, cams, **kw):
    vm, Ks = cam_tensors(cams)
    return rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, **kw)


def grads_of(s, cams, loss_fn, **kw):
    t = tensors(s)
    out, alphas, meta = render(t, cams, **kw)
    loss_fn(out, alphas, meta).backward()
    return {k: t[k].grad.numpy().copy() for k in GROUPS}, out.detach(), meta


def weighted(seed):
    def loss(out, alphas, meta):
        g = torch.Generator().manual_seed(seed)
        return (out * torch.randn(out.shape, generator=g)).sum() + (
            alphas * torch.randn(alphas.shape, generator=g)).sum()
    return loss


# 1. Signed scales: the covariance is built from their squares, as gsplat's.
def test_signed_scales_render_as_their_magnitudes_with_signed_gradients():
    s = scene(n=80, seed=10)
    cams = cameras(1)
    flip = np.random.default_rng(10).random(s["scales"].shape) < 0.5
    signed = dict(s, scales=np.where(flip, -s["scales"], s["scales"]).astype(np.float32))
    g_pos, img_pos, _ = grads_of(s, cams, weighted(1), sh_degree=3)
    g_sig, img_sig, _ = grads_of(signed, cams, weighted(1), sh_degree=3)
    assert torch.equal(img_pos, img_sig)
    np.testing.assert_array_equal(g_sig["scales"], np.where(flip, -1, 1) * g_pos["scales"])
    for k in ("means", "quats", "opacities", "colors"):
        np.testing.assert_array_equal(g_sig[k], g_pos[k])
    # A zero scale renders (dilated to a pixel-sized splat) and has a zero gradient.
    zero = dict(s, scales=s["scales"].copy())
    zero["scales"][:5, 0] = 0.0
    g0, img0, _ = grads_of(zero, cams, weighted(1), sh_degree=3)
    assert torch.isfinite(img0).all() and (g0["scales"][:5, 0] == 0).all()


def fit_image_like_gsplats_example(iterations, packed):
    """gsplat's examples/image_fitting.py (v1.5.3), its training loop as written there with
    only the import changed (and the device: CPU tensors); 64x64 and 500 points."""
    torch.manual_seed(0)
    h = w = 64
    ys, xs = torch.meshgrid(torch.linspace(0, 1, h), torch.linspace(0, 1, w), indexing="ij")
    gt_image = torch.stack([xs, ys, (xs - 0.5) ** 2 * 4], -1)
    num_points = 500
    fov_x = math.pi / 2.0
    focal = 0.5 * float(w) / math.tan(0.5 * fov_x)
    bd = 2
    means = bd * (torch.rand(num_points, 3) - 0.5)
    scales = torch.rand(num_points, 3)
    rgbs = torch.rand(num_points, 3)
    u, v, x = torch.rand(num_points, 1), torch.rand(num_points, 1), torch.rand(num_points, 1)
    quats = torch.cat([
        torch.sqrt(1.0 - u) * torch.sin(2.0 * math.pi * v),
        torch.sqrt(1.0 - u) * torch.cos(2.0 * math.pi * v),
        torch.sqrt(u) * torch.sin(2.0 * math.pi * x),
        torch.sqrt(u) * torch.cos(2.0 * math.pi * x),
    ], -1)
    opacities = torch.ones(num_points)
    viewmat = torch.tensor([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 8.0], [0, 0, 0, 1.0]])
    for p in (means, scales, quats, rgbs, opacities):
        p.requires_grad = True
    optimizer = torch.optim.Adam([rgbs, means, scales, opacities, quats], 0.01)
    mse_loss = torch.nn.MSELoss()
    K = torch.tensor([[focal, 0, w / 2], [0, focal, h / 2], [0, 0, 1]])
    losses = []
    for _ in range(iterations):
        renders = rasterization(
            means, quats / quats.norm(dim=-1, keepdim=True), scales, torch.sigmoid(opacities),
            torch.sigmoid(rgbs), viewmat[None], K[None], w, h, packed=packed,
        )[0]
        loss = mse_loss(renders[0], gt_image)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    return losses, scales


def test_gsplats_image_fitting_loop_runs_with_raw_signed_scales():
    losses, scales = fit_image_like_gsplats_example(40, packed=False)
    # The loop drives raw scales through zero: negative ones are rendered, not refused.
    assert (scales < 0).any()
    # Measured: 0.285 -> 0.232 in 40 steps (gsplat's example runs 1,000).
    assert losses[-1] < 0.9 * losses[0], losses


# 6. gsplat's keyword defaults are accepted at the values that mean "off".
def test_gsplats_off_keywords_are_accepted_and_on_values_refused():
    s = scene(n=30, seed=11)
    t = tensors(s, grad=False)
    cams = cameras(1)
    base, _, _ = render(t, cams, sh_degree=3)
    shutter = pytest.importorskip("gsplat.cuda._wrapper").RollingShutterType.GLOBAL
    out, _, _ = render(t, cams, sh_degree=3, with_ut=False, with_eval3d=False,
                       radial_coeffs=None, rolling_shutter=shutter, tile_size=32,
                       channel_chunk=8)
    assert torch.equal(base, out)
    # with_ut and the lens coefficients: test_lenses.py.
    for kw, match in [({"with_eval3d": True}, "with_eval3d is not supported"),
                      ({"radial_coeffs": torch.zeros(1, 6)}, "radial_coeffs need with_ut=True"),
                      ({"tile_size": 0}, "tile_size must be a positive integer"),
                      ({"channel_chunk": 0}, "channel_chunk must be a positive integer")]:
        with pytest.raises(ValueError, match=match):
            render(t, cams, sh_degree=3, **kw)


# 2. The packed layout: one row per visible (camera, Gaussian) pair.
def test_packed_meta_is_the_unpacked_meta_at_the_visible_pairs():
    s = scene(n=120, seed=12)
    cams = cameras(2)
    t = tensors(s)
    out_u, _, mu = render(t, cams, sh_degree=3, packed=False, absgrad=True)
    mu["means2d"].retain_grad()
    (out_u ** 2).sum().backward()
    tp = tensors(s)
    out_p, _, mp = render(tp, cams, sh_degree=3, absgrad=True)  # packed: gsplat's default
    mp["means2d"].retain_grad()
    (out_p ** 2).sum().backward()
    assert torch.equal(out_u, out_p)
    c, g = mp["camera_ids"], mp["gaussian_ids"]
    visible = mu["radii"][..., 0] > 0
    assert len(g) == int(visible.sum()) > 100 and c.dtype == torch.int64
    assert torch.equal(visible[c, g], torch.ones(len(g), dtype=torch.bool))
    assert (mp["batch_ids"] == 0).all() and mu["gaussian_ids"] is None
    for key in ("radii", "depths", "conics", "opacities"):
        assert torch.equal(mp[key], mu[key][c, g]), key
    assert torch.equal(mp["means2d"].detach(), mu["means2d"].detach()[c, g])
    assert torch.equal(mp["means2d"].grad, mu["means2d"].grad[c, g])
    assert torch.equal(mp["means2d"].absgrad, mu["means2d"].absgrad[c, g])
    for k in GROUPS:
        assert torch.equal(tp[k].grad, t[k].grad), k
    assert mp["tile_size"] == 16 and mp["n_cameras"] == 2 and mp["n_batches"] == 1


@pytest.fixture
def mcmc_calls(monkeypatch):
    """Counts what gsplat's MCMCStrategy does: its `relocate` and `sample_add` steps (with
    the Gaussians each moves or adds) and the calls of verisplat's relocation kernel (the
    one verisplat.gsplat.MCMCStrategy hands to gsplat's ops while it runs)."""
    import gsplat.strategy.mcmc as mcmc
    from verisplat import _gsplat_kernels

    calls = {"kernel": 0, "relocated": [], "added": []}
    kernel = _gsplat_kernels.compute_relocation

    def counted(**kwargs):
        calls["kernel"] += 1
        return kernel(**kwargs)

    def spy(name, key, count):
        real = getattr(mcmc, name)

        def wrapped(*args, **kwargs):
            calls[key].append(count(args, kwargs))
            return real(*args, **kwargs)

        monkeypatch.setattr(mcmc, name, wrapped)

    spy("relocate", "relocated", lambda a, k: int(k["mask"].sum()))
    spy("sample_add", "added", lambda a, k: int(k["n"]))
    monkeypatch.setattr(_gsplat_kernels, "compute_relocation", counted)
    return calls


def splat_parameters(s):
    """simple_trainer.py's parameters of scene `s`: log scales, logit opacities, SH split
    into sh0 and shN."""
    return torch.nn.ParameterDict({
        "means": torch.nn.Parameter(torch.tensor(s["means"])),
        "scales": torch.nn.Parameter(torch.log(torch.tensor(s["scales"]))),
        "quats": torch.nn.Parameter(torch.tensor(s["quats"])),
        "opacities": torch.nn.Parameter(torch.logit(torch.tensor(s["opacities"]))),
        "sh0": torch.nn.Parameter(torch.tensor(s["colors"][:, :1])),
        "shN": torch.nn.Parameter(torch.tensor(s["colors"][:, 1:])),
    })


def train_with_strategy(strategy, packed, steps=40, n=200, mode="classic", raster=None,
                        ssim=None):
    """A small 3DGS training loop as gsplat's simple_trainer.py runs one: log scales,
    logit opacities, SH, one Adam per group, the strategy's pre- and post-backward steps.
    `raster`: the rasterization called (verisplat.torch's unless given); `ssim`: a
    fused_ssim for simple_trainer.py's loss, 0.8 L1 + 0.2 (1 - SSIM) (L1 alone if None)."""
    raster = raster or rasterization
    s = scene(n=n, seed=13, degree=1)
    cams = cameras(2)
    target_t = tensors(scene(n=n, seed=14, degree=1), grad=False)
    targets, _, _ = render(target_t, cams, sh_degree=1)
    params = splat_parameters(s)
    optimizers = {k: torch.optim.Adam([params[k]], lr=0.01) for k in params}
    strategy.check_sanity(params, optimizers)
    state = strategy.initialize_state()
    vm, Ks = cam_tensors(cams)
    losses = []
    for step in range(steps):
        colors = torch.cat([params["sh0"], params["shN"]], 1)
        out, _, info = raster(
            params["means"], params["quats"], torch.exp(params["scales"]),
            torch.sigmoid(params["opacities"]), colors, vm, Ks, W, H, sh_degree=1,
            packed=packed, absgrad=getattr(strategy, "absgrad", False), rasterize_mode=mode,
        )
        loss = (out - targets).abs().mean()
        if ssim is not None:
            ssim_loss = 1.0 - ssim(out.permute(0, 3, 1, 2), targets.permute(0, 3, 1, 2),
                                   padding="valid")
            loss = 0.8 * loss + 0.2 * ssim_loss
        strategy.step_pre_backward(params, optimizers, state, step, info)
        loss.backward()
        for opt in optimizers.values():
            opt.step()
            opt.zero_grad(set_to_none=True)
        if isinstance(strategy, gs_strategy.MCMCStrategy):
            strategy.step_post_backward(params, optimizers, state, step, info, lr=0.01)
        else:
            strategy.step_post_backward(params, optimizers, state, step, info, packed=packed)
        losses.append(loss.item())
    return params, losses


@pytest.mark.parametrize("packed, mode", [(True, "classic"), (False, "classic"),
                                          (True, "antialiased")])
def test_gsplats_default_strategy_densifies_through_verisplat(packed, mode):
    strategy = gs_strategy.DefaultStrategy(
        refine_start_iter=10, refine_every=10, reset_every=1000, grow_grad2d=2e-5,
        refine_scale2d_stop_iter=30,
    )
    params, losses = train_with_strategy(strategy, packed, mode=mode)
    assert len(params["means"]) > 200, "nothing was duplicated or split"
    assert losses[-1] < losses[0], losses


def test_gsplats_default_strategy_is_the_same_packed_or_not():
    runs = []
    for packed in (True, False):
        strategy = gs_strategy.DefaultStrategy(
            refine_start_iter=10, refine_every=10, reset_every=1000, grow_grad2d=2e-5,
            refine_scale2d_stop_iter=30,
        )
        torch.manual_seed(3)  # the strategy's split samples
        params, _ = train_with_strategy(strategy, packed, steps=25)
        runs.append({k: v.detach().clone() for k, v in params.items()})
    for k in runs[0]:
        assert torch.equal(runs[0][k], runs[1][k]), k


MIN_OPACITY = 0.2  # high enough that some of the scene's Gaussians are dead at step 20


@pytest.mark.parametrize("packed", [True, False])
def test_gsplats_mcmc_strategy_relocates_and_adds_through_verisplat(mcmc_calls, packed):
    """simple_trainer.py's MCMC path (its L1 + SSIM loss) with only the import lines
    changed: `from verisplat.gsplat import MCMCStrategy, fused_ssim, rasterization`."""
    from verisplat.gsplat import MCMCStrategy, fused_ssim
    from verisplat.gsplat import rasterization as gs_rasterization
    import gsplat.strategy.ops as ops

    cuda_ones = (ops.compute_relocation, ops.quat_scale_to_covar_preci)
    torch.manual_seed(4)
    strategy = MCMCStrategy(cap_max=260, refine_start_iter=10, refine_every=10,
                            min_opacity=MIN_OPACITY)
    assert isinstance(strategy, gs_strategy.MCMCStrategy)
    params, losses = train_with_strategy(strategy, packed, steps=31, raster=gs_rasterization,
                                         ssim=fused_ssim)
    # Refinements at steps 20 and 30 each relocate the dead Gaussians (when there are
    # any), then add 5 % more (gsplat's rule): 200 -> 210 -> 220; one kernel call per
    # relocation and per addition.
    assert mcmc_calls["added"] == [10, 10], mcmc_calls
    assert sum(mcmc_calls["relocated"]) > 0, mcmc_calls
    assert mcmc_calls["kernel"] == len(mcmc_calls["relocated"]) + 2, mcmc_calls
    assert len(params["means"]) == 220, len(params["means"])
    assert losses[-1] < losses[0], losses
    # The swap lasted only while the strategy ran.
    assert (ops.compute_relocation, ops.quat_scale_to_covar_preci) == cuda_ones


def test_gsplats_own_kernels_cannot_run_here():
    """What verisplat.gsplat's MCMCStrategy replaces: gsplat's CUDA relocation fails
    on a machine without gsplat's CUDA build (skipped where it has one)."""
    from gsplat.cuda import _backend
    from gsplat.relocation import compute_relocation

    if _backend._C is not None:
        pytest.skip("gsplat's CUDA build loads on this machine")
    o, s = torch.tensor([0.5]), torch.ones(1, 3)
    with pytest.raises(AttributeError, match="relocation"):  # gsplat's _C is None
        compute_relocation(o, s, torch.tensor([2]), torch.ones(4, 4))


def test_torch_kernels_context_is_scoped_and_nests():
    from verisplat import _gsplat_kernels
    from verisplat.gsplat import torch_kernels
    import gsplat.strategy.ops as ops

    before = ops.compute_relocation
    with torch_kernels():
        assert ops.compute_relocation is _gsplat_kernels.compute_relocation
        with torch_kernels():
            assert ops.quat_scale_to_covar_preci is _gsplat_kernels.quat_scale_to_covar_preci
        assert ops.compute_relocation is _gsplat_kernels.compute_relocation
    assert ops.compute_relocation is before
    with pytest.raises(RuntimeError):
        with torch_kernels():
            raise RuntimeError("inside")
    assert ops.compute_relocation is before


# 8. Per-camera colours, batch dimensions, many channels, numpy sizes, backgrounds.
def test_per_camera_colours_equal_one_camera_at_a_time():
    s = scene(n=60, seed=15, degree=0)
    rng = np.random.default_rng(15)
    per_cam = rng.uniform(-0.2, 1.0, (2, 60, 3)).astype(np.float32)
    cams = cameras(2)
    t = tensors(dict(s, colors=per_cam))
    out, _, _ = render(t, cams)
    weighted(2)(out, torch.zeros(1), None).backward()
    g = torch.Generator().manual_seed(2)
    w = torch.randn(out.shape, generator=g)
    for c in range(2):
        tc = tensors(dict(s, colors=per_cam[c]))
        oc, _, _ = render(tc, [cams[c]])
        assert torch.equal(oc[0], out[c].detach())
        (oc * w[c:c + 1]).sum().backward()
        np.testing.assert_allclose(t["colors"].grad[c].numpy(), tc["colors"].grad.numpy(),
                                   rtol=0, atol=0)


def test_leading_batch_dimensions_equal_separate_calls():
    sets = [scene(n=40, seed=16 + b) for b in range(2)]
    batched = {k: np.stack([s[k] for s in sets]) for k in GROUPS}
    cams = cameras(2)
    vm, Ks = cam_tensors(cams)
    t = tensors(batched)
    out, alphas, meta = rasterization(*[t[k] for k in GROUPS], vm[None].repeat(2, 1, 1, 1),
                                      Ks[None].repeat(2, 1, 1, 1), W, H, sh_degree=3,
                                      packed=False)
    assert out.shape == (2, 2, H, W, 3) and meta["radii"].shape == (2, 2, 40, 2)
    weighted(3)(out, alphas, meta).backward()
    g = torch.Generator().manual_seed(3)
    wc, wa = torch.randn(out.shape, generator=g), torch.randn(alphas.shape, generator=g)
    for b in range(2):
        tb = tensors(sets[b])
        ob, ab, _ = render(tb, cams, sh_degree=3)
        assert torch.equal(ob, out[b].detach())
        ((ob * wc[b]).sum() + (ab * wa[b]).sum()).backward()
        for k in GROUPS:
            assert rel(t[k].grad[b].numpy(), tb[k].grad.numpy()) < 1e-6, k
    _, _, mp = rasterization(*[t[k] for k in GROUPS], vm[None].repeat(2, 1, 1, 1),
                             Ks[None].repeat(2, 1, 1, 1), W, H, sh_degree=3)
    assert set(mp["batch_ids"].tolist()) == {0, 1}
    visible = meta["radii"][..., 0] > 0
    assert len(mp["gaussian_ids"]) == int(visible.sum())


def test_more_than_16_channels_equal_the_reference():
    s = scene(n=40, seed=17, degree=0)
    s["colors"] = np.random.default_rng(17).normal(size=(40, 21)).astype(np.float32)
    cam = cameras(1)[0]
    t = tensors(s)
    out, alphas, _ = render(t, [cam])
    assert out.shape == (1, H, W, 21)
    rng = np.random.default_rng(18)
    wc = rng.normal(size=(H, W, 21)).astype(np.float32)
    wa = rng.normal(size=(H, W)).astype(np.float32)
    ((out[0] * torch.tensor(wc)).sum() + (alphas[0, ..., 0] * torch.tensor(wa)).sum()).backward()
    ref = raster.Rasterizer(backend="reference")
    f = ref.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H)
    assert np.abs(f.colors - out[0].detach().numpy()).max() < 1e-4
    gr = ref.backward(f, grad_colors=wc, grad_alphas=wa)
    for k in GROUPS:
        assert rel(t[k].grad.numpy(), gr[k]) <= 1e-3, k


# 9. Direct colours are blended as given, never clamped, whatever their count.
@pytest.mark.parametrize("channels", [3, 5])
def test_direct_colours_are_not_clamped(channels):
    s = scene(n=50, seed=19, degree=0)
    s["colors"] = np.random.default_rng(19).uniform(-1, 1, (50, channels)).astype(np.float32)
    cam = cameras(1)[0]
    out, _, _ = render(tensors(s, grad=False), [cam])
    ref = raster.Rasterizer(backend="reference").forward(
        **s, viewmat=cam.viewmat, K=cam.K, width=W, height=H)
    assert (ref.colors < -0.05).sum() > 50
    assert np.abs(ref.colors - out[0].numpy()).max() < 1e-4


def test_numpy_sizes_and_backgrounds_in_depth_only_modes():
    s = scene(n=30, seed=20)
    cams = cameras(2)
    t = tensors(s, grad=False)
    vm, Ks = cam_tensors(cams)
    args = [t[k] for k in GROUPS] + [vm, Ks]
    base, _, _ = rasterization(*args, W, H, sh_degree=3, render_mode="ED")
    out, _, _ = rasterization(*args, np.int64(W), np.int32(H), sh_degree=np.int64(3),
                              render_mode="ED", backgrounds=torch.ones(2, 3))
    assert torch.equal(base, out)
    # A background for direct feature channels is blended in (1 - alpha) * background.
    f = dict(s, colors=np.random.default_rng(20).normal(size=(30, 5)).astype(np.float32))
    tf = tensors(f, grad=False)
    plain, alphas, _ = render(tf, cams)
    bg = torch.tensor(np.random.default_rng(21).normal(size=(2, 5)).astype(np.float32))
    over, _, _ = render(tf, cams, backgrounds=bg)
    assert torch.allclose(over, plain + (1 - alphas) * bg[:, None, None, :], atol=1e-6)
    with pytest.raises(ValueError, match="width must be a positive integer"):
        rasterization(*args, 2.5, H, sh_degree=3)


# 3. Camera-pose (and intrinsics) gradients, against finite differences of the f64
# reference renderer.
def reference_loss(s, cams, vms, Ks, wc, wa, antialiased=False):
    ref = raster.Rasterizer(backend="reference")
    total = 0.0
    for c in range(len(cams)):
        f = ref.forward(**s, viewmat=vms[c], K=Ks[c], width=W, height=H, sh_degree=2,
                        antialiased=antialiased)
        total += float((f.colors * wc[c]).sum() + (f.alphas * wa[c]).sum())
    return total


@pytest.mark.parametrize("mode", ["classic", "antialiased"])
def test_camera_gradients_equal_finite_differences_of_the_reference(mode):
    aa = mode == "antialiased"
    s = scene(n=80, seed=22, degree=2)
    cams = cameras(2)
    vm, Ks = cam_tensors(cams)
    vm.requires_grad_()
    Ks.requires_grad_()
    t = tensors(s)
    out, alphas, _ = rasterization(*[t[k] for k in GROUPS], vm, Ks, W, H, sh_degree=2,
                                   rasterize_mode=mode)
    rng = np.random.default_rng(22)
    wc = rng.normal(size=out.shape)
    wa = rng.normal(size=alphas.shape[:-1])
    ((out * torch.tensor(wc, dtype=torch.float32)).sum()
     + (alphas[..., 0] * torch.tensor(wa, dtype=torch.float32)).sum()).backward()
    assert vm.grad is not None and Ks.grad is not None
    vms, ks = vm.detach().numpy().astype(np.float64), Ks.detach().numpy().astype(np.float64)
    analytic, numeric = [], []
    entries = [("vm", c, i, j) for c in range(2) for i in range(3) for j in range(4)]
    entries += [("K", c, i, j) for c in range(2) for (i, j) in ((0, 0), (1, 1), (0, 2), (1, 2))]
    for which, c, i, j in entries:
        base = vms if which == "vm" else ks
        x = base[c, i, j]
        # The rendered image has jumps (a tile rectangle's edge, the 1/255 alpha skip): a
        # step that crosses one is off by far, so the steps are small and the median of
        # three is taken.
        estimates = []
        for e in (2e-7, 5e-7, 1e-6):
            eps = e * max(1.0, abs(x))
            hi, lo = base.copy(), base.copy()
            # The renderer takes f32 cameras: divide by the step they hold.
            hi[c, i, j], lo[c, i, j] = np.float32(x + eps), np.float32(x - eps)
            step = float(np.float32(x + eps)) - float(np.float32(x - eps))
            f_hi = reference_loss(s, cams, *((hi, ks) if which == "vm" else (vms, hi)), wc, wa, aa)
            f_lo = reference_loss(s, cams, *((lo, ks) if which == "vm" else (vms, lo)), wc, wa, aa)
            estimates.append((f_hi - f_lo) / step)
        numeric.append(float(np.median(estimates)))
        grad = vm.grad if which == "vm" else Ks.grad
        analytic.append(float(grad[c, i, j]))
    err = rel(analytic, numeric)
    # Measured: 5.6e-7.
    assert err <= 1e-3, f"camera gradients: relative L2 error {err:.2e} against finite differences"
    assert np.abs(numeric).max() > 1.0


def test_a_camera_pose_is_learned_through_verisplat():
    # gsplat's simple_trainer.py --pose_opt in small: a learned correction of a camera's
    # translation and rotation (axis-angle) brings a displaced camera back to its image.
    s = scene(n=150, seed=23, degree=1)
    cam = cameras(1)[0]
    vm_true, K = cam_tensors([cam])
    t = tensors(s, grad=False)
    target, _, _ = rasterization(*[t[k] for k in GROUPS], vm_true, K, W, H, sh_degree=1)
    offset = torch.tensor([0.12, -0.08, 0.1])
    shift = torch.zeros(3, requires_grad=True)
    axis_angle = torch.zeros(3, requires_grad=True)
    opt = torch.optim.Adam([shift, axis_angle], lr=0.01)
    errors = []
    for _ in range(40):
        a = axis_angle
        skew = torch.stack([torch.stack([0 * a[0], -a[2], a[1]]),
                            torch.stack([a[2], 0 * a[0], -a[0]]),
                            torch.stack([-a[1], a[0], 0 * a[0]])])
        delta = torch.cat([torch.cat([torch.matrix_exp(skew), (shift)[:, None]], 1),
                           torch.tensor([[0.0, 0, 0, 1]])], 0)
        displaced = vm_true[0].clone()
        displaced[:3, 3] += offset
        vm = (delta @ displaced)[None]
        img, _, _ = rasterization(*[t[k] for k in GROUPS], vm, K, W, H, sh_degree=1)
        loss = (img - target).abs().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        errors.append(float((vm.detach()[0] - vm_true[0]).abs().max()))
    assert errors[-1] < 0.5 * errors[0], errors


# 4. Losses on meta's 2D means, depths and conics reach the Gaussians (and the camera).
def meta_loss(meta):
    m2d, d, con, o = meta["means2d"], meta["depths"], meta["conics"], meta["opacities"]
    return 1e-3 * (m2d ** 2).sum() + d.sum() + 10 * con.sum() + 5 * (o ** 2).sum()


def native_meta_loss(s, cams, visible, antialiased):
    r = raster.Rasterizer()
    total = 0.0
    for c, cam in enumerate(cams):
        f = r.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H, sh_degree=3,
                      antialiased=antialiased)
        v = visible[c]
        total += (1e-3 * (f.means2d[v].astype(np.float64) ** 2).sum()
                  + f.gaussian_depths[v].astype(np.float64).sum()
                  + 10 * f.conics[v].astype(np.float64).sum()
                  + 5 * (f.opacities[v].astype(np.float64) ** 2).sum())
    return total


@pytest.mark.parametrize("packed, mode", [(True, "classic"), (False, "classic"),
                                          (True, "antialiased")])
def test_losses_on_meta_reach_the_gaussians(packed, mode):
    aa = mode == "antialiased"
    s = scene(n=60, seed=24)
    cams = cameras(2)
    t = tensors(s)
    _, _, meta = render(t, cams, sh_degree=3, packed=packed, rasterize_mode=mode)
    meta_loss(meta).backward()
    visible = [(np.asarray(r) > 0) for r in (render(tensors(s, grad=False), cams, sh_degree=3,
                                                     packed=False)[2]["radii"][..., 0])]
    assert t["means"].grad is not None and t["means"].grad.abs().sum() > 0
    rng = np.random.default_rng(24)
    for k in ("means", "quats", "scales", "opacities"):
        analytic, numeric = [], []
        for _ in range(3):
            d = rng.normal(size=s[k].shape).astype(np.float64)
            eps = 1e-3
            hi = dict(s, **{k: (s[k] + eps * d).astype(np.float32)})
            lo = dict(s, **{k: (s[k] - eps * d).astype(np.float32)})
            numeric.append((native_meta_loss(hi, cams, visible, aa)
                            - native_meta_loss(lo, cams, visible, aa)) / (2 * eps))
            analytic.append(float((t[k].grad.numpy().astype(np.float64) * d).sum()))
        err = rel(analytic, numeric)
        # Measured: 1.3e-4, 9e-5, 3.8e-4 (central differences of the f32 device forward).
        assert err <= 2e-3, f"{k}: relative error {err:.2e} against finite differences"
    assert t["colors"].grad is None or (t["colors"].grad == 0).all()


def test_an_image_loss_and_a_meta_loss_add():
    s = scene(n=60, seed=25)
    cams = cameras(2)
    grads = []
    for which in ("image", "meta", "both"):
        t = tensors(s)
        out, _, meta = render(t, cams, sh_degree=3)
        meta["means2d"].retain_grad()
        loss = {"image": lambda: (out ** 2).sum(), "meta": lambda: meta_loss(meta),
                "both": lambda: (out ** 2).sum() + meta_loss(meta)}[which]()
        loss.backward()
        grads.append({k: t[k].grad.clone() for k in ("means", "quats", "scales")})
        if which == "image":
            image_2d = meta["means2d"].grad.clone()
        if which == "both":
            # The retained 2D-mean gradient is the whole loss's, as in gsplat.
            assert torch.allclose(meta["means2d"].grad, image_2d + 2e-3 * meta["means2d"],
                                  rtol=1e-5, atol=1e-6)
    for k in grads[0]:
        assert torch.allclose(grads[2][k], grads[0][k] + grads[1][k], rtol=1e-4, atol=1e-5), k


# 5. The antialiased mode's backward pass: the device against the f64 reference.
def test_antialiased_gradients_equal_the_reference():
    s = scene(n=120, seed=26)
    cams = cameras(2)
    t = tensors(s)
    out, alphas, meta = render(t, cams, sh_degree=3, rasterize_mode="antialiased")
    weighted(26)(out, alphas, meta).backward()
    g = torch.Generator().manual_seed(26)
    wc, wa = torch.randn(out.shape, generator=g), torch.randn(alphas.shape, generator=g)
    ref = raster.Rasterizer(backend="reference")
    total = {k: 0.0 for k in GROUPS}
    classic, _, _ = render(tensors(s, grad=False), cams, sh_degree=3)
    for c, cam in enumerate(cams):
        f = ref.forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H, sh_degree=3,
                        antialiased=True)
        assert np.abs(f.colors - out[c].detach().numpy()).max() < 1e-4
        gr = ref.backward(f, grad_colors=wc[c].numpy(), grad_alphas=wa[c, ..., 0].numpy())
        for k in GROUPS:
            total[k] = total[k] + gr[k]
    assert (classic - out.detach()).abs().max() > 0.01, "the compensation changed nothing"
    for k in GROUPS:
        err = rel(t[k].grad.numpy(), total[k])
        assert err <= 1e-3, f"{k}: relative L2 error {err:.2e} against the reference"
    # meta's opacities are the compensated ones, as gsplat's.
    assert (meta["opacities"] < t["opacities"][meta["gaussian_ids"]]).all()
