"""verisplat: 3D Gaussian Splatting on raw Vulkan compute, with an exact CPU reference.

Load a scene, render it on the GPU (``Renderer``) or on the CPU reference
(``render_cpu``), compare images (``compare``), all with numpy arrays in gsplat's
conventions: OpenCV camera axes (x right, y down, z forward), a world-to-camera 4x4
``viewmat``, 3x3 intrinsics ``K``, float32 arrays, channels last.

    import verisplat
    scene = verisplat.load("point_cloud.ply")
    cam = verisplat.default_camera(scene, 640, 480)
    out = verisplat.Renderer().render(scene, cam)
    out["rgb"].shape  # (480, 640, 3)

Errors are Python exceptions carrying the sentence the command line prints:
``FileNotFoundError`` for missing files, ``ValueError`` (or ``TypeError`` for a
wrong dtype) for bad input, ``RuntimeError`` for device failures.
"""

from __future__ import annotations

import os
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

try:
    from . import _native
except ImportError as e:  # the source tree (python/verisplat) has no compiled extension
    raise ImportError(
        f"verisplat's compiled extension is not next to {os.path.dirname(__file__)}: this "
        "is the package's source; install it (pip install ./python) and import the "
        "installed package"
    ) from e

__version__ = _native.__version__

__all__ = [
    "Camera",
    "Renderer",
    "Scene",
    "compare",
    "default_camera",
    "demo",
    "fit",
    "load",
    "load_cameras",
    "look_at",
    "orbit",
    "read_image",
    "render_cpu",
    "save_cameras",
    "save_image",
    "save_turntable",
]

PathLike = Union[str, "os.PathLike[str]"]
ArrayLike = Any

# ---------------------------------------------------------------------------------------
# Array helpers


def _numpy(value: Any) -> np.ndarray:
    """A numpy array of what gsplat users pass: numpy arrays, (nested) lists of Python
    numbers (integers too), and torch tensors (detached and moved to the CPU first, so
    one that requires grad works)."""
    if all(hasattr(value, a) for a in ("detach", "cpu", "numpy")):
        return value.detach().cpu().numpy()
    if isinstance(value, (list, tuple)):
        arr = np.asarray(value)
        return arr.astype(np.float64) if arr.dtype.kind in "iu" else arr
    return np.asarray(value)


def _floats(
    name: str, value: ArrayLike, shape: Tuple[Optional[int], ...], strict: bool = False
) -> np.ndarray:
    """`value` as a C-contiguous little-endian float32 array of `shape` (None: any size).
    Strict (Gaussian arrays): floating-point dtypes only; otherwise integers are fine too
    (a background of ``(1, 1, 1)``)."""
    arr = _numpy(value)
    kinds = "f" if strict else "fiu"
    if arr.dtype.kind not in kinds:
        what = "floats (float16/32/64)" if strict else "numbers"
        raise TypeError(f"{name} must be an array of {what}, got dtype {arr.dtype}")
    if arr.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, arr.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {tuple(arr.shape)}")
    return np.ascontiguousarray(arr, dtype="<f4")


def _view(data: Union[bytes, bytearray], shape: Tuple[int, ...]) -> np.ndarray:
    return np.frombuffer(data, dtype="<f4").reshape(shape)


# ---------------------------------------------------------------------------------------
# Cameras


