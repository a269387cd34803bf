"""Input checks shared by every compositing function.

Policy (the same everywhere in the package):

* **Shape.** RGBA lives in the last axis: shape ``(..., 4)``. A single colour is
  shape ``(4,)`` and broadcasts against an image.
* **Dtype.** ``float32`` or ``float64`` arrays are accepted and kept. Integer,
  boolean, complex and ``float16`` arrays are rejected with :class:`TypeError`:
  8/16-bit pixels are sRGB-encoded straight alpha and must be decoded first
  (:mod:`compositing.io` does that). A plain Python sequence of numbers (e.g. the
  colour ``(0, 0, 1, 0.5)``) is not an array yet and is converted to ``float32``.
* **Finite values.** NaN or ±Inf anywhere is a :class:`ValueError` that reports how
  many values are not finite.
* **Alpha range.** Colour channels may be HDR (> 1) or negative, but alpha is a
  coverage and must lie in [0, 1]. Values outside are a :class:`ValueError`
  reporting the count and the range found; nothing is clamped silently. (The
  OpenGL blend emulation, which models a float framebuffer, does not apply this
  check.)
* **Broadcasting.** Shapes that do not broadcast are a :class:`ValueError` naming
  both arguments and their shapes.

Every message names the argument, the expectation and what was received.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "FLOAT_DTYPES",
    "alpha_range_error",
    "as_rgba",
    "broadcast_shapes",
    "check_alpha_range",
    "check_factor",
    "check_finite",
    "nonfinite_error",
]

#: The dtypes image arrays may have.
FLOAT_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


def _describe_dtype_problem(dtype: np.dtype) -> str:
    if dtype.kind in "iub":
        return (
            "integer and boolean arrays are rejected: decode 8/16-bit pixels to linear float "
            "first (compositing.io.read_image does that)"
        )
    return "use float32 or float64"


def as_rgba(
    x: object, name: str, *, allow_scalar_colour: bool = True, check_values: bool = True
) -> np.ndarray:
    """Return ``x`` as a float RGBA array of shape ``(..., 4)``, or raise a clear error.

    Args:
        x: an array of shape ``(..., 4)`` (float32 or float64, kept as is), or a
            Python sequence of four numbers (converted to float32).
        name: the argument name used in error messages.
        allow_scalar_colour: accept a single colour of shape ``(4,)``.
        check_values: also run :func:`check_finite` (NaN/Inf). Callers that fuse
            that check into their own kernel pass ``False``.

    Raises:
        TypeError: ``x`` is not array-like or has a non-float dtype.
        ValueError: the last axis is not 4, a single colour is not allowed here,
            or values are not finite.
    """
    if isinstance(x, np.ndarray):
        arr = x
        if arr.dtype not in FLOAT_DTYPES:
            raise TypeError(
                f"{name}: expected a float32 or float64 array of premultiplied RGBA, "
                f"got dtype {arr.dtype}; {_describe_dtype_problem(arr.dtype)}"
            )
    elif isinstance(x, Sequence | np.generic) and not isinstance(x, str | bytes):
        try:
            arr = np.asarray(x, dtype=np.float32)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name}: expected numbers for an RGBA colour or image, got {x!r}") from exc
    else:
        raise TypeError(
            f"{name}: expected a numpy float array of shape (..., 4) or a sequence of 4 numbers, "
            f"got {type(x).__name__}"
        )
    if arr.ndim == 0 or arr.shape[-1] != 4:
        raise ValueError(f"{name}: expected RGBA in the last axis, shape (..., 4); got shape {arr.shape}")
    if arr.ndim == 1 and not allow_scalar_colour:
        raise ValueError(f"{name}: expected an image of shape (..., 4) with at least 2 axes; got shape (4,)")
    if check_values:
        check_finite(arr, name)
    return arr


def nonfinite_error(name: str, n_nan: int, n_inf: int, size: int) -> ValueError:
    """The error for an array holding NaN or Inf (shared by the numpy and fused checks)."""
    return ValueError(
        f"{name}: expected finite values; got {n_nan + n_inf} non-finite of {size} ({n_nan} NaN, {n_inf} Inf)"
    )


def check_finite(x: np.ndarray, name: str) -> None:
    """Raise ValueError reporting how many values of ``x`` are NaN or ±Inf."""
    if not np.isfinite(x).all():
        n_nan = int(np.count_nonzero(np.isnan(x)))
        n_inf = int(np.count_nonzero(np.isinf(x)))
        raise nonfinite_error(name, n_nan, n_inf, x.size)


def alpha_range_error(name: str, count: int, lowest: float, highest: float, size: int) -> ValueError:
    """The error for alpha outside [0, 1] (shared by the numpy and fused checks)."""
    return ValueError(
        f"{name}: expected alpha (last channel) in [0, 1]; got {count} of {size} pixels outside, "
        f"alpha range [{lowest:.6g}, {highest:.6g}]"
    )


def check_alpha_range(x: np.ndarray, name: str) -> None:
    """Raise ValueError if any alpha ``x[..., 3]`` lies outside [0, 1] (count and range reported).

    ``x`` must already have passed :func:`as_rgba` (finite values).
    """
    alpha = x[..., 3]
    bad = (alpha < 0) | (alpha > 1)
    if bad.any():
        raise alpha_range_error(
            name, int(np.count_nonzero(bad)), float(alpha.min()), float(alpha.max()), alpha.size
        )


def broadcast_shapes(**arrays: np.ndarray) -> tuple[int, ...]:
    """The common broadcast shape of the named arrays, or a ValueError naming them all.

    Example: ``broadcast_shapes(src=src, dst=dst)``.
    """
    try:
        return np.broadcast_shapes(*(a.shape for a in arrays.values()))
    except ValueError:
        listing = ", ".join(f"{k} {v.shape}" for k, v in arrays.items())
        raise ValueError(f"shapes do not broadcast: {listing}") from None


def check_factor(factor: object, name: str, pixel_shape: tuple[int, ...]) -> float | np.ndarray:
    """Validate a mix factor: a number or a float array broadcastable to ``pixel_shape``, in [0, 1].

    ``pixel_shape`` is the image shape without the RGBA axis. An array must broadcast *to*
    it (the result has exactly that shape); a one-channel image of shape
    ``(*pixel_shape, 1)`` (as ``alpha[..., 3:]`` gives) is accepted and read without its
    last axis. Returns a Python float for a scalar, otherwise the array (float32/float64
    kept, shape broadcastable to ``pixel_shape``).
    """
    if isinstance(factor, bool) or not isinstance(factor, int | float | np.floating | np.ndarray):
        raise TypeError(f"{name}: expected a number or a float array in [0, 1], got {type(factor).__name__}")
    if isinstance(factor, np.ndarray) and factor.ndim > 0:
        if factor.dtype not in FLOAT_DTYPES:
            raise TypeError(f"{name}: expected a float32 or float64 array, got dtype {factor.dtype}")
        if factor.shape == (*pixel_shape, 1):
            factor = factor[..., 0]  # one value per pixel, written as a one-channel image
        try:
            fits = np.broadcast_shapes(factor.shape, pixel_shape) == tuple(pixel_shape)
        except ValueError:
            fits = False
        if not fits:
            raise ValueError(
                f"{name}: expected a shape that broadcasts to the pixel shape {pixel_shape} "
                f"(the image shape without the RGBA axis), or {(*pixel_shape, 1)}; got {factor.shape}"
            )
        check_finite(factor, name)
        if (factor < 0).any() or (factor > 1).any():
            raise ValueError(
                f"{name}: expected values in [0, 1]; "
                f"got range [{float(factor.min()):.6g}, {float(factor.max()):.6g}]"
            )
        return factor
    value = float(factor)
    if not np.isfinite(value) or not 0.0 <= value <= 1.0:
        raise ValueError(f"{name}: expected a number in [0, 1], got {value!r}")
    return value
