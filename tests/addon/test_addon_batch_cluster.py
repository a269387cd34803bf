"""A real Dask cluster on loopback: a scheduler and two workers as separate processes.

The way it runs in production (``docs/addon.md``): ``dask scheduler`` and ``dask worker`` are
started on their own, with the repository on ``PYTHONPATH`` and ``bpy`` installed, sharing the
output directory; ``python -m addon.batch --scheduler tcp://…`` sends the frames. Each test bounds
every process's run time and stops the processes it started by their own ids.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from addon_testing import REPO, run_bpy

from compositing.io import read_image

pytest.importorskip("distributed")
pytestmark = [pytest.mark.blender, pytest.mark.slow]

FRAMES = range(1, 7)

# A sphere moving across a 48×36 frame: every frame differs, every frame is cheap.
MAKE_BLEND = """
import math, sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=16, ring_count=8)
ball = bpy.context.object
for frame, x in ((1, -1.5), (6, 1.5)):
    ball.location.x = x
    ball.keyframe_insert("location", index=0, frame=frame)
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location, cam.rotation_euler = (0, -8, 0), (math.pi / 2, 0, 0)
scene.collection.objects.link(cam)
scene.camera = cam
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.rotation_euler = (0.6, 0.3, 0.0)
scene.collection.objects.link(sun)
scene.render.resolution_x, scene.render.resolution_y = 48, 36
scene.render.film_transparent = True
settings = scene.render.image_settings
settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
scene.render.filepath = "ball_####"
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1])
emit(True)
"""

ENV = dict(os.environ, PYTHONPATH=str(REPO))


def _start(args: list[str], log: Path) -> subprocess.Popen:
    """A separate process in its own session (so it and its children can be stopped together)."""
    handle = log.open("w")
    return subprocess.Popen(
        [sys.executable, "-m", "dask", *args],
        stdout=handle,
        stderr=subprocess.STDOUT,
        env=ENV,
        cwd=str(REPO),
        start_new_session=True,
    )


def _stop(process: subprocess.Popen) -> None:
    """Stop a process we started, and its children, by its own id (its session's group id)."""
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=15)
    else:
        try:  # the group may outlive its leader (a nanny's worker)
            os.killpg(process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@pytest.fixture(scope="module")
def blend(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("cluster")
    path = root / "ball.blend"
    run_bpy(MAKE_BLEND, root, args=(str(path),))
    return path


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1; yields the address."""
    root = tmp_path_factory.mktemp("dask")
    scheduler_file = root / "scheduler.json"
    processes = [
        _start(
            [
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(scheduler_file),
            ],
            root / "scheduler.log",
        )
    ]
    try:
        deadline = time.monotonic() + 60
        while not scheduler_file.exists() and time.monotonic() < deadline:
            assert processes[0].poll() is None, (root / "scheduler.log").read_text()
            time.sleep(0.1)
        assert scheduler_file.exists(), (root / "scheduler.log").read_text()
        for i in range(2):
            processes.append(
                _start(
                    [
                        "worker",
                        "--scheduler-file",
                        str(scheduler_file),
                        "--nworkers",
                        "1",
                        "--nthreads",
                        "1",
                        "--no-dashboard",
                        "--host",
                        "127.0.0.1",
                        "--local-directory",
                        str(root / f"w{i}"),
                    ],
                    root / f"worker{i}.log",
                )
            )
        address = json.loads(scheduler_file.read_text())["address"]
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=90)
        yield address
    finally:
        for process in reversed(processes):
            _stop(process)


def _batch(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "addon.batch", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=str(REPO),
    )


def _pixels(out: Path) -> dict[int, np.ndarray]:
    return {frame: read_image(out / f"ball_{frame:04d}.exr") for frame in FRAMES}


@pytest.fixture(scope="module")
def reference(blend: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[int, np.ndarray]:
    """The six frames rendered one after another in a single process."""
    out = tmp_path_factory.mktemp("single")
    started = time.perf_counter()
    job = _batch(str(blend), "--frames", "1-6", "--out", str(out))
    stdout, stderr = job.communicate(timeout=300)
    assert job.returncode == 0, stdout + stderr
    print(f"\nsingle process, 6 frames: {time.perf_counter() - started:.1f} s wall")
    return _pixels(out)


@pytest.mark.timeout(600)
def test_cluster_frames_equal_single_process_bit_for_bit(
    blend: Path, cluster: str, reference: dict[int, np.ndarray], tmp_path: Path
) -> None:
    out = tmp_path / "cluster"
    started = time.perf_counter()
    job = _batch(str(blend), "--frames", "1-6", "--out", str(out), "--scheduler", cluster)
    stdout, stderr = job.communicate(timeout=300)
    print(f"\ntwo-worker Dask cluster, 6 frames: {time.perf_counter() - started:.1f} s wall")
    assert job.returncode == 0, stdout + stderr
    report = json.loads((out / "report.json").read_text())
    assert report["executor"] == "dask" and report["failed"] == 0 and report["total"] == 6
    assert len({(t["host"], t["pid"]) for t in report["tasks"]}) == 2  # both workers rendered
    # The renderer is deterministic by construction on one machine (same code, same inputs, fixed-order
    # loops; numba kernels without parallel reductions), so each frame is equal bit for bit.
    pixels = _pixels(out)
    assert not np.array_equal(pixels[1], pixels[6])  # the frames really differ
    for frame in FRAMES:
        np.testing.assert_array_equal(pixels[frame], reference[frame], err_msg=f"frame {frame}")


@pytest.mark.timeout(600)
def test_a_worker_killed_mid_job_loses_nothing(
    blend: Path, cluster: str, reference: dict[int, np.ndarray], tmp_path: Path
) -> None:
    from distributed import Client

    # Fresh worker processes: a task's first run imports bpy and loads the kernels (seconds), so the
    # kill below lands in the middle of a task, not between two 30 ms warm tasks.
    with Client(cluster, timeout=30) as client:
        client.restart(timeout=120)
        client.wait_for_workers(2, timeout=90)
    out = tmp_path / "killed"
    job = _batch(str(blend), "--frames", "1-6", "--out", str(out), "--scheduler", cluster)
    victim = None
    deadline = time.monotonic() + 120
    while victim is None and time.monotonic() < deadline and job.poll() is None:
        markers = sorted(p for p in out.glob(".batch-*/*") if not p.name.startswith("write."))
        if markers:
            try:
                victim = json.loads(markers[0].read_text())["pid"]
            except ValueError:  # being written
                continue
        time.sleep(0.01)
    assert victim is not None, "no task started on the cluster"
    os.kill(victim, signal.SIGKILL)  # the worker process running a task dies; its nanny starts a new one
    stdout, stderr = job.communicate(timeout=400)
    assert job.returncode == 0, stdout + stderr
    report = json.loads((out / "report.json").read_text())
    assert report["failed"] == 0 and report["total"] == 6
    # Every frame written once, by exactly one successful attempt; the lost attempt is recorded.
    assert sorted(report["written"]) == sorted(str(out / f"ball_{f:04d}.exr") for f in FRAMES)
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [*(f"ball_{f:04d}.exr" for f in FRAMES), "report.json", "reports"]
    )
    lost = [a for r in report["retried"] for a in r["attempts"] if a["pid"] == victim]
    assert len(lost) == 1 and lost[0]["outcome"] == "worker lost before the task finished", report["retried"]
    assert all(r["attempts"][-1]["outcome"] == "ok" for r in report["retried"])
    pixels = _pixels(out)
    for frame in FRAMES:
        np.testing.assert_array_equal(pixels[frame], reference[frame], err_msg=f"frame {frame}")


def _attempt_markers(out: Path) -> list[dict]:
    """The attempt markers of the running job (``OUT/.batch-<job>/<task>.<host>.<pid>``), as written."""
    markers = []
    for path in sorted(out.glob(".batch-*/*")):
        if path.name.startswith("write.") or path.parent.name.endswith(".closed"):
            continue
        try:
            markers.append({"task": path.name.split(".")[0], **json.loads(path.read_text())})
        except (OSError, ValueError):  # being written or just removed
            continue
    return markers


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    """Every file and folder under ``root`` with its size and modification time."""
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")}


def _wait(condition, seconds: float, what: str, job: subprocess.Popen):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        assert job.poll() is None, f"the job ended while waiting for {what}: " + "".join(job.communicate())
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


@pytest.mark.timeout(600)
def test_a_lost_worker_never_renders_a_finished_frame_again(
    blend: Path, cluster: str, reference: dict[int, np.ndarray], tmp_path: Path
) -> None:
    from distributed import Client

    out = tmp_path / "lost_after_finishing"
    job = _batch(str(blend), "--frames", "1-6", "--out", str(out), "--scheduler", cluster)
    runs: dict[str, set[int]] = {}  # every process that started each task, seen while the job runs

    def watch() -> None:
        while job.poll() is None:
            for marker in _attempt_markers(out):
                runs.setdefault(marker["task"], set()).add(marker["pid"])
            time.sleep(0.01)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    held = None
    try:
        # Hold one worker in the middle of its task (SIGSTOP), so that the job stays open.
        first = _wait(lambda: _attempt_markers(out), 120, "a task to start", job)
        held = first[0]["pid"]
        os.kill(held, signal.SIGSTOP)

        # The other worker renders every other frame it gets; wait until it is idle with its results
        # delivered (no new finished frame for a second).
        def idle_with_results() -> list[dict] | None:
            frames = {m["task"].split("-")[0]: m for m in _attempt_markers(out) if m["pid"] != held}
            written = {name: out / f"{name}.exr" for name in frames if (out / f"{name}.exr").exists()}
            if len(written) >= 2 and time.time() - max(p.stat().st_mtime for p in written.values()) > 1.0:
                return [frames[name] for name in written]
            return None

        finished = _wait(idle_with_results, 120, "the other worker to finish frames", job)
        other = finished[0]["pid"]
        snapshot = {m["task"] for m in finished}
        # The worker holding those finished results dies; its nanny starts a new one.
        with Client(cluster, timeout=30) as client:
            before = set(client.scheduler_info()["workers"])
            os.kill(other, signal.SIGKILL)

            def replaced() -> bool:  # the dead worker is gone and a fresh one has joined
                now = set(client.scheduler_info()["workers"])
                return len(now) == 2 and now != before

            _wait(replaced, 90, "the lost worker to be replaced", job)
        # Time for the scheduler to hand a recomputation of the lost results to the new worker.
        rerun = lambda: any(len(runs.get(m["task"], ())) > 1 for m in finished)  # noqa: E731
        deadline = time.monotonic() + 5.0
        while not rerun() and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        if held is not None:
            os.kill(held, signal.SIGCONT)
    stdout, stderr = job.communicate(timeout=300)
    after = _snapshot(out)
    watcher.join()
    assert not rerun(), f"finished frames were rendered again: {runs}"
    assert job.returncode == 0, stdout + stderr
    time.sleep(3.0)
    assert _snapshot(out) == after, "files changed under --out after the job returned"
    report = json.loads((out / "report.json").read_text())
    assert report["failed"] == 0 and report["total"] == 6
    # Each frame ran once: the finished ones were not computed again when their worker died.
    attempts = {t["task"]["frame"]: t["attempts"] for t in report["tasks"]}
    assert all(len(a) == 1 and a[0]["outcome"] == "ok" for a in attempts.values()), attempts
    assert report["retried"] == [] and len(snapshot) >= 2
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [*(f"ball_{f:04d}.exr" for f in FRAMES), "report.json", "reports"]
    )
    pixels = _pixels(out)
    for frame in FRAMES:
        np.testing.assert_array_equal(pixels[frame], reference[frame], err_msg=f"frame {frame}")


@pytest.mark.timeout(600)
def test_nothing_changes_under_out_after_an_interrupted_job_returns(
    blend: Path, cluster: str, tmp_path: Path
):
    out = tmp_path / "interrupted"
    job = _batch(str(blend), "--frames", "1-6", "--out", str(out), "--scheduler", cluster)
    held = None
    try:
        # A worker is in the middle of a task when the job is stopped: Dask cannot interrupt a
        # render, so the task runs on after the job has gone, and must write nothing.
        first = _wait(lambda: _attempt_markers(out), 120, "a task to start", job)
        held = first[0]["pid"]
        os.kill(held, signal.SIGSTOP)
        job.send_signal(signal.SIGTERM)  # a farm manager stops the job
        stdout, stderr = job.communicate(timeout=120)
        after = _snapshot(out)
    finally:
        if held is not None:
            os.kill(held, signal.SIGCONT)
    assert job.returncode == 1 and "interrupted (SIGTERM)" in stderr, stdout + stderr
    report = json.loads((out / "report.json").read_text())
    assert report["interrupted"] == "SIGTERM"
    time.sleep(4.0)  # the held task finishes its render (about a second) and tries to write
    assert _snapshot(out) == after, "files changed under --out after the job returned"
    names = {p.name for p in out.iterdir()}
    assert names == {"report.json", "reports", *(Path(p).name for p in report["written"])}, names
