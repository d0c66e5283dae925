"""GPU and CPU renders through Python against the command line, batches, the GIL and
memory."""

import sys
import threading
import time

import numpy as np
import pytest

import verisplat
from conftest import data, run_cli


def exr_planes(path):
    arr, names = verisplat.read_image(path)
    return {n: arr[..., i] for i, n in enumerate(names)}


@pytest.fixture(scope="module")
def cameras_file(tmp_path_factory, lod3):
    # Cameras both sides parse from one file, so they are the same bit for bit.
    path = tmp_path_factory.mktemp("cams") / "cameras.json"
    verisplat.save_cameras(path, verisplat.orbit(lod3, frames=4, width=160, height=120))
    return path


@pytest.mark.parametrize("cpu", [False, True], ids=["gpu", "cpu"])
def test_render_equals_cli_bit_for_bit(cpu, tmp_path, lod3, renderer, cli, cameras_file):
    cam = verisplat.load_cameras(cameras_file)[1]
    if cpu:
        out = verisplat.render_cpu(lod3, cam)
    else:
        out = renderer.render(lod3, cam)
    exr = tmp_path / "cli.exr"
    args = [data("playbot_lod3_31k_sh2.ply"), "--cameras", cameras_file, "--camera", "1", "-o", exr, "-q"]
    run_cli(cli, "render", *args, *(["--cpu"] if cpu else []))
    p = exr_planes(exr)
    assert out["rgb"].shape == (120, 160, 3) and out["rgb"].dtype == np.float32
    rgb = np.stack([p["R"], p["G"], p["B"]], axis=-1)
    assert np.array_equal(out["rgb"], rgb)
    assert np.array_equal(out["alpha"], p["A"])
    covered = out["alpha"] > 0
    assert covered.mean() > 0.2, "the camera should see the scene"
    # The EXR's Z is +inf where nothing was hit; the array has 0 there.
    assert np.array_equal(out["depth"][covered], p["Z"][covered])
    assert np.all(np.isinf(p["Z"][~covered])) and np.all(out["depth"][~covered] == 0)


def test_png_from_cli_matches_gpu_and_cpu(tmp_path, lod3, renderer, cli, cameras_file):
    cam = verisplat.load_cameras(cameras_file)[2]
    png = tmp_path / "cli.png"
    run_cli(cli, "render", data("playbot_lod3_31k_sh2.ply"), "--cameras", cameras_file,
            "--camera", "2", "-o", png, "-q")
    gpu = renderer.render(lod3, cam, mode="rgb")["rgb"]
    cpu = verisplat.render_cpu(lod3, cam, mode="rgb")["rgb"]
    m = verisplat.compare(png, gpu)
    assert m["within"] == 1.0 and m["max_abs"] <= 0.5 / 255 + 1e-7
    m = verisplat.compare(cpu, gpu)
    assert m["psnr"] >= 55 and m["within"] >= 0.999


def test_reproducible_frames_equal_the_cpu_reference_bit_for_bit(lod3, renderer, cameras_file):
    # lavapipe's pinhole preprocess is the reference's bits; the reproducible mode's blend
    # (the reference's exp) makes the frames so too. The default mode's exp is the
    # device's, so there they differ in the last bits.
    cam = verisplat.load_cameras(cameras_file)[3].resized(320, 240)
    cpu = verisplat.render_cpu(lod3, cam)
    exact = renderer.render(lod3, cam, reproducible=True)
    plain = renderer.render(lod3, cam)
    for plane in ("rgb", "alpha", "depth"):
        assert np.array_equal(exact[plane], cpu[plane]), plane
    assert not all(np.array_equal(plain[p], cpu[p]) for p in ("rgb", "alpha", "depth"))


