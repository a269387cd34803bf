"""Shadow volumes against shadow maps and Embree ray tracing: time against error, frame cost, crossover.

Three measurements, each a ratio between methods timed interleaved in the same run
(:func:`benchmarks._util.time_interleaved`, medians):

* ``same_scenes`` — the scene of the shadows chart (:func:`benchmarks.bench_effects._shadow_scene`:
  two spheres and a box on a ground plane, a directional and a point light): every visible sample
  classified by shadow volumes (z-fail and z-pass, adjacency rebuilt every call — "cold" — or reused
  — "warm"), by shadow maps (1024², 2048², nearest, the renderer's default bias) and by Embree. Error
  is against Embree (exact hard shadows): mean |Δ visibility| and the share of samples that differ.
* ``frame`` — the frame-pipeline scene (two 65,024-triangle spheres over a ground plane, a
  directional and a point light, 1920×1080; ``--quick``: 480×270): ``render`` with
  ``shadows="none"`` (the plain compiled frame), ``"shadow_volume"`` and ``"ray_traced"``, each
  warm (the next frame of an unchanged scene) and cold (adjacency, volumes, near-plane proofs and
  BVH rebuilt: new geometry every frame); frame times, their ratios to the plain frame, and the
  shadow stage alone against the plain frame.
* ``crossover`` — one sphere over a plane under a point light: shadow volumes against Embree as the
  sphere's triangle count and the number of samples grow, both *warm* (each method's per-caster
  cache kept: adjacency, volumes and near-plane proof; the BVH — what the next frame of an
  unchanged scene costs) and *cold* (both caches cleared before every call: adjacency and volume
  building against the BVH build, a new scene); where a ratio crosses 1 is where ray tracing
  starts to win.

Every shadow-volume call here counts its receivers as new ones (the tile binning a frame's
next light reuses is cleared first): a repeated call on the same arrays would otherwise skip
the sort a real next frame, with new sample arrays, pays for. Rounds interleave warm and cold
calls, and a cold call empties the caches: every warm call of ``same_scenes`` and ``frame``
first restores the caches its warm-up left.

Writes ``shadow_volume.json``.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from benchmarks._util import machine_info, save_figure, time_interleaved, write_json
from blinn_phong.frame.render import prepare_scene, render
from blinn_phong.geometry.raster import interpolate, rasterize, resolve_nearest
from blinn_phong.model.lights import DirectionalLight, PointLight
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.model.scene import Camera, Material, Mesh, Scene
from blinn_phong.model.transforms import look_at
from blinn_phong.shadows import volume as sv
from blinn_phong.shadows import volume_counting, volume_mesh
from blinn_phong.shadows.methods import light_visibility

__all__ = ["chart", "crossover", "frame", "run", "same_scenes"]


def _samples(scene: Scene, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    prepared = prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, width, height)
    win = resolve_nearest(frags)
    vis = frags.subset(win[win >= 0])
    eye = interpolate(vis, prepared.triangles, prepared.eye_position)
    world = (np.c_[eye, np.ones(len(eye))] @ np.linalg.inv(scene.camera.view).T)[:, :3]
    return world, prepared.face_world_normal[vis.triangle]


def _new_receivers(fn):
    """``fn`` as the next frame of an unchanged scene calls it: adjacency, volumes and near-plane
    proofs kept, but the receivers are new arrays (no tile binning of earlier calls to reuse)."""

    def call():
        volume_counting._BINNING.clear()
        return fn()

    return call


def _cold(fn):
    def call():
        volume_mesh._TOPOLOGY_CACHE.clear()
        sv._DERIVED_CACHE.clear()
        volume_counting._BINNING.clear()
        return fn()

    return call


def _caches() -> tuple:
    """Every per-caster cache a warm call relies on: topology, volumes and near-plane proofs,
    digests, and Embree's BVH."""
    from blinn_phong.shadows import raytrace

    return volume_mesh._TOPOLOGY_CACHE, sv._DERIVED_CACHE, volume_mesh._DIGESTS, raytrace._SCENE_CACHE


