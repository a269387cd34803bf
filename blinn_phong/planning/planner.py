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
from dataclasses import dataclass, field, replace

import numpy as np

from blinn_phong._numba import numba_available
from blinn_phong.geometry.mesh_facts import (
    _beyond_near_plane,
    _light_side_distance,
    _may_shadow,
    _mesh_facts,
    _MeshFacts,
    _normal_angle,
    _projected_width,
    _rects_overlap,
    _screen_rect_and_depth,
    coordinate_tolerance,
)
from blinn_phong.model.lights import AmbientLight, DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Material, Mesh, Scene
from blinn_phong.planning import calibration
from blinn_phong.shadows.method import embree_available

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


@dataclass(frozen=True)
class Choice:
    """One decision: ``method``, its ``params``, the ``reason`` and, for approximations, predictions.

    ``params`` are keyword arguments of the function that carries the method out:
    ``layers`` for :func:`blinn_phong.effects.oit.resolve_transparency`, ``plane`` or ``resolution``
    for :func:`blinn_phong.shadows.methods.light_visibility`. ``predicted_steps`` is the error the
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
        fog: with fog, what it does to the error bounds and what it costs (None without fog).
    """

    transparency: Choice
    shadows: tuple[Choice, ...]
    shading: tuple[Choice, ...]
    tolerance: float
    fog: Choice | None = None

    def reasons(self) -> list[str]:
        """Every decision as one human-readable line."""
        lines = [f"transparency: {self.transparency}"]
        lines += [f"shadows, light {i}: {c}" for i, c in enumerate(self.shadows)]
        lines += [f"shading, mesh {i}: {c}" for i, c in enumerate(self.shading)]
        if self.fog is not None:
            lines.append(f"fog: {self.fog}")
        return lines

    def __str__(self) -> str:
        return "\n".join(self.reasons())


# --------------------------------------------------------------------------- decisions


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
_EXACT_DISTANCE_TRIANGLES = 20_000