class Camera:
    """A pinhole camera in OpenCV axes (gsplat's convention).

    ``viewmat`` is the 4x4 world-to-camera matrix (``p_cam = R p_world + t``), ``K`` the
    3x3 intrinsics ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` where a point projects to
    ``(fx x/z + cx, fy y/z + cy)`` and pixel ``(i, j)`` covers ``[i, i+1) x [j, j+1)``.
    """

    __slots__ = ("viewmat", "K", "width", "height", "name")

    def __init__(
        self,
        viewmat: ArrayLike,
        K: ArrayLike,
        width: int,
        height: int,
        name: str = "",
    ) -> None:
        self.viewmat = _floats("viewmat", viewmat, (4, 4)).copy()
        self.K = _floats("K", K, (3, 3)).copy()
        if not (isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer))):
            raise TypeError(f"width and height must be integers, got {width!r} and {height!r}")
        self.width = int(width)
        self.height = int(height)
        self.name = str(name)
        # Checked now, so a bad camera is reported where it is made.
        self._tuple()

    def _tuple(self) -> tuple:
        K = self.K
        if K[0, 1] != 0 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise ValueError(
                f"camera {self.name!r}: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}"
            )
        if not np.all(np.isfinite(self.viewmat)) or not np.all(np.isfinite(K)):
            raise ValueError(f"camera {self.name!r}: viewmat and K must be finite")
        if self.viewmat[3].tolist() != [0.0, 0.0, 0.0, 1.0]:
            raise ValueError(
                f"camera {self.name!r}: the last row of viewmat must be [0, 0, 0, 1], got {self.viewmat[3].tolist()}"
            )
        return (
            self.name,
            self.width,
            self.height,
            [float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])],
            [float(v) for v in self.viewmat.reshape(-1)],
        )

    @classmethod
    def _from_tuple(cls, t: tuple) -> "Camera":
        name, width, height, (fx, fy, cx, cy), m = t
        K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float32)
        return cls(np.array(m, dtype=np.float32).reshape(4, 4), K, width, height, name)

    @property
    def position(self) -> np.ndarray:
        """The camera centre in world space."""
        R = self.viewmat[:3, :3].astype(np.float64)
        t = self.viewmat[:3, 3].astype(np.float64)
        return (-R.T @ t).astype(np.float32)

    def resized(self, width: int, height: int) -> "Camera":
        """The same view at another resolution (intrinsics scaled)."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0] *= sx
        K[1] *= sy
        K[2] = [0, 0, 1]
        return Camera(self.viewmat, K, width, height, self.name)

    def __repr__(self) -> str:
        return f"Camera(name={self.name!r}, width={self.width}, height={self.height})"


def load_cameras(
    path: PathLike, frames: Optional[int] = None, fps: Optional[float] = None
) -> List[Camera]:
    """Every camera of a camera file: INRIA cameras.json, a COLMAP sparse model (folder or
    cameras/images .txt/.bin), a nerfstudio camera_path.json or a verisplat keyframe JSON
    (``frames``/``fps`` resample a keyframe path); a trained model directory stands for
    its cameras.json."""
    return [Camera._from_tuple(t) for t in _native.load_cameras(os.fspath(path), frames, fps)]


# The library's messages name the command line's flags; Python callers get their own
# argument names.
_FLAG_NAMES = (("pass --overwrite", "pass overwrite=True"), ("--sh-degree", "sh_degree"))


def _python_names(e: Exception) -> Exception:
    text = str(e)
    for flag, argument in _FLAG_NAMES:
        text = text.replace(flag, argument)
    return type(e)(text)


def save_cameras(path: PathLike, cameras: Iterable[Camera], overwrite: bool = False) -> None:
    """Writes cameras as an INRIA cameras.json (readable by ``load_cameras`` and by
    ``verisplat render --cameras``); an existing file is refused unless ``overwrite``."""
    try:
        _native.save_cameras(os.fspath(path), [c._tuple() for c in cameras], overwrite)
    except (FileExistsError, ValueError) as e:
        raise _python_names(e) from None


def look_at(
    eye: ArrayLike,
    target: ArrayLike,
    up: ArrayLike = (0.0, -1.0, 0.0),
    width: int = 512,
    height: int = 512,
    vfov: float = 50.0,
    name: str = "",
) -> Camera:
    """A camera at ``eye`` looking at ``target``; ``up`` is the world's up direction
    (INRIA/COLMAP scenes: -y), ``vfov`` the vertical field of view in degrees."""
    e, t, u = _vec3("eye", eye), _vec3("target", target), _vec3("up", up)
    forward = np.subtract(t, e, dtype=np.float64)
    if not np.linalg.norm(forward) > 0.0:
        raise ValueError(f"eye and target are the same point {e}: there is no view direction")
    if not np.linalg.norm(u) > 0.0:
        raise ValueError("up must be a non-zero vector, got (0, 0, 0)")
    if not np.linalg.norm(np.cross(forward, u)) > 1e-9 * np.linalg.norm(forward) * np.linalg.norm(u):
        raise ValueError(f"up {u} is parallel to the view direction from eye to target")
    return Camera._from_tuple(_native.look_at(e, t, u, width, height, vfov, name))


def _vec3(name: str, v: ArrayLike) -> List[float]:
    return [float(x) for x in _floats(name, v, (3,))]


def default_camera(scene: "Scene", width: int = 1280, height: int = 720) -> Camera:
    """The camera ``verisplat render`` uses when given none: it frames the scene's bulk."""
    return Camera._from_tuple(_native.default_camera(scene._s, width, height))


