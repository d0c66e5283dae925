"""Cameras: ``Camera`` (a pinhole in OpenCV axes), camera files (``load_cameras``,
``save_cameras``) and cameras made for a scene (``look_at``, ``default_camera``,
``orbit``)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Iterable, List, Optional

import numpy as np

from . import _native
from ._common import ArrayLike, PathLike, _floats, _python_names

if TYPE_CHECKING:
    from ._scene import Scene


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
