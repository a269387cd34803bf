"""Random small scenes for checking the planner's promise, and the check itself.

:func:`random_scene` builds a seeded scene from a small vocabulary — open and closed boxes,
UV spheres, slabs, panes and thin slats — with random transforms (rotation, positive scale,
translation), materials (opaque or transparent by partial occlusion or absorption,
Kay–Greenberg, back materials under two-sided lighting) and lights (directional, point and
spot lights with attenuation ``k_c`` down to 0.01, ambient). :func:`check` renders it twice —
following ``plan(scene, T)`` and with the exact methods forced (A-buffer, ray-traced shadows
for every light, per-pixel shading) — and measures the per-pixel error in 8-bit steps, the
metric of docs/speed_accuracy.md ("What the tolerance promises"): the largest channel
difference of each pixel, its maximum over the image.

**The terminator rule.** The one place where two exact methods disagree by construction is
the polygon terminator: a triangle whose face turns away from a light while one of its vertex
normals faces it is lit by the shading normal (``n ⊙ l > 0``) yet shadowed by its own facets
for a ray tracer. The plan treats the smooth surface as exact ("no self-shadow that ``N·L``
does not give" for a convex mesh), the ray tracer the facets. Pixels with a fragment of such a
triangle (for any light) are left out of the comparison and counted (``terminator_pixels``).

**The silhouette-tie rule.** Where a closed mesh folds over (its silhouette), a sample can be
covered by a front- and a back-facing fragment of the same mesh at depths equal to the last
digits; which one is nearer is then undefined, and the A-buffer's sort and back-then-front
drawing may order them differently (one pixel in 40 000 of the sweep, up to 2.4 steps).
Pixels with such a pair within 10⁻⁵ in window depth are left out and counted
(``silhouette_tie_pixels``).

Shared by the planner tests and ``benchmarks/planner_fuzz.py`` (the sweep over many seeds).
"""

from __future__ import annotations

import math

import numpy as np

import blinn_phong as bp
from blinn_phong.frame.render import prepare_scene
from blinn_phong.geometry.raster import rasterize
from blinn_phong.model.primitives import uv_sphere

__all__ = [
    "TOLERANCES",
    "check",
    "faceted_box",
    "planned_render",
    "random_scene",
    "silhouette_tie_mask",
    "terminator_mask",
]

