"""Transparency models per material, Kay–Greenberg transparency and specular wash-out.

A transparent surface of lit colour ``c`` (linear RGB, not premultiplied) changes the light
arriving from behind it (``behind``, premultiplied RGBA) in one of three ways. Each model is
one function here, computed by the one implementation of the three models,
:mod:`compositing.transparency` (:func:`compositing.emission`,
:func:`compositing.partial_occlusion`, :func:`compositing.absorption`):

* ``emission`` — the surface only adds light (fire, glow, a hologram), scaled by its
  opacity ``α``: ``rgb' = α·c + behind.rgb``, ``α' = behind.α``. Order-independent (a sum).
  As a fragment: ``(α·c, 0)`` ``src over`` the background.
* ``partial_occlusion`` — the surface covers a fraction ``α`` of the pixel (a net curtain,
  screen door, coverage): ``(α·c, α) over behind = α·c + (1 − α)·behind``
  (Porter & Duff 1984).
* ``absorption`` — the surface filters what passes through it (coloured glass): each
  channel of the background is multiplied by the transmittance ``T`` (the OpenGL blend
  ``glBlendFunc(GL_ZERO, GL_SRC_COLOR)``), alpha is kept; the light the surface reflects
  itself (``c``, e.g. its highlight) is then added as in ``emission``:
  ``rgb' = c + T ⊙ behind.rgb``. Stacked filters multiply, so their order does not matter.
  A material's opacity ``α`` is the grey filter ``T = 1 − α``.

The renderer resolves fragments with ``src over`` (:mod:`blinn_phong.effects.oit`), so it asks
:func:`transparent_fragment` for the premultiplied fragment that gives each model:
``(α·c, α)``, ``(α·c, 0)`` and ``(c, α)``. Over an opaque background the three fragments
give exactly the three functions above. Over a partly transparent background
(``behind.α < 1``) the absorption fragment's alpha is ``α + (1 − α)·behind.α`` rather than
``behind.α``: the filter is counted as coverage, so that a backdrop ``W`` composited later
is filtered too (``c + T·(behind.rgb + (1 − behind.α)·W)``), which a single premultiplied
alpha can express only for a grey filter.

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

import compositing
from blinn_phong._checks import choice_error, number, real_array, unit_interval_array

__all__ = [
    "TRANSPARENCY_MODELS",
    "absorption_surface",
    "blend_transparent_surface",
    "emission_surface",
    "kay_greenberg_transparency",
    "partial_occlusion_surface",
    "transparent_fragment",
    "washed_out_opacity",
]

TransparencyModel = Literal["partial_occlusion", "emission", "absorption"]
#: The three transparency models a material can use (the first is a material's default).
TRANSPARENCY_MODELS: tuple[str, ...] = ("partial_occlusion", "emission", "absorption")


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
    nz = real_array(normal_z, "normal_z")
    if nz.size and np.abs(nz).max() > 1 + 1e-6:
        raise ValueError(
            f"normal_z: expected the z of a unit normal, |N_z| <= 1 (+1e-6), got max {np.abs(nz).max()!r}"
        )
    t_min = number(t_min, "t_min", low=0.0, high=1.0)
    t_max = number(t_max, "t_max", low=0.0, high=1.0)
    power = number(power, "power", low=0.0, low_open=True)
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
    t = unit_interval_array(transparency, "transparency")
    s = real_array(specular, "specular")
    if s.size and s.min() < 0:
        negative = int(np.count_nonzero(s < 0))
        raise ValueError(f"specular: expected values >= 0, got {negative} negative (minimum {s.min()!r})")
    return np.minimum(1.0, (1.0 - t) + s)


def _surface_and_behind(surface_rgb: object, behind: object) -> tuple[np.ndarray, np.ndarray]:
    """The lit colour as (..., 3) and ``behind`` as (..., 4), both in ``behind``'s float dtype."""
    back = real_array(behind, "behind", last_axis=4)
    rgb = real_array(surface_rgb, "surface_rgb", last_axis=3).astype(back.dtype, copy=False)
    return rgb, back


