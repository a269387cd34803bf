"""Error metrics for the speed/accuracy benchmarks and the failure suite.

Every error is measured on linear premultiplied RGBA (or on a scalar such as light
visibility) against a reference of the same shape, in **8-bit steps**: one step is
1/255 of the unit range, the smallest difference an 8-bit display buffer can hold.

* ``max_steps`` — ``255·max|x − ref|`` (the worst value anywhere);
* ``mean_steps`` — ``255·mean|x − ref|`` over all values;
* ``psnr_db`` — peak signal-to-noise ratio for peak 1 (the unit range),
  ``10·log10(1 / MSE)`` (Gonzalez & Woods, *Digital Image Processing*, 3rd ed., §8.1.5);
  ``None`` when the images are identical (MSE = 0, PSNR unbounded).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["STEP", "error_metrics", "has_nonfinite", "to_steps"]

#: One 8-bit step of the unit range.
STEP = 1.0 / 255.0


def _check_pair(image: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(image, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    if x.shape != r.shape:
        raise ValueError(f"image and reference must have the same shape; got {x.shape} and {r.shape}")
    if x.size == 0:
        raise ValueError("image: expected at least one value, got an empty array")
    for name, arr in (("image", x), ("reference", r)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        if bad:
            raise ValueError(f"{name}: expected finite values, got {bad} NaN/Inf of {arr.size}")
    return x, r


def to_steps(difference: float | np.ndarray) -> float | np.ndarray:
    """A difference in unit-range values expressed in 8-bit steps (``255·d``)."""
    return np.asarray(difference, dtype=np.float64) * 255.0


def error_metrics(image: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None) -> dict:
    """Max and mean absolute error in 8-bit steps and PSNR (dB, peak 1) of ``image`` against ``reference``.

    Args:
        image: any float array (e.g. premultiplied linear RGBA ``(..., 4)``, or visibilities).
        reference: the exact (or reference) values, same shape.
        mask: optional boolean array over the leading axes selecting the values compared
            (for RGBA, shape ``image.shape[:-1]``); all values by default.

    Returns:
        ``{"max_steps", "mean_steps", "psnr_db", "values"}``; ``psnr_db`` is ``None`` when the
        two are identical.

    Raises:
        ValueError: shapes differ, the arrays are empty or hold NaN/Inf, or the mask selects nothing.
    """
    x, r = _check_pair(image, reference)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != x.shape[: m.ndim]:
            raise ValueError(f"mask: expected shape {x.shape[: m.ndim]}, got {m.shape}")
        if not m.any():
            raise ValueError("mask: selects no values")
        x, r = x[m], r[m]
    diff = np.abs(x - r)
    mse = float(np.mean(diff**2))
    return {
        "max_steps": float(to_steps(diff.max())),
        "mean_steps": float(to_steps(diff.mean())),
        "psnr_db": None if mse == 0.0 else 10.0 * math.log10(1.0 / mse),
        "values": int(diff.size),
    }


def has_nonfinite(*arrays: np.ndarray) -> bool:
    """True if any of ``arrays`` holds a NaN or an infinity."""
    return any(not np.isfinite(np.asarray(a, dtype=np.float64)).all() for a in arrays)
