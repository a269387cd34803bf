"""Interactive frames never wait for a compile: the first frame renders with numpy while a
background process compiles the kernels; once it has finished, frames load them and compile
nothing (numba's own compile events, ``compositing._kernel_cache.compile_clock``).

Runs the add-on's frame path (``addon.pipeline``, no bpy) in a fresh process with an empty kernel
cache; the warm-up is limited to the frame's own case (``BLINN_PHONG_WARMUP_CASES``) to keep the
test short. Independent checks: the engines' images agree (the numpy engine is the reference the
compiled one is tested against, to float rounding), and the compile count is numba's.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import dataclasses, json, time
import numpy as np
from addon import pipeline
from addon.options import RenderOptions
from blinn_phong import warmup
from compositing._kernel_cache import compile_clock

scene = warmup._scenes()["opaque"]
options = RenderOptions(samples_per_axis=1, shadows="NONE")
pipeline.BACKGROUND_COMPILE = True
out = {}
started = time.perf_counter()
engine, note = pipeline.frame_engine(options.engine)
with compile_clock() as first_log:
    first = pipeline.render_frame(scene, 32, 18, dataclasses.replace(options, engine=engine))
out["first"] = {"engine": engine, "note": note, "kernels": first.choices["engine"],
                "compiled": first_log.compiled, "seconds": time.perf_counter() - started}
out["exit"] = pipeline._warmup["process"].wait(timeout=900)
engine, note = pipeline.frame_engine(options.engine)
with compile_clock() as log:
    second = pipeline.render_frame(scene, 32, 18, dataclasses.replace(options, engine=engine))
out["second"] = {"engine": engine, "note": note, "kernels": second.choices["engine"],
                 "compiled": log.compiled}
out["difference"] = float(np.abs(first.rgba - second.rgba).max())
choices = dict(first.choices, compile_note=out["first"]["note"])
out["status"] = pipeline.status_line(choices, 1.0, first.seconds)
print(json.dumps(out))
"""


@pytest.mark.slow
def test_the_first_frame_renders_with_numpy_while_the_kernels_compile(tmp_path: Path) -> None:
    env = {
        **os.environ, "PYTHONPATH": str(ROOT), "BLINN_PHONG_KERNEL_CACHE": str(tmp_path / "kernels"),
        "BLINN_PHONG_WARMUP_CASES": "plain 1 sample",
    }  # fmt: skip
    done = subprocess.run(
        [sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=1200, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr[-3000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    first, second = got["first"], got["second"]
    assert first["engine"] == "NUMPY" and first["kernels"] == "numpy"
    assert first["compiled"] == 0  # this process compiled nothing for its first frame
    assert "compiling in the background" in first["note"] and "compiling in the background" in got["status"]
    assert got["exit"] == 0
    assert second["engine"] == "AUTO" and second["kernels"] == "numba" and second["note"] is None
    assert second["compiled"] == 0  # every kernel of the frame was compiled by the background process
    assert got["difference"] <= 1e-6  # the engines agree to float rounding (test_engines_agree)


def test_without_a_user_interface_frames_compile_in_process() -> None:
    from addon import pipeline

    assert pipeline.BACKGROUND_COMPILE is False  # bpy.app.background, the batch, tests
    assert pipeline.frame_engine("AUTO") == ("AUTO", None)
    assert pipeline.frame_engine("NUMPY") == ("NUMPY", None)


F12 = """
import json, sys, time
import bpy
from addon import compat, engine, pipeline, properties, render_ui

bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
engine.register()
render_ui.register()
pipeline.BACKGROUND_COMPILE = True  # as with Blender's interface (bpy runs in background mode)
scene = bpy.context.scene
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.0, 0.0, 0.5))
bpy.ops.mesh.primitive_plane_add(size=8.0)
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location = (0.0, -6.0, 3.0)
cam.rotation_euler = (1.1, 0.0, 0.0)
scene.collection.objects.link(cam)
scene.camera = cam
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
scene.collection.objects.link(sun)
scene.render.engine = "BLINN_PHONG"
scene.render.film_transparent = True
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 40, 30, 100
scene.blinn_phong.samples_per_axis = 2
scene.blinn_phong.shadows = "NONE"
compat.set_image_format(scene.render.image_settings, "OPEN_EXR_MULTILAYER", "32")
out = {}
for tag in ("while_compiling", "compiled"):
    scene.render.filepath = f"{sys.argv[1]}/{tag}.exr"
    bpy.ops.render.render(write_still=True)
    out[tag] = {k: engine.LAST_RENDER.get(k) for k in ("ok", "status", "first_image")}
    out[tag]["engine"] = engine.LAST_RENDER["choices"]["engine"]
    if tag == "while_compiling":
        out["exit"] = pipeline._warmup["process"].wait(timeout=900)
scene.render.engine = "CYCLES"
render_ui.unregister()
engine.unregister()
properties.unregister()
emit(out)
"""


@pytest.mark.blender
@pytest.mark.slow
def test_f12_shows_a_one_sample_image_first_then_the_full_frame(tmp_path: Path) -> None:
    """While the kernels compile elsewhere, F12 at 2×2 samples writes a one-sample Combined first
    (a progressive first image) and then the full frame with every pass; the saved frame equals
    the compiled engine's render of the same scene once the kernels are in (the engines agree to
    float rounding)."""
    from addon_testing import exr_passes, run_bpy

    env = {
        "BLINN_PHONG_KERNEL_CACHE": str(tmp_path / "kernels"),
        "BLINN_PHONG_WARMUP_CASES": "plain 4 samples",
    }
    got = run_bpy(F12, tmp_path, args=(str(tmp_path),), timeout=900, env=env)
    first, second = got["while_compiling"], got["compiled"]
    assert first["ok"] and first["first_image"] and first["engine"] == "numpy"
    assert "compiling in the background" in first["status"]
    assert got["exit"] == 0
    assert second["ok"] and not second["first_image"] and second["engine"] == "numba"
    numpy_frame, _, _ = exr_passes(tmp_path / "while_compiling.exr")
    numba_frame, _, _ = exr_passes(tmp_path / "compiled.exr")
    assert {"ViewLayer.Depth", "ViewLayer.Shadow"} <= set(numpy_frame)  # the full frame's passes
    np.testing.assert_allclose(
        numpy_frame["ViewLayer.Combined"], numba_frame["ViewLayer.Combined"], atol=1e-6
    )
