"""Headless batch jobs: render frames with the Blinn-Phong engine, composite, verify, report.

Two ways to run the same job::

    python -m addon.batch sh010/lighting.blend sh020/lighting.blend --frames 1-4 --out out/batch \\
        --background backplate.exr --operator src_over --verify --workers 2
    blender -b scene.blend -P addon/batch.py -- --frames 1-4 --out out/batch

Outputs follow the file's own settings, as ``blender -b f.blend -a`` would: each frame goes to
``scene.render.filepath`` (``#`` frame padding, ``//`` relative to the .blend, Blender's path
templates such as ``{blend_name}`` in 5.0; a plain relative path is taken relative to ``--out``) in
the file's format and colour depth. ``--output-pattern`` and ``--format``/``--color-depth`` override
them; ``--format OPEN_EXR_MULTILAYER`` writes every pass the engine produces (Combined, Depth,
Ambient, Diffuse, Specular, Shadow) under Blender's own layer names (``ViewLayer.Diffuse.R``...).
Two tasks writing the same file are refused before anything renders (exit 2).

With ``--deep`` (also taken from the file's Deep EXR setting, ``Scene.blinn_phong.deep_output``)
each frame's deep image — every fragment the transparency resolve composites, from the same render
pass — is written next to its output as ``<output without its extension>.deep.exr``
(``shot_0001.png`` → ``shot_0001.deep.exr``; deep OpenEXR ``R, G, B, A, Z, ZBack`` through
``compositing.deep_io``), one more output of the frame like the others (skipped, placeholders,
read back, reported). It needs the file's Transparency to be A-Buffer, Depth Peeling or Opaque: any
other is refused before the first render (exit 2), naming the file and the setting.

With ``--background`` each frame is composited over an image or colour with any operator of
``compositing`` (``<output>_<operator>.exr`` linear and ``.png`` preview, next to the render);
``--verify`` runs the same composite through Blender's compositor (``addon.verify``) and compares.

Every input is checked before the first render: files, frame ranges (Blender's ±1,048,574),
operator, numbers, the scheduler's address, every output folder (writable), and the background's
size against each file's render size. Every file is written to a temporary name in its directory
(carrying the job's id), read back whole (every part decoded, the render's size) and only then
renamed over the target: a failed write — also one Blender only logs, such as a full disk — fails
the task and keeps the previous file, and a killed task never leaves a truncated file. A job removes
only its own temporary files, so jobs may share an output folder. ``--skip-existing`` (Blender's
Overwrite off, also taken from the file) renders only frames whose outputs are not whole images;
``--placeholders`` (Blender's Placeholders) marks frames in progress with an empty file. Each job
writes its record to ``OUT/reports/<time>-<job>.json`` and to ``OUT/report.json`` (the last job to
end): every task, every file written, files outside ``--out``, skipped frames, retries, warnings.

Once the job has returned, no file it could write changes: every write holds a permit in the job's
folder ``OUT/.batch-<job>``, which the job renames (so no permit can be taken) and empties at its
end, after the writes under way have finished (see :func:`write_permit`).

Parallelism: ``--workers N`` runs tasks in N worker processes, each with its own ``bpy``. A worker
that dies (or exceeds ``--timeout``) is replaced by a fresh process and only its own task is
retried, at most ``--retries`` times; healthy tasks are untouched and every attempt is in the
report. ``--scheduler tcp://host:8786`` sends the tasks to a Dask distributed cluster whose workers
have this repository and ``bpy`` installed and share the output storage (see ``docs/addon.md``);
it must answer within ``--connect-timeout`` seconds. Dask reschedules the task of a lost worker
itself, as often as the scheduler's ``allowed-failures`` setting says (``--retries`` is refused with
``--scheduler``); each result is released as soon as it arrives, so a worker lost later never makes
the cluster render a finished frame again. ``--dask-local N`` starts a Dask cluster of N workers
on loopback. Under ``blender -P`` tasks run in the Blender process itself.

Exit codes (the same for ``python -m addon.verify``): 0 every task rendered and every verification
stayed within ``--tolerance``; 1 a task or a check failed, or the job was interrupted (SIGINT,
SIGTERM: workers are stopped, the report records what finished and ``interrupted``); 2 usage error
(nothing was rendered).
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __name__ == "__main__" and __package__ in (None, ""):
    # Run as a script (``blender -b file.blend -P addon/batch.py -- ...``): run the package version
    # of this module instead, so that relative imports and worker pickling work as with ``-m``.
    import importlib

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    _code = importlib.import_module(f"{Path(__file__).resolve().parent.name}.batch").main()
    sys.stdout.flush()
    sys.exit(_code)

# The job's parts, one module each, imported in one direction (each only from the ones above it):
# batch_job (plain data) <- batch_files (atomic writes, permits) <- batch_task (one frame)
# <- batch_executors (process pool, Dask), batch_cli (arguments) <- batch_plan, batch_report;
# this module runs the job and re-exports their public names.
from .batch_cli import (
    _default_blend_and_frame,
    _inside_blender_binary,
    build_parser,
    check_arguments,
)
from .batch_executors import _attempts_from_markers as _attempts_from_markers
from .batch_executors import probe_scheduler, run_tasks
from .batch_files import (
    _cleanup_temporaries,
    _late_writes,
    _remove_job_dir,
    atomic_target,
    close_job,
    read_back,
    readable,
    write_permit,
)
from .batch_files import temporary_prefix as temporary_prefix
from .batch_files import write_text_atomic as write_text_atomic
from .batch_job import CLOSE_WAIT_S as CLOSE_WAIT_S
from .batch_job import CONNECT_TIMEOUT_S as CONNECT_TIMEOUT_S
from .batch_job import (
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    FORMATS,
    MAX_FRAME,
    MIN_FRAME,
    JobClosed,
    SchedulerUnreachable,
    Task,
    UsageError,
    _trim,
    parse_frames,
)
from .batch_job import MAX_PIXELS as MAX_PIXELS
from .batch_job import PERMIT_STALE_S as PERMIT_STALE_S
from .batch_job import REPO_ROOT as REPO_ROOT
from .batch_job import parse_colour as parse_colour
from .batch_job import parse_scheduler as parse_scheduler
from .batch_plan import Plan as Plan
from .batch_plan import plan_job
from .batch_report import Progress, _unreachable, _write_reports
from .batch_task import _finish_attempt as _finish_attempt
from .batch_task import _finished_result as _finished_result
from .batch_task import _record_attempt as _record_attempt
from .batch_task import run_task

__all__ = [
    "EXIT_FAILED",
    "EXIT_OK",
    "EXIT_USAGE",
    "FORMATS",
    "MAX_FRAME",
    "MIN_FRAME",
    "JobClosed",
    "SchedulerUnreachable",
    "Task",
    "UsageError",
    "atomic_target",
    "main",
    "parse_frames",
    "read_back",
    "readable",
    "run_task",
    "run_tasks",
    "write_permit",
]


class _Terminated(Exception):
    """SIGTERM arrived (a farm manager or ``kill`` stopping the job)."""


def _on_sigterm_raise() -> Any:
    """In the main thread: make SIGTERM raise :class:`_Terminated`; returns the previous handler."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: Any) -> None:
        raise _Terminated

    return signal.signal(signal.SIGTERM, handler)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code (0 ok, 1 a task or check failed, 2 usage error)."""
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
    parser = build_parser()
    args = parser.parse_args(list(argv))
    if (args.workers > 1 or args.timeout or args.scheduler or args.dask_local) and _inside_blender_binary():
        parser.error(
            "--workers, --timeout, --scheduler and --dask-local start Python processes with the bpy module; "
            "inside Blender (blender -P) tasks run in this process: run python -m addon.batch instead"
        )
    open_file, current_frame = _default_blend_and_frame()
    blends = args.blend or ([open_file] if open_file else [])
    if not blends:
        parser.error("no .blend file given (and none is open)")
    try:
        frames = check_arguments(args, blends)
        if frames is None and current_frame is not None and not args.blend:
            frames = [current_frame]
    except UsageError as error:
        parser.error(str(error))
    retries = 2 if args.retries is None else args.retries
    executor = (
        "dask"
        if (args.scheduler or args.dask_local)
        else (f"{args.workers} process(es)" if args.workers > 1 or args.timeout else "this process")
    )
    started = time.perf_counter()
    started_wall_ns = time.time_ns()
    if args.scheduler:  # before opening any file: an unreachable cluster is known in seconds
        try:
            probe_scheduler(args.scheduler, args.connect_timeout)
        except SchedulerUnreachable as error:
            return _unreachable(args, error, executor, started)
    try:
        plan = plan_job(args, blends, frames)
    except UsageError as error:
        parser.error(str(error))
    progress = Progress(len(plan.tasks), quiet=args.quiet)
    for warning in plan.warnings:
        print(f"warning: {warning}", file=sys.stderr, flush=True)
    for item in plan.skipped:
        progress.note(f"{Path(item['blend']).name} frame {item['frame']}: skipped (outputs exist)")
    arrived: list[dict[str, Any]] = []

    def on_result(result: dict[str, Any]) -> None:
        arrived.append(result)
        progress.update(result)

    interrupted = None
    error_text = None
    info: dict[str, Any] = {}
    closing_warnings: list[str] = []
    if plan.tasks and plan.attempt_dir:
        Path(plan.attempt_dir).mkdir(parents=True, exist_ok=True)
    previous = _on_sigterm_raise()
    try:
        results = run_tasks(
            plan.tasks,
            workers=args.workers,
            scheduler=args.scheduler,
            dask_local=args.dask_local,
            timeout=args.timeout,
            retries=retries,
            on_result=on_result,
            note=progress.note,
            connect_timeout=args.connect_timeout,
            info=info,
        )
    except (KeyboardInterrupt, _Terminated) as stop:
        # Ctrl-C or a farm manager's SIGTERM: stop the workers, keep what finished, say so.
        interrupted = "SIGINT" if isinstance(stop, KeyboardInterrupt) else "SIGTERM"
        results = list(arrived)
    except SchedulerUnreachable as error:
        error_text = str(error)
        results = list(arrived)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        progress.close()
        # The job ends here: from now on no task of it can write (see write_permit), then what its
        # lost attempts left behind is removed.
        closed = None
        if plan.attempt_dir:
            closed, closing_warnings = close_job(plan.attempt_dir)
        _cleanup_temporaries(plan.tasks)
        _remove_job_dir(closed)
    failed = [r for r in results if not r["ok"]]
    finished_ok = {r["task"]["output"] for r in results if r["ok"]}
    for task in plan.tasks:  # placeholders of tasks that failed, were killed or never finished
        if task.output in finished_ok:
            continue
        for marked in map(Path, task.placeholder_paths()):
            if marked.is_file() and marked.stat().st_size == 0:
                marked.unlink()
    warnings = list(plan.warnings)
    for result in results:
        result["error"] = _trim(result["error"]) if result["error"] else None
    for warning in [*(w for r in results for w in r.get("warnings", [])), *closing_warnings]:
        if warning not in warnings:
            warnings.append(warning)
            print(f"warning: {warning}", file=sys.stderr, flush=True)
    written = [path for r in results for path in r.get("written", [])]
    # A task whose result never arrived (the job was stopped) may still have finished its write
    # while the job waited for writes under way: list those files too, so that the report names
    # every file the job wrote.
    arrived_outputs = {r["task"]["output"] for r in results}
    unanswered = [task for task in plan.tasks if task.output not in arrived_outputs]
    for path in _late_writes(unanswered, set(written), started_wall_ns):
        written.append(path)
        warning = f"{path} was written by a task that finished while the job was ending"
        warnings.append(warning)
        print(f"warning: {warning}", file=sys.stderr, flush=True)
    retried = [r for r in results if len(r.get("attempts", [])) > 1]
    report = {
        "job": plan.job,
        "tasks": results,
        "failed": len(failed),
        "total": len(results),
        "written": written,
        "outside_out": plan.outside_out,
        "skipped": plan.skipped,
        "retried": [
            {"blend": r["task"]["blend"], "frame": r["task"]["frame"], "attempts": r["attempts"]}
            for r in retried
        ],
        "warnings": warnings,
        "seconds": time.perf_counter() - started,
        "executor": executor,
        **info,
    }
    code = EXIT_OK if not failed and len(results) == len(plan.tasks) and not error_text else EXIT_FAILED
    report["exit_code"] = code
    report["interrupted"] = interrupted
    report["error"] = error_text
    if interrupted:
        print(
            f"interrupted ({interrupted}): {len(plan.tasks) - len(results)} task(s) not finished",
            file=sys.stderr,
        )
    if error_text:
        print(f"error: {error_text}", file=sys.stderr)
    report_path = _write_reports(args, report)
    if not args.quiet:
        for path in written:
            print(f"wrote {path}")
    ok_count = len(results) - len(failed)
    print(
        f"{ok_count}/{len(results)} tasks ok, {len(written)} files written, {len(plan.skipped)} skipped, "
        f"{len(retried)} retried in {report['seconds']:.1f} s; report: {report_path}"
    )
    return code


if __name__ == "__main__":  # python -m addon.batch (run as a script: see the top of this module)
    code = main()
    sys.stdout.flush()
    sys.exit(code)
