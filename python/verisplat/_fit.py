"""``fit``: Gaussians with feature channels fitted to field samples."""

from __future__ import annotations

from typing import Optional, Sequence

from . import _native
from ._common import ArrayLike, _floats, _numpy
from ._scene import Scene


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
