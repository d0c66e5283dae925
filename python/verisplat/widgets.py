"""A notebook turntable: ``Turntable(scene)`` shows the scene rendered by verisplat's Vulkan
pipeline, turned by dragging and zoomed with the wheel, with a max-scale slider that
re-renders as it moves and the GPU stage timings under the image.

As in the browser viewer (``verisplat view``), the latest view wins: events only move the
camera, and one render thread draws the newest pose when it is free, so a fast drag never
queues renders. While the view moves, frames are previews at a reduced size (scaled so a
preview takes about ``PREVIEW_MS``); once it rests (the mouse released, or ``REST_S``
after the last move) the view is drawn at full size.

Needs the notebook extra: ``pip install "./python[notebook]"`` (ipywidgets, ipyevents).
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any, Dict, Optional

import numpy as np

from . import Camera, Renderer, Scene, _native, default_camera, look_at

try:
    import ipywidgets as _w
    from ipyevents import Event as _Event
except ImportError as e:  # pragma: no cover - depends on the environment
    raise ImportError(
        'verisplat.widgets needs ipywidgets and ipyevents: pip install "./python[notebook]"'
    ) from e

__all__ = ["Turntable"]

#: Radians of rotation per pixel dragged.
DRAG_RADIANS_PER_PIXEL = 0.01
#: Zoom factor per 100 units of wheel delta (one notch on most mice).
WHEEL_ZOOM = 1.15
#: Elevation limit, radians from the up axis, so the view never flips over the pole.
POLE_MARGIN = math.radians(2.0)
#: A preview (a frame while the view moves) should take about this long, ms.
PREVIEW_MS = 60.0
#: Previews have at least this share of the full size's pixels (a side of at least half).
MIN_PREVIEW_SHARE = 0.25
#: The view is drawn at full size this long after the last move without a mouse-up, s.
REST_S = 0.25


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation of ``v`` about the unit ``axis``."""
    c, s = math.cos(angle), math.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * float(np.dot(axis, v)) * (1.0 - c)


