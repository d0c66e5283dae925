"""The notebook turntable, driven headless through its event handlers."""

import numpy as np
import pytest

import verisplat
from conftest import data, run_cli

from verisplat import widgets  # the notebook extra: pip install "./python[notebook,test]"


def shown(tt, tmp_path, name="shown.png"):
    """The image the widget shows once the view rests, decoded."""
    tt.wait()
    path = tmp_path / name
    path.write_bytes(tt.image.value)
    return verisplat.read_image(path)[0]


def test_drag_turns_the_view_and_the_image(lod3, renderer, tmp_path):
    tt = widgets.Turntable(lod3, width=96, height=72, renderer=renderer)
    first = shown(tt, tmp_path)
    assert first.shape == (72, 96, 3) and first.max() > 0
    cam0 = tt.camera
    radius = np.linalg.norm(cam0.position - tt.focus)
    tt._handle_event({"type": "mousedown", "relativeX": 10, "relativeY": 30, "buttons": 1})
    tt._handle_event({"type": "mousemove", "relativeX": 40, "relativeY": 36, "buttons": 1})
    tt._handle_event({"type": "mouseup", "relativeX": 40, "relativeY": 36})
    cam1 = tt.camera
    assert not np.allclose(cam0.viewmat, cam1.viewmat)
    # Turned around the focus: same distance, still looking at it.
    assert np.linalg.norm(cam1.position - tt.focus) == pytest.approx(radius, rel=1e-4)
    ahead = cam1.viewmat @ np.append(tt.focus, 1.0)
    assert abs(ahead[0]) < 1e-3 * radius and abs(ahead[1]) < 1e-3 * radius and ahead[2] > 0
    turned = shown(tt, tmp_path)
    assert verisplat.compare(first, turned)["psnr"] < 40
    # What it shows is the renderer's image of its camera.
    direct = renderer.render(lod3, cam1, mode="rgb")["rgb"]
    assert verisplat.compare(direct, turned)["within"] == 1.0
    # Moving without a button pressed does nothing.
    tt._handle_event({"type": "mousemove", "relativeX": 90, "relativeY": 10, "buttons": 0})
    assert np.array_equal(tt.camera.viewmat, cam1.viewmat)
    assert "GPU" in tt.info.value and "blend" in tt.info.value


def test_wheel_zooms(lod3, renderer):
    tt = widgets.Turntable(lod3, width=64, height=48, renderer=renderer)
    d0 = np.linalg.norm(tt.camera.position - tt.focus)
    tt._handle_event({"type": "wheel", "deltaY": 100})
    d1 = np.linalg.norm(tt.camera.position - tt.focus)
    assert d1 == pytest.approx(d0 * widgets.WHEEL_ZOOM, rel=1e-4)
    tt._handle_event({"type": "wheel", "deltaY": -200})
    assert np.linalg.norm(tt.camera.position - tt.focus) < d0


def test_slider_filters_like_render_max_scale(lod3, renderer, tmp_path, cli):
    tt = widgets.Turntable(lod3, width=96, height=72, renderer=renderer)
    all_shown = shown(tt, tmp_path, "all.png")
    assert tt.max_scale is None
    cut = float(np.quantile(lod3.scales.max(axis=1), 0.3))
    tt.slider.value = cut  # observers re-render
    assert tt.max_scale == pytest.approx(cut, rel=1e-6)
    filtered = shown(tt, tmp_path, "filtered.png")
    assert verisplat.compare(all_shown, filtered)["psnr"] < 40
    cams = tmp_path / "cams.json"
    verisplat.save_cameras(cams, [tt.camera])
    png = tmp_path / "cli.png"
    run_cli(cli, "render", data("playbot_lod3_31k_sh2.ply"), "--cameras", cams,
            "--max-scale", repr(tt.max_scale), "-o", png, "-q")
    cli_img = verisplat.read_image(png)[0]
    m = verisplat.compare(cli_img, filtered)
    assert m["within"] == 1.0, m


def test_given_camera_is_the_first_view(lod3, renderer, tmp_path):
    cam = verisplat.orbit(lod3, frames=4, width=80, height=60)[1]
    tt = widgets.Turntable(lod3, camera=cam, width=80, height=60, renderer=renderer)
    assert np.array_equal(tt.camera.viewmat, cam.viewmat)
    direct = renderer.render(lod3, cam, mode="rgb")["rgb"]
    assert verisplat.compare(direct, shown(tt, tmp_path))["within"] == 1.0


