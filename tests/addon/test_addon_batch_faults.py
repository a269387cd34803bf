"""Faults a render farm meets, each reproduced against the batch job: a full disk, two jobs sharing
an output folder, a job that has ended while a task still runs, bad addresses and frames.

Each test feeds the fault itself (a file-size limit on the writing process, SIGSTOP on a writer, an
address nobody listens on, ...) and checks what is left on disk and in the report.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813
import pytest
from addon_testing import REPO, run_bpy

from addon.batch import (
    MAX_FRAME,
    MIN_FRAME,
    JobClosed,
    Task,
    _attempts_from_markers,
    _finish_attempt,
    _record_attempt,
    close_job,
    main,
    parse_frames,
    read_back,
    readable,
    write_permit,
)

# A sphere moving across the frame, every pass in an uncompressed 32-bit multilayer EXR (15
# channels: 184 KB at 64×48), saved at two sizes: argv[1] at 64×48, argv[2] at 320×240.
MAKE_BLEND = """
import math, sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=24, ring_count=12)
bpy.ops.object.shade_smooth()
ball = bpy.context.object
for frame, x in ((1, -0.4), (8, 0.4)):
    ball.location.x = x
    ball.keyframe_insert("location", index=0, frame=frame)
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location, cam.rotation_euler = (0, -6, 0), (math.pi / 2, 0, 0)
scene.collection.objects.link(cam)
scene.camera = cam
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.data.energy, sun.rotation_euler = 3.0, (0.5, 0.2, 0.0)
scene.collection.objects.link(sun)
scene.render.film_transparent = True
settings = scene.render.image_settings
from addon import compat
compat.set_image_format(settings, "OPEN_EXR_MULTILAYER", "32")
settings.color_mode, settings.exr_codec = "RGBA", "NONE"
scene.render.filepath = "ball_####"
for path, (w, h) in zip(sys.argv[1:], ((64, 48), (320, 240))):
    scene.render.resolution_x, scene.render.resolution_y = w, h
    bpy.ops.wm.save_as_mainfile(filepath=path)
emit(True)
"""

ENV = dict(os.environ, PYTHONPATH=str(REPO))
FILE_SIZE_LIMIT = 64 * 1024


@pytest.fixture(scope="module")
def blends(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("faults")
    small, large = root / "ball.blend", root / "ball_320.blend"
    run_bpy(MAKE_BLEND, root, args=(str(small), str(large)))
    return small, large


def _limit_file_size() -> None:
    """In the child: files may not grow past 64 KiB (as on a full disk or quota); the write fails
    with EFBIG instead of killing the process (SIGXFSZ ignored)."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (FILE_SIZE_LIMIT, FILE_SIZE_LIMIT))


def _batch(*args: str, limit_size: bool = False, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "addon.batch", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=ENV,
        cwd=str(REPO),
        check=False,
        preexec_fn=_limit_file_size if limit_size else None,
    )


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "addon.batch", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=str(REPO),
    )


def _report(out: Path) -> dict:
    return json.loads((out / "report.json").read_text())


def _files(root: Path) -> list[str]:
    """Every file under ``root`` except the per-job records in ``reports/``."""
    return sorted(
        str(p.relative_to(root))
        for p in root.rglob("*")
        if p.is_file() and p.relative_to(root).parts[0] != "reports"
    )


def _parts(path: Path) -> dict[str, np.ndarray]:
    """Every channel of every part of an EXR, read with OpenImageIO."""
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    channels, part = {}, 0
    while inp.seek_subimage(part, 0):
        spec = inp.spec()
        pixels = inp.read_image(part, 0, 0, spec.nchannels, "float")
        assert pixels is not None, inp.geterror()
        for i, name in enumerate(spec.channelnames):
            channels[name] = pixels[..., i]
        part += 1
    inp.close()
    return channels


