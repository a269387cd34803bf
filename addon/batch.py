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

With ``--background`` each frame is composited over an image or colour with any operator of
``compositing`` (``<output>_<operator>.exr`` linear and ``.png`` preview, next to the render);
``--verify`` runs the same composite through Blender's compositor (``addon.verify``) and compares.

Every input is checked before the first render: files, frame ranges, operator, numbers, and the
background's size against each file's render size. Every file is written to a temporary name in its
directory and renamed over the target, so a failed or killed task never leaves a truncated file.
``--skip-existing`` (Blender's Overwrite off, also taken from the file) renders only frames whose
outputs are missing; ``--placeholders`` (Blender's Placeholders) marks frames in progress with an
empty file. ``OUT/report.json`` lists every task, every file written, skipped frames, retries and
warnings.

Parallelism: ``--workers N`` runs tasks in N worker processes, each with its own ``bpy``. A worker
that dies (or exceeds ``--timeout``) is replaced by a fresh process and only its own task is
retried, at most ``--retries`` times; healthy tasks are untouched and every attempt is in the
report. ``--scheduler tcp://host:8786`` sends the tasks to a Dask distributed cluster whose workers
have this repository and ``bpy`` installed and share the output storage (see ``docs/addon.md``);
Dask reschedules the task of a lost worker itself. ``--dask-local N`` starts a Dask cluster of N
workers on loopback. Under ``blender -P`` tasks run in the Blender process itself.

Exit codes (the same for ``python -m addon.verify``): 0 every task rendered and every verification
stayed within ``--tolerance``; 1 a task or a check failed, or the job was interrupted (SIGINT,
SIGTERM: workers are stopped, the report records what finished and ``interrupted``); 2 usage error
(nothing was rendered).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import signal
import socket
import sys
import threading
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TextIO

__all__ = [
    "EXIT_FAILED",
    "EXIT_OK",
    "EXIT_USAGE",
    "FORMATS",
    "Task",
    "UsageError",
    "atomic_target",
    "main",
    "parse_frames",
    "run_task",
    "run_tasks",
]

REPO_ROOT = Path(__file__).resolve().parents[1]

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2
"""Exit codes of ``addon.batch`` and ``addon.verify``: ok, a task or check failed, usage error."""

#: ``--format`` values (Blender's ``ImageFormatSettings.file_format`` identifiers) and their depths.
FORMATS: dict[str, tuple[str, ...]] = {
    "OPEN_EXR": ("16", "32"),
    "OPEN_EXR_MULTILAYER": ("16", "32"),
    "PNG": ("8", "16"),
    "TIFF": ("8", "16"),
    "JPEG": ("8",),
    "TARGA": ("8",),
    "BMP": ("8",),
}

#: Bytes per pixel and channel the largest frame may need while compositing (float32 RGBA, a few
#: copies): refuse backgrounds whose decoded size alone exceeds this many pixels.
MAX_PIXELS = 1 << 26


class UsageError(ValueError):
    """A bad command-line input, found before anything ran; the message names the flag."""


@dataclass(frozen=True)
class Task:
    """One frame of one .blend file and what to do with it (plain data: it travels to workers).

    ``output`` is the absolute path of the render (resolved before the job starts);
    ``file_format``/``color_depth`` the image settings it is written with (None: the file's own).
    """

    blend: str
    frame: int
    out_dir: str
    output: str = ""
    file_format: str | None = None
    color_depth: str | None = None
    output_pattern: str | None = None
    background: str | None = None
    operator: str = "src_over"
    verify: bool = False
    tolerance: float = 1e-5
    placeholder: bool = False
    timeout: float | None = None
    attempt_dir: str | None = None

    @property
    def stem(self) -> str:
        """A readable name of the task: ``<file>_<frame:04d>``."""
        return f"{Path(self.blend).stem}_{self.frame:04d}"

    @property
    def key(self) -> str:
        """A name unique within a job (the output path decides uniqueness)."""
        import hashlib

        return f"{self.stem}-{hashlib.sha1(self.output.encode()).hexdigest()[:8]}"

    def composite_paths(self) -> tuple[str, str]:
        """The composite (linear EXR) and its PNG preview, next to the render."""
        base = Path(self.output)
        stem = base.with_suffix("") if base.suffix else base
        return f"{stem}_{self.operator}.exr", f"{stem}_{self.operator}.png"

    def outputs(self) -> list[str]:
        """Every file this task writes."""
        return [self.output, *(self.composite_paths() if self.background else ())]


def parse_frames(text: str) -> list[int]:
    """Frames from ``"1-5,7,10-12"`` (inclusive ranges), in the given order, without repeats.

    Raises:
        ValueError: empty text, a malformed item or a range running backwards.
    """
    frames: list[int] = []
    seen: set[int] = set()
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
        if hi - lo > 1_000_000:
            raise ValueError(f"frames: range {item!r} has more than a million frames")
        for f in range(lo, hi + 1):
            if f not in seen:
                seen.add(f)
                frames.append(f)
    return frames


def parse_colour(spec: str) -> tuple[float, ...] | None:
    """``"r,g,b[,a]"`` (linear, straight alpha) as floats, or None when ``spec`` is not a list of numbers.

    Raises:
        ValueError: the right count of numbers but a non-finite value or alpha outside [0, 1], or a
            list of numbers of the wrong length.
    """
    parts = spec.split(",")
    try:
        values = tuple(float(v) for v in parts)
    except ValueError:
        return None
    if len(values) not in (3, 4):
        raise ValueError(f"expected 3 or 4 numbers 'r,g,b[,a]', got {len(values)} in {spec!r}")
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"expected finite numbers, got {spec!r}")
    if len(values) == 4 and not 0.0 <= values[3] <= 1.0:
        raise ValueError(f"alpha must be in [0, 1], got {values[3]:g}")
    return values


def _background_image(spec: str, height: int, width: int) -> Any:
    """The background: an image file of the render's size, or a colour ``r,g,b[,a]`` (linear, straight)."""
    import numpy as np

    values = parse_colour(spec)
    if values is None:
        from compositing.io import read_image

        image = read_image(spec)
        if image.shape[:2] != (height, width):
            raise ValueError(
                f"--background: {spec} is {image.shape[1]}×{image.shape[0]} "
                f"but the render is {width}×{height}"
            )
        return image
    rgba = np.array([*values[:3], values[3] if len(values) == 4 else 1.0], dtype=np.float32)
    rgba[:3] *= rgba[3]  # premultiply
    return np.broadcast_to(rgba, (height, width, 4)).copy()


# --------------------------------------------------------------------------- atomic files


@contextlib.contextmanager
def atomic_target(target: str | os.PathLike) -> Iterator[Path]:
    """Context manager: a temporary path in the target's directory, renamed over it on success.

    :func:`compositing._atomic.atomic_path` (the project's one atomic writer) plus two things a
    render job needs: the directory is created, and a writer that silently wrote nothing (an empty
    temporary file) is an error rather than an empty output. The temporary name keeps the
    extension (writers choose the format by it). On an exception the temporary file is removed
    and the target is left as it was.
    """
    from compositing._atomic import atomic_path

    path = Path(target)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        yield Path(tmp)
        if os.path.getsize(tmp) == 0:
            raise OSError(f"nothing was written to the temporary file {tmp} for {path}")


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, creating the directory (see :func:`atomic_target`)."""
    from compositing._atomic import write_text_atomic as write

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write(path, text)


# --------------------------------------------------------------------------- one task


def _engine_module() -> Any:
    """The module of the registered Blinn-Phong engine (repository copy or installed extension)."""
    import bpy

    for cls in bpy.types.RenderEngine.__subclasses__():
        if getattr(cls, "bl_idname", None) == "BLINN_PHONG" and getattr(cls, "is_registered", False):
            return sys.modules[cls.__module__]
    return None


_BLENDER_SCRIPTS = re.compile(r"[/\\](bpy|blender)[/\\]\d+\.\d+[/\\]scripts([/\\]|$)")


def _unshadow_bpy() -> None:
    """Drop Blender's script directories from ``sys.path`` in a process that has not imported bpy.

    Spawned workers inherit the parent's ``sys.path``; after ``import bpy`` it holds Blender's
    ``scripts/modules``, whose ``bpy`` package (for Blender's own executable) would shadow the
    ``bpy`` module. The worker's own ``import bpy`` adds them back.
    """
    if "bpy" not in sys.modules:
        sys.path[:] = [p for p in sys.path if not _BLENDER_SCRIPTS.search(p)]


def _trim(text: Any) -> str:
    """Error text without Blender's trailing newline and padding."""
    return str(text).strip()


def _record_attempt(task: Task) -> None:
    """Leave a marker ``<attempt_dir>/<key>.<host>.<pid>`` (shared storage): who started the task."""
    if not task.attempt_dir:
        return
    marker = Path(task.attempt_dir) / f"{task.key}.{socket.gethostname()}.{os.getpid()}"
    try:
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(
            json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "start": time.time()})
        )
    except OSError:
        pass  # the record is informative; never fail a render for it