def orbit(
    scene: "Scene",
    frames: int = 120,
    width: int = 1280,
    height: int = 720,
    vfov: float = 50.0,
    elevation: float = 20.0,
    start: float = 0.0,
    up: ArrayLike = (0.0, -1.0, 0.0),
    centre: Optional[ArrayLike] = None,
    radius: Optional[float] = None,
) -> List[Camera]:
    """A turntable orbit of ``frames`` cameras around the scene's bulk, as
    ``verisplat render --orbit``."""
    return [
        Camera._from_tuple(t)
        for t in _native.orbit(
            scene._s,
            frames,
            width,
            height,
            vfov,
            elevation,
            start,
            _vec3("up", up),
            None if centre is None else _vec3("centre", centre),
            radius,
        )
    ]


# ---------------------------------------------------------------------------------------
# Scenes


class Scene:
    """A set of 3D Gaussians. Arrays are read-only float32 views: ``means (N, 3)``,
    ``quats (N, 4)`` (wxyz, normalised), ``scales (N, 3)`` and ``opacities (N,)``
    (activated), ``sh (N, (d+1)^2, 3)``; ``raw()`` gives the trainer's parameters."""

    __slots__ = ("_s", "_report")

    def __init__(self, native: Any, report: Optional[Dict[str, Any]] = None) -> None:
        self._s = native
        self._report = report

    @property
    def fit_report(self) -> Optional[Dict[str, Any]]:
        """For a scene made by :func:`fit`: the held-out errors, the Gaussian counts, what
        was chosen from the data (``notes``) and ``warnings``; None otherwise."""
        return self._report

    def evaluate_field(self, points: ArrayLike, time: Optional[ArrayLike] = None) -> np.ndarray:
        """The field the Gaussians hold, ``f(x) = sum_i o_i feat_i G_i(x)`` (the plain sum
        :func:`fit` fits and ``render --mode field-*`` shows), at ``points (N, 3)``:
        ``(N, K)`` float32. A time-varying scene (see :attr:`time_range`) needs the time:
        ``time`` one number or ``(N,)``, or ``points (N, 4)`` with t as the last column."""
        p = _numpy(points)
        if p.ndim == 2 and p.shape[1] == 4 and time is None:
            time, p = p[:, 3], p[:, :3]
        p = _floats("points", p, (None, 3))
        t = None
        if time is not None:
            t = np.broadcast_to(np.asarray(time, dtype=np.float32), (p.shape[0],))
            t = np.ascontiguousarray(t).tobytes()
        out = self._s.evaluate_field(p.tobytes(), p.shape[0], t)
        return _view(out, (p.shape[0], self.feature_count))

    @property
    def time_range(self) -> Optional[Tuple[float, float]]:
        """A time-varying scene's (``t_mean``, ``t_scale`` per Gaussian, what :func:`fit`
        with ``times`` makes) range of temporal means; None for a static scene."""
        return self._s.time_range

    def at_time(self, t: float) -> "Scene":
        """The static scene a time-varying one is at time ``t`` (each Gaussian's opacity
        times ``exp(-((t - t_mean) / t_scale)^2 / 2)``), which renders as ``render --time``
        does. A time-varying scene is rendered only this way."""
        return Scene(self._s.at_time(float(t)))

    def __len__(self) -> int:
        return len(self._s)

    def __repr__(self) -> str:
        return f"Scene({len(self)} Gaussians, SH degree {self.sh_degree}, from {self.source})"

    @property
    def sh_degree(self) -> int:
        return self._s.sh_degree

    @property
    def antialiased(self) -> bool:
        """Whether the file records antialiased training (rendered with the opacity
        compensation unless ``antialiased=False`` is passed)."""
        return self._s.antialiased

    @property
    def source(self) -> str:
        return self._s.source

    @property
    def feature_count(self) -> int:
        """Feature channels per Gaussian (K; 0 without features)."""
        return self._s.feature_count

    @property
    def kernel(self) -> str:
        """The falloff the file records: "gaussian" (the reference) or "power"."""
        return self._s.kernel

    @property
    def rules(self) -> str:
        """The rasterizer's rules the file records: "original" (the 3DGS rasterizer's) or
        "gsplat" (a model trained with ``verisplat train --rules gsplat``)."""
        return self._s.rules

    @property
    def features(self) -> Optional[np.ndarray]:
        """The feature channels ``(N, K)``, or None when the scene has none."""
        k = self.feature_count
        return self._array("features", (len(self), k)) if k else None

    def _array(self, name: str, shape: Tuple[int, ...]) -> np.ndarray:
        return _view(self._s.array(name), shape)

    @property
    def means(self) -> np.ndarray:
        return self._array("means", (len(self), 3))

    @property
    def quats(self) -> np.ndarray:
        return self._array("quats", (len(self), 4))

    @property
    def scales(self) -> np.ndarray:
        return self._array("scales", (len(self), 3))

    @property
    def opacities(self) -> np.ndarray:
        return self._array("opacities", (len(self),))

    @property
    def sh(self) -> np.ndarray:
        k = (self.sh_degree + 1) ** 2
        return self._array("sh", (len(self), k, 3))

    def raw(self) -> Dict[str, np.ndarray]:
        """The trainer's parameters: ``means``, ``log_scales``, ``quats`` (as stored, not
        normalised), ``opacity_logits`` and ``sh``; ``Scene.from_arrays(**scene.raw(),
        activated=False)`` gives the same scene back."""
        n = len(self)
        return {
            "means": self.means,
            "quats": self._array("raw_quats", (n, 4)),
            "scales": self._array("log_scales", (n, 3)),
            "opacities": self._array("opacity_logits", (n,)),
            "sh": self.sh,
        }

    @classmethod
    def from_arrays(
        cls,
        means: ArrayLike,
        quats: ArrayLike,
        scales: ArrayLike,
        opacities: ArrayLike,
        sh: Optional[ArrayLike] = None,
        colors: Optional[ArrayLike] = None,
        activated: bool = True,
        antialiased: bool = False,
        features: Optional[ArrayLike] = None,
    ) -> "Scene":
        """A scene from arrays. With ``activated=True`` (default): positive ``scales``,
        ``opacities`` in [0, 1] and any non-zero quaternions (wxyz; normalised, unit ones
        kept as given). With ``activated=False``: log scales, opacity logits and
        quaternions as the trainer stores them. Colour is ``sh (N, K, 3)`` with K = 1, 4,
        9 or 16, or ``colors (N, 3)`` in [0, 1] (converted to the DC term). ``features
        (N, K)``, K = 1..64, are feature channels (``mode="features"`` renders them)."""
        means_a = _numpy(means)
        if means_a.ndim != 2 or means_a.shape[1:] != (3,):
            raise ValueError(f"means must have shape (N, 3), got {tuple(means_a.shape)}")
        n = means_a.shape[0]
        # When every other array agrees on another count, means is the one that is off.
        counts = {}
        others = (("quats", quats), ("scales", scales), ("opacities", opacities))
        others += (("sh", sh), ("colors", colors), ("features", features))
        for name, value in others:
            shape = None if value is None else _numpy(value).shape
            if shape:
                counts[name] = shape[0]
        if len(set(counts.values())) == 1 and n not in counts.values():
            agreed = next(iter(counts.values()))
            raise ValueError(
                f"means must have shape ({agreed}, 3) like {', '.join(counts)} "
                f"({agreed} Gaussians), got {tuple(means_a.shape)}"
            )
        m = _floats("means", means_a, (n, 3), strict=True)
        q = _floats("quats", quats, (n, 4), strict=True)
        s = _floats("scales", scales, (n, 3), strict=True)
        o = _floats("opacities", opacities, (n,), strict=True)
        if (sh is None) == (colors is None):
            raise ValueError("pass exactly one of sh (N, K, 3) and colors (N, 3)")
        if colors is not None:
            c = _floats("colors", colors, (n, 3), strict=True)
            outside = np.argwhere(~((c >= 0.0) & (c <= 1.0)))
            if len(outside):
                i, ch = (int(x) for x in outside[0])
                raise ValueError(
                    f"colors[{i}] is {c[i].tolist()}; colors must be in [0, 1] "
                    f"(channel {ch}; {len(outside)} values outside)"
                )
            # The DC term whose evaluation (SH_C0 * dc + 0.5) gives the colour back.
            sh_a = ((c - 0.5) / 0.28209479177387814).astype("<f4").reshape(n, 1, 3)
        else:
            sh_a = _numpy(sh)
            if sh_a.ndim != 3 or sh_a.shape[0] != n or sh_a.shape[2] != 3:
                raise ValueError(f"sh must have shape ({n}, K, 3), got {tuple(sh_a.shape)}")
            sh_a = _floats("sh", sh_a, (n, sh_a.shape[1], 3), strict=True)
        feats = None
        if features is not None:
            fa = _numpy(features)
            if fa.ndim != 2 or fa.shape[0] != n or not 1 <= fa.shape[1] <= 64:
                raise ValueError(f"features must have shape ({n}, K) with K 1..64, got {tuple(fa.shape)}")
            feats = _floats("features", fa, (n, fa.shape[1]), strict=True)
        return cls(
            _native.scene_from_arrays(
                n,
                sh_a.shape[1],
                m.tobytes(),
                q.tobytes(),
                s.tobytes(),
                o.tobytes(),
                sh_a.tobytes(),
                bool(activated),
                bool(antialiased),
                0 if feats is None else feats.shape[1],
                None if feats is None else feats.tobytes(),
            )
        )

    def save(self, path: PathLike, overwrite: bool = False) -> None:
        """Writes the scene as .ply (lossless), .splat or .spz (by extension),
        atomically; an existing file is refused unless ``overwrite``."""
        try:
            self._s.save(os.fspath(path), overwrite)
        except (FileExistsError, ValueError) as e:
            raise _python_names(e) from None

    def filtered(
        self,
        max_scale: Optional[float] = None,
        min_opacity: Optional[float] = None,
        sh_degree: Optional[int] = None,
    ) -> "Scene":
        """A new scene without the Gaussians the CLI's ``--max-scale``/``--min-opacity``
        drop, its SH cut to ``sh_degree``."""
        try:
            return Scene(self._s.filtered(max_scale, min_opacity, sh_degree))
        except ValueError as e:
            raise _python_names(e) from None


