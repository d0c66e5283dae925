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

try:
    from . import _native
except ImportError as e:  # the source tree (python/verisplat) has no compiled extension
    raise ImportError(
        f"verisplat's compiled extension is not next to {os.path.dirname(__file__)}: this "
        "is the package's source; install it (pip install ./python) and import the "
        "installed package"
    ) from e

# This module only names the API; the implementation lives in private modules by area:
# _cameras, _scene, _fit, _render, _images, and _common (the helpers they share).
from ._cameras import Camera, default_camera, load_cameras, look_at, orbit, save_cameras
from ._common import ArrayLike, PathLike  # noqa: F401 (the aliases the signatures name)
from ._fit import fit
from ._images import compare, read_image, save_image, save_turntable
from ._render import Renderer, render_cpu
from ._scene import Scene, demo, load

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
