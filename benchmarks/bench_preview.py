"""Material preview: the engine's time per preview at Blender's preview size (128×128).

Blender renders the Material tab's preview with the engine (``bl_use_preview``); previews are small
and frequent, so fixed per-frame costs dominate. One bpy process (the bpy module renders previews
in background mode through ``bpy.ops.wm.previews_ensure``) renders the previews of a Principled
material; the converted preview scene of the 128×128 preview is then rendered again, interleaved,
with the compiled kernels and with the numpy kernels (the peer), after one untimed warm-up each
(numba compiles or loads its cache once per process; that time is reported apart).

Usage::

    python -m benchmarks.bench_preview --out benchmarks/results [--repeat 7]

Writes ``preview.json``: the whole preview (conversion + render + writing into Blender) per call,
and the render alone for compiled and numpy kernels, medians and minima, and their ratio.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks._util import machine_info, write_json

REPO = Path(__file__).resolve().parents[1]
MARK = "@@PREVIEW@@"

SCRIPT = """
import json, sys, time
sys.path.insert(0, sys.argv[1])
import bpy
from dataclasses import replace
from addon import engine, pipeline, properties
from benchmarks._util import time_interleaved
properties.register()
engine.register()
captured = {}
original = engine.render_converted
def capture(converted, progress=None):
    captured[converted.region_size] = converted
    return original(converted, progress)
engine.render_converted = capture
try:
    bpy.context.scene.render.engine = engine.ENGINE_ID
    material = bpy.data.materials.new("Preview")
    material.use_nodes = True
    node = material.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (0.8, 0.2, 0.1, 1.0)
    node.inputs["Roughness"].default_value = 0.3
    material.preview_ensure()
    bpy.ops.wm.previews_ensure()
    previews = list(engine.PREVIEW_TIMES)
    converted = captured[(128, 128)]
    compile_seconds = pipeline.warm_kernels("AUTO")
    numba_scene = converted
    numpy_scene = replace(converted, options=replace(converted.options, engine="NUMPY"))
    timings = time_interleaved(
        {"compiled": lambda: original(numba_scene), "numpy": lambda: original(numpy_scene)},
        repeat=int(sys.argv[2]),
    )
    last = engine.LAST_PREVIEW
    print("__MARK__" + json.dumps({
        "previews": previews, "timings": timings, "triangles": last.get("triangles"),
        "engine": last.get("choices", {}).get("engine"), "compile_s_in_process": compile_seconds,
        "stages": last.get("stats"),
    }), flush=True)
finally:
    engine.render_converted = original
    bpy.context.scene.render.engine = "CYCLES"
    engine.unregister()
    properties.unregister()
""".replace("__MARK__", MARK)


def run(out: Path, repeat: int = 7) -> dict:
    """Run the benchmark in a bpy subprocess; write and return ``out/preview.json``."""
    with tempfile.TemporaryDirectory() as scratch:
        script = Path(scratch) / "preview.py"
        script.write_text(SCRIPT, encoding="utf-8")
        done = subprocess.run(
            [sys.executable, str(script), str(REPO), str(repeat)],
            capture_output=True,
            text=True,
            timeout=900,
            cwd=scratch,
            check=False,
        )
    lines = [line[len(MARK) :] for line in done.stdout.splitlines() if line.startswith(MARK)]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"preview benchmark failed (exit {done.returncode}):\n{done.stderr[-3000:]}")
    data = json.loads(lines[-1])
    full = [seconds for width, _height, seconds in data["previews"] if width == 128]
    timings = data["timings"]
    result = {
        "machine": machine_info(),
        "preview_size": [128, 128],
        "triangles": data["triangles"],
        "engine": data["engine"],
        "preview_calls_128_s": full,
        "first_preview_s_including_compile": data["previews"][0][2] if data["previews"] else None,
        "render_only": timings,
        "stages_s_last_preview": data["stages"],
        "numpy_over_compiled": timings["numpy"]["median_s"] / timings["compiled"]["median_s"],
        "target_s": 0.2,
    }
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "preview.json", result)
    return result


def main(argv: list[str] | None = None) -> int:
    """Command-line entry: run, print a summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args(argv)
    result = run(args.out, args.repeat)
    r = result["render_only"]
    print(
        f"preview 128×128, {result['triangles']} triangles: compiled {r['compiled']['median_s']:.3f} s, "
        f"numpy {r['numpy']['median_s']:.3f} s (×{result['numpy_over_compiled']:.1f}); whole preview calls "
        + ", ".join(f"{s:.3f}" for s in result["preview_calls_128_s"])
        + " s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
