"""Conservative bounds the planner's choices rest on: how bright a surface can be (every factor of
the lighting equation, the attenuation at a mesh's nearest distance from a light, the spot cone
at its smallest angle, fog), how much a light's shadow can change a pixel, and how many
transparent layers can stack. Each bound is an upper bound, tested against rendered images
(tests/planning/test_planner_bounds.py)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from blinn_phong.geometry.mesh_facts import _MeshFacts, nearest_triangle_distance
from blinn_phong.model.lights import AmbientLight, DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Material, Mesh, Scene

_EPS = 1e-9


_EXACT_DISTANCE_TRIANGLES = 20_000


def _eye_triangles(f: _MeshFacts, view: np.ndarray) -> np.ndarray:
    """(T, 3, 3) triangles of a mesh in eye space (``view`` applied to the world triangles)."""
    return f.tris @ view[:3, :3].T + view[:3, 3]


def _rigid(view: np.ndarray) -> bool:
    """True when ``view``'s linear part is a rotation (orthonormal to 1e-12): it keeps distances and
    angles, so world-space bounding boxes and balls bound eye-space distances as well."""
    r = view[:3, :3]
    return bool(np.abs(r.T @ r - np.eye(3)).max() <= 1e-12) and bool(np.allclose(view[3], (0, 0, 0, 1)))


def _nearest_distance(point: np.ndarray, f: _MeshFacts, view: np.ndarray) -> float:
    """A lower bound of the eye-space distance from ``point`` (eye space) to any point of a mesh.

    Exact (:func:`~blinn_phong.geometry.mesh_facts.nearest_triangle_distance`) up to
    :data:`_EXACT_DISTANCE_TRIANGLES` triangles (under a rigid view in world space, with the
    facts' cached triangles: the same distance up to rounding); beyond, the larger of the distances to the
    eye-space vertices' bounding box and bounding sphere (each contains the mesh, so each is a
    lower bound). ``inf`` for an empty mesh.
    """
    if f.n_tris == 0 or len(f.world) == 0:
        return math.inf
    if f.n_tris <= _EXACT_DISTANCE_TRIANGLES:
        if _rigid(view):  # eye-space distances are world-space ones: the facts' cached triangles
            return nearest_triangle_distance(f.balls, view[:3, :3].T @ (point - view[:3, 3]))
        return nearest_triangle_distance(_eye_triangles(f, view), point)
    if _rigid(view):  # distances are those of world space: the world box and ball of the facts
        world = view[:3, :3].T @ (point - view[:3, 3])
        box = float(np.linalg.norm(np.maximum(np.maximum(f.lo - world, world - f.hi), 0.0)))
        return max(box, float(np.linalg.norm(world - f.centre)) - f.radius)
    eye = f.world @ view[:3, :3].T + view[:3, 3]
    lo, hi = eye.min(axis=0), eye.max(axis=0)
    box = float(np.linalg.norm(np.maximum(np.maximum(lo - point, point - hi), 0.0)))
    centre = (lo + hi) / 2
    radius = float(np.sqrt(np.max(np.einsum("ij,ij->i", eye - centre, eye - centre))))
    return max(box, float(np.linalg.norm(point - centre)) - radius)


def _spot_bound(light: SpotLight, f: _MeshFacts, view: np.ndarray, position: np.ndarray) -> float:
    """Upper bound of a spot light's factor ``spot = [−l·s ≥ cos(cutoff)]·max(−l·s, 0)^e`` over a mesh.

    ``−l·s = cos θ`` with ``θ`` the angle between the spot axis ``s`` and the direction from
    the light to the point (eye space, as :mod:`blinn_phong.frame.lighting` evaluates it). Every point
    of a triangle lies in the ball around its centroid ``m`` through its farthest vertex
    (radius ``ρ``; above :data:`_EXACT_DISTANCE_TRIANGLES` triangles one ball around the whole
    mesh); seen from the light at distance ``D = |m − p_L| > ρ`` the ball subtends a
    cone of half-angle ``asin(ρ/D)`` around ``m − p_L``, so by the triangle inequality of angles
    ``θ ≥ ∠(m − p_L, s) − asin(ρ/D)``; ``θ ≥ 0`` when the light is inside a ball. With
    ``θ_min`` the smallest of these over the triangles, ``spot ≤ cos(θ_min)^e`` (cos decreasing
    on [0, π]), and ``spot = 0`` everywhere when ``θ_min`` exceeds the cut-off.
    """
    axis = view[:3, :3] @ np.asarray(light.direction, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    if f.n_tris > _EXACT_DISTANCE_TRIANGLES and _rigid(view):  # the facts' world ball, moved to eye space
        centroid = (view[:3, :3] @ f.centre + view[:3, 3])[None]
        rho = np.array([f.radius])
    elif f.n_tris > _EXACT_DISTANCE_TRIANGLES:  # one ball around the whole mesh
        eye = f.world @ view[:3, :3].T + view[:3, 3]
        centroid = ((eye.min(axis=0) + eye.max(axis=0)) / 2)[None]
        rho = np.sqrt(np.max(np.einsum("ij,ij->i", eye - centroid, eye - centroid)))[None]
    else:
        tris = _eye_triangles(f, view)
        centroid = tris.mean(axis=1)
        rho = np.sqrt(
            np.max(np.einsum("tkc,tkc->tk", tris - centroid[:, None], tris - centroid[:, None]), axis=1)
        )
    to_m = centroid - position
    dist = np.sqrt(np.einsum("ij,ij->i", to_m, to_m))
    if np.any(dist <= rho):
        theta_min = 0.0
    else:
        cos_axis = np.clip((to_m @ axis) / dist, -1.0, 1.0)
        theta = np.arccos(cos_axis) - np.arcsin(np.clip(rho / dist, 0.0, 1.0))
        theta_min = max(float(theta.min()) - 1e-9, 0.0)  # 1e-9 rad: rounding of arccos/arcsin
    if theta_min > math.radians(light.cutoff):
        return 0.0
    return max(math.cos(theta_min), 0.0) ** light.exponent


def _mesh_light_factor(
    light: DirectionalLight | PointLight | SpotLight, f: _MeshFacts, view: np.ndarray
) -> float:
    """Upper bound of ``att·spot`` of ``light`` over every point of one mesh (eye space, as lit).

    ``att = 1/(k_c + k_l·d + k_q·d²)`` decreases with ``d ≥ 0`` (``k ≥ 0``), so over the mesh it
    is at most its value at the mesh's nearest distance ``d_min`` from the light
    (:func:`_nearest_distance`: exact, the nearest point of the nearest triangle); it exceeds 1
    whenever the denominator is below 1 there (``k_c < 1`` near the light): 100 for
    ``k_c = 0.01`` at ``d = 0``. The spot factor is bounded by :func:`_spot_bound` (the cone's
    smallest angle to the mesh's triangles), 1 for point lights; ``max(att·spot) ≤
    max(att)·max(spot)``. Directional lights: 1. Infinite when the denominator can be 0 on the
    mesh (``k_c = 0`` and a surface at the light); 0 for an empty mesh.
    """
    if not light.positional:
        return 1.0
    if f.n_tris == 0 or len(f.world) == 0:
        return 0.0
    position = view[:3, :3] @ np.asarray(light.position, dtype=np.float64) + view[:3, 3]
    spot = _spot_bound(light, f, view, position) if isinstance(light, SpotLight) else 1.0
    if spot == 0.0:
        return 0.0
    d_min = _nearest_distance(position, f, view)
    denominator = light.constant + light.linear * d_min + light.quadratic * d_min * d_min
    return math.inf if denominator <= 0 else spot / denominator


def _light_factor_bound(
    light: DirectionalLight | PointLight | SpotLight, facts: list[_MeshFacts], view: np.ndarray | None = None
) -> float:
    """Upper bound of ``att·spot`` of ``light`` over every surface point of the scene: the largest
    per-mesh bound (:func:`_mesh_light_factor`; ``view`` the camera's, identity by default)."""
    v = np.eye(4) if view is None else np.asarray(view, dtype=np.float64)
    return max((_mesh_light_factor(light, f, v) for f in facts), default=0.0)


def _light_factors(scene: Scene, facts: list[_MeshFacts]) -> np.ndarray:
    """(meshes, lights) bounds of ``att·spot`` per mesh and light (1 for ambient and directional)."""
    view = np.asarray(scene.camera.view, dtype=np.float64) if scene.camera is not None else np.eye(4)
    out = np.ones((len(facts), len(scene.lights)))
    for j, light in enumerate(scene.lights):
        if not light.positional:  # ambient and directional lights do not attenuate
            continue
        for i, f in enumerate(facts):
            out[i, j] = _mesh_light_factor(light, f, view)
    return out


@dataclass(frozen=True)
class _FogRange:
    """Per mesh, the smallest and largest fog factor over its points (1, 1 without fog), and the
    largest fog colour channel."""

    low: np.ndarray
    high: np.ndarray
    colour: float


def _fog_range(scene: Scene, facts: list[_MeshFacts], fog: object) -> _FogRange:
    """The fog factor's range over each mesh (OpenGL 2.1 §3.10; :func:`blinn_phong.model.fog.fog_factor`).

    The fog distance ``c`` of a fragment is ``|z_eye|`` (``distance="plane"``) or ``‖p_eye‖``
    (``"radial"``) of a point of one of its mesh's eye-space triangles, so it lies in
    ``[c_lo, c_hi]``: for ``plane`` the vertices' ``|z|`` range (0 when it spans z = 0), for
    ``radial`` the nearest distance from the eye to the triangles (:func:`_nearest_distance`)
    and the farthest vertex (the norm is convex: its maximum on a triangle is at a corner).
    The three factors are monotonic in ``c ≥ 0`` (linear both ways, exp and exp2 decreasing,
    all clamped to [0, 1]), so over the mesh ``f`` lies between its values at ``c_lo`` and ``c_hi``.
    """
    n = len(facts)
    if fog is None:
        return _FogRange(np.ones(n), np.ones(n), 0.0)
    from blinn_phong.model.fog import fog_factor

    view = np.asarray(scene.camera.view, dtype=np.float64)
    low, high = np.ones(n), np.ones(n)
    for i, f in enumerate(facts):
        if f.n_tris == 0 or len(f.world) == 0:
            continue
        eye = f.world @ view[:3, :3].T + view[:3, 3]
        if fog.distance == "plane":  # type: ignore[attr-defined]
            z_lo, z_hi = float(eye[:, 2].min()), float(eye[:, 2].max())
            c_lo = 0.0 if z_lo <= 0.0 <= z_hi else min(abs(z_lo), abs(z_hi))
            c_hi = max(abs(z_lo), abs(z_hi))
        else:
            c_lo = _nearest_distance(np.zeros(3), f, view)
            c_hi = float(np.sqrt(np.max(np.einsum("ij,ij->i", eye, eye))))
        ends = fog_factor(
            np.array([c_lo, c_hi]),
            fog.mode,  # type: ignore[attr-defined]
            density=fog.density,  # type: ignore[attr-defined]
            start=fog.start,  # type: ignore[attr-defined]
            end=fog.end,  # type: ignore[attr-defined]
        )
        low[i], high[i] = float(ends.min()), float(ends.max())
    return _FogRange(low, high, float(max(fog.color)))  # type: ignore[attr-defined]


def _sides(scene: Scene, mesh: Mesh) -> list[Material]:
    """The materials a mesh's fragments are shaded with: the back one too under two-sided lighting."""
    if scene.light_model.two_sided and mesh.back_material is not None:
        return [mesh.material, mesh.back_material]
    return [mesh.material]


def _fogged_radiance_bound(
    scene: Scene, facts: list[_MeshFacts], factors: np.ndarray, fog: _FogRange
) -> float:
    """Bound ``B`` of the straight colour (and of alpha, 1) of any fragment, fog included.

    Per mesh, :func:`_max_radiance` bounds the unfogged colour ``c`` by ``B_m`` (with that mesh's
    light factors). Fog (OpenGL 2.1 §3.10) makes a fragment's straight colour
    ``f·c + (1 − f)·C_f`` with ``f`` in the mesh's range ``[f_lo, f_hi]`` (:func:`_fog_range`),
    so it lies in ``[0, f_hi·B_m + (1 − f_lo)·max C_f]`` — smaller than ``B_m`` under dark fog,
    larger under fog brighter than the mesh. Alpha is not fogged and counts 1. The bound is the
    largest over the meshes, at least 1.
    """
    worst = 1.0
    for i, mesh in enumerate(scene.meshes):
        b = _max_radiance(scene, mesh, list(factors[i]))
        if not math.isfinite(b):
            return math.inf
        worst = max(worst, float(fog.high[i]) * b + (1.0 - float(fog.low[i])) * fog.colour)
    return worst


def _max_radiance(scene: Scene, mesh: Mesh, factors: list[float]) -> float:
    """Upper bound of the straight colour any fragment of ``mesh`` can have (unclamped lighting).

    Bounding every factor of the lighting equation (:mod:`blinn_phong.frame.lighting`, OpenGL 2.1
    §2.14.1) term by term, per channel and per side's material:

    ``c ≤ e_cm + a_cm·a_cs + a_cm·Σ_amb I + Σ_i F_i·(a_cm·a_cli + d_cm·d_cli + s_cm·s_cli)``

    since ``n ⊙ l ≤ 1``, ``spec^s ≤ 1``, the visibility ``≤ 1`` and ``att_i·spot_i ≤ F_i``
    (``factors``, :func:`_light_factor_bound`, which exceeds 1 for a positional light with
    ``k_c < 1`` close to a surface). The bound is the largest channel.
    """
    worst = 0.0
    for m in _sides(scene, mesh):
        total = np.asarray(m.emission) + np.asarray(m.ambient) * np.asarray(scene.ambient)
        for light, factor in zip(scene.lights, factors, strict=True):
            if isinstance(light, AmbientLight):
                total = total + np.asarray(m.ambient) * np.asarray(light.radiance)
                continue
            if factor == 0.0:
                continue
            per_light = (
                np.asarray(m.ambient) * np.asarray(light.ambient)
                + np.asarray(m.diffuse) * np.asarray(light.diffuse)
                + np.asarray(m.specular) * np.asarray(light.specular)
            )
            total = total + factor * per_light
        worst = max(worst, float(np.max(total)))
    return worst


def _shadow_weight(
    scene: Scene,
    light: DirectionalLight | PointLight | SpotLight,
    facts: list[_MeshFacts],
    factors: np.ndarray | None = None,
    fog: _FogRange | None = None,
    index: int | None = None,
) -> float:
    """Largest change of a pixel channel between lit and shadowed by ``light``.

    A fragment of mesh ``m`` changes by at most ``F_m·max(d_cm·d_cl + s_cm·s_cl)`` over its
    sides' materials, ``F_m`` the bound of ``att·spot`` on that mesh (:func:`_mesh_light_factor`),
    since ``n ⊙ l ≤ 1`` and the specular factor ``≤ 1``; the light's ambient term is not
    shadowed. Fog turns a fragment's colour into ``f·c + (1 − f)·C_f`` with the same ``f`` lit
    or shadowed, so the change is ``f·Δc ≤ f_hi,m·Δc`` (:func:`_fog_range`). A pixel blends
    fragments: with partial occlusion (and Kay–Greenberg) the weights of the fragments and the
    background add up to 1, so the pixel changes by at most the largest fragment change; the
    absorption model adds each layer's colour unscaled, ``c_j`` times the transmittance in
    front, at most ``Σ(1 − α_min)^j ≤ 1/α_min`` of it; emission-model fragments (α = 0) add
    up over every layer (:func:`_layer_bound`).
    """
    j = index if index is not None else (list(scene.lights).index(light) if factors is not None else None)
    view = np.asarray(scene.camera.view, dtype=np.float64) if scene.camera is not None else np.eye(4)
    weight = 0.0
    for i, mesh in enumerate(scene.meshes):
        factor = (
            float(factors[i, j])
            if factors is not None and j is not None
            else _mesh_light_factor(light, facts[i], view)
        )
        if factor == 0.0:
            continue
        for m in _sides(scene, mesh):
            term = np.asarray(m.diffuse) * np.asarray(light.diffuse)
            term = term + np.asarray(m.specular) * np.asarray(light.specular)
            peak = float(np.max(term))
            if peak > 0.0:
                f_hi = 1.0 if fog is None else float(fog.high[i])
                weight = max(weight, f_hi * factor * peak)
    return weight * _stack_gain(scene, facts)


def _layer_bound(scene: Scene, facts: list[_MeshFacts], meshes: list[int]) -> int:
    """An upper bound of the fragments of ``meshes`` on one sample: 1 per planar mesh, its
    triangles (two per ray at most for a convex one) otherwise."""
    return sum(
        1 if facts[i].planar else (2 if facts[i].convex else max(len(scene.meshes[i].triangles), 1))
        for i in meshes
    )


def _stack_gain(scene: Scene, facts: list[_MeshFacts]) -> float:
    """How much a pixel can change when every fragment on it changes by at most 1 (see
    :func:`_shadow_weight`): 1, ``1/α_min`` with absorbing transparent layers, the layer bound
    with emission-model ones (their α is 0: colours add)."""
    transparent = [
        i for i, m in enumerate(scene.meshes) if _lowest_opacity(scene, m) < 1.0 and len(m.triangles)
    ]
    models = {
        m.transparency_model for i in transparent for m in _sides(scene, scene.meshes[i]) if m.transparent
    }
    if "emission" in models:
        return float(max(_layer_bound(scene, facts, transparent), 1))
    if "absorption" in models:
        lowest = min(_lowest_opacity(scene, scene.meshes[i]) for i in transparent)
        return math.inf if lowest <= 0 else 1.0 / lowest
    return 1.0


def _lowest_opacity(scene: Scene, mesh: Mesh) -> float:
    """The lowest opacity a fragment of ``mesh`` can have, as the frame resolves it.

    Kay–Greenberg materials reach ``1 − max(t_min, t_max)`` (``Material.min_opacity``); an
    emission-model fragment has alpha 0 and hides nothing behind it (opacity 0); under
    two-sided lighting the back material counts too.
    """

    def lowest(material: Material) -> float:
        if not material.transparent:
            return 1.0
        return 0.0 if material.transparency_model == "emission" else material.min_opacity

    return min(lowest(m) for m in _sides(scene, mesh))
