"""The batch CLI end to end: the file's own outputs, inputs checked first, worker loss, resumable jobs."""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813
import pytest
from addon_testing import REPO, bpy_version, run_bpy

from addon.batch import Progress, atomic_target, main, parse_colour, parse_frames
from compositing.io import read_image

# Frame 2 is bound (timeline marker) to a panoramic camera, which the engine cannot render.
# spheres.blend writes 32-bit EXR to "spheres_####" (a relative path: batch puts it under --out);
# own.blend writes 16-bit PNG next to itself ("//renders/own_##_v"), as Blender would;
# nocam.blend has no camera.
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
settings = scene.render.image_settings
settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
scene.render.filepath = "spheres_####"
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1])
settings.file_format, settings.color_depth, settings.color_mode = "PNG", "16", "RGBA"
scene.render.filepath = "//renders/own_##_v"
scene.render.film_transparent = False
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
scene.render.filepath = "nocam_####"
scene.camera = None
scene.timeline_markers.clear()
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[3])
emit(True)
"""


@pytest.fixture(scope="module")
def blends(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("batch")
    spheres, own = root / "spheres.blend", root / "own" / "own.blend"
    own.parent.mkdir()
    run_bpy(MAKE_BLEND, root, args=(str(spheres), str(own), str(root / "nocam.blend")))
    return spheres, own


@pytest.fixture(scope="module")
def blend(blends: tuple[Path, Path]) -> Path:
    return blends[0]


def _batch(*args: str, script: bool = False, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*_command(script), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        cwd=str(REPO),
        check=False,
    )


def _command(script: bool = False) -> list[str]:
    if script:
        return [sys.executable, str(REPO / "addon" / "batch.py"), "--"]
    return [sys.executable, "-m", "addon.batch"]


def _report(out: Path) -> dict:
    return json.loads((out / "report.json").read_text())


def _files(root: Path) -> list[str]:
    """Every file under ``root`` except the per-job records in ``reports/`` (see test_addon_batch_faults)."""
    return sorted(
        str(p.relative_to(root))
        for p in root.rglob("*")
        if p.is_file() and p.relative_to(root).parts[0] != "reports"
    )


def _markers(out: Path) -> list[Path]:
    """The attempt markers in the job's folder ``OUT/.batch-<job>/`` (not its write permits)."""
    return sorted(p for p in out.glob(".batch-*/*") if not p.name.startswith("write."))


def test_parse_frames() -> None:
    assert parse_frames("1-3,7,2,10-11") == [1, 2, 3, 7, 10, 11]
    assert parse_frames("5") == [5]
    for bad in ("", "1-", "3-1", "a", "1,,2", "1-99999999"):
        with pytest.raises(ValueError, match="frames"):
            parse_frames(bad)


def test_parse_colour() -> None:
    assert parse_colour("0.2,0.3,0.4") == (0.2, 0.3, 0.4)
    assert parse_colour("1,0,0,0.5") == (1.0, 0.0, 0.0, 0.5)
    assert parse_colour("backplate.exr") is None
    for bad, message in (
        ("nan,0,0,1", "finite"),
        ("1,2", "3 or 4"),
        ("1,0,0,1.5", "alpha"),
        ("inf,0,0", "finite"),
    ):
        with pytest.raises(ValueError, match=message):
            parse_colour(bad)


def test_atomic_target_keeps_the_old_file_when_the_write_fails(tmp_path: Path) -> None:
    target = tmp_path / "frame.exr"
    target.write_bytes(b"old frame")
    with pytest.raises(RuntimeError), atomic_target(target) as tmp:
        tmp.write_bytes(b"half a fr")
        raise RuntimeError("disk full")
    assert target.read_bytes() == b"old frame" and _files(tmp_path) == ["frame.exr"]
    with atomic_target(target) as tmp:
        assert tmp.parent == tmp.parent and tmp.suffix == ".exr" and tmp != target
        tmp.write_bytes(b"new frame")
    assert target.read_bytes() == b"new frame" and _files(tmp_path) == ["frame.exr"]