def _snapshot() -> list:
    """The caches as they are now (shallow copies), for :func:`_restored`."""
    return [cache.copy() for cache in _caches()]


def _restored(fn, state: list):
    """``fn`` run with the caches put back to ``state`` first: rounds interleave cold calls,
    which empty the caches, so a warm call restores what its warm-up left (the state of the
    next frame of an unchanged scene)."""

    def call():
        for cache, saved in zip(_caches(), state, strict=True):
            cache.clear()
            cache.update(saved) if isinstance(cache, dict) else cache.extend(saved)
        return fn()

    return call


def _cold_embree(fn):
    from blinn_phong.shadows import raytrace

    def call():
        raytrace._SCENE_CACHE.clear()
        return fn()

    return call


def same_scenes(size: int, repeat: int) -> list[dict]:
    """Time and error of every method on the shadows chart's scene, per light."""
    from benchmarks.bench_effects import _shadow_scene

    scene, tris = _shadow_scene()
    points, normals = _samples(scene, size, size)
    out = []
    for light in (DirectionalLight((0.4, 0.25, -1.0)), PointLight((1.5, -1.0, 5.0))):
        cam = scene.camera

        def volume(method: str, light=light, cam=cam):
            def call() -> np.ndarray:
                args = (light, tris, points, normals)
                return light_visibility("shadow_volume", *args, camera=cam, stencil=method)

            return _new_receivers(call)

        methods = {
            "ray_traced": lambda light=light: light_visibility("ray_traced", light, tris, points, normals),
            "shadow_volume_zfail_cold": _cold(volume("zfail")),
            "shadow_volume_zpass_cold": _cold(volume("zpass")),
        }
        warm = {"shadow_volume_zfail_warm": volume("zfail"), "shadow_volume_auto_warm": volume("auto")}
        for fn in (methods["ray_traced"], *warm.values()):  # the warm-up: BVH, volumes, proof
            fn()
        state = _snapshot()
        methods.update({name: _restored(fn, state) for name, fn in warm.items()})
        for res in (1024, 2048):
            methods[f"shadow_map_{res}"] = lambda light=light, res=res: light_visibility(
                "shadow_map", light, tris, points, normals, resolution=res
            )
        times = time_interleaved(methods, repeat=repeat)
        reference = methods["ray_traced"]()
        ref_time = times["ray_traced"]["median_s"]
        for name, fn in methods.items():
            vis = fn()
            row = {
                "light": type(light).__name__,
                "method": name,
                "samples": len(points),
                "median_s": times[name]["median_s"],
                "ratio_to_embree": times[name]["median_s"] / ref_time,
                "mean_abs_error": float(np.mean(np.abs(vis - reference))),
                "differing_share": float(np.mean(vis != reference)),
            }
            out.append(row)
            print(
                f"same scenes {row['light']:16s} {name:26s} {row['median_s'] * 1e3:8.1f} ms "
                f"×{row['ratio_to_embree']:.2f} Embree  differing {row['differing_share']:.2e}",
                flush=True,
            )
    return out


def _frame_scene(segments: int = 256, rings: int = 128) -> Scene:
    p, t, n = uv_sphere(segments, rings, 1.0)
    mat = Material(ambient=(0.7, 0.7, 0.7), diffuse=(0.7, 0.7, 0.7), specular=(0.3, 0.3, 0.3), shininess=30.0)
    meshes = []
    for cx in (-1.3, 1.3):
        transform = np.eye(4)
        transform[:3, 3] = (cx, 0.0, 1.0)
        meshes.append(Mesh(p, t, normals=n, transform=transform, material=mat))
    gp, gt, gn = grid_plane(1, 1, (12.0, 12.0))
    meshes.append(Mesh(gp, gt, normals=gn, material=mat))
    camera = Camera.perspective(45.0, 16 / 9, 0.5, 50.0, view=look_at((0, -7, 4), (0, 0, 0.7), (0, 0, 1)))
    lights = (DirectionalLight((-0.4, -0.3, -1.0)), PointLight((2.0, -1.0, 5.0)))
    return Scene(tuple(meshes), lights, camera)


