"""Differentiable rasterization with numpy arrays: a forward pass and its backward pass.

Gaussians are given as a training loop holds them (gsplat's conventions): ``means``
(N, 3), ``quats`` (N, 4) as (w, x, y, z) of any non-zero length (normalised inside),
``scales`` (N, 3) linear, ``opacities`` (N,) in [0, 1], and ``colors`` either SH
coefficients (N, K, 3) with ``sh_degree`` (K >= (sh_degree + 1)^2; colour =
max(SH + 0.5, 0)) or direct values (N, D) without it.

    r = vksplat.raster.Rasterizer()
    fwd = r.forward(means, quats, scales, opacities, colors, viewmat, K, W, H, sh_degree=3)
    loss_grad = 2 * (fwd.colors - target)          # dL/d(colour) of an L2 loss
    grads = r.backward(fwd, grad_colors=loss_grad)  # dict: means, quats, scales, ...

The rules are the original 3DGS rasterizer's (``shared/docs/reference-semantics.md``): near
plane 0.2, 2D dilation 0.3, alpha clamp 0.99, skip below 1/255, stop at T < 1e-4; pixel
(i, j) is evaluated at (i, j) + 0.5 in gsplat's pixel coordinates. Backends: ``"vulkan"``
(the device's backward pass; deterministic by default) and ``"reference"`` (the f64 CPU
reference, exact and slow, for checks; also N-D direct channels).
"""

from __future__ import annotations

from typing import Any, Dict, Optional, Tuple

import numpy as np

from . import _native
from . import Camera, _numpy

ArrayLike = Any

_GRAD_SHAPES = {
    "means": 3,
    "quats": 4,
    "scales": 3,
    "means2d": 2,
    "absgrad": 2,
}


def _gaussian_array(name: str, value: ArrayLike, shape: Tuple[Optional[int], ...]) -> np.ndarray:
    """`value` as float32 of `shape` (None: any), finite; ValueError naming `name`."""
    arr = _numpy(value)
    if arr.dtype.kind != "f":
        raise ValueError(f"{name} must hold floats (float32), got dtype {arr.dtype}")
    if arr.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, arr.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {tuple(arr.shape)}")
    arr = np.ascontiguousarray(arr, dtype="<f4")
    bad = ~np.isfinite(arr)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{name} holds {arr[first]} at index {first}; every value must be finite")
    return arr


def _params(means, quats, scales, opacities, colors, sh_degree) -> Tuple[tuple, int, int]:
    """The native parameter tuple, the colour channels and K (SH coefficients per channel,
    or 0 for direct colours)."""
    m = _gaussian_array("means", means, (None, 3))
    n = m.shape[0]
    q = _gaussian_array("quats", quats, (n, 4))
    s = _gaussian_array("scales", scales, (n, 3))
    o = _gaussian_array("opacities", opacities, (n,))
    if sh_degree is None:
        c = _gaussian_array("colors", colors, (n, None))
        channels, k = c.shape[1], 0
        if channels == 0:
            raise ValueError("colors must have at least one channel")
    else:
        if not isinstance(sh_degree, (int, np.integer)) or not 0 <= sh_degree <= 3:
            raise ValueError(f"sh_degree must be 0..3 or None, got {sh_degree!r}")
        c = _gaussian_array("colors", colors, (n, None, 3))
        k = (int(sh_degree) + 1) ** 2
        if c.shape[1] < k:
            raise ValueError(
                f"colors must have at least {k} SH coefficients for sh_degree {sh_degree}, "
                f"got shape {tuple(c.shape)}"
            )
        c = np.ascontiguousarray(c[:, :k])
        channels = 3
    if (s <= 0).any():
        raise ValueError("scales must be positive (linear scales, not log)")
    if ((o < 0) | (o > 1)).any():
        raise ValueError("opacities must be in [0, 1] (activated, not logits)")
    if (np.einsum("ij,ij->i", q, q) == 0).any():
        raise ValueError("quats holds a zero quaternion")
    params = (
        n,
        m.tobytes(),
        q.tobytes(),
        s.tobytes(),
        o.tobytes(),
        c.tobytes(),
        None if sh_degree is None else int(sh_degree),
        channels,
    )
    return params, channels, k