def test_a_killed_attempts_temporary_is_cleaned_up_and_the_output_kept(tmp_path: Path) -> None:
    from addon.batch import Task, _cleanup_temporaries

    def task(job: str) -> Task:
        output = str(tmp_path / "scene_0001.exr")
        return Task(blend="scene.blend", frame=1, out_dir=str(tmp_path), output=output, job=job)

    ours, theirs = task("job1"), task("job2")  # two jobs sharing --out render the same frame
    Path(ours.output).write_bytes(b"finished frame")
    other = tmp_path / "other.exr"
    other.write_bytes(b"another output")
    with pytest.raises(RuntimeError), atomic_target(ours.output, job=ours.job) as tmp:
        left = tmp  # the temporary name the writer got
        raise RuntimeError("worker killed")
    left.write_bytes(b"half a frame")  # a killed worker (SIGKILL) leaves it behind
    with atomic_target(theirs.output, job=theirs.job) as in_progress:
        in_progress.write_bytes(b"the other job's frame, being written")
        _cleanup_temporaries([ours])  # our job ends while the other job writes
        assert in_progress.exists()  # only our own temporary is removed
        assert _files(tmp_path) == sorted(["other.exr", "scene_0001.exr", in_progress.name])
    assert _files(tmp_path) == ["other.exr", "scene_0001.exr"]
    assert Path(ours.output).read_bytes() == b"the other job's frame, being written"


def test_atomic_target_refuses_a_writer_that_wrote_nothing(tmp_path: Path) -> None:
    target = tmp_path / "out" / "frame.exr"
    with pytest.raises(OSError, match="nothing was written"), atomic_target(target):
        pass  # a writer that reported success but produced no bytes
    assert _files(tmp_path / "out") == []  # the directory was created; no empty frame left


@pytest.mark.parametrize(
    ("args", "flag", "accepts"),
    [
        (["--background", "nan,0,0,1"], "--background", "finite"),
        (["--background", "missing_plate.exr"], "--background", "image file or a colour"),
        (["--background", "0.1,0.2"], "--background", "3 or 4 numbers"),
        (["--background", "0,0,0", "--verify", "--tolerance", "-1"], "--tolerance", ">= 0"),
        (["--background", "0,0,0", "--verify", "--tolerance", "nan"], "--tolerance", ">= 0"),
        (["--verify"], "--verify", "needs --background"),
        (["--operator", "nonsense"], "--operator", "src_over"),
        (["--frames", "3-1"], "--frames", "runs backwards"),
        (["--workers", "0"], "--workers", ">= 1"),
        (["--timeout", "0"], "--timeout", "> 0"),
        (["--retries", "-1"], "--retries", ">= 0"),
        (["--format", "PNG", "--color-depth", "32"], "--color-depth", "8/16"),
        (["--output-pattern", "renders/"], "--output-pattern", "file path pattern"),
    ],
)
def test_bad_arguments_exit_2_naming_the_flag(
    tmp_path: Path, capsys: pytest.CaptureFixture, args: list[str], flag: str, accepts: str
) -> None:
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER-v405")  # the header is all the argument checks read
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:
        main([str(blend), "--out", str(out), *args])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    assert f"error: {flag}" in err and accepts in err, err
    assert not out.exists()  # nothing rendered, nothing written


