"""The batch job's command line: its arguments, and every check of them that needs no Blender.

:func:`check_arguments` gathers every problem of the command line (files, frame ranges,
operator, numbers, the scheduler's address, output folders) into one :class:`UsageError`, each
naming its flag, before anything is opened or rendered.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from .batch_job import (
    CONNECT_TIMEOUT_S,
    FORMATS,
    MAX_PIXELS,
    UsageError,
    _did_you_mean,
    parse_colour,
    parse_frames,
    parse_scheduler,
)

DESCRIPTION = "Headless batch jobs: render frames with the Blinn-Phong engine, composite, verify, report."
"""The first line of ``addon.batch``'s docstring: the command's one-line description."""


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface (see ``addon.batch``'s docstring)."""
    from .verify import DEFAULT_TOLERANCE

    parser = argparse.ArgumentParser(
        prog="python -m addon.batch",
        description=DESCRIPTION,
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
