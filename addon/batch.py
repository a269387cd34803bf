"""Headless batch jobs: render frames with the Blinn-Phong engine, composite, verify, report.

Two ways to run the same job::

    python -m addon.batch scene.blend other.blend --frames 1-4 --out out/batch \\
        --background backplate.exr --operator src_over --verify --workers 2
    blender -b scene.blend -P addon/batch.py -- --frames 1-4 --out out/batch

For every (file, frame) task: open the file, render the frame with the engine into
``OUT/<file>_<frame>.exr`` (linear premultiplied RGBA), optionally composite it over a background
with any operator of ``compositing`` (``..._<operator>.exr`` and ``.png``), optionally run the same
composite through Blender's compositor (``addon.verify``: Alpha Over for ``src_over``, the
Porter-Duff node group otherwise) and compare. ``OUT/report.json`` lists every task with its
timings, outputs, errors and verification errors.

Parallelism: ``--workers N`` runs tasks in N processes, each with its own ``bpy`` (a Blender is one
global per process); ``--scheduler tcp://host:8786`` sends them to a Dask distributed cluster whose
workers have this repository and ``bpy`` installed (``--dask-local N`` starts a local cluster on
loopback). Under ``blender -P`` tasks run in the Blender process itself.

Exit code: 0 when every task rendered and every verification stayed within ``--tolerance``,
1 otherwise, 2 for usage errors. A progress bar on a terminal, one plain line per task otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TextIO

__all__ = ["Task", "main", "parse_frames", "run_task", "run_tasks"]

REPO_ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Task:
    """One frame of one .blend file and what to do with it (plain data: it travels to workers)."""

    blend: str
    frame: int
    out_dir: str
    background: str | None = None
    operator: str = "src_over"
    verify: bool = False
    tolerance: float = 1e-5

    @property
    def stem(self) -> str:
        """Base name of this task's outputs: ``<file>_<frame:04d>``."""
        return f"{Path(self.blend).stem}_{self.frame:04d}"


def parse_frames(text: str) -> list[int]:
    """Frames from ``"1-5,7,10-12"`` (inclusive ranges), in the given order, without repeats.

    Raises:
        ValueError: empty text, a malformed item or a range running backwards.
    """
    frames: list[int] = []
    for item in (part.strip() for part in text.split(",")):
        if not item:
            raise ValueError(f"frames: empty item in {text!r}; expected e.g. '1-5,7'")
        first, sep, last = item.partition("-") if not item.startswith("-") else (item, "", "")
        try:
            lo = int(first)
            hi = int(last) if sep else lo
        except ValueError:
            raise ValueError(f"frames: expected integers or ranges like '1-5', got {item!r}") from None
        if hi < lo:
            raise ValueError(f"frames: range {item!r} runs backwards")
        frames.extend(f for f in range(lo, hi + 1) if f not in frames)
    return frames


def _background_image(spec: str, height: int, width: int) -> Any:
    """The background: an image file of the render's size, or a colour ``r,g,b[,a]`` (linear, straight)."""
    import numpy as np

    try:
        values = [float(v) for v in spec.split(",")]
    except ValueError:
        values = []
    if not values:
        from compositing.io import read_image

        image = read_image(spec)
        if image.shape[:2] != (height, width):
            raise ValueError(
                f"background: {spec} is {image.shape[1]}×{image.shape[0]} but the render is {width}×{height}"
            )
        return image
    if len(values) not in (3, 4):
        raise ValueError(f"background: expected 3 or 4 numbers, got {len(values)} in {spec!r}")
    rgba = np.array([*values[:3], values[3] if len(values) == 4 else 1.0], dtype=np.float32)
    rgba[:3] *= rgba[3]  # premultiply
    return np.broadcast_to(rgba, (height, width, 4)).copy()


def _engine_module() -> Any:
    """The module of the registered Blinn-Phong engine (repository copy or installed extension)."""
    import bpy

    for cls in bpy.types.RenderEngine.__subclasses__():
        if getattr(cls, "bl_idname", None) == "BLINN_PHONG" and getattr(cls, "is_registered", False):
            return sys.modules[cls.__module__]
    return None


