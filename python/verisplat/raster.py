"""Differentiable rasterization with numpy arrays: a forward pass and its backward pass.

Gaussians are given as a training loop holds them (gsplat's conventions): ``means``
(N, 3), ``quats`` (N, 4) as (w, x, y, z) of any non-zero length (normalised inside),
``scales`` (N, 3) linear, ``opacities`` (N,) in [0, 1], and ``colors`` either SH
coefficients (N, K, 3) with ``sh_degree`` (K >= (sh_degree + 1)^2; colour =
max(SH + 0.5, 0)) or direct values (N, D) without it (blended as given, never clamped).

    r = verisplat.raster.Rasterizer()
    fwd = r.forward(means, quats, scales, opacities, colors, viewmat, K, W, H, sh_degree=3)
    loss_grad = 2 * (fwd.colors - target)          # dL/d(colour) of an L2 loss
    grads = r.backward(fwd, grad_colors=loss_grad)  # dict: means, quats, scales, ...

With a neural ``Shader`` (the per-pixel MLP ``verisplat render --shader`` runs), ``colors``
are (N, K) feature values, the image is the shaded colour (H, W, 3) over ``background``, and
the backward pass also returns the network's gradients (``shader_weights``,
``shader_biases``: one array per layer), so feature splats and their shader can be learned
without torch:

    shader = verisplat.raster.Shader([(w1, b1, "relu"), (w2, b2, "sigmoid")])
    fwd = r.forward(means, quats, scales, opacities, features, viewmat, K, W, H, shader=shader)

The rules are the original 3DGS rasterizer's (``shared/docs/reference-semantics.md``): near
plane 0.2, 2D dilation 0.3, alpha clamp 0.99, skip below 1/255, stop at T < 1e-4; pixel
(i, j) is evaluated at (i, j) + 0.5 in gsplat's pixel coordinates. ``rules="gsplat"`` takes
gsplat's instead (near plane 0.01, alpha clamp 0.999, stop at T <= 1e-4, a per-axis
opacity-aware 3.33-sigma screen box, the guard band around the principal point, the
antialiased compensation's floor 0), for models trained with gsplat. Backends: ``"vulkan"``
(the device's backward pass; deterministic by default) and ``"reference"`` (the f64 CPU
reference, exact and slow, for checks; also N-D direct channels).
"""

from __future__ import annotations

from typing import Any, Dict, Optional, Tuple

import numpy as np

from . import _native
from ._cameras import Camera
from ._common import _numpy

ArrayLike = Any

# gsplat's box ends where a splat's alpha falls to ALPHA_MIN (1/255): opacity times its inverse.
_ALPHA_MIN_INVERSE = float(round(1.0 / _native.ALPHA_MIN))

