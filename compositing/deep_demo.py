"""Deep compositing demo: a sphere through a transparent pane, rendered as two separate sets.

The scene is computed in closed form (orthographic view along +z, one ray per subpixel
centre): a sphere of radius 1 centred at depth 5, its front and back surfaces both seen
(alpha 0.8, Lambert-shaded), and a tilted pane ``z = 5.0137 + 0.8·x + 0.3·y`` (alpha 0.45) that
cuts through it. Each set is "rendered" alone as fragments (depth and premultiplied RGBA per
subpixel). Composited flat, ``sphere over pane`` is wrong wherever the pane is in front of
the sphere; merged as deep images and then flattened, the pair equals the A-buffer of both
sets together.

``python -m compositing.deep_demo --out DIR [--size WxH] [--figure PATH]`` writes
``DIR/sphere.deep.exr`` and ``DIR/pane.deep.exr`` (deep OpenEXR), ``DIR/merged.deep.exr``,
the flattened ``DIR/deep.png`` and the flat ``DIR/flat.png``, and with ``--figure`` one PNG
with the flat composite, the deep composite and their difference side by side. Prints
``wrote <path>`` per file; exit status as for ``python -m compositing``.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .deep import DeepImage, flatten, from_fragments, merge
from .deep_io import write_deep
from .io import write_image
from .operators import composite

__all__ = ["Fragments", "main", "scene_fragments"]

SPHERE_CENTRE_Z = 5.0
SPHERE_RADIUS = 1.0
SPHERE_RGB = np.array([0.9, 0.35, 0.15])
PANE_RGB = np.array([0.15, 0.4, 0.9])
PANE_SLOPE = (0.8, 0.3)
#: Pane depth at the sphere's centre: off the sphere's centre by an amount no subpixel ray
#: reproduces exactly, so no pane fragment shares a depth with a sphere fragment (where the
#: A-buffer keeps submission order and a deep merge merges coincident samples).
PANE_Z0 = SPHERE_CENTRE_Z + 0.0137
PANE_HALF = (1.35, 0.85)
LIGHT = np.array([-0.5, 0.6, -0.62]) / np.linalg.norm([-0.5, 0.6, -0.62])


@dataclass(frozen=True)
class Fragments:
    """One object set's fragments: subpixel, pixel, surface id, depth and premultiplied RGBA."""

    subpixel: np.ndarray
    pixel: np.ndarray
    surface: np.ndarray
    depth: np.ndarray
    rgba: np.ndarray


