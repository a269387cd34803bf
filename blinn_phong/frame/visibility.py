"""Stage 3 of the frame: which fragments can be seen (``fragments -> visibility``).

Visibility is decided before any shading, so each fragment that can be seen is shaded once
and no hidden one is shaded at all:

* opaque geometry goes through a z-buffer (``GL_LESS`` in draw order: the smallest depth wins,
  equal depths go to the lower triangle index — :func:`blinn_phong.geometry.raster.resolve_nearest`);
* transparent geometry is depth-tested against the opaque depth but does not write it (the
  usual order for blending): every transparent fragment strictly in front of the sample's
  opaque depth (1.0, the clear value, where nothing opaque was drawn) is kept.

:func:`frame_fragments` returns both as a :class:`FrameFragments`: per sample its nearest
opaque fragment and its list of transparent fragments (in draw order), which is what every
transparency method of :mod:`blinn_phong.effects.oit` needs (the A-buffer of Carpenter 1984 keeps
exactly these lists).

Two engines implement the stage: ``"numpy"`` — the reference, which rasterizes every
fragment with :func:`blinn_phong.geometry.raster.rasterize` and filters; ``"numba"`` — the compiled
loops of :mod:`blinn_phong.geometry.raster_kernels`, which never build the array of all fragments (memory is
the per-sample z-buffer plus the fragments that survive the depth test). Both return the same
fragments in the same order (tests/blinn_phong/test_engines_agree.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from blinn_phong._numba import ENGINES, use_compiled
from blinn_phong.geometry.raster import Fragments, rasterize, resolve_nearest
from blinn_phong.geometry.raster_kernels import (
    frame_fragments_compiled,
    setup_triangles_compiled,
    visible_fragments_compiled,
)

__all__ = [
    "ENGINES",
    "FrameFragments",
    "frame_fragments",
    "rasterized_count",
    "use_compiled",
    "visible_fragments",
]

def visible_fragments(
    clip_xyzw: np.ndarray,
    triangles: np.ndarray,
    width: int,
    height: int,
    *,
    samples: int = 1,
    cull_backfaces: bool = False,
    engine: str = "numpy",
    progress: Callable[[float], None] | None = None,
) -> Fragments:
    """The nearest fragment of every covered sample (a z-buffer pass), ordered by ``sample_key``.

    ``engine="numpy"`` is :func:`~blinn_phong.geometry.raster.rasterize` +
    :func:`~blinn_phong.geometry.raster.resolve_nearest` (the reference); ``engine="numba"`` runs the
    compiled loop of :mod:`blinn_phong.geometry.raster_kernels`, which never materialises hidden fragments;
    ``"auto"`` picks numba when it imports. Arguments as for
    :func:`~blinn_phong.geometry.raster.rasterize` (``progress`` is reported by the numpy engine).
    """
    if use_compiled(engine):
        return visible_fragments_compiled(
            clip_xyzw, triangles, width, height, samples=samples, cull_backfaces=cull_backfaces
        )
    frags = rasterize(
        clip_xyzw, triangles, width, height, samples=samples, cull_backfaces=cull_backfaces, progress=progress
    )
    winner = resolve_nearest(frags)
    return frags.subset(winner[winner >= 0])


@dataclass(frozen=True, eq=False)
class FrameFragments:
    """The fragments of a frame that can be seen, grouped by sample.

    Attributes:
        fragments: the nearest opaque fragment of every covered sample (``n_opaque`` of them,
            in increasing ``sample_key``), then the transparent fragments in front of the
            opaque depth, grouped by increasing ``sample_key`` and in draw order (triangle
            index) inside a sample.
        n_opaque: number of opaque fragments at the start of ``fragments``.
        opaque_of: (width·height·samples,) int64 index into ``fragments`` of each sample's
            opaque fragment, −1 where none.
        offsets: (width·height·samples + 1,) int64: the transparent fragments of sample key
            ``s`` are ``fragments[n_opaque + offsets[s] : n_opaque + offsets[s + 1]]``.
    """

    fragments: Fragments
    n_opaque: int
    opaque_of: np.ndarray
    offsets: np.ndarray

    @cached_property
    def _opaque_keys(self) -> np.ndarray:
        """Sample keys of the opaque fragments (increasing), computed once for every band."""
        return self.fragments.sample_key[: self.n_opaque]

    @property
    def n_transparent(self) -> int:
        """Number of transparent fragments kept."""
        return len(self.fragments) - self.n_opaque

    @property
    def nbytes(self) -> int:
        """Bytes held by the kept fragments and the per-sample indices (``opaque_of``, ``offsets``).

        About 57 bytes per kept fragment (pixel, sample, depth, triangle: 8 each; barycentrics 24;
        facing 1) plus 16 bytes per sample: proportional to the fragments that survive the depth
        test, not to every rasterized fragment (:func:`rasterized_count` counts those).
        """
        f = self.fragments
        arrays = (
            f.pixel,
            f.sample,
            f.depth,
            f.triangle,
            f.bary,
            f.front_facing,
            self.opaque_of,
            self.offsets,
        )
        return int(sum(a.nbytes for a in arrays))

    def fragment_range(self, row0: int, row1: int) -> tuple[int, int, int, int]:
        """``(o0, o1, t0, t1)``: the opaque fragments ``[o0, o1)`` and transparent ones
        ``[n_opaque + t0, n_opaque + t1)`` of pixel rows ``[row0, row1)`` (both are grouped by sample key)."""
        f = self.fragments
        k0 = row0 * f.width * f.samples
        k1 = row1 * f.width * f.samples
        o0, o1 = (int(v) for v in np.searchsorted(self._opaque_keys, [k0, k1]))
        return o0, o1, int(self.offsets[k0]), int(self.offsets[k1])

    def rows(self, row0: int, row1: int) -> FrameFragments:
        """The fragments of pixel rows ``[row0, row1)`` as a frame of ``row1 − row0`` rows (a band)."""
        f = self.fragments
        o0, o1, t0, t1 = self.fragment_range(row0, row1)
        opaque, transparent = slice(o0, o1), slice(self.n_opaque + t0, self.n_opaque + t1)

        def part(a: np.ndarray) -> np.ndarray:  # opaque fragments only: views, no copies
            return np.concatenate([a[opaque], a[transparent]]) if t1 > t0 else a[opaque]

        k0 = row0 * f.width * f.samples
        k1 = row1 * f.width * f.samples
        band = Fragments(
            f.width,
            row1 - row0,
            f.samples,
            part(f.pixel) - row0 * f.width,
            part(f.sample),
            part(f.depth),
            part(f.triangle),
            part(f.bary),
            part(f.front_facing),
        )
        opaque_of = self.opaque_of[k0:k1] - o0
        opaque_of[opaque_of < 0] = -1  # (−1 − o0 for empty samples)
        return FrameFragments(band, o1 - o0, opaque_of, self.offsets[k0 : k1 + 1] - t0)


def frame_fragments(
    clip_xyzw: np.ndarray,
    triangles: np.ndarray,
    width: int,
    height: int,
    *,
    opaque: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    samples: int = 1,
    cull_backfaces: bool = False,
    engine: str = "numpy",
    progress: Callable[[float], None] | None = None,
) -> FrameFragments:
    """The fragments a frame can see: per sample the nearest opaque one and the transparent ones in front.

    Args:
        clip_xyzw: (V, 4) clip-space vertex positions.
        triangles: (T, 3) vertex indices (draw order = row order).
        width: image width in pixels.
        height: image height in pixels.
        opaque: ``opaque(triangle, front_facing) -> bool array``: which triangles (given as
            index and facing, arrays of one shape) are opaque and write depth; None: all of them
            (the plain z-buffer).
        samples: k² samples per pixel.
        cull_backfaces: discard clockwise triangles.
        engine: ``"numpy"`` (reference), ``"numba"`` or ``"auto"``.
        progress: ``callback(fraction)`` during rasterization (numpy engine).

    Returns:
        :class:`FrameFragments`.
    """
    if use_compiled(engine):
        setup = setup_triangles_compiled(clip_xyzw, triangles, width, height, samples, cull_backfaces)
        sub_opaque = None if opaque is None else np.asarray(opaque(setup.source, setup.front), dtype=bool)
        frags, n_opaque, opaque_of, offsets = frame_fragments_compiled(setup, sub_opaque)
        return FrameFragments(frags, n_opaque, opaque_of, offsets)

    frags = rasterize(
        clip_xyzw, triangles, width, height, samples=samples, cull_backfaces=cull_backfaces, progress=progress
    )
    n_keys = frags.width * frags.height * frags.samples
    key = frags.sample_key
    if opaque is None:
        is_opaque = np.ones(len(frags), dtype=bool)
    else:
        is_opaque = np.asarray(opaque(frags.triangle, frags.front_facing), dtype=bool)
    opaque_idx = np.flatnonzero(is_opaque)
    nearest = resolve_nearest(frags.subset(opaque_idx))
    covered = np.flatnonzero(nearest >= 0)
    winners = opaque_idx[nearest[covered]]  # in increasing sample key
    opaque_depth = np.ones(n_keys)
    opaque_depth[covered] = frags.depth[winners]
    transparent = np.flatnonzero(~is_opaque)
    kept = transparent[frags.depth[transparent] < opaque_depth[key[transparent]]]
    kept = kept[np.lexsort((frags.triangle[kept], key[kept]))]  # by sample, then draw order
    opaque_of = np.full(n_keys, -1, np.int64)
    opaque_of[covered] = np.arange(len(winners))
    offsets = np.zeros(n_keys + 1, np.int64)
    np.cumsum(np.bincount(key[kept], minlength=n_keys), out=offsets[1:])
    return FrameFragments(frags.subset(np.concatenate([winners, kept])), len(winners), opaque_of, offsets)


def rasterized_count(
    clip_xyzw: np.ndarray,
    triangles: np.ndarray,
    width: int,
    height: int,
    *,
    samples: int = 1,
    cull_backfaces: bool = False,
    engine: str = "auto",
) -> int:
    """Number of fragments rasterization produces: every covered sample of every triangle, hidden or not.

    What an array of all fragments (:func:`blinn_phong.geometry.raster.rasterize`) would hold, against
    which the fragments :func:`frame_fragments` keeps are measured. ``engine="numpy"`` is
    ``len(rasterize(...))``; the compiled engine counts them in the transparent-list counting
    pass of :mod:`blinn_phong.geometry.raster_kernels` against an empty depth buffer (memory: two integers per
    sample). Samples whose depth is not below 1.0 (the far plane, the depth buffer's clear value)
    are not counted by the compiled engine (``GL_LESS`` against the clear value discards them).
    Arguments as for :func:`frame_fragments`.
    """
    if not use_compiled(engine):
        return len(
            rasterize(clip_xyzw, triangles, width, height, samples=samples, cull_backfaces=cull_backfaces)
        )
    from blinn_phong.geometry.raster_kernels import _bands, _kernel

    setup = setup_triangles_compiled(clip_xyzw, triangles, width, height, samples, cull_backfaces)
    k = setup.k
    fine_w, fine_h = setup.width * k, setup.height * k
    _, _, in_front, _ = _kernel()
    winner = np.full(fine_w * fine_h, -1, np.int64)  # an empty depth buffer: every fragment is in front
    counts = np.zeros(fine_w * fine_h, np.int64)
    empty = np.zeros(0, np.int64)
    geometry = (
        setup.x0, setup.x1, setup.y0, setup.y1, setup.a, setup.b, setup.c,
        setup.top_left, setup.x_exact, setup.y_exact, setup.area, setup.z,
    )  # fmt: skip
    in_front(
        False, _bands(fine_h), fine_w, fine_h, k, setup.width, setup.selected.astype(np.int64), *geometry,
        np.ones(1), winner, counts, empty, empty, empty,
    )  # fmt: skip
    return int(counts.sum())
