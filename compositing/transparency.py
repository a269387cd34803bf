"""The three transparency models, and the union of independent coverages.

A transparent surface in front of a background colour ``B`` (premultiplied RGBA)
can act in three ways (the usual classification of real-time rendering courses;
see also Akenine-Möller et al., *Real-Time Rendering*, 4th ed., §5.5):

=====================  ==============================  =====================================
model                  result                          OpenGL blend state (premultiplied)
=====================  ==============================  =====================================
emission (additive)    ``B + (E, 0)``                  ``glBlendFunc(ONE, ONE)``, src α = 0
partial occlusion      ``S + B·(1 − αS)`` (over)       ``glBlendFunc(ONE, ONE_MINUS_SRC_ALPHA)``
absorption (filter)    ``(B.rgb ⊙ T, B.α)``            ``glBlendFunc(ZERO, SRC_COLOR)``, src = (T, 1)
=====================  ==============================  =====================================

Emission adds light without covering anything (a glow pixel: rgb > 0 at α = 0,
which premultiplied ``src_over`` already handles). Partial occlusion is
Porter-Duff ``src_over`` (computed by :func:`compositing.composite`). Absorption
multiplies the light coming through by the filter's transmittance ``T`` per
channel and leaves the background's coverage unchanged.

Coverage: two independent (uncorrelated) coverages ``a1`` and ``a2`` of the same
pixel together cover ``a1 + a2 − a1·a2 = 1 − (1 − a1)(1 − a2)`` (Porter & Duff
1984, §3: the probability that a random point of the pixel lies in either
shape). It is the alpha of ``src_over``.
"""

from __future__ import annotations

import numpy as np

from .operators import composite
from .validate import as_rgba, broadcast_shapes, check_alpha_range, check_finite

__all__ = ["absorption", "coverage_union", "emission", "partial_occlusion"]


def _as_rgb(x: object, name: str, *, unit_range: bool) -> np.ndarray:
    """A float RGB array ``(..., 3)`` (or a 3-sequence, as float32), finite, optionally in [0, 1]."""
    if isinstance(x, np.ndarray):
        arr = x
        if arr.dtype not in (np.float32, np.float64):
            raise TypeError(f"{name}: expected a float32 or float64 RGB array, got dtype {arr.dtype}")
    else:
        try:
            arr = np.asarray(x, dtype=np.float32)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name}: expected three numbers or an RGB array, got {x!r}") from exc
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise ValueError(f"{name}: expected RGB in the last axis, shape (..., 3); got shape {arr.shape}")
    check_finite(arr, name)
    if unit_range and ((arr < 0).any() or (arr > 1).any()):
        raise ValueError(
            f"{name}: expected values in [0, 1] (a filter cannot amplify light); "
            f"got range [{float(arr.min()):.6g}, {float(arr.max()):.6g}]"
        )
    return arr


def _with_alpha(rgb: np.ndarray, alpha: float) -> np.ndarray:
    return np.concatenate([rgb, np.full((*rgb.shape[:-1], 1), alpha, rgb.dtype)], axis=-1)


def emission(emitted: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Additive transparency: ``background + (emitted, 0)``; coverage unchanged.

    Args:
        emitted: linear emitted radiance, RGB ``(..., 3)``, finite (may exceed 1).
        background: linear premultiplied RGBA ``(..., 4)``, alpha in [0, 1].

    Returns:
        Premultiplied RGBA of the broadcast shape; equals ``src_over`` of the glow
        pixel ``(emitted, 0)`` and ``glBlendFunc(ONE, ONE)`` with source alpha 0.
    """
    light = _as_rgb(emitted, "emitted", unit_range=False)
    b = _checked_rgba(background, "background")
    broadcast_shapes(emitted=_with_alpha(light, 0.0), background=b)
    return composite(_with_alpha(light, 0.0), b, "plus")


def _checked_rgba(x: object, name: str) -> np.ndarray:
    """Premultiplied RGBA with alpha in [0, 1], errors naming the caller's argument ``name``."""
    arr = as_rgba(x, name)
    check_alpha_range(arr, name)
    return arr


def partial_occlusion(surface: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Alpha blending: a surface of premultiplied colour ``S`` and coverage ``αS`` over the background.

    ``S + B·(1 − αS)``, Porter & Duff's ``over``; both arguments premultiplied RGBA
    ``(..., 4)`` with alpha in [0, 1]. Errors name ``surface`` or ``background``.
    """
    s = _checked_rgba(surface, "surface")
    b = _checked_rgba(background, "background")
    broadcast_shapes(surface=s, background=b)
    return composite(s, b, "src_over")


def absorption(transmittance: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Multiplicative filter: ``(background.rgb · T, background.α)``.

    Args:
        transmittance: fraction of light let through per channel, RGB ``(..., 3)``
            in [0, 1] (1 = clear, 0 = opaque black filter).
        background: linear premultiplied RGBA ``(..., 4)``, alpha in [0, 1].

    Returns:
        Premultiplied RGBA of the broadcast shape, in the common float dtype.
    """
    t = _as_rgb(transmittance, "transmittance", unit_range=True)
    b = as_rgba(background, "background")
    check_alpha_range(b, "background")
    shape = broadcast_shapes(transmittance=_with_alpha(t, 1.0), background=b)
    dtype = np.result_type(t, b)
    out = np.empty(shape, dtype)
    out[..., :3] = b[..., :3] * t
    out[..., 3] = b[..., 3]
    return out


def coverage_union(a1: np.ndarray | float, a2: np.ndarray | float) -> np.ndarray:
    """Coverage of a pixel by two independent shapes: ``a1 + a2 − a1·a2``.

    Args:
        a1: coverage in [0, 1], a number or float array.
        a2: the same, broadcastable with ``a1``.

    Returns:
        The union coverage as a float array (float64 for Python numbers).
    """
    arrays = []
    for value, name in ((a1, "a1"), (a2, "a2")):
        arr = np.asarray(value, dtype=np.float64) if not isinstance(value, np.ndarray) else value
        if arr.dtype not in (np.float32, np.float64):
            raise TypeError(
                f"{name}: expected a float coverage (number or float array), got dtype {arr.dtype}"
            )
        check_finite(arr, name)
        if (arr < 0).any() or (arr > 1).any():
            raise ValueError(
                f"{name}: expected coverage in [0, 1]; "
                f"got range [{float(arr.min()):.6g}, {float(arr.max()):.6g}]"
            )
        arrays.append(arr)
    first, second = arrays
    try:
        np.broadcast_shapes(first.shape, second.shape)
    except ValueError:
        raise ValueError(f"shapes do not broadcast: a1 {first.shape}, a2 {second.shape}") from None
    return first + second - first * second