def _watchdog(task: Task) -> threading.Timer | None:
    """In a Dask worker: end the worker process when the task outlives ``task.timeout``.

    A render cannot be interrupted from Python; the worker's nanny starts a fresh worker and the
    scheduler reschedules the task (its retries are bounded by ``distributed.scheduler.allowed-failures``).
    """
    if not task.timeout:
        return None
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return None

    def expire() -> None:
        print(
            f"addon.batch: {task.stem} exceeded --timeout {task.timeout:g} s; ending this worker",
            file=sys.stderr,
            flush=True,
        )
        os._exit(75)

    timer = threading.Timer(task.timeout, expire)
    timer.daemon = True
    timer.start()
    return timer


def run_task(task: Task | dict) -> dict[str, Any]:
    """Run one task in this process (which must have ``bpy``); never raises, returns a result dict.

    The result holds ``ok``, ``error`` (trimmed text), ``written`` (every file written, absolute
    paths), ``outputs`` by role, ``seconds`` per stage, ``warnings``, ``pid`` and ``host``.
    """
    if isinstance(task, dict):
        task = Task(**task)
    _unshadow_bpy()
    started = time.perf_counter()
    result: dict[str, Any] = {
        "task": asdict(task),
        "ok": False,
        "error": None,
        "outputs": {},
        "written": [],
        "warnings": [],
        "seconds": {},
        "pid": os.getpid(),
        "host": socket.gethostname(),
    }
    _record_attempt(task)
    timer = _watchdog(task)
    registered_here: list[Any] = []
    placeholder: Path | None = None
    try:
        import bpy

        from . import compat, engine, properties

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
        if task.file_format:
            compat.set_image_format(settings, task.file_format, task.color_depth)
        elif task.color_depth:
            settings.color_depth = task.color_depth
        output = Path(task.output)
        if task.placeholder and not output.exists():
            output.parent.mkdir(parents=True, exist_ok=True)
            try:
                fd = os.open(output, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
                os.close(fd)
                placeholder = output
            except FileExistsError:
                pass
        t = time.perf_counter()
        _engine_module().LAST_RENDER.clear()  # no status of an earlier task in this worker
        try:
            bpy.ops.render.render()
        except RuntimeError as error:  # Blender turns the engine's error report into an exception
            status = dict(_engine_module().LAST_RENDER)
            raise RuntimeError(_trim(status.get("error") or error)) from None
        result["seconds"]["render"] = time.perf_counter() - t
        status = dict(_engine_module().LAST_RENDER)
        # stats: seconds per stage, and "compile" when the frame waited for kernels to compile
        result["render"] = {k: status.get(k) for k in ("ok", "error", "choices", "notes", "size", "stats")}
        if not status.get("ok"):
            raise RuntimeError(_trim(status.get("error") or "the engine reported no successful render"))
        render_result = bpy.data.images["Render Result"]
        with atomic_target(output) as tmp:
            render_result.save_render(filepath=str(tmp), scene=scene)
        placeholder = None
        result["outputs"]["render"] = str(output)
        result["written"].append(str(output))
        result["format"] = {"file_format": settings.file_format, "color_depth": settings.color_depth}
        if task.background:
            rendered = _linear_render(scene, render_result, output, settings)
            _composite_and_verify(task, rendered, scene.render.film_transparent, result)
        result["ok"] = result.get("verify", {}).get("ok", True)
        if not result["ok"]:
            result["error"] = (
                f"verification error {result['verify']['max_abs_error']:.3g} exceeds "
                f"--tolerance {task.tolerance:g}"
            )
    except Exception as error:
        message = _trim(error)
        result["error"] = (
            message if message.startswith("Blinn-Phong") else f"{type(error).__name__}: {message}"
        )
        result["traceback"] = traceback.format_exc()
    finally:
        if timer is not None:
            timer.cancel()
        if placeholder is not None:
            try:
                if placeholder.stat().st_size == 0:
                    placeholder.unlink()
            except OSError:
                pass
        for module in reversed(registered_here):
            try:
                module.unregister()
            except Exception as error:
                result.setdefault("cleanup_errors", []).append(repr(error))
        result["seconds"]["total"] = time.perf_counter() - started
    return result


def _linear_render(scene: Any, render_result: Any, output: Path, settings: Any) -> Any:
    """The render as linear premultiplied float32 RGBA, whatever format the output file has."""
    import tempfile

    from compositing.io import read_image

    from . import compat
    from .verify import read_exr_layers

    if settings.file_format == "OPEN_EXR" and settings.color_depth == "32" and settings.color_mode == "RGBA":
        return read_image(output)
    if settings.file_format == "OPEN_EXR_MULTILAYER" and settings.color_depth == "32":
        layers = read_exr_layers(output)
        combined = [name for name in layers if name.endswith(".Combined")]
        if combined:
            return layers[combined[0]]
    # Another format (PNG, half float, ...): a linear 32-bit copy for compositing only.
    saved = (settings.file_format, settings.color_depth, settings.color_mode)
    with tempfile.TemporaryDirectory(prefix="batch-linear-") as tmp:
        path = Path(tmp) / "combined.exr"
        try:
            compat.set_image_format(settings, "OPEN_EXR", "32")
            settings.color_mode = "RGBA"
            render_result.save_render(filepath=str(path), scene=scene)
        finally:
            compat.set_image_format(settings, saved[0], saved[1])
            settings.color_mode = saved[2]
        return read_image(path)


def _composite_and_verify(task: Task, rendered: Any, film_transparent: bool, result: dict[str, Any]) -> None:
    import numpy as np

    from compositing import composite
    from compositing.io import write_image

    background = _background_image(task.background, *rendered.shape[:2])
    t = time.perf_counter()
    composited = composite(rendered, background, task.operator)
    result["seconds"]["composite"] = time.perf_counter() - t
    if film_transparent and np.array_equal(composited, rendered):
        # (With Film → Transparent off the job's plan has already warned once per file.)
        result["warnings"].append(
            f"{task.stem}: --background with --operator {task.operator} does not change the image"
        )
    exr_path, png_path = task.composite_paths()
    with atomic_target(exr_path) as tmp:
        write_image(tmp, composited)
    result["written"].append(exr_path)
    with atomic_target(png_path) as tmp:
        write_image(tmp, composited, clip=True)
    result["written"].append(png_path)
    result["outputs"]["composite"] = exr_path
    result["outputs"]["preview"] = png_path
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


# --------------------------------------------------------------------------- progress


class Progress:
    """A tqdm bar over frames on a terminal, one plain line per finished task otherwise.

    Everything goes to ``stream`` (stderr); ``quiet`` silences both. Per-frame time is shown as
    the bar's postfix and in the plain lines.
    """

    def __init__(self, total: int, stream: TextIO = sys.stderr, *, quiet: bool = False) -> None:
        self.total, self.done, self.failed, self.stream, self.quiet = total, 0, 0, stream, quiet
        self.bar = None
        if not quiet and stream.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, file=stream, unit="frame", dynamic_ncols=True)

    def note(self, text: str) -> None:
        """A line of text that does not break the bar (retries, warnings)."""
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            self.stream.write(text + "\n")
            self.stream.flush()

    def update(self, result: dict[str, Any]) -> None:
        """Record one finished task."""
        self.done += 1
        self.failed += not result["ok"]
        task = result["task"]
        name = f"{Path(task['blend']).name} frame {task['frame']}"
        error = _trim(result["error"]).splitlines()[0] if result["error"] else ""
        status = "ok" if result["ok"] else f"FAILED ({error})"
        seconds = result["seconds"].get("total", 0.0)
        if self.quiet:
            return
        if self.bar is not None:
            self.bar.set_postfix_str(f"{name} {seconds:.2f} s/frame, {self.failed} failed", refresh=False)
            if not result["ok"]:
                self.bar.write(f"{name}: {status}", file=self.stream)
            self.bar.update(1)
            if self.done == self.total:
                self.bar.close()
        else:
            self.stream.write(f"[{self.done}/{self.total}] {name}: {status} ({seconds:.2f} s)\n")
            self.stream.flush()

    def close(self) -> None:
        """Close the bar (if any)."""
        if self.bar is not None:
            self.bar.close()