def run_task(task: Task | dict) -> dict[str, Any]:
    """Run one task in this process (which must have ``bpy``); never raises, returns a result dict."""
    if isinstance(task, dict):
        task = Task(**task)
    started = time.perf_counter()
    result: dict[str, Any] = {"task": asdict(task), "ok": False, "error": None, "outputs": {}, "seconds": {}}
    registered_here: list[Any] = []
    try:
        import bpy

        from . import engine, properties

        if _engine_module() is None:
            for module in (properties, engine):
                module.register()
                registered_here.append(module)
        bpy.ops.wm.open_mainfile(filepath=str(Path(task.blend).resolve()), load_ui=False)
        scene = bpy.context.scene
        scene.render.engine = engine.ENGINE_ID
        scene.blinn_phong.abort_on_error = False
        scene.frame_set(task.frame)
        settings = scene.render.image_settings
        settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
        out_dir = Path(task.out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        render_path = out_dir / f"{task.stem}.exr"
        scene.render.filepath = str(render_path)
        t = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        result["seconds"]["render"] = time.perf_counter() - t
        status = dict(_engine_module().LAST_RENDER)
        result["render"] = {k: status.get(k) for k in ("ok", "error", "choices", "notes", "size")}
        if not status.get("ok"):
            raise RuntimeError(status.get("error") or "the engine reported no successful render")
        if not render_path.exists():
            raise RuntimeError(f"Blender wrote no image at {render_path}")
        result["outputs"]["render"] = str(render_path)
        if task.background:
            _composite_and_verify(task, render_path, result)
        result["ok"] = result.get("verify", {}).get("ok", True)
        if not result["ok"]:
            result["error"] = (
                f"verification error {result['verify']['max_abs_error']:.3g} exceeds {task.tolerance:g}"
            )
    except Exception as error:
        result["error"] = f"{type(error).__name__}: {error}"
        result["traceback"] = traceback.format_exc()
    finally:
        for module in reversed(registered_here):
            try:
                module.unregister()
            except Exception as error:
                result.setdefault("cleanup_errors", []).append(repr(error))
        result["seconds"]["total"] = time.perf_counter() - started
        result["pid"] = os.getpid()
    return result


def _composite_and_verify(task: Task, render_path: Path, result: dict[str, Any]) -> None:
    from compositing import composite
    from compositing.io import read_image, write_image

    rendered = read_image(render_path)
    background = _background_image(task.background, *rendered.shape[:2])
    t = time.perf_counter()
    composited = composite(rendered, background, task.operator)
    result["seconds"]["composite"] = time.perf_counter() - t
    stem = Path(task.out_dir) / f"{task.stem}_{task.operator}"
    write_image(stem.with_suffix(".exr"), composited)
    write_image(stem.with_suffix(".png"), composited, clip=True)
    result["outputs"]["composite"] = str(stem.with_suffix(".exr"))
    result["outputs"]["preview"] = str(stem.with_suffix(".png"))
    if task.verify:
        from .verify import verify

        t = time.perf_counter()
        via = "alpha_over" if task.operator == "src_over" else "node_group"
        check = verify(rendered, background, task.operator, via=via)
        result["seconds"]["verify"] = time.perf_counter() - t
        result["verify"] = {
            "via": via,
            "max_abs_error": check.max_abs_error,
            "mean_abs_error": check.mean_abs_error,
            "ok": check.max_abs_error <= task.tolerance,
        }


# --------------------------------------------------------------------------- executors


class Progress:
    """A progress bar on a terminal, one plain line per finished task otherwise."""

    def __init__(self, total: int, stream: TextIO = sys.stderr) -> None:
        self.total, self.done, self.failed, self.stream = total, 0, 0, stream
        self.tty = stream.isatty()

    def update(self, result: dict[str, Any]) -> None:
        """Record one finished task."""
        self.done += 1
        self.failed += not result["ok"]
        task = result["task"]
        name = f"{Path(task['blend']).name} frame {task['frame']}"
        error = str(result["error"]).strip().splitlines()[0] if result["error"] else ""
        status = "ok" if result["ok"] else f"FAILED ({error})"
        if self.tty:
            width = 30
            filled = width * self.done // max(self.total, 1)
            bar = "#" * filled + "-" * (width - filled)
            self.stream.write(
                f"\r[{bar}] {self.done}/{self.total} {self.failed} failed  {name}: {status[:40]:40}"
            )
            if self.done == self.total:
                self.stream.write("\n")
        else:
            seconds = result["seconds"].get("total", 0.0)
            self.stream.write(f"[{self.done}/{self.total}] {name}: {status} ({seconds:.2f} s)\n")
        self.stream.flush()


def _worker_environment() -> None:
    """Make the repository importable in spawned workers (they start a fresh interpreter)."""
    paths = os.environ.get("PYTHONPATH", "").split(os.pathsep)
    if str(REPO_ROOT) not in paths:
        os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO_ROOT), *paths) if p)


