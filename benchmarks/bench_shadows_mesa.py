"""Shadow-mapped frames against Mesa llvmpipe doing the same two passes, in the same run.

Scene: two UV spheres of 65,536 triangles each over a ground plane, a directional and a point
light (one 1024² map and a cube of six), 1920×1080, per-pixel Blinn-Phong. Rendered by

* ``blinn_phong.frame.render(shadows=ShadowOptions("shadow_map", ...))`` — our shadow-mapped frame
  (constant bias 1e-4, slope bias 2, nearest PCF);
* ``oracles.gl_shadows.render_shadow_mapped`` — Mesa llvmpipe: depth passes with
  ``glPolygonOffset`` into a depth texture array, GLSL look-up with the same bias, kernel and
  map resolution (time per frame after a warm-up, geometry already uploaded);
* ``blinn_phong.frame.render(shadows="none")`` and ``shadows="ray_traced"`` — the plain frame and
  Embree hard shadows, for the ratios to the plain frame;
* ``oracles.gl_lighting.render_glsl_phong`` — Mesa's plain frame, for reference.

Runs are interleaved round-robin so machine load hits all alike; medians of wall time and of
process CPU time (all threads; llvmpipe's run in this process) are compared. The ``shadows``
stage time of our frames is reported separately (the light-visibility work this benchmark is
about). The light-visibility work alone (``light_visibility`` for both lights on every visible
sample of the frame) is timed as well, so that "plain frame + shadow work" can be set
against the plain frame and against Mesa whatever the rest of the effects pipeline costs.
The two shadow-mapped images are compared after UNORM8 rounding on covered pixels
away from shadow edges (3×3 neighbourhood of constant visibility).

Usage::

    .venv/bin/python -m benchmarks.bench_shadows_mesa [--out benchmarks/results] [--repeat 3] [--quick]

Writes ``shadows_mesa.json`` to ``--out``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from benchmarks._util import machine_info, markdown_table, write_json
from oracles.gl_common import to_unorm8
from testbeds.shadow_scenes import away_from_shadow_edges, two_spheres_over_ground

__all__ = ["main", "run"]

RESOLUTION = 1024
CONSTANT_BIAS = 1e-4
SLOPE_BIAS = 2.0
KERNEL = "nearest"


def _agreement(ours_rgba: np.ndarray, theirs_rgba: np.ndarray, shadow: np.ndarray) -> dict[str, float]:
    mine = to_unorm8(ours_rgba)
    gl = theirs_rgba.astype(np.int64)
    covered = (mine[..., 3] > 0) & (gl[..., 3] > 0)
    interior = covered & away_from_shadow_edges(shadow)
    diff = np.abs(mine[..., :3] - gl[..., :3]).max(axis=-1)
    return {
        "interior_pixels": int(interior.sum()),
        "covered_pixels": int(covered.sum()),
        "max_diff_8bit_interior": int(diff[interior].max()) if interior.any() else 0,
        "share_over_1_step_interior": float(np.mean(diff[interior] > 1)) if interior.any() else 0.0,
        "share_over_1_step_all_covered": float(np.mean(diff[covered] > 1)) if covered.any() else 0.0,
    }


def run(repeat: int = 3, quick: bool = False) -> dict[str, object]:
    """Run the comparison; returns the JSON-ready results."""
    import blinn_phong as bp
    from oracles.egl import EGLUnavailable, gl_context

    width, height = (640, 360) if quick else (1920, 1080)
    scene = two_spheres_over_ground(64 if quick else 256, width / height)
    n_tris = sum(len(m.triangles) for m in scene.meshes)
    try:
        info = gl_context()
        from oracles import gl_lighting, gl_shadows
    except EGLUnavailable as exc:
        print(f"Mesa unavailable, no peer ratio: {exc}")
        gl_shadows = gl_lighting = None
        info = None
    shadow_map = bp.ShadowOptions(
        "shadow_map", resolution=RESOLUTION, constant_bias=CONSTANT_BIAS, slope_bias=SLOPE_BIAS, kernel=KERNEL
    )

    def ours(shadows: object) -> tuple[float, float, dict[str, float], object]:
        start, cpu = time.perf_counter(), time.process_time()
        result = bp.render(scene, width, height, shading="phong", shadows=shadows, transparency="zbuffer")
        return time.perf_counter() - start, time.process_time() - cpu, dict(result.stats.seconds), result

    # The light-visibility work alone (both lights, every visible sample of the frame), as the
    # frame's shadows stage calls it: light_visibility on world points and face normals.
    from blinn_phong.frame.prepared import prepare_scene
    from blinn_phong.frame.visibility import visible_fragments
    from blinn_phong.geometry.raster import interpolate
    from blinn_phong.shadows.methods import light_visibility
    from blinn_phong.shadows.raytrace import world_triangles

    prepared = prepare_scene(scene)
    frags = visible_fragments(prepared.clip, prepared.triangles, width, height, engine="auto")
    eye = interpolate(frags, prepared.triangles, prepared.eye_position)
    points = (np.c_[eye, np.ones(len(eye))] @ np.linalg.inv(scene.camera.view).T)[:, :3]
    normals = prepared.face_world_normal[frags.triangle]
    tris, _ = world_triangles(scene)
    map_params = {
        "resolution": RESOLUTION,
        "constant_bias": CONSTANT_BIAS,
        "slope_bias": SLOPE_BIAS,
        "kernel": KERNEL,
    }

    def work(method: str, params: dict[str, object]) -> tuple[float, float, dict[str, float], object]:
        start, cpu = time.perf_counter(), time.process_time()
        for light in scene.lights:
            light_visibility(method, light, tris, points, normals, **params)  # type: ignore[arg-type]
        return time.perf_counter() - start, time.process_time() - cpu, {}, None

    cases = {
        "shadow_map_work": lambda: work("shadow_map", map_params),
        "ray_traced_work": lambda: work("ray_traced", {}),
        "ours_plain": lambda: ours("none"),
        "ours_shadow_map": lambda: ours(shadow_map),
        "ours_ray_traced": lambda: ours("ray_traced"),
    }
    if gl_shadows is not None:

        def mesa_shadow_map():
            r = gl_shadows.render_shadow_mapped(
                scene, width, height, resolution=RESOLUTION, constant_bias=CONSTANT_BIAS,
                slope_bias=SLOPE_BIAS, kernel=KERNEL,
            )  # fmt: skip
            return r.seconds, r.cpu_seconds, {}, r

        def mesa_plain():
            r = gl_lighting.render_glsl_phong(scene, width, height)
            return r.seconds, r.cpu_seconds, {}, r

        cases["mesa_shadow_map"] = mesa_shadow_map
        cases["mesa_plain"] = mesa_plain

    last: dict[str, object] = {}
    for name, fn in cases.items():  # untimed warm-up: numba compilation or cache load, page faults
        last[name] = fn()[3]
    wall: dict[str, list[float]] = {k: [] for k in cases}
    cpu: dict[str, list[float]] = {k: [] for k in cases}
    stages: dict[str, list[dict[str, float]]] = {k: [] for k in cases}
    for _ in range(repeat):
        for name, fn in cases.items():
            w, c, st, res = fn()
            wall[name].append(w)
            cpu[name].append(c)
            stages[name].append(st)
            last[name] = res
    med = {k: statistics.median(v) for k, v in wall.items()}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items()}
    shadow_stage = {
        k: statistics.median(s.get("shadows", 0.0) for s in stages[k])
        for k in ("ours_shadow_map", "ours_ray_traced")
    }
    ratios: dict[str, float] = {
        "shadow_map_over_plain": med["ours_shadow_map"] / med["ours_plain"],
        "ray_traced_over_plain": med["ours_ray_traced"] / med["ours_plain"],
        "shadow_map_stage_s": shadow_stage["ours_shadow_map"],
        "ray_traced_stage_s": shadow_stage["ours_ray_traced"],
        # the frame if every other stage cost what it costs in the plain frame
        "shadow_map_stage_plus_plain_over_plain": 1 + shadow_stage["ours_shadow_map"] / med["ours_plain"],
        "ray_traced_stage_plus_plain_over_plain": 1 + shadow_stage["ours_ray_traced"] / med["ours_plain"],
    }
    for method in ("shadow_map", "ray_traced"):
        w, c = med[f"{method}_work"], med_cpu[f"{method}_work"]
        ratios[f"{method}_work_s"] = w
        # the frame if the visibility work were added to the plain frame and nothing else
        ratios[f"plain_plus_{method}_work_over_plain"] = 1 + w / med["ours_plain"]
        ratios[f"plain_plus_{method}_work_over_plain_cpu"] = 1 + c / med_cpu["ours_plain"]
        if gl_shadows is not None and method == "shadow_map":
            ratios["plain_plus_shadow_map_work_over_mesa_shadow_map"] = (med["ours_plain"] + w) / med[
                "mesa_shadow_map"
            ]
            ratios["plain_plus_shadow_map_work_over_mesa_shadow_map_cpu"] = (
                med_cpu["ours_plain"] + c
            ) / med_cpu["mesa_shadow_map"]
    agreement = None
    if gl_shadows is not None:
        ratios["shadow_map_over_mesa_shadow_map"] = med["ours_shadow_map"] / med["mesa_shadow_map"]
        ratios["shadow_map_over_mesa_shadow_map_cpu"] = (
            med_cpu["ours_shadow_map"] / med_cpu["mesa_shadow_map"]
        )
        ratios["mesa_shadow_map_over_mesa_plain"] = med["mesa_shadow_map"] / med["mesa_plain"]
        ours_result = last["ours_shadow_map"]
        agreement = _agreement(
            ours_result.rgba,  # type: ignore[attr-defined]
            last["mesa_shadow_map"].rgba,  # type: ignore[attr-defined]
            ours_result.passes["shadow"][..., 0],  # type: ignore[attr-defined]
        )
    targets = {
        "shadow_map_over_mesa_shadow_map <= 3": ratios.get("shadow_map_over_mesa_shadow_map", float("nan"))
        <= 3,
        "shadow_map_over_plain <= 1.5": ratios["shadow_map_over_plain"] <= 1.5,
        "ray_traced_over_plain <= 2": ratios["ray_traced_over_plain"] <= 2,
    }
    return {
        "benchmark": "shadows_mesa",
        "machine": machine_info(),
        "mesa": None if info is None else {"renderer": info.renderer, "version": info.version},
        "scene": {
            "triangles": n_tris,
            "width": width,
            "height": height,
            "visible_samples": len(points),
            "lights": ["directional", "point"],
        },
        "shadow_map": {
            "resolution": RESOLUTION,
            "constant_bias": CONSTANT_BIAS,
            "slope_bias": SLOPE_BIAS,
            "kernel": KERNEL,
        },
        "repeat": repeat,
        "median_wall_s": med,
        "median_cpu_s": med_cpu,
        "all_wall_s": wall,
        "stage_seconds_last": {
            k: stages[k][-1] for k in ("ours_plain", "ours_shadow_map", "ours_ray_traced")
        },
        "ratios": ratios,
        "targets_met": targets,
        "image_agreement": agreement,
    }


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="640×360, 64-segment spheres")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error(f"--repeat must be >= 1, got {args.repeat}")
    results = run(repeat=args.repeat, quick=args.quick)
    write_json(args.out / "shadows_mesa.json", results)
    rows = [[k, f"{v:.3f}", f"{results['median_cpu_s'][k]:.3f}"] for k, v in results["median_wall_s"].items()]
    print(markdown_table(["case", "median wall s", "median cpu s"], rows))
    for k, v in results["ratios"].items():
        print(f"{k}: {v:.3f}")
    print("agreement:", results["image_agreement"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