# --------------------------------------------------------------------------- a full disk


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_a_full_disk_keeps_the_previous_frame_and_fails_the_task(blends: tuple[Path, Path], tmp_path: Path):
    small, _ = blends
    out = tmp_path / "out"
    done = _batch(str(small), "--frames", "1", "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    frame = out / "ball_0001.exr"
    good = frame.read_bytes()
    assert len(good) > FILE_SIZE_LIMIT  # the multilayer file cannot fit under the limit
    # The same job again, on a "full disk": Blender logs the failed write but save_render returns.
    done = _batch(str(small), "--frames", "1", "--out", str(out), limit_size=True)
    assert done.returncode == 1, done.stdout + done.stderr
    report = _report(out)
    assert report["failed"] == 1 and report["written"] == [], report
    error = report["tasks"][0]["error"]
    assert f"writing {frame} failed, the previous file is kept" in error, error
    assert "does not read back whole" in error and "part " in error, error
    assert frame.read_bytes() == good  # the previous frame, byte for byte
    assert _files(out) == ["ball_0001.exr", "report.json"]  # no temporary file left behind
    assert f"wrote {frame}" not in done.stdout


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_skip_existing_renders_a_cut_off_frame_again(blends: tuple[Path, Path], tmp_path: Path) -> None:
    small, _ = blends
    reference = tmp_path / "reference"
    done = _batch(str(small), "--frames", "1,2", "--out", str(reference))
    assert done.returncode == 0, done.stdout + done.stderr
    out = tmp_path / "out"
    out.mkdir()
    for frame in (1, 2):
        (out / f"ball_{frame:04d}.exr").write_bytes((reference / f"ball_{frame:04d}.exr").read_bytes())
    # What a full disk left behind: the first 64 KiB of a frame (its header and first parts decode).
    cut = out / "ball_0001.exr"
    cut.write_bytes(cut.read_bytes()[:FILE_SIZE_LIMIT])
    with pytest.raises(OSError, match=r"part \d cannot be decoded"):
        read_back(cut)
    done = _batch(str(small), "--frames", "1,2", "--out", str(out), "--skip-existing")
    assert done.returncode == 0, done.stdout + done.stderr
    report = _report(out)
    assert [t["task"]["frame"] for t in report["tasks"]] == [1]  # rendered again
    assert [s["frame"] for s in report["skipped"]] == [2]  # the whole frame is kept
    assert any("ball_0001.exr is not a whole image" in w for w in report["warnings"]), report["warnings"]
    read_back(cut, (64, 48))
    expected, got = _parts(reference / "ball_0001.exr"), _parts(cut)
    assert expected.keys() == got.keys()
    for name in expected:  # one renderer, one machine, same inputs: the same pixels
        np.testing.assert_array_equal(got[name], expected[name], err_msg=name)


def test_read_back_refuses_cut_off_images_of_every_batch_format(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    pixels = rng.random((48, 64, 4)).astype(np.float32)
    for ext, fmt, channels in (
        ("exr", "float", 4),
        ("png", "uint16", 4),
        ("tif", "uint16", 4),
        ("jpg", "uint8", 3),
        ("bmp", "uint8", 3),
        ("tga", "uint8", 4),
    ):
        path = tmp_path / f"image.{ext}"
        out = oiio.ImageOutput.create(str(path))
        assert out.open(str(path), oiio.ImageSpec(64, 48, channels, fmt)), out.geterror()
        assert out.write_image(pixels[..., :channels]) and out.close()
        read_back(path, (64, 48))  # whole
        with pytest.raises(OSError, match="expected 32×48"):
            read_back(path, (32, 48))
        whole = path.read_bytes()
        for keep in (0.5, 0.97):
            path.write_bytes(whole[: int(len(whole) * keep)])
            with pytest.raises(OSError, match=str(path)):
                read_back(path)


@pytest.mark.blender
@pytest.mark.timeout(120)
def test_a_format_openimageio_cannot_read_is_written_with_a_warning(
    blends: tuple[Path, Path], tmp_path: Path
) -> None:
    small, _ = blends
    jp2 = tmp_path / "ball_jp2.blend"  # the file's own format: JPEG 2000
    run_bpy(
        """
import sys
import bpy
from addon import compat
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
compat.set_image_format(bpy.context.scene.render.image_settings, "JPEG2000", None)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
emit(True)
""",
        tmp_path,
        args=(str(small), str(jp2)),
    )
    out = tmp_path / "out"
    done = _batch(str(jp2), "--frames", "1", "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr
    written = _report(out)["written"]
    assert [Path(p).suffix for p in written] == [".jp2"] and Path(written[0]).stat().st_size > 0
    unchecked = [w for w in _report(out)["warnings"] if "cannot be read back here" in w]
    assert len(unchecked) == (0 if readable(written[0]) else 1), _report(out)["warnings"]


# --------------------------------------------------------------------------- two jobs, one --out


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_two_jobs_sharing_out_never_remove_each_others_files(
    blends: tuple[Path, Path], tmp_path: Path
) -> None:
    _, large = blends
    out = tmp_path / "shared"
    # Job B renders eight frames in its own process; it is paused (SIGSTOP) while a frame of it is
    # being written, i.e. while its temporary file exists.
    job_b = _start(str(large), "--frames", "1-8", "--out", str(out), "--skip-existing")
    caught = None
    try:
        deadline = time.monotonic() + 180
        while caught is None and job_b.poll() is None and time.monotonic() < deadline:
            if out.is_dir():
                for entry in os.scandir(out):
                    if entry.name.startswith(".ball_") and ".part." in entry.name:
                        os.kill(job_b.pid, signal.SIGSTOP)
                        if Path(entry.path).exists():  # still mid-write when it stopped
                            caught = Path(entry.path)
                            break
                        os.kill(job_b.pid, signal.SIGCONT)
        assert caught is not None, "job B finished before one of its writes could be paused"
        # Job A renders the same frames into the same folder and ends while B is paused.
        done = _batch(str(large), "--frames", "1-8", "--out", str(out), "--skip-existing")
        assert done.returncode == 0, done.stdout + done.stderr
        assert caught.exists(), "job A removed job B's file in progress"
    finally:
        os.kill(job_b.pid, signal.SIGCONT)
    stdout, stderr = job_b.communicate(timeout=180)
    assert job_b.returncode == 0, stdout + stderr
    assert _files(out) == sorted([*(f"ball_{f:04d}.exr" for f in range(1, 9)), "report.json"])
    for frame in range(1, 9):
        read_back(out / f"ball_{frame:04d}.exr", (320, 240))
    # Each job keeps its own record; report.json is the last one to end (job B).
    records = [json.loads(p.read_text()) for p in sorted((out / "reports").iterdir())]
    assert len(records) == 2 and len({r["job"] for r in records}) == 2
    assert all(r["exit_code"] == 0 and r["failed"] == 0 for r in records)
    last = _report(out)  # job B, which was paused while job A ran to its end
    assert last["job"] in caught.name and last["job"] in {r["job"] for r in records}
    paused_frame = caught.name.removeprefix(".").split(f".{last['job']}.")[0]
    assert str(out / paused_frame) in last["written"]


# --------------------------------------------------------------------------- the job's fence


def _task(tmp_path: Path, name: str = "scene") -> Task:
    job_dir = tmp_path / ".batch-job1"
    job_dir.mkdir(exist_ok=True)
    return Task(
        blend=f"{name}.blend",
        frame=1,
        out_dir=str(tmp_path),
        output=str(tmp_path / f"{name}_0001.exr"),
        attempt_dir=str(job_dir),
        job="job1",
    )


def test_nothing_can_be_written_once_the_job_has_ended(tmp_path: Path) -> None:
    task = _task(tmp_path)
    with write_permit(task):  # the job is open
        pass
    closed, warnings = close_job(task.attempt_dir)
    assert closed is not None and warnings == []
    with pytest.raises(JobClosed), write_permit(task):
        Path(task.output).write_bytes(b"too late")
    assert not Path(task.output).exists()
    assert not _record_attempt(task)  # a task starting now does not run at all
    assert not Path(task.attempt_dir).exists()  # and does not bring the job's folder back


def test_the_end_of_a_job_waits_for_a_write_under_way(tmp_path: Path) -> None:
    task = _task(tmp_path)
    holding, release, finished = threading.Event(), threading.Event(), []

    def writer() -> None:
        with write_permit(task):
            holding.set()
            release.wait(10)
            Path(task.output).write_bytes(b"frame")
            finished.append(time.monotonic())

    thread = threading.Thread(target=writer)
    thread.start()
    assert holding.wait(10)
    threading.Timer(1.5, release.set).start()  # the write takes 1.5 s more (heartbeats keep it live)
    closed, warnings = close_job(task.attempt_dir)
    ended = time.monotonic()
    thread.join()
    assert finished and finished[0] <= ended and warnings == []
    assert Path(task.output).read_bytes() == b"frame"
    assert closed is not None and list(closed.glob("write.*")) == []


def test_a_writer_killed_while_writing_does_not_hold_the_job_up(tmp_path: Path) -> None:
    task = _task(tmp_path)
    code = (
        "import sys, time, json\n"
        "from addon.batch import Task, write_permit\n"
        "task = Task(**json.loads(sys.argv[1]))\n"
        "with write_permit(task):\n"
        "    print('holding', flush=True)\n"
        "    time.sleep(60)\n"
    )
    from dataclasses import asdict

    child = subprocess.Popen(
        [sys.executable, "-c", code, json.dumps(asdict(task))], stdout=subprocess.PIPE, text=True, env=ENV
    )
    try:
        assert child.stdout.readline().strip() == "holding"
    finally:
        child.kill()  # SIGKILL: its permit stays in the folder
        child.wait(10)
    started = time.monotonic()
    closed, _ = close_job(task.attempt_dir)
    assert time.monotonic() - started < 1.0  # its process is gone: nothing to wait for
    assert closed is not None and len(list(closed.glob("write.*"))) == 1


def test_a_finished_attempt_is_never_reported_as_lost(tmp_path: Path) -> None:
    task = _task(tmp_path)
    from dataclasses import asdict

    item = asdict(task)
    # Attempt 1 finished (its worker was lost only afterwards), attempt 2 was killed mid-task, and
    # attempt 3 (this process) returned the result. Each runs in its own process, as on a cluster.
    code = (
        "import sys, json\n"
        "from addon.batch import Task, _record_attempt, _finish_attempt\n"
        "task = Task(**json.loads(sys.argv[1]))\n"
        "assert _record_attempt(task)\n"
        "if sys.argv[2] == 'finish':\n"
        "    _finish_attempt(task, {'ok': True})\n"
    )
    for how in ("finish", "killed"):
        subprocess.run([sys.executable, "-c", code, json.dumps(item), how], env=ENV, check=True)
        time.sleep(0.01)  # distinct start times
    assert _record_attempt(task)
    result = {"ok": True, "pid": os.getpid(), "host": socket.gethostname()}
    _finish_attempt(task, result)
    outcomes = [a["outcome"] for a in _attempts_from_markers(item, result)]
    assert outcomes == ["ok", "worker lost before the task finished", "ok"], outcomes


# --------------------------------------------------------------------------- input checks


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (
            ["--frames", "10000000000"],
            "--frames: 10000000000 in '10000000000' is outside Blender's frame range",
        ),
        (["--frames", f"1-{MAX_FRAME + 1}"], f"{MIN_FRAME}..{MAX_FRAME}"),
        (["--frames", str(MIN_FRAME - 1)], "outside Blender's frame range"),
        (["--scheduler", "tcp://127.0.0.1:notaport"], "--scheduler: expected a port number in 1..65535"),
        (["--scheduler", "tcp://127.0.0.1:70000"], "got '70000'"),
        (["--scheduler", "127.0.0.1"], "--scheduler: expected an address like tcp://host:8786"),
        (["--scheduler", "tcp://127.0.0.1:8786", "--retries", "0"], "distributed.scheduler.allowed-failures"),
        (["--scheduler", "tcp://127.0.0.1:8786", "--connect-timeout", "0"], "--connect-timeout: expected"),
    ],
)
def test_bad_frames_and_addresses_exit_2_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture, args: list[str], expected: str
) -> None:
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER-v405")  # the header is all the argument checks read
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_info:
        main([str(blend), "--out", str(out), *args])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and expected in err, err
    assert "Traceback" not in err and not out.exists()


