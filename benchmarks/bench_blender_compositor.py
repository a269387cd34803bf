"""Blender's compositor against our numpy compositing, per 1920×1080 frame, measured in the same run.

For Blender's Alpha Over node (every mode this Blender has) and every Porter-Duff node
group of the add-on, one Blender process renders a compositor tree holding only that
case (two Image nodes → case → render output), once to warm up and then ``--repeat``
times round-robin over the cases; the wall-clock time of ``bpy.ops.render.render`` is recorded
and the best run reported (the least disturbed by other processes). A tree that just
passes the source image through (``copy``) measures the fixed cost of a render (image
fetch, render-result handling); ``blender_op_s`` is the case minus that baseline.
Our side is :func:`compositing.composite` on the same two frames with the numpy
reference engine and with the fused numba engine (compiled before timing).

Ratios are Blender time / our time (> 1: ours is faster), both measured on this machine in
this run. Usage::

    .venv/bin/python -m benchmarks.bench_blender_compositor [--out benchmarks/results] [--python PY]

Writes ``blender_compositor.json`` to ``--out``.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from addon.verify import ALPHA_OVER_OPERATORS, run_compositor_job, sample_images, write_exr
from benchmarks._util import write_json
from compositing import OPERATORS, composite

__all__ = ["main", "run"]

WIDTH, HEIGHT = 1920, 1080
GROUP_OPERATORS = (*OPERATORS, "plus")


def _median_time(fn, repeat: int) -> float:
    fn()  # warm-up (and numba compilation)
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def run(out_dir: str | os.PathLike, *, repeat: int = 5, python: str | None = None) -> dict:
    """Run the benchmark, write ``blender_compositor.json`` into ``out_dir`` and return its content."""
    load_before = os.getloadavg()
    src, dst = sample_images(HEIGHT, WIDTH, seed=1)
    cases: dict[str, dict] = {"copy": {"kind": "copy"}}
    for op in ALPHA_OVER_OPERATORS:
        cases[f"alpha_over/{op}"] = {"kind": "alpha_over", "operator": op, "factor": 1.0}
    for op in GROUP_OPERATORS:
        cases[f"node_group/{op}"] = {"kind": "node_group", "operator": op, "factor": 1.0}

    with tempfile.TemporaryDirectory(prefix="pd-bench-") as tmp:
        work = Path(tmp)
        write_exr(work / "src.exr", src)
        write_exr(work / "dst.exr", dst)
        probe = run_compositor_job(
            {
                "mode": "benchmark",
                "src": str(work / "src.exr"),
                "dst": str(work / "dst.exr"),
                "width": WIDTH,
                "height": HEIGHT,
                "repeat": 1,
                "cases": {"copy": {"kind": "copy"}},
            },
            work / "probe.json",
            python=python,
            timeout=300,
        )
        available = set(probe["alpha_over_modes"])
        cases = {
            key: case
            for key, case in cases.items()
            if case["kind"] != "alpha_over" or case["operator"] in available
        }
        job = {
            "mode": "benchmark",
            "src": str(work / "src.exr"),
            "dst": str(work / "dst.exr"),
            "width": WIDTH,
            "height": HEIGHT,
            "repeat": repeat,
            "register_addon": True,
            "cases": cases,
        }
        report = run_compositor_job(job, work / "job.json", python=python, timeout=600)

    baseline = min(report["timings"]["copy"])
    rows = []
    for key, case in cases.items():
        if case["kind"] == "copy":
            continue
        blender = min(report["timings"][key])
        op = case["operator"]
        numpy_s = _median_time(lambda op=op: composite(src, dst, op, engine="numpy"), repeat)
        numba_s = _median_time(lambda op=op: composite(src, dst, op, engine="numba"), repeat)
        blender_op = max(blender - baseline, 0.0)
        rows.append(
            {
                "case": key,
                "blender_render_s": blender,
                "blender_render_median_s": statistics.median(report["timings"][key]),
                "blender_op_s": blender_op,
                "numpy_s": numpy_s,
                "numba_s": numba_s,
                "ratio_blender_render_over_numpy": blender / numpy_s,
                "ratio_blender_op_over_numpy": blender_op / numpy_s,
                "ratio_blender_op_over_numba": blender_op / numba_s,
            }
        )
    result = {
        "benchmark": "blender_compositor",
        "frame": [WIDTH, HEIGHT],
        "repeat": repeat,
        "statistic": "best (minimum) wall-clock seconds per frame over the timed runs",
        "blender_version": report["blender_version"],
        "blender_copy_baseline_s": baseline,
        "machine": {
            "cpu_count": os.cpu_count(),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            # Other processes share the cores: 1-minute load average before and after the run.
            "load_average_1min": [load_before[0], os.getloadavg()[0]],
        },
        "rows": rows,
    }
    write_json(Path(out_dir) / "blender_compositor.json", result)
    return result


def main(argv: list[str] | None = None) -> int:
    """CLI entry point; prints a table and writes the JSON."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_blender_compositor")
    parser.add_argument("--out", default="benchmarks/results", help="output directory for the JSON")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per case (best reported)")
    parser.add_argument("--python", help="Python with bpy (default: this one)")
    args = parser.parse_args(argv)
    result = run(args.out, repeat=args.repeat, python=args.python)
    print(
        f"Blender {result['blender_version']}, {WIDTH}x{HEIGHT}, best of {args.repeat}; "
        f"render baseline (copy) {result['blender_copy_baseline_s'] * 1e3:.1f} ms"
    )
    print(f"{'case':28s} {'render ms':>10s} {'op ms':>8s} {'numpy ms':>9s} {'numba ms':>9s} {'op/numpy':>9s}")
    for row in result["rows"]:
        print(
            f"{row['case']:28s} {row['blender_render_s'] * 1e3:10.1f} {row['blender_op_s'] * 1e3:8.1f} "
            f"{row['numpy_s'] * 1e3:9.1f} {row['numba_s'] * 1e3:9.1f} "
            f"{row['ratio_blender_op_over_numpy']:9.2f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
