"""Rendering: ``Renderer`` (the Vulkan renderer) and ``render_cpu`` (the CPU reference),
with the argument checks and output arrays they share."""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._cameras import Camera
from ._common import ArrayLike, _floats, _numpy, _view
from ._scene import Scene

_PLANES = ("rgb", "alpha", "depth", "features")
# The surface pass's planes (docs/rendering.md, "Normals and median depth"): returned as
# "normal" (H, W, 3) and "median_depth" (H, W).
_SURFACE = ("normal", "median-depth")
_NORMAL_SPACES = ("camera", "world")


def _mode(mode: str) -> Tuple[bool, bool, bool, bool, bool, bool]:
    parts = set(mode.replace("rgba", "rgb+alpha").split("+"))
    unknown = parts - set(_PLANES) - set(_SURFACE)
    if unknown or not parts:
        raise ValueError(
            f"mode must join rgb, alpha, depth, features, normal and median-depth with '+' "
            f"(e.g. 'rgb', 'rgba', 'rgb+depth', 'rgb+alpha+depth', 'features+alpha', "
            f"'normal', 'normal+median-depth+alpha'), got {mode!r}"
        )
    if "features" in parts and parts & set(_SURFACE):
        raise ValueError(
            f"mode 'features' and the surface planes (normal, median-depth) are separate "
            f"renders; ask for one, got {mode!r}"
        )
    return tuple(p in parts for p in _PLANES + _SURFACE)  # type: ignore[return-value]


def _camera_list(
    camera: Union[Camera, Sequence[Camera], None],
    viewmat: Optional[ArrayLike],
    K: Optional[ArrayLike],
    width: Optional[int],
    height: Optional[int],
) -> Tuple[List[Camera], bool]:
    explicit = [v is not None for v in (viewmat, K, width, height)]
    if camera is not None:
        if any(explicit):
            raise ValueError("pass a camera or viewmat/K/width/height, not both")
        if isinstance(camera, Camera):
            return [camera], False
        cams = list(camera)
        if not cams or not all(isinstance(c, Camera) for c in cams):
            raise TypeError("camera must be a Camera or a non-empty list of Cameras")
        return cams, True
    if not all(explicit):
        raise ValueError("pass a camera, or all of viewmat, K, width and height")
    vm = _numpy(viewmat)
    if vm.ndim == 3:
        # gsplat's batches: viewmats (C, 4, 4) with one K (3, 3) or one per view (C, 3, 3).
        ks = _numpy(K)
        if ks.ndim == 3 and ks.shape[0] != vm.shape[0]:
            raise ValueError(
                f"K must have shape (3, 3) or ({vm.shape[0]}, 3, 3) for {vm.shape[0]} "
                f"viewmats, got {tuple(ks.shape)}"
            )
        per_view = [ks[i] if ks.ndim == 3 else ks for i in range(vm.shape[0])]
        return [
            Camera(v, k, width, height, f"view {i}") for i, (v, k) in enumerate(zip(vm, per_view))
        ], True
    ks = _numpy(K)
    return [Camera(vm, ks[0] if ks.shape == (1, 3, 3) else ks, width, height)], False


def _render(native_render, scene: "Scene", camera, kw: Dict[str, Any]) -> Dict[str, np.ndarray]:
    """The shared body of ``Renderer.render`` and ``render_cpu``: checks the arguments,
    calls the native renderer and wraps its planes as arrays."""
    want = _mode(kw["mode"])
    space = kw["normal_space"]
    if space not in _NORMAL_SPACES:
        raise ValueError(f"normal_space must be 'camera' or 'world', got {space!r}")
    surface = want[4] or want[5]
    cams, batch = _camera_list(camera, kw["viewmat"], kw["K"], kw["width"], kw["height"])
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a verisplat.Scene, got {type(scene).__name__}")
    if kw["sh_degree"] is not None and kw["sh_degree"] > scene.sh_degree:
        raise ValueError(
            f"sh_degree {kw['sh_degree']} exceeds the scene's SH degree {scene.sh_degree}"
        )
    opts = (
        [float(x) for x in _floats("background", kw["background"], (3,))],
        kw["sh_degree"],
        float(kw["scale_modifier"]),
        None if kw["max_scale"] is None else float(kw["max_scale"]),
        None if kw["min_opacity"] is None else float(kw["min_opacity"]),
        kw["antialiased"],
        kw["kernel"],
        kw["rules"],
        None if kw["near_plane"] is None else float(kw["near_plane"]),
        bool(kw.get("reproducible", False)),
    )
    native_want = (*want[:4], space if surface else None)
    planes = native_render(scene._s, [c._tuple() for c in cams], opts, native_want)
    return _outputs(planes, cams, batch, want, scene.feature_count)


def _outputs(planes, cams: List[Camera], batch: bool, want, k: int) -> Dict[str, np.ndarray]:
    b, h, w = len(cams), cams[0].height, cams[0].width
    out: Dict[str, np.ndarray] = {}
    for name, data, on in zip(_PLANES, planes, want):
        if not on:
            continue
        shape = {"rgb": (b, h, w, 3), "features": (b, h, w, k)}.get(name, (b, h, w))
        arr = _view(data, shape)
        out[name] = arr if batch else arr[0]
    if want[4] or want[5]:
        # The features plane holds the surface pass: unit normal, median depth.
        surface = _view(planes[3], (b, h, w, 4))
        if want[4]:
            normal = np.ascontiguousarray(surface[..., :3])
            out["normal"] = normal if batch else normal[0]
        if want[5]:
            median = np.ascontiguousarray(surface[..., 3])
            out["median_depth"] = median if batch else median[0]
    return out