def test_frames_at_the_ends_of_blenders_range_are_accepted() -> None:
    assert parse_frames(f"{MIN_FRAME},{MAX_FRAME}") == [MIN_FRAME, MAX_FRAME]


def test_help_says_where_retries_apply(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "refused with --scheduler" in text and "allowed-failures" in text and "--connect-timeout" in text


@pytest.mark.blender
@pytest.mark.timeout(120)
def test_a_frame_blender_would_clamp_is_not_written_under_its_name(blends: tuple[Path, Path], tmp_path: Path):
    small, _ = blends
    # The command line refuses such frames up front; the task itself checks too (API use).
    facts = run_bpy(
        """
import sys
from addon.batch import Task, run_task
task = Task(blend=sys.argv[1], frame=1048575, out_dir=sys.argv[2], output=sys.argv[2] + "/ball_1048575.exr")
result = run_task(task)
emit({"ok": result["ok"], "error": result["error"], "written": result["written"]})
""",
        tmp_path,
        args=(str(small), str(tmp_path)),
    )
    assert facts["ok"] is False and facts["written"] == [], facts
    assert "frame 1048575: Blender set the scene to frame 1048574" in facts["error"], facts
    assert not (tmp_path / "ball_1048575.exr").exists()


def _read_only_folder(path: Path) -> None:
    """Make ``path`` a folder nobody may write into (also root: the immutable attribute), or skip."""
    path.mkdir(parents=True)
    path.chmod(0o555)
    if os.access(path, os.W_OK):  # root ignores the mode bits
        done = subprocess.run(["chattr", "+i", str(path)], capture_output=True, check=False)
        if done.returncode != 0 or os.access(path, os.W_OK):
            pytest.skip("cannot make a folder read-only for this user (root without chattr +i)")


def _writable_again(path: Path) -> None:
    subprocess.run(["chattr", "-i", str(path)], capture_output=True, check=False)
    path.chmod(0o755)


@pytest.mark.blender
@pytest.mark.timeout(120)
def test_an_output_folder_that_cannot_be_written_is_refused_before_the_first_render(
    blends: tuple[Path, Path], tmp_path: Path
) -> None:
    small, _ = blends
    locked = tmp_path / "locked"
    _read_only_folder(locked)
    out = tmp_path / "out"
    try:
        done = _batch(
            str(small), "--frames", "1-3", "--out", str(out), "--output-pattern", f"{locked}/sub/ball_####"
        )
    finally:
        _writable_again(locked)
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"error: --output-pattern: cannot create or write into {locked}/sub" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr
    assert not out.exists() and list(locked.iterdir()) == []  # nothing rendered, nothing written


@pytest.mark.blender
@pytest.mark.timeout(120)
def test_outputs_outside_out_are_listed_in_the_report(blends: tuple[Path, Path], tmp_path: Path) -> None:
    small, _ = blends
    out = tmp_path / "out"
    done = _batch(str(small), "--frames", "1", "--out", str(out), "--output-pattern", "../elsewhere/b_####")
    assert done.returncode == 0, done.stdout + done.stderr
    outside = str(tmp_path / "elsewhere" / "b_0001.exr")
    report = _report(out)
    assert report["outside_out"] == [outside] and report["written"] == [outside]
    assert "writes 1 file(s) outside --out" in done.stderr and outside in done.stderr


# --------------------------------------------------------------------------- the scheduler


def test_a_scheduler_nobody_listens_on_is_named_within_seconds(tmp_path: Path) -> None:
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER-v405")  # nothing is opened: the scheduler is tried first
    with socket.socket() as probe:  # a loopback port with nothing listening on it
        probe.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{probe.getsockname()[1]}"
    out = tmp_path / "out"
    started = time.monotonic()
    done = _batch(str(blend), "--out", str(out), "--scheduler", address, "--connect-timeout", "2", timeout=60)
    seconds = time.monotonic() - started
    assert done.returncode == 1, done.stdout + done.stderr
    assert f"error: --scheduler: cannot connect to {address} within 2 s (Connection refused)" in done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.splitlines()) <= 2, done.stderr
    report = _report(out)
    assert report["exit_code"] == 1 and report["total"] == 0 and address in report["error"]
    print(f"exit after {seconds:.1f} s")


