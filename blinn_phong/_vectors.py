"""Vector operations every room uses (below the rooms: imports nothing of the renderer)."""

from __future__ import annotations

import numpy as np

__all__ = ["normalize"]


def normalize(vectors: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis; zero-length vectors stay zero (no NaN).

    Each vector is divided by its largest absolute component before its length is taken,
    ``v/|v| = (v/m)/|v/m|`` with ``m = max|v_i|`` (the scaling of LAPACK's ``dnrm2``), so
    lengths whose square under- or overflows (float64 ``1e-200``, ``1e200``; float32
    ``1e-23``, ``3e19``) still normalise. float32 and float64 keep their dtype; integers and
    booleans become float64.

    Args:
        vectors: (..., k) finite vectors (any unit).

    Returns:
        (..., k) unit vectors (or zero vectors), float32 or float64.
    """
    v = np.asarray(vectors)
    if v.dtype.kind not in "fiub":
        raise TypeError(f"vectors: expected real numbers, got dtype {v.dtype}")
    if v.dtype not in (np.float32, np.float64):
        v = v.astype(np.float64)
    if v.ndim == 0:
        raise ValueError("vectors: expected shape (..., k), got a scalar")
    largest = np.max(np.abs(v), axis=-1, keepdims=True, initial=0.0)
    nonzero = largest > 0
    scaled = v / np.where(nonzero, largest, 1)
    length = np.sqrt(np.einsum("...i,...i->...", scaled, scaled))[..., None]
    return np.where(nonzero, scaled / np.where(nonzero, length, 1), 0).astype(v.dtype, copy=False)