class Renderer:
    """The Vulkan renderer. ``device``: index or part of a device name (default:
    discrete GPU, then integrated, then CPU, e.g. lavapipe; also VERISPLAT_DEVICE).

    The last scene rendered stays on the device: rendering it again (another camera,
    a batch) does not upload it again (see ``counters``)."""

    def __init__(self, device: Union[int, str, None] = None) -> None:
        self._r = _native.Renderer(None if device is None else str(device))

    @property
    def device(self) -> str:
        """The name of the Vulkan device."""
        return self._r.device

    @property
    def timings(self) -> Dict[str, float]:
        """GPU milliseconds of each stage of the last frame (timestamp queries):
        preprocess, order, scan, keys, sort, ranges, blend, readback."""
        return dict(self._r.timings)

    @property
    def counters(self) -> Dict[str, int]:
        """``uploads`` (scenes uploaded), ``frames`` (frames rendered), ``scene_bytes`` and
        ``frame_bytes`` (device memory of the uploaded scene and of the frame buffers)."""
        return dict(self._r.counters)

    def render(
        self,
        scene: Scene,
        camera: Union[Camera, Sequence[Camera], None] = None,
        *,
        viewmat: Optional[ArrayLike] = None,
        K: Optional[ArrayLike] = None,
        width: Optional[int] = None,
        height: Optional[int] = None,
        background: ArrayLike = (0.0, 0.0, 0.0),
        sh_degree: Optional[int] = None,
        scale_modifier: float = 1.0,
        max_scale: Optional[float] = None,
        min_opacity: Optional[float] = None,
        antialiased: Optional[bool] = None,
        kernel: Optional[str] = None,
        rules: Optional[str] = None,
        near_plane: Optional[float] = None,
        mode: str = "rgb+alpha+depth",
        normal_space: str = "camera",
        reproducible: bool = False,
    ) -> Dict[str, np.ndarray]:
        """Renders ``scene`` from ``camera`` (or ``viewmat``/``K``/``width``/``height``).

        Returns a dict of float32 arrays: ``rgb (H, W, 3)`` (with the background, not
        clamped), ``alpha (H, W)`` and ``depth (H, W)`` (alpha-weighted view depth
        divided by alpha, 0 where empty), as ``mode`` asks (``'rgb'``, ``'rgba'``,
        ``'rgb+depth'``, ``'features'``: the scene's K feature channels blended with the
        colour rules over 0, ``(H, W, K)``). ``kernel``: ``"gaussian"`` (the reference's
        falloff) or ``"power"`` (``opacity * max(0, 1 - d2/9)``); default the scene's
        recorded kernel. ``rules``: ``"original"`` (the 3DGS rasterizer's) or ``"gsplat"``
        (near plane 0.01, alpha clamp 0.999, a per-axis 3.33-sigma box); default the
        scene's recorded rules; ``near_plane`` overrides the rules' near plane.
        ``'normal'`` and ``'median-depth'`` (joinable with rgb, alpha and depth, not
        features) run the surface pass: ``normal (H, W, 3)``, each Gaussian's shortest axis
        turned to face the camera, blended with the colour weights and normalised (0 where
        alpha is 0), in ``normal_space`` ``"camera"`` (x right, y down, z the direction of
        view: a surface facing the camera is ``(0, 0, -1)``) or ``"world"``; and
        ``median_depth (H, W)``, the depth of the Gaussian at which the transmittance first
        drops to 0.5 or below (0 where it never does). A list of cameras (or a ``(B, 4, 4)`` viewmat) renders a
        batch: arrays gain a leading ``B``. ``max_scale``/``min_opacity`` drop
        Gaussians for this frame only, exactly as ``--max-scale``/``--min-opacity``.
        ``reproducible``: the blends with the CPU reference's exp and unfused arithmetic,
        as ``--reproducible`` (on lavapipe, pinhole frames equal ``render_cpu``'s bit for
        bit; docs/reproducibility.md). The GIL is released while rendering."""
        kw = dict(locals())
        return _render(self._r.render, kw.pop("scene"), kw.pop("camera"), kw)


def render_cpu(
    scene: Scene,
    camera: Union[Camera, Sequence[Camera], None] = None,
    *,
    viewmat: Optional[ArrayLike] = None,
    K: Optional[ArrayLike] = None,
    width: Optional[int] = None,
    height: Optional[int] = None,
    background: ArrayLike = (0.0, 0.0, 0.0),
    sh_degree: Optional[int] = None,
    scale_modifier: float = 1.0,
    max_scale: Optional[float] = None,
    min_opacity: Optional[float] = None,
    antialiased: Optional[bool] = None,
    kernel: Optional[str] = None,
    rules: Optional[str] = None,
    near_plane: Optional[float] = None,
    mode: str = "rgb+alpha+depth",
    normal_space: str = "camera",
) -> Dict[str, np.ndarray]:
    """``Renderer.render`` on the CPU reference renderer (the original 3DGS rasterizer's
    rules in f32, multithreaded): the yardstick the GPU is checked against."""
    kw = dict(locals())
    return _render(_native.render_cpu, kw.pop("scene"), kw.pop("camera"), kw)
