"""The planner: per concern, the fastest method that is exact or predicted within a tolerance.

:func:`plan` inspects a :class:`~blinn_phong.scene.Scene` — geometry, materials, lights,
camera — and returns a :class:`Plan`: one :class:`Choice` (method, parameters, a sentence
saying why, and for approximations the predicted error and relative cost) for
transparency, one per light for shadows and one per mesh for the shading frequency. It
renders nothing. Exact methods are picked from conservative geometric facts; with a
tolerance ``T > 0`` in **8-bit steps** (1/255 of the unit range) an approximate method is
picked where the measured error model of :mod:`blinn_phong.calibration` predicts at most
``T`` and its measured cost model predicts it faster than the exact method. ``T = 0``
means exact methods only. The error ``T`` bounds, per concern:

* transparency: the max error of any channel of the resolved image against the A-buffer;
* shadows: the mean error, over the covered pixels, against ray-traced shadows (any shadow
  map is a whole light's contribution off somewhere on a hard edge, so the max is no use);
* shading: the max error on interior pixels against per-pixel shading of the exact surface.

Transparency (methods of :mod:`blinn_phong.oit`):

* ``zbuffer`` — no material has opacity < 1.
* ``draw_last`` — one transparent mesh, planar or convex: drawn after the opaque ones,
  back faces first, then front faces; along any view ray a convex mesh's back face lies
  behind its front face, and a planar mesh never overlaps itself.
* ``sort_objects`` — several transparent meshes, each planar or convex, and every pair
  whose screen rectangles overlap is separated in eye depth: drawing them back to front
  (each as in ``draw_last``) follows the per-pixel order everywhere.
* ``depth_peeling`` — with a tolerance: the fewest layers ``k`` whose predicted max error
  ``255·c·B·(1 − α_min)^k`` is within it (what lies behind ``k`` layers is scaled by their
  transmittance, at most ``(1 − α_min)^k``; ``B`` bounds the straight radiance behind them,
  at least 1 because alpha counts too, divided by ``α_min`` for the absorption model whose
  fragments are not premultiplied by their opacity; ``c`` measured), if its predicted cost
  ``t₀ + t₁·k`` is below the A-buffer's.
* ``a_buffer`` — otherwise (surfaces may interpenetrate or overlap in depth): exact.

Shadows, per light (:mod:`blinn_phong.shadows`, :mod:`blinn_phong.raytrace`):

* ``none`` — ambient lights; or no mesh can shade another from this light: every caster's
  shadow volume (the cylinder or cone its bounding sphere sweeps away from the light)
  misses every other mesh's bounding sphere, and no mesh can shade itself (planar, or
  convex, whose self-shadowed faces face away from the light and are unlit anyway).
* ``planar`` — every receiver that can be shadowed is a planar mesh on one common plane and
  every caster lies between that plane and the light: Blinn's projected shadows are exact.
* ``shadow_map`` — with a tolerance, directional lights (the calibrated case): the smallest
  power-of-two resolution ``R`` whose predicted mean error ``255·c·w·D/(r·R)`` is within it
  (``D`` the scene's diameter, ``r`` the smallest caster's radius, ``w`` the largest change
  a pixel sees between lit and shadowed, the shadowed share taken as 1), if its predicted
  cost ``t₀ + t₂·R²`` is below ray tracing's.
* ``ray_traced`` — otherwise: exact hard shadows.

Shading frequency, per mesh (:mod:`blinn_phong.render`):

* ``flat`` — every triangle's vertex normals equal its face normal (planar faces), all
  lights are directional or ambient and the viewer is at infinity
  (``LightModel(local_viewer=False)``, what an orthographic camera should use): L, H and N
  are constant over each face, so the lighting is.
* ``flat`` or ``gouraud`` — with a tolerance, shininess within the calibrated range: the
  cheaper one whose predicted max error ``margin·a·θ^b`` (``θ`` the largest angle between
  adjacent vertex normals) is within it, if it is measured faster than Phong.
* ``phong`` — otherwise (per-pixel evaluation, the reference).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import calibration
from .normals import vertex_normals
from .scene import AmbientLight, DirectionalLight, Material, Mesh, PointLight, Scene, SpotLight

__all__ = ["Choice", "Plan", "plan"]

_EPS = 1e-9


@dataclass(frozen=True)
class Choice:
    """One decision: ``method``, its ``params``, the ``reason`` and, for approximations, predictions.

    ``params`` are keyword arguments of the function that carries the method out:
    ``layers`` for :func:`blinn_phong.oit.resolve_transparency`, ``plane`` or ``resolution``
    for :func:`blinn_phong.shadows.light_visibility`. ``predicted_steps`` is the error the
    calibrated model predicts (8-bit steps, in the concern's metric, see :func:`plan`; 0 for
    the exact method of a concern) and ``relative_cost`` the predicted time relative to that
    exact method (A-buffer, ray tracing, Phong); both None where no model applies.
    """

    method: str
    reason: str
    params: dict[str, object] = field(default_factory=dict)
    predicted_steps: float | None = None
    relative_cost: float | None = None

    def __str__(self) -> str:
        extra = ", ".join(f"{k}={v}" for k, v in self.params.items())
        return f"{self.method}{f' ({extra})' if extra else ''}: {self.reason}"


@dataclass(frozen=True)
class Plan:
    """The planner's decisions for one scene.

    Attributes:
        transparency: how transparent fragments are resolved.
        shadows: one choice per entry of ``scene.lights`` (same order).
        shading: one choice per entry of ``scene.meshes`` (same order).
        tolerance: the tolerance the plan was made for, in 8-bit steps (0: exact only).
    """

    transparency: Choice
    shadows: tuple[Choice, ...]
    shading: tuple[Choice, ...]
    tolerance: float

    def reasons(self) -> list[str]:
        """Every decision as one human-readable line."""
        lines = [f"transparency: {self.transparency}"]
        lines += [f"shadows, light {i}: {c}" for i, c in enumerate(self.shadows)]
        lines += [f"shading, mesh {i}: {c}" for i, c in enumerate(self.shading)]
        return lines

    def __str__(self) -> str:
        return "\n".join(self.reasons())


# --------------------------------------------------------------------------- geometry facts


@dataclass(frozen=True)
class _MeshFacts:
    world: np.ndarray  # (V, 3)
    tris: np.ndarray  # (T, 3, 3) world
    centre: np.ndarray
    radius: float
    planar: bool
    plane: np.ndarray | None  # (a, b, c, d) unit normal when planar
    convex: bool
    flat_normals: bool


def _mesh_facts(mesh: Mesh) -> _MeshFacts:
    hom = np.c_[mesh.positions, np.ones(len(mesh.positions))]
    world = (hom @ mesh.transform.T)[:, :3]
    used = world[np.unique(mesh.triangles)] if len(mesh.triangles) else world
    tris = world[mesh.triangles]
    lo, hi = used.min(axis=0), used.max(axis=0)
    centre = (lo + hi) / 2
    radius = float(np.max(np.linalg.norm(used - centre, axis=1))) if len(used) else 0.0
    scale = max(radius, 1e-300)
    fn = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    fn_len = np.linalg.norm(fn, axis=1)
    good = fn_len > 0
    fn_unit = fn[good] / fn_len[good, None]
    # planar: all used vertices on the plane of the first good face
    plane = None
    planar = False
    if good.any():
        n0 = fn_unit[0]
        d0 = -float(n0 @ tris[good][0, 0])
        planar = bool(np.all(np.abs(used @ n0 + d0) <= 1e-9 * scale))
        if planar:
            plane = np.r_[n0, d0]
    # convex (closed, outward-wound): no vertex in front of any face plane
    convex = planar
    if not planar and good.any() and len(fn_unit) * len(used) <= 4_000_000:
        dist = used @ fn_unit.T - np.einsum("ij,ij->i", fn_unit, tris[good][:, 0])[None, :]
        convex = bool(np.all(dist <= 1e-9 * scale))
    # flat normals: every vertex normal of a triangle is parallel to the face normal
    if mesh.normals is None:
        flat_normals = planar
    else:
        nrm = mesh.normals @ np.linalg.inv(mesh.transform[:3, :3])  # inverse-transpose, row vectors
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        per_corner = nrm[mesh.triangles][good]  # (T, 3, 3)
        cos = np.einsum("tkc,tc->tk", per_corner, fn_unit)
        flat_normals = bool(np.all(cos >= 1 - 1e-9))
    return _MeshFacts(world, tris, centre, radius, planar, plane, convex, flat_normals)


def _screen_rect_and_depth(facts: _MeshFacts, scene: Scene) -> tuple[np.ndarray, tuple[float, float]]:
    """NDC rectangle (x0, y0, x1, y1) and eye distance interval (−z) of a mesh."""
    hom = np.c_[facts.world, np.ones(len(facts.world))]
    eye = hom @ scene.camera.view.T
    clip = eye @ scene.camera.projection.T
    depth = (-float(eye[:, 2].max()), -float(eye[:, 2].min()))
    if np.any(clip[:, 3] <= 0):
        return np.array([-np.inf, -np.inf, np.inf, np.inf]), depth
    ndc = clip[:, :2] / clip[:, 3:4]
    return np.r_[ndc.min(axis=0), ndc.max(axis=0)], depth


def _rects_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3])


def _may_shadow(
    caster: _MeshFacts, receiver: _MeshFacts, light: DirectionalLight | PointLight | SpotLight
) -> bool:
    """Conservative: can ``caster`` lie between ``light`` and any point of ``receiver``?"""
    if caster.planar and caster.plane is not None:
        # a flat caster shades only what lies on its far side from the light
        oriented, _ = _light_side_distance(caster.plane, light)
        if float(np.min(receiver.world @ oriented[:3]) + oriented[3]) >= -_EPS * max(receiver.radius, 1.0):
            return False
    r = caster.radius + receiver.radius
    if isinstance(light, DirectionalLight):
        d = np.asarray(light.direction)  # the direction light travels
        w = receiver.centre - caster.centre
        along = float(w @ d)
        if along < -r:
            return False  # receiver entirely on the light's side of the caster
        perp = float(np.linalg.norm(w - max(along, 0.0) * d))
        return perp < r
    pos = np.asarray(light.position)
    to_c = caster.centre - pos
    to_r = receiver.centre - pos
    dc, dr = float(np.linalg.norm(to_c)), float(np.linalg.norm(to_r))
    if dc <= caster.radius or dr <= receiver.radius:
        return True  # the light is inside a bounding sphere
    if dr + receiver.radius < dc - caster.radius:
        return False  # receiver entirely nearer the light than the caster
    angle = math.acos(float(np.clip(to_c @ to_r / (dc * dr), -1, 1)))
    return angle < math.asin(min(caster.radius / dc, 1.0)) + math.asin(min(receiver.radius / dr, 1.0))


def _light_side_distance(
    plane: np.ndarray, light: DirectionalLight | PointLight | SpotLight
) -> tuple[np.ndarray, float]:
    """Plane oriented towards the light, and the light's signed distance (inf if directional)."""
    n, d = plane[:3], plane[3]
    if isinstance(light, DirectionalLight):
        towards = -np.asarray(light.direction)
        if float(n @ towards) < 0:
            n, d = -n, -d
        return np.r_[n, d], math.inf
    lp = np.asarray(light.position)
    h = float(n @ lp + d)
    if h < 0:
        n, d, h = -n, -d, -h
    return np.r_[n, d], h