def test_a_scheduler_that_never_answers_is_given_up_after_connect_timeout(tmp_path: Path) -> None:
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER-v405")
    with socket.socket() as silent:  # accepts connections (the kernel does) and never says a word
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        address = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        out = tmp_path / "out"
        done = _batch(
            str(blend), "--out", str(out), "--scheduler", address, "--connect-timeout", "2", timeout=60
        )
    assert done.returncode == 1, done.stdout + done.stderr
    assert f"error: --scheduler: {address} did not answer as a Dask scheduler within 2 s" in done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    assert _report(out)["exit_code"] == 1


# --------------------------------------------------------------------------- papercuts


@pytest.mark.blender
@pytest.mark.timeout(120)
def test_placeholders_leave_an_ordinary_file_mode(blends: tuple[Path, Path], tmp_path: Path) -> None:
    small, _ = blends
    umask = os.umask(0o022)
    os.umask(umask)
    modes = {}
    for flag in ("--placeholders", None):
        out = tmp_path / str(flag)
        done = _batch(str(small), "--frames", "1", "--out", str(out), *([flag] if flag else []))
        assert done.returncode == 0, done.stdout + done.stderr
        modes[flag] = stat.S_IMODE((out / "ball_0001.exr").stat().st_mode)
    assert modes == {"--placeholders": 0o666 & ~umask, None: 0o666 & ~umask}, {
        k: oct(v) for k, v in modes.items()
    }


