"""Atomic file writes: a failed write leaves the existing file untouched.

Every writer in the project goes through :func:`atomic_path`: the content is
written to a temporary file in the target's directory (same file system, same
extension, so format-sniffing writers such as OpenImageIO or Matplotlib pick the
same format), flushed to disk, and renamed over the target only after the writer
returned without error. ``os.replace`` is atomic on POSIX and Windows for two
paths on one file system, so a reader sees either the old file or the new one,
never a truncated mix; a full disk, an exception or a killed process leaves the
target byte-for-byte as it was (and at worst a hidden ``.name.*.part.ext`` file).

Usage::

    with atomic_path("out.exr") as tmp:
        writer(tmp)               # any writer taking a path
    write_text_atomic("report.json", text)
    write_json_atomic("report.json", data, indent=1)
"""

from __future__ import annotations

import contextlib
import json
import os
import stat
import tempfile
from collections.abc import Iterator

__all__ = ["atomic_path", "write_bytes_atomic", "write_json_atomic", "write_text_atomic"]


def _current_umask() -> int:
    """The process umask, read without changing it where /proc allows (Linux), else via os.umask."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync(path: str) -> None:
    """Flush a closed file's data to disk (best effort: some file systems refuse fsync)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """Yield a temporary path next to ``path``; rename it over ``path`` when the block succeeds.

    The temporary file sits in the same directory (so the rename cannot cross file
    systems) and ends with the same extension. If the block raises, the temporary
    file is removed and ``path`` is left exactly as it was. The new file gets the
    old file's permission bits, or ``0o666`` minus the umask for a new file (what
    ``open(path, "w")`` would give).

    Raises:
        OSError: the directory does not exist or is not writable, or the rename fails.
    """
    target = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(target))
    name = os.path.basename(target)
    ext = os.path.splitext(name)[1]
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=f".part{ext}", dir=directory)
    except OSError as exc:
        raise OSError(
            exc.errno, f"path: cannot write {target!r}: {exc.strerror} (directory {directory!r})"
        ) from exc
    os.close(fd)
    try:
        try:
            mode = stat.S_IMODE(os.stat(target).st_mode)
        except OSError:
            mode = 0o666 & ~_current_umask()
        os.chmod(tmp, mode)
        yield tmp
        _fsync(tmp)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as out:
        out.write(data)


def write_text_atomic(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_path`)."""
    write_bytes_atomic(path, text.encode(encoding))


def write_json_atomic(path: str | os.PathLike, data: object, **dumps_kwargs: object) -> None:
    """``json.dumps(data, **dumps_kwargs)`` plus a final newline, written atomically.

    The text is built before the file is touched, so data that cannot be serialised
    raises ``TypeError``/``ValueError`` and leaves ``path`` alone.
    """
    write_text_atomic(path, json.dumps(data, **dumps_kwargs) + "\n")
