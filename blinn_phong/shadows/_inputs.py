"""Checks of the arrays the shadow methods take, shared by the methods of :mod:`blinn_phong.shadows`.

:func:`checked_triangles` and :func:`checked_points` check shapes and finiteness and return
float64 arrays; inside :func:`trusted_arrays` the arrays a caller made itself skip the checks.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator

import numpy as np

#: ids of float64 arrays already checked by the light_visibility call running in this context
_CHECKED: contextvars.ContextVar[frozenset[int]] = contextvars.ContextVar("checked", default=frozenset())


@contextlib.contextmanager
def trusted_arrays(*arrays: np.ndarray) -> Iterator[None]:
    """Inside the block the shadow functions skip the shape and finiteness checks of these arrays.

    For a caller that made them itself (the frame pipeline's world points, face normals and
    caster triangles, finite float64 arrays of the right shapes): a 1.3 M-point frame then checks
    its points once, not once per light. Arrays not listed are checked as usual.
    """
    token = _CHECKED.set(_CHECKED.get() | frozenset(id(a) for a in arrays))
    try:
        yield
    finally:
        _CHECKED.reset(token)


def checked_triangles(name: str, value: np.ndarray) -> np.ndarray:
    """``value`` as a float64 (n, 3, 3) array of finite triangles (``name``: the argument's, for errors)."""
    tris = np.asarray(value)
    if id(tris) in _CHECKED.get():
        return tris
    if tris.dtype.kind not in "fiu" or tris.ndim != 3 or tris.shape[1:] != (3, 3):
        raise ValueError(f"{name} must be a real array of shape (n, 3, 3), got {tris.dtype} {tris.shape}")
    if not np.all(np.isfinite(tris)):
        raise ValueError(f"{name} must be finite, got NaN or Inf")
    return tris.astype(np.float64, copy=False)


def checked_points(name: str, value: np.ndarray) -> np.ndarray:
    """``value`` as a float64 (n, 3) array of finite points; ``name`` is the argument's name in errors."""
    arr = np.asarray(value)
    if id(arr) in _CHECKED.get():
        return arr
    if arr.dtype.kind not in "fiu" or arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must be a real array of shape (n, 3), got {arr.dtype} {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got NaN or Inf")
    return arr.astype(np.float64, copy=False)


def homogeneous(points: np.ndarray) -> np.ndarray:
    """(n, 4) homogeneous coordinates ``(x, y, z, 1)`` of (n, 3) points."""
    return np.concatenate([points, np.ones((len(points), 1))], axis=1)
