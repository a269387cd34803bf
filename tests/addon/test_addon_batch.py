"""The batch CLI end to end: processes, Dask on loopback, script mode, a failing frame, the report."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from addon_testing import REPO, run_bpy

from addon.batch import parse_frames
from compositing.io import read_image

# Frame 2 is bound (timeline marker) to a panoramic camera, which the engine cannot render.
MAKE_BLEND = """
import math, sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=24, ring_count=12)
bpy.ops.object.shade_smooth()
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location, cam.rotation_euler = (0, -6, 0), (math.pi / 2, 0, 0)
pano = bpy.data.objects.new("Pano", bpy.data.cameras.new("Pano"))
pano.data.type = "PANO"
for ob in (cam, pano):
    scene.collection.objects.link(ob)
scene.camera = cam
for frame, camera in ((1, cam), (2, pano), (3, cam)):
    scene.timeline_markers.new(f"f{frame}", frame=frame).camera = camera
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.data.energy, sun.rotation_euler = 3.0, (0.5, 0.2, 0.0)
scene.collection.objects.link(sun)
scene.render.resolution_x, scene.render.resolution_y = 64, 48
scene.render.film_transparent = True
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1])
emit(True)
"""


@pytest.fixture(scope="module")
def blend(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("batch")
    path = root / "spheres.blend"
    run_bpy(MAKE_BLEND, root, args=(str(path),))
    return path


def _batch(*args: str, script: bool = False, timeout: float = 240) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    command = (
        [sys.executable, str(REPO / "addon" / "batch.py"), "--"]
        if script
        else [sys.executable, "-m", "addon.batch"]
    )
    return subprocess.run(
        [*command, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=str(REPO),
        check=False,
    )


def test_parse_frames() -> None:
    assert parse_frames("1-3,7,2,10-11") == [1, 2, 3, 7, 10, 11]
    assert parse_frames("5") == [5]
    for bad in ("", "1-", "3-1", "a", "1,,2"):
        with pytest.raises(ValueError, match="frames"):
            parse_frames(bad)


@pytest.mark.blender
@pytest.mark.timeout(400)
def test_processes_failing_frame_composite_and_verify(blend: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = _batch(
        str(blend),
        "--frames",
        "1-3",
        "--out",
        str(out),
        "--background",
        "0.2,0.3,0.4",
        "--verify",
        "--workers",
        "2",
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert "[3/3]" in done.stderr and "frame 2: FAILED" in done.stderr  # plain lines when not a terminal
    report = json.loads((out / "report.json").read_text())
    by_frame = {t["task"]["frame"]: t for t in report["tasks"]}
    assert report["failed"] == 1 and report["total"] == 3
    assert by_frame[2]["ok"] is False and "panoramic" in by_frame[2]["error"]
    assert not (out / "spheres_0002.exr").exists()
    assert len({by_frame[f]["pid"] for f in (1, 2, 3)} - {os.getpid()}) >= 1
    for frame in (1, 3):
        task = by_frame[frame]
        assert task["ok"] is True, task
        rendered = read_image(out / f"spheres_{frame:04d}.exr")
        assert 0.1 < rendered[..., 3].mean() < 0.9
        # Porter-Duff over a constant opaque colour: C = C_src + (1 - α_src)·C_bg, α = 1.
        expected = rendered + (1.0 - rendered[..., 3:4]) * np.array([0.2, 0.3, 0.4, 1.0], np.float32)
        np.testing.assert_allclose(read_image(out / f"spheres_{frame:04d}_src_over.exr"), expected, atol=1e-6)
        assert (out / f"spheres_{frame:04d}_src_over.png").exists()
        assert task["verify"]["via"] == "alpha_over" and task["verify"]["max_abs_error"] <= 1e-5


@pytest.mark.blender
@pytest.mark.timeout(400)
def test_dask_local_cluster_on_loopback(blend: Path, tmp_path: Path) -> None:
    out = tmp_path / "dask"
    done = _batch(str(blend), "--frames", "1,3", "--out", str(out), "--dask-local", "2")
    assert done.returncode == 0, done.stdout + done.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["executor"] == "dask" and report["failed"] == 0
    assert [t["task"]["frame"] for t in report["tasks"]] == [1, 3]
    first = read_image(out / "spheres_0001.exr")
    np.testing.assert_array_equal(first, read_image(out / "spheres_0003.exr"))  # same camera, same scene


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_script_mode_as_under_blender_p(blend: Path, tmp_path: Path) -> None:
    # `blender -b f.blend -P addon/batch.py -- ...` runs the file as a script with arguments after `--`.
    out = tmp_path / "script"
    done = _batch(str(blend), "--frames", "3", "--out", str(out), script=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1/1 tasks ok" in done.stdout
    assert read_image(out / "spheres_0003.exr").shape == (48, 64, 4)


def test_usage_errors_exit_2(tmp_path: Path) -> None:
    done = _batch("x.blend", "--out", str(tmp_path), "--frames", "3-1")
    assert done.returncode == 2 and "runs backwards" in done.stderr
    done = _batch("x.blend", "--out", str(tmp_path), "--operator", "nonsense")
    assert done.returncode == 2 and "--operator" in done.stderr
