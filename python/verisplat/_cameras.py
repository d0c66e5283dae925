"""Cameras: ``Camera`` (OpenCV axes, a pinhole or another lens), camera files
(``load_cameras``, ``save_cameras``) and cameras made for a scene (``look_at``,
``default_camera``, ``orbit``)."""

from __future__ import annotations

import os
import math
from typing import TYPE_CHECKING, Any, Dict, Iterable, List, Optional, Tuple

import numpy as np

from . import _native
from ._common import ArrayLike, PathLike, _floats, _numpy, _python_names

if TYPE_CHECKING:
    from ._scene import Scene


# Each lens kind's keys (cameras.json's names, docs/cameras.md) and how many numbers each
# holds; a key with a default may be left out.
_LENS_KEYS: Dict[str, Tuple[Tuple[str, int], ...]] = {
    "pinhole": (),
    "orthographic": (),
    "distorted": (("radial", 6), ("tangential", 2)),
    "fisheye": (("k", 4), ("max_theta", 1)),
    "equirectangular": (("longitude", 2), ("latitude", 2)),
}
_LENS_DEFAULTS: Dict[str, Any] = {
    "tangential": [0.0, 0.0],
    "longitude": [-math.pi, math.pi],
    "latitude": [math.pi / 2, -math.pi / 2],
}


def _lens_tuple(lens: Any) -> Tuple[str, List[float]]:
    """The extension's form of a lens (its kind and its numbers) from the public one: None
    (the pinhole), a kind's name, or a dict in cameras.json's form, e.g.
    ``{"kind": "fisheye", "k": [k1, k2, k3, k4], "max_theta": RADIANS}``; ValueError
    naming what is wrong."""
    if lens is None:
        return ("pinhole", [])
    if isinstance(lens, str):
        lens = {"kind": lens}
    if not isinstance(lens, dict):
        raise ValueError(f"lens must be None, a kind's name or a dict with a 'kind', got {lens!r}")
    kind = lens.get("kind")
    if kind not in _LENS_KEYS:
        raise ValueError(
            f"lens kind {kind!r} is unknown; the kinds are {', '.join(_LENS_KEYS)}"
        )
    keys = _LENS_KEYS[kind]
    unknown = sorted(set(lens) - {"kind"} - {k for k, _ in keys})
    if unknown:
        allowed = ", ".join(k for k, _ in keys) or "no other keys"
        raise ValueError(f"a {kind} lens has {allowed}; unknown: {', '.join(unknown)}")
    numbers_out: List[float] = []
    for key, count in keys:
        value = lens.get(key, _LENS_DEFAULTS.get(key))
        if value is None:
            if key == "max_theta":  # the lens's own default: as far as the polynomial grows
                continue
            raise ValueError(f"a {kind} lens needs {key!r} ({count} numbers)")
        arr = np.asarray(_numpy(value), dtype=np.float64).reshape(-1)
        if arr.shape[0] != count:
            raise ValueError(f"the {kind} lens's {key!r} must hold {count} numbers, got {arr.shape[0]}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"the {kind} lens's {key!r} must be finite, got {arr.tolist()}")
        numbers_out.extend(float(v) for v in arr)
    return (kind, numbers_out)


def _lens_dict(t: Tuple[str, List[float]]) -> Optional[Dict[str, Any]]:
    """The public form of the extension's lens (None for the pinhole)."""
    kind, values = t
    if kind == "pinhole":
        return None
    out: Dict[str, Any] = {"kind": kind}
    i = 0
    for key, count in _LENS_KEYS[kind]:
        if i >= len(values):
            break
        out[key] = float(values[i]) if key == "max_theta" else [float(v) for v in values[i : i + count]]
        i += count
    return out


class Camera:
    """A camera in OpenCV axes (gsplat's convention).

    ``viewmat`` is the 4x4 world-to-camera matrix (``p_cam = R p_world + t``), ``K`` the
    3x3 intrinsics ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` where, through the pinhole, a
    point projects to ``(fx x/z + cx, fy y/z + cy)`` and pixel ``(i, j)`` covers
    ``[i, i+1) x [j, j+1)``.

    ``lens`` is another lens (docs/cameras.md, "Lenses"), in cameras.json's form: None (the
    pinhole), ``{"kind": "distorted", "radial": [k1, ..., k6], "tangential": [p1, p2]}``
    (OpenCV's Brown-Conrady, the rational radial factor), ``{"kind": "fisheye", "k": [k1,
    k2, k3, k4], "max_theta": RADIANS}`` (equidistant; ``max_theta``, half the field of
    view, defaults to as far as the polynomial grows), ``{"kind": "orthographic"}`` (``fx``,
    ``fy`` in pixels per world unit) or ``{"kind": "equirectangular", "longitude": [LEFT,
    RIGHT], "latitude": [TOP, BOTTOM]}`` (radians; the whole sphere by default). A kind
    whose numbers all have defaults may be named alone (``lens="orthographic"``).
    """

    __slots__ = ("viewmat", "K", "width", "height", "name", "_lens")

    def __init__(
        self,
        viewmat: ArrayLike,
        K: ArrayLike,
        width: int,
        height: int,
        name: str = "",
        lens: Any = None,
    ) -> None:
        self.viewmat = _floats("viewmat", viewmat, (4, 4)).copy()
        self.K = _floats("K", K, (3, 3)).copy()
        if not (isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer))):
            raise TypeError(f"width and height must be integers, got {width!r} and {height!r}")
        self.width = int(width)
        self.height = int(height)
        self.name = str(name)
        self._lens = _lens_tuple(lens)
        # Checked now, so a bad camera is reported where it is made.
        _native.check_lens(self._lens)
        self._tuple()

    @property
    def lens(self) -> Optional[Dict[str, Any]]:
        """The lens in cameras.json's form (None: the pinhole)."""
        return _lens_dict(self._lens)

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
            self._lens,
        )

    @classmethod
    def _from_tuple(cls, t: tuple) -> "Camera":
        name, width, height, (fx, fy, cx, cy), m, lens = t
        K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float32)
        return cls(
            np.array(m, dtype=np.float32).reshape(4, 4), K, width, height, name, _lens_dict(lens)
        )

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
        return Camera(self.viewmat, K, width, height, self.name, self.lens)

    def __repr__(self) -> str:
        lens = "" if self._lens[0] == "pinhole" else f", lens={self._lens[0]!r}"
        return f"Camera(name={self.name!r}, width={self.width}, height={self.height}{lens})"


def load_cameras(
    path: PathLike, frames: Optional[int] = None, fps: Optional[float] = None
) -> List[Camera]:
    """Every camera of a camera file: INRIA cameras.json, a COLMAP sparse model (folder or
    cameras/images .txt/.bin), a nerfstudio camera_path.json or a verisplat keyframe JSON
    (``frames``/``fps`` resample a keyframe path); a trained model directory stands for
    its cameras.json."""
    return [Camera._from_tuple(t) for t in _native.load_cameras(os.fspath(path), frames, fps)]



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
