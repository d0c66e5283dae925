"""Scenes: ``Scene`` (a set of 3D Gaussians), ``load`` and ``demo``."""

from __future__ import annotations

import os
from typing import Any, Dict, Optional, Tuple

import numpy as np

from . import _native
from ._common import ArrayLike, PathLike, _floats, _numpy, _python_names, _view


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
            sh_a = ((c - 0.5) / _native.SH_C0).astype("<f4").reshape(n, 1, 3)
        else:
            sh_a = _numpy(sh)
            if sh_a.ndim != 3 or sh_a.shape[0] != n or sh_a.shape[2] != 3:
                raise ValueError(f"sh must have shape ({n}, K, 3), got {tuple(sh_a.shape)}")
            sh_a = _floats("sh", sh_a, (n, sh_a.shape[1], 3), strict=True)
        feats = None
        if features is not None:
            fa = _numpy(features)
            most = _native.MAX_FEATURES
            if fa.ndim != 2 or fa.shape[0] != n or not 1 <= fa.shape[1] <= most:
                raise ValueError(f"features must have shape ({n}, K) with K 1..{most}, got {tuple(fa.shape)}")
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

    def save(self, path: PathLike, overwrite: bool = False, spz_axes: str = "spec") -> None:
        """Writes the scene as .ply (lossless), .splat, .spz, .compressed.ply
        (PlayCanvas), .sog (PlayCanvas SOG bundle), ``DIR/meta.json`` (an unbundled
        SOG, its WebP textures beside it), .glb or .gltf (glTF with
        KHR_gaussian_splatting; a .gltf's buffer embedded), by name, atomically; an existing file is refused unless ``overwrite``. ``spz_axes`` is the
        frame of a .spz: ``"spec"`` (the SPZ spec's RUB axes) or ``"raw"`` (PLY axes as
        they are, what PlayCanvas's splat-transform reads); docs/formats.md, "SPZ"."""
        try:
            self._s.save(os.fspath(path), overwrite, spz_axes)
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


def load(path: PathLike, iteration: Optional[int] = None, spz_axes: str = "spec") -> Scene:
    """Loads a scene: INRIA .ply, compressed .ply, .splat, .spz, SOG, or a trained model
    directory (``iteration`` picks point_cloud/iteration_N, default the largest).
    ``spz_axes`` is the frame of a .spz file, which the file does not record: ``"spec"``
    (the SPZ spec's RUB axes: Niantic's spz library, verisplat) or ``"raw"`` (PLY axes as
    they are: PlayCanvas's splat-transform); docs/formats.md, "SPZ"."""
    return Scene(_native.load(os.fspath(path), iteration, spz_axes))


def demo() -> Scene:
    """The built-in demo scene (PLAYBOT, 1,873 Gaussians, CC BY 4.0)."""
    return Scene(_native.demo())