class Forward:
    """What a forward pass returns: the image planes, the per-Gaussian projection and what
    its backward pass needs."""

    __slots__ = (
        "colors",
        "alphas",
        "depths",
        "radii",
        "means2d",
        "gaussian_depths",
        "conics",
        "_params",
        "_camera",
        "_background",
        "_kernel",
        "_token",
        "_channels",
        "_k",
        "_backend",
    )

    def __repr__(self) -> str:
        h, w = self.alphas.shape
        return f"Forward({w}x{h}, {self._params[0]} Gaussians, backend {self._backend})"


def _background(background: Optional[ArrayLike], channels: int) -> list:
    if background is None:
        return []
    bg = _numpy(background).astype(np.float64).reshape(-1)
    if bg.shape[0] != channels:
        raise ValueError(f"background must have {channels} values, got {bg.shape[0]}")
    if not np.all(np.isfinite(bg)):
        raise ValueError("background must be finite")
    return [float(v) for v in bg]


def _pixel_grad(name: str, value: Optional[ArrayLike], shape: Tuple[int, ...]) -> Optional[bytes]:
    """A pixel gradient of `shape` (a trailing axis of 1 may be left out or kept)."""
    if value is None:
        return None
    arr = _numpy(value)
    if arr.shape != shape and arr.size == int(np.prod(shape)) and arr.shape[:2] == shape[:2]:
        arr = arr.reshape(shape)
    return _gaussian_array(name, arr, shape).tobytes()


