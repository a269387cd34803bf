"""The two sample images bundled for the demo, drawn analytically.

``python -m compositing.samples`` regenerates ``blend_files/images/``:

* ``sample_a.png`` (source A): an orange disc, opaque in the middle and fading to
  half coverage at its rim, with an anti-aliased edge, on a transparent ground,
  plus a faint cyan veil (α = 0.25) over the left third.
* ``sample_b.png`` (destination B): a blue square, opaque, with an anti-aliased
  edge, and a vertical alpha ramp (0 → 1) of green across the bottom band.

Shapes overlap partly so that every Porter-Duff region (A only, B only, both,
neither) appears, with partial alphas that tell the disjoint/conjoint variants
apart. Coverage is computed by 4×4 supersampling. Colours are linear; the files
store them sRGB-encoded with straight alpha (see :mod:`compositing.io`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .io import write_image
from .operators import composite

__all__ = ["SAMPLE_DIR", "SAMPLE_SIZE", "make_samples", "sample_paths"]

#: Where the bundled images live.
SAMPLE_DIR = Path(__file__).resolve().parent.parent / "blend_files" / "images"
#: Size of the samples (height, width).
SAMPLE_SIZE = (192, 256)


def _coverage(inside, shape: tuple[int, int], supersample: int = 4) -> np.ndarray:
    """Fraction of each pixel where ``inside(x, y)`` holds (x, y in pixels, origin top-left)."""
    h, w = shape
    offsets = (np.arange(supersample) + 0.5) / supersample
    y = (np.arange(h)[:, None] + offsets[None, :]).reshape(-1)
    x = (np.arange(w)[:, None] + offsets[None, :]).reshape(-1)
    hit = np.broadcast_to(inside(x[None, :], y[:, None]), (y.size, x.size)).astype(np.float32)
    return hit.reshape(h, supersample, w, supersample).mean(axis=(1, 3))


def _layer(colour: tuple[float, float, float], alpha: np.ndarray) -> np.ndarray:
    """Premultiplied layer of one straight linear colour under an alpha map."""
    rgb = np.asarray(colour, np.float32) * alpha[..., None]
    return np.concatenate([rgb, alpha[..., None]], axis=-1).astype(np.float32)


def make_samples(shape: tuple[int, int] = SAMPLE_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """The two sample images as linear premultiplied float32 RGBA ``(H, W, 4)``: (A, B)."""
    h, w = shape
    cx, cy, r = 0.42 * w, 0.42 * h, 0.33 * min(h, w) * 1.2
    disc = _coverage(lambda x, y: (x - cx) ** 2 + (y - cy) ** 2 < r * r, shape)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
    radial = np.clip(np.hypot(xx - cx, yy - cy) / r, 0.0, 1.0)
    disc_alpha = disc * (1.0 - 0.5 * radial**2)
    veil = _coverage(lambda x, y: x < w / 3, shape) * 0.25
    a = composite(_layer((1.0, 0.35, 0.02), disc_alpha), _layer((0.0, 0.6, 0.8), veil), "src_over")

    x0, y0, x1, y1 = 0.40 * w, 0.30 * h, 0.92 * w, 0.80 * h
    square = _coverage(lambda x, y: (x > x0) & (x < x1) & (y > y0) & (y < y1), shape)
    band = _coverage(lambda x, y: y > 0.85 * h, shape) * (xx / w)
    b = composite(_layer((0.05, 0.15, 0.9), square), _layer((0.1, 0.8, 0.15), band), "src_over")
    return a, b


def sample_paths(directory: Path = SAMPLE_DIR) -> tuple[Path, Path]:
    """Paths of the bundled samples (A, B)."""
    return directory / "sample_a.png", directory / "sample_b.png"


def main(argv: list[str] | None = None) -> None:
    """Write the samples as 8-bit PNG (sRGB, straight alpha)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=SAMPLE_DIR, help="output directory")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for image, path in zip(make_samples(), sample_paths(args.out), strict=True):
        write_image(path, image)
        print(f"wrote {path} ({path.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