def _opacity(opacity: object, dtype: np.dtype) -> np.ndarray:
    """Opacity in [0, 1] as a (..., 1) array in ``dtype`` (broadcasts against RGB or RGBA)."""
    return unit_interval_array(opacity, "opacity").astype(dtype, copy=False)[..., None]


def emission_surface(surface_rgb: np.ndarray, behind: np.ndarray, *, opacity: object = 1.0) -> np.ndarray:
    """The emission model: ``rgb' = α·c + behind.rgb``, ``α' = behind.α`` (additive, order-free).

    Computed by :func:`compositing.emission` with the emitted light ``α·c``.

    Args:
        surface_rgb: (..., 3) linear light ``c`` the surface sends to the eye (not premultiplied).
        behind: (..., 4) premultiplied linear RGBA behind the surface.
        opacity: ``α`` in [0, 1], a number or an array of ``behind.shape[:-1]``; it scales the
            glow (1 by default: the full lit colour is added).

    Returns:
        (..., 4) premultiplied RGBA (broadcast shape) in the float dtype of ``behind``.
    """
    rgb, back = _surface_and_behind(surface_rgb, behind)
    return compositing.emission(_opacity(opacity, back.dtype) * rgb, back)


def partial_occlusion_surface(surface_rgb: np.ndarray, behind: np.ndarray, *, opacity: object) -> np.ndarray:
    """The partial-occlusion model: ``(α·c, α) over behind = α·c + (1 − α)·behind`` (Porter & Duff 1984).

    Computed by :func:`compositing.partial_occlusion`.

    Args:
        surface_rgb: (..., 3) linear lit colour ``c`` (not premultiplied).
        behind: (..., 4) premultiplied linear RGBA behind the surface.
        opacity: coverage ``α`` in [0, 1], a number or an array of ``behind.shape[:-1]``.

    Returns:
        (..., 4) premultiplied RGBA (broadcast shape) in the float dtype of ``behind``.
    """
    rgb, back = _surface_and_behind(surface_rgb, behind)
    a = _opacity(opacity, back.dtype)
    shape = np.broadcast_shapes(rgb.shape[:-1], a.shape[:-1])
    surface = np.concatenate(
        [np.broadcast_to(a * rgb, (*shape, 3)), np.broadcast_to(a, (*shape, 1))], axis=-1
    )
    return compositing.partial_occlusion(surface, back)


def absorption_surface(surface_rgb: np.ndarray, behind: np.ndarray, *, transmittance: object) -> np.ndarray:
    """The absorption model: ``rgb' = c + T ⊙ behind.rgb``, ``α' = behind.α`` (a filter plus its own light).

    The filter is :func:`compositing.absorption` (``glBlendFunc(GL_ZERO, GL_SRC_COLOR)`` with
    source ``(T, 1)``); the surface's own light ``c`` is then added by :func:`compositing.emission`.

    Args:
        surface_rgb: (..., 3) linear light ``c`` the surface reflects itself (e.g. its highlight).
        behind: (..., 4) premultiplied linear RGBA behind the surface.
        transmittance: ``T`` in [0, 1], per channel (..., 3), or one number for a grey filter
            (a material of opacity ``α`` is the grey filter ``1 − α``).

    Returns:
        (..., 4) premultiplied RGBA (broadcast shape) in the float dtype of ``behind``.
    """
    rgb, back = _surface_and_behind(surface_rgb, behind)
    t = unit_interval_array(transmittance, "transmittance").astype(back.dtype, copy=False)
    if t.ndim == 0:
        t = np.full(3, t, dtype=back.dtype)
    elif t.shape[-1] != 3:
        raise ValueError(f"transmittance: expected a number or shape (..., 3), got shape {t.shape}")
    return compositing.emission(rgb, compositing.absorption(t, back))


