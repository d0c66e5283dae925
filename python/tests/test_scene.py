"""Scenes and cameras: loading, arrays, from_arrays round trips and its errors, saving."""

import json
import os

import numpy as np
import pytest

import verisplat
from conftest import data


def test_arrays_of_a_loaded_scene(lod3):
    n = len(lod3)
    assert n > 30_000
    assert lod3.means.shape == (n, 3) and lod3.means.dtype == np.float32
    assert lod3.quats.shape == (n, 4)
    assert np.allclose(np.linalg.norm(lod3.quats, axis=1), 1, atol=1e-5)
    assert lod3.scales.shape == (n, 3) and np.all(lod3.scales > 0)
    assert lod3.opacities.shape == (n,) and np.all((lod3.opacities >= 0) & (lod3.opacities <= 1))
    assert lod3.sh.shape == (n, 9, 3) and lod3.sh_degree == 2
    raw = lod3.raw()
    assert np.allclose(np.exp(raw["scales"]), lod3.scales, rtol=1e-6, atol=0)
    assert np.allclose(1 / (1 + np.exp(-raw["opacities"])), lod3.opacities, atol=1e-6)
    with pytest.raises(ValueError):
        lod3.means[0, 0] = 1.0  # read-only views


@pytest.mark.parametrize("activated", [True, False], ids=["activated", "raw"])
def test_from_arrays_renders_identically(activated, lod3, renderer):
    arrays = (
        dict(means=lod3.means, quats=lod3.quats, scales=lod3.scales,
             opacities=lod3.opacities, sh=lod3.sh)
        if activated else lod3.raw()
    )
    built = verisplat.Scene.from_arrays(**arrays, activated=activated)
    assert len(built) == len(lod3) and built.sh_degree == lod3.sh_degree
    cam = verisplat.default_camera(lod3, 160, 120)
    a, b = renderer.render(lod3, cam), renderer.render(built, cam)
    for k in a:
        assert np.array_equal(a[k], b[k]), k
    assert np.array_equal(verisplat.render_cpu(lod3, cam)["rgb"], verisplat.render_cpu(built, cam)["rgb"])


def test_from_arrays_float64_and_colors(demo, renderer):
    n = len(demo)
    s = verisplat.Scene.from_arrays(
        demo.means.astype(np.float64), demo.quats, demo.scales, demo.opacities,
        colors=np.full((n, 3), 0.25),
    )
    assert s.sh_degree == 0 and s.sh.shape == (n, 1, 3)
    cam = verisplat.default_camera(s, 64, 48)
    out = renderer.render(s, cam, mode="rgba")
    covered = out["alpha"] > 0.5
    # Colour 0.25 everywhere: the premultiplied colour is 0.25 * alpha.
    assert np.allclose(out["rgb"][covered], 0.25 * out["alpha"][covered][:, None], atol=1e-5)


def _good(n=3):
    return dict(
        means=np.zeros((n, 3), np.float32),
        quats=np.tile(np.array([1, 0, 0, 0], np.float32), (n, 1)),
        scales=np.full((n, 3), 0.1, np.float32),
        opacities=np.full(n, 0.5, np.float32),
        sh=np.zeros((n, 1, 3), np.float32),
    )