# --------------------------------------------------------------------------- executors


def _worker_environment() -> None:
    """Make the repository importable in spawned workers (they start a fresh interpreter)."""
    paths = os.environ.get("PYTHONPATH", "").split(os.pathsep)
    if str(REPO_ROOT) not in paths:
        os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO_ROOT), *paths) if p)


def _worker_loop(conn: Any) -> None:
    """A worker process: run each task received on ``conn`` and send its result back; None ends."""
    while True:
        try:
            item = conn.recv()
        except EOFError:
            return
        if item is None:
            return
        conn.send(run_task(item))


@dataclass
class _Slot:
    process: Any
    conn: Any
    index: int | None = None
    deadline: float | None = None
    started: float = 0.0


@dataclass
class _Pending:
    index: int
    attempts: list[dict[str, Any]] = field(default_factory=list)


def _run_pool(
    payload: list[dict[str, Any]],
    workers: int,
    timeout: float | None,
    retries: int,
    finished: Callable[[int, dict[str, Any]], None],
    note: Callable[[str], None],
) -> None:
    """Run tasks on ``workers`` processes; a dead or timed-out worker is replaced and its task retried.

    Only the lost worker's own task is affected: it goes back to the queue (at most ``retries``
    times) with the attempt recorded; every other task keeps running where it is.
    """
    import multiprocessing
    from multiprocessing.connection import wait

    _worker_environment()
    context = multiprocessing.get_context("spawn")
    queue = [_Pending(i) for i in range(len(payload))]
    slots: list[_Slot] = []

    def spawn() -> _Slot:
        parent, child = context.Pipe()
        process = context.Process(target=_worker_loop, args=(child,), daemon=True)
        process.start()
        child.close()
        return _Slot(process, parent)

    def lost(slot: _Slot, reason: str, pending: dict[int, _Pending]) -> None:
        entry = pending.pop(slot.index)  # type: ignore[arg-type]
        item = payload[entry.index]
        entry.attempts.append({"pid": slot.process.pid, "host": socket.gethostname(), "outcome": reason})
        name = f"{Path(item['blend']).name} frame {item['frame']}"
        if len(entry.attempts) <= retries:
            note(f"{name}: {reason}; retrying on a fresh worker ({len(entry.attempts)}/{retries})")
            queue.insert(0, entry)
        else:
            finished(
                entry.index,
                {
                    "task": item,
                    "ok": False,
                    "error": f"{reason} ({len(entry.attempts)} attempt(s), --retries {retries})",
                    "outputs": {},
                    "written": [],
                    "warnings": [],
                    "seconds": {},
                    "attempts": entry.attempts,
                },
            )

    pending: dict[int, _Pending] = {}
    try:
        slots = [spawn() for _ in range(min(workers, len(payload)))]
        while queue or pending:
            for slot in slots:
                if slot.index is None and queue:
                    entry = queue.pop(0)
                    slot.index, slot.started = entry.index, time.monotonic()
                    slot.deadline = slot.started + timeout if timeout else None
                    pending[entry.index] = entry
                    slot.conn.send(payload[entry.index])
            now = time.monotonic()
            deadlines = [s.deadline - now for s in slots if s.index is not None and s.deadline]
            ready = wait(
                [s.conn for s in slots] + [s.process.sentinel for s in slots],
                timeout=max(0.0, min(deadlines)) if deadlines else None,
            )
            for i, slot in enumerate(list(slots)):
                if slot.conn in ready and slot.index is not None:
                    try:
                        result = slot.conn.recv()
                    except (EOFError, OSError):
                        result = None
                    if result is not None:
                        entry = pending.pop(slot.index)
                        result["attempts"] = [
                            *entry.attempts,
                            {
                                "pid": result.get("pid"),
                                "host": result.get("host"),
                                "outcome": "ok" if result["ok"] else "failed",
                            },
                        ]
                        finished(entry.index, result)
                        slot.index = slot.deadline = None
                        continue
                expired = slot.deadline is not None and time.monotonic() >= slot.deadline
                if slot.process.sentinel in ready or expired or (slot.conn in ready and slot.index is None):
                    if expired and slot.process.is_alive():
                        slot.process.kill()
                    slot.process.join(5)
                    if slot.index is not None:
                        reason = (
                            f"timed out after --timeout {timeout:g} s"
                            if expired
                            else f"worker process died (exit code {slot.process.exitcode})"
                        )
                        lost(slot, reason, pending)
                    slot.conn.close()
                    slots[i] = spawn() if (queue or pending) else slots[i]
                    if slots[i] is slot:
                        slot.index = slot.deadline = None
    finally:
        for slot in slots:
            if slot.index is not None and slot.process.is_alive():
                slot.process.kill()  # interrupted while busy: its task is not finished, stop it now
                continue
            try:
                slot.conn.send(None)
            except (OSError, ValueError):
                pass
        for slot in slots:
            slot.process.join(10)
            if slot.process.is_alive():
                slot.process.kill()
                slot.process.join(5)


