"""The registry of shadow methods and the dispatch by name.

Each method of :mod:`blinn_phong.shadows` is one module implementing
:class:`~blinn_phong.shadows.method.ShadowMethod` — ``none`` here, ``planar``
(:mod:`.planar`), ``shadow_map`` (:mod:`.maps`), ``ray_traced`` (:mod:`.ray_traced`),
``shadow_volume`` (:mod:`.volume`) and ``soft`` (:mod:`.soft`). :data:`METHODS` lists them once;
the renderer (:func:`light_visibility`, :func:`frame_visibility`), the planner, the frame plan and
the add-on read their names and facts from it rather than from string literals.
"""

from __future__ import annotations

import numpy as np

from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.shadows import maps, planar, ray_traced, soft, volume
from blinn_phong.shadows._inputs import checked_points, checked_triangles, trusted_arrays
from blinn_phong.shadows.method import ShadowFrame, ShadowMethod

__all__ = [
    "METHODS",
    "NONE",
    "SHADOW_METHODS",
    "ShadowFrame",
    "ShadowMethod",
    "frame_visibility",
    "light_visibility",
    "shadow_method",
    "trusted_arrays",
]


def _unshadowed(light: object, tris: np.ndarray, p: np.ndarray, normals: object, **_: object) -> np.ndarray:
    return np.ones(len(p))


NONE = ShadowMethod(
    name="none",
    title="no shadows",
    summary="no shadows: every light reaches every point",
    exact=False,
    coloured=False,
    uses_rays=False,
    without_embree=None,
    cost_model=None,
    parameters=(),
    visibility=_unshadowed,
)

#: Every shadow method by name, in the order the docs and the add-on list them.
METHODS: dict[str, ShadowMethod] = {
    m.name: m for m in (NONE, planar.METHOD, maps.METHOD, ray_traced.METHOD, volume.METHOD, soft.METHOD)
}
#: Their names: what ``render(shadows=...)``, :class:`blinn_phong.ShadowOptions` and the planner take.
SHADOW_METHODS: tuple[str, ...] = tuple(METHODS)


def shadow_method(name: str) -> ShadowMethod:
    """The registered method called ``name``; a ValueError naming the known ones otherwise."""
    try:
        return METHODS[name]
    except (KeyError, TypeError):
        raise ValueError(f"method must be one of {SHADOW_METHODS}, got {name!r}") from None


def light_visibility(
    method: str,
    light: DirectionalLight | PointLight | SpotLight,
    world_triangles: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    *,
    resolution: int = 1024,
    constant_bias: float = 1e-4,
    slope_bias: float = 2.0,
    kernel: str = "nearest",
    plane: np.ndarray | tuple[float, ...] | None = None,
    caster_triangles: np.ndarray | None = None,
    normal_offset: float = 0.0,
    engine: str = "auto",
    transmittance: np.ndarray | None = None,
    **volume_options: object,
) -> np.ndarray:
    """Visibility of points for one light by a named method (a planner choice).

    Args:
        method: one of :data:`SHADOW_METHODS` (the registry :data:`METHODS`).
        light: the light.
        world_triangles: (n, 3, 3) every triangle of the scene, world space.
        points: (m, 3) world-space receiver points.
        normals: (m, 3) their normals.
        resolution: shadow-map size for ``shadow_map``.
        constant_bias: see :func:`render_shadow_map`.
        slope_bias: see :func:`render_shadow_map`.
        kernel: PCF kernel for ``shadow_map``.
        plane: ``(a, b, c, d)`` receiving plane for ``planar``.
        caster_triangles: casters for ``planar`` (default: every triangle not in the plane).
        normal_offset: receiver offset along the normal for ``shadow_map`` (world units).
        engine: ``shadow_map`` maps and look-ups by the numpy reference (``numpy``), the
            compiled kernels (``numba``) or ``auto``; see :func:`render_shadow_map`.
        transmittance: optional (n, 3) per-triangle RGB transmittance in [0, 1] (1 − α for
            partial occlusion, the per-channel transmittance for absorption, 0 for opaque):
            transparent casters then cast coloured shadows
            (:func:`blinn_phong.shadows.raytrace.transmitted_light`) and the result is (m, 3).
            Only ``none`` and the coloured methods (``ray_traced``) accept it.
        volume_options: the other keyword parameters of the method (:attr:`ShadowMethod.parameters`):
            for ``shadow_volume`` those of :func:`blinn_phong.shadows.volume.shadow_volume_visibility`
            (``camera``, ``stencil``...), for ``soft`` ``radius``, ``samples_per_axis`` and ``offset``.

    Returns:
        (m,) float64 visibility in [0, 1]; (m, 3) per channel when ``transmittance`` is given.
    """
    m = shadow_method(method)
    p = checked_points("points", points)
    unknown = sorted(set(volume_options) - set(m.parameters))
    if unknown:
        raise TypeError(
            f"light_visibility: {unknown} are not parameters of {method} (it takes {m.parameters})"
        )
    if transmittance is not None:
        if method == NONE.name:
            return np.ones((len(p), 3))
        if not m.coloured:
            coloured = [c.name for c in METHODS.values() if c.coloured]
            raise ValueError(
                f"transmittance: coloured shadows are cast by {coloured}; method {method!r} casts full "
                "shadows only (use 'ray_traced' or pass transmittance=None)"
            )
    if method == NONE.name:
        return np.ones(len(p))
    tris = checked_triangles("world_triangles", world_triangles)
    given = {
        "resolution": resolution, "constant_bias": constant_bias, "slope_bias": slope_bias,
        "kernel": kernel, "plane": plane, "caster_triangles": caster_triangles,
        "normal_offset": normal_offset, "engine": engine,
    }  # fmt: skip
    params = {k: v for k, v in given.items() if k in m.parameters}
    if transmittance is not None:
        params = {"transmittance": transmittance}
    # p and tris are checked: the functions called below need not check them again
    with trusted_arrays(p, tris):
        return m.visibility(light, tris, p, normals, **params, **volume_options)


def frame_visibility(frame: ShadowFrame, lit: list[tuple[object, object]]) -> np.ndarray:
    """The visibility of each light of ``lit`` at the frame's points, by the light's method.

    Args:
        frame: what the lights share (:class:`ShadowFrame`: points, normals, casters, BVH,
            culling tables, screen binning); its ``transmittance`` is set when some light's
            method is coloured and a caster lets light through.
        lit: ``(light, choice)`` per non-ambient light, ``choice.method`` a name of
            :data:`METHODS` and ``choice.params`` its parameters.

    Returns:
        (N, L) float64 in [0, 1]; (N, L, 3) with ``frame.transmittance`` (the binary methods'
        visibility repeated over the channels).
    """
    n = len(frame.world)
    coloured = frame.transmittance is not None
    out = np.empty((n, len(lit), 3) if coloured else (n, len(lit)))
    for i, (light, choice) in enumerate(lit):
        m = shadow_method(choice.method)  # type: ignore[attr-defined]
        column = m.at_frame(frame, light, dict(choice.params))  # type: ignore[attr-defined]
        out[:, i] = column[:, None] if coloured and column.ndim == 1 else column
    return out
