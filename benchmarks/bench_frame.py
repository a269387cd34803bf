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

Peer (``--mesa``): the plain compiled frame against Mesa llvmpipe running
:mod:`oracles.gl_lighting`'s GLSL shader on the same scene, interleaved in the same run (medians
of wall and process CPU time, llvmpipe's threads included), for two scenes:
:mod:`benchmarks.bench_renderer`'s (about 100k triangles, four lights, per-pixel Blinn-Phong,
1920×1080) and :func:`small_sphere_scene` (a 64-segment sphere at 640×360, where the fixed
per-frame costs dominate).

Peak memory: each row is rendered once more in a fresh process (after a small warm-up render that
loads the compiled kernels) and reports its peak resident set (``VmHWM``), with the warm-up's as
the baseline.

Scaling (:func:`scaling_series`): every row above and the shadow-volume frame
(``shadows="shadow_volume"``, :data:`SCALING_CASES`) against the number of pixels (480×270 …
3840×2160, 65k-triangle spheres) and against the number of triangles (spheres of 64×32 …
512×256 segments, 960×540), time and peak memory; each series runs in one fresh process in
increasing size, so each point's peak RSS is its own. The plain and A-buffer points also count
their fragments (:func:`_census`): rasterized (every covered sample of every triangle) against
kept by the visibility stage, and the bytes of each.

Usage::

    .venv/bin/python -m benchmarks.bench_frame [--out benchmarks/results] [--repeat 3] [--quick]
        [--no-scaling] [--mesa] [--charts docs]

``--no-scaling`` measures the table only and keeps the scaling series of the ``frame.json``
already in ``--out`` (marked ``scaling_measured: false``). ``--quick`` writes
``frame_quick.json`` instead, so a quick run never replaces the full measurement
(``python -m benchmarks --only frame`` runs this module; ``--quick`` passes on).

Writes ``frame.json`` to ``--out``; :func:`benchmarks.charts.frame_scaling_chart` makes
``frame_scaling.png`` from it (``--charts``, and :func:`benchmarks.charts.draw_all` when
``frame.json`` is in the results directory).
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
from benchmarks._util import machine_info, markdown_table, time_interleaved, write_json
from blinn_phong.model.primitives import grid_plane, uv_sphere

__all__ = [
    "CASES",
    "SCALING_CASES",
    "issue_scene",
    "main",
    "mesa_peer",
    "run",
    "scaling_series",
    "small_sphere_scene",
]


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


#: Row name → (transparent sphere?, render() options) of the scaling series: every row of
#: :data:`CASES` and the shadow-volume frame (hard shadows from both lights by z-fail volumes).
SCALING_CASES: dict[str, tuple[bool, dict[str, object]]] = {
    **CASES,
    "shadow_volume": (False, {"shadows": "shadow_volume"}),
}

#: Series whose points also count fragments (rasterized, kept, bytes): the opaque path and the A-buffer.
CENSUS_CASES = ("plain", "a_buffer")


def _census(scene: bp.Scene, width: int, height: int) -> dict[str, int]:
    """Fragments of a frame: rasterized (all, and of transparent meshes) against kept by the visibility stage.

    ``kept_*`` and ``kept_bytes`` are what :func:`blinn_phong.frame.visibility.frame_fragments` holds
    (the nearest opaque fragment per sample and the transparent ones in front of it);
    ``rasterized_bytes`` is what an array of every rasterized fragment would take at the same
    bytes per fragment.
    """
    from blinn_phong.frame.prepared import prepare_scene
    from blinn_phong.frame.resolve import side_tables
    from blinn_phong.frame.visibility import frame_fragments, rasterized_count

    prepared = prepare_scene(scene)
    _, side_opaque = side_tables(scene)
    two_sided = scene.light_model.two_sided

    def opaque(triangle: np.ndarray, front_facing: np.ndarray) -> np.ndarray:  # as render_frame's
        back = ~front_facing if two_sided else False
        return side_opaque[2 * prepared.triangle_mesh[triangle] + back]

    visible = frame_fragments(prepared.clip, prepared.triangles, width, height, opaque=opaque, engine="numba")
    n_keys = width * height
    per_fragment = (visible.nbytes - 16 * n_keys - 8) / max(1, len(visible.fragments))
    transparent_mesh = np.array([m.material.transparent for m in scene.meshes])
    see_through = prepared.triangles[transparent_mesh[prepared.triangle_mesh]]
    counts = {
        "rasterized": rasterized_count(prepared.clip, prepared.triangles, width, height),
        "rasterized_transparent": rasterized_count(prepared.clip, see_through, width, height),
        "kept_opaque": visible.n_opaque,
        "kept_transparent": visible.n_transparent,
        "kept_bytes": visible.nbytes,
    }
    counts["rasterized_bytes"] = round(counts["rasterized"] * per_fragment) + 16 * n_keys + 8
    return counts