class Turntable:
    """An interactive view of ``scene`` in a notebook.

    Drag with the mouse to turn the view around the focus point (the centre of the
    scene's bulk, or the point the given ``camera`` looks at), use the wheel to move
    closer or further, and the ``max scale`` slider to hide Gaussians larger than its
    value (as ``verisplat render --max-scale``; the slider's right end keeps them all).
    The GPU stage timings of the last frame are shown under the image.

    ``camera``: the first view (default: the camera ``verisplat render`` uses); it is shown
    at ``width`` x ``height``. ``up``: the world's up direction (INRIA/COLMAP: -y).
    Display it by making it the last expression of a cell, or ``display(tt.widget)``.
    """

    def __init__(
        self,
        scene: Scene,
        camera: Optional[Camera] = None,
        width: int = 512,
        height: int = 512,
        renderer: Optional[Renderer] = None,
        up: Any = (0.0, -1.0, 0.0),
        background: Any = (0.0, 0.0, 0.0),
    ) -> None:
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a verisplat.Scene, got {type(scene).__name__}")
        if len(scene) == 0:
            raise ValueError("the scene has no Gaussians to show")
        self.scene = scene
        self.renderer = renderer if renderer is not None else Renderer()
        self.width, self.height = int(width), int(height)
        self.background = background
        self.up = _unit(np.asarray(up, dtype=np.float64))
        if camera is None:
            camera = default_camera(scene, self.width, self.height)
        elif (camera.width, camera.height) != (self.width, self.height):
            camera = camera.resized(self.width, self.height)
        self.camera: Camera = camera
        # The first camera's lens (None: a pinhole) and intrinsics, which moves keep.
        self._lens = camera.lens
        self._K = camera.K.copy()
        self.vfov = math.degrees(2.0 * math.atan(self.height / (2.0 * float(camera.K[1, 1]))))
        # The focus: on the camera's axis, as far as the bulk's centre is along it.
        eye = camera.position.astype(np.float64)
        forward = camera.viewmat[2, :3].astype(np.float64)
        centre = np.asarray(_native.bulk_centre(scene._s), dtype=np.float64)
        depth = float(np.dot(centre - eye, forward))
        if not depth > 1e-6:
            depth = max(float(np.linalg.norm(centre - eye)), 1e-3)
        self.focus = eye + forward * depth
        self.offset = eye - self.focus  # eye relative to the focus
        self._drag: Optional[tuple] = None
        #: Frames drawn (previews included) and how long the last took with encoding.
        self.frames = 0
        self.previews = 0
        self.last_frame_ms = 0.0
        #: The size of the last frame shown (smaller than width x height for previews).
        self.shown_size = (self.width, self.height)
        #: The size of the last preview (None before the first).
        self.preview_size: Optional[tuple] = None
        # The render thread's work: the newest request (a version number; 0 = none) and
        # whether it is a preview; `_drawn` the version last drawn.
        self._lock = threading.Condition()
        self._version = 0
        self._drawn = 0
        self._moving = False
        self._moved_at = 0.0
        self._preview_share = MIN_PREVIEW_SHARE
        self._error: Optional[BaseException] = None
        self._thread: Optional[threading.Thread] = None

        largest = np.max(scene.scales, axis=1)
        largest = largest[np.isfinite(largest) & (largest > 0)]
        lo = float(np.min(largest)) if largest.size else 1e-3
        hi = float(np.max(largest)) if largest.size else 1.0
        lo = min(lo, hi / 10.0)
        self._scale_max = hi
        self.image = _w.Image(format="png", width=self.width, height=self.height)
        self.slider = _w.FloatLogSlider(
            value=hi,
            base=10.0,
            min=math.log10(lo),
            max=math.log10(hi),
            step=(math.log10(hi) - math.log10(lo)) / 200.0,
            description="max scale",
            readout_format=".3g",
            continuous_update=True,
            layout=_w.Layout(width=f"{max(self.width, 300)}px"),
        )
        self.info = _w.HTML()
        self.widget = _w.VBox([self.image, self.slider, self.info])
        self.events = _Event(
            source=self.image,
            watched_events=["mousedown", "mousemove", "mouseup", "mouseleave", "wheel"],
            prevent_default_action=True,
        )
        self.events.on_dom_event(self._handle_event)
        self.slider.observe(self._on_slider, names="value")
        self.render()

    # -- display --------------------------------------------------------------------------

    def _repr_mimebundle_(self, **kwargs: Any) -> Any:
        return self.widget._repr_mimebundle_(**kwargs)

    @property
    def max_scale(self) -> Optional[float]:
        """The slider's filter: ``None`` at its right end (every Gaussian kept)."""
        v = float(self.slider.value)
        return None if v >= self._scale_max else v

    def render(self) -> None:
        """Renders the current view at full size into the image (and the timings under
        it) now, on the calling thread."""
        self._draw(self.camera, preview=False)

    def _draw(self, camera: Camera, preview: bool) -> None:
        start = time.perf_counter()
        if preview:
            share = self._preview_share
            w = max(1, round(self.width * math.sqrt(share)))
            h = max(1, round(self.height * math.sqrt(share)))
            camera = camera.resized(w, h)
        w, h = camera.width, camera.height
        out = self.renderer.render(
            self.scene,
            camera,
            background=self.background,
            max_scale=self.max_scale,
            mode="rgb",
        )
        # The image widget keeps its width and height: the browser scales a preview up.
        self.image.value = _native.encode_png(out["rgb"].tobytes(), w, h)
        self.last_frame_ms = (time.perf_counter() - start) * 1e3
        self.frames += 1
        self.shown_size = (w, h)
        if preview:
            self.previews += 1
            self.preview_size = (w, h)
            # Towards PREVIEW_MS, halfway (in ratio) per frame, between the floor and 1.
            ratio = PREVIEW_MS / max(self.last_frame_ms, 1e-3)
            share = self._preview_share * math.sqrt(min(4.0, max(0.25, ratio)))
            self._preview_share = min(1.0, max(MIN_PREVIEW_SHARE, share))
        t = self.renderer.timings
        gpu = sum(t.values())
        stages = " &middot; ".join(f"{k} {v:.1f}" for k, v in t.items())
        kept = "all Gaussians" if self.max_scale is None else f"max scale {self.max_scale:.3g}"
        what = "preview " if preview else ""
        self.info.value = (
            f"<code>{what}{w}x{h}, {kept}: GPU {gpu:.1f} ms "
            f"({stages} ms), {self.last_frame_ms:.0f} ms with encoding, "
            f"on {self.renderer.device}</code>"
        )

    # -- the render thread ----------------------------------------------------------------

    def _request(self, moving: bool) -> None:
        """Asks for the current view: a preview while ``moving``, else at full size. Only
        the newest request is drawn; one not yet drawn is replaced."""
        with self._lock:
            if self._error is not None:
                error, self._error = self._error, None
                raise RuntimeError(f"the turntable's last render failed: {error}") from error
            self._version += 1
            self._moving = moving
            self._moved_at = time.monotonic()
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(
                    target=self._run, name="verisplat-turntable", daemon=True
                )
                self._thread.start()
            self._lock.notify_all()

    def _run(self) -> None:
        """Draws the newest request whenever there is one; a moving view gets its full
        frame ``REST_S`` after the last move. Ends after a while without work."""
        while True:
            with self._lock:
                while True:
                    if self._version != self._drawn:
                        break
                    if self._moving:
                        due = self._moved_at + REST_S - time.monotonic()
                        if due <= 0:
                            self._moving = False
                            self._version += 1
                            break
                        self._lock.wait(due)
                    elif not self._lock.wait(5.0) and self._version == self._drawn:
                        self._thread = None
                        self._lock.notify_all()
                        return
                version, preview, camera = self._version, self._moving, self.camera
            try:
                self._draw(camera, preview)
            except BaseException as e:  # reported by the next request and by wait()
                with self._lock:
                    self._error = e
            with self._lock:
                self._drawn = version
                self._lock.notify_all()

    def wait(self, timeout: float = 60.0) -> None:
        """Waits until the newest view is drawn at full size (the view at rest); raises
        TimeoutError after ``timeout`` seconds and the render's error if it failed."""
        deadline = time.monotonic() + timeout
        with self._lock:
            while self._version != self._drawn or self._moving:
                if self._error is not None:
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"the turntable did not come to rest within {timeout} s")
                self._lock.wait(min(left, 0.05))
            if self._error is not None:
                error, self._error = self._error, None
                raise RuntimeError(f"the turntable's last render failed: {error}") from error

    # -- interaction ----------------------------------------------------------------------

    def _set_view(self) -> None:
        eye = self.focus + self.offset
        view = look_at(
            eye, self.focus, self.up, self.width, self.height, self.vfov, name="turntable"
        )
        if self._lens is not None:
            # A camera through a lens keeps its lens and intrinsics as it moves.
            view = Camera(view.viewmat, self._K, self.width, self.height, "turntable", self._lens)
        self.camera = view

    def rotate(self, dx: float, dy: float) -> None:
        """Turns the view as a drag of ``dx``, ``dy`` pixels does: ``dx`` around the up
        axis, ``dy`` over the focus (stopping short of the poles)."""
        offset = _rotate(self.offset, self.up, -dx * DRAG_RADIANS_PER_PIXEL)
        right = np.cross(self.up, offset)
        if np.linalg.norm(right) > 1e-12:
            tilted = _rotate(offset, _unit(right), dy * DRAG_RADIANS_PER_PIXEL)
            angle = math.acos(float(np.clip(np.dot(_unit(tilted), self.up), -1.0, 1.0)))
            if POLE_MARGIN < angle < math.pi - POLE_MARGIN:
                offset = tilted
        self.offset = offset
        self._set_view()

    def zoom(self, delta: float) -> None:
        """Moves closer (``delta`` < 0) or further, as a wheel delta does."""
        self.offset = self.offset * (WHEEL_ZOOM ** (float(delta) / 100.0))
        self._set_view()

    def _handle_event(self, event: Dict[str, Any]) -> None:
        kind = event.get("type")
        x, y = event.get("relativeX", 0), event.get("relativeY", 0)
        if kind == "mousedown":
            self._drag = (x, y)
        elif kind == "mousemove" and self._drag is not None:
            if not event.get("buttons", 1):
                self._drag = None
                return
            px, py = self._drag
            self._drag = (x, y)
            if (x, y) != (px, py):
                self.rotate(x - px, y - py)
                self._request(moving=True)
        elif kind in ("mouseup", "mouseleave"):
            if self._drag is not None:
                self._request(moving=False)  # released: the full frame now
            self._drag = None
        elif kind == "wheel":
            delta = event.get("deltaY", 0)
            if delta:
                self.zoom(delta)
                self._request(moving=True)

    def _on_slider(self, change: Dict[str, Any]) -> None:
        self._request(moving=True)
