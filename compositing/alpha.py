"""Conversions between straight (unassociated) and premultiplied (associated) alpha.

Premultiplied ``(r·a, g·a, b·a, a)`` from straight ``(r, g, b, a)`` (Porter & Duff
1984, §2; Blender's Alpha Convert node; OIIO ``ImageBufAlgo.premult``). The
inverse divides by alpha, which needs a policy where α = 0:

==========  =====================================================  =======================
policy      α = 0 pixel becomes                                    as in
==========  =====================================================  =======================
``keep``    colour unchanged                                       Blender Alpha Convert,
                                                                   OIIO ``unpremult``
``zero``    rgb = 0                                                Skia ``unpremul``
``raise``   ValueError naming the count                            —
==========  =====================================================  =======================

A "glow" pixel (rgb > 0 with α = 0, light added without coverage) is lost by a
plain premultiply. ``premultiply(x, keep_zero_alpha=True)`` leaves α = 0 colour
untouched, as OIIO's ``repremult`` does, so ``unpremultiply(keep)`` followed by it
round-trips glow.
"""

from __future__ import annotations

import numpy as np

from .validate import as_rgba, check_alpha_range

__all__ = ["ZERO_ALPHA_POLICIES", "premultiply", "unpremultiply"]

#: Policies ``unpremultiply`` accepts for α = 0.
ZERO_ALPHA_POLICIES = ("keep", "zero", "raise")


def premultiply(rgba: np.ndarray, *, keep_zero_alpha: bool = False) -> np.ndarray:
    """Straight RGBA to premultiplied: ``(rgb·a, a)``.

    Args:
        rgba: linear straight-alpha RGBA ``(..., 4)``, float32/float64, alpha in [0, 1].
        keep_zero_alpha: leave the colour of α = 0 pixels unchanged instead of
            zeroing it (OIIO ``repremult``; keeps glow through a round trip).

    Returns:
        A new premultiplied array, same shape and dtype.
    """
    x = as_rgba(rgba, "rgba")
    check_alpha_range(x, "rgba")
    out = np.array(x, copy=True)
    alpha = x[..., 3:4]
    if keep_zero_alpha:
        out[..., :3] = np.where(alpha == 0, x[..., :3], x[..., :3] * alpha)
    else:
        out[..., :3] *= alpha
    return out


def unpremultiply(rgba: np.ndarray, zero_alpha: str = "keep") -> np.ndarray:
    """Premultiplied RGBA to straight: ``(rgb / a, a)`` where a > 0.

    Args:
        rgba: linear premultiplied RGBA ``(..., 4)``, float32/float64, alpha in [0, 1].
        zero_alpha: what α = 0 pixels become: ``"keep"`` (colour unchanged, as
            Blender and OIIO), ``"zero"`` (rgb = 0, as Skia) or ``"raise"``
            (ValueError if any pixel has α = 0).

    Returns:
        A new straight-alpha array, same shape and dtype.

    Raises:
        ValueError: unknown policy; α = 0 under ``"raise"``; or a division that
            overflows the dtype (tiny alpha under a large colour), reported with
            the number of pixels, rather than writing Inf.
    """
    if zero_alpha not in ZERO_ALPHA_POLICIES:
        raise ValueError(f"zero_alpha: expected one of {ZERO_ALPHA_POLICIES}, got {zero_alpha!r}")
    x = as_rgba(rgba, "rgba")
    check_alpha_range(x, "rgba")
    alpha = x[..., 3:4]
    zero = alpha == 0
    if zero_alpha == "raise" and zero.any():
        raise ValueError(
            f"rgba: expected alpha > 0 everywhere (zero_alpha='raise'); got {int(np.count_nonzero(zero))} "
            f"pixels with alpha = 0 of {alpha.size}"
        )
    with np.errstate(over="ignore"):
        divided = x[..., :3] / np.where(zero, 1, alpha)
    if not np.isfinite(divided).all():
        n = int(np.count_nonzero(~np.isfinite(divided).all(axis=-1)))
        raise ValueError(
            f"rgba: unpremultiplying overflows {x.dtype} in {n} pixels (colour far above a tiny alpha)"
        )
    out = np.array(x, copy=True)
    out[..., :3] = np.where(zero, 0 if zero_alpha == "zero" else x[..., :3], divided)
    return out