@pytest.mark.blender
@pytest.mark.timeout(200)
def test_bundled_files_batch_together_without_engine_errors(tmp_path: Path) -> None:
    # Files saved with the engine: opening them while planning must not log "not available".
    blends = [REPO / "blend_files" / f"{name}.blend" for name in ("showcase", "transparency")]
    out = tmp_path / "out"
    done = _batch(*map(str, blends), "--out", str(out), "--output-pattern", "{blend_name}_####", "--quiet")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "not available" not in done.stdout + done.stderr, done.stdout + done.stderr
    # Their own outputs: one folder per scene beside the file, never Blender's /tmp/ default.
    bundled = sorted((REPO / "blend_files").glob("*.blend"))
    facts = run_bpy(
        """
import sys
import bpy
paths = {}
for blend in sys.argv[1:]:
    bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
    scene = bpy.context.scene
    paths[blend] = [scene.render.filepath, bpy.path.abspath(scene.render.frame_path(frame=1))]
emit(paths)
""",
        tmp_path,
        args=tuple(str(p) for p in bundled),
    )
    for blend, (pattern, frame) in facts.items():
        name = Path(blend).stem
        assert pattern == f"//render/{name}/####", (blend, pattern)
        assert Path(frame).parent == REPO / "blend_files" / "render" / name, frame
    assert len({frame for _, frame in facts.values()}) == len(facts) == len(bundled)  # one each