def run_tasks(
    tasks: Sequence[Task],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    dask_local: int = 0,
    timeout: float | None = None,
    retries: int = 2,
    on_result: Callable[[dict[str, Any]], None] | None = None,
    note: Callable[[str], None] = lambda text: None,
) -> list[dict[str, Any]]:
    """Run tasks in this process, in ``workers`` processes, or on a Dask cluster; results in task order.

    Args:
        tasks: the tasks (output paths already resolved).
        workers: worker processes; 1 without ``timeout`` runs in this process.
        scheduler: a Dask scheduler address (``tcp://host:port``).
        dask_local: start a Dask cluster of this many workers on loopback.
        timeout: seconds per task before its worker is ended and the task retried.
        retries: how many times a task whose worker was lost is run again.
        on_result: called with each result as it arrives.
        note: receives one-line messages (retries) for the user.
    """
    payload = [asdict(t) for t in tasks]
    results: list[dict[str, Any] | None] = [None] * len(tasks)

    def finished(index: int, result: dict[str, Any]) -> None:
        results[index] = result
        if on_result is not None:
            on_result(result)

    if scheduler or dask_local:
        _run_dask(payload, scheduler, dask_local, retries, finished)
    elif workers > 1 or timeout:
        _run_pool(payload, workers, timeout, retries, finished, note)
    else:
        for i, item in enumerate(payload):
            result = run_task(item)
            result["attempts"] = [
                {"pid": result["pid"], "host": result["host"], "outcome": "ok" if result["ok"] else "failed"}
            ]
            finished(i, result)
    return [r for r in results if r is not None]