@pytest.mark.parametrize(
    "change, error, message",
    [
        (dict(means=np.zeros((3, 2), np.float32)), ValueError, r"means must have shape \(N, 3\)"),
        (dict(quats=np.zeros((2, 4), np.float32) + 1), ValueError, r"quats must have shape \(3, 4\)"),
        (dict(scales=np.zeros((3, 3), np.int32)), TypeError, "scales must be an array of floats"),
        (dict(sh=np.zeros((3, 5, 3), np.float32)), ValueError, "1, 4, 9 or 16"),
        (dict(means=np.array([[0, 0, 0], [0, np.nan, 0], [0, 0, 0]], np.float32)), ValueError,
         r"means\[1\] is NaN; every value must be finite"),
        (dict(opacities=np.array([0.5, np.inf, 0.5], np.float32)), ValueError, r"opacities\[1\] is inf"),
        (dict(scales=np.array([[0.1] * 3, [0.1] * 3, [0.1, -0.2, 0.1]], np.float32)), ValueError,
         r"scales\[2\] is -0.2; activated scales must be positive"),
        (dict(quats=np.array([[1, 0, 0, 0], [0, 0, 0, 0], [1, 0, 0, 0]], np.float32)), ValueError,
         r"quats\[1\] is \[0.0, 0.0, 0.0, 0.0\], a zero quaternion"),
        (dict(opacities=np.array([0.5, 1.5, 0.5], np.float32)), ValueError, r"opacities\[1\] is 1.5"),
    ],
    ids=["means-shape", "n-mismatch", "int-dtype", "sh-coeffs", "nan", "inf", "negative-scale",
         "zero-quat", "opacity-range"],
)
def test_from_arrays_errors(change, error, message):
    arrays = {**_good(), **change}
    with pytest.raises(error, match=message):
        verisplat.Scene.from_arrays(**arrays)


def test_from_arrays_needs_one_colour_source():
    arrays = _good()
    with pytest.raises(ValueError, match="exactly one of sh"):
        verisplat.Scene.from_arrays(**arrays, colors=np.zeros((3, 3)))


def test_save_and_load_round_trip(tmp_path, demo):
    path = tmp_path / "out.ply"
    demo.save(path)
    back = verisplat.load(path)
    for k in ("means", "quats", "scales", "opacities", "sh"):
        assert np.array_equal(getattr(back, k), getattr(demo, k)), k
    with pytest.raises(FileExistsError, match="out.ply"):
        demo.save(path)
    demo.save(path, overwrite=True)
    with pytest.raises(ValueError, match="out.xyz"):
        demo.save(tmp_path / "out.xyz")


def test_spz_axes_raw_is_the_spec_turned_about_x(tmp_path, demo):
    spec, raw = tmp_path / "spec.spz", tmp_path / "raw.spz"
    demo.save(spec)
    demo.save(raw, spz_axes="raw")
    assert spec.read_bytes() != raw.read_bytes()
    # Read in the axes it was written in: the scene, within SPZ's 1/4096 position step.
    for path, axes in ((spec, "spec"), (raw, "raw")):
        back = verisplat.load(path, spz_axes=axes)
        assert np.abs(back.means - demo.means).max() <= 0.5 / 4096 + 1e-6, axes
    # Read in the other axes: exactly the 180-degree turn about x (y and z negated).
    as_spec = verisplat.load(raw)
    as_raw = verisplat.load(raw, spz_axes="raw")
    assert np.array_equal(as_spec.means * np.array([1, -1, -1], np.float32), as_raw.means)
    assert np.array_equal(as_spec.quats * np.array([1, 1, -1, -1], np.float32), as_raw.quats)
    with pytest.raises(ValueError, match="unknown SPZ axes"):
        verisplat.load(raw, spz_axes="rub")
    with pytest.raises(ValueError, match="not SPZ"):
        verisplat.load(data("playbot_lod6_1873_sh2.ply"), spz_axes="raw")
    with pytest.raises(ValueError, match="applies to SPZ only"):
        demo.save(tmp_path / "x.ply", spz_axes="raw")


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.ply"):
        verisplat.load(tmp_path / "missing.ply")
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 2\nend_header\n")
    with pytest.raises(ValueError, match="bad.ply"):
        verisplat.load(bad)