#: Tolerances (8-bit steps) every scene is planned and checked at.
TOLERANCES = (0.0, 2.0, 8.0, 32.0)


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def faceted_box(half: np.ndarray, lid: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A box centred at the origin with 4 vertices and one normal per face (planar faces, outward
    counter-clockwise winding); without ``lid`` the +z face is left out (an open box)."""
    positions, triangles, normals = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            if not lid and axis == 2 and sign > 0:
                continue
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v = np.cross(n, u)
            base = len(positions)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                positions.append((n + a * u + b * v) * half)
                normals.append(n)
            triangles += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.array(positions), np.array(triangles), np.array(normals)


def _material(rng: np.random.Generator, transparent: bool) -> bp.Material:
    colour = tuple(float(v) for v in rng.uniform(0.2, 0.9, 3))
    kw: dict[str, object] = {
        "ambient": colour,
        "diffuse": colour,
        "specular": (float(rng.uniform(0.0, 0.5)),) * 3,
        "shininess": float(rng.uniform(5.0, 60.0)),
    }
    if rng.random() < 0.15:
        kw["emission"] = tuple(float(v) for v in rng.uniform(0.0, 0.3, 3))
    if transparent:
        kind = rng.choice(["partial", "absorption", "kay_greenberg"])
        kw["opacity"] = float(rng.uniform(0.3, 0.85))
        if kind == "absorption":
            kw["transparency_model"] = "absorption"
        elif kind == "kay_greenberg":
            kw["opacity"] = 1.0
            t_max = float(rng.uniform(0.3, 0.8))
            kw["kay_greenberg"] = (float(rng.uniform(0.0, t_max)), t_max, float(rng.uniform(1.0, 4.0)))
    return bp.Material(**kw)  # type: ignore[arg-type]


def _mesh(rng: np.random.Generator, kind: str, two_sided: bool) -> bp.Mesh:
    if kind in ("open_box", "closed_box"):
        positions, triangles, normals = faceted_box(rng.uniform(0.3, 0.8, 3), lid=kind == "closed_box")
    elif kind == "slab":
        positions, triangles, normals = faceted_box(
            np.array([rng.uniform(0.6, 1.2), rng.uniform(0.6, 1.2), 0.05])
        )
    elif kind == "slat":
        positions, triangles, normals = faceted_box(np.array([1.5, 0.03, 0.02]))
    elif kind == "pane":
        half = rng.uniform(0.5, 1.2, 2)
        positions = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float) * [*half, 1]
        triangles = np.array([[0, 1, 2], [0, 2, 3]])
        normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    else:  # sphere
        segments = int(rng.integers(10, 20))
        positions, triangles, normals = uv_sphere(segments, segments // 2, float(rng.uniform(0.3, 0.7)))
    transform = np.eye(4)
    transform[:3, :3] = _rotation(rng) * rng.uniform(0.7, 1.3)
    transform[:3, 3] = [rng.uniform(-1.2, 1.2), rng.uniform(-1.2, 1.2), rng.uniform(0.2, 1.6)]
    transparent = kind in ("pane", "sphere", "closed_box") and rng.random() < 0.45
    back = _material(rng, transparent) if two_sided and rng.random() < 0.5 else None
    return bp.Mesh(
        positions,
        triangles,
        normals,
        transform=transform,
        material=_material(rng, transparent),
        back_material=back,
    )


def _light(rng: np.random.Generator) -> object:
    intensity = float(rng.choice([1.0, 0.5, 0.1, 0.04]))
    kind = rng.choice(["directional", "point", "spot"], p=[0.5, 0.3, 0.2])
    if kind == "directional":
        d = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), -1.0])
        return bp.DirectionalLight(tuple(d), intensity=intensity)
    position = (float(rng.uniform(-2, 2)), float(rng.uniform(-2, 2)), float(rng.uniform(2.8, 4.0)))
    att = {
        "constant": float(rng.choice([1.0, 0.3, 0.01])),
        "linear": float(rng.choice([0.0, 0.2])),
        "quadratic": float(rng.choice([0.0, 0.3, 1.0])),
    }
    if kind == "point":
        return bp.PointLight(position, intensity=intensity, **att)
    aim = -np.asarray(position) + rng.uniform(-0.5, 0.5, 3)
    return bp.SpotLight(
        position, tuple(aim), float(rng.uniform(20, 60)), float(rng.uniform(0, 8)), intensity=intensity, **att
    )


def random_scene(seed: int) -> bp.Scene:
    """A seeded random scene: a floor, 1–4 meshes of the vocabulary, 1–2 lights, a perspective camera."""
    rng = np.random.default_rng(seed)
    two_sided = bool(rng.random() < 0.5)
    floor = bp.Mesh(*faceted_box(np.array([3.0, 3.0, 0.05])), material=bp.Material(diffuse=(0.6, 0.6, 0.6)))
    kinds = ["open_box", "closed_box", "sphere", "slab", "pane", "slat"]
    meshes = [floor] if rng.random() < 0.8 else []
    meshes += [_mesh(rng, str(rng.choice(kinds)), two_sided) for _ in range(int(rng.integers(1, 5)))]
    lights = [_light(rng) for _ in range(int(rng.integers(1, 3)))]
    if rng.random() < 0.5:
        lights.append(bp.AmbientLight((1.0, 1.0, 1.0), 0.2))
    angle = rng.uniform(0, 2 * math.pi)
    eye = (7.0 * math.cos(angle), 7.0 * math.sin(angle), float(rng.uniform(3.0, 6.0)))
    camera = bp.Camera.perspective(45.0, 1.0, 0.5, 40.0, view=bp.look_at(eye, (0.0, 0.0, 0.6), (0, 0, 1)))
    model = bp.LightModel(two_sided=two_sided, local_viewer=bool(rng.random() < 0.7))
    return bp.Scene(meshes, lights, camera, ambient=(0.1, 0.1, 0.1), light_model=model)


def terminator_mask(scene: bp.Scene, size: int) -> np.ndarray:
    """(size, size) pixels holding a fragment of a terminator triangle (see the module docstring).

    A triangle is a terminator one for a light when its face normal and one of its vertex
    normals (world space) lie on different sides of the light's direction at that vertex.
    """
    prepared = prepare_scene(scene)
    tris = prepared.triangles
    world = np.zeros((len(prepared.clip), 3))
    for i, mesh in enumerate(scene.meshes):
        lo, hi = prepared.vertex_offset[i], prepared.vertex_offset[i + 1]
        world[lo:hi] = mesh.positions @ mesh.transform[:3, :3].T + mesh.transform[:3, 3]
    face = prepared.face_world_normal
    flagged = np.zeros(len(tris), dtype=bool)
    for light in scene.lights:
        if isinstance(light, bp.AmbientLight):
            continue
        for k in range(3):
            p = world[tris[:, k]]
            if isinstance(light, bp.DirectionalLight):
                to_light = np.broadcast_to(-np.asarray(light.direction), p.shape)
            else:
                to_light = np.asarray(light.position) - p
            f_side = np.einsum("ij,ij->i", face, to_light) > 0
            v_side = np.einsum("ij,ij->i", prepared.world_normal[tris[:, k]], to_light) > 0
            flagged |= f_side != v_side
    frags = rasterize(prepared.clip, tris, size, size)
    mask = np.zeros(size * size, dtype=bool)
    mask[frags.pixel[flagged[frags.triangle]]] = True
    return mask.reshape(size, size)


def silhouette_tie_mask(scene: bp.Scene, size: int, rel_depth: float = 1e-5) -> np.ndarray:
    """(size, size) pixels where a front- and a back-facing fragment of one mesh lie within
    ``rel_depth`` (window depth) of each other: on a silhouette, where the surface folds over,
    interpolated depths of the two sides cross in the last digits and their order — which the
    A-buffer sorts and back-then-front drawing fixes — is undefined (see the module docstring)."""
    prepared = prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, size, size)
    mesh = prepared.triangle_mesh[frags.triangle]
    order = np.lexsort((frags.depth, mesh, frags.sample_key))
    key, m = frags.sample_key[order], mesh[order]
    depth, front = frags.depth[order], frags.front_facing[order]
    tie = (
        (key[1:] == key[:-1])
        & (m[1:] == m[:-1])
        & (front[1:] != front[:-1])
        & (np.abs(depth[1:] - depth[:-1]) <= rel_depth)
    )
    mask = np.zeros(size * size, dtype=bool)
    mask[frags.pixel[order[1:][tie]]] = True
    return mask.reshape(size, size)


def planned_render(
    scene: bp.Scene, tolerance: float, size: int, plan_frame: tuple[int, int] | None
) -> object:
    """``render(scene, size, size, tolerance=tolerance)``, or — with ``plan_frame`` ``(width, height)``
    — the plan ``plan(scene, tolerance, width=, height=)`` makes for that frame, rendered at
    ``size²`` with every choice passed to ``render`` (transparency and its layers, each light's
    method and parameters, each mesh's shading). The promise does not depend on the frame; the
    cost models do, and at a few hundred pixels they find no approximation worth its error."""
    if plan_frame is None:
        return bp.render(scene, size, size, tolerance=tolerance, shading="auto")
    from blinn_phong.planning.frame_plan import scene_with_planned_shading

    p = bp.plan(scene, tolerance, width=plan_frame[0], height=plan_frame[1])
    shadows = [
        bp.ShadowOptions(c.method, resolution=c.params.get("resolution"), plane=c.params.get("plane"))
        for c in p.shadows
    ]
    return bp.render(
        scene_with_planned_shading(scene, p, "auto"),
        size,
        size,
        tolerance=tolerance,
        transparency=p.transparency.method,
        layers=p.transparency.params.get("layers"),
        shadows=shadows,
        shading="auto",
    )


def check(
    scene: bp.Scene,
    tolerance: float,
    size: int = 40,
    exact: np.ndarray | None = None,
    plan_frame: tuple[int, int] | None = (640, 480),
) -> dict:
    """Render ``scene`` following the plan at ``tolerance`` and with exact methods; measure.

    The plan is made for ``plan_frame`` (default 640×480, :data:`blinn_phong.planning.planner.DEFAULT_FRAME`;
    None: the rendered frame) and rendered at ``size²`` (:func:`planned_render`).

    Returns a dict: ``max_steps`` (the largest per-pixel error outside terminator and
    silhouette-tie pixels), ``terminator_pixels``, ``silhouette_tie_pixels``, ``exceeded``
    (``max_steps`` above 1 at tolerance 0, above the tolerance otherwise), the plan's methods,
    and ``exact`` (the exact image, to reuse).
    """
    if exact is None:
        exact = bp.render(
            scene, size, size, transparency="a_buffer", shadows="ray_traced", shading="phong"
        ).rgba
    planned = planned_render(scene, tolerance, size, plan_frame)
    diff = 255.0 * np.abs(planned.rgba.astype(np.float64) - exact.astype(np.float64)).max(axis=-1)
    term = terminator_mask(scene, size)
    ties = silhouette_tie_mask(scene, size)
    worst = float(diff[~(term | ties)].max(initial=0.0))
    limit = 1.0 if tolerance == 0 else tolerance
    p = planned.plan
    return {
        "tolerance": tolerance,
        "max_steps": worst,
        "terminator_pixels": int(term.sum()),
        "silhouette_tie_pixels": int(ties.sum()),
        "exceeded": worst > limit,
        "transparency": p.transparency.method,
        "shadows": [c.method for c in p.shadows],
        "shading": sorted({c.method for c in p.shading}),
        "predicted_steps": [
            c.predicted_steps for c in (p.transparency, *p.shadows) if c.predicted_steps is not None
        ],
        "exact": exact,
    }