def test_modes_and_options(lod3, renderer, cameras_file):
    cam = verisplat.load_cameras(cameras_file)[0]
    assert set(renderer.render(lod3, cam, mode="rgb")) == {"rgb"}
    assert set(renderer.render(lod3, cam, mode="rgba")) == {"rgb", "alpha"}
    assert set(renderer.render(lod3, cam, mode="rgb+depth")) == {"rgb", "depth"}
    white = renderer.render(lod3, cam, background=(1, 1, 1))
    black = renderer.render(lod3, cam)
    t = 1 - black["alpha"][..., None]
    assert np.allclose(white["rgb"], black["rgb"] + t, atol=1e-6)
    # Explicit viewmat/K/width/height give the same frame as the Camera.
    same = renderer.render(lod3, viewmat=cam.viewmat, K=cam.K, width=cam.width, height=cam.height)
    assert np.array_equal(same["rgb"], black["rgb"])
    # A lower SH degree and a smaller scale modifier change the image.
    assert not np.array_equal(renderer.render(lod3, cam, sh_degree=0)["rgb"], black["rgb"])
    small = renderer.render(lod3, cam, scale_modifier=0.5)
    assert small["alpha"].sum() < black["alpha"].sum()
    with pytest.raises(ValueError, match="mode"):
        renderer.render(lod3, cam, mode="rgb+normals")
    with pytest.raises(ValueError, match="scale modifier"):
        renderer.render(lod3, cam, scale_modifier=-1)
    with pytest.raises(ValueError, match="camera, or all of viewmat"):
        renderer.render(lod3, viewmat=cam.viewmat)


def test_max_scale_equals_filtered_scene(lod3, renderer, cameras_file):
    cam = verisplat.load_cameras(cameras_file)[3]
    cut = float(np.quantile(lod3.scales.max(axis=1), 0.5))
    per_frame = renderer.render(lod3, cam, max_scale=cut)
    filtered = lod3.filtered(max_scale=cut)
    assert 0 < len(filtered) < len(lod3)
    assert np.array_equal(per_frame["rgb"], renderer.render(filtered, cam)["rgb"])


def test_batch_equals_one_by_one_and_uploads_once(lod3, cameras_file):
    r = verisplat.Renderer()
    cams = verisplat.load_cameras(cameras_file)
    batch = r.render(lod3, cams)
    assert batch["rgb"].shape == (4, 120, 160, 3) and batch["depth"].shape == (4, 120, 160)
    assert r.counters["uploads"] == 1 and r.counters["frames"] == 4
    for i, cam in enumerate(cams):
        one = r.render(lod3, cam)
        for k in ("rgb", "alpha", "depth"):
            assert np.array_equal(batch[k][i], one[k])
    assert r.counters["uploads"] == 1 and r.counters["frames"] == 8
    assert r.counters["scene_bytes"] > 0 and r.counters["frame_bytes"] > 0
    # A (B, 4, 4) viewmat is a batch too.
    vm = np.stack([c.viewmat for c in cams])
    again = r.render(lod3, viewmat=vm, K=cams[0].K, width=160, height=120, mode="rgb")
    assert np.array_equal(again["rgb"], batch["rgb"])
    # Another scene is uploaded once, and coming back uploads the first again.
    other = verisplat.demo()
    r.render(other, cams[0])
    r.render(other, cams[1])
    assert r.counters["uploads"] == 2
    r.render(lod3, cams[0])
    assert r.counters["uploads"] == 3
    with pytest.raises(ValueError, match="one size"):
        r.render(lod3, [cams[0], cams[1].resized(80, 60)])


def test_cpu_batch(demo):
    cams = verisplat.orbit(demo, frames=2, width=64, height=48)
    batch = verisplat.render_cpu(demo, cams)
    assert batch["rgb"].shape == (2, 48, 64, 3)
    assert np.array_equal(batch["rgb"][1], verisplat.render_cpu(demo, cams[1])["rgb"])


def test_timings_and_device(lod3, renderer, cameras_file):
    renderer.render(lod3, verisplat.load_cameras(cameras_file)[0])
    t = renderer.timings
    assert list(t) == ["preprocess", "order", "scan", "keys", "sort", "ranges", "blend", "readback"]
    assert all(v >= 0 for v in t.values()) and sum(t.values()) > 0
    assert isinstance(renderer.device, str) and renderer.device