def load(path: PathLike, iteration: Optional[int] = None) -> Scene:
    """Loads a scene: INRIA .ply, compressed .ply, .splat, .spz, SOG, or a trained model
    directory (``iteration`` picks point_cloud/iteration_N, default the largest)."""
    return Scene(_native.load(os.fspath(path), iteration))


def demo() -> Scene:
    """The built-in demo scene (PLAYBOT, 1,873 Gaussians, CC BY 4.0)."""
    return Scene(_native.demo())


def fit(
    points: ArrayLike,
    values: ArrayLike,
    *,
    gaussians: Optional[int] = None,
    max_gaussians: Optional[int] = None,
    steps: int = 1500,
    kernel: str = "gaussian",
    holdout: float = 0.1,
    seed: int = 1,
    bounds: Optional[Sequence[float]] = None,
    magnitude_channel: int = 0,
    db: bool = False,
    clip_grad: float = 0.0,
    times: Optional[ArrayLike] = None,
    force: bool = False,
) -> Scene:
    """Fits Gaussians with feature channels to field samples, as ``verisplat fit`` does:
    ``points (N, 3)`` and ``values (N, K)`` (or ``(N,)`` for one channel). The scene's
    features hold the field (``scene.evaluate_field(x)``); ``scene.fit_report`` the
    held-out errors. Gaussian counts default to one per 20 samples (at most one per 5);
    ``bounds`` (xmin, ymin, zmin, xmax, ymax, zmax) is the region sampled; ``db=True``
    takes the magnitude channel as dB and fits its linear power. ``times (N,)`` fits the
    field in space and time (each Gaussian gets a temporal mean and scale; evaluate it with
    ``evaluate_field(x, time=t)``, render ``scene.at_time(t)``). A fit no better than
    predicting 0 raises a ``UserWarning``. Too few samples to fit and hold out (fewer than
    20 to fit on, or 5 held out with ``holdout`` above 0: 45 at the default 0.1) raise a
    ``ValueError`` unless ``force=True``."""
    p = _floats("points", points, (None, 3))
    v = _numpy(values)
    if v.ndim == 1:
        v = v[:, None]
    v = _floats("values", v, (p.shape[0], None))
    b = None if bounds is None else [float(x) for x in bounds]
    if b is not None and len(b) != 6:
        raise ValueError(f"bounds must be 6 numbers (xmin, ymin, zmin, xmax, ymax, zmax), got {len(b)}")
    native, report = _native.fit(
        p.tobytes(), v.tobytes(), p.shape[0], v.shape[1], gaussians, max_gaussians, steps,
        kernel, holdout, seed, b, magnitude_channel, db, clip_grad,
        None if times is None else _floats("times", _numpy(times).reshape(-1), (p.shape[0],)).tobytes(),
        bool(force),
    )
    report = dict(report)
    for w in report["warnings"]:
        import warnings

        warnings.warn(w, UserWarning, stacklevel=2)
    return Scene(native, report)