def blend_transparent_surface(
    surface_rgb: np.ndarray,
    behind: np.ndarray,
    model: TransparencyModel,
    *,
    opacity: object = None,
    transmittance: object = None,
) -> np.ndarray:
    """Put one transparent surface in front of ``behind`` by one of the three models.

    Dispatches to :func:`emission_surface`, :func:`partial_occlusion_surface` or
    :func:`absorption_surface` (formulas in the module docstring).

    Args:
        surface_rgb: (..., 3) linear light the surface sends to the eye (its lit colour,
            not premultiplied).
        behind: (..., 4) premultiplied linear RGBA of what lies behind the surface.
        model: ``"emission"``, ``"partial_occlusion"`` or ``"absorption"``.
        opacity: ``α`` in [0, 1] (number or ``behind.shape[:-1]``): required by
            ``partial_occlusion``, optional for ``emission`` (default 1), refused by ``absorption``.
        transmittance: ``T`` in [0, 1] ((..., 3) or a number): required by ``absorption``,
            refused by the other two models.

    Returns:
        (..., 4) premultiplied RGBA in the float dtype of ``behind``.

    Raises:
        ValueError: unknown model, a missing parameter, or a parameter the model does not use.
    """
    if model not in TRANSPARENCY_MODELS:
        raise choice_error("model", model, TRANSPARENCY_MODELS)
    if model == "absorption":
        if opacity is not None:
            raise ValueError(
                "opacity: the absorption model does not use it; pass transmittance "
                f"(the grey filter of opacity a is 1 - a), got opacity={opacity!r}"
            )
        if transmittance is None:
            raise ValueError("transmittance: the absorption model needs it ((..., 3) or a number in [0, 1])")
        return absorption_surface(surface_rgb, behind, transmittance=transmittance)
    if transmittance is not None:
        raise ValueError(
            f"transmittance: the {model} model does not use it (only absorption does), "
            f"got transmittance={transmittance!r}"
        )
    if model == "emission":
        return emission_surface(surface_rgb, behind, opacity=1.0 if opacity is None else opacity)
    if opacity is None:
        raise ValueError("opacity: the partial_occlusion model needs it (coverage in [0, 1])")
    return partial_occlusion_surface(surface_rgb, behind, opacity=opacity)


def transparent_fragment(surface_rgb: np.ndarray, opacity: object, model: TransparencyModel) -> np.ndarray:
    """The premultiplied fragment whose ``src over`` the background gives ``model``.

    ``partial_occlusion``: ``(α·c, α)``; ``emission``: ``(α·c, 0)``; ``absorption``: ``(c, α)``,
    the grey filter ``T = 1 − α``. Over an opaque background, ``fragment over behind`` equals
    :func:`blend_transparent_surface` exactly; over a partly transparent one the absorption
    fragment also counts the filter as coverage (module docstring).

    Args:
        surface_rgb: (N, 3) or (..., 3) linear lit colour ``c`` (not premultiplied).
        opacity: ``α`` in [0, 1], shape ``surface_rgb.shape[:-1]`` or a number.
        model: one of :data:`TRANSPARENCY_MODELS`.

    Returns:
        (..., 4) premultiplied RGBA in the float dtype of ``surface_rgb`` (float64 for integers).
    """
    if model not in TRANSPARENCY_MODELS:
        raise choice_error("model", model, TRANSPARENCY_MODELS)
    rgb = real_array(surface_rgb, "surface_rgb", last_axis=3)
    a = _opacity(opacity, rgb.dtype)
    shape = np.broadcast_shapes(rgb.shape[:-1], a.shape[:-1])
    colour = rgb if model == "absorption" else a * rgb
    alpha = np.zeros_like(a) if model == "emission" else a
    return np.concatenate(
        [np.broadcast_to(colour, (*shape, 3)), np.broadcast_to(alpha, (*shape, 1))], axis=-1
    )
