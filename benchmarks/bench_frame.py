"""The frame pipeline with and without effects: time ratios to the plain frame, peak memory, scaling.

Scene (the effects issue's): two UV spheres of 65 536 triangles each (256 segments × 128 rings)
over a ground plane, lit by a directional and a point light, rendered at 1920×1080 with one
sample per pixel; for the transparency rows the left sphere has opacity 0.5.

Rows, timed interleaved in one process (:func:`benchmarks._util.time_interleaved`, medians of
wall and CPU time) and reported as ratios to the plain frame of the same run:

* ``plain`` — ``shadows="none"``: the pipeline with no effect;
* ``default`` — no options: the planner's choices (hard shadows from both lights);
* ``a_buffer``, ``draw_last``, ``weighted_blended`` — the transparent sphere by each method;
* ``fog`` — ``Fog("exp", density=0.05)`` on the opaque scene;
* ``shadow_map`` (1024², default bias) and ``ray_traced`` — hard shadows from both lights.

Peer (``--mesa``): the plain compiled frame of :mod:`benchmarks.bench_renderer`'s scene (about
100k triangles, four lights, per-pixel Blinn-Phong, 1920×1080) against Mesa llvmpipe running
:mod:`oracles.gl_lighting`'s GLSL shader on it, interleaved in the same run (medians of wall and
process CPU time, llvmpipe's threads included).

Peak memory: each row is rendered once more in a fresh process (after a small warm-up render that
loads the compiled kernels) and reports its peak resident set (``VmHWM``), with the warm-up's as
the baseline.

Scaling: the plain, A-buffer and fog frames against the number of pixels (480×270 … 3840×2160,
65k-triangle spheres) and against the number of triangles (spheres of 64×32 … 512×256
segments, 960×540), time and peak memory; each series runs in one fresh process in increasing
size, so each point's peak RSS is its own.

Usage::

    .venv/bin/python -m benchmarks.bench_frame [--out benchmarks/results] [--repeat 3] [--quick]
        [--no-scaling] [--mesa] [--charts docs]

``--no-scaling`` measures the table only and keeps the scaling series of the ``frame.json``
already in ``--out`` (marked ``scaling_measured: false``).

Writes ``frame.json`` to ``--out``; :func:`draw` makes ``frame_scaling.png``
(:func:`benchmarks.charts.draw_all` calls it when ``frame.json`` is in the results directory).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import blinn_phong as bp
from benchmarks._util import machine_info, markdown_table, save_figure, time_interleaved, write_json
from blinn_phong.primitives import grid_plane, uv_sphere

__all__ = ["CASES", "draw", "issue_scene", "main", "run"]


def issue_scene(segments: int = 256, rings: int = 128, transparent: bool = False) -> bp.Scene:
    """Two UV spheres (``2·segments·(rings − 1)`` triangles each) over a ground plane, two lights."""
    pos, tris, normals = uv_sphere(segments, rings, 1.0)
    meshes = []
    for i, x in enumerate((-1.2, 1.2)):
        transform = np.eye(4)
        transform[:3, 3] = (x, 0.0, 1.0)
        material = bp.Material(
            diffuse=(0.8, 0.3, 0.2) if i else (0.2, 0.4, 0.9),
            specular=(0.5, 0.5, 0.5),
            shininess=40.0,
            opacity=0.5 if (transparent and i == 0) else 1.0,
        )
        meshes.append(bp.Mesh(pos, tris, normals, transform=transform, material=material))
    plane, ptris, pnormals = grid_plane(1, 1, (12.0, 12.0))
    meshes.append(bp.Mesh(plane, ptris, pnormals, material=bp.Material(diffuse=(0.6, 0.6, 0.6))))
    camera = bp.Camera.perspective(
        40.0, 16 / 9, 0.5, 50.0, view=bp.look_at((0.0, -7.0, 3.5), (0.0, 0.0, 0.8), (0, 0, 1))
    )
    lights = (bp.DirectionalLight((0.3, 0.4, -1.0)), bp.PointLight((2.0, -2.0, 4.0), quadratic=0.02))
    return bp.Scene(tuple(meshes), lights, camera)


#: Row name → (transparent sphere?, render() options).
CASES: dict[str, tuple[bool, dict[str, object]]] = {
    "plain": (False, {"shadows": "none"}),
    "default": (False, {}),
    "a_buffer": (True, {"shadows": "none", "transparency": "a_buffer"}),
    "draw_last": (True, {"shadows": "none", "transparency": "draw_last"}),
    "weighted_blended": (True, {"shadows": "none", "transparency": "weighted_blended"}),
    "fog": (False, {"shadows": "none", "fog": bp.Fog("exp", (0.5, 0.6, 0.7), density=0.05)}),
    "shadow_map": (False, {"shadows": bp.ShadowOptions("shadow_map", resolution=1024)}),
    "ray_traced": (False, {"shadows": "ray_traced"}),
    "shadow_volume": (False, {"shadows": "shadow_volume"}),
}


def _renderer(case: str, width: int, height: int, segments: int) -> Callable[[], bp.RenderResult]:
    transparent, options = CASES[case]
    scene = issue_scene(segments, segments // 2, transparent)
    return lambda: bp.render(scene, width, height, **options)  # type: ignore[arg-type]


def _peak_rss_bytes() -> int:
    """This process's peak resident set (``VmHWM``; ``ru_maxrss`` where /proc is missing).

    ``ru_maxrss`` keeps the forking parent's peak across ``exec`` on Linux, so a child started by
    a big benchmark process would report the parent's; ``VmHWM`` belongs to the new image only.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _child(case: str, points: list[tuple[int, int, int]]) -> list[dict[str, object]]:
    """Renders in this (fresh) process, in the given order: seconds, stage times, peak RSS.

    The peak resident set only grows, so points are given in increasing size: each one's peak is its own
    (the smaller renders before it need less).
    """
    out = []
    for width, height, segments in points:
        transparent, options = CASES[case]
        scene = issue_scene(segments, segments // 2, transparent)
        bp.render(scene, 64, 36, **options)  # type: ignore[arg-type]  # loads the compiled kernels
        baseline = _peak_rss_bytes()
        start, cpu = time.perf_counter(), time.process_time()
        result = bp.render(scene, width, height, **options)  # type: ignore[arg-type]
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
        out.append(
            {
                "case": case,
                "width": width,
                "height": height,
                "pixels": width * height,
                "triangles": result.stats.triangles,
                "seconds": seconds,
                "cpu_seconds": cpu,
                "stages": result.stats.seconds,
                "shaded": result.stats.shaded,
                "baseline_rss_bytes": baseline,
                "peak_rss_bytes": _peak_rss_bytes(),
                "plan": result.plan.transparency.method if result.plan else None,
            }
        )
        del result
    return out


def _in_fresh_process(case: str, points: list[tuple[int, int, int]]) -> list[dict[str, object]]:
    cmd = [sys.executable, "-m", "benchmarks.bench_frame", "--child", case, json.dumps(points)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def mesa_peer(repeat: int = 3) -> dict[str, object] | None:
    """Plain compiled frame vs Mesa llvmpipe GLSL on :mod:`benchmarks.bench_renderer`'s scene, interleaved.

    Returns medians of wall and process CPU seconds and their ratios (ours / Mesa), or None when
    no EGL context can be made.
    """
    from benchmarks.bench_renderer import HEIGHT, WIDTH, build_scene
    from oracles.egl import EGLUnavailable, gl_context

    try:
        gl_context()
        from oracles import gl_lighting
    except EGLUnavailable as exc:
        print(f"Mesa unavailable, no peer ratio: {exc}")
        return None
    scene = build_scene()
    bp.render(scene, WIDTH, HEIGHT, shadows="none")  # warm-up: kernels, first-touch pages
    gl_lighting.render_glsl_phong(scene, WIDTH, HEIGHT)
    wall: dict[str, list[float]] = {"ours": [], "mesa_glsl": []}
    cpu: dict[str, list[float]] = {"ours": [], "mesa_glsl": []}
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        bp.render(scene, WIDTH, HEIGHT, shadows="none")
        wall["ours"].append(time.perf_counter() - start)
        cpu["ours"].append(time.process_time() - start_cpu)
        frame = gl_lighting.render_glsl_phong(scene, WIDTH, HEIGHT, repeats=1)
        wall["mesa_glsl"].append(frame.seconds)
        cpu["mesa_glsl"].append(frame.cpu_seconds)
    med = {k: float(np.median(v)) for k, v in wall.items()}
    med_cpu = {k: float(np.median(v)) for k, v in cpu.items()}
    return {
        "scene": "benchmarks.bench_renderer.build_scene()",
        "triangles": sum(len(m.triangles) for m in scene.meshes),
        "size": [WIDTH, HEIGHT],
        "median_s": med,
        "median_cpu_s": med_cpu,
        "runs_s": wall,
        "runs_cpu_s": cpu,
        "ratio_to_mesa": med["ours"] / med["mesa_glsl"],
        "cpu_ratio_to_mesa": med_cpu["ours"] / med_cpu["mesa_glsl"],
    }


def run(
    out_dir: str | Path, *, repeat: int = 3, quick: bool = False, scaling: bool = True, mesa: bool = False
) -> dict:
    """Measure the table (and the scaling series, and the Mesa peer when asked); write ``frame.json``."""
    width, height = (960, 540) if quick else (1920, 1080)
    segments = 128 if quick else 256
    timings = time_interleaved(
        {case: _renderer(case, width, height, segments) for case in CASES}, repeat=repeat, warmup=1
    )
    cpu = {}
    for case in CASES:  # CPU time of one more render each (less sensitive to other load than wall time)
        fn = _renderer(case, width, height, segments)
        start = time.process_time()
        fn()
        cpu[case] = time.process_time() - start
    rows = []
    plain = timings["plain"]["median_s"]
    for case in CASES:
        memory = _in_fresh_process(case, [(width, height, segments)])[0]
        rows.append(
            {
                "case": case,
                "median_s": timings[case]["median_s"],
                "min_s": timings[case]["min_s"],
                "ratio_to_plain": timings[case]["median_s"] / plain,
                "cpu_s": cpu[case],
                "cpu_ratio_to_plain": cpu[case] / cpu["plain"],
                "peak_rss_bytes": memory["peak_rss_bytes"],
                "baseline_rss_bytes": memory["baseline_rss_bytes"],
                "stages": memory["stages"],
                "shaded": memory["shaded"],
            }
        )
    sizes = [(480, 270), (960, 540), (1920, 1080)] + ([] if quick else [(3840, 2160)])
    tessellations = [64, 128, 256] + ([] if quick else [512])
    series: dict[str, list[dict]] = {"pixels": [], "triangles": []}
    previous = Path(out_dir) / "frame.json"
    if scaling:
        for case in ("plain", "a_buffer", "fog"):
            series["pixels"] += _in_fresh_process(case, [(w, h, segments) for w, h in sizes])
            series["triangles"] += _in_fresh_process(case, [(960, 540, s) for s in tessellations])
    elif previous.exists():
        series = json.loads(previous.read_text()).get("scaling", series)
    peer = mesa_peer(repeat) if mesa else None
    data = {
        "benchmark": "frame",
        "scene": f"two {2 * segments * (segments // 2 - 1)}-triangle spheres over a plane, 2 lights",
        "size": [width, height],
        "repeat": repeat,
        "machine": machine_info(),
        "rows": rows,
        "mesa_peer": peer,
        "scaling_measured": scaling,
        "scaling": series,
    }
    write_json(Path(out_dir) / "frame.json", data)
    return data


def draw(data: dict, out_dir: str | Path) -> list[Path]:
    """``frame_scaling.png``: time and peak RSS against pixels and against triangles, per effect."""
    from benchmarks.charts import DPI, plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
    for col, key in enumerate(("pixels", "triangles")):
        points = data["scaling"][key]
        for case, marker in (("plain", "o"), ("a_buffer", "s"), ("fog", "^")):
            mine = sorted((p for p in points if p["case"] == case), key=lambda p: p[key])
            x = [p[key] for p in mine]
            (line,) = axes[0, col].plot(x, [p["seconds"] for p in mine], marker + "-", label=f"{case} (wall)")
            axes[0, col].plot(
                x,
                [p["cpu_seconds"] for p in mine],
                marker + "--",
                color=line.get_color(),
                label=f"{case} (CPU)",
            )
            axes[1, col].plot(x, [p["peak_rss_bytes"] / 2**30 for p in mine], marker + "-", label=case)
        fixed = "65k-triangle spheres" if key == "pixels" else "960×540"
        for row, label in ((0, "seconds (one render; CPU: all threads)"), (1, "peak RSS, GiB")):
            ax = axes[row, col]
            ax.set_xscale("log")
            ax.set_xlabel(f"{key} ({fixed})", fontsize=8)
            ax.set_ylabel(label, fontsize=8)
            ax.grid(True, which="both", alpha=0.25)
            ax.legend(fontsize=7)
        axes[0, col].set_yscale("log")
    fig.suptitle(
        "Frame pipeline scaling: plain z-buffer, A-buffer (one sphere at opacity 0.5), exp fog", fontsize=10
    )
    fig.tight_layout()
    path = save_figure(fig, out / "frame_scaling.png", dpi=DPI)  # atomic: a failed save keeps the old chart
    plt.close(fig)
    return [path]


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="960×540, 16k-triangle spheres, fewer points")
    parser.add_argument(
        "--charts", type=Path, default=None, help="documentation directory (PNG in <dir>/charts)"
    )
    parser.add_argument(
        "--no-scaling", action="store_true", help="the table only; keep the old scaling series"
    )
    parser.add_argument(
        "--mesa", action="store_true", help="also the plain frame vs Mesa llvmpipe (renderer scene)"
    )
    parser.add_argument("--child", nargs=2, metavar=("CASE", "POINTS_JSON"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        case, points = args.child
        print(json.dumps(_child(case, [tuple(p) for p in json.loads(points)])))
        return
    data = run(args.out, repeat=args.repeat, quick=args.quick, scaling=not args.no_scaling, mesa=args.mesa)
    print(
        markdown_table(
            ["render", "median s", "× plain", "CPU × plain", "peak RSS GB"],
            [
                [
                    r["case"],
                    f"{r['median_s']:.3f}",
                    f"{r['ratio_to_plain']:.2f}",
                    f"{r['cpu_ratio_to_plain']:.2f}",
                    f"{r['peak_rss_bytes'] / 1e9:.2f}",
                ]
                for r in data["rows"]
            ],
        )
    )
    peer = data.get("mesa_peer")
    if peer:
        print(
            f"plain frame vs Mesa llvmpipe ({peer['triangles']} triangles): "
            f"wall {peer['ratio_to_mesa']:.2f}×, CPU {peer['cpu_ratio_to_mesa']:.2f}×"
        )
    if args.charts is not None:
        for path in draw(data, args.charts / "charts"):
            print(f"chart {path}")


if __name__ == "__main__":
    main()