def _child(case: str, points: list[tuple[int, int, int]]) -> list[dict[str, object]]:
    """Renders in this (fresh) process, in the given order: seconds, stage times, peak RSS.

    The peak resident set only grows, so points are given in increasing size: each one's peak is its own
    (the smaller renders before it need less). Cases of :data:`CENSUS_CASES` also count their
    fragments (:func:`_census`, after the peak is read).
    """
    out = []
    for width, height, segments in points:
        transparent, options = SCALING_CASES[case]
        scene = issue_scene(segments, segments // 2, transparent)
        bp.render(scene, 64, 36, **options)  # type: ignore[arg-type]  # loads the compiled kernels
        baseline = _peak_rss_bytes()
        start, cpu = time.perf_counter(), time.process_time()
        result = bp.render(scene, width, height, **options)  # type: ignore[arg-type]
        seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
        point = {
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
            "shadow_plan": [c.method for c in result.plan.shadows] if result.plan else None,
        }
        del result
        if case in CENSUS_CASES:
            point["fragments"] = _census(scene, width, height)
        out.append(point)
    return out


def _in_fresh_process(case: str, points: list[tuple[int, int, int]]) -> list[dict[str, object]]:
    """:func:`_child` in a new interpreter (its own peak RSS), returning its points."""
    cmd = [sys.executable, "-m", "benchmarks.bench_frame", "--child", case, json.dumps(points)]
    done = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def scaling_series(segments: int, quick: bool = False) -> dict[str, list[dict]]:
    """Time and peak RSS of every :data:`SCALING_CASES` row against pixels and against triangles.

    Pixels: 480×270 … 3840×2160 with ``segments``-segment spheres (``quick``: 240×135 and
    480×270); triangles: spheres of 64×32 … 512×256 segments at 960×540 (``quick``: 32×16 and
    64×32 at 240×135, plain and A-buffer only). Each series runs in one fresh process, in
    increasing size (a few seconds of start-up each).
    """
    if quick:
        sizes, tessellations, fixed = [(240, 135), (480, 270)], [32, 64], (240, 135)
    else:
        sizes = [(480, 270), (960, 540), (1920, 1080), (3840, 2160)]
        tessellations, fixed = [64, 128, 256, 512], (960, 540)
    series: dict[str, list[dict]] = {"pixels": [], "triangles": []}
    for case in SCALING_CASES:
        print(f"   scaling {case}", flush=True)
        series["pixels"] += _in_fresh_process(case, [(w, h, segments) for w, h in sizes])
        if not quick or case in CENSUS_CASES:  # quick: the triangle series of two cases only
            series["triangles"] += _in_fresh_process(case, [(*fixed, s) for s in tessellations])
    return series


#: The small scene of the fixed per-frame costs: a 64-segment UV sphere at 640×360.
SMALL_SPHERE = (64, 32, 640, 360)


def small_sphere_scene() -> bp.Scene:
    """One ``uv_sphere(64, 32)`` (per-pixel Blinn-Phong) under a directional and a point light:
    the frame whose cost is mostly fixed per-frame work (planning, set-up, buffers)."""
    segments, rings, width, height = SMALL_SPHERE
    positions, triangles, normals = uv_sphere(segments, rings)
    material = bp.Material(diffuse=(0.8, 0.3, 0.2), specular=(0.5, 0.5, 0.5), shininess=32.0)
    camera = bp.Camera.perspective(40.0, width / height, 0.1, 100.0, view=bp.look_at((0, 0.5, 4), (0, 0, 0)))
    lights = [bp.DirectionalLight(direction=(-1.0, -1.0, -1.0)), bp.PointLight(position=(2.0, 3.0, 2.0))]
    return bp.Scene([bp.Mesh(positions, triangles, normals, material=material)], lights, camera)


def _peer_row(name: str, scene: bp.Scene, width: int, height: int, repeat: int) -> dict[str, object]:
    """Our plain frame (``shadows="none"``) and Mesa's GLSL frame of ``scene``, interleaved."""
    from oracles import gl_lighting

    bp.render(scene, width, height, shadows="none")  # warm-up: kernels, first-touch pages
    gl_lighting.render_glsl_phong(scene, width, height)
    wall: dict[str, list[float]] = {"ours": [], "mesa_glsl": []}
    cpu: dict[str, list[float]] = {"ours": [], "mesa_glsl": []}
    stages: list[dict[str, float]] = []
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = bp.render(scene, width, height, shadows="none")
        wall["ours"].append(time.perf_counter() - start)
        cpu["ours"].append(time.process_time() - start_cpu)
        stages.append(dict(result.stats.seconds))
        frame = gl_lighting.render_glsl_phong(scene, width, height, repeats=1)
        wall["mesa_glsl"].append(frame.seconds)
        cpu["mesa_glsl"].append(frame.cpu_seconds)
    med = {k: float(np.median(v)) for k, v in wall.items()}
    med_cpu = {k: float(np.median(v)) for k, v in cpu.items()}
    return {
        "scene": name,
        "triangles": sum(len(m.triangles) for m in scene.meshes),
        "size": [width, height],
        "median_s": med,
        "median_cpu_s": med_cpu,
        "runs_s": wall,
        "runs_cpu_s": cpu,
        "stage_median_s": {k: float(np.median([s.get(k, 0.0) for s in stages])) for k in stages[0]},
        "ratio_to_mesa": med["ours"] / med["mesa_glsl"],
        "cpu_ratio_to_mesa": med_cpu["ours"] / med_cpu["mesa_glsl"],
    }


def mesa_peer(repeat: int = 3) -> dict[str, object] | None:
    """Plain compiled frames vs Mesa llvmpipe GLSL, interleaved: two rows.

    * :mod:`benchmarks.bench_renderer`'s scene (about 100k triangles, four lights, 1920×1080);
    * :func:`small_sphere_scene` (a 64-segment sphere at 640×360): the fixed per-frame costs.

    Each row holds medians of wall and process CPU seconds (llvmpipe's threads included), our
    stage times and the ratios (ours / Mesa); the first row's fields are also at the top level
    (as before the second row existed). None when no EGL context can be made.
    """
    from benchmarks.bench_renderer import HEIGHT, WIDTH, build_scene
    from oracles.egl import EGLUnavailable, gl_context

    try:
        gl_context()
        from oracles import gl_lighting  # noqa: F401
    except EGLUnavailable as exc:
        print(f"Mesa unavailable, no peer ratio: {exc}")
        return None
    big = _peer_row("benchmarks.bench_renderer.build_scene()", build_scene(), WIDTH, HEIGHT, repeat)
    segments, rings, width, height = SMALL_SPHERE
    small = _peer_row(
        f"benchmarks.bench_frame.small_sphere_scene() (uv_sphere({segments}, {rings}))",
        small_sphere_scene(),
        width,
        height,
        max(repeat, 5),  # a short frame: more runs for a stable median
    )
    return {**big, "rows": [big, small]}


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
    series: dict[str, list[dict]] = {"pixels": [], "triangles": []}
    previous = Path(out_dir) / ("frame_quick.json" if quick else "frame.json")
    if scaling:
        series = scaling_series(segments, quick)
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
    write_json(previous, data)  # a quick run never replaces the full measurement
    return data


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
        for row in peer.get("rows", [peer]):
            w, h = row["size"]
            ours, mesa = row["median_s"]["ours"] * 1e3, row["median_s"]["mesa_glsl"] * 1e3
            print(
                f"plain frame vs Mesa llvmpipe ({row['triangles']} triangles, {w}×{h}): "
                f"ours {ours:.1f} ms, Mesa {mesa:.1f} ms, "
                f"wall {row['ratio_to_mesa']:.2f}×, CPU {row['cpu_ratio_to_mesa']:.2f}×"
            )
    if args.charts is not None:
        from benchmarks.charts import frame_scaling_chart  # matplotlib only when charts are asked for

        for path in frame_scaling_chart(data, args.charts / "charts"):
            print(f"chart {path}")


if __name__ == "__main__":
    main()