def test_cameras_round_trip_and_errors(tmp_path, lod3):
    cams = verisplat.orbit(lod3, frames=3, width=100, height=80)
    assert [c.name for c in cams] == ["orbit_00000", "orbit_00001", "orbit_00002"]
    path = tmp_path / "cams.json"
    verisplat.save_cameras(path, cams)
    back = verisplat.load_cameras(path)
    for a, b in zip(cams, back):
        assert np.array_equal(a.K, b.K) and (a.width, a.height) == (b.width, b.height)
        assert np.allclose(a.viewmat, b.viewmat, atol=1e-6)
    assert len(json.loads(path.read_text())) == 3
    real = verisplat.load_cameras(data("playbot_orbit_cameras.synthetic.json"))
    assert len(real) > 1 and real[0].viewmat.shape == (4, 4)
    with pytest.raises(FileExistsError):
        verisplat.save_cameras(path, cams)
    with pytest.raises(FileNotFoundError):
        verisplat.load_cameras(tmp_path / "none.json")
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(ValueError, match="broken.json"):
        verisplat.load_cameras(tmp_path / "broken.json")
    with pytest.raises(ValueError, match="K must be"):
        verisplat.Camera(np.eye(4), np.eye(3) * 2, 10, 10)


def test_look_at_and_camera_conventions(demo, renderer):
    cam = verisplat.look_at(eye=(0, 0, -3), target=(0, 0, 0), up=(0, -1, 0), width=64, height=48)
    assert np.allclose(cam.position, [0, 0, -3], atol=1e-6)
    # OpenCV axes: the camera looks along +z of its frame; the target is straight ahead.
    p = cam.viewmat @ np.array([0, 0, 0, 1.0])
    assert p[2] > 0 and abs(p[0]) < 1e-6 and abs(p[1]) < 1e-6
    assert cam.K[0, 2] == 32 and cam.K[1, 2] == 24


def test_errors_name_python_arguments_not_cli_flags(tmp_path):
    # Issue 29: scene.save(existing) said "pass --overwrite", filtered(sh_degree=9)
    # "--sh-degree must be 0..3".
    scene = verisplat.demo()
    out = tmp_path / "scene.ply"
    scene.save(out)
    with pytest.raises(FileExistsError) as e:
        scene.save(out)
    assert "overwrite=True" in str(e.value) and "--" not in str(e.value)
    with pytest.raises(ValueError) as e:
        scene.filtered(sh_degree=9)
    assert "sh_degree must be 0..3" in str(e.value) and "--" not in str(e.value)
    cams = tmp_path / "cams.json"
    verisplat.save_cameras(cams, verisplat.orbit(scene, frames=2, width=32, height=32))
    with pytest.raises(FileExistsError) as e:
        verisplat.save_cameras(cams, verisplat.orbit(scene, frames=2, width=32, height=32))
    assert "overwrite=True" in str(e.value) and "--" not in str(e.value)


def test_a_count_mismatch_blames_the_array_that_disagrees():
    # Issue 29: means of (N+1, 3) with the rest (N, ...) said "quats must have shape
    # (N+1, 4)"; the odd one out is means.
    n = 1000
    rest = dict(
        quats=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
        scales=np.full((n, 3), 0.1, np.float32),
        opacities=np.full(n, 0.5, np.float32),
        colors=np.full((n, 3), 0.5, np.float32),
    )
    with pytest.raises(ValueError, match=r"means must have shape \(1000, 3\) .* got \(1001, 3\)"):
        verisplat.Scene.from_arrays(np.zeros((n + 1, 3), np.float32), **rest)
    # One other array off: that one is named, against means.
    rest["quats"] = rest["quats"][:-1]
    with pytest.raises(ValueError, match=r"quats must have shape \(1000, 4\), got \(999, 4\)"):
        verisplat.Scene.from_arrays(np.zeros((n, 3), np.float32), **rest)


def test_impossible_cameras_colours_and_sh_degrees_are_refused():
    # Issue 29: look_at(eye == target) and up=(0,0,0) gave an identity camera, colours
    # outside [0, 1] were taken, sh_degree above the scene's was accepted.
    with pytest.raises(ValueError, match="same point"):
        verisplat.look_at(eye=(1, 2, 3), target=(1, 2, 3))
    with pytest.raises(ValueError, match="up must be a non-zero vector"):
        verisplat.look_at(eye=(0, 0, -3), target=(0, 0, 0), up=(0, 0, 0))
    with pytest.raises(ValueError, match="parallel"):
        verisplat.look_at(eye=(0, 0, -3), target=(0, 0, 0), up=(0, 0, 2))
    arrays = _good()
    del arrays["sh"]
    with pytest.raises(ValueError, match=r"colors\[1\] is \[0.5, 1.5, 0.5\]; colors must be in \[0, 1\]"):
        verisplat.Scene.from_arrays(**arrays, colors=np.float32([[0.5] * 3, [0.5, 1.5, 0.5], [0.5] * 3]))
    flat = verisplat.Scene.from_arrays(**arrays, colors=np.full((3, 3), 0.5, np.float32))
    cam = verisplat.look_at(eye=(0, 0, -3), target=(0, 0, 0), width=16, height=16)
    with pytest.raises(ValueError, match="sh_degree 2 exceeds the scene's SH degree 0"):
        verisplat.render_cpu(flat, cam, sh_degree=2)