def run_tasks(
    tasks: Sequence[Task],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    dask_local: int = 0,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Run tasks in this process, in ``workers`` processes, or on a Dask cluster; results in task order."""
    payload = [asdict(t) for t in tasks]
    results: list[dict[str, Any] | None] = [None] * len(tasks)

    def finished(index: int, result: dict[str, Any]) -> None:
        results[index] = result
        if on_result is not None:
            on_result(result)

    if scheduler or dask_local:
        _run_dask(payload, scheduler, dask_local, finished)
    elif workers > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        _worker_environment()
        with ProcessPoolExecutor(
            max_workers=workers, mp_context=multiprocessing.get_context("spawn")
        ) as pool:
            futures = {pool.submit(run_task, item): i for i, item in enumerate(payload)}
            for future in as_completed(futures):
                finished(futures[future], _result_or_failure(future, payload[futures[future]]))
    else:
        for i, item in enumerate(payload):
            finished(i, run_task(item))
    return [r for r in results if r is not None]


def _result_or_failure(future: Any, item: dict[str, Any]) -> dict[str, Any]:
    """A worker's result, or a failure record when the worker itself died."""
    try:
        return future.result()
    except Exception as error:
        return {
            "task": item,
            "ok": False,
            "error": f"worker failed: {type(error).__name__}: {error}",
            "outputs": {},
            "seconds": {},
        }


def _run_dask(
    payload: list[dict[str, Any]],
    scheduler: str | None,
    local_workers: int,
    finished: Callable[[int, dict[str, Any]], None],
) -> None:
    from distributed import Client, LocalCluster, as_completed

    _worker_environment()
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(
            n_workers=local_workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        )
    try:
        with Client(scheduler or cluster) as client:
            futures = client.map(run_task, payload, pure=False)
            index = {f.key: i for i, f in enumerate(futures)}
            for future in as_completed(futures):
                finished(index[future.key], _result_or_failure(future, payload[index[future.key]]))
    finally:
        if cluster is not None:
            cluster.close()


# --------------------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface (see the module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m addon.batch", description=__doc__.splitlines()[0])
    parser.add_argument("blend", nargs="*", help=".blend files (default under blender -P: the open file)")
    parser.add_argument("--frames", default=None, help="frames, e.g. '1-5,7' (default: the current frame)")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--background", help="composite over this image (same size) or colour 'r,g,b[,a]'")
    parser.add_argument("--operator", default="src_over", help="compositing operator (default src_over)")
    parser.add_argument(
        "--verify", action="store_true", help="also composite in Blender's compositor and compare"
    )
    parser.add_argument("--tolerance", type=float, default=1e-5, help="max |ours - Blender| (default 1e-5)")
    parser.add_argument("--workers", type=int, default=1, help="render in N processes (default 1)")
    parser.add_argument("--scheduler", help="Dask distributed scheduler address, e.g. tcp://host:8786")
    parser.add_argument(
        "--dask-local",
        type=int,
        default=0,
        metavar="N",
        help="start a local Dask cluster of N workers on loopback",
    )
    parser.add_argument("--report", type=Path, help="JSON report path (default OUT/report.json)")
    return parser


def _default_blend_and_frame() -> tuple[str | None, int | None]:
    """The open file and its current frame when running inside Blender (``blender -b f.blend -P``)."""
    if "bpy" not in sys.modules:
        return None, None
    import bpy

    return (bpy.data.filepath or None), bpy.context.scene.frame_current


def _inside_blender_binary() -> bool:
    """True under ``blender -b ... -P``: Blender's own executable, not the ``bpy`` module.

    Worker processes start ``sys.executable``, which in a Blender binary is its bundled Python
    without ``bpy``. ``bpy.app.binary_path`` is empty in the ``bpy`` module.
    """
    if "bpy" not in sys.modules:
        return False
    import bpy

    return bool(bpy.app.binary_path)


def make_tasks(args: argparse.Namespace, blends: Iterable[str], default_frame: int | None) -> list[Task]:
    """One task per (file, frame)."""
    frames = parse_frames(args.frames) if args.frames else [default_frame if default_frame is not None else 1]
    return [
        Task(
            str(Path(b).resolve()),
            f,
            str(args.out.resolve()),
            args.background,
            args.operator,
            args.verify,
            args.tolerance,
        )
        for b in blends
        for f in frames
    ]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    parser = build_parser()
    args = parser.parse_args(list(argv))
    if args.workers < 1 or args.dask_local < 0:
        parser.error("--workers must be >= 1 and --dask-local >= 0")
    if (args.workers > 1 or args.scheduler or args.dask_local) and _inside_blender_binary():
        parser.error(
            "--workers, --scheduler and --dask-local start Python processes with the bpy module; "
            "inside Blender (blender -P) tasks run in this process: run python -m addon.batch instead"
        )
    open_file, current_frame = _default_blend_and_frame()
    blends = args.blend or ([open_file] if open_file else [])
    if not blends:
        parser.error("no .blend file given (and none is open)")
    try:
        from compositing import ALL_OPERATORS

        if args.operator not in ALL_OPERATORS:
            parser.error(f"--operator: expected one of {sorted(ALL_OPERATORS)}, got {args.operator!r}")
        tasks = make_tasks(args, blends, current_frame)
    except ValueError as error:
        parser.error(str(error))
    progress = Progress(len(tasks))
    started = time.perf_counter()
    results = run_tasks(
        tasks,
        workers=args.workers,
        scheduler=args.scheduler,
        dask_local=args.dask_local,
        on_result=progress.update,
    )
    failed = [r for r in results if not r["ok"]]
    report = {
        "tasks": results,
        "failed": len(failed),
        "total": len(results),
        "seconds": time.perf_counter() - started,
        "executor": "dask" if (args.scheduler or args.dask_local) else f"{args.workers} process(es)",
    }
    report_path = args.report or args.out / "report.json"
    report_path.parent.mkdir(parents=True, exist_ok=True)
    report_path.write_text(json.dumps(report, indent=1, default=str))
    ok_count = len(results) - len(failed)
    print(f"{ok_count}/{len(results)} tasks ok in {report['seconds']:.1f} s; report: {report_path}")
    return 0 if not failed and len(results) == len(tasks) else 1


if __name__ == "__main__":
    if __package__ in (None, ""):
        # Run as a script (``blender -b file.blend -P addon/batch.py -- ...``): import the package
        # version of this module so that relative imports and worker pickling work as with ``-m``.
        import importlib

        sys.path.insert(0, str(REPO_ROOT))
        package_module = importlib.import_module(f"{Path(__file__).resolve().parent.name}.batch")
        code = package_module.main()
    else:
        code = main()
    sys.stdout.flush()
    sys.exit(code)
