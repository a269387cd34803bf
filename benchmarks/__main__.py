"""One command for every benchmark: speed against accuracy, peers, charts.

Usage::

    python -m benchmarks --out benchmarks/results --charts docs            # everything (make bench)
    python -m benchmarks --quick --out /tmp/bench                           # a small run, < 2 minutes
    python -m benchmarks --only shading --only shadows --charts docs        # a subset
    python -m benchmarks --list                                             # what can be run

Tradeoff families (:mod:`benchmarks.tradeoffs`) write ``tradeoffs.json`` (``--quick``:
``tradeoffs_quick.json``) into ``--out``; a subset run updates only its families in that
file, so the charts always show the latest measurement of each. Charts go to
``<--charts>/charts/*.png`` (:mod:`benchmarks.charts`). A full run that measured the
shading, shadow and transparency families refits the planner's error and cost models
(:mod:`benchmarks.error_models` → ``blinn_phong/planning/calibration.json``). The per-module benchmarks
(``bench_*``) run through their own ``run`` functions and write their own JSON; they are
skipped by ``--quick`` unless named with ``--only``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from benchmarks._util import machine_info, write_json

MODULES = (
    "compositing_vs_oiio",
    "gl_blend",
    "effects",
    "renderer",
    "blender_compositor",
    "shadow_volume",
    "shadows_mesa",
    "frame",
    "planning",
    "deep",
    "compile",
)


def _module_runner(name: str, out: Path, repeat: int, quick: bool) -> Callable[[], object]:
    """The public entry point of one ``bench_*`` module, writing its JSON into ``out``."""
    if name == "compositing_vs_oiio":
        from benchmarks import bench_compositing

        return lambda: write_json(
            out / "compositing.json", bench_compositing.run(repeat=max(repeat, 5), quick=quick)
        )
    if name == "gl_blend":
        from benchmarks import bench_gl_blend

        return lambda: bench_gl_blend.run(out, repeat=max(repeat, 5))
    if name == "effects":
        from benchmarks import bench_effects

        return lambda: bench_effects.run(out, repeat=repeat, size=128 if quick else 256)
    if name == "renderer":
        from benchmarks import bench_renderer

        return lambda: write_json(out / "renderer.json", bench_renderer.run(repeat=repeat))
    if name == "shadows_mesa":
        from benchmarks import bench_shadows_mesa

        return lambda: write_json(
            out / "shadows_mesa.json", bench_shadows_mesa.run(repeat=repeat, quick=quick)
        )
    if name == "blender_compositor":
        from benchmarks import bench_blender_compositor

        return lambda: bench_blender_compositor.run(out, repeat=repeat)
    if name == "shadow_volume":
        from benchmarks import bench_shadow_volume

        return lambda: bench_shadow_volume.run(out, repeat=repeat, quick=quick)
    if name == "frame":
        from benchmarks import bench_frame

        # --quick: 960×540, 16k-triangle spheres, scaling to 960×540 (frame_quick.json)
        return lambda: bench_frame.run(out, repeat=repeat, quick=quick)
    if name == "planning":
        from benchmarks import bench_planning

        return lambda: bench_planning.run(out, repeat=repeat)
    if name == "deep":
        from benchmarks import bench_deep

        return lambda: bench_deep.run(out, repeat=repeat, quick=quick)
    if name == "compile":
        from benchmarks import bench_compile

        # every case in a fresh process with an empty kernel cache, then warm (about an hour)
        return lambda: bench_compile.run(out)
    raise ValueError(f"unknown benchmark module {name!r}; expected one of {MODULES}")


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status (1 if any benchmark failed)."""
    from benchmarks.tradeoffs import FAMILIES

    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"), help="directory for the JSON")
    parser.add_argument(
        "--charts", type=Path, default=None, help="documentation directory; PNGs go to <dir>/charts"
    )
    parser.add_argument(
        "--quick", action="store_true", help="smaller scenes, tradeoff families only (< 2 min)"
    )
    parser.add_argument("--repeat", type=int, default=None, help="timed rounds per case (default 5, quick 2)")
    parser.add_argument(
        "--only",
        action="append",
        choices=[*FAMILIES, *MODULES],
        help="run only this family or module (repeatable)",
    )
    parser.add_argument("--list", action="store_true", help="list families and modules, then exit")
    args = parser.parse_args(argv)
    if args.list:
        print("tradeoff families:", ", ".join(FAMILIES))
        print("benchmark modules:", ", ".join(MODULES))
        return 0
    if args.repeat is not None and args.repeat < 1:
        parser.error(f"--repeat must be >= 1, got {args.repeat}")
    repeat = args.repeat or (2 if args.quick else 5)
    selected = args.only or [*FAMILIES, *([] if args.quick else MODULES)]
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    json_path = out / ("tradeoffs_quick.json" if args.quick else "tradeoffs.json")
    previous = json.loads(json_path.read_text()) if json_path.exists() else {}
    results: dict[str, dict] = dict(previous.get("families", {}))
    failures: list[str] = []
    started = time.perf_counter()
    for name in selected:
        t0 = time.perf_counter()
        print(f"== {name}", flush=True)
        try:
            if name in FAMILIES:
                results[name] = FAMILIES[name](quick=args.quick, repeat=repeat)
                results[name]["wall_s"] = time.perf_counter() - t0
                write_json(
                    json_path,
                    {
                        "benchmark": "tradeoffs",
                        "quick": args.quick,
                        "repeat": repeat,
                        "machine": machine_info(),
                        "families": results,
                    },
                )
            else:
                _module_runner(name, out, repeat, args.quick)()
        except Exception:  # report and go on with the others: one broken peer must not hide the rest
            traceback.print_exc()
            failures.append(name)
        print(f"   {name}: {time.perf_counter() - t0:.1f} s", flush=True)
    if not args.quick and {"shading", "shadows", "transparency"} <= set(selected) - set(failures):
        from benchmarks import error_models

        path = error_models.save(error_models.fit_results(out, results))
        print(f"calibration {path}")
    if args.charts is not None:
        from benchmarks.charts import draw_all

        for path in draw_all(results, args.charts / "charts", out):
            print(f"chart {path}")
    print(f"total {time.perf_counter() - started:.1f} s; results in {json_path}")
    if failures:
        print(f"FAILED: {', '.join(failures)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