def test_gil_is_released_while_rendering(lod3):
    # Frames render in a second thread while this one records every stretch of over 1 ms
    # in which it did not run. A render that holds the GIL stops this thread for the whole
    # frame (but for at most a switch interval at either end, while the other thread is
    # still in Python); one that releases it leaves only the pauses of the OS scheduler.
    r = verisplat.Renderer()
    cam = verisplat.default_camera(lod3, 1280, 720)
    r.render(lod3, cam)  # upload and warm up
    done = threading.Event()
    frames = []  # (start, end) of each render, timed by the rendering thread

    def work():
        for _ in range(3):
            start = time.perf_counter()
            r.render(lod3, cam)
            frames.append((start, time.perf_counter()))
        done.set()

    pauses = []  # (from, to) of each stretch of over 1 ms without this thread running
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(0.001)
    try:
        thread = threading.Thread(target=work)
        last = time.perf_counter()
        thread.start()
        while not done.is_set():
            now = time.perf_counter()
            if now - last > 0.001:
                pauses.append((last, now))
            last = now
        now = time.perf_counter()  # after the last frame ended
        if now - last > 0.001:
            pauses.append((last, now))
        thread.join()
    finally:
        sys.setswitchinterval(switch_interval)
    assert len(frames) == 3
    assert sum(end - start for start, end in frames) > 0.05
    for start, end in frames:
        # The longest time this thread stood still within the frame.
        still = max((min(b, end) - max(a, start) for a, b in pauses), default=0.0)
        assert still < (end - start) / 2, (
            f"the main thread stood still for {still * 1e3:.1f} ms of a "
            f"{(end - start) * 1e3:.1f} ms frame: the render holds the GIL"
        )


def _rss_bytes():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


def test_memory_stays_flat_over_200_frames(demo):
    r = verisplat.Renderer()
    cams = verisplat.orbit(demo, frames=8, width=128, height=96)
    for i in range(20):
        out = r.render(demo, cams[i % 8])
    before = _rss_bytes()
    for i in range(200):
        out = r.render(demo, cams[i % 8])
        cpu_view = out["rgb"].mean()
    after = _rss_bytes()
    assert np.isfinite(cpu_view)
    # A leaked frame (128 x 96 x 5 floats) per render would add 50 MB.
    assert after - before < 12 * 2**20, f"RSS grew by {(after - before) / 2**20:.1f} MiB"


def test_device_errors():
    with pytest.raises(RuntimeError, match="no-such-device"):
        verisplat.Renderer(device="no-such-device")


def test_features_and_power_kernel_equal_the_cli(tmp_path, cli, cameras_file, renderer):
    base = verisplat.load(data("playbot_lod3_31k_sh2.ply"))
    n, k = len(base), 5
    feats = np.random.default_rng(4).uniform(-1, 2, (n, k)).astype(np.float32)
    scene = verisplat.Scene.from_arrays(**base.raw(), activated=False, features=feats)
    assert scene.feature_count == k and np.array_equal(scene.features, feats)
    assert base.features is None and base.kernel == "gaussian"
    cam = verisplat.load_cameras(cameras_file)[1]
    npy = tmp_path / "f.npy"
    np.save(npy, feats)
    for kernel in ("gaussian", "power"):
        out = tmp_path / f"cli_{kernel}.npy"
        run_cli(cli, "render", data("playbot_lod3_31k_sh2.ply"), "--features", npy, "--mode",
                "features", "--kernel", kernel, "--cameras", cameras_file, "--camera", "1",
                "-o", out, "-q")
        gpu = renderer.render(scene, cam, mode="features+alpha", kernel=kernel)
        assert gpu["features"].shape == (120, 160, k)
        assert np.array_equal(gpu["features"], np.load(out)), kernel
        cpu = verisplat.render_cpu(scene, cam, mode="features", kernel=kernel)
        for c in range(k):
            m = verisplat.compare(cpu["features"][..., c], gpu["features"][..., c], kind="data")
            assert m["psnr"] >= 55, (kernel, c, m)
    g = renderer.render(scene, cam, mode="rgb")["rgb"]
    p = renderer.render(scene, cam, mode="rgb", kernel="power")["rgb"]
    assert not np.array_equal(g, p)
    with pytest.raises(ValueError, match="needs feature channels"):
        renderer.render(base, cam, mode="features")
    with pytest.raises(ValueError, match="kernel"):
        renderer.render(base, cam, kernel="cubic")