class Rasterizer:
    """The differentiable rasterizer. ``backend="vulkan"`` runs on a Vulkan device
    (``device``: index or part of its name, as ``Renderer``); ``accumulation`` is how the
    backward pass sums per-tile gradients: ``"deterministic"`` (default: bit-identical
    gradients run after run), ``"float-atomics"`` or ``"cas"`` (faster, not reproducible).
    ``backend="reference"`` runs the f64 CPU reference instead."""

    def __init__(
        self,
        device: Any = None,
        accumulation: str = "deterministic",
        backend: str = "vulkan",
    ) -> None:
        if backend not in ("vulkan", "reference"):
            raise ValueError(f"backend must be 'vulkan' or 'reference', got {backend!r}")
        self.backend = backend
        self._native = None
        if backend == "vulkan":
            self._native = _native.Rasterizer(None if device is None else str(device))
            self._native.set_accumulation(accumulation)

    @property
    def device(self) -> str:
        return "CPU reference (f64)" if self._native is None else self._native.device

    @property
    def timings(self) -> Dict[str, float]:
        """Device milliseconds of the last passes' stages (``forward/...``, ``backward/...``)."""
        return {} if self._native is None else dict(self._native.timings)

    def forward(
        self,
        means: ArrayLike,
        quats: ArrayLike,
        scales: ArrayLike,
        opacities: ArrayLike,
        colors: ArrayLike,
        viewmat: ArrayLike,
        K: ArrayLike,
        width: int,
        height: int,
        sh_degree: Optional[int] = None,
        background: Optional[ArrayLike] = None,
        kernel: str = "gaussian",
    ) -> Forward:
        """Renders the Gaussians from one camera: ``colors`` (H, W, D) with the background,
        ``alphas`` (H, W), ``depths`` (H, W, alpha-normalised), and per Gaussian ``radii``,
        ``means2d`` (pixels), ``gaussian_depths`` and ``conics`` (Vulkan backend)."""
        cam = Camera(viewmat, K, width, height)
        params, channels, k = _params(means, quats, scales, opacities, colors, sh_degree)
        bg = _background(background, channels)
        if self._native is not None and channels != 3 and any(bg):
            raise ValueError(
                f"background: {channels} direct channels are blended without a background on "
                "the device (the reference backend takes one)"
            )
        if kernel not in ("gaussian", "power"):
            raise ValueError(f"kernel must be 'gaussian' or 'power', got {kernel!r}")
        f = Forward()
        f._params, f._camera, f._background, f._kernel = params, cam._tuple(), bg, kernel
        f._channels, f._k, f._backend = channels, k, self.backend
        h, w, n = cam.height, cam.width, params[0]
        if self._native is None:
            color, alpha, depth = _native.reference_forward(params, f._camera, bg, kernel)
            f.colors = np.frombuffer(color, dtype="<f8").reshape(h, w, channels)
            f.alphas = np.frombuffer(alpha, dtype="<f8").reshape(h, w)
            f.depths = np.frombuffer(depth, dtype="<f8").reshape(h, w)
            f._token = 0
            f.radii = f.means2d = f.gaussian_depths = f.conics = None
            return f
        color, alpha, depth, token, projected = self._native.forward(params, f._camera, bg, kernel)
        f.colors = np.frombuffer(color, dtype="<f4").reshape(h, w, channels)
        f.alphas = np.frombuffer(alpha, dtype="<f4").reshape(h, w)
        f.depths = np.frombuffer(depth, dtype="<f4").reshape(h, w)
        proj = np.frombuffer(projected, dtype="<f4").reshape(n, 12)
        f._token = token
        f.radii = proj[:, 11].astype(np.int32)
        # The device's 2D means put pixel (i, j) at (i, j); gsplat's at (i + 0.5, j + 0.5).
        f.means2d = proj[:, 0:2] + 0.5
        f.gaussian_depths = proj[:, 7].copy()
        f.conics = proj[:, 4:7].copy()
        return f

    def backward(
        self,
        fwd: Forward,
        grad_colors: Optional[ArrayLike] = None,
        grad_alphas: Optional[ArrayLike] = None,
        grad_depths: Optional[ArrayLike] = None,
    ) -> Dict[str, np.ndarray]:
        """The gradients of a loss with respect to the forward pass's Gaussians, from its
        gradients with respect to the pixels (any of them may be None: zero). Returns
        ``means`` (N, 3), ``quats`` (N, 4, the unnormalised quaternions given), ``scales``,
        ``opacities``, ``colors`` (the shape given: SH (N, K, 3) with zeros past the degree,
        or (N, D)), ``means2d`` (N, 2, pixels) and ``absgrad`` (N, 2)."""
        if not isinstance(fwd, Forward):
            raise TypeError("fwd must be what Rasterizer.forward returned")
        if fwd._backend != self.backend:
            raise ValueError(f"fwd came from the {fwd._backend} backend, this is {self.backend}")
        h, w = fwd.alphas.shape
        gc = _pixel_grad("grad_colors", grad_colors, (h, w, fwd._channels))
        ga = _pixel_grad("grad_alphas", grad_alphas, (h, w))
        gd = _pixel_grad("grad_depths", grad_depths, (h, w))
        if self._native is None:
            raw = _native.reference_backward(
                fwd._params, fwd._camera, fwd._background, fwd._kernel, gc, ga, gd
            )
            dtype = "<f8"
        else:
            raw = self._native.backward(
                fwd._params, fwd._camera, fwd._background, fwd._kernel, fwd._token, gc, ga, gd
            )
            dtype = "<f4"
        n = fwd._params[0]
        out: Dict[str, np.ndarray] = {}
        for name, data in raw.items():
            arr = np.frombuffer(data, dtype=dtype)
            if name in _GRAD_SHAPES:
                arr = arr.reshape(n, _GRAD_SHAPES[name])
            elif name == "colors":
                arr = arr.reshape(n, fwd._k, 3) if fwd._k else arr.reshape(n, fwd._channels)
            out[name] = arr
        return out


_default: Optional[Rasterizer] = None


def _rasterizer() -> Rasterizer:
    global _default
    if _default is None:
        _default = Rasterizer()
    return _default


def rasterize(*args: Any, **kwargs: Any) -> Forward:
    """``Rasterizer().forward`` on a rasterizer shared by these functions."""
    return _rasterizer().forward(*args, **kwargs)


def rasterize_backward(fwd: Forward, **grads: Any) -> Dict[str, np.ndarray]:
    """``Rasterizer().backward`` on the rasterizer shared by these functions."""
    return _rasterizer().backward(fwd, **grads)