_GRAD_SHAPES = {
    "means": 3,
    "quats": 4,
    "scales": 3,
    "means2d": 2,
    "absgrad": 2,
    "screen": 8,
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


def _radii_xy(radii: np.ndarray, conics: np.ndarray, opacities: np.ndarray, rules: str) -> np.ndarray:
    """Per-axis radii (N, 2). gsplat's box is ``ceil(e sqrt(cov_xx))`` by ``ceil(e sqrt(cov_yy))``
    with ``e = min(3.33, sqrt(2 ln(255 opacity)))``; the device keeps the larger, so the
    other is found again from the conic (the 2D covariance's inverse) and never exceeds it.
    The original's disc has one radius."""
    r = radii.astype(np.int32)
    if rules != "gsplat":
        return np.stack([r, r], axis=-1)
    a, b, c = (conics[:, k].astype(np.float64) for k in range(3))
    det = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        cov = np.stack([c / det, a / det], axis=-1)
        e = np.minimum(
            _native.GSPLAT_EXTEND,
            np.sqrt(2.0 * np.log(np.maximum(opacities, 1e-30) * _ALPHA_MIN_INVERSE)),
        )
        xy = np.ceil(e[:, None] * np.sqrt(np.maximum(cov, 0.0)))
    xy = np.where(np.isfinite(xy), xy, 0.0)
    larger = np.argmax(xy, axis=-1)
    out = np.minimum(xy, r[:, None]).astype(np.int32)
    out[np.arange(len(r)), larger] = r
    out[r == 0] = 0
    return out


class Forward:
    """What a forward pass returns: the image planes, the per-Gaussian projection and what
    its backward pass needs."""

    __slots__ = (
        "colors",
        "alphas",
        "depths",
        "radii",
        "radii_xy",
        "means2d",
        "gaussian_depths",
        "conics",
        "opacities",
        "_params",
        "_camera",
        "_background",
        "_kernel",
        "_antialiased",
        "_rules",
        "_reproducible",
        "_token",
        "_channels",
        "_k",
        "_backend",
        "_shader",
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


class Shader:
    """A neural shader: a per-pixel MLP from the blended feature channels (and, as
    ``inputs`` lists them, the pixel's unit view direction and its alpha) to a colour,
    ``alpha * mlp(...) + (1 - alpha) * background`` (the file format and rules of
    ``verisplat render --shader``). ``layers``: ``(weight (outputs, inputs), bias (outputs,),
    activation)`` per layer, activation one of ``"relu"``, ``"sigmoid"``, ``"tanh"``,
    ``"none"``; the last layer gives 3 outputs."""

    __slots__ = ("inputs", "layers", "_bytes")

    def __init__(self, layers: Any, inputs: Any = ("features",)) -> None:
        if isinstance(inputs, str):
            raise ValueError("inputs must be a list of names, e.g. ['features', 'view_dir']")
        names = [str(i) for i in inputs]
        parts = []
        copies = []
        for i, layer in enumerate(layers):
            try:
                w, b, act = layer
            except (TypeError, ValueError):
                raise ValueError(f"layer {i} must be (weight, bias, activation)") from None
            w = np.ascontiguousarray(_numpy(w), dtype="<f4")
            b = np.ascontiguousarray(_numpy(b), dtype="<f4").reshape(-1)
            if w.ndim != 2:
                raise ValueError(f"layer {i}: weight must be 2-D (outputs, inputs), got {w.shape}")
            if b.shape[0] != w.shape[0]:
                raise ValueError(f"layer {i}: bias has {b.shape[0]} values for {w.shape[0]} outputs")
            parts.append((int(w.shape[0]), int(w.shape[1]), w.tobytes(), b.tobytes(), str(act)))
            copies.append((w.copy(), b.copy(), str(act)))
        self._bytes = bytes(_native.shader_from_layers(names, parts))
        self.inputs = tuple(names)
        self.layers = copies

    @classmethod
    def _from_bytes(cls, data: bytes) -> "Shader":
        names, parts = _native.shader_layers(bytes(data))
        layers = [
            (
                np.frombuffer(w, dtype="<f4").reshape(o, i).copy(),
                np.frombuffer(b, dtype="<f4").copy(),
                act,
            )
            for (o, i, w, b, act) in parts
        ]
        return cls(layers, names)

    @classmethod
    def load(cls, path: Any) -> "Shader":
        """A shader file (safetensors, as ``render --shader`` reads it)."""
        return cls._from_bytes(bytes(_native.shader_file(str(path))))

    def to_bytes(self) -> bytes:
        """The network as safetensors bytes (what ``save`` writes)."""
        return self._bytes

    def save(self, path: Any, overwrite: bool = False) -> None:
        """Writes the shader for ``verisplat render --shader`` (atomically; an existing file
        only with ``overwrite``)."""
        import os
        import tempfile

        path = os.fspath(path)
        if os.path.exists(path) and not overwrite:
            raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
        fd, tmp = tempfile.mkstemp(prefix=".shader.", suffix=".tmp", dir=os.path.dirname(path) or ".")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(self._bytes)
            os.replace(tmp, path)
        except BaseException:
            os.unlink(tmp)
            raise

    @property
    def feature_channels(self) -> int:
        """The feature channels (K) the network takes."""
        extra = {"features": 0, "view_dir": 3, "alpha": 1}
        return self.layers[0][0].shape[1] - sum(extra[i] for i in self.inputs)

    def __repr__(self) -> str:
        widths = [self.layers[0][0].shape[1]] + [w.shape[0] for w, _, _ in self.layers]
        return f"Shader({'-'.join(map(str, widths))}, inputs {list(self.inputs)})"


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
    def stats(self) -> Dict[str, int]:
        """The device's last frame: its sorted (tile, Gaussian) ``pairs``, and the bands its
        backward pass was split into where its buffers exceed one storage binding
        (``backward_pixel_bands``, ``backward_pair_bands``; 1 each in one piece). Empty for
        the reference."""
        return {} if self._native is None else dict(self._native.stats)

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
        shader: Optional[Shader] = None,
        antialiased: bool = False,
        rules: str = "original",
        near_plane: Optional[float] = None,
        lens: Any = None,
        reproducible: bool = False,
    ) -> Forward:
        """Renders the Gaussians from one camera: ``colors`` (H, W, D) with the background,
        ``alphas`` (H, W), ``depths`` (H, W, alpha-normalised), and per Gaussian ``radii``,
        ``radii_xy`` (N, 2: per axis under gsplat's rules, else the radius twice),
        ``means2d`` (pixels), ``gaussian_depths``, ``conics`` and ``opacities`` (the
        blended ones: compensated with ``antialiased``, gsplat's ``rasterize_mode=
        "antialiased"``, opacity times sqrt(det(cov2d) / det(cov2d + 0.3 I))) (Vulkan
        backend). ``rules``: ``"original"`` (the 3DGS rasterizer's, the default) or
        ``"gsplat"`` (see the module's docstring); ``near_plane`` (None: the rules' 0.2 or
        0.01) culls the Gaussians nearer than it. With a
        ``shader``, ``colors`` are (N, K) feature values and the image is shaded (H, W, 3).
        ``lens`` (None: the pinhole) is another lens, as ``verisplat.Camera`` takes it
        (e.g. ``{"kind": "fisheye", "k": [k1, k2, k3, k4]}``, ``"orthographic"``): each
        Gaussian is then projected by the unscented transform through the lens's exact map
        (``means2d`` its mean, ``conics`` its covariance's inverse; ``gaussian_depths`` and
        ``depths`` the distance from the camera through a fisheye or equirectangular lens,
        else ``z``). The backward pass differentiates through the lens on both backends
        (the chain rule through the sigma points). ``reproducible``: the Vulkan backend
        blends with the CPU reference's exp and unfused arithmetic (the same bits on every
        device where the preprocess gives them; docs/reproducibility.md), forward and
        backward (the reference backend, in f64, has no such mode)."""
        cam = Camera(viewmat, K, width, height, lens=lens)
        params, channels, k = _params(means, quats, scales, opacities, colors, sh_degree)
        shader_bytes = None
        if shader is not None:
            if not isinstance(shader, Shader):
                raise TypeError("shader must be a verisplat.raster.Shader")
            if sh_degree is not None:
                raise ValueError("colors: a shader reads (N, K) feature values, not SH coefficients")
            if channels != shader.feature_channels:
                raise ValueError(
                    f"colors: the shader takes {shader.feature_channels} feature channels, "
                    f"colors has {channels}"
                )
            shader_bytes = shader.to_bytes()
            channels = 3
        bg = _background(background, channels)
        if self._native is not None and shader is None and channels != 3 and any(bg):
            raise ValueError(
                f"background: {channels} direct channels are blended without a background on "
                "the device (the reference backend takes one)"
            )
        if kernel not in ("gaussian", "power"):
            raise ValueError(f"kernel must be 'gaussian' or 'power', got {kernel!r}")
        if rules not in ("original", "gsplat"):
            raise ValueError(f"rules must be 'original' or 'gsplat', got {rules!r}")
        if near_plane is not None:
            near_plane = float(near_plane)
            if not (np.isfinite(near_plane) and near_plane > 0.0):
                raise ValueError(f"near_plane must be a positive number, got {near_plane}")
        f = Forward()
        f._params, f._camera, f._background, f._kernel = params, cam._tuple(), bg, kernel
        f._antialiased = bool(antialiased)
        f._rules = (rules, near_plane)
        f._reproducible = bool(reproducible)
        f._channels, f._k, f._backend, f._shader = channels, k, self.backend, shader
        h, w, n = cam.height, cam.width, params[0]
        if self._native is None:
            color, alpha, depth = _native.reference_forward(
                params, f._camera, bg, kernel, shader_bytes, f._antialiased, rules, near_plane
            )
            f.colors = np.frombuffer(color, dtype="<f8").reshape(h, w, channels)
            f.alphas = np.frombuffer(alpha, dtype="<f8").reshape(h, w)
            f.depths = np.frombuffer(depth, dtype="<f8").reshape(h, w)
            f._token = 0
            f.radii = f.radii_xy = f.means2d = f.gaussian_depths = f.conics = None
            f.opacities = None
            return f
        color, alpha, depth, token, projected = self._native.forward(
            params, f._camera, bg, kernel, shader_bytes, f._antialiased, rules, near_plane,
            f._reproducible,
        )
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
        f.opacities = proj[:, 2].copy()
        f.radii_xy = _radii_xy(f.radii, f.conics, f.opacities, rules)
        return f

    def backward(
        self,
        fwd: Forward,
        grad_colors: Optional[ArrayLike] = None,
        grad_alphas: Optional[ArrayLike] = None,
        grad_depths: Optional[ArrayLike] = None,
        screen: bool = False,
    ) -> Dict[str, np.ndarray]:
        """The gradients of a loss with respect to the forward pass's Gaussians, from its
        gradients with respect to the pixels (any of them may be None: zero). Returns
        ``means`` (N, 3), ``quats`` (N, 4, the unnormalised quaternions given), ``scales``,
        ``opacities``, ``colors`` (the shape given: SH (N, K, 3) with zeros past the degree,
        or (N, D)), ``means2d`` (N, 2, pixels) and ``absgrad`` (N, 2); for a shaded pass
        also ``shader_weights`` and ``shader_biases``, one array per layer. With
        ``screen`` (always from the reference backend) also ``screen`` (N, 8): dL/d(conic
        A, B, C), dL/d(the view's SH colour, 0 for direct values), dL/d(view depth), 0:
        the projected quantities' gradients, from which a camera's follows."""
        if not isinstance(fwd, Forward):
            raise TypeError("fwd must be what Rasterizer.forward returned")
        if fwd._backend != self.backend:
            raise ValueError(f"fwd came from the {fwd._backend} backend, this is {self.backend}")
        h, w = fwd.alphas.shape
        gc = _pixel_grad("grad_colors", grad_colors, (h, w, fwd._channels))
        ga = _pixel_grad("grad_alphas", grad_alphas, (h, w))
        gd = _pixel_grad("grad_depths", grad_depths, (h, w))
        shader_bytes = None if fwd._shader is None else fwd._shader.to_bytes()
        if self._native is None:
            raw = _native.reference_backward(
                fwd._params,
                fwd._camera,
                fwd._background,
                fwd._kernel,
                gc,
                ga,
                gd,
                shader_bytes,
                fwd._antialiased,
                *fwd._rules,
            )
            dtype = "<f8"
        else:
            raw = self._native.backward(
                fwd._params,
                fwd._camera,
                fwd._background,
                fwd._kernel,
                fwd._token,
                gc,
                ga,
                gd,
                shader_bytes,
                bool(screen),
                fwd._antialiased,
                *fwd._rules,
                fwd._reproducible,
            )
            if not screen:
                raw.pop("screen", None)
            dtype = "<f4"
        n = fwd._params[0]
        direct = fwd._params[7]
        out: Dict[str, Any] = {}
        for name, data in raw.items():
            if name in ("shader_weights", "shader_biases"):
                shapes = [
                    w.shape if name == "shader_weights" else b.shape
                    for w, b, _ in fwd._shader.layers
                ]
                out[name] = [
                    np.frombuffer(d, dtype=dtype).reshape(shape) for d, shape in zip(data, shapes)
                ]
                continue
            arr = np.frombuffer(data, dtype=dtype)
            if name in _GRAD_SHAPES:
                arr = arr.reshape(n, _GRAD_SHAPES[name])
            elif name == "colors":
                arr = arr.reshape(n, fwd._k, 3) if fwd._k else arr.reshape(n, direct)
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
