"""Images: reading (``read_image``), metrics (``compare``) and writing (``save_image``,
``save_turntable``)."""

from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from . import _native
from ._cameras import orbit
from ._common import ArrayLike, PathLike, _floats, _python_names, _view
from ._render import Renderer
from ._scene import Scene


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