def _failure(item: dict[str, Any], error: BaseException) -> dict[str, Any]:
    """A failure record for a task whose worker could not return a result."""
    return {
        "task": item,
        "ok": False,
        "error": f"worker failed: {type(error).__name__}: {_trim(error)}",
        "outputs": {},
        "written": [],
        "warnings": [],
        "seconds": {},
    }


def _attempts_from_markers(item: dict[str, Any], result: dict[str, Any]) -> list[dict[str, Any]]:
    """Every attempt of a Dask task, from the markers its runs left in the shared attempt directory."""
    directory = item.get("attempt_dir")
    task = Task(**item)
    markers = []
    if directory and Path(directory).is_dir():
        for path in Path(directory).glob(f"{task.key}.*"):
            try:
                markers.append(json.loads(path.read_text()))
            except (OSError, ValueError):
                continue
    markers.sort(key=lambda m: m.get("start", 0.0))
    attempts = []
    for marker in markers:
        final = marker.get("pid") == result.get("pid") and marker.get("host") == result.get("host")
        outcome = ("ok" if result["ok"] else "failed") if final else "worker lost before the task finished"
        attempts.append({"pid": marker.get("pid"), "host": marker.get("host"), "outcome": outcome})
    return attempts


def _run_dask(
    payload: list[dict[str, Any]],
    scheduler: str | None,
    local_workers: int,
    retries: int,
    finished: Callable[[int, dict[str, Any]], None],
) -> None:
    import dask
    from distributed import Client, LocalCluster, as_completed

    _worker_environment()
    cluster = None
    if scheduler is None:
        # A lost worker's task is rescheduled by the scheduler until it has killed this many workers.
        with dask.config.set({"distributed.scheduler.allowed-failures": retries}):
            cluster = LocalCluster(
                n_workers=local_workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
            )
    try:
        with Client(scheduler or cluster) as client:
            keys = [f"batch-{Task(**item).key}-{uuid.uuid4().hex[:6]}" for item in payload]
            futures = client.map(run_task, payload, key=keys, pure=False)
            index = {f.key: i for i, f in enumerate(futures)}
            for future in as_completed(futures):
                i = index[future.key]
                try:
                    result = future.result()
                except Exception as error:
                    result = _failure(payload[i], error)
                result["attempts"] = _attempts_from_markers(payload[i], result)
                finished(i, result)
    finally:
        if cluster is not None:
            cluster.close()


