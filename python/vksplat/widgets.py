"""A notebook turntable: ``Turntable(scene)`` shows the scene rendered by vksplat's Vulkan
pipeline, turned by dragging and zoomed with the wheel, with a max-scale slider that
re-renders as it moves and the GPU stage timings under the image.

Needs the notebook extra: ``pip install "./python[notebook]"`` (ipywidgets, ipyevents).
"""

from __future__ import annotations

import math
import time
from typing import Any, Dict, Optional

import numpy as np

from . import Camera, Renderer, Scene, _native, default_camera, look_at

try:
    import ipywidgets as _w
    from ipyevents import Event as _Event
except ImportError as e:  # pragma: no cover - depends on the environment
    raise ImportError(
        'vksplat.widgets needs ipywidgets and ipyevents: pip install "./python[notebook]"'
    ) from e

__all__ = ["Turntable"]

#: Radians of rotation per pixel dragged.
DRAG_RADIANS_PER_PIXEL = 0.01
#: Zoom factor per 100 units of wheel delta (one notch on most mice).
WHEEL_ZOOM = 1.15
#: Elevation limit, radians from the up axis, so the view never flips over the pole.
POLE_MARGIN = math.radians(2.0)


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
    value (as ``vksplat render --max-scale``; the slider's right end keeps them all).
    The GPU stage timings of the last frame are shown under the image.

    ``camera``: the first view (default: the camera ``vksplat render`` uses); it is shown
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
            raise TypeError(f"scene must be a vksplat.Scene, got {type(scene).__name__}")
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
        self.frames = 0
        self.last_frame_ms = 0.0

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
        """Renders the current view into the image and the timings under it."""
        start = time.perf_counter()
        out = self.renderer.render(
            self.scene,
            self.camera,
            background=self.background,
            max_scale=self.max_scale,
            mode="rgb",
        )
        self.image.value = _native.encode_png(out["rgb"].tobytes(), self.width, self.height)
        self.last_frame_ms = (time.perf_counter() - start) * 1e3
        self.frames += 1
        t = self.renderer.timings
        gpu = sum(t.values())
        stages = " &middot; ".join(f"{k} {v:.1f}" for k, v in t.items())
        kept = "all Gaussians" if self.max_scale is None else f"max scale {self.max_scale:.3g}"
        self.info.value = (
            f"<code>{self.width}x{self.height}, {kept}: GPU {gpu:.1f} ms "
            f"({stages} ms), {self.last_frame_ms:.0f} ms with encoding, "
            f"on {self.renderer.device}</code>"
        )

    # -- interaction ----------------------------------------------------------------------

    def _set_view(self) -> None:
        eye = self.focus + self.offset
        self.camera = look_at(
            eye, self.focus, self.up, self.width, self.height, self.vfov, name="turntable"
        )

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
                self.render()
        elif kind in ("mouseup", "mouseleave"):
            self._drag = None
        elif kind == "wheel":
            delta = event.get("deltaY", 0)
            if delta:
                self.zoom(delta)
                self.render()

    def _on_slider(self, change: Dict[str, Any]) -> None:
        self.render()