# --------------------------------------------------------------------------- decisions


def _plan_transparency(scene: Scene, facts: list[_MeshFacts], tolerance: float, models: dict) -> Choice:
    transparent = [i for i, m in enumerate(scene.meshes) if m.material.opacity < 1.0 and len(m.triangles)]
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
    alpha_min = min(scene.meshes[i].material.opacity for i in transparent)
    if alpha_min <= 0:
        return Choice(
            "a_buffer",
            f"{why}: a surface of opacity 0 (or the emission model) attenuates nothing behind it, so no "
            "number of peeled layers bounds the rest; the A-buffer is exact",
            predicted_steps=0.0,
            relative_cost=1.0,
        )
    # what the dropped layers hide: transparent and opaque colour behind them, and coverage (alpha)
    brightest = max(1.0, *(_max_radiance(scene, m) for m in scene.meshes))
    if any(scene.meshes[i].material.transparency_model == "absorption" for i in transparent):
        brightest /= alpha_min  # c + (1 − α)·behind: a stack behind adds up to B·Σ(1 − α)^j ≤ B/α
    layers_bound = sum(
        1 if facts[i].planar else 2 * max(len(scene.meshes[i].triangles), 1) for i in transparent
    )
    pick = calibration.choose_depth_peeling(models, tolerance, alpha_min, brightest, layers_bound)
    c = calibration.depth_peeling_factor(models)
    if pick["method"] == "depth_peeling":
        k, err, cost = pick["layers"], pick["predicted_steps"], pick["predicted_cost"]
        return Choice(
            "depth_peeling",
            f"{why}; depth peeling, {k} layers: predicted max error {err:.2g} steps ≤ tolerance "
            f"{tolerance:g}, cost {cost:.2f}× A-buffer (255·{c:.3g}·{brightest:.3g}·(1 − {alpha_min:g})^{k})",
            {"layers": k},
            predicted_steps=err,
            relative_cost=cost,
        )
    return Choice(
        "a_buffer",
        f"{why}: no number of peeled layers is predicted within {tolerance:g} steps and faster than the "
        f"A-buffer (peeling k of at most {layers_bound} layers costs ({models['depth_peeling']['t0']:.2f} + "
        f"{models['depth_peeling']['t1']:.3f}·k)× the A-buffer); the A-buffer is exact",
        predicted_steps=0.0,
        relative_cost=1.0,
    )


