"""Input checks shared by the renderer modules (private).

Every message names the argument, the expectation and what was received.
"""

from __future__ import annotations

import numpy as np


def float_array(value: object, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """Return ``value`` as a finite float64 array of ``shape`` (``None`` = any length), or raise.

    Raises:
        TypeError: not numeric.
        ValueError: wrong shape, or NaN/Inf present (the count is reported).
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"{name}: expected numbers of shape {_fmt(shape)}, got {type(value).__name__}"
        ) from exc
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape, strict=True)):
        raise ValueError(f"{name}: expected shape {_fmt(shape)}, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        n_nan = int(np.count_nonzero(np.isnan(arr)))
        n_inf = int(np.count_nonzero(np.isinf(arr)))
        raise ValueError(f"{name}: expected finite values; got {n_nan} NaN and {n_inf} Inf of {arr.size}")
    return arr


def colour3(value: object, name: str) -> tuple[float, float, float]:
    """An RGB triple of finite non-negative floats (linear light), or a clear error."""
    arr = float_array(value, name, (3,))
    if (arr < 0).any():
        raise ValueError(f"{name}: expected non-negative linear RGB, got {tuple(arr.tolist())}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def vector3(value: object, name: str, *, unit: bool = False) -> tuple[float, float, float]:
    """A finite 3-vector; with ``unit=True`` it must be non-zero and is normalised."""
    arr = float_array(value, name, (3,))
    if unit:
        length = float(np.linalg.norm(arr))
        if length == 0.0:
            raise ValueError(f"{name}: expected a non-zero direction, got (0, 0, 0)")
        arr = arr / length
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def number(
    value: object, name: str, *, low: float | None = None, high: float | None = None, low_open: bool = False
) -> float:
    """A finite float within [low, high] (or (low, high] with ``low_open``), or a clear error."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    x = float(value)
    if not np.isfinite(x):
        raise ValueError(f"{name}: expected a finite number, got {x!r}")
    if low is not None and (x < low or (low_open and x == low)):
        bracket = "(" if low_open else "["
        raise ValueError(
            f"{name}: expected a value in {bracket}{low}, {high if high is not None else 'inf'}], got {x!r}"
        )
    if high is not None and x > high:
        raise ValueError(f"{name}: expected a value <= {high}, got {x!r}")
    return x


def _fmt(shape: tuple[int | None, ...]) -> str:
    return (
        "(" + ", ".join("N" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
    )