# ---------------------------------------------------------------------------------------
# Rendering

_PLANES = ("rgb", "alpha", "depth", "features")


def _mode(mode: str) -> Tuple[bool, bool, bool, bool]:
    parts = set(mode.replace("rgba", "rgb+alpha").split("+"))
    unknown = parts - set(_PLANES)
    if unknown or not parts:
        raise ValueError(
            f"mode must join rgb, alpha, depth and features with '+' (e.g. 'rgb', 'rgba', "
            f"'rgb+depth', 'rgb+alpha+depth', 'features+alpha'), got {mode!r}"
        )
    return tuple(p in parts for p in _PLANES)  # type: ignore[return-value]


def _cameras(
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
    cams, batch = _cameras(camera, kw["viewmat"], kw["K"], kw["width"], kw["height"])
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
    )
    planes = native_render(scene._s, [c._tuple() for c in cams], opts, want)
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
        scene's recorded rules; ``near_plane`` overrides the rules' near plane. A list of cameras (or a ``(B, 4, 4)`` viewmat) renders a
        batch: arrays gain a leading ``B``. ``max_scale``/``min_opacity`` drop
        Gaussians for this frame only, exactly as ``--max-scale``/``--min-opacity``.
        The GIL is released while rendering."""
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
) -> Dict[str, np.ndarray]:
    """``Renderer.render`` on the CPU reference renderer (the original 3DGS rasterizer's
    rules in f32, multithreaded): the yardstick the GPU is checked against."""
    kw = dict(locals())
    return _render(_native.render_cpu, kw.pop("scene"), kw.pop("camera"), kw)


# ---------------------------------------------------------------------------------------
# Images and metrics


def read_image(path: PathLike) -> Tuple[np.ndarray, List[str]]:
    """Reads PNG (8/16-bit), JPEG, WebP, OpenEXR or .npy as ``(H, W, C)`` float32 (8- and
    16-bit scaled to [0, 1]) and its channel names (``R, G, B, A, Z, ...``)."""
    w, h, names, data = _native.read_image(os.fspath(path))
    return _view(data, (h, w, len(names))), names


def _image(x: Union[ArrayLike, PathLike], name: str) -> np.ndarray:
    if isinstance(x, (str, os.PathLike)):
        arr, names = read_image(x)
        for group in (["R", "G", "B"], ["Y"]):
            if all(g in names for g in group):
                return arr[..., [names.index(g) for g in group]]
        return arr
    arr = np.asarray(x)
    if arr.dtype == np.uint8:
        arr = arr.astype(np.float32) / 255.0
    elif arr.dtype == np.uint16:
        arr = arr.astype(np.float32) / 65535.0
    elif arr.dtype.kind != "f":
        raise TypeError(f"{name} must be a float, uint8 or uint16 array, got dtype {arr.dtype}")
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3:
        raise ValueError(f"{name} must have shape (H, W) or (H, W, C), got {tuple(arr.shape)}")
    return np.ascontiguousarray(arr, dtype="<f4")


def compare(
    reference: Union[ArrayLike, PathLike],
    test: Union[ArrayLike, PathLike],
    kind: str = "color",
) -> Dict[str, Optional[float]]:
    """The metrics of ``verisplat compare``: PSNR (dB, ``inf`` when equal), SSIM (the 3DGS
    evaluation's), LDR-FLIP (3-channel colour), largest and mean absolute error, the share
    of pixels whose 8-bit values are within 1/255, and the peak.

    ``reference`` and ``test`` are ``(H, W, C)`` or ``(H, W)`` arrays (float, or uint8 /
    uint16 scaled to [0, 1]) or image paths (their R, G, B are used). ``kind``:
    ``"color"`` (clamped to [0, 1]), ``"alpha"``, or ``"data"`` (as given, peak the
    reference's largest value)."""
    a = _image(reference, "reference")
    b = _image(test, "test")
    for arr, name in ((a, "reference"), (b, "test")):
        bad = ~np.isfinite(arr)
        if bad.any():
            y, x, c = (int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"{name} has {int(bad.sum())} values that are NaN or infinite "
                f"(the first at row {y}, column {x}, channel {c}: {arr[y, x, c]}); "
                "metrics of such images would mean nothing"
            )
    if a.shape != b.shape:
        raise ValueError(f"the images differ in shape: reference {a.shape}, test {b.shape}")
    h, w, c = a.shape
    return dict(_native.compare(a.tobytes(), b.tobytes(), w, h, c, kind))


# ---------------------------------------------------------------------------------------
# Writing images


def save_image(
    path: PathLike,
    rgb: Union[ArrayLike, Dict[str, np.ndarray]],
    alpha: Optional[ArrayLike] = None,
    depth: Optional[ArrayLike] = None,
    overwrite: bool = False,
    png16: bool = False,
) -> None:
    """Writes an image as ``verisplat render`` does, atomically: ``.png`` (8-bit colour, or
    16-bit with ``png16``; clamped to [0, 1], rounded) or ``.exr`` (R, G, B, A, Z as 32-bit
    floats; alpha 1 and depth +inf where not given). ``rgb`` is ``(H, W, 3)`` (float, or
    uint8 scaled to [0, 1]) or a render's output dict (its ``rgb``, ``alpha`` and
    ``depth``). An existing file is refused unless ``overwrite``."""
    if isinstance(rgb, dict):
        alpha = rgb.get("alpha") if alpha is None else alpha
        depth = rgb.get("depth") if depth is None else depth
        rgb = rgb["rgb"]
    colour = _image(rgb, "rgb")
    h, w, c = colour.shape
    if c != 3:
        raise ValueError(f"rgb must have shape (H, W, 3), got {colour.shape}")
    planes = []
    for name, plane in (("alpha", alpha), ("depth", depth)):
        if plane is None:
            planes.append(None)
            continue
        arr = _floats(name, plane, (h, w))
        planes.append(arr.tobytes())
    try:
        _native.save_image(
            os.fspath(path), colour.tobytes(), planes[0], planes[1], w, h, png16, overwrite
        )
    except (FileExistsError, ValueError) as e:
        raise _python_names(e) from None


def save_turntable(
    path: PathLike,
    scene: "Scene",
    frames: int = 48,
    width: int = 640,
    height: int = 480,
    fps: float = 24.0,
    overwrite: bool = False,
    renderer: Optional["Renderer"] = None,
    **orbit_args: Any,
) -> List[str]:
    """Renders a turntable (``orbit``) of ``scene`` and writes it. A video (``.mp4``,
    ``.gif``, ...) is written with imageio (``pip install imageio imageio-ffmpeg``) when it
    is installed; a path ending in ``.png``, or any path when imageio is not there, gives a
    PNG sequence ``<stem>_0000.png``, ``<stem>_0001.png``, ... beside it. Returns the files
    written. ``renderer``: a ``Renderer`` (default: a new one); ``orbit_args`` go to
    ``orbit`` (``elevation``, ``radius``, ...)."""
    path = os.fspath(path)
    cams = orbit(scene, frames=frames, width=width, height=height, **orbit_args)
    r = renderer if renderer is not None else Renderer()
    stem, ext = os.path.splitext(path)
    imageio = None
    if ext.lower() != ".png":
        try:
            import imageio.v2 as imageio  # type: ignore
        except ImportError:
            imageio = None
    if imageio is not None:
        if os.path.exists(path) and not overwrite:
            raise FileExistsError(f"{path}: already exists; pass overwrite=True to replace it")
        tmp = f"{stem}.partial{ext}"
        with imageio.get_writer(tmp, fps=fps) as writer:
            for cam in cams:
                rgb = r.render(scene, cam, mode="rgb")["rgb"]
                writer.append_data((np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))
        os.replace(tmp, path)
        return [path]
    files = [f"{stem}_{i:04d}.png" for i in range(len(cams))]
    if not overwrite:
        for f in files:
            if os.path.exists(f):
                raise FileExistsError(f"{f}: already exists; pass overwrite=True to replace it")
    for cam, f in zip(cams, files):
        save_image(f, r.render(scene, cam, mode="rgb"), overwrite=overwrite)
    return files