def _max_radiance(scene: Scene, mesh: Mesh) -> float:
    """Upper bound of the straight colour a surface of ``mesh`` can reach (unclamped lighting)."""
    m = mesh.material
    total = np.asarray(m.emission) + np.asarray(m.ambient) * np.asarray(scene.ambient)
    for light in scene.lights:
        if isinstance(light, AmbientLight):
            total = total + np.asarray(m.ambient) * np.asarray(light.radiance)
            continue
        total = total + np.asarray(m.ambient) * np.asarray(light.ambient)
        total = total + np.asarray(m.diffuse) * np.asarray(light.diffuse)
        total = total + np.asarray(m.specular) * np.asarray(light.specular)
    return float(np.max(total))


def _plan_shadow(scene: Scene, facts: list[_MeshFacts], index: int, tolerance: float, models: dict) -> Choice:
    light = scene.lights[index]
    if isinstance(light, AmbientLight):
        return Choice("none", "an ambient light has no direction and casts no shadow")
    pairs = []
    for a, fa in enumerate(facts):
        if len(fa.tris) == 0:
            continue
        for b, fb in enumerate(facts):
            if len(fb.tris) == 0:
                continue
            if a == b:
                if not (fa.planar or fa.convex):
                    pairs.append((a, b))
            elif _may_shadow(fa, fb, light):
                pairs.append((a, b))
    if not pairs:
        return Choice(
            "none",
            "no occluder between the light and anything: every shadow volume misses the other meshes "
            "and no mesh can shade itself",
        )
    receivers = {b for _, b in pairs}
    casters = {a for a, _ in pairs}
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
            if ok:
                return Choice(
                    "planar",
                    f"only the plane of mesh {min(receivers)} receives shadows and every caster lies between "
                    "it and the light: projected (fake) shadows are exact",
                    {"plane": tuple(float(v) for v in oriented)},
                )
    a, b = pairs[0]
    what = f"mesh {a} can shade itself" if a == b else f"mesh {a} can shadow mesh {b}"
    exact = Choice(
        "ray_traced", f"{what}: ray-traced shadows are exact", predicted_steps=0.0, relative_cost=1.0
    )
    if tolerance <= 0:
        return exact
    if not isinstance(light, DirectionalLight):
        return Choice(
            "ray_traced",
            f"{what}: ray-traced shadows are exact (the shadow-map error model is calibrated for "
            "directional lights only)",
            predicted_steps=0.0,
            relative_cost=1.0,
        )
    everything = np.concatenate([f.tris.reshape(-1, 3) for f in facts if len(f.tris)])
    diameter = calibration.scene_extent(everything)
    r_min = min(facts[c].radius for c in casters)
    weight = _shadow_weight(scene, light)
    if diameter <= 0 or r_min <= 0:
        return exact
    pick = calibration.choose_shadow_map(models, tolerance, diameter, r_min, 1.0, weight)
    formula = (
        f"255·{models['shadow_map']['c']:.3g}·{weight:.3g}·{diameter:.3g}/({r_min:.3g}·R), "
        "nearest texel, bias 1e-4 + 2·slope"
    )
    if pick["method"] == "shadow_map":
        res, err, cost = pick["resolution"], pick["predicted_steps"], pick["predicted_cost"]
        return Choice(
            "shadow_map",
            f"{what}; a {res}² shadow map: predicted mean error {err:.2g} steps ≤ tolerance {tolerance:g}, "
            f"cost {cost:.2f}× ray tracing ({formula})",
            {"resolution": res},
            predicted_steps=err,
            relative_cost=cost,
        )
    faster = [r for r in calibration.SHADOW_MAP_RESOLUTIONS if calibration.shadow_map_cost(models, r) < 1]
    if not faster:
        why = "no shadow map is predicted faster than ray tracing"
    else:
        err = weight * calibration.predict_shadow_map(models, faster[-1], diameter, r_min, 1.0)
        why = (
            f"the largest shadow map predicted faster ({faster[-1]}²) is predicted at {err:.2g} mean "
            f"steps > tolerance {tolerance:g} ({formula})"
        )
    return Choice(
        "ray_traced",
        f"{what}: ray-traced shadows are exact; {why}",
        predicted_steps=0.0,
        relative_cost=1.0,
    )


