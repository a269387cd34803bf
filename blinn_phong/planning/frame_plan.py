"""The plan of a frame: the planner's choices, the caller's overrides, and the effect options.

:func:`blinn_phong.frame.render` asks :func:`blinn_phong.planning.planner.plan` for one method per concern and
replaces a concern's choice only where the caller set one (:func:`frame_plan`); :class:`Fog` and
:class:`ShadowOptions` are the options it accepts. The frame itself — the same stages with or
without effects — is :mod:`blinn_phong.frame.pipeline`; this module decides, it does not render.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blinn_phong._checks import choice_error, number
from blinn_phong.effects.oit import TRANSPARENCY_METHODS
from blinn_phong.geometry.mesh_facts import nearest_triangle_distance
from blinn_phong.model.fog import Fog
from blinn_phong.model.lights import AmbientLight
from blinn_phong.model.scene import SHADINGS, Scene
from blinn_phong.planning.planner import Choice, Plan, coloured_shadow_reason, plan
from blinn_phong.shadows.maps import PCF_KERNELS
from blinn_phong.shadows.method import embree_available
from blinn_phong.shadows.methods import SHADOW_METHODS, shadow_method

__all__ = [
    "SHADOW_CHOICES",
    "TRANSPARENCY_CHOICES",
    "WBOIT_WEIGHTS",
    "Fog",
    "ShadowOptions",
    "frame_plan",
    "needs_effects",
    "scene_with_planned_shading",
]

#: Transparency methods render() accepts: the plain z-buffer and every :mod:`blinn_phong.effects.oit` method.
TRANSPARENCY_CHOICES: tuple[str, ...] = ("zbuffer", *TRANSPARENCY_METHODS)
#: Shadow methods render() accepts per light: every method of the registry
#: (:data:`blinn_phong.shadows.methods.SHADOW_METHODS`).
SHADOW_CHOICES: tuple[str, ...] = SHADOW_METHODS
#: Weighted blended OIT weights available on rasterized fragments (they carry window depth):
#: McGuire & Bavoil's eq. 10 and the depth-free α weight.
WBOIT_WEIGHTS: tuple[str, ...] = ("eq10", "constant")
_AUTO = (None, "auto")
#: Depth-peeling layers beyond this are peeled as this many: a sample's fragment count is an
#: int32 in the compiled kernels, so no sample holds more, and extra layers change nothing.
MAX_PEEL_LAYERS = 2**31 - 1


@dataclass(frozen=True)
class ShadowOptions:
    """Shadow settings for one light (or for every light), passed to ``render(shadows=...)``.

    Attributes:
        method: ``None``/``"auto"`` — the planner's choice; or one of :data:`SHADOW_CHOICES`:
            ``none``, ``planar`` (Blinn's projected shadows), ``shadow_map``, ``ray_traced``
            (Embree, exact hard shadows) or ``soft`` (area light of side ``2·radius`` sampled
            on a stratified m×m grid; a directional light or radius 0 falls back to ``ray_traced``).
        resolution: shadow-map size in texels per side (None: the planner's, else 1024).
        constant_bias: shadow-map constant bias in window-depth units (None: 1e-4).
        slope_bias: shadow-map slope-scaled bias (None: 2.0), as ``glPolygonOffset``.
        kernel: percentage-closer filter, one of :data:`blinn_phong.shadows.maps.PCF_KERNELS`
            (None: nearest).
        plane: ``(a, b, c, d)`` receiving plane for ``planar`` (None: the planner's).
        samples: rays per point for ``soft``; a stratified grid is square, so ``m×m`` rays with
            ``m = round(√samples)`` are cast and, when that differs from ``samples``, the plan's
            reason says so (e.g. 20 → 4×4 = 16).
        radius: half-side of the square area light for ``soft``, world units.
        offset: ray-origin offset along the normal for ``soft``, world units.

    Parameters left at None that the method does not use are ignored.
    """

    method: str | None = None
    resolution: int | None = None
    constant_bias: float | None = None
    slope_bias: float | None = None
    kernel: str | None = None
    plane: tuple[float, float, float, float] | None = None
    samples: int = 16
    radius: float = 0.0
    offset: float = 1e-3

    def __post_init__(self) -> None:
        if self.method not in _AUTO and self.method not in SHADOW_CHOICES:
            raise choice_error("ShadowOptions.method", self.method, SHADOW_CHOICES, also="None, 'auto' or ")
        if self.resolution is not None and (
            not isinstance(self.resolution, int | np.integer)
            or isinstance(self.resolution, bool)
            or self.resolution < 1
        ):
            raise ValueError(
                f"ShadowOptions.resolution: expected an integer >= 1 or None, got {self.resolution!r}"
            )
        for name in ("constant_bias", "slope_bias"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, number(getattr(self, name), f"ShadowOptions.{name}", low=0.0))
        if self.kernel is not None and self.kernel not in PCF_KERNELS:
            raise choice_error("ShadowOptions.kernel", self.kernel, PCF_KERNELS, also="None or ")
        if self.plane is not None:
            plane = np.asarray(self.plane, dtype=np.float64)
            if plane.shape != (4,) or not np.isfinite(plane).all() or np.linalg.norm(plane[:3]) == 0:
                raise ValueError(
                    f"ShadowOptions.plane: expected finite (a, b, c, d), (a, b, c) != 0, got {self.plane!r}"
                )
            plane = plane / np.linalg.norm(plane[:3])
            object.__setattr__(self, "plane", tuple(float(v) for v in plane))
        if (
            not isinstance(self.samples, int | np.integer)
            or isinstance(self.samples, bool)
            or self.samples < 1
        ):
            raise ValueError(f"ShadowOptions.samples: expected an integer >= 1, got {self.samples!r}")
        object.__setattr__(self, "radius", number(self.radius, "ShadowOptions.radius", low=0.0))
        object.__setattr__(self, "offset", number(self.offset, "ShadowOptions.offset", low=0.0))


# --------------------------------------------------------------------------- choices


def _shadow_list(shadows: object, n_lights: int) -> list[ShadowOptions]:
    """Normalise ``render(shadows=...)`` to one :class:`ShadowOptions` per entry of ``scene.lights``."""

    def one(value: object, name: str) -> ShadowOptions:
        if isinstance(value, ShadowOptions):
            return value
        if value in _AUTO or value in SHADOW_CHOICES:
            return ShadowOptions(method=value)  # type: ignore[arg-type]
        raise choice_error(name, value, SHADOW_CHOICES, also="a ShadowOptions, None, 'auto' or ")

    if isinstance(shadows, list | tuple):
        if len(shadows) != n_lights:
            raise ValueError(
                f"shadows: expected one entry per scene light ({n_lights}), got {len(shadows)} entries"
            )
        return [one(v, f"shadows[{i}]") for i, v in enumerate(shadows)]
    return [one(shadows, "shadows")] * n_lights


def _overridden(planned: Choice, what: str) -> str:
    return f"{what} (planner: {planned.method} — {planned.reason})"


#: The resolution of a shadow map standing in for a method that needs Embree, when the caller set none.
STAND_IN_RESOLUTION = 2048


def _shadow_choice(light: object, options: ShadowOptions, planned: Choice) -> Choice:
    """The planner's choice for one light unless ``options.method`` overrides it, with full
    parameters (each method's :meth:`~blinn_phong.shadows.method.ShadowMethod.params_for`)."""
    if isinstance(light, AmbientLight):
        return planned
    method, reason = shadow_method(planned.method), planned.reason
    overridden = options.method not in _AUTO
    if overridden:
        method = shadow_method(str(options.method))
        if method.name != planned.method:
            reason = _overridden(planned, "set by the caller")
    if method.stand_in is not None and (instead := method.stand_in(light, options)) is not None:
        method, reason = shadow_method(instead[0]), instead[1]
    # The planner already picks methods that cast no rays where Embree is missing; a method the
    # caller sets that casts rays is replaced here by its stand-in, saying so.
    while overridden and method.uses_rays and not embree_available():
        stand_in = shadow_method(str(method.without_embree))
        exact = ", exact too," if stand_in.exact else ""
        reason = (
            f"Embree (embreex) is not installed: {stand_in.title}{exact} instead of {method.name} ({reason})"
        )
        if "resolution" in stand_in.parameters and options.resolution is None:
            options = replace(options, resolution=STAND_IN_RESOLUTION)
        method = stand_in
    params, note = method.params_for(options, planned)
    if note:
        reason = f"{reason}; {note}"
    if method.name == planned.method and reason == planned.reason:
        return replace(planned, params=params)  # the planner's choice keeps its predictions
    return Choice(method.name, reason, params)


#: A light closer than this to a caster's surface, relative to the scene's extent (the largest
#: world coordinate magnitude, at least 1), counts as lying on it for shadow volumes.
LIGHT_ON_SURFACE = 1e-7


def _light_on_caster(scene: Scene, light: object) -> float | None:
    """The distance from a point or spot light to the nearest shadow-casting triangle, when that
    is within :data:`LIGHT_ON_SURFACE` of the scene's extent (else None).

    A light on a caster's vertex, edge or face makes its shadow volume degenerate: the quads
    extruded from the silhouette edges through the light have no direction there, and the
    volume test counts pixels inside or outside the caster wrongly.
    """
    position = getattr(light, "position", None)
    if position is None:
        return None
    point = np.asarray(position, dtype=np.float64)
    nearest = np.inf
    for mesh in scene.meshes:
        if not mesh.casts_shadows or not len(mesh.triangles):
            continue
        world = (np.c_[mesh.positions, np.ones(len(mesh.positions))] @ mesh.transform.T)[:, :3]
        scale = max(1.0, float(np.abs(world).max()), float(np.abs(point).max()))
        tol = LIGHT_ON_SURFACE * scale
        if (point < world.min(axis=0) - tol).any() or (point > world.max(axis=0) + tol).any():
            continue  # outside the mesh's bounding box: not on its surface
        tris = world[mesh.triangles]
        near = ((tris.min(axis=1) - tol <= point) & (point <= tris.max(axis=1) + tol)).all(axis=1)
        if near.any():
            distance = nearest_triangle_distance(tris[near], point)
            if distance <= tol:
                nearest = min(nearest, distance)
    return None if nearest == np.inf else nearest


def _robust_volume(scene: Scene, light: object, choice: Choice) -> Choice:
    """``choice`` unless it is a shadow volume for a light on a caster's surface: then the exact
    ray-traced shadows (or, without Embree, a 2048² shadow map), the reason saying why."""
    if choice.method != "shadow_volume":
        return choice
    distance = _light_on_caster(scene, light)
    if distance is None:
        return choice
    why = (
        f"the light lies on a caster's surface (distance {distance:.3g}): its shadow volume is "
        f"degenerate there, so"
    )
    if embree_available():
        return Choice("ray_traced", f"{why} exact ray-traced shadows instead ({choice.reason})")
    return Choice("shadow_map", f"{why} a shadow map instead ({choice.reason})", {"resolution": 2048})


def frame_plan(
    scene: Scene,
    *,
    tolerance: float = 0.0,
    shading: str = "auto",
    transparency: str | None = None,
    peel_layers: int | None = None,
    wboit_weight: str = "eq10",
    shadows: object = None,
    gl_compat: bool = False,
    width: int | None = None,
    height: int | None = None,
    samples: int = 1,
    fog: Fog | None = None,
) -> Plan:
    """The plan a render follows: :func:`blinn_phong.planning.planner.plan`, with the caller's choices
    replacing it.

    Each concern is independent: a method the caller sets replaces the planner's choice for that
    concern only, and its reason says so and keeps the planner's own choice and reason.

    Args:
        scene: the scene.
        tolerance: the planner's tolerance in 8-bit steps (see
            :func:`blinn_phong.planning.planner.plan`), ≥ 0.
        shading: ``"auto"`` — the planner's per-mesh shading frequency; otherwise the render's
            ``shading`` (a mesh's own ``shading`` still wins), as :func:`blinn_phong.frame.render.render`
            uses it.
        transparency: ``None``/``"auto"`` or one of :data:`TRANSPARENCY_CHOICES`.
        peel_layers: layers for ``depth_peeling`` (None: the planner's, else 8), ≥ 1.
        wboit_weight: weight for ``weighted_blended``, one of :data:`WBOIT_WEIGHTS`.
        shadows: ``None``/``"auto"``, a method of :data:`SHADOW_CHOICES`, a :class:`ShadowOptions`,
            or a list of those with one entry per ``scene.lights`` entry.
        gl_compat: the OpenGL 2.1 preset: no effects (fixed-function OpenGL has neither shadows
            nor order-independent transparency); asking for one raises ``ValueError``.
        width: frame width in pixels, for the cost models (None: the planner's default frame).
        height: frame height in pixels (None: the planner's default frame).
        samples: samples per pixel (k² for a k×k grid), as render takes them.
        fog: the render's :class:`Fog` (or None): the planner scales its error bounds by the fog
            factor and states fog's cost (:func:`blinn_phong.planning.planner.plan`).

    Returns:
        A :class:`~blinn_phong.planning.planner.Plan` whose choices carry the keyword parameters of the
        functions that carry them out.
    """
    if shading != "auto" and shading not in SHADINGS:
        raise choice_error("shading", shading, SHADINGS, also="'auto' or ")
    if transparency not in _AUTO and transparency not in TRANSPARENCY_CHOICES:
        raise choice_error("transparency", transparency, TRANSPARENCY_CHOICES, also="None, 'auto' or ")
    if peel_layers is not None and (
        not isinstance(peel_layers, int | np.integer) or isinstance(peel_layers, bool) or peel_layers < 1
    ):
        raise ValueError(f"peel_layers: expected an integer >= 1 or None, got {peel_layers!r}")
    if wboit_weight not in WBOIT_WEIGHTS:
        raise choice_error("wboit_weight", wboit_weight, WBOIT_WEIGHTS)
    per_light = _shadow_list(shadows, len(scene.lights))
    planned = plan(scene, tolerance, width=width, height=height, samples=samples, fog=fog)

    if gl_compat:
        if transparency not in (*_AUTO, "zbuffer"):
            raise ValueError(f"transparency: gl_compat renders with the plain z-buffer, got {transparency!r}")
        if any(o.method not in (*_AUTO, "none") for o in per_light):
            raise ValueError(
                "shadows: gl_compat (fixed-function OpenGL 2.1) has no shadows; pass None or 'none'"
            )
        t_choice = Choice(
            "zbuffer", "gl_compat: the nearest fragment, as the fixed-function z-buffer writes it"
        )
        s_choices = tuple(
            c if c.method == "none" else Choice("none", "gl_compat: fixed-function OpenGL 2.1 has no shadows")
            for c in planned.shadows
        )
    else:
        t_choice = planned.transparency
        if transparency not in _AUTO and transparency != t_choice.method:
            t_choice = Choice(str(transparency), _overridden(t_choice, "set by the caller"))
        if t_choice.method == "depth_peeling":
            layers = int(peel_layers or planned.transparency.params.get("layers", 8))  # type: ignore[call-overload]
            if layers > MAX_PEEL_LAYERS:
                t_choice = replace(
                    t_choice,
                    reason=f"{t_choice.reason}; {layers} layers asked, {MAX_PEEL_LAYERS} peeled (no sample "
                    "holds more fragments, so more layers change nothing)",
                )
                layers = MAX_PEEL_LAYERS
            t_choice = replace(t_choice, params={"layers": layers})
        elif t_choice.method == "weighted_blended":
            t_choice = replace(t_choice, params={"wboit_equation": wboit_weight})
        else:
            t_choice = replace(t_choice, params={})  # sorting and the A-buffer take no parameters
        s_choices = tuple(
            _robust_volume(scene, light, _shadow_choice(light, options, c))
            for light, options, c in zip(scene.lights, per_light, planned.shadows, strict=True)
        )
        # a method set by the caller: say how transparent casters shadow with it (coloured if ray traced)
        s_choices = tuple(
            c if c.method == p.method else coloured_shadow_reason(scene, c)
            for c, p in zip(s_choices, planned.shadows, strict=True)
        )

    if shading == "auto":
        shading_choices = planned.shading
    else:
        shading_choices = tuple(
            c
            if mesh.shading is not None or c.method == shading
            else Choice(shading, _overridden(c, f"render(shading={shading!r})"))
            for mesh, c in zip(scene.meshes, planned.shading, strict=True)
        )
    return Plan(t_choice, s_choices, shading_choices, planned.tolerance, planned.fog)


def needs_effects(scene: Scene, the_plan: Plan, fog: Fog | None) -> bool:
    """False when the plain z-buffer pipeline renders ``the_plan`` exactly.

    That is: transparency ``zbuffer``, every shadow ``none``, no fog, and no transparent material
    whose fragment is more than ``(α·c, α)`` with its constant opacity (a transparency model
    other than partial occlusion, Kay–Greenberg or wash-out).
    """
    if fog is not None or the_plan.transparency.method != "zbuffer":
        return True
    if any(c.method != "none" for c in the_plan.shadows):
        return True
    materials = [m for mesh in scene.meshes for m in (mesh.material, mesh.back_material) if m is not None]
    return any(
        m.transparent
        and (m.transparency_model != "partial_occlusion" or m.kay_greenberg is not None or m.specular_washout)
        for m in materials
    )


def scene_with_planned_shading(scene: Scene, the_plan: Plan, shading: str) -> Scene:
    """``scene`` with each mesh's shading from ``the_plan`` when ``shading == "auto"`` (else unchanged)."""
    if shading != "auto":
        return scene
    meshes = tuple(
        m if m.shading == c.method else replace(m, shading=c.method)  # type: ignore[arg-type]
        for m, c in zip(scene.meshes, the_plan.shading, strict=True)
    )
    return replace(scene, meshes=meshes)
