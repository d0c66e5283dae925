"""verisplat._gsplat_kernels: gsplat 1.5.3's CUDA kernels of its strategies (relocation,
quaternion and scale to covariance/precision) in torch, against independent formulas:
the relocation's double binomial sum term by term in Python floats, the covariance from a
rotation built another way (the exponential of the axis-angle's cross matrix), the
precision as the covariance's inverse, gsplat's upper-triangle packing, and gradients
against finite differences."""

import math
import os

import pytest

if os.environ.get("VERISPLAT_REQUIRE_TORCH") == "1":
    import torch
else:
    torch = pytest.importorskip("torch")

from verisplat import _gsplat_kernels as kernels  # noqa: E402


def binomials(n_max, dtype=torch.float32):
    """gsplat's MCMCStrategy table: binoms[n, k] = C(n, k)."""
    return torch.tensor([[math.comb(n, k) for k in range(n_max)] for n in range(n_max)],
                        dtype=dtype)


def relocation_by_the_paper(o, s, n):
    """Equation 9 of the 3DGS-MCMC paper, term by term in Python floats."""
    new_o = 1.0 - (1.0 - o) ** (1.0 / n)
    denom = 0.0
    for i in range(1, n + 1):
        for k in range(i):
            denom += math.comb(i - 1, k) * (-1.0) ** k / math.sqrt(k + 1) * new_o ** (k + 1)
    return new_o, [o / denom * x for x in s]


@pytest.mark.parametrize("dtype, n_top, rtol", [(torch.float64, 51, 1e-9),
                                                (torch.float32, 12, 2e-4)])
def test_relocation_is_the_papers_sum(dtype, n_top, rtol):
    g = torch.Generator().manual_seed(1)
    count = 200
    o = torch.rand(count, generator=g, dtype=dtype) * 0.98 + 0.01
    s = torch.rand(count, 3, generator=g, dtype=dtype) + 0.1
    n = torch.randint(1, n_top + 1, (count,), generator=g)
    new_o, new_s = kernels.compute_relocation(o, s, n, binomials(51, dtype))
    assert new_o.dtype == dtype and new_s.shape == (count, 3)
    for i in range(count):
        want_o, want_s = relocation_by_the_paper(o[i].item(), s[i].tolist(), int(n[i]))
        assert new_o[i].item() == pytest.approx(want_o, rel=rtol), i
        assert new_s[i].tolist() == pytest.approx(want_s, rel=rtol), i


def test_relocated_copies_composite_to_the_original_opacity():
    o = torch.tensor([0.05, 0.3, 0.6, 0.95], dtype=torch.float64)
    s = torch.ones(4, 3, dtype=torch.float64)
    for n in range(1, 8):
        new_o, _ = kernels.compute_relocation(o, s, torch.full((4,), n), binomials(51, torch.float64))
        assert torch.allclose(1 - (1 - new_o) ** n, o, rtol=1e-12)
    # One copy is the Gaussian itself.
    new_o, new_s = kernels.compute_relocation(o, s, torch.ones(4), binomials(51, torch.float64))
    assert torch.allclose(new_o, o) and torch.allclose(new_s, s)


def test_relocation_clamps_the_ratios_and_reads_only_the_lower_triangle():
    o = torch.tensor([0.4, 0.4, 0.4, 0.4], dtype=torch.float64)
    s = torch.rand(4, 3, dtype=torch.float64)
    ratios = torch.tensor([0, 1, 10, 99])
    before = ratios.clone()
    table = binomials(10, torch.float64)
    new_o, new_s = kernels.compute_relocation(o, s, ratios, table)
    assert torch.equal(ratios, before), "the caller's ratios were changed"
    clamped_o, clamped_s = kernels.compute_relocation(o, s, torch.tensor([1, 1, 10, 10]), table)
    assert torch.equal(new_o, clamped_o) and torch.equal(new_s, clamped_s)
    junk = table + torch.triu(torch.full_like(table, 7.0), diagonal=1)
    junk_o, junk_s = kernels.compute_relocation(o, s, ratios, junk)
    assert torch.equal(junk_o, new_o) and torch.equal(junk_s, new_s)


