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

import argparse
import contextlib
import difflib
import glob
import json
import math
import os
import re
import shutil
import signal
import socket
import stat
import sys
import tempfile
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

#: Blender's frame range (``MINAFRAME``/``MAXAFRAME`` in its source): ``Scene.frame_set`` clamps
#: any frame outside it, so a file named after such a frame would hold another frame's image.
MIN_FRAME, MAX_FRAME = -1_048_574, 1_048_574

#: Seconds without a heartbeat (measured by the job) after which a write permit belongs to a lost
#: process (see :func:`write_permit`); and the longest wait at the end of a job for writes under way.
PERMIT_STALE_S = 5.0
CLOSE_WAIT_S = 60.0

#: Default ``--connect-timeout``: seconds to reach a ``--scheduler`` before giving up.
CONNECT_TIMEOUT_S = 5.0


class UsageError(ValueError):
    """A bad command-line input, found before anything ran; the message names the flag."""


class JobClosed(RuntimeError):
    """The job a task belongs to has ended: the task may not write anything any more."""


class SchedulerUnreachable(OSError):
    """``--scheduler`` did not answer within ``--connect-timeout``; nothing was rendered."""


def _did_you_mean(value: str, names: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``names`` (difflib), or an empty string."""
    close = difflib.get_close_matches(value, list(names), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""


@dataclass(frozen=True)
class Task:
    """One frame of one .blend file and what to do with it (plain data: it travels to workers).

    ``output`` is the absolute path of the render (resolved before the job starts);
    ``file_format``/``color_depth`` the image settings it is written with (None: the file's own).
    ``deep_output`` is the absolute path of the frame's deep EXR (empty: no deep output).
    ``job`` names the job (its temporary files carry it, so a job removes only its own);
    ``attempt_dir`` is the job's folder on the output storage: each attempt leaves a marker there,
    and every write needs it to exist (see :func:`write_permit`).
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
    job: str = ""
    deep_output: str = ""

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
        return [
            self.output,
            *((self.deep_output,) if self.deep_output else ()),
            *(self.composite_paths() if self.background else ()),
        ]

    def placeholder_paths(self) -> list[str]:
        """The files marked with an empty placeholder while the frame renders (with ``placeholder``):
        the render and its deep image."""
        return [self.output, *((self.deep_output,) if self.deep_output else ())] if self.placeholder else []


def parse_frames(text: str) -> list[int]:
    """Frames from ``"1-5,7,10-12"`` (inclusive ranges), in the given order, without repeats.

    Raises:
        ValueError: empty text, a malformed item, a range running backwards, or a frame outside
            Blender's range ``MIN_FRAME..MAX_FRAME`` (±1,048,574).
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
        for value in (lo, hi):
            if not MIN_FRAME <= value <= MAX_FRAME:
                raise ValueError(
                    f"frames: {value} in {item!r} is outside Blender's frame range {MIN_FRAME}..{MAX_FRAME}"
                )
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


def temporary_prefix(target: str | os.PathLike, job: str = "") -> str:
    """The start of every temporary name for ``target``: ``.<name>.<job>.`` (``.<name>.`` without a job).

    Temporary names are ``<prefix><random>.part<ext>``; a job removes only names with its own prefix.
    """
    name = Path(target).name
    return f".{name}.{job}." if job else f".{name}."


@contextlib.contextmanager
def atomic_target(
    target: str | os.PathLike, *, job: str = "", check: Callable[[Path], None] | None = None
) -> Iterator[Path]:
    """Context manager: a temporary path in the target's directory, renamed over it on success.

    The same protocol as :func:`compositing._atomic.atomic_path` (the project's atomic writer: same
    directory, same extension so writers choose the format by it, flushed to disk, ``os.replace``,
    the old file's permission bits or ``0o666`` minus the umask), plus what a render job needs:

    * the directory is created;
    * the temporary name carries the job (``.<name>.<job>.<random>.part<ext>``), so that a job
      cleaning up after its killed attempts never touches another job's file in progress;
    * the written file must prove whole before it replaces anything: a writer that wrote nothing is
      an error, and ``check`` (e.g. :func:`read_back`) runs on the temporary file; a writer that
      failed without raising (Blender's ``save_render`` on a full disk) is caught there.

    On any exception the temporary file is removed and the target is left exactly as it was.

    Raises:
        OSError: the directory cannot be written, nothing was written, or ``check`` found the file bad.
    """
    from compositing._atomic import _current_umask, _fsync

    path = Path(target)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(
        prefix=temporary_prefix(path, job), suffix=f".part{path.suffix}", dir=path.parent
    )
    os.close(fd)
    tmp = Path(name)
    try:
        try:
            mode = stat.S_IMODE(os.stat(path).st_mode)
        except OSError:
            mode = 0o666 & ~_current_umask()
        os.chmod(tmp, mode)
        yield tmp
        if os.path.getsize(tmp) == 0:
            raise OSError(f"nothing was written to the temporary file {tmp} for {path}")
        if check is not None:
            try:
                check(tmp)
            except OSError as error:
                detail = str(error).replace(f"{tmp}: ", "")
                raise OSError(
                    f"the written file does not read back whole ({detail}); the disk may be full"
                ) from None
        _fsync(str(tmp))
        _permit_still_open()  # a writer paused past the job's end must not replace anything now
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


#: The last bytes of a TGA 2.0 file (Blender writes this footer): a cut-off file lacks them.
_TGA_FOOTER = b"TRUEVISION-XFILE.\x00"


def readable(path: str | os.PathLike) -> bool:
    """Whether OpenImageIO has a reader for the file's extension (e.g. no JPEG 2000 in some builds)."""
    import OpenImageIO as oiio  # noqa: N813

    extensions = {
        ext
        for entry in oiio.get_string_attribute("extension_list").split(";")
        for ext in entry.partition(":")[2].split(",")
    }
    return Path(path).suffix.lower().lstrip(".") in extensions


def read_back(path: str | os.PathLike, size: tuple[int, int] | None = None) -> bool:
    """Decode every pixel of every part of an image file; raise when it is not a whole image.

    What proves a file whole: OpenImageIO opens it, every part (subimage: a multilayer EXR has one
    per pass) decodes without an error — a cut-off EXR, PNG, BMP fails here, and a cut-off TIFF or
    JPEG decodes with an error message, which counts as failing; a deep EXR part is read as deep
    data (``read_native_deep_image``: every sample count and value) — each part is ``size``
    (width, height) when given, and a TGA still ends with its footer.

    Returns:
        True when the file was checked; False (nothing checked) when OpenImageIO has no reader for
        its format (see :func:`readable`).

    Raises:
        OSError: naming the file and what is wrong with it.
    """
    import OpenImageIO as oiio  # noqa: N813

    path = Path(path)
    if not readable(path):
        return False
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"{path}: not a readable image ({oiio.geterror().strip() or 'unknown format'})")
    try:
        part = 0
        while inp.seek_subimage(part, 0):
            spec = inp.spec()
            if size is not None and (spec.width, spec.height) != tuple(size):
                raise OSError(
                    f"{path}: part {part} is {spec.width}×{spec.height}, expected {size[0]}×{size[1]}"
                )
            if spec.deep:
                deep = inp.read_native_deep_image(part, 0)
                pixels = deep if deep is not None and deep.initialized() else None
            else:
                pixels = inp.read_image(part, 0, 0, spec.nchannels, oiio.FLOAT)
            error = inp.geterror().strip()
            if pixels is None or error:
                raise OSError(f"{path}: part {part} cannot be decoded ({error or 'no pixels'})")
            part += 1
        inp.geterror()  # seeking past the last part leaves a message; nothing is wrong
        if part == 0:
            raise OSError(f"{path}: holds no image")
    finally:
        inp.close()
        oiio.geterror()
    if path.suffix.lower() in (".tga", ".tpic"):
        with open(path, "rb") as handle:
            handle.seek(max(0, path.stat().st_size - len(_TGA_FOOTER)))
            if handle.read() != _TGA_FOOTER:
                raise OSError(f"{path}: cut off (no TGA footer)")
    return True


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, creating the directory (see :func:`atomic_target`)."""
    from compositing._atomic import write_text_atomic as write

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write(path, text)


# --------------------------------------------------------------------------- the job's fence
#
# A job owns a folder on the output storage, ``OUT/.batch-<job>``. Every write of a task (its
# placeholder, each output) holds a permit: a file ``write.<random>`` in that folder, created
# through a handle on the folder and refreshed every second while the write lasts. At its end the
# job renames the folder (one atomic step), so no permit can be taken any more, waits for the
# permits still held (live writers finish their rename), and removes it. A task still running
# somewhere on a cluster after that (Dask cannot interrupt a render) can write nothing: no file
# under the outputs changes once the job has returned.


_PERMITS_BY_HANDLE = hasattr(os, "O_DIRECTORY") and all(
    f in os.supports_dir_fd for f in (os.open, os.utime, os.unlink)
)


def _job_dir_closed(directory: str | os.PathLike) -> Path:
    """Where a job's folder goes when the job ends."""
    return Path(f"{os.fspath(directory)}.closed")


@contextlib.contextmanager
def write_permit(task: Task) -> Iterator[None]:
    """Hold the job's permit to write for as long as the block runs (no-op without ``attempt_dir``).

    Raises:
        JobClosed: the job has ended (its folder is gone or was renamed): nothing may be written.
    """
    directory = task.attempt_dir
    if not directory:
        yield
        return
    closed = f"the job has ended; {task.stem} writes nothing"
    # Through a handle on the folder where the system allows (POSIX): the permit then follows the
    # folder when the job renames it, and the job sees it there.
    dir_fd: int | None = None
    try:
        if _PERMITS_BY_HANDLE:
            dir_fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
            reference = os.fstat(dir_fd)
        else:
            reference = os.stat(directory)
    except OSError:
        raise JobClosed(closed) from None
    where = {"dir_fd": dir_fd} if dir_fd is not None else {}
    name = f"write.{uuid.uuid4().hex}"
    if dir_fd is None:
        name = os.path.join(directory, name)
    stop = threading.Event()
    beat: threading.Thread | None = None
    created = False
    try:
        try:
            fd = os.open(name, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644, **where)
        except FileNotFoundError:
            raise JobClosed(closed) from None
        created = True
        try:
            os.write(fd, json.dumps({"host": socket.gethostname(), "pid": os.getpid()}).encode())
        finally:
            os.close(fd)
        try:  # the folder may have been renamed between opening it and creating the permit
            still_open = os.path.samestat(os.stat(directory), reference)
        except OSError:
            still_open = False
        if not still_open:
            raise JobClosed(closed)

        def heartbeat() -> None:
            while not stop.wait(1.0):
                with contextlib.suppress(OSError):
                    os.utime(name, **where)

        beat = threading.Thread(target=heartbeat, name="batch-permit", daemon=True)
        beat.start()
        _HELD[threading.get_ident()] = (directory, reference, closed)
        yield
    finally:
        _HELD.pop(threading.get_ident(), None)
        stop.set()
        if beat is not None:
            beat.join()
        if created:
            with contextlib.suppress(OSError):
                os.unlink(name, **where)
        if dir_fd is not None:
            os.close(dir_fd)


#: The permit each thread holds: ``(job folder, its stat when the permit was taken, message)``
#: (a plain dict, which cloudpickle can send to cluster workers with this module's functions).
_HELD: dict[int, tuple[str, os.stat_result, str]] = {}


def _same_folder(directory: str, reference: os.stat_result, message: str) -> None:
    try:
        still_open = os.path.samestat(os.stat(directory), reference)
    except OSError:
        still_open = False
    if not still_open:
        raise JobClosed(message)


def _permit_still_open() -> None:
    """Raise :class:`JobClosed` when this thread's write permit belongs to a job that has ended
    (checked again right before a file replaces its target: a writer paused while its job ended,
    and was judged lost, writes nothing when it resumes)."""
    held = _HELD.get(threading.get_ident())
    if held is not None:
        _same_folder(*held)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class _Permits:
    """The permits in a closed job folder, watched for signs of life.

    A permit is live while its holder refreshes it: its modification time changes (every second)
    within ``PERMIT_STALE_S`` seconds of this process's clock — measured here, so a cluster node's
    clock being off does not matter. A permit of a process on this host that is gone is dead at once.
    """

    def __init__(self) -> None:
        self.seen: dict[str, tuple[int, float]] = {}

    def live(self, permit: Path) -> bool:
        try:
            mtime = permit.stat().st_mtime_ns
            holder = json.loads(permit.read_text() or "{}")
        except FileNotFoundError:
            return False
        except (OSError, ValueError):
            return True  # being written
        if holder.get("host") == socket.gethostname() and isinstance(holder.get("pid"), int):
            if not _pid_alive(holder["pid"]):
                return False
        now = time.monotonic()
        previous = self.seen.get(permit.name)
        if previous is None or previous[0] != mtime:
            self.seen[permit.name] = (mtime, now)
            return True
        return now - previous[1] <= PERMIT_STALE_S


def close_job(directory: str | os.PathLike, wait: float = CLOSE_WAIT_S) -> tuple[Path | None, list[str]]:
    """End a job: no task of it can write from now on; wait (at most ``wait`` s) for writes under way.

    Returns the renamed folder (its attempt markers are still there; None if the folder was gone)
    and warnings about writers that did not finish within ``wait``.
    """
    closed = _job_dir_closed(directory)
    try:
        os.rename(directory, closed)
    except FileNotFoundError:
        return None, []
    deadline = time.monotonic() + wait
    permits = _Permits()
    while True:
        live = [p for p in closed.glob("write.*") if permits.live(p)]
        if not live or time.monotonic() >= deadline:
            break
        time.sleep(0.05)
    warnings = []
    for permit in live:
        with contextlib.suppress(OSError):
            warnings.append(
                f"a write was still under way when the job ended ({permit.read_text(errors='replace')}): "
                "its temporary file may be left next to its output"
            )
    return closed, warnings


def _late_writes(tasks: list[Task], reported: set[str], since_ns: int) -> list[str]:
    """Outputs of ``tasks`` not in ``reported`` that are non-empty files modified since ``since_ns``
    (wall clock, ns; 50 ms of slack: file-system timestamps come from a coarser clock)."""
    late = []
    for task in tasks:
        for path in task.outputs():
            if path in reported:
                continue
            with contextlib.suppress(OSError):
                stat = os.stat(path)
                if stat.st_size > 0 and stat.st_mtime_ns >= since_ns - 50_000_000:
                    late.append(path)
    return late


def _remove_job_dir(closed: Path | None) -> None:
    if closed is not None:
        shutil.rmtree(closed, ignore_errors=True)
        if closed.exists():  # a late marker write raced the removal
            time.sleep(0.1)
            shutil.rmtree(closed, ignore_errors=True)


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


def _marker(task: Task) -> Path:
    return Path(task.attempt_dir) / f"{task.key}.{socket.gethostname()}.{os.getpid()}"  # type: ignore[arg-type]


def _record_attempt(task: Task) -> bool:
    """Leave a marker ``<attempt_dir>/<key>.<host>.<pid>`` (shared storage): who started the task.

    Returns False when the job has ended (its folder is gone): the task must not run. The folder is
    made by the job, never here.
    """
    if not task.attempt_dir:
        return True
    if not Path(task.attempt_dir).is_dir():
        return False
    try:
        _marker(task).write_text(
            json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "start": time.time()})
        )
    except FileNotFoundError:
        return False
    except OSError:
        pass  # the record is informative; never fail a render for it
    return True


def _finish_attempt(task: Task, result: dict[str, Any]) -> None:
    """Complete this attempt's marker with its end, outcome and, when it succeeded, its result (so
    a finished attempt is never 'lost', and never rendered again: :func:`_finished_result`)."""
    if not task.attempt_dir:
        return
    marker = _marker(task)
    try:
        record = json.loads(marker.read_text())
        record.update(end=time.time(), outcome="ok" if result["ok"] else "failed")
        if result["ok"]:
            record["result"] = result
        marker.write_text(json.dumps(record, default=str))
    except (OSError, ValueError, TypeError):
        pass  # the job has ended (folder renamed) or the marker is unreadable: informative only


def _finished_result(task: Task) -> dict[str, Any] | None:
    """The result of an earlier attempt of ``task`` that succeeded, if every file it wrote is still
    there; else None.

    Dask keeps a task's result on the worker that computed it until the job has fetched it. When
    that worker is lost first, the scheduler computes the task again on another worker: the frame
    is already written, so the earlier attempt's result (kept in its marker by
    :func:`_finish_attempt`) is returned instead of rendering the frame a second time.
    """
    if not task.attempt_dir:
        return None
    for marker in sorted(Path(task.attempt_dir).glob(f"{task.key}.*")):
        try:
            record = json.loads(marker.read_text())
        except (OSError, ValueError):
            continue
        result = record.get("result")
        if record.get("outcome") != "ok" or not isinstance(result, dict):
            continue
        if all(Path(path).is_file() for path in result.get("written", [])):
            return result
    return None


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

    Every file is written through :func:`atomic_target` under the job's :func:`write_permit` and
    read back whole (:func:`read_back`) before it replaces anything; a write that fails — also one
    that Blender only logs, such as a full disk — fails the task and keeps the previous file.
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
    earlier = _finished_result(task)
    if earlier is not None:  # its worker was lost before the job fetched the result
        return earlier
    if not _record_attempt(task):
        result["error"] = f"JobClosed: the job has ended before {task.stem} started; nothing was rendered"
        result["seconds"]["total"] = time.perf_counter() - started
        return result
    timer = _watchdog(task)
    registered_here: list[Any] = []
    placeholders: list[Path] = []
    engine_module: Any = None
    write_deep_files = True
    try:
        import bpy

        from . import compat, engine, mapping, properties

        if _engine_module() is None:
            for module in (properties, engine):
                module.register()
                registered_here.append(module)
        bpy.ops.wm.open_mainfile(filepath=str(Path(task.blend).resolve()), load_ui=False)
        scene = bpy.context.scene
        scene.render.engine = engine.ENGINE_ID
        scene.blinn_phong.abort_on_error = False
        # The deep image is written here, under the job's rules, never by the engine itself.
        scene.blinn_phong.deep_output = bool(task.deep_output)
        engine_module = _engine_module()
        write_deep_files, engine_module.WRITE_DEEP_FILES = engine_module.WRITE_DEEP_FILES, False
        scene.frame_set(task.frame)
        if scene.frame_current != task.frame:  # Blender clamps to its frame range
            raise ValueError(
                f"frame {task.frame}: Blender set the scene to frame {scene.frame_current} instead "
                f"(its frame range is {MIN_FRAME}..{MAX_FRAME}); nothing was written"
            )
        settings = scene.render.image_settings
        if task.file_format:
            compat.set_image_format(settings, task.file_format, task.color_depth)
        elif task.color_depth:
            settings.color_depth = task.color_depth
        output = Path(task.output)
        for marked in map(Path, task.placeholder_paths()):
            if marked.exists():
                continue
            with write_permit(task):
                marked.parent.mkdir(parents=True, exist_ok=True)
                try:  # an ordinary empty file: 0o666 minus the umask, as the frame itself gets
                    fd = os.open(marked, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
                    os.close(fd)
                    placeholders.append(marked)
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
        render = scene.render
        size = mapping.render_size(render.resolution_x, render.resolution_y, render.resolution_percentage)
        render_result = bpy.data.images["Render Result"]
        t = time.perf_counter()
        try:
            with (
                write_permit(task),
                atomic_target(output, job=task.job, check=lambda tmp: read_back(tmp, size)) as tmp,
            ):
                render_result.save_render(filepath=str(tmp), scene=scene)
        except OSError as error:
            raise OSError(f"writing {output} failed, the previous file is kept: {error}") from None
        result["seconds"]["write"] = time.perf_counter() - t
        if not readable(output):
            result["warnings"].append(
                f"{output.suffix} files cannot be read back here (OpenImageIO has no reader for them): "
                "written without the check that the write succeeded"
            )
        placeholders = [p for p in placeholders if p != output]
        result["outputs"]["render"] = str(output)
        result["written"].append(str(output))
        result["format"] = {"file_format": settings.file_format, "color_depth": settings.color_depth}
        if task.deep_output:
            _write_deep_output(task, engine_module, size, result)
            placeholders = [p for p in placeholders if p != Path(task.deep_output)]
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
        if engine_module is not None:
            engine_module.WRITE_DEEP_FILES = write_deep_files
            engine_module.LAST_DEEP.clear()  # the deep image's memory
        for placeholder in placeholders:
            try:
                with write_permit(task):
                    if placeholder.stat().st_size == 0:
                        placeholder.unlink()
            except (OSError, JobClosed):
                pass  # the job has ended: its own clean-up removes placeholders
        for module in reversed(registered_here):
            try:
                module.unregister()
            except Exception as error:
                result.setdefault("cleanup_errors", []).append(repr(error))
        result["seconds"]["total"] = time.perf_counter() - started
        _finish_attempt(task, result)
    return result


def _write_deep_output(task: Task, engine_module: Any, size: tuple[int, int], result: dict[str, Any]) -> None:
    """Write the engine's deep image of the frame (``LAST_DEEP``) to ``task.deep_output``: through
    :func:`atomic_target` under the job's permit, read back whole (every sample) before it
    replaces anything."""
    from compositing.deep_io import write_deep

    image = engine_module.LAST_DEEP.get("image")
    if image is None:
        raise RuntimeError(f"{task.stem}: the engine returned no deep image; {task.deep_output} not written")
    t = time.perf_counter()
    try:
        with (
            write_permit(task),
            atomic_target(task.deep_output, job=task.job, check=lambda tmp: read_back(tmp, size)) as tmp,
        ):
            write_deep(tmp, image, atomic=False)  # tmp is already this job's temporary file
    except OSError as error:
        raise OSError(f"writing {task.deep_output} failed, the previous file is kept: {error}") from None
    result["seconds"]["write_deep"] = time.perf_counter() - t
    result["outputs"]["deep"] = task.deep_output
    result["written"].append(task.deep_output)
    result["deep"] = {"samples": int(image.n_samples), "max_per_pixel": int(image.counts.max(initial=0))}


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
    size = (rendered.shape[1], rendered.shape[0])
    for path, clip in ((exr_path, False), (png_path, True)):
        try:
            with (
                write_permit(task),
                atomic_target(path, job=task.job, check=lambda tmp: read_back(tmp, size)) as tmp,
            ):
                write_image(tmp, composited, clip=clip)
        except OSError as error:
            raise OSError(f"writing {path} failed, the previous file is kept: {error}") from None
        result["written"].append(path)
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
    connect_timeout: float = CONNECT_TIMEOUT_S,
    info: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Run tasks in this process, in ``workers`` processes, or on a Dask cluster; results in task order.

    Args:
        tasks: the tasks (output paths already resolved).
        workers: worker processes; 1 without ``timeout`` runs in this process.
        scheduler: a Dask scheduler address (``tcp://host:port``).
        dask_local: start a Dask cluster of this many workers on loopback.
        timeout: seconds per task before its worker is ended and the task retried.
        retries: how many times a task whose worker was lost is run again (with ``scheduler`` the
            scheduler's own ``distributed.scheduler.allowed-failures`` decides instead).
        on_result: called with each result as it arrives.
        note: receives one-line messages (retries) for the user.
        connect_timeout: seconds allowed to reach ``scheduler``.
        info: receives facts about the executor for the report.

    Raises:
        SchedulerUnreachable: ``scheduler`` did not answer within ``connect_timeout``.
    """
    payload = [asdict(t) for t in tasks]
    results: list[dict[str, Any] | None] = [None] * len(tasks)

    def finished(index: int, result: dict[str, Any]) -> None:
        results[index] = result
        if on_result is not None:
            on_result(result)

    if scheduler or dask_local:
        _run_dask(payload, scheduler, dask_local, retries, finished, connect_timeout, info)
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
    """Every attempt of a Dask task, from the markers its runs left in the shared attempt directory.

    An attempt whose marker records an end is reported with its own outcome; only one without an
    end — its process was lost mid-task — is "worker lost before the task finished". The attempt
    that produced ``result`` gets the result's outcome even if its end was not recorded yet.
    """
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
        if final:
            outcome = "ok" if result["ok"] else "failed"
        else:
            outcome = marker.get("outcome") or "worker lost before the task finished"
        attempts.append({"pid": marker.get("pid"), "host": marker.get("host"), "outcome": outcome})
    return attempts


_ADDRESS = re.compile(
    r"^(?:(?P<scheme>[a-z][a-z0-9+.-]*)://)?(?P<host>\[[0-9A-Fa-f:.]+\]|[^:/\[\]]+):(?P<port>[^:/]*)$"
)
#: Dask's communication schemes that run over TCP (``ucx``/``inproc`` are not probed).
_TCP_SCHEMES = ("tcp", "tls", "ws", "wss")


def parse_scheduler(address: str) -> tuple[str, str, int]:
    """``(scheme, host, port)`` of a Dask scheduler address such as ``tcp://host:8786``.

    Raises:
        ValueError: the address is not ``[scheme://]host:port`` with a port in 1..65535.
    """
    match = _ADDRESS.match(address.strip())
    if match is None:
        raise ValueError(f"expected an address like tcp://host:8786, got {address!r}")
    scheme = match["scheme"] or "tcp"
    if scheme not in (*_TCP_SCHEMES, "ucx"):
        raise ValueError(
            f"expected the scheme tcp://, tls://, ws://, wss:// or ucx://, got {scheme!r} in {address!r}"
        )
    port = match["port"]
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"expected a port number in 1..65535 after the host, got {port!r} in {address!r}")
    return scheme, match["host"].strip("[]"), int(port)


def probe_scheduler(address: str, timeout: float) -> None:
    """Reach the Dask scheduler at ``address`` within ``timeout`` seconds (TCP, then Dask's handshake).

    Raises:
        SchedulerUnreachable: naming the address, the time allowed and the reason.
    """
    scheme, host, port = parse_scheduler(address)
    if scheme in _TCP_SCHEMES:
        try:
            with socket.create_connection((host, port), timeout=timeout):
                pass
        except OSError as error:
            reason = "no answer" if isinstance(error, TimeoutError) else (error.strerror or str(error))
            raise SchedulerUnreachable(
                f"--scheduler: cannot connect to {address} within {timeout:g} s ({reason}); is "
                "`dask scheduler` running there? (--connect-timeout sets the time allowed)"
            ) from None
    # Dask's own handshake, bounded here: Client() and comm.connect() wait forever on a server that
    # accepts the connection and never answers.
    import asyncio

    from distributed.comm import connect

    async def handshake() -> None:
        comm = await asyncio.wait_for(connect(address), timeout)
        await comm.close()

    try:
        asyncio.run(handshake())
    except (OSError, TimeoutError) as error:
        reason = _trim(error).splitlines()[0] if str(error).strip() else "no Dask handshake"
        raise SchedulerUnreachable(
            f"--scheduler: {address} did not answer as a Dask scheduler within {timeout:g} s ({reason})"
        ) from None


def _connect(address: str, timeout: float) -> Any:
    """A Dask client of the scheduler at ``address``.

    Raises:
        SchedulerUnreachable: no Dask scheduler answered within ``timeout`` seconds.
    """
    from distributed import Client

    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as error:
        reason = _trim(error).splitlines()[0] if str(error).strip() else type(error).__name__
        raise SchedulerUnreachable(
            f"--scheduler: {address} did not answer as a Dask scheduler within {timeout:g} s ({reason})"
        ) from None


def _run_dask(
    payload: list[dict[str, Any]],
    scheduler: str | None,
    local_workers: int,
    retries: int,
    finished: Callable[[int, dict[str, Any]], None],
    connect_timeout: float = CONNECT_TIMEOUT_S,
    info: dict[str, Any] | None = None,
) -> None:
    """Run the tasks on a Dask cluster; each result is released as soon as it has arrived.

    A finished task's result (its file is written and read back by then) is released at once, so
    the scheduler forgets it: a worker lost later cannot make it compute the frame again. Whatever
    has not finished is cancelled before returning. ``info`` receives facts for the report
    (the scheduler's ``allowed-failures``).
    """
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
        client = _connect(scheduler, connect_timeout) if scheduler else Client(cluster)
        with client:
            if info is not None:

                def allowed_failures(dask_scheduler: Any = None) -> int:  # runs on the scheduler
                    return int(dask_scheduler.allowed_failures)

                with contextlib.suppress(Exception):  # informative only
                    info["allowed_failures"] = client.run_on_scheduler(allowed_failures)
            keys = [f"batch-{Task(**item).key}-{uuid.uuid4().hex[:6]}" for item in payload]
            futures = client.map(run_task, payload, key=keys, pure=False)
            index = {f.key: i for i, f in enumerate(futures)}
            live = {f.key: f for f in futures}
            arriving = as_completed(futures, loop=client.loop)
            del futures
            try:
                for future in arriving:
                    i = index[future.key]
                    try:
                        result = future.result()
                    except Exception as error:
                        result = _failure(payload[i], error)
                    # Release the result now: a finished frame is never computed again.
                    live.pop(future.key, None)
                    future.release()
                    result["attempts"] = _attempts_from_markers(payload[i], result)
                    finished(i, result)
            finally:
                if live:
                    client.cancel(list(live.values()), force=True)
                    live.clear()
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
        metavar="FORMAT",
        help=f"file format instead of the file's own: {', '.join(sorted(FORMATS))} "
        "(OPEN_EXR_MULTILAYER: every pass)",
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
    parser.add_argument(
        "--deep",
        action="store_true",
        help="also write each frame's deep image (deep OpenEXR R, G, B, A, Z, ZBack) next to it as "
        "<output without its extension>.deep.exr (also on when the file's Deep EXR setting is); needs "
        "Transparency A-Buffer, Depth Peeling or Opaque in the file",
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
        "--retries",
        type=int,
        default=None,
        help="retries of a task whose worker was lost (default 2), with --workers/--timeout and "
        "--dask-local; refused with --scheduler, where the scheduler's own "
        "distributed.scheduler.allowed-failures setting decides (set it where the scheduler starts)",
    )
    parser.add_argument("--scheduler", help="Dask distributed scheduler address, e.g. tcp://host:8786")
    parser.add_argument(
        "--connect-timeout",
        type=float,
        default=CONNECT_TIMEOUT_S,
        metavar="S",
        help=f"seconds allowed to reach --scheduler (default {CONNECT_TIMEOUT_S:g})",
    )
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
        f"--operator: expected one of {', '.join(ALL_OPERATORS)}; got {args.operator!r}"
        + _did_you_mean(str(args.operator), ALL_OPERATORS),
    )
    if args.format is not None and args.format not in FORMATS:
        problems.append(
            f"--format: expected one of {', '.join(sorted(FORMATS))}; got {args.format!r}"
            + _did_you_mean(args.format, FORMATS)
        )
        args.format = None
    check(
        math.isfinite(args.tolerance) and args.tolerance >= 0,
        f"--tolerance: expected a finite number >= 0, got {args.tolerance!r}",
    )
    check(args.workers >= 1, f"--workers: expected an integer >= 1, got {args.workers}")
    check(args.dask_local >= 0, f"--dask-local: expected an integer >= 0, got {args.dask_local}")
    check(
        args.retries is None or args.retries >= 0, f"--retries: expected an integer >= 0, got {args.retries}"
    )
    check(
        math.isfinite(args.connect_timeout) and args.connect_timeout > 0,
        f"--connect-timeout: expected seconds > 0, got {args.connect_timeout!r}",
    )
    check(
        args.timeout is None or (math.isfinite(args.timeout) and args.timeout > 0),
        f"--timeout: expected seconds > 0, got {args.timeout!r}",
    )
    check(not (args.scheduler and args.dask_local), "--scheduler and --dask-local: give one, not both")
    if args.scheduler:
        try:
            parse_scheduler(args.scheduler)
        except ValueError as error:
            problems.append(f"--scheduler: {error}")
        if args.retries is not None:
            problems.append(
                "--retries: not with --scheduler: there the scheduler decides how often a lost worker's "
                "task runs again, by its distributed.scheduler.allowed-failures setting (e.g. "
                "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES=0 dask scheduler ...); --retries applies "
                "to --workers, --timeout and --dask-local"
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
    job: str = ""
    attempt_dir: str | None = None
    outside_out: list[str] = field(default_factory=list)


@contextlib.contextmanager
def _engine_registered() -> Iterator[None]:
    """The engine and its settings registered for the block (unless they already are).

    Files saved with the Blinn-Phong engine name it in their scene; opening one without it makes
    Blender log "Engine 'BLINN_PHONG' not available" and drop its settings. A RenderEngine left
    registered at exit crashes bpy 4.2, so what is registered here is unregistered after.
    """
    from . import engine, properties

    registered: list[Any] = []
    try:
        if _engine_module() is None:
            for module in (properties, engine):
                module.register()
                registered.append(module)
        yield
    finally:
        for module in reversed(registered):
            with contextlib.suppress(Exception):
                module.unregister()


def plan_job(args: argparse.Namespace, blends: Sequence[str], frames: list[int] | None) -> Plan:
    """Open every file once (``bpy``) and resolve each task's outputs; check what needs the file.

    Checks: the background's size against each file's render size; that no two tasks write the
    same file; that every output folder can be created and written; that each file's format
    accepts the colour depth. With ``--skip-existing`` a frame counts as done only when each of its
    outputs is a whole image of the render's size (:func:`read_back`). Warns when a requested
    composite cannot change the image (Film → Transparent off with an operator an opaque source
    decides) and when ``--output-pattern`` leads outside ``--out`` (such paths are listed in
    ``Plan.outside_out``).

    Raises:
        UsageError: naming the flag or file.
    """
    with _engine_registered():
        return _plan_job(args, blends, frames)


def _plan_job(args: argparse.Namespace, blends: Sequence[str], frames: list[int] | None) -> Plan:
    import bpy
    import numpy as np

    from compositing import composite

    from . import compat, mapping, options

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
    # The job's folder (shared storage on a cluster): each attempt leaves a marker there, for the
    # report, and every write needs it (write_permit); the job removes it when it ends.
    job = uuid.uuid4().hex[:12]
    attempt_dir = str(out_dir / f".batch-{job}")
    outside_out: list[str] = []
    checked_dirs: dict[Path, str | None] = {}
    planned: list[tuple[Task, tuple[int, int] | None]] = []  # each task, and its size if it may be skipped
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
        deep = bool(getattr(args, "deep", False)) or scene.blinn_phong.deep_output
        if deep and (problem := options.deep_output_problem(scene.blinn_phong.transparency)):
            flag = "--deep" if getattr(args, "deep", False) else "Deep EXR (scene.blinn_phong.deep_output)"
            problems.append(f"{flag}: {blend}: scene {scene.name!r}: {problem}")
            continue
        extension = render.file_extension if render.use_file_extension else ""
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
                deep_output=options.deep_output_path(output, extension) if deep else "",
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
                job=job,
            )
            name = f"{blend} frame {frame}"
            for target in task.outputs():
                if target in owners:
                    problems.append(f"{name} and {owners[target]} both write {target}")
                owners[target] = name
                if Path(target).is_dir():
                    problems.append(f"{name}: its output {target} is a directory")
                folder = Path(target).parent
                if folder not in checked_dirs:
                    try:
                        _check_writable_dir(folder, source)
                        checked_dirs[folder] = None
                    except UsageError as error:
                        checked_dirs[folder] = str(error)
                        problems.append(str(error))
                if not Path(target).is_relative_to(out_dir):
                    outside_out.append(target)
            planned.append((task, size if skip else None))
    if any("both write" in p for p in problems):
        problems.append(
            "give each file its own output path (render.filepath in the file, or --output-pattern "
            "with {blend_name} / {blend_dir_name}, e.g. '{blend_dir_name}/{blend_name}_####')"
        )
    if problems:
        raise UsageError("\n  ".join(problems))
    # --skip-existing: decode the outputs that exist (in threads: OpenImageIO decodes without the GIL).
    from concurrent.futures import ThreadPoolExecutor

    checks = [(task.outputs(), size) for task, size in planned if size is not None]
    with ThreadPoolExecutor(max_workers=max(1, min(8, os.cpu_count() or 1))) as pool:
        verdicts = iter(list(pool.map(lambda check: _incomplete(*check), checks)))
    for task, size in planned:
        if size is not None:
            missing = next(verdicts)
            if not missing:
                skipped.append({"blend": task.blend, "frame": task.frame, "outputs": task.outputs()})
                continue
            for target, why in missing:
                if why:  # a file is there but is not a whole image: rendered again
                    warnings.append(
                        f"{target} is not a whole image ({why}); rendering frame {task.frame} again"
                    )
        tasks.append(task)
    if args.output_pattern is not None and outside_out:
        warnings.append(
            f"--output-pattern {args.output_pattern!r} writes {len(outside_out)} file(s) outside --out "
            f"{out_dir} (e.g. {outside_out[0]}); the report lists them under 'outside_out'"
        )
    bpy.ops.wm.read_homefile(use_empty=True)
    return Plan(tasks, skipped, warnings, job, attempt_dir, outside_out)


def _incomplete(paths: Iterable[str], size: tuple[int, int]) -> list[tuple[str, str]]:
    """The outputs that are not done, each with why a file that is there is not whole ('' if absent).

    An output is done when it decodes whole at the render's size (:func:`read_back`); an empty
    placeholder, a cut-off file (a full disk, a killed writer of another program) or a file of
    another size is not.
    """
    missing = []
    for path in paths:
        try:
            if Path(path).stat().st_size == 0:
                missing.append((path, ""))
                continue
        except OSError:
            missing.append((path, ""))
            continue
        try:
            read_back(path, size)
        except OSError as error:
            missing.append((path, _trim(error).removeprefix(f"{path}: ")))
    return missing


def _cleanup_temporaries(tasks: Iterable[Task]) -> None:
    """Remove the temporary files this job's killed attempts left next to the outputs.

    Only names with the job's own prefix (``.<name>.<job>.*.part<ext>``, see :func:`atomic_target`)
    are removed: never an output, never another job's file in progress.
    """
    for task in tasks:
        if not task.job:
            continue
        for target in task.outputs():
            target_path = Path(target)
            prefix = temporary_prefix(target_path, task.job)
            pattern = f"{glob.escape(prefix)}*.part{glob.escape(target_path.suffix)}"
            for stale in target_path.parent.glob(pattern):
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


def _write_reports(args: argparse.Namespace, report: dict[str, Any]) -> Path:
    """Write the job's record ``OUT/reports/<time>-<job>.json``, then ``--report`` (``OUT/report.json``).

    Jobs sharing an ``--out`` each keep their own record; ``report.json`` is the last job to end
    (each file is written atomically, so it is always one whole report). Returns ``report.json``'s path.
    """
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime())
    own = (args.out / "reports" / f"{stamp}-{report['job'] or uuid.uuid4().hex[:12]}.json").resolve()
    report["job_report"] = str(own)
    text = json.dumps(report, indent=1, default=str)
    write_text_atomic(own, text)
    report_path = (args.report or args.out / "report.json").resolve()
    write_text_atomic(report_path, text)
    return report_path


def _unreachable(args: argparse.Namespace, error: SchedulerUnreachable, executor: str, started: float) -> int:
    """``--scheduler`` cannot be reached: say so in one line and in the report; nothing was rendered."""
    print(f"error: {error}", file=sys.stderr)
    report = {
        "job": "",
        "tasks": [],
        "failed": 0,
        "total": 0,
        "written": [],
        "outside_out": [],
        "skipped": [],
        "retried": [],
        "warnings": [],
        "seconds": time.perf_counter() - started,
        "executor": executor,
        "exit_code": EXIT_FAILED,
        "interrupted": None,
        "error": str(error),
    }
    report_path = _write_reports(args, report)
    print(f"nothing rendered; report: {report_path}")
    return EXIT_FAILED


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