def test_every_bad_input_is_listed_at_once(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    existing_file = tmp_path / "taken"
    existing_file.write_text("not a directory")
    not_a_blend = tmp_path / "notes.blend"
    not_a_blend.write_text("hello")
    with pytest.raises(SystemExit) as exit_info:
        main(
            [
                str(tmp_path / "missing.blend"),
                str(not_a_blend),
                "--out",
                str(existing_file),
                "--operator",
                "ovr",
                "--background",
                "nan,0,0",
            ]
        )
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    for expected in (
        "missing.blend: no such .blend file",
        "notes.blend: not a .blend file",
        f"--out: {existing_file} exists and is not a directory",
        "--operator:",
        "--background:",
    ):
        assert expected in err, err


@pytest.mark.blender
def test_inputs_that_need_the_file_are_checked_before_the_first_render(blend: Path, tmp_path: Path) -> None:
    # Two files with the same name in different shots, writing to the same relative pattern:
    # refused (exit 2) before anything renders, naming both and the file they would share.
    shots = []
    for shot in ("sh010", "sh020"):
        (tmp_path / shot).mkdir()
        shots.append(tmp_path / shot / "lighting.blend")
        shots[-1].write_bytes(blend.read_bytes())
    plate = tmp_path / "plate.exr"
    out_image = oiio.ImageBuf(oiio.ImageSpec(10, 10, 4, oiio.FLOAT))
    out_image.setpixel(3, 4, (0.5, float("nan"), 0.0, 1.0))
    assert out_image.write(str(plate))
    out = tmp_path / "out"
    started = time.perf_counter()
    done = _batch(*map(str, shots), "--frames", "1", "--out", str(out), "--background", str(plate))
    seconds = time.perf_counter() - started
    assert done.returncode == 2, done.stdout + done.stderr
    assert (
        "sh020/lighting.blend frame 1 and " in done.stderr and "sh010/lighting.blend frame 1" in done.stderr
    )
    assert "both write" in done.stderr and "{blend_dir_name}" in done.stderr
    assert (
        "--background: " in done.stderr and "is 10×10 but" in done.stderr and "renders 64×48" in done.stderr
    )
    assert f"--background: {plate}: " in done.stderr and "finite" in done.stderr  # the NaN pixel
    assert not out.exists() or _files(out) == []
    print(f"time to the first error needing the .blend: {seconds:.2f} s")
    if bpy_version() >= (5, 0):  # path templates: Blender's own parser names the bad expression
        done = _batch(str(blend), "--frames", "1", "--out", str(out), "--output-pattern", "{shot}_####")
        assert done.returncode == 2 and "error: --output-pattern: Parse errors" in done.stderr, done.stderr
        assert "'{shot}'" in done.stderr


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
    report = _report(out)
    by_frame = {t["task"]["frame"]: t for t in report["tasks"]}
    assert report["failed"] == 1 and report["total"] == 3 and report["exit_code"] == 1
    assert by_frame[2]["ok"] is False and "panoramic" in by_frame[2]["error"]
    assert by_frame[2]["error"] == by_frame[2]["error"].strip()  # no trailing newline from Blender
    assert not (out / "spheres_0002.exr").exists()
    assert len({by_frame[f]["pid"] for f in (1, 2, 3)} - {os.getpid()}) >= 1
    expected_files = []
    for frame in (1, 3):
        task = by_frame[frame]
        assert task["ok"] is True, task
        rendered = read_image(out / f"spheres_{frame:04d}.exr")
        assert 0.1 < rendered[..., 3].mean() < 0.9
        # Porter-Duff over a constant opaque colour: C = C_src + (1 - α_src)·C_bg, α = 1.
        expected = rendered + (1.0 - rendered[..., 3:4]) * np.array([0.2, 0.3, 0.4, 1.0], np.float32)
        np.testing.assert_allclose(read_image(out / f"spheres_{frame:04d}_src_over.exr"), expected, atol=1e-6)
        assert task["verify"]["via"] == "alpha_over" and task["verify"]["max_abs_error"] <= 1e-6
        expected_files += [
            f"spheres_{frame:04d}{suffix}" for suffix in (".exr", "_src_over.exr", "_src_over.png")
        ]
    # The report and stdout list every file written, and nothing else was left behind.
    assert sorted(Path(p).name for p in report["written"]) == sorted(expected_files)
    assert _files(out) == sorted([*expected_files, "report.json"])
    for path in report["written"]:
        assert f"wrote {path}" in done.stdout


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.timeout(300)
def test_a_killed_worker_costs_only_its_own_task(blend: Path, tmp_path: Path) -> None:
    out = tmp_path / "kill"
    job = subprocess.Popen(
        [*_command(), str(blend), "--frames", "1,3,4,5", "--out", str(out), "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        cwd=str(REPO),
    )
    victim = None
    deadline = time.monotonic() + 120
    while victim is None and time.monotonic() < deadline and job.poll() is None:
        markers = _markers(out)
        if markers:
            victim = json.loads(markers[0].read_text())["pid"]
        time.sleep(0.05)
    assert victim is not None, "no task started"
    os.kill(victim, signal.SIGKILL)  # a worker dies in the middle of its task (importing, rendering)
    stdout, stderr = job.communicate(timeout=240)
    assert job.returncode == 0, stdout + stderr
    report = _report(out)
    assert report["failed"] == 0 and report["total"] == 4
    assert len(report["retried"]) == 1, report["retried"]
    attempts = report["retried"][0]["attempts"]
    assert attempts[0]["pid"] == victim and "died (exit code -9)" in attempts[0]["outcome"]
    assert attempts[-1]["outcome"] == "ok" and len(attempts) == 2
    # Every other task ran once; every frame was written exactly once, nothing half-written is left.
    assert sorted(len(t["attempts"]) for t in report["tasks"]) == [1, 1, 1, 2]
    assert sorted(report["written"]) == sorted(str(out / f"spheres_{f:04d}.exr") for f in (1, 3, 4, 5))
    assert _files(out) == sorted([*(f"spheres_{f:04d}.exr" for f in (1, 3, 4, 5)), "report.json"])
    assert "retrying on a fresh worker" in stderr


@pytest.mark.blender
@pytest.mark.timeout(200)
def test_timeout_ends_the_task_after_bounded_retries(blend: Path, tmp_path: Path) -> None:
    # No task can open Blender, convert and render within 0.2 s: each attempt is ended, then the task fails.
    out = tmp_path / "timeout"
    done = _batch(str(blend), "--frames", "1", "--out", str(out), "--timeout", "0.2", "--retries", "1")
    assert done.returncode == 1, done.stdout + done.stderr
    task = _report(out)["tasks"][0]
    assert "timed out after --timeout 0.2 s (2 attempt(s), --retries 1)" in task["error"]
    assert [a["outcome"] for a in task["attempts"]] == ["timed out after --timeout 0.2 s"] * 2
    assert _files(out) == ["report.json"]


def _exr_parts(path: Path) -> dict[str, np.ndarray]:
    """Every part of a multi-part EXR by channel name, read with OpenImageIO."""
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    channels, part = {}, 0
    while inp.seek_subimage(part, 0):
        spec = inp.spec()
        pixels = inp.read_image(part, 0, 0, spec.nchannels, "float")
        for i, name in enumerate(spec.channelnames):
            channels[name] = pixels[..., i]
        part += 1
    inp.close()
    return channels


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.timeout(300)
def test_the_files_own_output_settings_and_overrides(blends: tuple[Path, Path], tmp_path: Path) -> None:
    spheres, own = blends
    out = tmp_path / "own_out"
    # The file's own settings: 16-bit PNG at //renders/own_##_v (relative to the .blend), frame 3.
    done = _batch(str(own), "--frames", "3", "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    png = own.parent / "renders" / "own_03_v.png"
    assert _report(out)["written"] == [str(png)] and f"wrote {png}" in done.stdout
    spec = oiio.ImageInput.open(str(png)).spec()
    assert (spec.format.basetype, spec.nchannels, spec.width) == (oiio.UINT16, 4, 64)

    # Overrides: a multilayer EXR with every pass under Blender's names, at a pattern under --out.
    out = tmp_path / "ml"
    done = _batch(
        str(spheres),
        "--frames",
        "3",
        "--out",
        str(out),
        "--format",
        "open_exr_multilayer",
        "--color-depth",
        "32",
        "--output-pattern",
        "passes/{blend_name}_###",
    )
    assert done.returncode == 0, done.stdout + done.stderr
    path = out / "passes" / "spheres_003.exr"
    parts = _exr_parts(path)
    layer = "ViewLayer"
    names = {f"{layer}.{p}.{c}" for p in ("Combined",) for c in "RGBA"}
    names |= {f"{layer}.{p}.{c}" for p in ("Ambient", "Diffuse", "Specular") for c in "RGB"}
    names |= {f"{layer}.Depth.Z", f"{layer}.Shadow.X"}
    assert names <= set(parts), sorted(parts)
    rgb = np.stack([parts[f"{layer}.Combined.{c}"] for c in "RGB"], axis=-1)
    terms = sum(
        np.stack([parts[f"{layer}.{p}.{c}"] for c in "RGB"], axis=-1)
        for p in ("Ambient", "Diffuse", "Specular")
    )
    # No transparency, no fog: Combined = Ambient + Diffuse + Specular (the lighting equation's sum),
    # up to float32 rounding of three terms of magnitude <= ~3.
    np.testing.assert_allclose(rgb, terms, rtol=0, atol=1e-5)
    alpha, depth = parts[f"{layer}.Combined.A"], parts[f"{layer}.Depth.Z"]
    assert (depth[alpha == 0] == 1e10).all()  # empty pixels: Blender's "no surface" depth
    # The pixel next to the image centre sees the sphere's front (distance 6 − radius 1 along the
    # view axis); the 24×12 tessellation and half-pixel offset move it by well under 0.01.
    assert abs(depth[23, 31] - 5.0) < 0.01
    # Combined of the multilayer file equals the render written as a plain 32-bit EXR.
    plain = tmp_path / "plain"
    done = _batch(str(spheres), "--frames", "3", "--out", str(plain))
    assert done.returncode == 0, done.stdout + done.stderr
    combined = np.stack([parts[f"{layer}.Combined.{c}"] for c in "RGBA"], axis=-1)
    np.testing.assert_array_equal(combined, read_image(plain / "spheres_0003.exr"))


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.timeout(300)
def test_skip_existing_renders_only_what_is_missing(blend: Path, tmp_path: Path) -> None:
    out = tmp_path / "resume"
    out.mkdir()
    done = _batch(str(blend), "--frames", "1", "--out", str(out), "--background", "0,0,0,0")
    assert done.returncode == 0, done.stdout + done.stderr
    first = {name: (out / name).stat().st_mtime_ns for name in _files(out) if name != "report.json"}
    (out / "spheres_0003.exr").touch()  # an empty placeholder left by a crashed run
    done = _batch(
        str(blend),
        "--frames",
        "1,3",
        "--out",
        str(out),
        "--background",
        "0,0,0,0",
        "--skip-existing",
        "--placeholders",
    )
    assert done.returncode == 0, done.stdout + done.stderr
    report = _report(out)
    assert [(s["frame"], Path(s["outputs"][0]).name) for s in report["skipped"]] == [(1, "spheres_0001.exr")]
    assert [t["task"]["frame"] for t in report["tasks"]] == [3]
    assert (out / "spheres_0003.exr").stat().st_size > 0
    assert all((out / name).stat().st_mtime_ns == mtime for name, mtime in first.items())
    assert "frame 1: skipped" in done.stderr


@pytest.mark.blender
@pytest.mark.timeout(400)
def test_dask_local_cluster_on_loopback(blend: Path, tmp_path: Path) -> None:
    out = tmp_path / "dask"
    done = _batch(str(blend), "--frames", "1,3", "--out", str(out), "--dask-local", "2")
    assert done.returncode == 0, done.stdout + done.stderr
    report = _report(out)
    assert report["executor"] == "dask" and report["failed"] == 0
    assert [t["task"]["frame"] for t in report["tasks"]] == [1, 3]
    assert all(len(t["attempts"]) == 1 for t in report["tasks"])
    first = read_image(out / "spheres_0001.exr")
    # bitwise: one code path on identical inputs; the renderer has no threaded float reductions
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


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_an_opaque_render_warns_that_the_composite_cannot_change_it(
    blends: tuple[Path, Path], tmp_path: Path
) -> None:
    _, own = blends  # Film → Transparent is off in own.blend
    out = tmp_path / "opaque"
    done = _batch(
        str(own),
        "--frames",
        "1",
        "--out",
        str(out),
        "--background",
        "0.2,0.3,0.4",
        "--output-pattern",
        "o_####",
        "--format",
        "OPEN_EXR",
        "--color-depth",
        "32",
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "warning:" in done.stderr and "Film → Transparent is off" in done.stderr
    assert any("Film → Transparent is off" in w for w in _report(out)["warnings"])
    np.testing.assert_array_equal(read_image(out / "o_0001_src_over.exr"), read_image(out / "o_0001.exr"))


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _result(frame: int, ok: bool, seconds: float) -> dict:
    return {
        "task": {"blend": "/shots/sh010/lighting.blend", "frame": frame},
        "ok": ok,
        "error": None if ok else "RuntimeError: Cannot render, no camera\n",
        "seconds": {"total": seconds},
    }


def test_progress_bar_on_a_terminal_plain_lines_otherwise_silent_when_quiet() -> None:
    terminal = _Terminal()
    progress = Progress(2, terminal)
    progress.update(_result(1, True, 1.25))
    progress.update(_result(2, False, 0.5))
    text = terminal.getvalue()
    assert "2/2" in text and "frame" in text and "s/frame" in text and "100%" in text  # tqdm's bar
    assert "lighting.blend frame 2: FAILED (RuntimeError: Cannot render, no camera)" in text
    log = io.StringIO()
    progress = Progress(2, log)
    progress.update(_result(1, True, 1.25))
    assert log.getvalue() == "[1/2] lighting.blend frame 1: ok (1.25 s)\n"
    quiet = _Terminal()
    progress = Progress(2, quiet, quiet=True)
    progress.update(_result(1, True, 1.25))
    progress.note("retrying")
    assert quiet.getvalue() == ""


@pytest.mark.slow
@pytest.mark.blender
@pytest.mark.timeout(300)
def test_dask_timeout_ends_the_worker_and_retries_are_bounded(blend: Path, tmp_path: Path) -> None:
    # Under Dask a render cannot be interrupted: the task's worker process is ended, and with
    # --retries 0 the scheduler gives the task up after that one lost worker.
    out = tmp_path / "dask_timeout"
    done = _batch(
        str(blend),
        "--frames",
        "1",
        "--out",
        str(out),
        "--dask-local",
        "1",
        "--timeout",
        "0.5",
        "--retries",
        "0",
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert "exceeded --timeout 0.5 s; ending this worker" in done.stderr
    task = _report(out)["tasks"][0]
    assert task["ok"] is False and "KilledWorker" in task["error"], task["error"]
    assert [a["outcome"] for a in task["attempts"]] == ["worker lost before the task finished"]
    assert _files(out) == ["report.json"]


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_each_failure_is_named_for_its_own_task(blend: Path, tmp_path: Path) -> None:
    # One process, two failing tasks in a row: the engine's error (panoramic camera), then Blender's
    # own ("no camera", raised before the engine runs) — the second must not inherit the first.
    out = tmp_path / "failures"
    done = _batch(str(blend), str(blend.parent / "nocam.blend"), "--frames", "2", "--out", str(out))
    assert done.returncode == 1, done.stdout + done.stderr
    errors = {Path(t["task"]["blend"]).name: t["error"] for t in _report(out)["tasks"]}
    assert "panoramic" in errors["spheres.blend"]
    assert "Cannot render, no camera" in errors["nocam.blend"] and "panoramic" not in errors["nocam.blend"]
    assert all(e == e.strip() for e in errors.values())  # Blender's trailing newline trimmed
    assert _files(out) == ["report.json"]


@pytest.mark.blender
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_sigterm_stops_the_workers_and_reports_what_finished(blend: Path, tmp_path: Path) -> None:
    out = tmp_path / "stopped"
    job = subprocess.Popen(
        [
            *_command(),
            str(blend),
            "--frames",
            "1,3,4,5",
            "--out",
            str(out),
            "--workers",
            "2",
            "--placeholders",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        cwd=str(REPO),
    )
    workers: set[int] = set()
    deadline = time.monotonic() + 120
    while not workers and time.monotonic() < deadline and job.poll() is None:
        for marker in _markers(out):
            workers.add(int(marker.name.rsplit(".", 1)[1]))
        time.sleep(0.05)
    assert workers, "no task started"
    job.send_signal(signal.SIGTERM)  # as a farm manager stops a job
    stdout, stderr = job.communicate(timeout=60)
    assert job.returncode == 1, stdout + stderr
    assert "interrupted (SIGTERM)" in stderr
    report = _report(out)
    assert report["interrupted"] == "SIGTERM" and report["total"] < 4
    # Whatever finished is listed; nothing half-written, no placeholder, no marker is left behind.
    assert _files(out) == sorted([*(Path(p).name for p in report["written"]), "report.json"])
    for pid in workers:  # the worker processes were stopped
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
