"""The batch job's files: atomic writes read back whole, the job's write permits, skip-existing checks.

Every output of a task is written to a job-named temporary file next to its target, read back
whole (:func:`read_back`) and only then renamed over the target (:func:`atomic_target`), under
the job's :func:`write_permit`; :func:`close_job` ends the job so that no write of it can land
afterwards. :func:`_incomplete` decides whether a frame's outputs are done (``--skip-existing``),
and :func:`_cleanup_temporaries` removes what a job's killed attempts left.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import shutil
import socket
import stat
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from .batch_job import CLOSE_WAIT_S, PERMIT_STALE_S, JobClosed, Task, _trim

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


#: The permit each thread holds: ``(job folder, its stat when the permit was taken, message)``.
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