class _FakeTensor:
    """Behaves as a torch tensor that requires grad: no direct numpy conversion."""

    def __init__(self, array):
        self._a = np.asarray(array)

    def __array__(self, *args, **kwargs):
        raise RuntimeError("Can't call numpy() on Tensor that requires grad.")

    def detach(self):
        return self

    def cpu(self):
        return self

    def numpy(self):
        return self._a


def test_what_gsplat_users_pass_is_accepted():
    # Issue 29: batched Ks (C, 3, 3) were refused, tensors that require grad failed in
    # numpy's conversion, lists of Python ints raised TypeError.
    scene = verisplat.Scene.from_arrays(
        means=[[0, 0, 0], [0.2, 0, 0]],
        quats=_FakeTensor(np.tile(np.float32([1, 0, 0, 0]), (2, 1))),
        scales=[[0.1, 0.1, 0.1], [0.1, 0.1, 0.1]],
        opacities=_FakeTensor(np.float32([0.9, 0.9])),
        colors=[[1, 0, 0], [0, 1, 0]],
    )
    assert len(scene) == 2
    view = verisplat.look_at(eye=(0, 0, -3), target=(0, 0, 0), width=32, height=24)
    viewmats = np.stack([view.viewmat, view.viewmat])
    ks = np.stack([view.K, view.K])
    ks[1, 0, 0] *= 2  # a longer focal length for the second view
    ks[1, 1, 1] *= 2
    out = verisplat.render_cpu(scene, viewmat=_FakeTensor(viewmats), K=ks, width=32, height=24)
    assert out["rgb"].shape == (2, 24, 32, 3)
    single = [
        verisplat.render_cpu(scene, viewmat=viewmats[i], K=ks[i], width=32, height=24)["rgb"]
        for i in range(2)
    ]
    assert np.array_equal(out["rgb"][0], single[0]) and np.array_equal(out["rgb"][1], single[1])
    assert not np.array_equal(single[0], single[1])
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\) or \(2, 3, 3\)"):
        verisplat.render_cpu(scene, viewmat=viewmats, K=np.stack([view.K] * 3), width=32, height=24)


def test_compare_refuses_nan_and_infinite_values():
    # Issue 29: NaN input gave psnr nan and "100 % of pixels within 1/255".
    nan = np.full((4, 4, 3), np.nan, dtype=np.float32)
    zero = np.zeros((4, 4, 3), dtype=np.float32)
    with pytest.raises(ValueError, match="reference has 48 values that are NaN or infinite"):
        verisplat.compare(nan, zero)
    inf = zero.copy()
    inf[2, 1, 0] = np.inf
    with pytest.raises(ValueError, match=r"test has 1 values .* row 2, column 1, channel 0"):
        verisplat.compare(zero, inf)


def test_compare_metrics(tmp_path):
    rng = np.random.default_rng(1)
    a = rng.random((32, 48, 3), dtype=np.float32) * 0.5 + 0.25
    same = verisplat.compare(a, a)
    assert same["psnr"] == float("inf") and same["ssim"] == pytest.approx(1.0) and same["flip"] == 0
    shifted = verisplat.compare(a, a + np.float32(0.01))
    # A constant offset d has PSNR -20 log10(d).
    assert shifted["psnr"] == pytest.approx(40.0, abs=1e-3)
    assert shifted["max_abs"] == pytest.approx(0.01, abs=1e-6)
    u8 = (a * 255).round().astype(np.uint8)
    assert verisplat.compare(u8, u8)["psnr"] == float("inf")
    with pytest.raises(ValueError, match="differ in shape"):
        verisplat.compare(a, a[:10])
    with pytest.raises(TypeError, match="dtype"):
        verisplat.compare(a.astype(np.complex64), a)
    with pytest.raises(ValueError, match="kind"):
        verisplat.compare(a, a, kind="colours")


