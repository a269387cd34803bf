"""Renderer speed against Mesa llvmpipe, measured in the same run, and how it scales.

Scene: four UV spheres and a floor (about 100k triangles), four lights (directional,
attenuated point, spot, second point), per-pixel Blinn-Phong (``shading="phong"``),
rendered at 1920×1080 by

* ``blinn_phong.frame.render(engine="numba")`` — the compiled fast path,
* ``blinn_phong.frame.render(engine="numpy")`` — the numpy reference,
* Mesa llvmpipe running the per-pixel GLSL shader of ``oracles.gl_lighting`` on the
  same scene (geometry in buffer objects, time per frame including ``glFinish``).

Runs are interleaved (numba, numpy, Mesa, numba, ...) so machine load hits all alike;
the medians are compared, for wall time and for process CPU time (all threads,
llvmpipe's worker threads included — they run in this process), which is robust to
other programs competing for the cores. The same scene is also rendered with ``gl_compat=True`` and
compared with the Mesa image (8-bit difference on pixels both cover).

Scaling: CPU time of the numba and numpy engines as the triangle count grows at 1920×1080,
and as the pixel count grows at about 100k triangles, with a least-squares line
(time = a + b·x) and its R² to show whether growth is linear.

Usage::

    .venv/bin/python -m benchmarks.bench_renderer [--out benchmarks/results] [--repeat 3] [--charts docs]

Writes ``renderer.json`` to ``--out`` (and ``renderer_scaling.png`` to ``--charts``).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from benchmarks._util import machine_info, markdown_table, save_figure, write_json

__all__ = ["main", "run"]

WIDTH, HEIGHT = 1920, 1080


def build_scene(segments: int = 160) -> object:  # a blinn_phong.Scene
    """Four spheres of ``2·segments·(segments/2 - 1)`` triangles each, a 800-triangle floor, 4 lights."""
    import blinn_phong as bp
    from blinn_phong.model.primitives import grid_plane, uv_sphere

    meshes = []
    colours = [(0.7, 0.3, 0.2), (0.2, 0.5, 0.8), (0.8, 0.7, 0.2), (0.3, 0.7, 0.4)]
    for (x, z), colour in zip([(-1.6, 0.0), (1.6, 0.0), (0.0, -2.2), (0.0, 1.6)], colours, strict=True):
        pos, tris, normals = uv_sphere(segments, segments // 2)
        transform = np.eye(4)
        transform[:3, 3] = (x, 0.0, z)
        material = bp.Material(ambient=colour, diffuse=colour, specular=(0.9, 0.9, 0.9), shininess=48.0)
        meshes.append(bp.Mesh(pos, tris, normals, transform=transform, material=material))
    pos, tris, normals = grid_plane(20, 20, (14.0, 14.0))
    floor = np.array([[1, 0, 0, 0], [0, 0, 1, -1], [0, -1, 0, 0], [0, 0, 0, 1]], float)
    meshes.append(bp.Mesh(pos, tris, normals, transform=floor, material=bp.Material(diffuse=(0.5, 0.5, 0.5))))
    lights = [
        bp.DirectionalLight((-1.0, -1.0, -1.0), (0.8, 0.8, 0.8)),
        bp.PointLight((3.0, 3.0, 3.0), (0.9, 0.7, 0.5), linear=0.1, quadratic=0.02),
        bp.SpotLight((0.0, 5.0, 0.5), (0.0, -1.0, -0.1), cutoff=40.0, exponent=4.0, color=(0.5, 0.6, 1.0)),
        bp.PointLight((-3.0, 2.0, 3.0), (0.3, 0.3, 0.6), quadratic=0.05),
    ]
    camera = bp.Camera.perspective(45.0, WIDTH / HEIGHT, 0.5, 50.0, view=bp.look_at((0, 3, 8), (0, 0, 0)))
    return bp.Scene(meshes, lights, camera, ambient=(0.1, 0.1, 0.1))


def _line_fit(x: list[float], y: list[float]) -> dict[str, float]:
    xs, ys = np.asarray(x, float), np.asarray(y, float)
    slope, intercept = np.polyfit(xs, ys, 1)
    pred = intercept + slope * xs
    ss_res = float(((ys - pred) ** 2).sum())
    ss_tot = float(((ys - ys.mean()) ** 2).sum())
    return {"intercept_s": float(intercept), "slope_s_per_unit": float(slope), "r2": 1 - ss_res / ss_tot}


def _time_render(
    scene: object, width: int, height: int, engine: str
) -> tuple[float, float, dict[str, float]]:
    """(wall seconds, process CPU seconds, stage seconds) of one render."""
    import blinn_phong as bp

    start, cpu_start = time.perf_counter(), time.process_time()
    # Like for like with Mesa, which draws neither shadows nor sorted transparency: the
    # planner would otherwise add ray-traced shadows to this multi-object scene.
    result = bp.render(
        scene, width, height, shading="phong", engine=engine, shadows="none", transparency="zbuffer"
    )
    return time.perf_counter() - start, time.process_time() - cpu_start, result.stats.seconds


def run(repeat: int = 3) -> dict[str, object]:
    """Run every measurement; returns the JSON-ready results."""
    import blinn_phong as bp
    from oracles.egl import EGLUnavailable, gl_context

    try:
        info = gl_context()
        from oracles import gl_lighting

        mesa: dict[str, object] | None = {"renderer": info.renderer, "version": info.version}
    except EGLUnavailable as exc:
        gl_lighting = None
        mesa = None
        print(f"Mesa unavailable, no ratio: {exc}")

    scene = build_scene()
    n_tris = sum(len(m.triangles) for m in scene.meshes)
    # Untimed warm-up at full size: numba compilation (or cache load), first-touch page faults.
    for engine in ("numba", "numpy"):
        bp.render(scene, WIDTH, HEIGHT, engine=engine, shadows="none", transparency="zbuffer")
    if gl_lighting is not None:
        gl_lighting.render_glsl_phong(scene, WIDTH, HEIGHT)

    # Headline: interleaved rounds at 1920×1080. Wall time is what a user waits; process CPU
    # time (all threads, llvmpipe's included) is the work done and is robust to machine load.
    wall: dict[str, list[float]] = {"numba": [], "numpy": [], "mesa_glsl": []}
    cpu: dict[str, list[float]] = {"numba": [], "numpy": [], "mesa_glsl": []}
    stages: dict[str, dict[str, float]] = {}
    for _ in range(repeat):
        for engine in ("numba", "numpy"):
            seconds, cpu_seconds, stage = _time_render(scene, WIDTH, HEIGHT, engine)
            wall[engine].append(seconds)
            cpu[engine].append(cpu_seconds)
            stages[engine] = stage
        if gl_lighting is not None:
            frame = gl_lighting.render_glsl_phong(scene, WIDTH, HEIGHT, repeats=1)
            wall["mesa_glsl"].append(frame.seconds)
            cpu["mesa_glsl"].append(frame.cpu_seconds)
    med = {k: statistics.median(v) for k, v in wall.items() if v}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items() if v}
    headline: dict[str, object] = {
        "width": WIDTH,
        "height": HEIGHT,
        "triangles": n_tris,
        "lights": len(scene.lights),
        "shading": "phong",
        "median_s": med,
        "median_cpu_s": med_cpu,
        "runs_s": wall,
        "runs_cpu_s": cpu,
        "stages_last_run_s": stages,
    }
    if "mesa_glsl" in med:
        headline["ratio_numba_to_mesa"] = med["numba"] / med["mesa_glsl"]
        headline["ratio_numpy_to_mesa"] = med["numpy"] / med["mesa_glsl"]
        headline["cpu_ratio_numba_to_mesa"] = med_cpu["numba"] / med_cpu["mesa_glsl"]
        headline["cpu_ratio_numpy_to_mesa"] = med_cpu["numpy"] / med_cpu["mesa_glsl"]
        # Agreement on the same frame: GL-compatible per-pixel render vs the Mesa image.
        ours = bp.render(scene, WIDTH, HEIGHT, shading="phong", gl_compat=True, engine="numba").rgba
        theirs = gl_lighting.render_glsl_phong(scene, WIDTH, HEIGHT).rgba.astype(np.int64)
        mine = np.floor(np.clip(ours, 0, 1) * 255 + 0.5).astype(np.int64)
        both = (mine[..., 3] > 0) & (theirs[..., 3] > 0)
        diff = np.abs(mine[..., :3] - theirs[..., :3]).max(axis=-1)[both]
        headline["agreement_with_mesa"] = {
            "pixels_compared": int(both.sum()),
            "coverage_mismatch_pixels": int(((mine[..., 3] > 0) != (theirs[..., 3] > 0)).sum()),
            "share_within_1_of_255": float((diff <= 1).mean()),
            "max_abs_diff_8bit": int(diff.max()),
            "mean_abs_diff_8bit": float(diff.mean()),
        }

    # Scaling with triangle count (1920×1080) and pixel count (~100k triangles): process CPU
    # time, the best of the runs, so other processes on the machine do not bend the curves.
    runs = max(1, repeat - 1)

    def best_cpu(s: object, width: int, height: int, engine: str) -> float:
        return min(_time_render(s, width, height, engine)[1] for _ in range(runs))

    tri_rows = []
    for segments in (40, 80, 113, 160, 226):
        s = build_scene(segments)
        row: dict[str, float] = {"triangles": sum(len(m.triangles) for m in s.meshes)}
        for engine in ("numba", "numpy"):
            row[f"{engine}_cpu_s"] = best_cpu(s, WIDTH, HEIGHT, engine)
        tri_rows.append(row)
    pix_rows = []
    for width, height in ((480, 270), (960, 540), (1440, 810), (1920, 1080), (2560, 1440)):
        row = {"width": width, "height": height, "pixels": width * height}
        for engine in ("numba", "numpy"):
            row[f"{engine}_cpu_s"] = best_cpu(scene, width, height, engine)
        pix_rows.append(row)

    def fits(rows: list[dict[str, float]], key: str) -> dict[str, object]:
        x = [r[key] for r in rows]
        return {
            "rows": rows,
            "fit_numba": _line_fit(x, [r["numba_cpu_s"] for r in rows]),
            "fit_numpy": _line_fit(x, [r["numpy_cpu_s"] for r in rows]),
        }

    scaling = {"triangles": fits(tri_rows, "triangles"), "pixels": fits(pix_rows, "pixels")}
    return {"machine": machine_info(), "mesa": mesa, "headline": headline, "scaling": scaling}


def _charts(results: dict[str, object], directory: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scaling = results["scaling"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, key, label in (
        (axes[0], "triangles", "triangles (1920×1080)"),
        (axes[1], "pixels", "pixels (~100k tris)"),
    ):
        rows = scaling[key]["rows"]
        x = [r[key] for r in rows]
        for engine in ("numba", "numpy"):
            ax.plot(x, [r[f"{engine}_cpu_s"] for r in rows], "o-", label=engine)
        ax.set_xlabel(label)
        ax.set_ylabel("CPU seconds per frame")
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.suptitle("blinn_phong.frame.render, phong shading, 4 lights")
    fig.tight_layout()
    save_figure(fig, directory / "renderer_scaling.png", dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=Path("benchmarks/results"), help="directory for renderer.json"
    )
    parser.add_argument("--repeat", type=int, default=3, help="interleaved rounds for the headline timing")
    parser.add_argument("--charts", type=Path, default=None, help="directory for renderer_scaling.png")
    args = parser.parse_args(argv)
    results = run(args.repeat)
    write_json(args.out / "renderer.json", results)
    head = results["headline"]
    rows = [[k, f"{head['median_s'][k]:.3f}", f"{head['median_cpu_s'][k]:.3f}"] for k in head["median_s"]]
    title = f"1920×1080, {head['triangles']} tris, 4 lights"
    print(markdown_table(["engine", f"median wall s ({title})", "median CPU s"], rows))
    if "ratio_numba_to_mesa" in head:
        ratios = {k: f"{v:.2f}" for k, v in head.items() if "ratio" in k}
        print("ratios to Mesa:", ratios)
        print("agreement with Mesa:", head["agreement_with_mesa"])
    for key in ("triangles", "pixels"):
        sc = results["scaling"][key]
        table = [[r[key], f"{r['numba_cpu_s']:.3f}", f"{r['numpy_cpu_s']:.3f}"] for r in sc["rows"]]
        print(markdown_table([key, "numba CPU s", "numpy CPU s"], table))
        print(f"linear fit R²: numba {sc['fit_numba']['r2']:.4f}, numpy {sc['fit_numpy']['r2']:.4f}")
    if args.charts is not None:
        _charts(results, args.charts)


if __name__ == "__main__":
    main()