def _shadow_weight(scene: Scene, light: DirectionalLight) -> float:
    """Largest change of a pixel channel between lit and shadowed by ``light``: max over materials of
    ``diffuse·light.diffuse + specular·light.specular`` (N·L ≤ 1 and the specular factor ≤ 1)."""
    weight = 0.0
    for mesh in scene.meshes:
        materials: list[Material] = [mesh.material]
        if mesh.back_material is not None and scene.light_model.two_sided:
            materials.append(mesh.back_material)
        for m in materials:
            term = np.asarray(m.diffuse) * np.asarray(light.diffuse)
            term = term + np.asarray(m.specular) * np.asarray(light.specular)
            weight = max(weight, float(np.max(term)))
    return weight


def _plan_shading(
    scene: Scene, facts: list[_MeshFacts], index: int, tolerance: float, models: dict
) -> Choice:
    mesh = scene.meshes[index]
    if mesh.shading is not None:
        return Choice(mesh.shading, "set on the mesh by the caller")
    positional = [type(light).__name__ for light in scene.lights if isinstance(light, PointLight | SpotLight)]
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
    theta = calibration.max_normal_angle(_world_normals(mesh), mesh.triangles)
    theta_max = min(m["theta_range"][1] for m in models["shading"]["methods"].values())
    if theta > theta_max:
        return Choice(
            "phong",
            f"{choice.reason}; adjacent normals {math.degrees(theta):.3g}° apart, beyond the calibrated "
            f"{math.degrees(theta_max):.3g}°",
        )
    pick = calibration.choose_shading(models, tolerance, theta)
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
    methods = models["shading"]["methods"]
    others = ", ".join(
        f"{name} {calibration.predict_shading(models, name, theta):.2g} steps at "
        f"{methods[name]['ratio_to_phong']:.2f}×"
        for name in ("flat", "gouraud")
    )
    return Choice(
        "phong",
        f"{choice.reason}; predicted: {others} Phong's time, none both within {tolerance:g} steps and faster",
        predicted_steps=err,
        relative_cost=1.0,
    )