def frame(width: int, height: int, repeat: int) -> dict:
    """Frame times with no shadows, shadow volumes and Embree on the two-sphere scene, each method
    warm (the next frame of an unchanged scene: adjacency, volumes and near-plane proofs kept,
    the BVH kept) and cold (new geometry every frame: all of them rebuilt)."""
    scene = _frame_scene()
    stages: dict[str, dict] = {}
    for shadows in ("shadow_volume", "ray_traced"):  # the warm-up: both methods' caches
        render(scene, width, height, shadows=shadows)
    warm = _snapshot()
    empty = [[] if isinstance(cache, list) else {} for cache in _caches()]

    def run_with(name: str, shadows: str, cold: bool):
        def call():
            volume_counting._BINNING.clear()
            stages[name] = render(scene, width, height, shadows=shadows).stats.seconds

        return _restored(call, empty if cold else warm)

    candidates = {
        "none": run_with("none", "none", False),
        "shadow_volume": run_with("shadow_volume", "shadow_volume", False),
        "shadow_volume_cold": run_with("shadow_volume_cold", "shadow_volume", True),
        "ray_traced": run_with("ray_traced", "ray_traced", False),
        "ray_traced_cold": run_with("ray_traced_cold", "ray_traced", True),
    }
    times = time_interleaved(candidates, repeat=repeat)
    plain = times["none"]["median_s"]
    result = {
        "size": [width, height],
        "triangles": int(sum(len(m.triangles) for m in scene.meshes)),
        "frame_median_s": {k: v["median_s"] for k, v in times.items()},
        "frame_ratio_to_plain": {k: v["median_s"] / plain for k, v in times.items()},
        "last_stage_seconds": stages,
        "shadow_stage_ratio_to_plain": {
            k: stages[k].get("shadows", 0.0) / plain for k in candidates if k != "none"
        },
    }
    ratios = {k: round(v, 2) for k, v in result["frame_ratio_to_plain"].items()}
    print(f"frame {width}×{height}, × the plain frame: {ratios}", flush=True)
    stage = {k: round(v, 2) for k, v in result["shadow_stage_ratio_to_plain"].items()}
    print(f"  shadow stage / plain frame: {stage}", flush=True)
    return result


