"""Composite the two bundled sample images with every operator and write the results.

``python -m compositing.demo [--out DIR]`` (default ``out/demo-compositing`` under the
current directory; the absolute path is printed before and after) reads ``blend_files/images/sample_a.png``
(A, the source) and ``sample_b.png`` (B, the destination), computes
``composite(A, B, op)`` for every operator, and writes for each:

* ``DIR/<op>.exr``: the result, linear premultiplied float (exact);
* ``DIR/<op>.png``: the result as an 8-bit sRGB PNG with straight alpha;

plus ``DIR/contact_sheet.png``, all results over a grey checkerboard with their
names, and ``DIR/results.json`` with the table printed on standard output
(operator, named factors and their formulas, mean alpha, mean premultiplied
colour, time).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from ._atomic import write_json_atomic
from .factors import ALL_OPERATORS, describe
from .io import read_image, write_image
from .operators import composite
from .samples import sample_paths

__all__ = ["checkerboard", "contact_sheet", "main", "run_demo"]


def checkerboard(
    shape: tuple[int, int], square: int = 16, levels: tuple[float, float] = (0.2, 0.4)
) -> np.ndarray:
    """Opaque grey checkerboard (linear premultiplied RGBA), the usual backdrop for transparency.

    Args:
        shape: ``(height, width)`` in pixels.
        square: side of one square in pixels.
        levels: linear grey of the squares whose ``row // square + column // square`` is even,
            then odd (the top-left square takes the first).

    Returns:
        ``(height, width, 4)`` float32, alpha 1.
    """
    rows, cols = np.indices(shape)
    grey = np.where((rows // square + cols // square) % 2 == 0, levels[0], levels[1]).astype(np.float32)
    return np.stack([grey, grey, grey, np.ones_like(grey)], axis=-1)


def contact_sheet(images: dict[str, np.ndarray], columns: int = 6, label_height: int = 14) -> np.ndarray:
    """All images over a checkerboard in a grid, each with a strip for its name (linear, opaque).

    Alpha above 1 (``plus``) is shown as 1. Labels are drawn with Pillow when it is
    installed; without it the strips stay blank.
    """
    names = list(images)
    h, w = next(iter(images.values())).shape[:2]
    rows = -(-len(names) // columns)
    cell_h = h + label_height
    sheet = np.ones((rows * cell_h, columns * w, 4), np.float32)
    backdrop = checkerboard((h, w))
    for k, name in enumerate(names):
        r, c = divmod(k, columns)
        shown = images[name].copy()
        shown[..., 3] = np.minimum(shown[..., 3], 1.0)  # display only: ``plus`` can exceed full coverage
        sheet[r * cell_h + label_height : (r + 1) * cell_h, c * w : (c + 1) * w] = composite(
            shown, backdrop, "src_over"
        )
    try:
        from PIL import Image, ImageDraw
    except ImportError:  # pragma: no cover - Pillow is in the lock file
        return sheet
    labels = Image.new("L", (sheet.shape[1], sheet.shape[0]), 255)
    draw = ImageDraw.Draw(labels)
    for k, name in enumerate(names):
        r, c = divmod(k, columns)
        draw.text((c * w + 3, r * cell_h + 1), name, fill=0)
    ink = np.asarray(labels, np.float32)[..., None] / 255.0
    strip = np.zeros(sheet.shape[:2], bool)
    for r in range(rows):
        strip[r * cell_h : r * cell_h + label_height] = True
    sheet[..., :3] = np.where(strip[..., None], ink, sheet[..., :3])
    return sheet


def run_demo(out: Path, a_path: Path | None = None, b_path: Path | None = None) -> list[dict]:
    """Composite A with B by every operator, write the files into ``out``; return the table rows."""
    default_a, default_b = sample_paths()
    a = read_image(a_path or default_a)
    b = read_image(b_path or default_b)
    out.mkdir(parents=True, exist_ok=True)
    rows, results = [], {}
    for name, spec in ALL_OPERATORS.items():
        start = time.perf_counter()
        result = composite(a, b, name)
        elapsed = time.perf_counter() - start
        results[name] = result
        write_image(out / f"{name}.exr", result)
        write_image(out / f"{name}.png", result, clip=True)
        rows.append(
            {
                "operator": name,
                "title": spec.title,
                "Fa": spec.fa,
                "Fb": spec.fb,
                "Fa_formula": describe(spec.fa_expr),
                "Fb_formula": describe(spec.fb_expr),
                "mean_alpha": round(float(result[..., 3].mean()), 4),
                "mean_rgb": [round(float(v), 4) for v in result[..., :3].mean(axis=(0, 1))],
                "ms": round(elapsed * 1e3, 3),
            }
        )
    write_image(out / "contact_sheet.png", contact_sheet(results), clip=True)
    write_json_atomic(out / "results.json", rows, indent=1)
    return rows


#: Where ``python -m compositing.demo`` writes without ``--out`` (relative to the current directory).
DEFAULT_OUT = Path("out") / "demo-compositing"


def main(argv: list[str] | None = None) -> int:
    """Command-line entry: ``python -m compositing.demo [--out DIR]``; returns the exit status.

    Exit status: 0 success, 1 an input image could not be read or an output not
    written (the message says which), 2 usage error.
    """
    parser = argparse.ArgumentParser(
        prog="python -m compositing.demo", description=__doc__.splitlines()[0]
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help=f"output directory (default: {DEFAULT_OUT} under the current directory)",
    )
    parser.add_argument("--a", type=Path, default=None, help="source image A (default: bundled sample)")
    parser.add_argument("--b", type=Path, default=None, help="destination image B (default: bundled sample)")
    args = parser.parse_args(argv)
    out = args.out.resolve()
    print(f"writing to {out}")
    try:
        rows = run_demo(out, args.a, args.b)
    except (ValueError, TypeError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"| {'operator':<18} | {'Fa':<24} | {'Fb':<24} | mean α | ms    |")
    print(f"|{'-' * 20}|{'-' * 26}|{'-' * 26}|--------|-------|")
    for row in rows:
        print(
            f"| {row['operator']:<18} | {row['Fa']:<24} | {row['Fb']:<24} | {row['mean_alpha']:.4f} "
            f"| {row['ms']:5.2f} |"
        )
    print(f"wrote {len(rows)} operators (.exr linear, .png sRGB), contact_sheet.png, results.json to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
