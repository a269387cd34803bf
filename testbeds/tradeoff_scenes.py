"""Scenes and fragment sets of the speed/accuracy benchmarks that the failure tests reuse.

``benchmarks/tradeoffs.py`` times and measures every method family on these scenes (and
``benchmarks/error_models.py`` fits the calibrated error models to the results);
``tests/failures`` checks the calibrated models on them and on scenes not used to fit them.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

import blinn_phong as bp
from blinn_phong.effects.oit import resolve_transparency, wboit_weights
from blinn_phong.model.primitives import grid_plane, uv_sphere

__all__ = ["layered_scene", "shadow_scene", "transparency_methods", "transparent_fragments", "visible_points"]


def _box(centre: tuple[float, float, float], half: tuple[float, float, float]) -> bp.Mesh:
    c, h = np.asarray(centre), np.asarray(half)
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float) * h + c
    tris = np.array(
        [
            *([0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4]),
            *([2, 6, 7], [2, 7, 3], [1, 3, 7], [1, 7, 5], [0, 4, 6], [0, 6, 2]),
        ]
    )
    return bp.Mesh(corners, tris, material=bp.Material(diffuse=(0.3, 0.3, 0.9)))


def shadow_scene(segments: int = 48) -> bp.Scene:
    """A ground plane (z = 0), a sphere (``segments`` × ``segments/2``) floating over it and a box
    standing on it."""
    gp, gt, gn = grid_plane(1, 1, (8.0, 8.0))
    sp, st, sn = uv_sphere(segments, segments // 2, 0.7)
    lift = np.eye(4)
    lift[:3, 3] = (0.0, 0.0, 1.4)
    meshes = [
        bp.Mesh(gp, gt, gn, material=bp.Material(diffuse=(0.6, 0.6, 0.6))),
        bp.Mesh(sp, st, sn, transform=lift, material=bp.Material(diffuse=(0.8, 0.2, 0.2))),
        _box((1.4, 0.9, 0.6), (0.3, 0.3, 0.6)),
    ]
    camera = bp.Camera.perspective(
        45.0, 1.0, 0.5, 50.0, view=bp.look_at((0.0, -7.0, 4.5), (0.0, 0.0, 0.3), (0, 0, 1))
    )
    return bp.Scene(meshes, [bp.DirectionalLight((0.4, 0.25, -1.0))], camera)


def visible_points(scene: bp.Scene, size: int) -> tuple[np.ndarray, np.ndarray]:
    """World positions and face normals of the nearest surface at every covered pixel."""
    from blinn_phong.geometry.raster import interpolate, rasterize, resolve_nearest

    prepared = bp.prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, size, size)
    win = resolve_nearest(frags)
    vis = frags.subset(win[win >= 0])
    eye = interpolate(vis, prepared.triangles, prepared.eye_position)
    world = (np.c_[eye, np.ones(len(eye))] @ np.linalg.inv(scene.camera.view).T)[:, :3]
    return world, prepared.face_world_normal[vis.triangle]


def layered_scene(layers: int, opacity: float, seed: int = 7) -> bp.Scene:
    """``layers`` transparent quads, alternately tilted ±30° so neighbours interpenetrate, seen from above."""
    rng = np.random.default_rng(seed)
    meshes = []
    for i in range(layers):
        z = 0.25 * i
        tilt = math.radians(30.0 if i % 2 else -30.0)
        half = 1.6
        xs = np.array([-half, half, half, -half])
        ys = np.array([-half, -half, half, half])
        zs = z + np.tan(tilt) * xs * 0.5
        corners = np.stack([xs, ys, zs], axis=1)
        n = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        n /= np.linalg.norm(n)
        colour = tuple(rng.uniform(0.1, 0.9, 3))
        mat = bp.Material(ambient=colour, diffuse=colour, specular=(0, 0, 0), opacity=opacity)
        meshes.append(bp.Mesh(corners, np.array([[0, 1, 2], [0, 2, 3]]), np.tile(n, (4, 1)), material=mat))
    extent = 1.5
    camera = bp.Camera.orthographic(
        -extent, extent, -extent, extent, 0.1, 40.0, view=bp.look_at((0.0, 0.0, 20.0), (0.0, 0.0, 0.0))
    )
    return bp.Scene(meshes, [bp.DirectionalLight((0.2, 0.3, -1.0))], camera, ambient=(0.3, 0.3, 0.3))


def transparent_fragments(scene: bp.Scene, size: int) -> dict:
    """Shaded premultiplied fragments of every (transparent) triangle and what the resolvers need."""
    from blinn_phong.geometry.raster import rasterize

    prepared = bp.prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, size, size)
    shaded = bp.shade_fragments(prepared, frags, shading="flat")
    rgba = np.c_[shaded.rgb * shaded.alpha[:, None], shaded.alpha]
    return {
        "pixel": frags.pixel,
        "depth": frags.depth,
        "rgba": rgba,
        "n_pixels": size * size,
        "triangle": frags.triangle,
        "triangle_mesh": prepared.triangle_mesh,
        "triangle_eye_distance": -prepared.face_eye_centroid[:, 2],
        "front_facing": frags.front_facing,
    }


def transparency_methods(fr: dict, background: np.ndarray, peel: tuple[int, ...]) -> dict[str, Callable]:
    """Resolver calls for every transparency method over the same fragments (``name → callable``)."""
    common = {
        "triangle": fr["triangle"],
        "triangle_mesh": fr["triangle_mesh"],
        "triangle_eye_distance": fr["triangle_eye_distance"],
        "background": background,
        "front_facing": fr["front_facing"],
    }
    args = (fr["pixel"], fr["depth"], fr["rgba"], fr["n_pixels"])
    weights = wboit_weights(fr["rgba"][:, 3], "eq10", window_depth=fr["depth"])
    methods: dict[str, Callable] = {
        "a_buffer": lambda: resolve_transparency("a_buffer", *args, **common),
        "sort_objects": lambda: resolve_transparency("sort_objects", *args, **common),
        "sort_triangles": lambda: resolve_transparency("sort_triangles", *args, **common),
        "weighted_blended": lambda: resolve_transparency(
            "weighted_blended", *args, weights=weights, **common
        ),
    }
    for k in peel:
        methods[f"depth_peeling_{k}"] = lambda k=k: resolve_transparency(
            "depth_peeling", *args, layers=k, **common
        )
    return methods