# --------------------------------------------------------------------------- command line


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface (see the module docstring)."""
    from .verify import DEFAULT_TOLERANCE

    parser = argparse.ArgumentParser(
        prog="python -m addon.batch",
        description=__doc__.splitlines()[0],
        epilog="Exit codes: 0 ok, 1 a task or check failed, 2 usage error (nothing rendered).",
    )
    parser.add_argument("blend", nargs="*", help=".blend files (default under blender -P: the open file)")
    parser.add_argument(
        "--frames", default=None, help="frames, e.g. '1-5,7' (default: each file's current frame)"
    )
    parser.add_argument(
        "--out", type=Path, required=True, help="directory for the report (and relative outputs)"
    )
    parser.add_argument(
        "--output-pattern",
        help="render path instead of the file's render.filepath: '#' frame padding, '//' relative to the "
        ".blend, {blend_name} {blend_dir_name} {scene} {camera} tokens, relative to --out otherwise",
    )
    parser.add_argument(
        "--format",
        type=str.upper,
        choices=sorted(FORMATS),
        help="file format instead of the file's own (OPEN_EXR_MULTILAYER: every pass)",
    )
    parser.add_argument("--color-depth", choices=("8", "16", "32"), help="colour depth instead of the file's")
    parser.add_argument("--background", help="composite over this image (render size) or colour 'r,g,b[,a]'")
    parser.add_argument(
        "--operator",
        "--op",
        dest="operator",
        default="src_over",
        help="compositing operator (default src_over)",
    )
    parser.add_argument(
        "--verify",
        action="store_true",
        help="also composite in Blender's compositor and compare (needs --background)",
    )
    parser.add_argument(
        "--tolerance",
        type=float,
        default=DEFAULT_TOLERANCE,
        help=f"max |ours - Blender| accepted by --verify (default {DEFAULT_TOLERANCE:g})",
    )
    parser.add_argument("--skip-existing", action="store_true", help="skip frames whose outputs exist")
    parser.add_argument(
        "--placeholders", action="store_true", help="mark frames in progress with an empty file"
    )
    parser.add_argument("--workers", type=int, default=1, help="render in N processes (default 1: this one)")
    parser.add_argument(
        "--timeout", type=float, help="seconds per task before its worker is ended and retried"
    )
    parser.add_argument(
        "--retries", type=int, default=2, help="retries of a task whose worker was lost (default 2)"
    )
    parser.add_argument("--scheduler", help="Dask distributed scheduler address, e.g. tcp://host:8786")
    parser.add_argument(
        "--dask-local",
        type=int,
        default=0,
        metavar="N",
        help="start a local Dask cluster of N workers on loopback",
    )
    parser.add_argument("--report", type=Path, help="JSON report path (default OUT/report.json)")
    parser.add_argument("--quiet", action="store_true", help="no progress and no list of written files")
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


_BLEND_MAGIC = (b"BLENDER", b"\x1f\x8b", b"\x28\xb5\x2f\xfd")  # plain, gzip, zstd-compressed .blend


def _check_writable_dir(path: Path, flag: str) -> None:
    """Refuse a path that exists and is not a directory, or a directory we cannot write into."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"{flag}: {path} exists and is not a directory")
    probe = path
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise UsageError(f"{flag}: cannot create or write into {path} ({probe} is not writable)")


def check_arguments(args: argparse.Namespace, blends: Sequence[str]) -> list[int] | None:
    """Every check that needs no Blender: files, numbers, names. Returns the frames (None: current).

    Raises:
        UsageError: naming the flag (or file), what it accepts and what it got.
    """
    from compositing import ALL_OPERATORS

    problems: list[str] = []

    def check(condition: bool, message: str) -> None:
        if not condition:
            problems.append(message)

    frames = None
    if args.frames is not None:
        try:
            frames = parse_frames(args.frames)
        except ValueError as error:
            problems.append(f"--frames: {str(error).removeprefix('frames: ')}")
    check(
        args.operator in ALL_OPERATORS,
        f"--operator: expected one of {', '.join(ALL_OPERATORS)}; got {args.operator!r}",
    )
    check(
        math.isfinite(args.tolerance) and args.tolerance >= 0,
        f"--tolerance: expected a finite number >= 0, got {args.tolerance!r}",
    )
    check(args.workers >= 1, f"--workers: expected an integer >= 1, got {args.workers}")
    check(args.dask_local >= 0, f"--dask-local: expected an integer >= 0, got {args.dask_local}")
    check(args.retries >= 0, f"--retries: expected an integer >= 0, got {args.retries}")
    check(
        args.timeout is None or (math.isfinite(args.timeout) and args.timeout > 0),
        f"--timeout: expected seconds > 0, got {args.timeout!r}",
    )
    check(not (args.scheduler and args.dask_local), "--scheduler and --dask-local: give one, not both")
    if args.scheduler:
        check(
            "://" in args.scheduler or ":" in args.scheduler,
            f"--scheduler: expected an address like tcp://host:8786, got {args.scheduler!r}",
        )
    if args.verify and not args.background:
        problems.append("--verify: needs --background (without a composite there is nothing to verify)")
    if args.format and args.color_depth:
        check(
            args.color_depth in FORMATS[args.format],
            f"--color-depth: {args.format} accepts {'/'.join(FORMATS[args.format])}, got {args.color_depth}",
        )
    if args.output_pattern is not None:
        check(
            args.output_pattern.strip() != "" and not args.output_pattern.endswith(("/", os.sep)),
            f"--output-pattern: expected a file path pattern like 'renders/{{blend_name}}_####', "
            f"got {args.output_pattern!r}",
        )
    if args.background:
        try:
            values = parse_colour(args.background)
        except ValueError as error:
            problems.append(f"--background: {error}")
            values = ()
        if values is None:
            _check_image_file(args.background, problems)
    try:
        _check_writable_dir(args.out, "--out")
    except UsageError as error:
        problems.append(str(error))
    if args.report is not None:
        check(not args.report.is_dir(), f"--report: {args.report} is a directory; expected a file path")
    seen: dict[str, str] = {}
    for blend in blends:
        path = Path(blend)
        if not path.is_file():
            problems.append(f"{blend}: no such .blend file")
            continue
        try:
            with open(path, "rb") as handle:
                head = handle.read(8)
        except OSError as error:
            problems.append(f"{blend}: cannot be read ({error.strerror})")
            continue
        if not head.startswith(_BLEND_MAGIC):
            problems.append(f"{blend}: not a .blend file (it does not start with 'BLENDER')")
        resolved = str(path.resolve())
        if resolved in seen:
            problems.append(f"{blend}: given twice (also as {seen[resolved]})")
        seen[resolved] = blend
    if problems:
        raise UsageError("\n  ".join(problems))
    return frames


