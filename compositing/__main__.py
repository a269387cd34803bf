"""Command line: composite two image files.

``python -m compositing OP SRC DST -o OUT [--factor F]`` (or ``--operator OP SRC DST ...``)
    ``OUT = composite(SRC, DST, OP, factor=F)``, e.g. ``src_over a.png b.png -o c.exr``.

``python -m compositing blend SRC DST -o OUT --src-factor S --dst-factor D [--equation E] ...``
    the OpenGL blend stage (:func:`compositing.gl_blend`), GL names without ``GL_``.

``python -m compositing list``
    the operators with their (Fa, Fb) factors.

``python -m compositing deep-merge A B [C ...] -o OUT.exr [--tiled] [--compression C] [--half]``
    the deep images merged (:func:`compositing.deep.merge`: union of the samples, made
    tidy), written as a deep OpenEXR file.

``python -m compositing deep-flatten A [B ...] -o OUT [--bits N] [--clip] [--flatten]``
    the deep image (the merge of several) flattened (:func:`compositing.deep.flatten`)
    and written as a flat image, as the other commands write theirs.

Files are read and written with :mod:`compositing.io` (8/16-bit files are sRGB with
straight alpha, EXR is linear premultiplied; JPEG and HDR need ``--flatten``). The
operator is positional or given as ``--operator`` (alias ``--op``), the spelling the
other command lines of the project use. On success the command prints
``wrote <path>``. Exit status, as for every command line of the project: 0 success,
1 a check on the data failed (an input cannot be read, the result does not fit the
output format, ...; the message says which), 2 usage error (unknown operator: the
valid names and the closest match).
"""

from __future__ import annotations

import argparse
import difflib
import itertools
import re
import sys
import warnings
from pathlib import Path

from .factors import ALL_OPERATORS, describe
from .io import read_image, write_image
from .operators import composite, resolve_operator

__all__ = ["main"]


def _io_options(parser: argparse.ArgumentParser, *, images: bool = True) -> None:
    if images:
        parser.add_argument("src", type=Path, help="source image (A, the fragment)")
        parser.add_argument("dst", type=Path, help="destination image (B, the framebuffer)")
    parser.add_argument("-o", "--out", type=Path, required=True, help="output image (.exr, .png, .tif, ...)")
    parser.add_argument("--bits", type=int, default=8, choices=(8, 16), help="bits for PNG/TIFF output")
    parser.add_argument(
        "--clip", action="store_true", help="clip to [0, 1] when an 8/16-bit file cannot hold the result"
    )
    parser.add_argument(
        "--flatten",
        action="store_true",
        help="for JPEG or HDR output (no alpha channel): store the image over black",
    )


def _composite_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m compositing",
        usage="python -m compositing OP SRC DST -o OUT [options]\n"
        "       python -m compositing --operator OP SRC DST -o OUT [options]\n"
        "       python -m compositing blend SRC DST -o OUT --src-factor S --dst-factor D [options]\n"
        "       python -m compositing list",
        description="Composite SRC with DST by a Porter-Duff (or disjoint/conjoint) operator.",
        epilog="Other commands: 'blend' (OpenGL blend stage), 'list' (operators), 'deep-merge', "
        "'deep-flatten' (deep OpenEXR images). Exit status: 0 success, "
        "1 a check on the data failed, 2 usage error. Operators: " + ", ".join(ALL_OPERATORS),
    )
    parser.add_argument(
        "images",
        nargs="+",
        metavar="OP SRC DST",
        help="operator name (e.g. src_over) unless --operator is given, then the source image "
        "(A, the fragment) and the destination image (B, the framebuffer)",
    )
    parser.add_argument("--operator", "--op", dest="operator", default=None, help="operator name")
    _io_options(parser, images=False)
    parser.add_argument("--factor", type=float, default=1.0, help="mix with DST, in [0, 1] (default 1)")
    return parser


