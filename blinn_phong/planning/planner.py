"""The planner: per concern, the fastest method that is exact or predicted within a tolerance.

:func:`plan` inspects a :class:`~blinn_phong.model.scene.Scene` — geometry, materials, lights,
camera — and returns a :class:`Plan`: one :class:`Choice` (method, parameters, a sentence
saying why, and for approximations the predicted error and relative cost) for
transparency, one per light for shadows and one per mesh for the shading frequency. It
renders nothing. Exact methods are picked from conservative geometric facts; with a
tolerance ``T > 0`` in **8-bit steps** (1/255 of the unit range) an approximate method is
picked where a bound (or the measured error model of :mod:`blinn_phong.planning.calibration`)
keeps it within ``T`` and its measured cost model predicts it faster than the exact method
for the frame (``width``, ``height``, ``samples``). ``T = 0`` means exact methods only.

``T`` means one thing for every concern (docs/speed_accuracy.md, "What the tolerance
promises"): **no channel of any pixel differs by more than T steps** from the image every
exact method gives (A-buffer, ray-traced shadows, per-pixel shading of the exact surface).

Transparency (methods of :mod:`blinn_phong.effects.oit`):

* ``zbuffer`` — no material has opacity < 1.
* ``draw_last`` — one transparent mesh, planar or convex: drawn after the opaque ones,
  back faces first, then front faces; along any view ray a convex mesh's back face lies
  behind its front face, and a planar mesh never overlaps itself.
* ``sort_objects`` — several transparent meshes, each planar or convex, and every pair
  whose screen rectangles overlap is separated in eye depth: drawing them back to front
  (each as in ``draw_last``) follows the per-pixel order everywhere.
* ``depth_peeling`` — with a tolerance: the fewest layers ``k`` whose predicted max error
  ``255·c·B·(1 − α_min)^k`` is within it (what lies behind ``k`` layers is scaled by their
  transmittance, at most ``(1 − α_min)^k``; ``B`` bounds the straight radiance behind them
  with every factor of the lighting equation — emission, ambient, light colours, and per
  mesh the attenuation ``1/(k_c + k_l·d + k_q·d²)`` at the mesh's nearest distance from the
  light, above 1 when ``k_c < 1``, and the spot cone's factor at its smallest angle to the
  mesh (:func:`_mesh_light_factor`) — see :func:`_max_radiance`; with fog
  ``f_hi·B + (1 − f_lo)·C_f`` (:func:`_fogged_radiance_bound`); at least 1 because alpha
  counts too; divided by ``α_min`` for the absorption model whose fragments are not
  premultiplied by their opacity; ``c`` measured), if its predicted frame cost for the
  frame's samples and triangles (:func:`blinn_phong.planning.calibration.depth_peeling_cost`) is
  below the A-buffer's.
* ``a_buffer`` — otherwise (surfaces may interpenetrate or overlap in depth): exact.

Shadows, per light (:mod:`blinn_phong.shadows.methods`, :mod:`blinn_phong.shadows.raytrace`):

* ``none`` — ambient lights; or no mesh can shade another from this light: every caster's
  shadow volume (the cylinder or cone its bounding sphere sweeps away from the light)
  misses every other mesh's bounding sphere, and no mesh can shade itself: planar, or
  closed and convex (:func:`_convex_surface`, a tolerance from the coordinates' precision)
  and never lit from inside — one-sided lighting, or two-sided with the mesh opaque and
  wholly beyond the near plane (:func:`_self_shadow_free`). An open box under two-sided
  lighting shades its own floor.
* ``planar`` — every receiver that can be shadowed is a planar mesh on one common plane and
  every caster lies between that plane and the light: Blinn's projected shadows are exact.
* ``shadow_map`` — with a tolerance, directional lights (the calibrated case), only when
  ``255·w ≤ T``: ``w`` is the largest change a pixel sees between lit and shadowed (the
  light's diffuse and specular colours times the materials', times each mesh's bound of
  ``att·spot`` and, with fog, its largest fog factor; see :func:`_shadow_weight`), which a
  misplaced hard edge costs in full. The resolution is the smallest power of two
  whose texel ``D/R`` (``D`` the map's span) is at most half the thinnest caster seen from
  the light (the smallest extent of its projection across the light direction,
  :func:`_projected_width`), if its predicted cost for the frame's receiver samples is below
  ray tracing's.
* ``shadow_volume`` — exact hard shadows by stencil counting (:mod:`blinn_phong.shadows.volume`):
  where Embree cannot be imported (for every hard shadow, ``planar`` included, which tests
  points with it), or where the fitted cost model
  (:func:`blinn_phong.planning.calibration.shadow_volume_cost`, the scene's triangles and the frame's
  receiver samples) predicts them faster than Embree ray tracing and ``255·w ≤ T``: the two
  exact methods may classify a sample whose shadow ray grazes a silhouette differently, which
  costs a pixel the light's whole contribution ``w`` against the ray tracer's image (see
  :func:`_exact_shadow`).
* ``ray_traced`` — otherwise: exact hard shadows.

Shading frequency, per mesh (:mod:`blinn_phong.frame.render`):

* ``flat`` — every triangle's vertex normals equal its face normal (planar faces), all
  lights are directional or ambient and the viewer is at infinity
  (``LightModel(local_viewer=False)``, what an orthographic camera should use): L, H and N
  are constant over each face, so the lighting is.
* ``flat`` or ``gouraud`` — with a tolerance, shininess within the calibrated range: the
  cheaper one whose predicted max error ``margin·a·θ^b`` (``θ`` the largest angle between
  adjacent vertex normals) is within it, if it is predicted faster than Phong for the frame
  (:func:`blinn_phong.planning.calibration.shading_cost`).

Fog (``plan(..., fog=Fog(...))``, as ``render`` takes it) is no choice but scales the bounds
(:func:`_fog_range`); the plan's ``fog`` entry states its factor range and predicted cost.
* ``phong`` — otherwise (per-pixel evaluation, the reference).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from blinn_phong.geometry.mesh_facts import (
    _mesh_facts,
    _MeshFacts,
    _normal_angle,
    _rects_overlap,
    _screen_rect_and_depth,
    coordinate_tolerance,
)
from blinn_phong.model.scene import Scene
from blinn_phong.planning import calibration
from blinn_phong.planning.bounds import (
    _fog_range,
    _fogged_radiance_bound,
    _FogRange,
    _light_factors,
    _lowest_opacity,
    _sides,
)
from blinn_phong.planning.choice import DEFAULT_FRAME, Choice, Plan, _Frame, _frame
from blinn_phong.planning.shadow_plan import (
    MapGeometry,
    _plan_shadow,
    coloured_shadow_reason,
    shadow_map_geometry,
    traced_share,
)

__all__ = [
    "DEFAULT_FRAME",
    "Choice",
    "MapGeometry",
    "Plan",
    "coloured_shadow_reason",
    "coordinate_tolerance",
    "plan",
    "shadow_map_geometry",
    "traced_share",
]

_EPS = 1e-9


def _plan_transparency(
    scene: Scene,
    facts: list[_MeshFacts],
    tolerance: float,
    models: dict,
    frame: _Frame | None = None,
    factors: np.ndarray | None = None,
    fog: _FogRange | None = None,
) -> Choice:
    frame = frame if frame is not None else _frame(None, None, 1)
    factors = factors if factors is not None else _light_factors(scene, facts)
    fog = fog if fog is not None else _fog_range(scene, facts, None)
    opacity = [_lowest_opacity(scene, m) for m in scene.meshes]
    transparent = [i for i, m in enumerate(scene.meshes) if opacity[i] < 1.0 and len(m.triangles)]
    if not transparent:
        return Choice("zbuffer", "no transparent objects: a plain z-buffer is exact")
    simple = all(facts[i].planar or facts[i].convex for i in transparent)
    if len(transparent) == 1 and simple:
        i = transparent[0]
        shape = "planar" if facts[i].planar else "convex"
        return Choice(
            "draw_last",
            f"one transparent object (mesh {i}), {shape}: drawn after the opaque ones, back faces "
            "then front faces, is exact",
        )
    rects = {i: _screen_rect_and_depth(facts[i], scene) for i in transparent}
    conflicts = []
    for a_pos, a in enumerate(transparent):
        for b in transparent[a_pos + 1 :]:
            (ra, (na, fa)), (rb, (nb, fb)) = rects[a], rects[b]
            if _rects_overlap(ra, rb) and not (fa < nb or fb < na):
                conflicts.append((a, b))
    if simple and not conflicts:
        return Choice(
            "sort_objects",
            f"{len(transparent)} transparent planar or convex objects that never overlap in depth where "
            "they overlap on screen: sorting them back to front is exact",
        )
    why = (
        f"transparent meshes {conflicts[0][0]} and {conflicts[0][1]} overlap on screen and in depth "
        "(they may interpenetrate)"
        if conflicts
        else "a transparent object can overlap itself (neither planar nor convex)"
    )
    exact = Choice(
        "a_buffer",
        f"{why}: only a per-pixel sort (A-buffer) is exact",
        predicted_steps=0.0,
        relative_cost=1.0,
    )
    if tolerance <= 0:
        return exact
    alpha_min = min(opacity[i] for i in transparent)
    if alpha_min <= 0:
        return Choice(
            "a_buffer",
            f"{why}: a surface of opacity 0 (or the emission model) attenuates nothing behind it, so no "
            "number of peeled layers bounds the rest; the A-buffer is exact",
            predicted_steps=0.0,
            relative_cost=1.0,
        )
    # what the dropped layers hide: transparent and opaque colour behind them, and coverage (alpha)
    brightest = _fogged_radiance_bound(scene, facts, factors, fog)
    if any(m.transparency_model == "absorption" for i in transparent for m in _sides(scene, scene.meshes[i])):
        brightest /= alpha_min  # c + (1 − α)·behind: a stack behind adds up to B·Σ(1 − α)^j ≤ B/α
    if not math.isfinite(brightest):
        return replace(
            exact,
            reason=f"{why}: a light's attenuation is unbounded at a surface (k_c + k_l·d + k_q·d² can be 0), "
            "so no number of peeled layers bounds the rest; the A-buffer is exact",
        )
    layers_bound = sum(
        1 if facts[i].planar else 2 * max(len(scene.meshes[i].triangles), 1) for i in transparent
    )
    n_triangles = sum(f.n_tris for f in facts)
    pick = calibration.choose_depth_peeling(
        models, tolerance, alpha_min, brightest, layers_bound, frame.samples_total, n_triangles
    )
    c = calibration.depth_peeling_factor(models)
    if pick["method"] == "depth_peeling":
        k, err, cost = pick["layers"], pick["predicted_steps"], pick["predicted_cost"]
        return Choice(
            "depth_peeling",
            f"{why}; depth peeling, {k} layers: predicted max error {err:.2g} steps ≤ tolerance "
            f"{tolerance:g}, cost {cost:.2f}× A-buffer (the frame, {frame.samples_total} samples) "
            f"(255·{c:.3g}·{brightest:.3g}·(1 − {alpha_min:g})^{k})",
            {"layers": k},
            predicted_steps=err,
            relative_cost=cost,
        )
    return Choice(
        "a_buffer",
        f"{why}: no number of peeled layers is predicted within {tolerance:g} steps and faster than the "
        f"A-buffer (peeling 1 of at most {layers_bound} layers is predicted at "
        f"{calibration.depth_peeling_cost(models, 1, frame.samples_total, n_triangles):.2f}× the A-buffer's "
        f"frame for {frame.samples_total} samples); the A-buffer is exact",
        predicted_steps=0.0,
        relative_cost=1.0,
    )


#: Meshes up to this many triangles get the exact nearest distance to the light and per-triangle
#: cone angles (one vectorised pass over their triangles); larger ones the bounding-box /
#: bounding-sphere bounds, which keep planning of 100k-triangle meshes cheap.


def _plan_shading(
    scene: Scene,
    facts: list[_MeshFacts],
    index: int,
    tolerance: float,
    models: dict,
    frame: _Frame | None = None,
) -> Choice:
    mesh = scene.meshes[index]
    if mesh.shading is not None:
        return Choice(mesh.shading, "set on the mesh by the caller")
    positional = [type(light).__name__ for light in scene.lights if light.positional]
    infinite_viewer = not scene.light_model.local_viewer
    if not facts[index].flat_normals:
        choice = Choice("phong", "normals vary across faces: per-pixel shading is the reference")
    elif positional:
        choice = Choice(
            "phong", f"planar faces, but a {positional[0]} changes the light direction across each face"
        )
    elif not infinite_viewer:
        choice = Choice(
            "phong",
            "planar faces, but a local viewer changes the view direction across each face "
            "(an orthographic camera should set LightModel(local_viewer=False))",
        )
    else:
        return Choice(
            "flat",
            "planar faces under directional light with a distant viewer: lighting is constant per face, "
            "flat shading is exact",
        )
    if tolerance <= 0 or len(mesh.triangles) == 0 or facts[index].flat_normals:
        return choice  # the shading model is calibrated on curved meshes (vertex normals that vary)
    calibrated = models["shading"]["shininess_calibrated"]
    if mesh.material.shininess > calibrated:
        return Choice(
            "phong",
            f"{choice.reason}; shininess {mesh.material.shininess:g} is beyond the calibrated {calibrated:g}",
        )
    theta = _normal_angle(mesh)  # calibration.max_normal_angle of the world normals, compiled
    theta_max = min(m["theta_range"][1] for m in models["shading"]["methods"].values())
    if theta > theta_max:
        return Choice(
            "phong",
            f"{choice.reason}; adjacent normals {math.degrees(theta):.3g}° apart, beyond the calibrated "
            f"{math.degrees(theta_max):.3g}°",
        )
    triangles = sum(f.n_tris for f in facts)
    samples = (frame if frame is not None else _frame(None, None, 1)).samples_total
    pick = calibration.choose_shading(models, tolerance, theta, samples, triangles)
    err, cost = pick["predicted_steps"], pick["predicted_cost"]
    if pick["method"] != "phong":
        return Choice(
            pick["method"],
            f"{pick['method']} shading: predicted max error {err:.2g} steps ≤ tolerance {tolerance:g}, "
            f"cost {cost:.2f}× Phong (adjacent normals up to {math.degrees(theta):.3g}° apart)",
            {},
            predicted_steps=err,
            relative_cost=cost,
        )
    others = ", ".join(
        f"{name} {calibration.predict_shading(models, name, theta):.2g} steps at "
        f"{calibration.shading_cost(models, name, samples, triangles):.2f}×"
        for name in ("flat", "gouraud")
    )
    return Choice(
        "phong",
        f"{choice.reason}; predicted: {others} Phong's time, none both within {tolerance:g} steps and faster",
        predicted_steps=err,
        relative_cost=1.0,
    )


#: The frame assumed when :func:`plan` is not told one (receiver samples for the cost models).


def plan(
    scene: Scene,
    tolerance: float = 0.0,
    models: dict | None = None,
    *,
    width: int | None = None,
    height: int | None = None,
    samples: int = 1,
    fog: object = None,
) -> Plan:
    """Pick, per concern, the fastest method that is exact or predicted within ``tolerance`` for ``scene``.

    Args:
        scene: the scene to plan for.
        tolerance: acceptable error in 8-bit steps (1/255 of the unit range), ≥ 0: a bound on
            every channel of every pixel of the image against the image every exact method
            gives (docs/speed_accuracy.md, "What the tolerance promises"). 0 asks for exact
            methods only.
        models: error and cost models (default: :func:`blinn_phong.planning.calibration.shipped_models`,
            fitted to ``python -m benchmarks`` measurements).
        width: frame width in pixels (None: :data:`DEFAULT_FRAME`), as passed to ``render``.
        height: frame height in pixels (None: :data:`DEFAULT_FRAME`).
        samples: samples per pixel (``k²`` for a k×k grid: 1, 4, 9, …), as passed to ``render``.
        fog: a :class:`blinn_phong.Fog` (or None), as passed to ``render``. Fog blends each
            fragment with the fog colour, ``f·c + (1 − f)·C_f`` (OpenGL 2.1 §3.10), ``f`` in [0, 1]
            taken over each mesh's eye distances (:func:`_fog_range`): a shadow's change of a
            pixel is scaled by ``f`` (``C_f`` cancels), and the colours behind peeled layers lie
            in ``[0, f_hi·B + (1 − f_lo)·C_f]``; the plan's ``fog`` choice states the range and
            the predicted cost of fog for the frame.

    ``render(scene, width, height, samples=k, tolerance=T, fog=F)`` follows
    ``plan(scene, T, width=width, height=height, samples=k, fog=F)`` wherever the caller sets
    no method (:func:`blinn_phong.planning.frame_plan.frame_plan`); the frame matters only to the cost models.

    Returns:
        :class:`Plan` with a choice and a reason per concern; approximate choices carry their
        predicted error and cost relative to the exact method.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a blinn_phong.Scene, got {type(scene).__name__}")
    real = int | float | np.integer | np.floating
    if isinstance(tolerance, bool | np.bool_) or not isinstance(tolerance, real):
        raise TypeError(f"tolerance: expected a number of 8-bit steps >= 0, got {type(tolerance).__name__}")
    if not (math.isfinite(tolerance) and tolerance >= 0):
        raise ValueError(f"tolerance: expected a finite number of 8-bit steps >= 0, got {tolerance!r}")
    tolerance = float(tolerance)
    if fog is not None:
        from blinn_phong.model.fog import Fog

        if not isinstance(fog, Fog):
            raise TypeError(f"fog: expected a blinn_phong.Fog or None, got {type(fog).__name__}")
    tol = float(tolerance)
    frame = _frame(width, height, samples)
    m = models if models is not None else calibration.shipped_models()
    facts = [_mesh_facts(mesh) for mesh in scene.meshes]
    factors = _light_factors(scene, facts)
    fogged = _fog_range(scene, facts, fog)
    transparency = _plan_transparency(scene, facts, tol, m, frame, factors, fogged)
    shadows = tuple(
        _plan_shadow(scene, facts, i, tol, m, frame, factors, fogged) for i in range(len(scene.lights))
    )
    shadows = tuple(coloured_shadow_reason(scene, c) for c in shadows)
    shading = tuple(_plan_shading(scene, facts, i, tol, m, frame) for i in range(len(scene.meshes)))
    return Plan(transparency, shadows, shading, tol, _plan_fog(fog, fogged, m, frame, facts))


def _plan_fog(
    fog: object, fogged: _FogRange, models: dict, frame: _Frame, facts: list[_MeshFacts]
) -> Choice | None:
    """The fog entry of a plan: its factor range over the meshes and its predicted cost."""
    if fog is None:
        return None
    used = [i for i, f in enumerate(facts) if f.n_tris]
    lo = min((float(fogged.low[i]) for i in used), default=1.0)
    hi = max((float(fogged.high[i]) for i in used), default=1.0)
    triangles = sum(f.n_tris for f in facts)
    cost = calibration.fog_cost(models, frame.samples_total, triangles)
    mode = fog.mode  # type: ignore[attr-defined]
    where = f"for {frame.samples_total} samples and {triangles} triangles"
    return Choice(
        mode,
        f"{mode} fog by {fog.distance} distance (OpenGL 2.1 §3.10): factor f in [{lo:.3g}, {hi:.3g}] "  # type: ignore[attr-defined]
        "over the meshes' eye distances; a shadow's change of a pixel is scaled by f, the colour behind "
        "peeled layers lies within f·B + (1 − f)·C_f"
        + (f"; predicted cost {cost:.2f}× the frame without fog {where}" if cost is not None else ""),
        predicted_steps=0.0,
        relative_cost=cost,
    )