def test_a_lost_writer_on_another_node_holds_the_job_up_only_briefly(tmp_path: Path) -> None:
    from addon.batch import PERMIT_STALE_S

    task = _task(tmp_path)
    # What a node that died mid-write leaves: its permit, never refreshed again, stamped by a clock
    # an hour ahead of this one (the job judges by its own clock whether the permit still changes).
    permit = Path(task.attempt_dir) / "write.lost"
    permit.write_text(json.dumps({"host": "render-node-7.invalid", "pid": 4242}))
    ahead = time.time() + 3600
    os.utime(permit, (ahead, ahead))
    started = time.monotonic()
    closed, _ = close_job(task.attempt_dir, wait=60)
    seconds = time.monotonic() - started
    assert PERMIT_STALE_S <= seconds < PERMIT_STALE_S + 5, seconds
    assert closed is not None and (closed / "write.lost").exists()


def test_a_recomputed_task_returns_its_finished_attempt_instead_of_rendering(tmp_path: Path) -> None:
    """Dask recomputes a task whose worker was lost before the job fetched its result; the frame
    is on disk already, so the earlier attempt's result comes back and nothing renders again (no
    new attempt marker: the attempt markers are the record of every render)."""
    from addon.batch import run_task

    attempts = tmp_path / "attempts"
    attempts.mkdir()
    frame = tmp_path / "shot_0001.png"
    task = Task(blend=str(tmp_path / "shot.blend"), frame=1, out_dir=str(tmp_path), output=str(frame),
                attempt_dir=str(attempts))  # fmt: skip
    assert _record_attempt(task)
    frame.write_bytes(b"the finished frame")
    earlier = {"ok": True, "written": [str(frame)], "pid": 1234, "outputs": {"image": str(frame)}}
    _finish_attempt(task, earlier)
    markers = sorted(attempts.iterdir())
    assert run_task(task) == earlier
    assert sorted(attempts.iterdir()) == markers  # no second attempt started
    frame.unlink()  # the file is gone: the earlier result no longer stands, and the task runs
    from addon.batch import _finished_result

    assert _finished_result(task) is None