def _grid(height: int, width: int, subpixels: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scene x, y of every subpixel centre (n × n per pixel), and the pixel each belongs to."""
    n = subpixels
    rows = (np.arange(height * n) + 0.5) / (height * n)
    cols = (np.arange(width * n) + 0.5) / (width * n)
    half_w = 1.6 * width / height
    x = (cols * 2 - 1) * half_w
    y = (1 - rows * 2) * 1.6  # row 0 at the top
    xx, yy = np.meshgrid(x, y)
    pr, pc = np.meshgrid(np.arange(height * n) // n, np.arange(width * n) // n, indexing="ij")
    return xx.reshape(-1), yy.reshape(-1), (pr * width + pc).reshape(-1)


def scene_fragments(
    height: int,
    width: int,
    subpixels: int = 1,
    *,
    sphere_alpha: float = 0.8,
    pane_alpha: float = 0.45,
    back_faces: bool = True,
    shading: bool = True,
) -> dict[str, Fragments]:
    """Fragments of the two sets, ``{"sphere": ..., "pane": ...}``, ``subpixels²`` rays per pixel.

    Subpixel indices run over the ``(height·subpixels) × (width·subpixels)`` grid, row by row.
    Surface ids: sphere front 0, sphere back 1, pane 2. Without ``shading`` every fragment of a
    surface has the same colour.
    """
    x, y, pixel = _grid(height, width, subpixels)
    sub = np.arange(len(x))
    r2 = SPHERE_RADIUS**2 - x**2 - y**2
    hit = r2 > 0
    h = np.sqrt(np.where(hit, r2, 0.0))
    parts = []
    for surface, sign in ((0, -1.0), (1, 1.0)):
        if surface == 1 and not back_faces:
            continue
        z = SPHERE_CENTRE_Z + sign * h
        if shading:
            normal = np.stack([x, y, z - SPHERE_CENTRE_Z], axis=-1) / SPHERE_RADIUS
            lambert = np.clip(normal @ LIGHT, 0.0, None) if surface == 0 else np.full(len(x), 0.15)
            straight = SPHERE_RGB[None, :] * (0.2 + 0.8 * lambert[:, None])
        else:
            straight = np.tile(SPHERE_RGB, (len(x), 1))
        rgba = np.concatenate([straight * sphere_alpha, np.full((len(x), 1), sphere_alpha)], axis=1)
        parts.append((sub[hit], pixel[hit], np.full(hit.sum(), surface), z[hit], rgba[hit]))
    sphere = Fragments(*(np.concatenate(k) for k in zip(*parts, strict=True)))
    on_pane = (np.abs(x) < PANE_HALF[0]) & (np.abs(y) < PANE_HALF[1])
    zp = PANE_Z0 + PANE_SLOPE[0] * x + PANE_SLOPE[1] * y
    shade = 1.0 - 0.25 * (y + 1.6) / 3.2 if shading else np.ones(len(x))
    rgba_p = np.concatenate(
        [PANE_RGB[None, :] * shade[:, None] * pane_alpha, np.full((len(x), 1), pane_alpha)], 1
    )
    pane = Fragments(sub[on_pane], pixel[on_pane], np.full(on_pane.sum(), 2), zp[on_pane], rgba_p[on_pane])
    return {"sphere": sphere, "pane": pane}


def deep_of(fragments: Fragments, shape: tuple[int, int], subpixels: int = 1) -> DeepImage:
    """The set's deep image (:func:`compositing.deep.from_fragments`, coverage 1/subpixels²)."""
    return from_fragments(
        shape,
        fragments.pixel,
        fragments.depth,
        fragments.rgba,
        samples_per_pixel=subpixels**2,
        surface=fragments.surface if subpixels > 1 else None,
    )


def flat_of(fragments: Fragments, shape: tuple[int, int]) -> np.ndarray:
    """The set rendered flat at one sample per pixel: its fragments composited front to back."""
    return flatten(deep_of(fragments, shape))


def run_demo(out: Path, size: tuple[int, int] = (320, 240), figure: Path | None = None) -> list[Path]:
    """Write the demo files into ``out`` (module docstring); return their paths."""
    width, height = size
    shape = (height, width)
    sets = scene_fragments(height, width)
    out.mkdir(parents=True, exist_ok=True)
    deep = {name: deep_of(f, shape) for name, f in sets.items()}
    merged = merge(deep["sphere"], deep["pane"])
    written = []
    for name, image in (("sphere", deep["sphere"]), ("pane", deep["pane"]), ("merged", merged)):
        path = out / f"{name}.deep.exr"
        write_deep(path, image)
        written.append(path)
    deep_flat = flatten(merged)
    flat = composite(flat_of(sets["sphere"], shape), flat_of(sets["pane"], shape), "src_over")
    for name, image in (("deep", deep_flat), ("flat", flat)):
        path = out / f"{name}.png"
        write_image(path, image, clip=True)
        written.append(path)
    if figure is not None:
        grey = np.array([0.18, 0.18, 0.18, 1.0], np.float32)  # over a grey backdrop
        diff = np.abs(flat - deep_flat)[..., :3].max(axis=-1, keepdims=True) * 4.0
        panels = [
            composite(flat, np.broadcast_to(grey, flat.shape).copy(), "src_over"),
            composite(deep_flat, np.broadcast_to(grey, flat.shape).copy(), "src_over"),
            np.concatenate([np.repeat(diff, 3, axis=-1), np.ones_like(diff)], axis=-1).astype(np.float32),
        ]
        gap = np.ones((height, 8, 4), np.float32)
        strip = np.concatenate([panels[0], gap, panels[1], gap, panels[2]], axis=1)
        figure.parent.mkdir(parents=True, exist_ok=True)
        write_image(figure, strip, clip=True)
        written.append(figure)
    return written


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 320x240, got {text!r}") from None
    if not (1 <= w <= 8192 and 1 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"expected each side in 1..8192, got {text!r}")
    return w, h


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status (0 ok, 1 a write failed, 2 usage)."""
    parser = argparse.ArgumentParser(
        prog="python -m compositing.deep_demo", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--size", type=_size, default=(320, 240), help="WIDTHxHEIGHT (default 320x240)")
    parser.add_argument("--figure", type=Path, default=None, help="also write the side-by-side PNG here")
    args = parser.parse_args(argv)
    try:
        for path in run_demo(args.out, args.size, args.figure):
            print(f"wrote {path}")
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
