"""Predicted against measured cost ratios of the choices the planner compares, on the benchmark scenes.

For each scene and frame, every method the planner weighs for a concern is rendered with
``render()`` (that concern's method forced, the others fixed), interleaved in one run, and its
measured time ratio to the concern's exact method is set against the ratio the planner's cost
models predict (:mod:`blinn_phong.planning.calibration`, fitted by :mod:`benchmarks.error_models`):

* shadows, per light (the other lights without shadows): Embree ray tracing (the reference),
  shadow volumes (:func:`~blinn_phong.planning.calibration.shadow_volume_cost`) and, for directional
  lights, shadow maps (:func:`~blinn_phong.planning.calibration.shadow_map_cost`), with the planner's
  estimate of the rays a frame traces (:func:`~blinn_phong.planning.planner.traced_share`); measured on
  the ``shadows`` stage of ``RenderStats.seconds``;
* transparency: the A-buffer (reference), draw-last, sorted objects and depth peeling with 1,
  2, 4 layers (:func:`~blinn_phong.planning.calibration.transparency_seconds`,
  :func:`~blinn_phong.planning.calibration.depth_peeling_cost`);
* shading: Phong (reference), Gouraud, flat (:func:`~blinn_phong.planning.calibration.shading_cost`),
  and fog against no fog (:func:`~blinn_phong.planning.calibration.fog_cost`).

Shadows are measured on the ``shadows`` stage's wall time (tens to hundreds of milliseconds),
with Embree's scene (BVH) built in every frame, as the models assume (:func:`benchmarks.tradeoffs.uncached`),
the others on the whole frame's process CPU time (what their models predict; their stages
take milliseconds, which preemption on a loaded machine swamps). Each is the fastest of the
interleaved rounds.

Scenes: the frame benchmark's scene (:func:`benchmarks.bench_frame.issue_scene`, opaque and
with its transparent sphere) at two sizes, the transparency calibration scene
(:func:`testbeds.tradeoff_scenes.layered_scene`, 8 layers) and the shadow calibration scene
(:func:`testbeds.tradeoff_scenes.shadow_scene`). A prediction is within 2× when
``max(p/m, m/p) ≤ 2``.

``python -m benchmarks.cost_check [--repeat 3] [--segments 256]`` writes
``benchmarks/results/cost_check.json`` and prints the table.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path

import blinn_phong as bp
from benchmarks._util import machine_info, markdown_table, write_json
from benchmarks.bench_frame import issue_scene
from benchmarks.tradeoffs import shadow_runs
from blinn_phong.planning import calibration as cal
from blinn_phong.planning.planner import shadow_map_geometry, traced_share
from testbeds.tradeoff_scenes import layered_scene, shadow_scene

__all__ = ["check_frame", "main", "run"]

#: Shadow-map resolutions timed for directional lights.
MAP_RESOLUTIONS = (256, 1024)
#: Depth-peeling layers timed.
PEEL = (1, 2, 4)


def _timed(runs: dict[str, Callable[[], bp.RenderResult]], repeat: int) -> dict[str, dict[str, float]]:
    """The fastest round's seconds per stage (``total``, ``cpu`` and each ``RenderStats`` stage) of
    interleaved renders, by :func:`benchmarks.tradeoffs.timed_renders` (on a shared machine
    contention only adds time, as the fits use)."""
    from benchmarks.tradeoffs import timed_renders

    return {
        name: {key[: -len("_s")]: value for key, value in table.items() if not key.endswith("_median_s")}
        for name, table in timed_renders(runs, repeat).items()
    }


def _row(scene: str, frame: str, concern: str, method: str, predicted: float, measured: float) -> dict:
    off = max(predicted / measured, measured / predicted) if predicted > 0 and measured > 0 else math.inf
    return {
        "scene": scene,
        "frame": frame,
        "concern": concern,
        "method": method,
        "predicted": predicted,
        "measured": measured,
        "factor_off": off,
        "within_2x": off <= 2.0,
    }


def check_frame(
    name: str,
    scene: bp.Scene,
    width: int,
    height: int,
    *,
    concerns: tuple[str, ...],
    models: dict,
    repeat: int = 3,
) -> list[dict]:
    """Rows of predicted and measured ratios for one frame (see the module docstring)."""
    samples = width * height
    triangles = sum(len(m.triangles) for m in scene.meshes)
    frame = f"{width}×{height}"
    render = functools.partial(bp.render, scene, width, height)
    rows: list[dict] = []
    if "shadows" in concerns:
        for j, light in enumerate(scene.lights):
            if isinstance(light, bp.AmbientLight):
                continue

            runs = shadow_runs(render, scene, j, MAP_RESOLUTIONS)
            t = _timed(runs, repeat)
            ref = t["ray_traced"]["shadows"]
            share = traced_share(scene, models=models)  # the planner's estimate, as it plans
            volume = cal.shadow_volume_cost(models, triangles, samples, share)
            if volume is not None:
                rows.append(
                    _row(
                        name,
                        frame,
                        f"shadows, light {j}",
                        "shadow_volume",
                        volume["ratio"],
                        t["shadow_volume"]["shadows"] / ref,
                    )
                )
            for res in MAP_RESOLUTIONS if isinstance(light, bp.DirectionalLight) else ():
                geometry = shadow_map_geometry(scene, j)
                predicted = cal.shadow_map_cost(models, res, samples, geometry.triangles, share)
                rows.append(
                    _row(
                        name,
                        frame,
                        f"shadows, light {j}",
                        f"shadow_map {res}²",
                        predicted,
                        t[f"shadow_map {res}"]["shadows"] / ref,
                    )
                )
    if "transparency" in concerns:
        runs = {
            m: functools.partial(render, shadows="none", transparency=m)
            for m in ("a_buffer", "draw_last", "sort_objects")
        }
        for k in PEEL:
            runs[f"depth_peeling {k}"] = functools.partial(
                render, shadows="none", transparency="depth_peeling", layers=k
            )
        t = _timed(runs, repeat)
        ref = t["a_buffer"]["cpu"]
        for m in ("draw_last", "sort_objects"):
            predicted = cal.transparency_seconds(models, m, samples, triangles) / cal.transparency_seconds(
                models, "a_buffer", samples, triangles
            )
            rows.append(_row(name, frame, "transparency", m, predicted, t[m]["cpu"] / ref))
        for k in PEEL:
            rows.append(
                _row(
                    name,
                    frame,
                    "transparency",
                    f"depth_peeling {k}",
                    cal.depth_peeling_cost(models, k, samples, triangles),
                    t[f"depth_peeling {k}"]["cpu"] / ref,
                )
            )
    if "shading" in concerns:
        fog = bp.Fog("exp", (0.5, 0.6, 0.7), density=0.05)
        runs = {m: functools.partial(render, shadows="none", shading=m) for m in ("phong", "gouraud", "flat")}
        runs["fog"] = functools.partial(render, shadows="none", shading="phong", fog=fog)
        t = _timed(runs, repeat)
        ref = t["phong"]["cpu"]
        for m in ("gouraud", "flat"):
            rows.append(
                _row(
                    name,
                    frame,
                    "shading",
                    m,
                    cal.shading_cost(models, m, samples, triangles),
                    t[m]["cpu"] / ref,
                )
            )
        rows.append(
            _row(
                name,
                frame,
                "fog",
                "exp fog",
                cal.fog_cost(models, samples, triangles) or math.nan,
                t["fog"]["cpu"] / ref,
            )
        )
    return rows


def run(repeat: int = 3, segments: int = 256, out: Path | None = None) -> dict:
    """Every benchmark frame (see the module docstring); writes ``cost_check.json`` to ``out``."""
    models = cal.shipped_models()
    frames: list[tuple[str, bp.Scene, int, int, tuple[str, ...]]] = []
    for w, h in ((320, 180), (640, 360)):
        frames.append(("frame benchmark", issue_scene(segments, segments // 2), w, h, ("shadows", "shading")))
        frames.append(
            (
                "frame benchmark, transparent sphere",
                issue_scene(segments, segments // 2, True),
                w,
                h,
                ("transparency",),
            )
        )
    frames.append(
        ("transparency calibration (8 layers, α 0.5)", layered_scene(8, 0.5), 160, 160, ("transparency",))
    )
    frames.append(("shadow calibration", shadow_scene(), 256, 256, ("shadows",)))
    rows: list[dict] = []
    for name, scene, w, h, concerns in frames:
        print(f"{name} {w}×{h}: {', '.join(concerns)}", file=sys.stderr, flush=True)
        rows += check_frame(name, scene, w, h, concerns=concerns, models=models, repeat=repeat)
    result = {
        "benchmark": "cost_check",
        "machine": machine_info(),
        "repeat": repeat,
        "segments": segments,
        "rows": rows,
        "within_2x": sum(r["within_2x"] for r in rows),
        "cases": len(rows),
    }
    if out is not None:
        write_json(Path(out) / "cost_check.json", result)
    return result


def table(result: dict) -> str:
    """The rows as a markdown table."""
    return markdown_table(
        ["scene", "frame", "concern", "method", "predicted", "measured", "off by"],
        [
            [
                r["scene"],
                r["frame"],
                r["concern"],
                r["method"],
                f"{r['predicted']:.2f}",
                f"{r['measured']:.2f}",
                f"{r['factor_off']:.2f}×",
            ]
            for r in result["rows"]
        ],
    )


def main(argv: list[str] | None = None) -> int:
    """Command line: run the check, write the JSON, print the table; exit 1 if a prediction is off by > 2×."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--segments", type=int, default=256)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    args = parser.parse_args(argv)
    result = run(args.repeat, args.segments, args.out)
    print(table(result))
    print(json.dumps({"within_2x": result["within_2x"], "cases": result["cases"]}))
    return 0 if result["within_2x"] == result["cases"] else 1


if __name__ == "__main__":
    sys.exit(main())
