"""Batch jobs: a two-worker Dask cluster on this machine against one process, by frame size.

Per-task overhead (scheduling, moving the task and its result, opening the .blend in the worker)
is fixed, so a cluster only pays off once a frame takes long enough. The scene is the bundled
``showcase.blend`` (five shaded spheres, three lights, shadows) saved at each size, six frames a
job, written as the file's own PNG. Both executors run the same command line
(``python -m addon.batch``); the cluster is ``dask scheduler`` and two ``dask worker --nthreads 1``
processes on 127.0.0.1, started once and warmed (``bpy`` imported, kernels loaded) before timing,
as a farm's cluster would be. Jobs alternate between the two executors, size by size, round after
round, so a disturbance of the shared machine hits both alike; the ratio of medians is the figure.

Also measured: what reading each written frame back (every pixel decoded: the batch job's check
that a write really succeeded) costs at 1920×1080, for PNG and for a 32-bit multilayer EXR.

Usage::

    python -m benchmarks.bench_batch_cluster --out benchmarks/results [--repeat 3] [--frames 6]

Writes ``batch_cluster.json``: per size, the wall time of the command (Python start, planning,
rendering, report) and the time of the task phase (``report.json``'s ``seconds``) for each
executor, their medians, the cluster/one-process ratios, the one-process render time per frame and
the cores it keeps busy (CPU seconds per wall second), and the smallest size at which the cluster
is faster. A third executor, one process whose kernels run on one thread (``NUMBA_NUM_THREADS=1``),
shows how much of a core count the renderer already uses by itself.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks._util import machine_info, markdown_table, write_json

REPO = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(REPO))
SIZES = ((64, 48), (480, 270), (960, 540), (1920, 1080))

MAKE = """
import sys
import bpy
from addon import engine, properties
properties.register()
engine.register()
try:
    bpy.ops.wm.open_mainfile(filepath=sys.argv[1], load_ui=False)
    scene = bpy.context.scene
    for path, size in zip(sys.argv[2::2], sys.argv[3::2]):
        w, h = (int(v) for v in size.split("x"))
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = w, h, 100
        scene.render.filepath = f"//frames_{w}x{h}/f_####"
        bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
finally:
    engine.unregister()
    properties.unregister()
"""


def _dask(args: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "dask", *args],
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        env=ENV,
        cwd=str(REPO),
        start_new_session=True,
    )


def _stop(process: subprocess.Popen) -> None:
    """Stop a process this benchmark started, and its children (its own session), by its id."""
    try:
        os.killpg(process.pid, signal.SIGTERM)
        process.wait(timeout=15)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        try:
            os.killpg(process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def start_cluster(root: Path, workers: int = 2) -> tuple[str, list[subprocess.Popen]]:
    """A scheduler and ``workers`` single-threaded workers on 127.0.0.1; returns the address."""
    scheduler_file = root / "scheduler.json"
    processes = [
        _dask(
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
    deadline = time.monotonic() + 60
    while not scheduler_file.exists():
        if time.monotonic() > deadline or processes[0].poll() is not None:
            raise RuntimeError((root / "scheduler.log").read_text())
        time.sleep(0.1)
    for i in range(workers):
        processes.append(
            _dask(
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
        client.wait_for_workers(workers, timeout=120)
    return address, processes


def run_job(
    blend: Path, out: Path, frames: int, extra: list[str], env: dict[str, str] | None = None
) -> dict[str, Any]:
    """One ``python -m addon.batch`` job: its wall time, the CPU time of the command, its report."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "addon.batch",
            str(blend),
            "--frames",
            f"1-{frames}",
            "--out",
            str(out),
            "--quiet",
            *extra,
        ],
        capture_output=True,
        text=True,
        env=env or ENV,
        cwd=str(REPO),
        check=False,
    )
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"batch job failed ({done.returncode}):\n{done.stdout}\n{done.stderr}")
    report = json.loads((out / "report.json").read_text())
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "tasks_s": report["seconds"], "report": report}


def read_back_cost(root: Path, blend: Path, repeat: int = 5) -> dict[str, Any]:
    """Seconds to decode a written 1920×1080 frame whole (PNG, multilayer EXR) against its write."""
    from addon.batch import read_back

    costs = {}
    for name, extra in (
        ("png_16bit_rgba", []),
        ("exr_multilayer_32bit", ["--format", "OPEN_EXR_MULTILAYER", "--color-depth", "32"]),
    ):
        out = root / f"readback_{name}"
        job = run_job(blend, out, 1, ["--output-pattern", "f_####", *extra])
        path = Path(job["report"]["written"][0])
        times = []
        for _ in range(repeat):
            started = time.perf_counter()
            read_back(path, (1920, 1080))
            times.append(time.perf_counter() - started)
        seconds = job["report"]["tasks"][0]["seconds"]
        costs[name] = {
            "bytes": path.stat().st_size,
            "read_back_median_s": statistics.median(times),
            "write_with_read_back_s": seconds.get("write"),
            "render_s": seconds.get("render"),
        }
    return costs


