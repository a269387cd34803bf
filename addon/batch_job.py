"""What a batch job is made of, as plain data: its limits, its errors, its tasks, its parsed values.

The lowest of the batch modules (``addon.batch`` and the ``addon.batch_*`` modules it re-exports):
it imports nothing of the project, so every other batch module may use it. :class:`Task` travels
to worker processes and Dask workers as a dict (``dataclasses.asdict``). The values parsed here
(``--frames``, ``--background`` colours, ``--scheduler`` addresses) raise :class:`ValueError`
naming what they expected and what they got.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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


def _trim(text: Any) -> str:
    """Error text without Blender's trailing newline and padding."""
    return str(text).strip()


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
