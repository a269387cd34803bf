"""Input checks shared by the renderer modules (private).

Every message names the argument, the expectation and what was received.
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Mapping, Sequence

import numpy as np


def float_array(value: object, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """Return ``value`` as a finite float64 array of ``shape`` (``None`` = any length), or raise.

    Raises:
        TypeError: not numeric, or complex (the imaginary part would be dropped silently).
        ValueError: wrong shape, or NaN/Inf present (the count is reported).
    """
    raw = value if isinstance(value, np.ndarray) else None
    if raw is None:
        try:
            raw = np.asarray(value)
        except (TypeError, ValueError):
            raw = None
    if raw is not None and raw.dtype.kind == "c":
        raise TypeError(f"{name}: expected real numbers of shape {_fmt(shape)}, got dtype {raw.dtype}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"{name}: expected numbers of shape {_fmt(shape)}, got {type(value).__name__}"
        ) from exc
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape, strict=True)):
        raise ValueError(f"{name}: expected shape {_fmt(shape)}, got shape {arr.shape}")
    _check_finite(arr, name)
    return arr


def real_array(value: object, name: str, *, last_axis: int | None = None) -> np.ndarray:
    """Return ``value`` as a finite float array of any shape, or raise.

    float32 and float64 arrays keep their dtype; integers, booleans and Python numbers
    become float64. With ``last_axis`` the array must have shape ``(..., last_axis)``.

    Raises:
        TypeError: not real numbers.
        ValueError: wrong last axis, or NaN/Inf present (the count is reported).
    """
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    if arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64)
    if last_axis is not None and (arr.ndim < 1 or arr.shape[-1] != last_axis):
        raise ValueError(f"{name}: expected shape (..., {last_axis}), got shape {arr.shape}")
    _check_finite(arr, name)
    return arr


def unit_interval_array(value: object, name: str, *, last_axis: int | None = None) -> np.ndarray:
    """:func:`real_array` whose values must also lie in [0, 1] (no clamping)."""
    arr = real_array(value, name, last_axis=last_axis)
    if arr.size and (arr.min() < 0 or arr.max() > 1):
        outside = int(np.count_nonzero((arr < 0) | (arr > 1)))
        raise ValueError(
            f"{name}: expected values in [0, 1]; got {outside} of {arr.size} outside, "
            f"range [{float(arr.min())!r}, {float(arr.max())!r}]"
        )
    return arr


def _check_finite(arr: np.ndarray, name: str) -> None:
    if not np.isfinite(arr).all():
        n_nan = int(np.count_nonzero(np.isnan(arr)))
        n_inf = int(np.count_nonzero(np.isinf(arr)))
        raise ValueError(f"{name}: expected finite values; got {n_nan} NaN and {n_inf} Inf of {arr.size}")


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


#: Lower bound of the memory one frame sample needs: the z-buffer pass (float64 depth and
#: int64 winner, 16 bytes) and the float32 per-sample buffers the resolve fills (RGBA 4, the
#: ambient/diffuse/specular passes 3 + 3 + 3, normal 3, depth 1: 68 bytes).
BYTES_PER_SAMPLE = 16 + 17 * 4
#: Lower bound per pixel: the float32 output images (RGBA, three passes, normal, depth).
BYTES_PER_PIXEL = 17 * 4


def frame_bytes(width: int, height: int, samples: int) -> int:
    """A lower bound of the bytes a ``width × height`` frame with ``samples`` per pixel allocates.

    Counts only the buffers every render fills (:data:`BYTES_PER_SAMPLE` per sample,
    :data:`BYTES_PER_PIXEL` per pixel); fragments, transparency layers and shadow maps
    come on top.
    """
    return int(width) * int(height) * (int(samples) * BYTES_PER_SAMPLE + BYTES_PER_PIXEL)


def physical_memory() -> int | None:
    """Bytes of physical memory of this machine, or None where the OS does not say."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def _bytes_text(n: float) -> str:
    for unit in ("bytes", "KB", "MB", "GB", "TB", "PB"):
        if n < 1000 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1000
    raise AssertionError("unreachable")


def check_frame_size(width: object, height: object, samples: object, memory: int | None = None) -> None:
    """Refuse a frame whose buffers cannot fit in memory, before anything is allocated.

    Args:
        width: image width in pixels, a positive integer.
        height: image height in pixels, a positive integer.
        samples: samples per pixel, a positive integer (the rasterizer checks it is a square).
        memory: bytes available; default: the machine's physical memory.

    Raises:
        ValueError: a size that is not a positive integer, or :func:`frame_bytes` above
            ``memory``; the message names width, height, samples and the bytes needed.
    """
    for value, name in ((width, "width"), (height, "height")):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
            raise ValueError(f"{name}: expected a positive integer number of pixels, got {value!r}")
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or samples < 1:
        raise ValueError(f"samples: expected a positive perfect square (1, 4, 9, 16, ...), got {samples!r}")
    limit = physical_memory() if memory is None else memory
    need = frame_bytes(width, height, samples)
    if limit is not None and need > limit:
        raise ValueError(
            f"width, height, samples: a {width} × {height} frame with {samples} sample(s) per pixel "
            f"needs at least {_bytes_text(need)} ({need} bytes: {BYTES_PER_SAMPLE} per sample + "
            f"{BYTES_PER_PIXEL} per pixel) but this machine has {_bytes_text(limit)} of memory; "
            "render fewer pixels or samples (or in tiles)"
        )


def choice_error(
    name: str,
    value: object,
    allowed: Sequence[object],
    *,
    also: str = "",
    aliases: Mapping[str, str] | None = None,
) -> ValueError:
    """The error for ``value`` not among ``allowed``, with a "did you mean" for a near miss.

    Args:
        name: the argument or field, as the caller spells it (``"shadows"``, ``"Fog.mode"``).
        value: what was received.
        allowed: the valid values.
        also: other accepted values to name first, e.g. ``"None, 'auto' or "``.
        aliases: other libraries' names for the valid values (``{"clamp_to_edge": "extend"}``):
            a value found there (case ignored) is answered with its valid name.

    Returns:
        ``ValueError("{name}: expected {also}one of {allowed}, got {value!r}; did you mean 'x'?")``
        (the last clause only when a valid name is close to a string ``value``; case is ignored).
    """
    message = f"{name}: expected {also}one of {tuple(allowed)}, got {value!r}"
    if isinstance(value, str) and aliases and value.lower() in aliases:
        return ValueError(message + f"; did you mean {aliases[value.lower()]!r}?")
    if isinstance(value, str):
        by_folded = {str(a).lower(): a for a in allowed}
        close = difflib.get_close_matches(value.lower(), list(by_folded), n=1, cutoff=0.6)
        if close:
            message += f"; did you mean {by_folded[close[0]]!r}?"
    return ValueError(message)