def _blend_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m compositing blend",
        description="The OpenGL blend stage on two images (names as in GL without GL_, any case).",
    )
    _io_options(parser)
    parser.add_argument("--src-factor", required=True, help="sfactor, e.g. ONE")
    parser.add_argument("--dst-factor", required=True, help="dfactor, e.g. ONE_MINUS_SRC_ALPHA")
    parser.add_argument("--equation", default="FUNC_ADD", help="FUNC_ADD (default), FUNC_SUBTRACT, ...")
    parser.add_argument("--src-factor-alpha", default=None, help="separate alpha sfactor")
    parser.add_argument("--dst-factor-alpha", default=None, help="separate alpha dfactor")
    parser.add_argument("--equation-alpha", default=None, help="separate alpha equation")
    parser.add_argument(
        "--constant", type=float, nargs=4, default=(0.0, 0.0, 0.0, 0.0), metavar=("R", "G", "B", "A")
    )
    parser.add_argument(
        "--target", default="float32", choices=("float32", "unorm8"), help="framebuffer format"
    )
    return parser


#: Argument names in the library's messages and the command-line flags that set them.
_FLAG_OF = {
    "factor": "--factor",
    "op": "OP (or --operator)",
    "src_factor": "--src-factor",
    "dst_factor": "--dst-factor",
    "src_factor_alpha": "--src-factor-alpha",
    "dst_factor_alpha": "--dst-factor-alpha",
    "equation": "--equation",
    "equation_alpha": "--equation-alpha",
    "target": "--target",
    "bits": "--bits",
}


def _cli_message(text: str, out: Path | None = None) -> str:
    """A library message in the command line's words: flags (``--clip``) instead of keywords (``clip=True``).

    The leading argument name (``factor: ...``) becomes its flag; ``clip:``/``flatten:``/``rgba:``
    (about the result) become ``--out PATH:``; a misspelled GL name gets the closest valid one.
    """
    text = text.replace("pass clip=True", "give --clip").replace("pass flatten=True", "give --flatten")
    name, sep, rest = text.partition(": ")
    if sep and name in _FLAG_OF:
        text = f"{_FLAG_OF[name]}: {rest}"
        if name.startswith(("src_factor", "dst_factor", "equation")):
            from .gl_blend import GL_BLEND_EQUATIONS, GL_BLEND_FACTORS

            names = GL_BLEND_EQUATIONS if name.startswith("equation") else GL_BLEND_FACTORS
            match = re.search(r"unknown blend (?:factor|equation) '([^']*)'", rest)
            close = difflib.get_close_matches(match[1].upper(), list(names), n=1) if match else []
            if close:
                text += f" (did you mean {close[0]}?)"
    elif sep and name in ("clip", "flatten", "rgba") and out is not None:
        text = f"--out {out}: {rest}"
    return text


def _deep_parser(command: str) -> argparse.ArgumentParser:
    merge = command == "deep-merge"
    parser = argparse.ArgumentParser(
        prog=f"python -m compositing {command}",
        description=(
            "Merge deep OpenEXR images (union of their samples, made tidy) into a deep OpenEXR file."
            if merge
            else "Flatten a deep OpenEXR image (the merge of several) into a flat image."
        ),
        epilog="Exit status: 0 success, 1 a check on the data failed, 2 usage error.",
    )
    parser.add_argument(
        "images",
        type=Path,
        nargs="+",
        metavar="DEEP",
        help="deep OpenEXR inputs" + (" (two or more)" if merge else ""),
    )
    if merge:
        parser.add_argument("-o", "--out", type=Path, required=True, help="output deep OpenEXR file (.exr)")
        parser.add_argument("--tiled", action="store_true", help="write tiles instead of scanlines")
        parser.add_argument("--tile-size", type=int, default=64, help="tile edge in pixels (default 64)")
        parser.add_argument("--compression", default="zips", help="zips (default) or none")
        parser.add_argument(
            "--half", action="store_true", help="store RGBA as half floats (depth stays float)"
        )
    else:
        _io_options(parser, images=False)
    return parser


def _progress(label: str):
    """A callback printing ``label: N%`` to stderr every 25% (file I/O of deep images is slow)."""
    state = {"next": 0.25}

    def report(fraction: float) -> None:
        if fraction >= state["next"] and fraction < 1.0:
            print(f"{label}: {int(fraction * 100)}%", file=sys.stderr, flush=True)
            while state["next"] <= fraction:
                state["next"] += 0.25

    return report