def _check_image_file(spec: str, problems: list[str]) -> None:
    """A background image must exist and be readable (header only: no pixels are decoded)."""
    path = Path(spec)
    if not path.is_file():
        problems.append(f"--background: expected an image file or a colour 'r,g,b[,a]'; {spec!r} is neither")
        return
    import OpenImageIO as oiio  # noqa: N813

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        oiio.geterror()
        problems.append(f"--background: {spec} is not an image OpenImageIO can read")
        return
    spec_ = inp.spec()
    inp.close()
    if spec_.width * spec_.height > MAX_PIXELS:
        problems.append(
            f"--background: {spec} is {spec_.width}×{spec_.height}, more than {MAX_PIXELS} pixels"
        )


def _expand_tokens(pattern: str, blend: Path, scene: Any) -> str:
    """Our tokens in ``--output-pattern`` (Blender 5.0 resolves its own path templates as well)."""
    values = {
        "{blend_name}": blend.stem,
        "{blend_dir_name}": blend.parent.name,
        "{scene}": scene.name,
        "{camera}": scene.camera.name if scene.camera else "no_camera",
    }
    for token, value in values.items():
        pattern = pattern.replace(token, value)
    return pattern


@dataclass
class Plan:
    """What the job will do, worked out before the first render."""

    tasks: list[Task]
    skipped: list[dict[str, Any]]
    warnings: list[str]


def plan_job(args: argparse.Namespace, blends: Sequence[str], frames: list[int] | None) -> Plan:
    """Open every file once (``bpy``) and resolve each task's outputs; check what needs the file.

    Checks: the background's size against each file's render size; that no two tasks write the
    same file; that each file's format accepts the colour depth. Warns when a requested composite
    cannot change the image (Film → Transparent off with an operator an opaque source decides).

    Raises:
        UsageError: naming the flag or file.
    """
    import bpy
    import numpy as np

    from compositing import composite

    from . import compat, mapping

    out_dir = args.out.resolve()
    problems: list[str] = []
    warnings: list[str] = []
    tasks: list[Task] = []
    skipped: list[dict[str, Any]] = []
    owners: dict[str, str] = {}
    background_size = None
    if args.background and parse_colour(args.background) is None:
        import OpenImageIO as oiio  # noqa: N813

        inp = oiio.ImageInput.open(args.background)
        background_size = (inp.spec().width, inp.spec().height)
        inp.close()
        from compositing.io import read_image
        from compositing.validate import check_alpha_range

        try:  # decoded once here, so that bad pixels are found before the first render
            check_alpha_range(read_image(args.background), "pixels")
        except (OSError, ValueError) as error:
            problems.append(f"--background: {args.background}: {error}")
    # Each attempt leaves a marker here (shared storage on a cluster): who ran what, for the report.
    attempt_dir = str(out_dir / f".batch-attempts-{uuid.uuid4().hex[:8]}")
    # An opaque source decides the result of these operators: the composite equals the render.
    opaque = np.array([[[0.25, 0.5, 0.75, 1.0]]], np.float32)
    probe_bg = np.array([[[0.1, 0.7, 0.3, 0.6]]], np.float32)
    inert_when_opaque = bool(np.array_equal(composite(opaque, probe_bg, args.operator), opaque))

    for blend in blends:
        path = Path(blend).resolve()
        try:
            bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
        except RuntimeError as error:
            problems.append(f"{blend}: Blender cannot open it ({_trim(error)})")
            continue
        scene = bpy.context.scene
        render = scene.render
        settings = render.image_settings
        if args.format:
            compat.set_image_format(settings, args.format, None)
        file_format = settings.file_format
        if args.color_depth:
            allowed = FORMATS.get(file_format)
            if allowed is not None and args.color_depth not in allowed:
                problems.append(
                    f"--color-depth: {blend} writes {file_format}, which accepts {'/'.join(allowed)}, "
                    f"not {args.color_depth}"
                )
                continue
            settings.color_depth = args.color_depth
        size = mapping.render_size(render.resolution_x, render.resolution_y, render.resolution_percentage)
        if background_size is not None and background_size != size:
            problems.append(
                f"--background: {args.background} is {background_size[0]}×{background_size[1]} but "
                f"{blend} renders {size[0]}×{size[1]}"
            )
        if args.background and not render.film_transparent and inert_when_opaque:
            warnings.append(
                f"{blend}: Film → Transparent is off, so the render is opaque and --operator "
                f"{args.operator} over --background gives back the render unchanged"
            )
        pattern = args.output_pattern if args.output_pattern is not None else render.filepath
        pattern = _expand_tokens(pattern, path, scene)
        if not pattern.startswith("//") and not os.path.isabs(pattern):
            pattern = str(out_dir / pattern) + ("/" if pattern.endswith(("/", os.sep)) or not pattern else "")
        render.filepath = pattern
        skip = args.skip_existing or not render.use_overwrite
        placeholder = args.placeholders or render.use_placeholder
        source = "--output-pattern" if args.output_pattern is not None else f"{blend}: render.filepath"
        for frame in frames if frames is not None else [scene.frame_current]:
            try:
                output = str(Path(bpy.path.abspath(render.frame_path(frame=frame))).resolve())
            except RuntimeError as error:  # Blender 5.0 path templates: unknown or broken {…}
                problems.append(f"{source}: {_trim(error).removeprefix('Error: ')}")
                break
            task = Task(
                blend=str(path),
                frame=frame,
                out_dir=str(out_dir),
                output=output,
                file_format=args.format,
                color_depth=args.color_depth,
                output_pattern=args.output_pattern,
                background=args.background,
                operator=args.operator,
                verify=args.verify,
                tolerance=args.tolerance,
                placeholder=placeholder,
                timeout=args.timeout,
                attempt_dir=attempt_dir,
            )
            name = f"{blend} frame {frame}"
            for target in task.outputs():
                if target in owners:
                    problems.append(f"{name} and {owners[target]} both write {target}")
                owners[target] = name
                if Path(target).is_dir():
                    problems.append(f"{name}: its output {target} is a directory")
            if skip and all(_complete(p) for p in task.outputs()):
                skipped.append({"blend": str(path), "frame": frame, "outputs": task.outputs()})
                continue
            tasks.append(task)
    if any("both write" in p for p in problems):
        problems.append(
            "give each file its own output path (render.filepath in the file, or --output-pattern "
            "with {blend_name} / {blend_dir_name}, e.g. '{blend_dir_name}/{blend_name}_####')"
        )
    if problems:
        raise UsageError("\n  ".join(problems))
    bpy.ops.wm.read_homefile(use_empty=True)
    return Plan(tasks, skipped, warnings)


