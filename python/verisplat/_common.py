"""The package's shared helpers: the type aliases of its signatures, numpy arrays of what
callers pass, float32 views of the bytes the extension returns, and the library's messages
in Python's argument names."""

from __future__ import annotations

import os
from typing import Any, Optional, Tuple, Union

import numpy as np

PathLike = Union[str, "os.PathLike[str]"]
ArrayLike = Any


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


# The library's messages name the command line's flags; Python callers get their own
# argument names.
_FLAG_NAMES = (("pass --overwrite", "pass overwrite=True"), ("--sh-degree", "sh_degree"))


def _python_names(e: Exception) -> Exception:
    text = str(e)
    for flag, argument in _FLAG_NAMES:
        text = text.replace(flag, argument)
    return type(e)(text)
