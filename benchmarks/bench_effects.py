"""Transparency and shadow methods: time and error against the exact reference, in the same run.

Transparency: the transparent fragments of a scene of interpenetrating transparent spheres
(rasterized at ``--size``², depth complexity up to about 10) are resolved by every method of
:mod:`blinn_phong.effects.oit`. The reference is the A-buffer; each method reports its time, the
ratio of its time to the A-buffer's, and its error against it (mean and max absolute
difference of premultiplied RGBA, and the share of pixels more than one 8-bit step off).

Shadows: the visible points of a scene of spheres and a box on a ground plane, lit by a
directional and a point light. The reference is Embree ray tracing (exact hard shadows);
shadow maps at several resolutions and PCF kernels and planar projected shadows report their
time, ratio to the ray tracer and error (share of points classified differently, mean
absolute visibility difference). Soft shadows from an area light with m×m stratified samples
are compared with a 16×16-sample reference.

Usage::

    .venv/bin/python -m benchmarks.bench_effects [--out benchmarks/results] [--repeat 3] [--size 256]

Writes ``effects.json`` to ``--out``. The whole frame with each effect against the plain frame
(``frame.json``) is :mod:`benchmarks.bench_frame` (``python -m benchmarks --only frame``).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from blinn_phong.effects.oit import (
    depth_test,
    resolve_a_buffer,
    resolve_depth_peeling,
    resolve_transparency,
    resolve_weighted_blended,
    wboit_weights,
)
from blinn_phong.frame.render import prepare_scene, shade_fragments
from blinn_phong.geometry.raster import interpolate, rasterize, resolve_nearest
from blinn_phong.model.lights import DirectionalLight, PointLight
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.model.scene import Camera, Material, Mesh, Scene
from blinn_phong.model.transforms import look_at
from blinn_phong.shadows.maps import light_shadow_maps, shadow_map_visibility
from blinn_phong.shadows.planar import planar_shadow_mask
from blinn_phong.shadows.raytrace import (
    RayScene,
    area_light_visibility,
    directional_light_visibility,
    point_light_visibility,
)
from compositing._atomic import write_json_atomic

__all__ = ["main", "run"]


def _best_time(fn: Callable[[], object], repeat: int) -> tuple[float, object]:
    result = fn()  # warm-up
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def _sphere_mesh(centre, radius, colour, opacity, segments=32, rings=16) -> Mesh:
    p, t, n = uv_sphere(segments, rings, radius)
    tr = np.eye(4)
    tr[:3, 3] = centre
    mat = Material(ambient=colour, diffuse=colour, specular=(0.4, 0.4, 0.4), shininess=30.0, opacity=opacity)
    return Mesh(p, t, normals=n, transform=tr, material=mat)


def _ground(z: float, half: float) -> Mesh:
    p, t, n = grid_plane(1, 1, (2 * half, 2 * half))
    tr = np.eye(4)
    tr[2, 3] = z
    return Mesh(p, t, normals=n, transform=tr, material=Material(diffuse=(0.6, 0.6, 0.6)))


def _camera() -> Camera:
    return Camera.perspective(
        45.0, 1.0, 0.5, 50.0, view=look_at((0.0, -7.0, 4.5), (0.0, 0.0, 0.3), (0, 0, 1))
    )


def transparency_cases(size: int, repeat: int) -> list[dict]:
    """Every transparency resolve on six translucent spheres at ``size``² pixels, best of ``repeat``.

    Each row: the method, its seconds, the time ratio to the A-buffer (the exact reference,
    every fragment sorted by depth) and its error against it (linear premultiplied RGBA).
    """
    rng = np.random.default_rng(3)
    meshes = [_ground(-1.2, 4.0)]
    for _ in range(6):
        centre = rng.uniform([-1.2, -1.2, -0.5], [1.2, 1.2, 1.0])
        meshes.append(_sphere_mesh(centre, rng.uniform(0.6, 1.0), tuple(rng.uniform(0.1, 1.0, 3)), 0.45))
    scene = Scene(tuple(meshes), (DirectionalLight((0.3, 0.4, -1.0)),), _camera())
    prepared = prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, size, size)
    shaded = shade_fragments(prepared, frags, shading="phong")
    a = shaded.alpha
    rgba = np.c_[shaded.rgb * a[:, None], a]
    n_pix = size * size
    opaque = a >= 1
    op = frags.subset(opaque)
    win = resolve_nearest(op)
    background = np.zeros((n_pix, 4))
    depth = np.ones(n_pix)
    hit = win >= 0
    background[hit] = rgba[opaque][win[hit]]
    depth[hit] = op.depth[win[hit]]
    t = np.flatnonzero(~opaque)
    idx = t[depth_test(frags.pixel[t], frags.depth[t], depth)]
    pix, dep, col, tri = frags.pixel[idx], frags.depth[idx], rgba[idx], frags.triangle[idx]
    eye_dist = -interpolate(frags.subset(idx), prepared.triangles, prepared.eye_position)[:, 2]
    complexity = np.bincount(pix, minlength=n_pix)
    common = {
        "front_facing": frags.front_facing[idx],
        "triangle": tri,
        "triangle_mesh": prepared.triangle_mesh,
        "triangle_eye_distance": -prepared.face_eye_centroid[:, 2],
        "background": background,
    }
    t_ref, reference = _best_time(lambda: resolve_a_buffer(pix, dep, col, n_pix, background), repeat)
    methods: dict[str, Callable[[], np.ndarray]] = {
        "a_buffer": lambda: reference,
        "sort_objects": lambda: resolve_transparency("sort_objects", pix, dep, col, n_pix, **common),
        "sort_triangles": lambda: resolve_transparency("sort_triangles", pix, dep, col, n_pix, **common),
    }
    for k in (1, 2, 4, 8):
        methods[f"depth_peeling_{k}"] = lambda k=k: resolve_depth_peeling(pix, dep, col, n_pix, k, background)
    for eq in ("constant", "eq7", "eq8", "eq9", "eq10"):
        w = wboit_weights(col[:, 3], eq, view_distance=eye_dist, window_depth=dep)
        methods[f"weighted_blended_{eq}"] = lambda w=w: resolve_weighted_blended(
            pix, w, col, n_pix, background
        )
    cases = []
    for name, fn in methods.items():
        seconds, image = (t_ref, reference) if name == "a_buffer" else _best_time(fn, repeat)
        diff = np.abs(np.asarray(image) - reference)
        case = {
            "method": name,
            "seconds": seconds,
            "ratio_to_a_buffer": seconds / t_ref,
            "mean_abs_error": float(diff.mean()),
            "max_abs_error": float(diff.max()),
            "share_pixels_off_by_more_than_1_of_255": float(np.mean(diff.max(axis=1) > 1 / 255)),
        }
        cases.append(case)
        print(
            f"transparency {name:28s} {seconds * 1e3:8.1f} ms  x{case['ratio_to_a_buffer']:5.2f}  "
            f"mean {case['mean_abs_error']:.2e}  max {case['max_abs_error']:.3f}"
        )
    return [
        {
            "scene": "6 interpenetrating transparent spheres (opacity 0.45) over an opaque ground",
            "size": [size, size],
            "transparent_fragments": len(idx),
            "max_depth_complexity": int(complexity.max()),
            "mean_depth_complexity_covered": float(complexity[complexity > 0].mean()),
            "reference": "a_buffer",
            "cases": cases,
        }
    ]


def _shadow_scene() -> tuple[Scene, np.ndarray]:
    meshes = [
        _ground(0.0, 4.0),
        _sphere_mesh((0.0, 0.0, 1.5), 0.7, (0.8, 0.2, 0.2), 1.0),
        _sphere_mesh((-0.8, -0.6, 0.4), 0.4, (0.2, 0.8, 0.2), 1.0),
    ]
    corners = [[x, y, z] for z in (0, 1.2) for y in (-0.3, 0.3) for x in (-0.3, 0.3)]
    box_p = np.array(corners) + np.array([1.3, 0.8, 0.0])
    box_t = np.array(
        [
            [0, 2, 3],
            [0, 3, 1],
            [4, 5, 7],
            [4, 7, 6],
            [0, 1, 5],
            [0, 5, 4],
            [2, 6, 7],
            [2, 7, 3],
            [1, 3, 7],
            [1, 7, 5],
            [0, 4, 6],
            [0, 6, 2],
        ]
    )
    meshes.append(Mesh(box_p, box_t, material=Material(diffuse=(0.3, 0.3, 0.9))))
    scene = Scene(tuple(meshes), (), _camera())
    world = []
    for m in meshes:
        w = (np.c_[m.positions, np.ones(len(m.positions))] @ m.transform.T)[:, :3]
        world.append(w[m.triangles])
    return scene, np.concatenate(world)


def shadow_cases(size: int, repeat: int) -> list[dict]:
    """Every shadow method on one scene at ``size``² pixels, best of ``repeat``.

    Hard shadows are compared with Embree ray casting (visibility 0/1 per pixel), soft ones
    with a 16×16 stratified reference at the same points; rows give seconds, the time ratio
    to the reference and the mismatch share / mean absolute error.
    """
    scene, tris = _shadow_scene()
    prepared = prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, size, size)
    win = resolve_nearest(frags)
    vis_frags = frags.subset(win[win >= 0])
    eye = interpolate(vis_frags, prepared.triangles, prepared.eye_position)
    points = (np.c_[eye, np.ones(len(eye))] @ np.linalg.inv(scene.camera.view).T)[:, :3]
    normals = prepared.face_world_normal[vis_frags.triangle]
    casters = tris[len(scene.meshes[0].triangles) :]  # everything but the ground
    out = []
    for light in (DirectionalLight((0.4, 0.25, -1.0)), PointLight((1.5, -1.0, 5.0))):
        if isinstance(light, DirectionalLight):
            to_light = np.broadcast_to(-np.asarray(light.direction), points.shape)
        else:
            to_light = np.asarray(light.position) - points
        facing = np.einsum("ij,ij->i", normals, to_light) > 0
        p, n = points[facing], normals[facing]

        def ray_traced(light=light, p=p, n=n):
            rs = RayScene(tris)
            if isinstance(light, DirectionalLight):
                return directional_light_visibility(rs, p, n, -np.asarray(light.direction))
            return point_light_visibility(rs, p, n, light.position)

        t_ref, reference = _best_time(ray_traced, repeat)
        cases = [
            {
                "method": "ray_traced",
                "seconds": t_ref,
                "ratio_to_ray_traced": 1.0,
                "mismatch_share": 0.0,
                "mean_abs_error": 0.0,
            }
        ]
        methods: dict[str, Callable[[], np.ndarray]] = {}
        for res in (256, 512, 1024, 2048):
            for kernel in ("nearest", "bilinear", "box3"):
                slope = {"nearest": 2.0, "bilinear": 3.0, "box3": 3.0}[kernel]

                def sm(light=light, res=res, kernel=kernel, slope=slope, p=p, n=n):
                    maps = light_shadow_maps(light, tris, res, constant_bias=1e-4, slope_bias=slope)
                    return shadow_map_visibility(light, maps, p, n, kernel=kernel)

                methods[f"shadow_map_{res}_{kernel}"] = sm
        hl = (
            np.r_[-np.asarray(light.direction), 0.0]
            if isinstance(light, DirectionalLight)
            else np.r_[light.position, 1.0]
        )

        def planar(p=p, hl=hl, casters=casters):
            vis = np.ones(len(p))
            on = np.abs(p[:, 2]) < 1e-6
            vis[on] = planar_shadow_mask(casters, (0, 0, 1, 0), hl, p[on])
            return vis

        methods["planar"] = planar
        for name, fn in methods.items():
            seconds, vis = _best_time(fn, repeat)
            vis = np.asarray(vis)
            case = {
                "method": name,
                "seconds": seconds,
                "ratio_to_ray_traced": seconds / t_ref,
                "mismatch_share": float(np.mean(np.abs(vis - reference) > 0.5)),
                "mean_abs_error": float(np.mean(np.abs(vis - reference))),
            }
            cases.append(case)
            print(
                f"shadows {type(light).__name__:16s} {name:26s} {seconds * 1e3:8.1f} ms  "
                f"x{case['ratio_to_ray_traced']:6.2f}  mismatch {case['mismatch_share']:.2e}"
            )
        out.append(
            {
                "scene": "two spheres and a box on a ground plane; visible points facing the light",
                "light": type(light).__name__,
                "size": [size, size],
                "points": len(p),
                "shadowed_share": float(1 - reference.mean()),
                "reference": "ray_traced (Embree)",
                "cases": cases,
            }
        )
    # soft shadows: stratified samples against a 16×16 reference, same points
    p, n = points, normals
    corner, eu, ev = (0.5, -0.5, 5.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)
    rs = RayScene(tris)
    t_ref, reference = _best_time(
        lambda: area_light_visibility(rs, p, n, corner, eu, ev, samples_per_axis=16, seed=99), 1
    )
    soft = []
    for m in (1, 2, 4, 8):
        seconds, vis = _best_time(
            lambda m=m: area_light_visibility(rs, p, n, corner, eu, ev, samples_per_axis=m, seed=1), repeat
        )
        soft.append(
            {
                "samples_per_axis": m,
                "seconds": seconds,
                "ratio_to_reference": seconds / t_ref,
                "mean_abs_error": float(np.mean(np.abs(np.asarray(vis) - reference))),
            }
        )
        print(f"soft shadows {m}x{m}: {seconds * 1e3:8.1f} ms  mean error {soft[-1]['mean_abs_error']:.3e}")
    out.append(
        {
            "scene": "same scene, 1×1 area light at height 5",
            "reference": "16×16 stratified samples",
            "reference_seconds": t_ref,
            "cases": soft,
        }
    )
    return out


def run(out_dir: str | os.PathLike, *, repeat: int = 3, size: int = 256) -> dict:
    """Run the benchmark, write ``effects.json`` into ``out_dir`` and return its content."""
    result = {
        "benchmark": "effects",
        "timing": "best of repeat, wall clock, same process and run for a method and its reference",
        "repeat": repeat,
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor(),
            "cpus": os.cpu_count(),
        },
        "numpy": np.__version__,
        "transparency": transparency_cases(size, repeat),
        "shadows": shadow_cases(size, repeat),
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "effects.json", result, indent=2)
    return result


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="benchmarks/results", help="directory for effects.json")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per case (best is kept)")
    parser.add_argument("--size", type=int, default=256, help="image size in pixels (square)")
    args = parser.parse_args(argv)
    run(args.out, repeat=args.repeat, size=args.size)


if __name__ == "__main__":
    main()