def test_a_lens_stays_through_drags_and_zooms(lod3, renderer, tmp_path):
    cam = verisplat.orbit(lod3, frames=4, width=80, height=60)[1]
    K = cam.K.copy()
    K[0, 0] = K[1, 1] = 60 / np.radians(190)  # 190 degrees across the shorter side
    fish = verisplat.Camera(cam.viewmat, K, 80, 60, "fish", {"kind": "fisheye", "k": [0, 0, 0, 0]})
    tt = widgets.Turntable(lod3, camera=fish, width=80, height=60, renderer=renderer)
    tt._handle_event({"type": "mousedown", "relativeX": 10, "relativeY": 30, "buttons": 1})
    tt._handle_event({"type": "mousemove", "relativeX": 35, "relativeY": 35, "buttons": 1})
    tt._handle_event({"type": "mouseup", "relativeX": 35, "relativeY": 35})
    tt._handle_event({"type": "wheel", "deltaY": 120})
    assert tt.camera.lens == fish.lens and np.array_equal(tt.camera.K, K)
    assert not np.allclose(tt.camera.viewmat, fish.viewmat)
    direct = renderer.render(lod3, tt.camera, mode="rgb")["rgb"]
    assert verisplat.compare(direct, shown(tt, tmp_path))["within"] == 1.0


def test_example_notebook_runs():
    """python/examples/turntable.ipynb's code cells run in order, headless."""
    import json
    import pathlib

    nb = json.loads((pathlib.Path(__file__).parents[1] / "examples" / "turntable.ipynb").read_text())
    ns = {}
    code = [("".join(c["source"])) for c in nb["cells"] if c["cell_type"] == "code"]
    assert len(code) >= 3
    for src in code:
        exec(compile(src, "turntable.ipynb", "exec"), ns)
    assert isinstance(ns["tt"], widgets.Turntable) and ns["tt"].image.value[:4] == b"\x89PNG"
    assert verisplat.compare(ns["ref"]["rgb"], ns["out"]["rgb"])["psnr"] >= 55


def test_a_fast_drag_draws_the_latest_pose_only_with_previews(lod3, renderer, tmp_path):
    """30 mouse moves in a burst do not queue 30 renders (each took 309 ms on the 31k
    scene): the handler returns at once, the render thread draws the newest pose when it
    is free, at a reduced size while the view moves, and the full frame when it rests."""
    import time

    tt = widgets.Turntable(lod3, width=192, height=144, renderer=renderer)
    start = time.perf_counter()
    tt.render()
    one_render = time.perf_counter() - start
    frames = tt.frames
    tt._handle_event({"type": "mousedown", "relativeX": 0, "relativeY": 50, "buttons": 1})
    start = time.perf_counter()
    for k in range(1, 31):
        tt._handle_event({"type": "mousemove", "relativeX": 3 * k, "relativeY": 50, "buttons": 1})
    handling = time.perf_counter() - start
    # The events only move the camera: far less than one render each (the old handler
    # rendered each one: 30 renders).
    assert handling < 5 * one_render + 0.02, (handling, one_render)
    # While the button is held the frames are previews, smaller than the widget.
    deadline = time.monotonic() + 60
    while tt.previews == 0:
        assert time.monotonic() < deadline, "no preview"
        time.sleep(0.01)
    assert tt.preview_size[0] < 192 and tt.preview_size[1] < 144, tt.preview_size
    last = tt.camera
    tt._handle_event({"type": "mouseup", "relativeX": 90, "relativeY": 50})
    tt.wait()
    drawn = tt.frames - frames
    assert 1 <= drawn <= 10, drawn  # not 30
    # At rest: the full size, and the renderer's image of the last pose.
    assert tt.shown_size == (192, 144)
    direct = renderer.render(lod3, last, mode="rgb")["rgb"]
    assert verisplat.compare(direct, shown(tt, tmp_path))["within"] == 1.0
    # Without a mouse-up (a wheel turn), the full frame follows by itself.
    tt._handle_event({"type": "wheel", "deltaY": 100})
    tt.wait()
    assert tt.shown_size == (192, 144)
    direct = renderer.render(lod3, tt.camera, mode="rgb")["rgb"]
    assert verisplat.compare(direct, shown(tt, tmp_path, "wheel.png"))["within"] == 1.0
