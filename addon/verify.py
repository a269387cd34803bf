"""Compare our compositing kernels with Blender's own compositor, pixel by pixel.

:func:`verify` takes two premultiplied RGBA images and an operation, runs them
through Blender's compositor in a separate Blender process, and returns Blender's
result, ours (:func:`compositing.composite`, :func:`compositing.premultiply`,
:func:`compositing.unpremultiply`) and their difference. :func:`verify_cases` does
the same for many cases in one Blender process (one compositor tree, one branch per
case), which is how the tests and the CLI run the whole matrix.

What runs on the Blender side (``kind`` of a :class:`Case`):

* ``"node_group"``: the generated "Porter-Duff · …" node group of any operator in
  :data:`compositing.factors.ALL_OPERATORS`, added through the add-on's own operator;
* ``"alpha_over"``: Blender's Alpha Over node, modes Over (``src_over``), Disjoint
  Over and Conjoint Over (5.0 only), Straight Alpha off/on, any Factor;
* ``"alpha_convert"``: the Alpha Convert node, ``premultiply`` or ``unpremultiply``.

Our side: ``composite(src, dst, op, factor=f)``; with Straight Alpha on,
``composite(premultiply(src), dst, op, factor=f)`` (Blender premultiplies the
foreground: ``node_composite_alpha_over.cc``); ``unpremultiply(src,
zero_alpha="keep")`` for Alpha Convert "To Straight", which leaves α = 0 pixels
unchanged (``node_composite_alpha_convert.cc``).

Data path: our arrays are written as 32-bit float EXR files, loaded in Blender as
``Non-Color`` / ``Channel Packed`` images, composited, written by a File Output node
as a 32-bit float multilayer EXR and read back with OpenImageIO (Blender's in-memory
Render Result and Viewer images are empty in background mode). Row 0 is the top
row on both sides.

CLI: ``python -m addon.verify --help``.
"""

from __future__ import annotations