def _deep(command: str, argv: list[str]) -> None:
    from .deep import flatten, merge
    from .deep_io import COMPRESSIONS, read_deep, write_deep

    parser = _deep_parser(command)
    args = parser.parse_args(argv)
    if command == "deep-merge":
        if len(args.images) < 2:
            parser.error(f"expected two or more deep images to merge, got {len(args.images)}")
        if args.compression not in COMPRESSIONS:
            parser.error(
                f"--compression: expected one of {', '.join(COMPRESSIONS)}, got {args.compression!r}"
            )
        if args.tile_size < 1:
            parser.error(f"--tile-size: expected an integer >= 1, got {args.tile_size}")
    images = [read_deep(path, progress=_progress(f"reading {path}")) for path in args.images]
    result = images[0]
    for other in images[1:]:
        result = merge(result, other)
    if command == "deep-merge":
        write_deep(
            args.out,
            result,
            tiled=args.tiled,
            tile_size=args.tile_size,
            compression=args.compression,
            float_format="half" if args.half else "float",
            progress=_progress(f"writing {args.out}"),
        )
        print(f"wrote {args.out}")
    else:
        _write(args, flatten(result))


def _list() -> None:
    for name, spec in ALL_OPERATORS.items():
        print(f"{name:<18} Fa = {describe(spec.fa_expr)}")
        print(f"{'':<18} Fb = {describe(spec.fb_expr)}")


def _blend(argv: list[str]) -> None:
    try:
        from .gl_blend import gl_blend
    except ImportError:  # pragma: no cover - only while the module is absent
        _blend_parser().error("the OpenGL blend emulation (compositing.gl_blend) is not available")
    parser = _blend_parser()
    args = parser.parse_args(argv)
    src, dst = read_image(args.src), read_image(args.dst)
    try:
        result = gl_blend(
            src,
            dst,
            args.src_factor,
            args.dst_factor,
            args.equation,
            src_factor_alpha=args.src_factor_alpha,
            dst_factor_alpha=args.dst_factor_alpha,
            equation_alpha=args.equation_alpha,
            constant=tuple(args.constant),
            target=args.target,
        )
    except ValueError as exc:
        if "blend factor" in str(exc) or "equation" in str(exc) or "target" in str(exc):
            parser.error(_cli_message(str(exc)))
        raise
    _write(args, result)


def _write(args: argparse.Namespace, result) -> None:
    write_image(args.out, result, bits=args.bits, clip=args.clip, flatten=args.flatten)
    print(f"wrote {args.out}")


def _composite(argv: list[str]) -> None:
    parser = _composite_parser()
    args = parser.parse_args(argv)
    images = list(args.images)
    if args.operator is None:
        if len(images) != 3:
            parser.error(f"expected OP SRC DST (or --operator OP SRC DST), got {images}")
        op = images.pop(0)
    else:
        if len(images) != 2:
            parser.error(f"expected SRC DST after --operator, got {images}")
        op = args.operator
    try:
        spec = resolve_operator(op)
    except ValueError as exc:
        parser.error(_cli_message(str(exc)))
    src, dst = (Path(p) for p in images)
    result = composite(read_image(src), read_image(dst), spec, factor=args.factor)
    _write(args, result)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status: 0 ok, 1 a data check failed, 2 usage (via argparse)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)  # e.g. which channels of a file were read
        try:
            if argv[:1] == ["list"]:
                _list()
            elif argv[:1] == ["blend"]:
                _blend(argv[1:])
            elif argv[:1] in (["deep-merge"], ["deep-flatten"]):
                _deep(argv[0], argv[1:])
            else:
                _composite(argv)
        except (ValueError, TypeError, OSError) as exc:
            status = 1
            out = next((Path(a) for flag, a in itertools.pairwise(argv) if flag in ("-o", "--out")), None)
            print(f"error: {_cli_message(str(exc), out)}", file=sys.stderr)
        else:
            status = 0
        finally:
            for warning in caught:
                print(f"warning: {warning.message}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