def test_relocation_refuses_mismatched_shapes():
    with pytest.raises(ValueError, match="scales"):
        kernels.compute_relocation(torch.rand(3), torch.rand(3, 2), torch.ones(3), binomials(5))
    with pytest.raises(ValueError, match="ratios"):
        kernels.compute_relocation(torch.rand(3), torch.rand(3, 3), torch.ones(4), binomials(5))


def rotation_by_axis_angle(q):
    """The rotation of unit quaternion q = (cos t/2, sin t/2 u) as exp(t [u]x)."""
    q = q / q.norm()
    angle = 2 * torch.atan2(q[1:].norm(), q[0])
    axis = q[1:] / q[1:].norm()
    x, y, z = (angle * axis).tolist()
    cross = torch.tensor([[0, -z, y], [z, 0, -x], [-y, x, 0]], dtype=q.dtype)
    return torch.linalg.matrix_exp(cross)


def test_covariance_and_precision_are_r_s_s_rt_and_its_inverse():
    g = torch.Generator().manual_seed(2)
    quats = torch.randn(2, 5, 4, generator=g, dtype=torch.float64) * 3  # not normalised
    scales = torch.rand(2, 5, 3, generator=g, dtype=torch.float64) + 0.05
    covars, precis = kernels.quat_scale_to_covar_preci(quats, scales)
    assert covars.shape == (2, 5, 3, 3) and precis.shape == (2, 5, 3, 3)
    for b in range(2):
        for i in range(5):
            rot = rotation_by_axis_angle(quats[b, i])
            want = rot @ torch.diag(scales[b, i] ** 2) @ rot.T
            assert torch.allclose(covars[b, i], want, rtol=1e-10, atol=1e-12)
            assert torch.allclose(precis[b, i], torch.linalg.inv(want), rtol=1e-8, atol=1e-8)
    covars_t, precis_t = kernels.quat_scale_to_covar_preci(quats, scales, triu=True)
    rows, cols = torch.triu_indices(3, 3)  # row by row: 00 01 02 11 12 22
    assert torch.equal(covars_t, covars[..., rows, cols])
    assert torch.equal(precis_t, precis[..., rows, cols])
    only_covar = kernels.quat_scale_to_covar_preci(quats, scales, compute_preci=False)
    only_preci = kernels.quat_scale_to_covar_preci(quats, scales, compute_covar=False)
    assert only_covar[1] is None and torch.equal(only_covar[0], covars)
    assert only_preci[0] is None and torch.equal(only_preci[1], precis)


def test_covariance_equals_gsplats_torch_reference():
    gs_impl = pytest.importorskip("gsplat.cuda._torch_impl")
    quats, scales = torch.randn(50, 4), torch.rand(50, 3) + 0.01
    for triu in (False, True):
        ours = kernels.quat_scale_to_covar_preci(quats, scales, triu=triu)
        theirs = gs_impl._quat_scale_to_covar_preci(quats, scales, triu=triu)
        for a, b in zip(ours, theirs):
            torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("triu", [False, True])
def test_covariance_gradients_equal_finite_differences(triu):
    g = torch.Generator().manual_seed(3)
    quats = torch.randn(4, 4, generator=g, dtype=torch.float64, requires_grad=True)
    scales = (torch.rand(4, 3, generator=g, dtype=torch.float64) + 0.2).requires_grad_()
    assert torch.autograd.gradcheck(
        lambda q, s: kernels.quat_scale_to_covar_preci(q, s, triu=triu), (quats, scales))


