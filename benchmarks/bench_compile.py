"""Compile cost: seconds to the first image, compile seconds per kernel family and peak memory.

Every case runs in a fresh Python process whose kernel cache
(``BLINN_PHONG_KERNEL_CACHE``, :mod:`compositing._kernel_cache`) is a new, empty directory —
cold: every kernel the case needs is compiled — then in a second fresh process with the cache
the first one left — warm: every kernel is loaded. Cases (320×180, the quick start's red
sphere on a grey floor under a sun and a point light, unless stated):

* ``plain``: no shadows, no transparency (the plain z-buffer frame), 4 samples;
* ``plain_one_sample``: the same at 1 sample, the fused pass (the baseline of the one-sample
  method cases: what a method's first use adds to the plain frame);
* ``shadows_<method>``: each shadow method (``planar``, ``shadow_map``, ``ray_traced``,
  ``shadow_volume``, ``soft``) for both lights, 1 sample;
* ``transparency_<method>``: each transparency method, with a transparent sphere, 1 sample;
* ``fog``: exponential fog on the plain frame; ``textures``: a texture on the floor;
* ``quickstart`` and ``readme_busy``: the README's first and second Python blocks as written
  (the busy scene renders five times);
* ``preview``: Blender's material preview through the engine (``bpy``; 128×128 previews);
* ``batch``: ``python -m addon.batch blend_files/shadows.blend --frames 1-2 --workers 2``.

Measured per run, by the parent process: seconds from the process's start to its first image
(the first ``blinn_phong.frame.render`` returning; the first preview; the first output file of the
batch) and to its exit, its CPU seconds (user + system, with its reaped descendants: the batch
workers) and the peak resident memory of the largest process of the run (``ru_maxrss`` from
``os.wait4``). Measured inside, with numba's ``numba:compile`` event
(:func:`compositing._kernel_cache.compile_clock`): compile seconds, wall and the compiling
thread's CPU, per module and per kernel (a kernel's own time; numba library functions it
compiled count as its time). The batch's compile seconds are the sum over its frames of the
engine's ``stats["compile"]``. On a shared machine the wall times stretch with the load; the
CPU seconds much less.

Usage::

    python -m benchmarks.bench_compile --out benchmarks/results [--charts docs] [--only plain ...]

Writes ``compile.json`` (``--only``: ``compile_<cases>.json``, never replacing the full run) and,
with ``--charts``, ``<dir>/charts/compile.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from benchmarks._util import machine_info, markdown_table, save_figure, write_json

REPO = Path(__file__).resolve().parents[1]
MARK = "@@COMPILE@@"

SCENE = """
import numpy as np
import blinn_phong as bp
from blinn_phong.model.primitives import grid_plane, uv_sphere