@pytest.mark.parametrize("cpu", [False, True], ids=["gpu", "cpu"])
def test_normal_and_median_depth_equal_the_cli(cpu, tmp_path, lod3, renderer, cli, cameras_file):
    cam = verisplat.load_cameras(cameras_file)[1]
    render = verisplat.render_cpu if cpu else renderer.render
    out = render(lod3, cam, mode="normal+median-depth+alpha")
    assert set(out) == {"normal", "median_depth", "alpha"}
    assert out["normal"].shape == (120, 160, 3) and out["median_depth"].shape == (120, 160)
    scene = data("playbot_lod3_31k_sh2.ply")
    flags = ["--cameras", cameras_file, "--camera", "1", "-q", *(["--cpu"] if cpu else [])]
    run_cli(cli, "render", scene, "--mode", "normal", "-o", tmp_path / "n.exr", *flags)
    run_cli(cli, "render", scene, "--mode", "median-depth", "-o", tmp_path / "m.exr", *flags)
    n, m = exr_planes(tmp_path / "n.exr"), exr_planes(tmp_path / "m.exr")
    assert set(n) == {"N.x", "N.y", "N.z", "A"} and set(m) == {"Z"}
    assert np.array_equal(out["normal"], np.stack([n["N.x"], n["N.y"], n["N.z"]], axis=-1))
    assert np.array_equal(out["alpha"], n["A"])
    hit = out["median_depth"] > 0
    assert 0.2 < hit.mean() < out["alpha"].astype(bool).mean() + 1e-9
    assert np.array_equal(out["median_depth"][hit], m["Z"][hit])
    assert np.all(np.isinf(m["Z"][~hit]))
    # Unit normals where anything is hit, 0 elsewhere; mostly facing the camera (-z).
    covered = out["alpha"] > 0
    length = np.linalg.norm(out["normal"], axis=-1)
    assert np.allclose(length[covered], 1, atol=1e-5) and np.all(length[~covered] == 0)
    assert (out["normal"][..., 2][out["alpha"] > 0.5] < 0).mean() > 0.9
    # World space is camera space turned back by the camera's rotation.
    world = render(lod3, cam, mode="normal", normal_space="world")["normal"]
    rotation = np.asarray(cam.viewmat, dtype=np.float64)[:3, :3]
    assert np.abs(world @ rotation.T - out["normal"]).max() < 1e-5


def test_normal_and_median_depth_gpu_against_cpu_and_refusals(lod3, renderer, cameras_file):
    cam = verisplat.load_cameras(cameras_file)[2]
    gpu = renderer.render(lod3, cam, mode="normal+median-depth")
    cpu = verisplat.render_cpu(lod3, cam, mode="normal+median-depth")
    for c in range(3):
        m = verisplat.compare(cpu["normal"][..., c], gpu["normal"][..., c], kind="data")
        assert m["psnr"] >= 55, (c, m)
    agree = np.isclose(gpu["median_depth"], cpu["median_depth"], rtol=1e-4, atol=0)
    assert agree.mean() >= 0.999
    # The colour planes of a surface render are the plain render's.
    both = renderer.render(lod3, cam, mode="rgb+normal")
    assert np.array_equal(both["rgb"], renderer.render(lod3, cam, mode="rgb")["rgb"])
    with pytest.raises(ValueError, match="separate"):
        renderer.render(lod3, cam, mode="features+normal")
    with pytest.raises(ValueError, match="normal_space"):
        renderer.render(lod3, cam, mode="normal", normal_space="view")