def _world_normals(mesh: Mesh) -> np.ndarray:
    """Vertex normals in world space (the inverse transpose of the linear part), as the renderer uses them."""
    normals = mesh.normals if mesh.normals is not None else vertex_normals(mesh.positions, mesh.triangles)
    return np.asarray(normals, dtype=np.float64) @ np.linalg.inv(mesh.transform[:3, :3])


def plan(scene: Scene, tolerance: float = 0.0, models: dict | None = None) -> Plan:
    """Pick, per concern, the fastest method that is exact or predicted within ``tolerance`` for ``scene``.

    Args:
        scene: the scene to plan for.
        tolerance: acceptable error in 8-bit steps (1/255 of the unit range), ≥ 0: the max
            error of the transparency resolve against the A-buffer, the mean error of the
            shadows against ray tracing over the covered pixels, the max interior error of the
            shading frequency against per-pixel shading of the exact surface. 0 asks for exact
            methods only.
        models: error and cost models (default: :func:`blinn_phong.calibration.shipped_models`,
            fitted to ``python -m benchmarks`` measurements).

    Returns:
        :class:`Plan` with a choice and a reason per concern; approximate choices carry their
        predicted error and cost relative to the exact method.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a blinn_phong.Scene, got {type(scene).__name__}")
    if isinstance(tolerance, bool) or not (
        isinstance(tolerance, int | float) and math.isfinite(tolerance) and tolerance >= 0
    ):
        raise ValueError(f"tolerance must be a finite number of 8-bit steps >= 0, got {tolerance!r}")
    tol = float(tolerance)
    m = models if models is not None else calibration.shipped_models()
    facts = [_mesh_facts(mesh) for mesh in scene.meshes]
    transparency = _plan_transparency(scene, facts, tol, m)
    shadows = tuple(_plan_shadow(scene, facts, i, tol, m) for i in range(len(scene.lights)))
    shading = tuple(_plan_shading(scene, facts, i, tol, m) for i in range(len(scene.meshes)))
    return Plan(transparency, shadows, shading, tol)