positions, triangles, normals = uv_sphere(48, 24)
red = bp.Material(diffuse=(0.8, 0.1, 0.1), specular=(0.5, 0.5, 0.5), shininess=40.0)
sphere = bp.Mesh(positions, triangles, normals, material=red)
fp, ft, fn = grid_plane(1, 1, size=(8.0, 8.0))
lay_flat = np.array([[1, 0, 0, 0], [0, 0, 1, -1], [0, -1, 0, 0], [0, 0, 0, 1]], float)
floor = bp.Mesh(fp, ft, fn, transform=lay_flat)
lights = [bp.DirectionalLight(direction=(-1.0, -2.0, -1.0)), bp.PointLight(position=(2, 3, 2))]
camera = bp.Camera.perspective(40.0, 320 / 180, 0.1, 100.0, view=bp.look_at((0, 1.5, 6), (0, 0, 0)))
opaque = bp.Scene([sphere, floor], lights, camera)
glass_material = bp.Material(diffuse=(0.1, 0.3, 0.8), opacity=0.5)
moved = np.array([[0.6, 0, 0, 0.8], [0, 0.6, 0, -0.2], [0, 0, 0.6, 0.9], [0, 0, 0, 1]], float)
glass = bp.Mesh(positions, triangles, normals, transform=moved, material=glass_material)
see_through = bp.Scene([sphere, floor, glass], lights, camera)
"""

SHADOW_METHODS = ("planar", "shadow_map", "ray_traced", "shadow_volume", "soft")
TRANSPARENCY_METHODS = (
    "draw_last",
    "sort_objects",
    "sort_triangles",
    "depth_peeling",
    "a_buffer",
    "weighted_blended",
)


def python_blocks(text: str) -> list[str]:
    """The contents of the ```python fenced blocks of a Markdown text, in order."""
    return re.findall(r"^```python\n(.*?)^```$", text, flags=re.S | re.M)


def _python_cases() -> dict[str, str]:
    cases = {"plain": SCENE + 'bp.render(opaque, 320, 180, samples=4, shadows="none")\n'}
    cases["plain_one_sample"] = SCENE + 'bp.render(opaque, 320, 180, shadows="none")\n'
    for method in SHADOW_METHODS:
        shadows = 'bp.ShadowOptions("soft", radius=0.3)' if method == "soft" else repr(method)
        cases[f"shadows_{method}"] = SCENE + f"bp.render(opaque, 320, 180, shadows={shadows})\n"
    for method in TRANSPARENCY_METHODS:
        cases[f"transparency_{method}"] = (
            SCENE + f'bp.render(see_through, 320, 180, shadows="none", transparency={method!r})\n'
        )
    fog = 'fog=bp.Fog(mode="exp", density=0.1)'
    cases["fog"] = SCENE + f'bp.render(opaque, 320, 180, shadows="none", {fog})\n'
    cases["textures"] = SCENE + (
        "checker = ((np.indices((64, 64)).sum(axis=0) // 8) % 2).astype(np.float32)\n"
        "image = np.stack([checker, 0.5 * checker + 0.25, 1 - checker, np.ones_like(checker)], axis=-1)\n"
        "textured = bp.Material(base_color_texture=bp.Texture(image))\n"
        "floor = bp.Mesh(fp, ft, fn, transform=lay_flat, uv=fp[:, :2] / 8.0 + 0.5, material=textured)\n"
        'bp.render(bp.Scene([sphere, floor], lights, camera), 320, 180, shadows="none")\n'
    )
    blocks = python_blocks((REPO / "README.md").read_text(encoding="utf-8"))
    cases["quickstart"] = blocks[0]
    cases["readme_busy"] = blocks[1]
    return cases


CHILD = """
import json, sys, time
import blinn_phong as bp
from compositing._kernel_cache import compile_clock

first = []
_render = bp.render


def render(*args, **kwargs):
    result = _render(*args, **kwargs)
    if not first:
        first.append(time.time())
    return result


bp.render = render
source = open(sys.argv[1], encoding="utf-8").read()
with compile_clock() as log:
    exec(compile(source, "<case>", "exec"), {"__name__": "__case__"})
print("__MARK__" + json.dumps({
    "first_image_at": first[0], "compile_s": log.seconds, "by_module": dict(log.by_module),
    "compile_cpu_s": log.cpu_seconds, "cpu_by_module": dict(log.cpu_by_module),
    "cpu_by_kernel": dict(log.cpu_by_kernel), "compilations": log.compiled,
}), flush=True)
""".replace("__MARK__", MARK)

PREVIEW = """
import json, sys, time
sys.path.insert(0, sys.argv[2])
import bpy
from addon import engine, properties
from compositing._kernel_cache import compile_clock

properties.register()
engine.register()
first = []
original = engine.render_converted


def capture(converted, progress=None):
    result = original(converted, progress)
    if not first:
        first.append(time.time())
    return result


engine.render_converted = capture
try:
    bpy.context.scene.render.engine = engine.ENGINE_ID
    material = bpy.data.materials.new("Preview")
    material.use_nodes = True
    node = material.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (0.8, 0.2, 0.1, 1.0)
    with compile_clock() as log:
        material.preview_ensure()
        bpy.ops.wm.previews_ensure()
    print("__MARK__" + json.dumps({
        "first_image_at": first[0], "compile_s": log.seconds, "by_module": dict(log.by_module),
        "compile_cpu_s": log.cpu_seconds, "cpu_by_module": dict(log.cpu_by_module),
        "cpu_by_kernel": dict(log.cpu_by_kernel), "compilations": log.compiled,
        "previews": len(engine.PREVIEW_TIMES),
        "ok": engine.LAST_PREVIEW.get("ok"),
    }), flush=True)
finally:
    engine.render_converted = original
    engine.unregister()
    properties.unregister()
""".replace("__MARK__", MARK)


def _measure(command: list[str], env: dict[str, str], cwd: Path, watch: Path | None, timeout: float) -> dict:
    """Run ``command``; wall seconds, first output file under ``watch``, stdout, peak RSS (``wait4``)."""
    started = time.time()
    pipe = subprocess.PIPE
    proc = subprocess.Popen(command, env=env, cwd=cwd, stdout=pipe, stderr=pipe, text=True)
    streams: dict[str, str] = {}

    def drain(name: str, stream: object) -> None:
        streams[name] = stream.read()

    readers = [
        threading.Thread(target=drain, args=("out", proc.stdout)),
        threading.Thread(target=drain, args=("err", proc.stderr)),
    ]
    for reader in readers:
        reader.start()
    first_file: list[float] = []
    done = threading.Event()

    def watch_files() -> None:
        while not done.wait(0.05):
            # the outputs (frame_####.*), renamed into place once whole; not the workers' markers
            if any(p.is_file() and p.stat().st_size > 0 for p in watch.glob("frame_*")):
                first_file.append(time.time())
                return

    def kill() -> None:
        if not done.wait(timeout):
            proc.kill()

    helpers = [threading.Thread(target=kill, daemon=True)]
    if watch is not None:
        helpers.append(threading.Thread(target=watch_files, daemon=True))
    for helper in helpers:
        helper.start()
    _pid, status, usage = os.wait4(proc.pid, 0)
    ended = time.time()
    done.set()
    proc.returncode = os.waitstatus_to_exitcode(status)
    for reader in readers:
        reader.join()
    return {
        "started": started,
        "wall_s": ended - started,
        "first_file_s": first_file[0] - started if first_file else None,
        "returncode": proc.returncode,
        "stdout": streams.get("out", ""),
        "stderr": streams.get("err", ""),
        "peak_rss_gb": usage.ru_maxrss * 1024 / 1e9,  # ru_maxrss is in KiB on Linux
        "cpu_s": usage.ru_utime + usage.ru_stime,  # the process and its reaped descendants
    }


def _report(run: dict) -> dict:
    lines = [line[len(MARK) :] for line in run["stdout"].splitlines() if line.startswith(MARK)]
    if run["returncode"] != 0 or not lines:
        raise RuntimeError(f"case failed (exit {run['returncode']}):\n{run['stderr'][-3000:]}")
    return json.loads(lines[-1])


def run_case(name: str, cache: Path, scratch: Path, cases: dict[str, str], timeout: float = 1800) -> dict:
    """One run of case ``name`` in a fresh process with kernel cache ``cache``."""
    env = {**os.environ, "BLINN_PHONG_KERNEL_CACHE": str(cache), "PYTHONPATH": str(REPO)}
    env.pop("NUMBA_CACHE_DIR", None)
    scratch.mkdir(parents=True, exist_ok=True)
    if name == "batch":
        out = scratch / "batch"
        command = [
            sys.executable, "-m", "addon.batch", str(REPO / "blend_files" / "shadows.blend"),
            "--frames", "1-2", "--workers", "2", "--out", str(out), "--output-pattern", "frame_####",
        ]  # fmt: skip
        run = _measure(command, env, REPO, out, timeout)
        if run["returncode"] != 0:
            raise RuntimeError(f"batch failed (exit {run['returncode']}):\n{run['stderr'][-3000:]}")
        report = json.loads((out / "report.json").read_text())
        tasks = report["tasks"]
        compile_s = sum((t.get("render") or {}).get("stats", {}).get("compile", 0.0) for t in tasks)
        return {
            "first_image_s": run["first_file_s"],
            "exit_s": run["wall_s"],
            "cpu_s": run["cpu_s"],
            "peak_rss_gb": run["peak_rss_gb"],
            "compile_s": compile_s,
            "by_module": {},
            "frames": len(tasks),
        }
    if name == "preview":
        script = scratch / "preview.py"
        script.write_text(PREVIEW, encoding="utf-8")
        run = _measure([sys.executable, str(script), "-", str(REPO)], env, scratch, None, timeout)
    else:
        source = scratch / f"{name}.py"
        source.write_text(cases[name], encoding="utf-8")
        script = scratch / "child.py"
        script.write_text(CHILD, encoding="utf-8")
        run = _measure([sys.executable, str(script), str(source)], env, scratch, None, timeout)
    child = _report(run)

    def ranked(values: dict[str, float], top: int | None = None) -> dict[str, float]:
        return {k: round(v, 3) for k, v in sorted(values.items(), key=lambda kv: -kv[1])[:top]}

    return {
        "first_image_s": child["first_image_at"] - run["started"],
        "exit_s": run["wall_s"],
        "cpu_s": run["cpu_s"],
        "peak_rss_gb": run["peak_rss_gb"],
        "compile_s": child["compile_s"],
        "compile_cpu_s": child["compile_cpu_s"],
        "by_module": ranked(child["by_module"]),
        "cpu_by_module": ranked(child["cpu_by_module"]),
        "cpu_by_kernel_top": ranked(child["cpu_by_kernel"], 12),
        "compilations": child.get("compilations"),
    }


def all_cases() -> list[str]:
    """Every case name, in the order they run."""
    return [*_python_cases(), "preview", "batch"]


def run(out: Path, only: list[str] | None = None) -> dict:
    """Measure every case (or ``only`` those) cold then warm; write and return the JSON."""
    cases = _python_cases()
    names = only or all_cases()
    unknown = sorted(set(names) - set(all_cases()))
    if unknown:
        raise ValueError(f"only: unknown case(s) {unknown}; expected some of {all_cases()}")
    results: dict[str, dict] = {}
    path = out / ("compile.json" if not only else "compile_" + "_".join(names)[:80] + ".json")
    data = {"benchmark": "compile", "machine": machine_info(), "cases": results}
    with tempfile.TemporaryDirectory(prefix="bench-compile-") as tmp:
        for name in names:
            cache = Path(tmp) / name / "kernels"
            row = {}
            for state in ("cold", "warm"):
                print(f"== {name} {state}", flush=True)
                row[state] = run_case(name, cache, Path(tmp) / name / state, cases)
                got = row[state]
                print(
                    f"   first image {got['first_image_s']:.1f} s, compile {got['compile_s']:.1f} s, "
                    f"peak {got['peak_rss_gb']:.2f} GB",
                    flush=True,
                )
            row["cache_mb"] = sum(p.stat().st_size for p in cache.rglob("*") if p.is_file()) / 1e6
            results[name] = row
            write_json(path, data)  # after every case: an interrupted run keeps what it measured
    data["machine"]["load_average_1min_end"] = machine_info().get("load_average_1min")
    write_json(path, data)
    return data


def table(data: dict) -> str:
    """The results as a markdown table (cold and warm side by side)."""
    rows = []
    for name, row in data["cases"].items():
        cold, warm = row["cold"], row["warm"]
        by = cold.get("cpu_by_module") or cold["by_module"]
        top = ", ".join(f"{m} {s:.0f}" for m, s in list(by.items())[:3])
        rows.append([
            name, f"{cold['first_image_s']:.1f}", f"{cold['cpu_s']:.0f}", f"{cold['compile_s']:.1f}",
            f"{cold.get('compile_cpu_s', float('nan')):.1f}", f"{cold['peak_rss_gb']:.2f}",
            f"{warm['first_image_s']:.1f}", f"{warm['compile_s']:.2f}", f"{warm['peak_rss_gb']:.2f}", top,
        ])  # fmt: skip
    header = [
        "case", "cold: first image s", "CPU s", "compile s", "compile CPU s", "peak GB",
        "warm: first image s", "compile s", "peak GB", "cold compile CPU s by module (top 3)",
    ]  # fmt: skip
    return markdown_table(header, rows)


def draw(data: dict, charts: Path) -> Path:
    """Horizontal bars per case: cold compile CPU seconds per module (stacked); the cold first image."""
    from benchmarks.charts import DPI, plt

    names = list(data["cases"])

    def by(row: dict) -> dict[str, float]:
        return row["cold"].get("cpu_by_module") or row["cold"]["by_module"]

    modules = sorted({m for row in data["cases"].values() for m in by(row)})
    totals = {m: sum(by(row).get(m, 0.0) for row in data["cases"].values()) for m in modules}
    modules.sort(key=lambda m: -totals[m])
    shown = modules[:9]
    fig, ax = plt.subplots(figsize=(9, 0.35 * len(names) + 1.8))
    left = [0.0] * len(names)
    colours = plt.get_cmap("tab10")
    for k, module in enumerate([*shown, "other"]):
        widths = [
            sum(v for m, v in by(row).items() if m not in shown)
            if module == "other"
            else by(row).get(module, 0.0)
            for row in data["cases"].values()
        ]
        ax.barh(names, widths, left=left, color=colours(k % 10), label=module)
        left = [a + b for a, b in zip(left, widths, strict=True)]
    ax.scatter(
        [row["cold"]["first_image_s"] for row in data["cases"].values()],
        names,
        color="black",
        marker="|",
        s=200,
        label="first image, wall seconds",
        zorder=3,
    )
    ax.invert_yaxis()
    ax.set_xlabel(
        "seconds; fresh process, empty kernel cache. Bars: compile CPU seconds per module "
        f"(2-core VM, load {data['machine'].get('load_average_1min')})",
        fontsize=8,
    )
    ax.set_title("Compile cost before the first image")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    path = save_figure(fig, charts / "compile.png", dpi=DPI)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    """Command-line entry: run, print the table, optionally draw the chart."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    parser.add_argument("--charts", type=Path, default=None, help="docs directory (PNG in <dir>/charts)")
    parser.add_argument("--only", action="append", choices=all_cases(), help="only this case (repeatable)")
    args = parser.parse_args(argv)
    data = run(args.out, args.only)
    print(table(data))
    if args.charts is not None:
        print(f"chart {draw(data, args.charts / 'charts')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