import argparse
import difflib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813 (the name OpenImageIO's own docs use)

from compositing._atomic import atomic_path
from compositing.factors import ALL_OPERATORS, OPERATORS
from compositing.validate import as_rgba, check_alpha_range, check_factor

__all__ = [
    "ALPHA_OVER_OPERATORS",
    "DEFAULT_TOLERANCE",
    "BlenderRun",
    "Case",
    "Verification",
    "ours",
    "read_exr_layers",
    "relative_bound",
    "run_blender",
    "run_compositor_job",
    "sample_images",
    "standard_cases",
    "verify",
    "verify_cases",
    "within_bound",
    "write_exr",
]

#: Operators that Blender's Alpha Over node realises, by mode (Disjoint/Conjoint need 5.0).
ALPHA_OVER_OPERATORS: tuple[str, ...] = ("src_over", "disjoint_over", "conjoint_over")
_KINDS = ("node_group", "alpha_over", "alpha_convert")

DEFAULT_TOLERANCE = 1e-6
"""Default ``--tolerance`` of ``addon.verify`` and ``addon.batch --verify``: max |ours − Blender|.

Both sides compute in float32 with the same formula, so differences are a few units in the last
place of values up to ~3 (HDR samples): 1e-6 ≈ 4 ulp at 2.0. The compositor bridge tests hold
the whole matrix to it."""
_REPO_ROOT = Path(__file__).resolve().parent.parent


def _closest(name: str, names: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest valid name (difflib), or an empty string."""
    close = difflib.get_close_matches(str(name), list(names), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _parse_via(text: str) -> str:
    if text not in _KINDS:
        raise argparse.ArgumentTypeError(
            f"expected one of {', '.join(_KINDS)}; got {text!r}{_closest(text, _KINDS)}"
        )
    return text


@dataclass(frozen=True)
class Case:
    """One operation to run through Blender's compositor.

    ``kind`` is ``"node_group"``, ``"alpha_over"`` or ``"alpha_convert"``; ``operator``
    an operator name (``"premultiply"``/``"unpremultiply"`` for ``alpha_convert``);
    ``factor`` the node's Factor in [0, 1]; ``straight_alpha`` Alpha Over's Straight
    Alpha switch (treat the source as straight alpha).
    """

    kind: str
    operator: str
    factor: float = 1.0
    straight_alpha: bool = False

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise ValueError(
                f"kind: expected one of {', '.join(_KINDS)}; got {self.kind!r}{_closest(self.kind, _KINDS)}"
            )
        allowed = {
            "node_group": tuple(ALL_OPERATORS),
            "alpha_over": ALPHA_OVER_OPERATORS,
            "alpha_convert": ("premultiply", "unpremultiply"),
        }[self.kind]
        if self.operator not in allowed:
            raise ValueError(
                f"operator: for kind {self.kind!r} expected one of {', '.join(allowed)}; "
                f"got {self.operator!r}{_closest(self.operator, allowed)}"
            )
        check_factor(self.factor, "factor", ())
        if self.straight_alpha and self.kind != "alpha_over":
            raise ValueError(
                f"straight_alpha: only Alpha Over has a Straight Alpha switch, not {self.kind!r}"
            )

    @property
    def label(self) -> str:
        """A short readable name, e.g. ``alpha_over/disjoint_over straight f=0.5``."""
        straight = " straight" if self.straight_alpha else ""
        factor = "" if self.kind == "alpha_convert" else f" f={self.factor:g}"
        return f"{self.kind}/{self.operator}{straight}{factor}"


@dataclass
class Verification:
    """Blender's result, ours, and how far apart they are.

    ``blender``, ``ours`` and ``difference`` (= ``|blender − ours|``) have the shape of
    the inputs, ``(height, width, 4)``, premultiplied RGBA, row 0 at the top.
    """

    case: Case
    blender: np.ndarray
    ours: np.ndarray
    difference: np.ndarray
    max_abs_error: float
    mean_abs_error: float


@dataclass
class BlenderRun:
    """The raw outcome of one Blender process: one image per case and Blender's report."""

    images: list[np.ndarray]
    report: dict


def write_exr(path: str | os.PathLike, rgba: np.ndarray) -> None:
    """Write an ``(h, w, 4)`` float RGBA array as a 32-bit float EXR, row 0 at the top, lossless."""
    rgba = np.ascontiguousarray(rgba, dtype=np.float32)
    if rgba.ndim != 3 or rgba.shape[2] != 4:
        raise ValueError(f"rgba: expected shape (height, width, 4), got {rgba.shape}")
    spec = oiio.ImageSpec(rgba.shape[1], rgba.shape[0], 4, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B", "A")
    spec.alpha_channel = 3
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise OSError(f"path: cannot write an EXR to {path}: {oiio.geterror()}")
    try:
        if not out.open(str(path), spec) or not out.write_image(rgba):
            raise OSError(f"path: writing {path} failed: {out.geterror()}")
    finally:
        out.close()


def read_exr_layers(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read every RGBA layer of a (multi-part or single-part) multilayer EXR.

    Returns ``{layer name: (h, w, 4) float32}`` for channels named ``layer.R/G/B/A``,
    row 0 at the top.
    """
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"path: cannot open {path}: {oiio.geterror()}")
    channels: dict[str, np.ndarray] = {}
    try:
        subimage = 0
        while inp.seek_subimage(subimage, 0):
            names = inp.spec().channelnames
            pixels = inp.read_image(subimage, 0, 0, len(names), "float")
            if pixels is None:
                raise OSError(f"path: reading {path} failed: {inp.geterror()}")
            for index, name in enumerate(names):
                channels[name] = pixels[..., index]
            subimage += 1
    finally:
        inp.close()
    layers = {name.rsplit(".", 1)[0] for name in channels if "." in name}
    return {
        layer: np.stack([channels[f"{layer}.{c}"] for c in "RGBA"], axis=-1).astype(np.float32)
        for layer in layers
        if all(f"{layer}.{c}" in channels for c in "RGBA")
    }


def _checked_images(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    src = as_rgba(src, "src", allow_scalar_colour=False)
    dst = as_rgba(dst, "dst", allow_scalar_colour=False)
    for name, image in (("src", src), ("dst", dst)):
        if image.ndim != 3:
            raise ValueError(f"{name}: expected an image of shape (height, width, 4), got {image.shape}")
        check_alpha_range(image, name)
    if src.shape != dst.shape:
        raise ValueError(f"src, dst: expected equal shapes, got {src.shape} and {dst.shape}")
    return src, dst


def run_blender(
    src: np.ndarray,
    dst: np.ndarray,
    cases: Sequence[Case],
    *,
    python: str | None = None,
    timeout: float = 300.0,
    workdir: str | os.PathLike | None = None,
) -> BlenderRun:
    """Run ``cases`` through Blender's compositor in one subprocess and return its images.

    Args:
        src: source (foreground) image, ``(h, w, 4)`` premultiplied RGBA, alpha in [0, 1].
        dst: destination (background) image, same shape.
        cases: the operations; each becomes one branch of one compositor tree.
        python: the Python interpreter with ``bpy`` (default: the running one).
        timeout: seconds before the Blender process is killed (``subprocess.TimeoutExpired``).
        workdir: where the EXR files go (default: a temporary directory, removed afterwards).

    Raises:
        RuntimeError: Blender exited with an error or wrote no image for a case.
    """
    src, dst = _checked_images(src, dst)
    if not cases:
        raise ValueError("cases: expected at least one Case, got none")
    with tempfile.TemporaryDirectory(prefix="pd-verify-", dir=workdir) as tmp:
        work = Path(tmp)
        write_exr(work / "src.exr", src)
        write_exr(work / "dst.exr", dst)
        job = {
            "mode": "verify",
            "src": str(work / "src.exr"),
            "dst": str(work / "dst.exr"),
            "width": src.shape[1],
            "height": src.shape[0],
            "output_dir": str(work / "out"),
            "file_name": "result",
            "register_addon": True,
            "cases": {f"case{i:03d}": asdict(case) for i, case in enumerate(cases)},
        }
        report = run_compositor_job(job, work / "job.json", python=python, timeout=timeout)
        files = sorted((work / "out").glob("result*.exr"))
        if len(files) != 1:
            raise RuntimeError(f"Blender wrote {len(files)} result files, expected 1: {files}")
        layers = read_exr_layers(files[0])
        missing = [key for key in job["cases"] if key not in layers]
        if missing:
            raise RuntimeError(f"Blender's result has no layer for {len(missing)} case(s): {missing[:5]}")
        return BlenderRun([layers[key] for key in job["cases"]], report)


def run_compositor_job(job: dict, job_path: Path, *, python: str | None, timeout: float) -> dict:
    """Write ``job`` to ``job_path``, run ``addon.compositor_job`` on it in Blender, return its report.

    Args:
        job: the job description (see :mod:`addon.compositor_job`).
        job_path: where the job JSON goes; the report is written next to it.
        python: the interpreter with ``bpy`` (default: the running one).
        timeout: seconds before the Blender process is killed.

    Raises:
        RuntimeError: Blender exited non-zero or wrote no report (the message carries its output).
    """
    job_path.write_text(json.dumps(job))
    env = dict(os.environ)
    # A private user-resources directory: no user preferences or add-ons leak into the run.
    env["BLENDER_USER_RESOURCES"] = str(job_path.parent / "blender_user")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(_REPO_ROOT), env.get("PYTHONPATH")]))
    proc = subprocess.run(
        [python or sys.executable, "-m", "addon.compositor_job", str(job_path)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        cwd=str(_REPO_ROOT),
        check=False,
    )
    report_path = job_path.with_suffix(".report.json")
    if proc.returncode != 0 or not report_path.exists():
        tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-30:])
        raise RuntimeError(f"Blender job failed (exit code {proc.returncode}):\n{tail}")
    return json.loads(report_path.read_text())


def ours(case: Case, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Our result for ``case`` on premultiplied ``src``/``dst`` (see the module docstring)."""
    import compositing

    if case.kind == "alpha_convert":
        if case.operator == "premultiply":
            return compositing.premultiply(src)
        return compositing.unpremultiply(src, zero_alpha="keep")
    source = compositing.premultiply(src) if case.straight_alpha else src
    return compositing.composite(source, dst, case.operator, factor=case.factor)


def verify_cases(
    src: np.ndarray,
    dst: np.ndarray,
    cases: Sequence[Case],
    *,
    python: str | None = None,
    timeout: float = 300.0,
) -> tuple[list[Verification], dict]:
    """Run every case through Blender (one process) and compare each with :func:`ours`.

    Returns the verifications, in the order of ``cases``, and Blender's report
    (version, Alpha Over modes available, render time). Arguments as in :func:`run_blender`.
    """
    src, dst = _checked_images(src, dst)
    run = run_blender(src, dst, cases, python=python, timeout=timeout)
    results = []
    for case, blender in zip(cases, run.images, strict=True):
        mine = np.asarray(ours(case, src, dst), dtype=np.float32)
        difference = np.abs(blender.astype(np.float64) - mine.astype(np.float64))
        results.append(
            Verification(
                case=case,
                blender=blender,
                ours=mine,
                difference=difference.astype(np.float32),
                max_abs_error=float(difference.max()),
                mean_abs_error=float(difference.mean()),
            )
        )
    return results, run.report


def verify(
    src: np.ndarray,
    dst: np.ndarray,
    operator: str,
    *,
    factor: float = 1.0,
    straight_alpha: bool = False,
    via: str = "node_group",
    python: str | None = None,
    timeout: float = 300.0,
) -> Verification:
    """Composite ``src`` over/in/... ``dst`` in Blender and with numpy, and compare.

    Args:
        src: source (Blender's foreground), ``(h, w, 4)`` float, premultiplied linear RGBA.
        dst: destination (Blender's background), same shape.
        operator: an operator from :data:`compositing.factors.ALL_OPERATORS`, or
            ``"premultiply"``/``"unpremultiply"`` with ``via="alpha_convert"``.
        factor: the Factor input in [0, 1] (result = lerp(dst, op(src, dst), factor)).
        straight_alpha: Alpha Over's Straight Alpha switch (``via="alpha_over"`` only).
        via: ``"node_group"`` (the generated Porter-Duff group), ``"alpha_over"``
            (Blender's node, for src_over/disjoint_over/conjoint_over) or ``"alpha_convert"``.
        python: interpreter with ``bpy`` (default: the running one).
        timeout: seconds before the Blender process is killed.
    """
    case = Case(via, operator, float(factor), bool(straight_alpha))
    results, _ = verify_cases(src, dst, [case], python=python, timeout=timeout)
    return results[0]


def sample_images(height: int = 61, width: int = 97, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Random premultiplied test images with every special case the issue lists.

    Colour channels in [−0.5, 3] (negative and HDR values), alpha in [0, 1]; bands of
    α = 0 (including glow: rgb ≠ 0 at α = 0) and α = 1 in both images, placed so that
    every combination (0/1/between in src × 0/1/between in dst) occurs; pixels where
    both alphas are equal (the ``sa > da`` and ``sa + da < 1`` boundaries of Disjoint
    and Conjoint Over). Non-square by default so row/column mistakes show.
    """
    rng = np.random.default_rng(seed)
    src = rng.uniform(-0.5, 3.0, (height, width, 4)).astype(np.float32)
    dst = rng.uniform(-0.5, 3.0, (height, width, 4)).astype(np.float32)
    src[..., 3] = rng.uniform(0.0, 1.0, (height, width))
    dst[..., 3] = rng.uniform(0.0, 1.0, (height, width))
    band = max(1, height // 6)
    src[:band, :, 3] = 0.0  # transparent rows (glow: rgb stays non-zero)
    src[band : 2 * band, :, 3] = 1.0  # opaque rows
    col = max(1, width // 6)
    dst[:, :col, 3] = 0.0  # transparent columns
    dst[:, col : 2 * col, 3] = 1.0  # opaque columns
    dst[-band:, -col:, 3] = src[-band:, -col:, 3]  # sa == da
    dst[-band:, 2 * col : 3 * col, 3] = 1.0 - src[-band:, 2 * col : 3 * col, 3]  # sa + da == 1 (nearly)
    return src, dst


def standard_cases(alpha_over_operators: Sequence[str] = ALPHA_OVER_OPERATORS) -> list[Case]:
    """The full verification matrix.

    Alpha Over in every mode in ``alpha_over_operators`` × Straight Alpha off/on ×
    Factor 0, 0.37, 1; every operator's node group at Factor 1 and 0.37 (the twelve
    Porter-Duff operators, plus and the disjoint/conjoint family); Alpha Convert both ways.
    """
    factors = (0.0, 0.37, 1.0)
    cases = [
        Case("alpha_over", op, f, straight)
        for op in alpha_over_operators
        for straight in (False, True)
        for f in factors
    ]
    cases += [Case("node_group", op, f) for op in ALL_OPERATORS for f in (1.0, 0.37)]
    cases += [Case("node_group", op, 0.0) for op in OPERATORS]
    cases += [Case("alpha_convert", "premultiply"), Case("alpha_convert", "unpremultiply")]
    return cases


def relative_bound(case: Case, blender_version: str) -> bool:
    """True where ``case`` is held to 1 ulp relative rather than to an absolute tolerance.

    Blender before 4.4 (the CPU compositor's ``COM_*Operation`` code; 4.2 LTS) computes Alpha
    Convert "To Straight" as ``rgb·(1/a)``, one rounding away from our ``rgb/a``: the difference is
    ≤ 1 ulp of the result, so its absolute size grows with rgb/a (2.4e-4 where rgb/a ≈ 2300 in the
    sample images). docs/blender_compositor.md, "Results", documents this bound.

    Args:
        case: the verified case.
        blender_version: ``bpy.app.version_string`` of the Blender that ran it, e.g. ``"4.2.23 LTS"``.
    """
    major, minor = (int(part) for part in blender_version.split()[0].split(".")[:2])
    return (case.kind, case.operator) == ("alpha_convert", "unpremultiply") and (major, minor) < (4, 4)


def within_bound(result: Verification, tolerance: float, blender_version: str) -> bool:
    """Whether ``result`` passes: every value within ``tolerance`` absolute, or, for a case under
    :func:`relative_bound`, each value within ``tolerance`` or 1 ulp relative (``ε₃₂·|ours|``)."""
    if not relative_bound(result.case, blender_version):
        return result.max_abs_error <= tolerance
    ulp = np.finfo(np.float32).eps * np.abs(result.ours.astype(np.float64))
    return bool((result.difference <= np.maximum(tolerance, ulp)).all())


#: Largest ``--size`` side: sample images, their EXR copies and Blender's buffers stay in memory.
MAX_SIDE = 8192


def _parse_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 97x61, got {text!r}") from None
    if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT with each side in 1..{MAX_SIDE}, got {text!r}"
        )
    return width, height


def _parse_tolerance(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def _parse_factor(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}")
    return value


def _parse_python(text: str) -> str:
    found = shutil.which(text) if os.sep not in text else (text if os.access(text, os.X_OK) else None)
    if not found or not Path(found).is_file():
        raise argparse.ArgumentTypeError(f"expected an executable Python interpreter with bpy, got {text!r}")
    return found


def _read_image(path: str, flag: str) -> np.ndarray:
    if not Path(path).is_file():
        raise ValueError(f"{flag}: no such file {path!r}")
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        raise ValueError(f"{flag}: cannot read {path}: {buf.geterror().strip()}")
    pixels = buf.get_pixels(oiio.FLOAT)
    if pixels.ndim != 3 or pixels.shape[2] != 4:
        raise ValueError(f"{flag}: {path}: expected an RGBA image, got {pixels.shape[-1]} channel(s)")
    return pixels


def build_parser() -> argparse.ArgumentParser:
    """The command line (``python -m addon.verify --help``)."""
    parser = argparse.ArgumentParser(
        prog="python -m addon.verify",
        description="Composite two premultiplied RGBA images in Blender's compositor and with numpy, "
        "and report the difference. Without --src/--dst, random 97x61 sample images with α = 0, "
        "α = 1, glow, HDR and negative colour values are used.",
        epilog="Exit codes: 0 every case within --tolerance, 1 a case exceeded it, 2 usage error "
        "(nothing ran).",
    )
    parser.add_argument("--src", help="source (foreground) image: premultiplied linear RGBA, e.g. EXR")
    parser.add_argument("--dst", help="destination (background) image, same size")
    parser.add_argument(
        "--operator",
        "--op",
        dest="operator",
        help=f"operator (one of {', '.join(ALL_OPERATORS)}; or premultiply/unpremultiply with "
        "--via alpha_convert)",
    )
    parser.add_argument(
        "--via",
        type=_parse_via,
        default="node_group",
        metavar="KIND",
        help=f"what runs in Blender: {', '.join(_KINDS)} (default node_group)",
    )
    parser.add_argument("--factor", type=_parse_factor, default=1.0, help="Factor in [0, 1] (default 1)")
    parser.add_argument("--straight-alpha", action="store_true", help="Alpha Over's Straight Alpha switch")
    parser.add_argument("--all", action="store_true", help="run the whole matrix (standard_cases)")
    parser.add_argument(
        "--size", type=_parse_size, default=(97, 61), help=f"sample image size WxH, sides 1..{MAX_SIDE}"
    )
    parser.add_argument("--python", type=_parse_python, help="Python with bpy (default: this one)")
    parser.add_argument("--out", help="directory for blender/ours/difference EXRs (single operation)")
    parser.add_argument(
        "--tolerance",
        type=_parse_tolerance,
        default=DEFAULT_TOLERANCE,
        help=f"max abs error accepted, exit 1 above (default {DEFAULT_TOLERANCE:g})",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: verify one operation on two EXR files, or the whole matrix on sample images.

    Exit codes: 0 within ``--tolerance``, 1 above it, 2 usage error (before Blender starts).
    """
    parser = build_parser()
    args = parser.parse_args(argv)

    if (args.src is None) != (args.dst is None):
        parser.error("--src and --dst go together")
    if args.all and args.operator:
        parser.error("--operator: give --operator OPERATOR or --all, not both")
    if not args.all and not args.operator:
        parser.error("--operator: give --operator OPERATOR (alias --op) or --all")
    if args.out is not None and Path(args.out).exists() and not Path(args.out).is_dir():
        parser.error(f"--out: {args.out} exists and is not a directory")
    try:
        if args.src:
            src = _read_image(args.src, "--src")
            dst = _read_image(args.dst, "--dst")
            if src.shape != dst.shape:
                raise ValueError(f"--src, --dst: expected equal sizes, got {src.shape} and {dst.shape}")
            src, dst = _checked_images(src, dst)
        else:
            src, dst = sample_images(height=args.size[1], width=args.size[0])
        if args.all:
            probe = run_blender(src, dst, [Case("alpha_over", "src_over")], python=args.python)
            cases = standard_cases(tuple(probe.report["alpha_over_modes"]))
        else:
            try:
                cases = [Case(args.via, args.operator, args.factor, args.straight_alpha)]
            except ValueError as error:
                name, _, rest = str(error).partition(": ")
                flag = {"operator": "--operator", "factor": "--factor", "straight_alpha": "--straight-alpha"}
                raise ValueError(f"{flag.get(name, '--operator/--via')}: {rest or name}") from None
    except (OSError, ValueError, TypeError) as error:
        parser.error(str(error))
    try:
        results, report = verify_cases(src, dst, cases, python=args.python)
    except (RuntimeError, subprocess.TimeoutExpired) as error:
        print(f"{parser.prog}: Blender's side failed: {str(error).strip()}", file=sys.stderr)
        return 1
    print(f"Blender {report['blender_version']}, {src.shape[1]}x{src.shape[0]}, {len(results)} case(s)")
    print(f"{'case':48s} {'max abs error':>14s} {'mean abs error':>15s}")
    worst = 0.0
    failed = 0
    version = report["blender_version"]
    for result in results:
        worst = max(worst, result.max_abs_error)
        passed = within_bound(result, args.tolerance, version)
        failed += not passed
        flag = "" if passed else "  FAIL"
        if relative_bound(result.case, version):
            flag += f"  (bound: {args.tolerance:g} or 1 ulp relative, Blender {version.split()[0]})"
        print(f"{result.case.label:48s} {result.max_abs_error:14.3e} {result.mean_abs_error:15.3e}{flag}")
    if args.out and len(results) == 1:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        for name in ("blender", "ours", "difference"):
            target = out / f"{name}.exr"
            with atomic_path(target) as tmp:  # a failed write keeps the previous image
                write_exr(tmp, getattr(results[0], name))
            print(f"wrote {target}")
    print(f"worst max abs error {worst:.3e} (tolerance {args.tolerance:g}); {failed} case(s) failed")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