def crossover(repeat: int, quick: bool) -> list[dict]:
    """Shadow volumes against Embree, warm and cold, as triangles and samples grow (one sphere, a plane)."""
    light = PointLight((1.5, -1.0, 5.0))
    camera = Camera.perspective(45.0, 16 / 9, 0.5, 50.0, view=look_at((0, -6, 4), (0, 0, 0.7), (0, 0, 1)))
    segment_list = (16, 64, 256) if quick else (16, 32, 64, 128, 256, 512)
    sizes = ((240, 135), (480, 270)) if quick else ((240, 135), (480, 270), (960, 540))
    out = []
    mat = Material()
    gp, gt, gn = grid_plane(1, 1, (12.0, 12.0))
    for segments in segment_list:
        p, t, n = uv_sphere(segments, max(segments // 2, 2), 1.0)
        transform = np.eye(4)
        transform[:3, 3] = (0.0, 0.0, 1.2)
        scene = Scene(
            (
                Mesh(p, t, normals=n, transform=transform, material=mat),
                Mesh(gp, gt, normals=gn, material=mat),
            ),
            (light,),
            camera,
        )
        tris = np.concatenate([(p + transform[:3, 3])[t], gp[gt]])
        for width, height in sizes:
            points, normals = _samples(scene, width, height)
            args = (light, tris, points, normals)

            def traced(args=args):
                return light_visibility("ray_traced", *args)

            @_new_receivers
            def volume(args=args):
                return light_visibility("shadow_volume", *args, camera=camera)

            methods = {
                "ray_traced": traced,
                "shadow_volume": volume,
                "ray_traced_cold": _cold_embree(traced),
                "shadow_volume_cold": _cold(volume),
            }
            times = time_interleaved(methods, repeat=repeat)
            row = {
                "triangles": len(tris),
                "size": [width, height],
                "samples": len(points),
                **{f"{name}_s": times[name]["median_s"] for name in methods},
            }
            row["ratio"] = row["shadow_volume_s"] / row["ray_traced_s"]
            row["ratio_cold"] = row["shadow_volume_cold_s"] / row["ray_traced_cold_s"]
            out.append(row)
            print(
                f"crossover {len(tris):7d} tris {width}×{height}: volumes/Embree warm {row['ratio']:.2f}, "
                f"cold {row['ratio_cold']:.2f}",
                flush=True,
            )
    return out


def chart(result: dict, path: str | os.PathLike) -> Path:
    """Two panels: time against error on the shared scene; the volumes/Embree ratio against triangles."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for light, marker in (("DirectionalLight", "o"), ("PointLight", "s")):
        rows = [r for r in result["same_scenes"] if r["light"] == light]
        for r in rows:
            err = max(r["differing_share"], 1e-6)  # exact methods drawn at the floor of the axis
            left.scatter(
                r["ratio_to_embree"],
                err,
                marker=marker,
                color="C0" if "volume" in r["method"] else ("C1" if "map" in r["method"] else "C2"),
            )
            left.annotate(r["method"].replace("shadow_", ""), (r["ratio_to_embree"], err), fontsize=6)
    left.set_xscale("log")
    left.set_yscale("log")
    left.set_xlabel("time / Embree ray tracing (same run)")
    left.set_ylabel("share of samples differing from Embree (1e-6 = none)")
    left.set_title("shadows chart scene: volumes, maps, Embree")
    sizes = sorted({tuple(r["size"]) for r in result["crossover"]})
    for size in sizes:
        rows = [r for r in result["crossover"] if tuple(r["size"]) == size]
        line = right.plot(
            [r["triangles"] for r in rows],
            [r["ratio"] for r in rows],
            marker="o",
            label=f"{size[0]}×{size[1]} warm",
        )
        right.plot(
            [r["triangles"] for r in rows],
            [r["ratio_cold"] for r in rows],
            marker="s",
            ls="--",
            color=line[0].get_color(),
            label=f"{size[0]}×{size[1]} cold",
        )
    right.axhline(1.0, color="grey", lw=0.8)
    right.set_xscale("log")
    right.set_xlabel("triangles (one sphere over a plane)")
    right.set_ylabel("shadow volumes / Embree time")
    right.set_title("crossover: below 1, volumes are faster")
    right.legend(fontsize=8)
    fig.tight_layout()
    out = save_figure(fig, path, dpi=110)  # a failed write leaves the previous chart intact
    plt.close(fig)
    return out


def run(out_dir: str | os.PathLike, *, repeat: int = 3, quick: bool = False) -> dict:
    """Run all three measurements, write ``shadow_volume.json`` into ``out_dir`` and return it."""
    sv.shadow_volume_visibility(  # compile the kernel outside the timings
        PointLight((0, 0, 3.0)),
        np.array([[[0, 0, 1.0], [1, 0, 1.0], [0, 1, 1.0]]]),
        np.zeros((1, 3)),
        np.array([[0, 0, 1.0]]),
    )
    result = {
        "benchmark": "shadow_volume",
        "timing": "medians of interleaved rounds, wall clock, same process",
        "repeat": repeat,
        "machine": machine_info(),
        "same_scenes": same_scenes(128 if quick else 256, repeat),
        "frame": frame(480, 270, repeat) if quick else frame(1920, 1080, repeat),
        "crossover": crossover(repeat, quick),
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "shadow_volume.json", result)
    return result


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="benchmarks/results", help="directory for shadow_volume.json")
    parser.add_argument("--repeat", type=int, default=3, help="interleaved rounds per case")
    parser.add_argument("--quick", action="store_true", help="small sizes")
    parser.add_argument("--chart", default=None, help="also draw the chart to this PNG path")
    args = parser.parse_args(argv)
    result = run(args.out, repeat=args.repeat, quick=args.quick)
    if args.chart:
        print(f"chart {chart(result, args.chart)}")


if __name__ == "__main__":
    main()
