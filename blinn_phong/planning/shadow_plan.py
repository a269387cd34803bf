"""The planner's shadow choice for one light: no shadows where no mesh can shade another or
itself, planar shadows where one plane receives them all, a shadow map within the tolerance
where its cost model predicts it faster, else the exact method predicted cheaper (ray tracing or
shadow volumes). Every choice names its reason (:func:`_plan_shadow`)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blinn_phong._numba import numba_available
from blinn_phong.geometry.mesh_facts import (
    _beyond_near_plane,
    _light_side_distance,
    _may_shadow,
    _mesh_facts,
    _MeshFacts,
    _projected_width,
    _screen_rect_and_depth,
)
from blinn_phong.model.lights import AmbientLight, DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Scene
from blinn_phong.planning import calibration
from blinn_phong.planning.bounds import _FogRange, _lowest_opacity, _shadow_weight
from blinn_phong.planning.choice import Choice, _Frame
from blinn_phong.shadows.method import embree_available
from blinn_phong.shadows.methods import METHODS, NONE

# The methods this planner decides between, by their registered facts (blinn_phong.shadows.methods):
# the one that carries transparent casters' colour, the exact one that casts rays with Embree and
# the one standing in for it without Embree, the shadow map and the planar projection.
_COLOURED = next(m for m in METHODS.values() if m.coloured)
_TRACED = METHODS["ray_traced"]
_VOLUME = METHODS[str(_TRACED.without_embree)]
_MAP = METHODS["shadow_map"]
_PLANAR = METHODS["planar"]

_EPS = 1e-9


def _self_shadow_free(scene: Scene, f: _MeshFacts) -> str | None:
    """Why a mesh cannot shade itself (a phrase), or None when it may.

    A point ``p`` of a triangle on a supporting plane of a convex mesh, lit from the outer
    side of that plane (``n·l > 0``, ``n`` outward), sends its ray to the light into the open
    half-space beyond the plane, where no point of the mesh lies: no self-shadow. With
    one-sided lighting every fragment, back faces included, is lit with the outward normal,
    so that is every lit point. Two-sided lighting lights back faces with ``−n``, from the
    inner side, whose rays cross the mesh: they are never seen only when the mesh is closed,
    opaque (a transparent front shows the inside) and the camera outside it, which holds
    when the whole mesh lies beyond the near plane. A planar mesh never shades itself (a ray
    leaving its plane does not return to it).
    """
    if f.planar:
        return "planar"
    if not f.convex:
        return None
    if not scene.light_model.two_sided:
        return "convex, lit one-sided (inside faces with the outward normal)"
    if _lowest_opacity(scene, f.mesh) < 1.0:
        return None
    if scene.camera is not None and len(f.world):
        if _beyond_near_plane(f, scene.camera.projection @ scene.camera.view):
            return "closed and convex, wholly beyond the near plane (its inside is never seen)"
    return None


def _shadow_pairs(
    scene: Scene, facts: list[_MeshFacts], light: DirectionalLight | PointLight | SpotLight
) -> list[tuple[int, int]]:
    """Every ``(caster, receiver)`` pair of mesh indices that may shadow (``a == b``: itself)."""
    pairs = []
    for a, fa in enumerate(facts):
        if fa.n_tris == 0:
            continue
        for b, fb in enumerate(facts):
            if fb.n_tris == 0:
                continue
            if a == b:
                if _self_shadow_free(scene, fa) is None:
                    pairs.append((a, b))
            elif _may_shadow(fa, fb, light):
                pairs.append((a, b))
    return pairs


def _linked_pairs(
    scene: Scene, index: int, pairs: list[tuple[int, int]]
) -> tuple[list[tuple[int, int]], str]:
    """The ``(caster, receiver)`` pairs that can show a shadow of light ``index``: the caster one of
    the light's blockers, the receiver one of its receivers (``Scene.light_links``) and not a
    holdout (``Mesh.holdout``: its colour is 0 however it is lit); with the reason when none is left."""
    link = None if scene.light_links is None else scene.light_links[index]
    kept = [
        (a, b)
        for a, b in pairs
        if not scene.meshes[b].holdout
        and (link is None or link.blockers is None or link.blockers[a])
        and (link is None or link.receivers is None or link.receivers[b])
    ]
    if kept or link is None:
        return kept, "every mesh the light's shadows could fall on is a holdout (its colour is 0)"
    return kept, (
        "light linking: none of the light's blockers can shadow one of its receivers (the other "
        "occluders are not linked to it)"
    )


@dataclass(frozen=True)
class MapGeometry:
    """What the shadow-map models read of a scene, for one directional light (world units).

    Attributes:
        span: side of the square the map covers (the diameter of the sphere around every
            vertex, as :func:`blinn_phong.shadows.maps.light_shadow_maps` frames it).
        feature: the thinnest caster seen from the light (:func:`_projected_width`).
        triangles: triangles in the scene (what the ray tracer's scene build scales with).
    """

    span: float
    feature: float
    triangles: int


def _map_geometry(facts: list[_MeshFacts], light: DirectionalLight, casters: set[int]) -> MapGeometry:
    world = np.concatenate([f.world for f in facts if len(f.world)])
    centre = (world.min(axis=0) + world.max(axis=0)) / 2
    span = 2.0 * float(np.sqrt(np.max(np.einsum("ij,ij->i", world - centre, world - centre))))
    direction = np.asarray(light.direction, dtype=np.float64)
    feature = min(_projected_width(facts[c], direction) for c in casters)
    return MapGeometry(span, feature, sum(f.n_tris for f in facts))


def shadow_map_geometry(scene: Scene, index: int) -> MapGeometry:
    """The :class:`MapGeometry` the planner feeds the shadow-map models for directional light ``index``.

    Used by :mod:`benchmarks.error_models` to fit the models with the planner's own inputs.
    """
    light = scene.lights[index]
    if not isinstance(light, DirectionalLight):
        raise ValueError(f"index: expected a directional light, got {type(light).__name__}")
    facts = [_mesh_facts(mesh) for mesh in scene.meshes]
    casters = {a for a, _ in _shadow_pairs(scene, facts, light)}
    if not casters:
        raise ValueError("scene: no mesh casts a shadow from this light")
    return _map_geometry(facts, light, casters)


def _plan_shadow(
    scene: Scene,
    facts: list[_MeshFacts],
    index: int,
    tolerance: float,
    models: dict,
    frame: _Frame,
    factors: np.ndarray | None = None,
    fog: _FogRange | None = None,
) -> Choice:
    light = scene.lights[index]
    if isinstance(light, AmbientLight):
        return Choice(NONE.name, "an ambient light has no direction and casts no shadow")
    pairs = _shadow_pairs(scene, facts, light)
    if not pairs:
        return Choice(
            NONE.name,
            "no occluder between the light and anything: every shadow volume misses the other meshes "
            "and no mesh can shade itself (each is planar, or convex and never lit from inside)",
        )
    pairs, why_not = _linked_pairs(scene, index, pairs)
    if not pairs:
        return Choice(NONE.name, why_not)
    receivers = {b for _, b in pairs}
    casters = {a for a, _ in pairs}
    see_through = _see_through_casters(scene, casters)
    if see_through and embree_available():
        return Choice(
            _COLOURED.name,
            f"meshes {', '.join(map(str, see_through))} cast shadows and let light through: ray-traced "
            "shadows are the exact method (planar, shadow-map and shadow-volume shadows are binary)",
            predicted_steps=0.0,
        )
    planes = [facts[b].plane for b in receivers]
    if all(facts[b].planar for b in receivers) and not (receivers & casters):
        base = planes[0]
        same_plane = all(
            abs(abs(float(p[:3] @ base[:3])) - 1) < 1e-9 and abs(abs(p[3]) - abs(base[3])) < 1e-9
            for p in planes
        )
        if same_plane:
            oriented, light_height = _light_side_distance(base, light)
            ok = True
            for a in casters:
                h = facts[a].world @ oriented[:3] + oriented[3]
                if h.min() < -1e-9 or h.max() >= light_height:
                    ok = False
            if ok and not embree_available():
                return Choice(
                    _VOLUME.name,
                    f"{NO_EMBREE}, instead of planar projected shadows (which test points against the "
                    f"casters with it); only the plane of mesh {min(receivers)} receives shadows",
                    predicted_steps=0.0,
                )
            if ok:
                return Choice(
                    _PLANAR.name,
                    f"only the plane of mesh {min(receivers)} receives shadows and every caster lies between "
                    "it and the light: projected (fake) shadows are exact",
                    {"plane": tuple(float(v) for v in oriented)},
                )
    a, b = pairs[0]
    if a == b:
        why_self = (
            "open or not convex"
            if not facts[a].convex
            else "two-sided lighting lights its inside, which may be seen"
        )
        what = f"mesh {a} can shade itself ({why_self})"
    else:
        what = f"mesh {a} can shadow mesh {b}"
    # The tolerance bounds every pixel: a sample classified differently from the ray tracer
    # (a shadow map's misplaced edge, a shadow volume's grazing sample) costs the light's whole
    # lit-minus-shadowed contribution there, so such a method is allowed only when that fits.
    weight = _shadow_weight(scene, light, facts, factors, fog, index)
    worst = 255.0 * weight
    share = traced_share(scene, facts, models)
    exact = _exact_shadow(what, models, frame, sum(f.n_tris for f in facts), tolerance, worst, share)
    if tolerance <= 0:
        return exact
    if light.positional:
        return replace(
            exact, reason=f"{exact.reason}; the shadow-map models are calibrated for directional lights only"
        )
    if worst > tolerance:
        return replace(
            exact,
            reason=f"{exact.reason}; a shadow map can misplace a hard edge, where a pixel changes by the "
            f"light's whole contribution, up to {worst:.3g} steps > tolerance {tolerance:g}",
        )
    geometry = _map_geometry(facts, light, casters)
    span, feature = geometry.span, geometry.feature
    if span <= 0 or feature <= 0:
        return replace(
            exact,
            reason=f"{exact.reason}; a caster has no width seen from the light (a pane edge-on), which no "
            "shadow-map resolution resolves",
        )
    pick = calibration.choose_shadow_map(
        models,
        tolerance,
        span,
        feature,
        1.0,
        weight,
        receivers=frame.receivers,
        triangles=geometry.triangles,
        traced_share=share,
    )
    exact_cost = 1.0 if exact.relative_cost is None else exact.relative_cost
    if pick["method"] == _MAP.name and pick["predicted_cost"] < exact_cost:
        res, cost = pick["resolution"], pick["predicted_cost"]
        return Choice(
            _MAP.name,
            f"{what}; a {res}² shadow map: every pixel within the light's contribution {worst:.3g} steps "
            f"≤ tolerance {tolerance:g}; texel {span / res:.3g} ≤ half the thinnest caster seen from the "
            f"light ({feature:.3g}); predicted mean {pick['predicted_mean']:.2g} steps, cost {cost:.2f}× "
            f"ray tracing for {frame.receivers} receiver samples"
            + (f" (shadow volumes: {exact_cost:.2f}×)" if exact.method == _VOLUME.name else ""),
            {"resolution": res},
            predicted_steps=worst,
            relative_cost=cost,
        )
    if pick["method"] == _MAP.name:
        return replace(
            exact,
            reason=f"{exact.reason}; the cheapest shadow map resolving every caster ({pick['resolution']}²) "
            f"is predicted at {pick['predicted_cost']:.2f}× ray tracing, not below {exact_cost:.2f}×",
        )
    return replace(
        exact,
        reason=f"{exact.reason}; no shadow map with texels of at most half the thinnest caster seen from "
        f"the light ({feature:.3g} of a {span:.3g} span) is predicted faster for {frame.receivers} "
        "receiver samples",
    )


def _see_through_casters(scene: Scene, casters: set[int]) -> list[int]:
    """The casters among ``casters`` that let some light through (coloured shadows when ray traced).

    Such a caster's shadow is the light times its transmittance per RGB channel
    (:func:`blinn_phong.shadows.transmittance.mesh_shadow_transmittance`); only ray tracing carries it, so the
    binary methods differ from it by up to the light's whole contribution times the transmittance.
    """
    from blinn_phong.shadows.transmittance import mesh_shadow_transmittance

    two_sided = scene.light_model.two_sided
    return sorted(a for a in casters if mesh_shadow_transmittance(scene.meshes[a], two_sided).any())


def coloured_shadow_reason(scene: Scene, choice: Choice) -> Choice:
    """``choice`` with its reason saying how transparent casters shadow (coloured only when ray traced).

    Args:
        scene: the scene planned for.
        choice: one light's shadow choice.

    Returns:
        ``choice`` unchanged when its method is ``none`` or no caster lets light through
        (:func:`blinn_phong.shadows.transmittance.mesh_shadow_transmittance`); else with
        "; coloured shadows: …"
        (``ray_traced``) or "; transparent meshes … cast full shadows" (the binary methods) appended.
    """
    if choice.method == NONE.name:
        return choice
    from blinn_phong.shadows.transmittance import mesh_shadow_transmittance

    two_sided = scene.light_model.two_sided
    lets_through = [
        i
        for i, mesh in enumerate(scene.meshes)
        if mesh.casts_shadows and mesh_shadow_transmittance(mesh, two_sided).any()
    ]
    if not lets_through:
        return choice
    which = ", ".join(str(i) for i in lets_through)
    if choice.method == _COLOURED.name:
        return replace(choice, reason=f"{choice.reason}; coloured shadows: light crossing transparent "
                       f"meshes {which} keeps their transmittance per RGB channel")  # fmt: skip
    return replace(choice, reason=f"{choice.reason}; transparent meshes {which} cast full shadows "
                   f"({choice.method} is binary; coloured shadows are ray traced)")  # fmt: skip


#: Why a plan without Embree uses shadow volumes (the start of the choice's reason).
NO_EMBREE = "Embree (embreex) is not installed: shadow volumes, exact too"


def traced_share(
    scene: Scene, facts: list[_MeshFacts] | None = None, models: dict | None = None
) -> float | None:
    """Estimated share of a frame's receivers whose hard shadow rays the compiled engine traces.

    :mod:`blinn_phong.shadows.ray_culling` answers the rays of receivers on planar and convex meshes
    (and all rays that miss every caster) without Embree; it never answers those of receivers
    on other meshes that cast shadows. The estimate is the screen share of those meshes (their
    normalised-device bounding rectangles, clipped to the screen, summed, at most 1) plus the
    ``rim`` the calibration measured (rays that pass close to a convex caster), at most 1.
    None without numba (the numpy engine traces every ray) or without the ``frame_shadows``
    fit.

    Args:
        scene: the scene.
        facts: its mesh facts (computed when None).
        models: the cost models (the shipped ones when None).
    """
    models = calibration.shipped_models() if models is None else models
    if "frame_shadows" not in models or not numba_available():
        return None
    facts = [_mesh_facts(m) for m in scene.meshes] if facts is None else facts
    share = 0.0
    for mesh, f in zip(scene.meshes, facts, strict=True):
        if not mesh.casts_shadows or f.planar or f.convex or len(f.world) == 0:
            continue
        rect, _ = _screen_rect_and_depth(f, scene)
        width = min(rect[2], 1.0) - max(rect[0], -1.0)
        height = min(rect[3], 1.0) - max(rect[1], -1.0)
        share += max(width, 0.0) * max(height, 0.0) / 4.0
    return min(1.0, share + float(models["frame_shadows"]["rim"]))


def _exact_shadow(
    what: str,
    models: dict,
    frame: _Frame,
    triangles: int,
    tolerance: float,
    worst: float,
    share: float | None = None,
) -> Choice:
    """The cheaper predicted exact hard-shadow method: Embree ray tracing or shadow volumes.

    Shadow volumes where Embree cannot be imported; otherwise the one the cost model
    (:func:`blinn_phong.planning.calibration.shadow_volume_cost`, for the scene's ``triangles`` and the
    frame's receiver samples) predicts faster, ray tracing on a tie or without a model.
    ``relative_cost`` is relative to ray tracing.

    Both methods are exact, but they are different computations: on samples whose shadow ray
    grazes a caster's silhouette they may disagree (and the planner fuzzer measured further
    disagreements on random scenes: docs/speed_accuracy.md). The tolerance is measured
    against the ray tracer's image, so shadow volumes replace an available Embree only when
    ``worst`` — 255 times the light's whole lit-minus-shadowed contribution, what one
    differently classified sample can cost a pixel — is within ``tolerance``.
    """
    costs = calibration.shadow_volume_cost(models, triangles, frame.receivers, share)
    where = f"for {triangles} triangles and {frame.receivers} receiver samples"
    if not embree_available():
        predicted = f" (predicted {costs['shadow_volume'] * 1e3:.3g} ms {where})" if costs is not None else ""
        return Choice(
            _VOLUME.name,
            f"{what}: {NO_EMBREE}, instead of ray tracing{predicted}",
            predicted_steps=0.0,
            relative_cost=None if costs is None else costs["ratio"],
        )
    if costs is None:
        return Choice(
            _TRACED.name, f"{what}: ray-traced shadows are exact", predicted_steps=0.0, relative_cost=1.0
        )
    volume, traced, ratio = costs[_VOLUME.cost_model] * 1e3, costs[_TRACED.cost_model] * 1e3, costs["ratio"]
    if ratio < 1.0 and worst > tolerance:
        return Choice(
            _TRACED.name,
            f"{what}: ray-traced shadows are exact; shadow volumes, predicted faster ({volume:.3g} ms "
            f"against {traced:.3g} ms, {ratio:.2f}×, {where}), may classify a grazing sample differently, "
            f"where a pixel changes by the light's whole contribution, up to {worst:.3g} steps > tolerance "
            f"{tolerance:g}",
            predicted_steps=0.0,
            relative_cost=1.0,
        )
    if ratio < 1.0:
        return Choice(
            _VOLUME.name,
            f"{what}: shadow volumes are exact and predicted faster than Embree ray tracing, "
            f"{volume:.3g} ms against {traced:.3g} ms ({ratio:.2f}×) {where}; a sample they classify "
            f"differently changes a pixel by at most {worst:.3g} steps ≤ tolerance {tolerance:g}",
            predicted_steps=worst,
            relative_cost=ratio,
        )
    return Choice(
        _TRACED.name,
        f"{what}: ray-traced shadows are exact and predicted faster than shadow volumes, "
        f"{traced:.3g} ms against {volume:.3g} ms ({ratio:.2f}× ray tracing) {where}",
        predicted_steps=0.0,
        relative_cost=1.0,
    )