def run(out_dir: Path, repeat: int = 3, frames: int = 6) -> dict[str, Any]:
    """Measure and write ``batch_cluster.json`` into ``out_dir``; returns the data."""
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        root = Path(tmp)
        blends = {f"{w}x{h}": root / f"showcase_{w}x{h}.blend" for w, h in SIZES}
        make = root / "make.py"
        make.write_text(MAKE)
        pairs = [str(v) for size, path in blends.items() for v in (path, size)]
        subprocess.run(
            [sys.executable, str(make), str(REPO / "blend_files" / "showcase.blend"), *pairs],
            env=ENV,
            cwd=str(REPO),
            check=True,
            capture_output=True,
        )
        address, processes = start_cluster(root)
        try:
            executors = {
                "one_process": ([], ENV),
                # The peer that shows what one core does: the renderer's kernels run on every core
                # (numba threads) unless told otherwise.
                "one_process_1_thread": ([], dict(ENV, NUMBA_NUM_THREADS="1")),
                "dask_2_workers": (["--scheduler", address], ENV),
            }
            smallest = next(iter(blends.values()))
            for name, (extra, env) in executors.items():  # warm-up: bpy imported, kernels loaded
                for _ in range(2):
                    run_job(smallest, root / f"warm_{name}", frames, extra, env)
            samples: dict[str, dict[str, list[dict[str, Any]]]] = {
                size: {name: [] for name in executors} for size in blends
            }
            for round_ in range(repeat):
                for size, blend in blends.items():
                    for name, (extra, env) in executors.items():
                        job = run_job(blend, root / f"{size}_{name}_{round_}", frames, extra, env)
                        tasks = job["report"]["tasks"]
                        samples[size][name].append(
                            {
                                "wall_s": job["wall_s"],
                                "tasks_s": job["tasks_s"],
                                "command_cpu_s": job["cpu_s"],
                                "render_s": [t["seconds"].get("render", 0.0) for t in tasks],
                                "task_total_s": [t["seconds"].get("total", 0.0) for t in tasks],
                            }
                        )
                        print(f"{size} {name}: {job['wall_s']:.2f} s wall", flush=True)
            readback = read_back_cost(root, blends["1920x1080"])
        finally:
            for process in reversed(processes):
                _stop(process)
    results = []
    for size, by_executor in samples.items():
        entry: dict[str, Any] = {"size": size, "frames": frames}
        for name, runs in by_executor.items():
            entry[name] = {
                "wall_median_s": statistics.median(r["wall_s"] for r in runs),
                "tasks_median_s": statistics.median(r["tasks_s"] for r in runs),
                "runs": runs,
            }
        single = by_executor["one_process"]
        entry["render_per_frame_median_s"] = statistics.median(s for r in single for s in r["render_s"])
        # CPU seconds per wall second of the one-process command: ~1 serial, ~cpus all cores busy.
        entry["one_process_cores_used"] = statistics.median(r["command_cpu_s"] / r["wall_s"] for r in single)
        cluster, one = entry["dask_2_workers"], entry["one_process"]
        entry["ratio_wall"] = cluster["wall_median_s"] / one["wall_median_s"]
        entry["ratio_tasks"] = cluster["tasks_median_s"] / one["tasks_median_s"]
        entry["ratio_wall_vs_1_thread"] = (
            cluster["wall_median_s"] / entry["one_process_1_thread"]["wall_median_s"]
        )
        results.append(entry)
    pays_off = next((e["size"] for e in results if e["ratio_wall"] < 1.0), None)
    data = {
        "benchmark": "batch_cluster",
        "scene": "blend_files/showcase.blend at each size, PNG (the file's own format)",
        "machine": machine_info(),
        "repeat": repeat,
        "results": results,
        "cluster_faster_from": pays_off,
        "read_back_1920x1080": readback,
    }
    write_json(out_dir / "batch_cluster.json", data)
    return data


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--frames", type=int, default=6)
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))  # stop the cluster it started (finally)
    data = run(args.out, repeat=args.repeat, frames=args.frames)
    rows = [
        [
            e["size"],
            f"{e['render_per_frame_median_s']:.3f}",
            f"{e['one_process_cores_used']:.2f}",
            f"{e['one_process']['wall_median_s']:.2f}",
            f"{e['one_process_1_thread']['wall_median_s']:.2f}",
            f"{e['dask_2_workers']['wall_median_s']:.2f}",
            f"{e['ratio_wall']:.2f}",
            f"{e['ratio_tasks']:.2f}",
            f"{e['ratio_wall_vs_1_thread']:.2f}",
        ]
        for e in data["results"]
    ]
    header = [
        "size",
        "render/frame (s)",
        "cores used",
        "one process (s)",
        "1 thread (s)",
        "2-worker cluster (s)",
        "cluster/one (wall)",
        "cluster/one (tasks)",
        "cluster/1 thread",
    ]
    print(markdown_table(header, rows))
    print(f"cluster faster from: {data['cluster_faster_from']}; read-back: {data['read_back_1920x1080']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
