"""Transparency models per material, Kay–Greenberg transparency and specular wash-out.

A transparent surface changes the light arriving from behind it (``behind``, premultiplied
RGBA) in one of three ways; each is one blend of :mod:`compositing`:

* ``emission`` — the surface only adds light (fire, glow, a hologram): its reflected light
  is a premultiplied colour of alpha 0, ``src over`` the background, i.e.
  ``rgb' = c + behind.rgb``, ``α' = behind.α``. Order-independent (a sum).
* ``partial_occlusion`` — the surface covers a fraction ``α`` of the pixel (a net curtain,
  screen door, coverage): ``(α·c, α) src over behind = α·c + (1 − α)·behind``
  (Porter & Duff 1984).
* ``absorption`` — the surface filters what passes through it (coloured glass): each
  channel of the background is multiplied by the transmittance ``T``, the OpenGL blend
  ``glBlendFunc(GL_ZERO, GL_SRC_COLOR)`` (:func:`compositing.gl_blend`); alpha is kept.
  The light the surface reflects itself (``c``, e.g. its highlight) is then added as in
  ``emission``. Stacked filters multiply, so their order does not matter.

Kay & Greenberg, "Transparency for computer synthesized images", SIGGRAPH '79: a thin
curved shell looks more opaque towards its silhouette, where the view crosses more
material. With the eye-space normal's z component ``N_z`` (1 facing the viewer, 0 at the
silhouette) the transparency is ``t = t_min + (t_max − t_min)·[1 − (1 − |N_z|)^p]``;
the simple model is a constant ``t``. Opacity is ``1 − t``.

Specular highlights wash out transparency: a highlight on glass is opaque, so the opaque
fraction becomes ``(1 − t) + specular`` (specular = the highlight's intensity, e.g. the
Blinn–Phong specular term), limited to 1 since it is a coverage.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from compositing import composite, gl_blend

__all__ = [
    "TRANSPARENCY_MODELS",
    "blend_transparent_surface",
    "kay_greenberg_transparency",
    "washed_out_opacity",
]

TransparencyModel = Literal["emission", "partial_occlusion", "absorption"]
#: The three transparency models a material can use.
TRANSPARENCY_MODELS: tuple[str, ...] = ("emission", "partial_occlusion", "absorption")


def _real(name: str, value: np.ndarray | float) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiu":
        raise TypeError(f"{name} must be real numbers, got dtype {arr.dtype}")
    if arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got NaN or Inf")
    return arr


def _unit_interval(name: str, value: np.ndarray | float) -> np.ndarray:
    arr = _real(name, value)
    if arr.size and (arr.min() < 0 or arr.max() > 1):
        raise ValueError(f"{name} must lie in [0, 1], got range [{arr.min()}, {arr.max()}]")
    return arr


def kay_greenberg_transparency(
    normal_z: np.ndarray | float, t_min: float, t_max: float, power: float = 2.0
) -> np.ndarray:
    """Normal-modulated transparency ``t = t_min + (t_max − t_min)·[1 − (1 − |N_z|)^p]``.

    Kay & Greenberg 1979, in the form Foley, van Dam, Feiner & Hughes give in *Computer
    Graphics: Principles and Practice* (2nd ed.), section on transparency.

    Args:
        normal_z: z component of the unit eye-space normal (either sign), any shape.
        t_min: transparency at the silhouette (|N_z| = 0), in [0, 1].
        t_max: transparency facing the viewer (|N_z| = 1), in [0, 1].
        power: the exponent p > 0 (2–3 typical); larger keeps the centre clear longer.

    Returns:
        Transparency in [min(t_min, t_max), max(t_min, t_max)], shape and float dtype of ``normal_z``.
    """
    nz = _real("normal_z", normal_z)
    if nz.size and np.abs(nz).max() > 1 + 1e-6:
        raise ValueError(f"normal_z must be the z of a unit normal (|N_z| <= 1), got max {np.abs(nz).max()}")
    for name, v in (("t_min", t_min), ("t_max", t_max)):
        if not 0 <= v <= 1:
            raise ValueError(f"{name} must lie in [0, 1], got {v}")
    if not np.isfinite(power) or power <= 0:
        raise ValueError(f"power must be finite and > 0, got {power}")
    a = np.minimum(np.abs(nz), 1.0)
    return (t_min + (t_max - t_min) * (1.0 - (1.0 - a) ** power)).astype(nz.dtype, copy=False)


def washed_out_opacity(transparency: np.ndarray | float, specular: np.ndarray | float) -> np.ndarray:
    """Opaque fraction of a transparent surface with a highlight: ``min(1, (1 − t) + specular)``.

    Args:
        transparency: ``t`` in [0, 1] (1 = clear).
        specular: highlight intensity ≥ 0 (the specular term of the lighting, e.g. its luminance).

    Returns:
        Opacity in [0, 1] (broadcast shape).
    """
    t = _unit_interval("transparency", transparency)
    s = _real("specular", specular)
    if s.size and s.min() < 0:
        raise ValueError(f"specular must be >= 0, got minimum {s.min()}")
    return np.minimum(1.0, (1.0 - t) + s)


def blend_transparent_surface(
    surface_rgb: np.ndarray,
    behind: np.ndarray,
    model: TransparencyModel,
    *,
    opacity: np.ndarray | float | None = None,
    transmittance: np.ndarray | None = None,
) -> np.ndarray:
    """Put one transparent surface in front of ``behind`` by one of the three models.

    Args:
        surface_rgb: (..., 3) linear light the surface sends to the eye (its lit colour,
            not premultiplied).
        behind: (..., 4) premultiplied linear RGBA of what lies behind the surface.
        model: ``"emission"``, ``"partial_occlusion"`` or ``"absorption"``.
        opacity: coverage α in [0, 1] (scalar or ``behind.shape[:-1]``), for ``partial_occlusion``.
        transmittance: (..., 3) per-channel transmittance in [0, 1], for ``absorption``.

    Returns:
        (..., 4) premultiplied RGBA in the dtype of ``behind``.
    """
    rgb = _real("surface_rgb", surface_rgb)
    back = _real("behind", behind)
    if rgb.ndim < 1 or rgb.shape[-1] != 3:
        raise ValueError(f"surface_rgb must have shape (..., 3), got {rgb.shape}")
    if back.ndim < 1 or back.shape[-1] != 4:
        raise ValueError(f"behind must have shape (..., 4) (premultiplied RGBA), got {back.shape}")
    shape = np.broadcast_shapes(rgb.shape[:-1], back.shape[:-1])
    dtype = back.dtype
    rgb = np.broadcast_to(rgb, (*shape, 3)).astype(dtype)
    back = np.broadcast_to(back, (*shape, 4)).astype(dtype)
    glow = np.concatenate([rgb, np.zeros((*shape, 1), dtype=dtype)], axis=-1)
    if model == "emission":
        return composite(glow, back, "src_over")
    if model == "partial_occlusion":
        if opacity is None:
            raise ValueError("the partial_occlusion model needs opacity (coverage in [0, 1])")
        a = np.broadcast_to(_unit_interval("opacity", opacity), shape).astype(dtype)[..., None]
        return composite(np.concatenate([rgb * a, a], axis=-1), back, "src_over")
    if model == "absorption":
        if transmittance is None:
            raise ValueError("the absorption model needs transmittance ((..., 3) in [0, 1])")
        t = _unit_interval("transmittance", transmittance)
        if t.ndim < 1 or t.shape[-1] != 3:
            raise ValueError(f"transmittance must have shape (..., 3), got {t.shape}")
        t = np.broadcast_to(t, (*shape, 3)).astype(dtype)
        filt = np.concatenate([t, np.ones((*shape, 1), dtype=dtype)], axis=-1)
        filtered = gl_blend(filt, back, "ZERO", "SRC_COLOR", src_factor_alpha="ZERO", dst_factor_alpha="ONE")
        return composite(glow, filtered.astype(dtype, copy=False), "src_over")
    raise ValueError(f"model must be one of {TRANSPARENCY_MODELS}, got {model!r}")