def test_the_tests_run_from_the_package_folder_too():
    # Issue 29: `cd python && python -m pytest` failed with a circular import: python/
    # came first on sys.path and its source shadowed the installed package.
    import subprocess
    import sys
    from pathlib import Path

    package_folder = Path(__file__).resolve().parents[1]
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "tests/test_scene.py"],
        cwd=package_folder,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert "test_the_tests_run_from_the_package_folder_too" in run.stdout


def test_save_image_writes_what_render_writes_and_keeps_existing_files(tmp_path, demo):
    # Issue 29: no writer for the numpy outputs.
    cam = verisplat.look_at(eye=(0, -0.5, -3), target=(0, -0.5, 0), width=40, height=30)
    out = verisplat.render_cpu(demo, cam)
    png = tmp_path / "frame.png"
    verisplat.save_image(png, out)
    back, names = verisplat.read_image(png)
    assert names[:3] == ["R", "G", "B"] and back.shape[:2] == (30, 40)
    want = (np.clip(out["rgb"], 0, 1) * 255 + 0.5).astype(np.uint8) / 255.0
    assert np.allclose(back[..., :3], want, atol=1e-6)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        verisplat.save_image(png, out["rgb"])
    exr = tmp_path / "frame.exr"
    verisplat.save_image(exr, out["rgb"], alpha=out["alpha"], depth=out["depth"])
    back, names = verisplat.read_image(exr)
    assert names == ["R", "G", "B", "A", "Z"]
    assert np.array_equal(back[..., :3], out["rgb"]) and np.array_equal(back[..., 3], out["alpha"])
    with pytest.raises(ValueError, match=r"alpha must have shape \(30, 40\)"):
        verisplat.save_image(tmp_path / "bad.exr", out["rgb"], alpha=out["alpha"][:-1])
    assert not (tmp_path / "bad.exr").exists()


def test_save_turntable_writes_a_png_sequence_without_a_video_writer(tmp_path, demo):
    stem = tmp_path / "turn.png"
    files = verisplat.save_turntable(stem, demo, frames=3, width=32, height=24)
    assert [os.path.basename(f) for f in files] == ["turn_0000.png", "turn_0001.png", "turn_0002.png"]
    first, _ = verisplat.read_image(files[0])
    second, _ = verisplat.read_image(files[1])
    assert first.shape[:2] == (24, 32) and not np.array_equal(first, second)
    with pytest.raises(FileExistsError, match="turn_0000.png"):
        verisplat.save_turntable(stem, demo, frames=3, width=32, height=24)


def test_save_compressed_ply_and_sog(tmp_path, demo):
    # Both PlayCanvas formats by name, read back within their quantisation: positions
    # within half an 11-bit step of a chunk's box (compressed PLY) or of the 16-bit
    # log-transformed range (SOG); the writers reorder the Gaussians (Morton order).
    for name in ("d.compressed.ply", "d.sog", "d_sog/meta.json"):
        demo.save(tmp_path / name)
        back = verisplat.load(tmp_path / name)
        assert len(back) == len(demo) and back.sh_degree == demo.sh_degree, name
        got = np.sort(back.means, axis=0)
        want = np.sort(demo.means, axis=0)
        assert np.abs(got - want).max() < 2e-3, name
        with pytest.raises(FileExistsError):
            demo.save(tmp_path / name)
    assert (tmp_path / "d_sog" / "quats.webp").is_file()
    with pytest.raises(ValueError, match="holds no Gaussians"):
        demo.filtered(min_opacity=1.0).save(tmp_path / "empty.sog")