def test_triu_cotangents_are_gsplats_halved_symmetric_ones():
    """gsplat's backward reads a packed cotangent v as the symmetric matrix with v's
    off-diagonal entries halved on both sides: the same gradient as autograd's."""
    quats = torch.randn(6, 4, dtype=torch.float64, requires_grad=True)
    scales = (torch.rand(6, 3, dtype=torch.float64) + 0.2).requires_grad_()
    v = torch.randn(6, 6, dtype=torch.float64)
    covar_t, _ = kernels.quat_scale_to_covar_preci(quats, scales, compute_preci=False, triu=True)
    gq, gs = torch.autograd.grad((covar_t * v).sum(), (quats, scales))
    sym = torch.stack([v[:, 0], v[:, 1] / 2, v[:, 2] / 2,
                       v[:, 1] / 2, v[:, 3], v[:, 4] / 2,
                       v[:, 2] / 2, v[:, 4] / 2, v[:, 5]], -1).reshape(6, 3, 3)
    covar, _ = kernels.quat_scale_to_covar_preci(quats, scales, compute_preci=False)
    hq, hs = torch.autograd.grad((covar * sym).sum(), (quats, scales))
    assert torch.allclose(gq, hq) and torch.allclose(gs, hs)


def ssim_by_windows(img1, img2, padding):
    """SSIM pixel by pixel: each pixel's 11x11 neighbourhood (zeros outside the image)
    weighted by the outer product of the 1-D Gaussian of sigma 1.5, in float64."""
    g = torch.tensor([math.exp(-(x * x) / 4.5) for x in range(-5, 6)], dtype=torch.float64)
    w = torch.outer(g / g.sum(), g / g.sum())
    a = torch.nn.functional.pad(img1.double(), (5, 5, 5, 5))
    b = torch.nn.functional.pad(img2.double(), (5, 5, 5, 5))
    _, _, h, wd = img1.shape
    values = torch.zeros(img1.shape, dtype=torch.float64)
    for i in range(h):
        for j in range(wd):
            pa, pb = a[:, :, i:i + 11, j:j + 11], b[:, :, i:i + 11, j:j + 11]
            m1, m2 = (pa * w).sum((-1, -2)), (pb * w).sum((-1, -2))
            s1 = ((pa * pa * w).sum((-1, -2)) - m1 * m1).clamp(min=0)
            s2 = ((pb * pb * w).sum((-1, -2)) - m2 * m2).clamp(min=0)
            s12 = (pa * pb * w).sum((-1, -2)) - m1 * m2
            c1, c2 = 0.01 ** 2, 0.03 ** 2
            values[:, :, i, j] = ((2 * m1 * m2 + c1) * (2 * s12 + c2)) / (
                (m1 * m1 + m2 * m2 + c1) * (s1 + s2 + c2))
    values = values.clamp(-1, 1)
    if padding == "valid":
        values = values[:, :, 5:-5, 5:-5]
    return values.mean()


@pytest.mark.parametrize("padding", ["same", "valid"])
def test_fused_ssim_is_the_windowed_ssim(padding):
    g = torch.Generator().manual_seed(5)
    img2 = torch.rand(2, 3, 16, 19, generator=g)
    img1 = (img2 + 0.2 * torch.randn(2, 3, 16, 19, generator=g)).clamp(0, 1)
    got = kernels.fused_ssim(img1, img2, padding=padding)
    want = ssim_by_windows(img1, img2, padding)
    assert got.item() == pytest.approx(want.item(), abs=2e-6)
    assert 0.2 < want.item() < 0.95, "a pair neither equal nor unrelated"
    assert kernels.fused_ssim(img2, img2, padding=padding).item() == pytest.approx(1.0, abs=1e-5)


def test_fused_ssim_window_is_the_packages_table():
    # The first entries of fused-ssim's cGauss (ssim.cu).
    w = kernels._ssim_window(torch.float64, torch.device("cpu"))
    assert w[:4].tolist() == pytest.approx(
        [0.001028380123898387, 0.0075987582094967365, 0.036000773310661316,
         0.10936068743467331], rel=1e-7)


def test_fused_ssim_gradients_reach_the_render_only():
    g = torch.Generator().manual_seed(6)
    img1 = torch.rand(1, 2, 12, 13, generator=g, dtype=torch.float64, requires_grad=True)
    img2 = torch.rand(1, 2, 12, 13, generator=g, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a: kernels.fused_ssim(a, img2, "valid"), (img1,))
    kernels.fused_ssim(img1, img2).backward()
    assert img1.grad.abs().sum() > 0 and img2.grad is None
    with pytest.raises(ValueError, match="padding"):
        kernels.fused_ssim(img1, img2, padding="full")