def _complete(path: str) -> bool:
    """An output counts as done when it exists and is not an empty placeholder."""
    try:
        return Path(path).stat().st_size > 0
    except OSError:
        return False


def _cleanup_temporaries(tasks: Iterable[Task]) -> None:
    """Remove temporary files a killed attempt left next to the outputs (never the outputs)."""
    for task in tasks:
        for target in task.outputs():
            target_path = Path(target)
            # atomic_target's temporaries: ``.<name>.<random>.part<ext>`` (compositing._atomic)
            for stale in target_path.parent.glob(f".{target_path.name}.*.part{target_path.suffix}"):
                try:
                    stale.unlink()
                except OSError:
                    pass


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
        plan = plan_job(args, blends, frames)
    except UsageError as error:
        parser.error(str(error))
    progress = Progress(len(plan.tasks), quiet=args.quiet)
    for warning in plan.warnings:
        print(f"warning: {warning}", file=sys.stderr, flush=True)
    for item in plan.skipped:
        progress.note(f"{Path(item['blend']).name} frame {item['frame']}: skipped (outputs exist)")
    started = time.perf_counter()
    arrived: list[dict[str, Any]] = []

    def on_result(result: dict[str, Any]) -> None:
        arrived.append(result)
        progress.update(result)

    interrupted = None
    previous = _on_sigterm_raise()
    try:
        results = run_tasks(
            plan.tasks,
            workers=args.workers,
            scheduler=args.scheduler,
            dask_local=args.dask_local,
            timeout=args.timeout,
            retries=args.retries,
            on_result=on_result,
            note=progress.note,
        )
    except (KeyboardInterrupt, _Terminated) as stop:
        # Ctrl-C or a farm manager's SIGTERM: stop the workers, keep what finished, say so.
        interrupted = "SIGINT" if isinstance(stop, KeyboardInterrupt) else "SIGTERM"
        results = list(arrived)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        progress.close()
        _cleanup_temporaries(plan.tasks)
        attempt_dir = plan.tasks[0].attempt_dir if plan.tasks else None
        if attempt_dir and Path(attempt_dir).is_dir():
            for marker in Path(attempt_dir).iterdir():
                marker.unlink(missing_ok=True)
            try:
                Path(attempt_dir).rmdir()
            except OSError:
                pass
    failed = [r for r in results if not r["ok"]]
    finished_ok = {r["task"]["output"] for r in results if r["ok"]}
    for task in plan.tasks:  # placeholders of tasks that failed, were killed or never finished
        output = Path(task.output)
        if (
            task.placeholder
            and task.output not in finished_ok
            and output.is_file()
            and output.stat().st_size == 0
        ):
            output.unlink()
    warnings = list(plan.warnings)
    for result in results:
        result["error"] = _trim(result["error"]) if result["error"] else None
        for warning in result.get("warnings", []):
            if warning not in warnings:
                warnings.append(warning)
                print(f"warning: {warning}", file=sys.stderr, flush=True)
    written = [path for r in results for path in r.get("written", [])]
    retried = [r for r in results if len(r.get("attempts", [])) > 1]
    report = {
        "tasks": results,
        "failed": len(failed),
        "total": len(results),
        "written": written,
        "skipped": plan.skipped,
        "retried": [
            {"blend": r["task"]["blend"], "frame": r["task"]["frame"], "attempts": r["attempts"]}
            for r in retried
        ],
        "warnings": warnings,
        "seconds": time.perf_counter() - started,
        "executor": "dask"
        if (args.scheduler or args.dask_local)
        else (f"{args.workers} process(es)" if args.workers > 1 or args.timeout else "this process"),
    }
    code = EXIT_OK if not failed and len(results) == len(plan.tasks) else EXIT_FAILED
    report["exit_code"] = code
    report["interrupted"] = interrupted
    if interrupted:
        print(
            f"interrupted ({interrupted}): {len(plan.tasks) - len(results)} task(s) not finished",
            file=sys.stderr,
        )
    report_path = (args.report or args.out / "report.json").resolve()
    write_text_atomic(report_path, json.dumps(report, indent=1, default=str))
    if not args.quiet:
        for path in written:
            print(f"wrote {path}")
    ok_count = len(results) - len(failed)
    print(
        f"{ok_count}/{len(results)} tasks ok, {len(written)} files written, {len(plan.skipped)} skipped, "
        f"{len(retried)} retried in {report['seconds']:.1f} s; report: {report_path}"
    )
    return code


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
