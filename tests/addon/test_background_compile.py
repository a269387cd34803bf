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