def _triangle_distances(point: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Euclidean distance from ``point`` (3,) to each triangle of ``tris`` (T, 3, 3), exactly.

    The nearest point of a triangle is the foot of the perpendicular on its plane when that
    foot lies inside (same side of all three edges), otherwise the nearest point of one of its
    edges (clamped projection on each segment; Ericson, *Real-Time Collision Detection*, 2005,
    §5.1.5). Degenerate triangles (zero area) use their edges only.
    """
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    ap = point - a
    inside = nn > 0
    for p0, p1 in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(p1 - p0, point - p0), n) >= 0
    plane = np.abs(np.einsum("ij,ij->i", ap, n)) / np.sqrt(np.where(nn > 0, nn, 1.0))
    best = np.full(len(tris), np.inf)
    for p0, p1 in ((a, b), (b, c), (c, a)):
        e = p1 - p0
        ee = np.einsum("ij,ij->i", e, e)
        t = np.clip(np.einsum("ij,ij->i", point - p0, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
        q = p0 + t[:, None] * e - point
        best = np.minimum(best, np.sqrt(np.einsum("ij,ij->i", q, q)))
    return np.where(inside, plane, best)


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

    Exact (:func:`_triangle_distances`) up to :data:`_EXACT_DISTANCE_TRIANGLES` triangles;
    beyond, the larger of the distances to the eye-space vertices' bounding box and bounding
    sphere (each contains the mesh, so each is a lower bound). ``inf`` for an empty mesh.
    """
    if f.n_tris == 0 or len(f.world) == 0:
        return math.inf
    if f.n_tris <= _EXACT_DISTANCE_TRIANGLES:
        return float(_triangle_distances(point, _eye_triangles(f, view)).min())
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
        return Choice("none", "an ambient light has no direction and casts no shadow")
    pairs = _shadow_pairs(scene, facts, light)
    if not pairs:
        return Choice(
            "none",
            "no occluder between the light and anything: every shadow volume misses the other meshes "
            "and no mesh can shade itself (each is planar, or convex and never lit from inside)",
        )
    pairs, why_not = _linked_pairs(scene, index, pairs)
    if not pairs:
        return Choice("none", why_not)
    receivers = {b for _, b in pairs}
    casters = {a for a, _ in pairs}
    see_through = _see_through_casters(scene, casters)
    if see_through and embree_available():
        return Choice(
            "ray_traced",
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
                    "shadow_volume",
                    f"{NO_EMBREE}, instead of planar projected shadows (which test points against the "
                    f"casters with it); only the plane of mesh {min(receivers)} receives shadows",
                    predicted_steps=0.0,
                )
            if ok:
                return Choice(
                    "planar",
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
    if pick["method"] == "shadow_map" and pick["predicted_cost"] < exact_cost:
        res, cost = pick["resolution"], pick["predicted_cost"]
        return Choice(
            "shadow_map",
            f"{what}; a {res}² shadow map: every pixel within the light's contribution {worst:.3g} steps "
            f"≤ tolerance {tolerance:g}; texel {span / res:.3g} ≤ half the thinnest caster seen from the "
            f"light ({feature:.3g}); predicted mean {pick['predicted_mean']:.2g} steps, cost {cost:.2f}× "
            f"ray tracing for {frame.receivers} receiver samples"
            + (f" (shadow volumes: {exact_cost:.2f}×)" if exact.method == "shadow_volume" else ""),
            {"resolution": res},
            predicted_steps=worst,
            relative_cost=cost,
        )
    if pick["method"] == "shadow_map":
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
    if choice.method == "none":
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
    if choice.method == "ray_traced":
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
            "shadow_volume",
            f"{what}: {NO_EMBREE}, instead of ray tracing{predicted}",
            predicted_steps=0.0,
            relative_cost=None if costs is None else costs["ratio"],
        )
    if costs is None:
        return Choice(
            "ray_traced", f"{what}: ray-traced shadows are exact", predicted_steps=0.0, relative_cost=1.0
        )
    volume, traced, ratio = costs["shadow_volume"] * 1e3, costs["ray_traced"] * 1e3, costs["ratio"]
    if ratio < 1.0 and worst > tolerance:
        return Choice(
            "ray_traced",
            f"{what}: ray-traced shadows are exact; shadow volumes, predicted faster ({volume:.3g} ms "
            f"against {traced:.3g} ms, {ratio:.2f}×, {where}), may classify a grazing sample differently, "
            f"where a pixel changes by the light's whole contribution, up to {worst:.3g} steps > tolerance "
            f"{tolerance:g}",
            predicted_steps=0.0,
            relative_cost=1.0,
        )
    if ratio < 1.0:
        return Choice(
            "shadow_volume",
            f"{what}: shadow volumes are exact and predicted faster than Embree ray tracing, "
            f"{volume:.3g} ms against {traced:.3g} ms ({ratio:.2f}×) {where}; a sample they classify "
            f"differently changes a pixel by at most {worst:.3g} steps ≤ tolerance {tolerance:g}",
            predicted_steps=worst,
            relative_cost=ratio,
        )
    return Choice(
        "ray_traced",
        f"{what}: ray-traced shadows are exact and predicted faster than shadow volumes, "
        f"{traced:.3g} ms against {volume:.3g} ms ({ratio:.2f}× ray tracing) {where}",
        predicted_steps=0.0,
        relative_cost=1.0,
    )


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
DEFAULT_FRAME = (640, 480, 1)


@dataclass(frozen=True)
class _Frame:
    width: int
    height: int
    samples: int

    @property
    def samples_total(self) -> int:
        """Samples of the frame, ``width·height·samples`` (``samples`` per pixel, a k×k grid, as
        ``render`` takes it): what rasterization, shading and the resolve scale with."""
        return self.width * self.height * self.samples

    @property
    def receivers(self) -> int:
        """Shading samples of the frame, ``width·height·samples`` (the points that need a visibility)."""
        return self.width * self.height * self.samples


def _frame(width: int | None, height: int | None, samples: int) -> _Frame:
    w = DEFAULT_FRAME[0] if width is None else width
    h = DEFAULT_FRAME[1] if height is None else height
    for name, value in (("width", w), ("height", h), ("samples", samples)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return _Frame(int(w), int(h), int(samples))


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
