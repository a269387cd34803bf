"""The fragments of a frame, band by band, as a deep image (:class:`DeepFragments`).

:func:`blinn_phong.frame.pipeline.render_frame` hands each band of pixel rows it resolves (and each
strip of a large frame) to a :class:`DeepFragments`: the band's visible fragments and their
premultiplied colours from :func:`blinn_phong.frame.resolve.fragment_colours`. What the deep image
holds, and how it relates to the flat frame, is described in :mod:`blinn_phong.frame.deep_output`
(``render(..., deep=True)``).

Holdout meshes (``Mesh.holdout``) enter the deep image as samples of zero colour whose alpha is
their coverage, ``(0, 0, 0, coverage)``, as deep holdouts are written for OpenEXR deep compositing
(a deep merge with another image then occludes what lies behind the holdout); the flat frame's
holdout fragments are ``(0, 0, 0, 0)`` instead (:mod:`blinn_phong.model.linking`). The holdout samples
alone are kept as a second deep image (:meth:`DeepFragments.holdout_image`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from blinn_phong.geometry.raster import interpolate
from blinn_phong.model.linking import holdout_meshes
from compositing.deep import DeepImage, from_fragments

if TYPE_CHECKING:
    from blinn_phong.frame.prepared import PreparedScene
    from blinn_phong.frame.visibility import FrameFragments

__all__ = ["DEEP_METHODS", "DeepFragments", "check_deep_method"]

#: Transparency methods whose fragments have a depth order a deep image can hold.
DEEP_METHODS = ("a_buffer", "depth_peeling", "zbuffer")


def check_deep_method(method: str) -> None:
    """Raise ``ValueError`` (naming ``transparency``) unless ``method`` is one of :data:`DEEP_METHODS`."""
    if method not in DEEP_METHODS:
        raise ValueError(
            f"transparency: deep output keeps depth-sorted fragments; expected one of {DEEP_METHODS}, "
            f"got {method!r}"
        )


class DeepFragments:
    """Collects a frame's fragments band by band into a deep image (module docstring).

    Args:
        height: frame height in pixels.
        width: frame width in pixels.
        method: the frame's transparency method, one of :data:`DEEP_METHODS`.
        layers: depth-peeling layers (None: every transparent fragment is kept).

    :func:`blinn_phong.frame.pipeline.render_frame` calls :meth:`add` for every band it resolves and
    :meth:`strip` for every strip of a large frame; :meth:`image` joins the bands.
    """

    def __init__(self, height: int, width: int, method: str, layers: int | None = None) -> None:
        check_deep_method(method)
        self.height, self.width, self.method = int(height), int(width), method
        self.layers = None if method != "depth_peeling" or not layers else int(layers)
        self._parts: list[tuple[int, DeepImage]] = []
        self._holdout_parts: list[tuple[int, DeepImage]] = []
        self._row0 = 0

    def strip(self, row0: int) -> DeepFragments:
        """A collector for the strip whose row 0 is frame row ``row0`` (its bands land in this one)."""
        view = object.__new__(DeepFragments)
        view.__dict__.update(self.__dict__)
        view._row0 = self._row0 + int(row0)
        return view

    def add(self, prepared: PreparedScene, band: FrameFragments, rgba: np.ndarray, row0: int) -> None:
        """Keep the fragments of one band: the rows ``row0 …`` of the (strip's) frame.

        Args:
            prepared: the prepared scene the band was rasterized from (its eye space is the frame's).
            band: the band's visible fragments (:meth:`blinn_phong.frame.visibility.FrameFragments.rows`).
            rgba: (N, 4) premultiplied fragment colours from
                :func:`blinn_phong.frame.resolve.fragment_colours`.
            row0: the band's first row in the frame passed to ``render_frame``.

        The fragments of holdout meshes are kept as ``(0, 0, 0, 1)`` (zero colour, full alpha:
        with the subpixel weights of :func:`compositing.deep.from_fragments` a sample's alpha is
        the holdout's coverage of its pixel), whatever ``rgba`` holds for them.
        """
        f = band.fragments
        keep = np.ones(len(f), bool)
        if self.method == "depth_peeling" and band.n_transparent and self.layers is not None:
            tr = np.arange(band.n_opaque, len(f))
            order = tr[np.lexsort((f.depth[tr], f.sample_key[tr]))]  # by sample, nearest first
            key = f.sample_key[order]
            first = np.searchsorted(key, key, side="left")
            rank = np.arange(len(order)) - first
            keep[order[rank >= self.layers]] = False
        eye_depth = -interpolate(f, prepared.triangles, prepared.eye_position[:, 2])
        # Near-plane clipping keeps fragments in front of the camera: eye depth >= near > 0 (a
        # rounding step below 0 at worst is clamped, as OpenEXR depths are >= 0).
        eye_depth = np.maximum(eye_depth, 0.0)
        surface = 2 * prepared.triangle_mesh[f.triangle] + (~f.front_facing)
        holdout = holdout_meshes(prepared.scene)
        held = None if holdout is None else holdout[prepared.triangle_mesh[f.triangle]]
        if held is not None and held.any():
            rgba = np.array(rgba, dtype=np.float32)
            rgba[held] = (0.0, 0.0, 0.0, 1.0)

        def image_of(chosen: np.ndarray) -> DeepImage:
            return from_fragments(
                (f.height, f.width),
                f.pixel[chosen],
                eye_depth[chosen],
                rgba[chosen],
                samples_per_pixel=f.samples,
                surface=surface[chosen] if f.samples > 1 else None,
            )

        self._parts.append((self._row0 + int(row0), image_of(keep)))
        if held is not None:
            self._holdout_parts.append((self._row0 + int(row0), image_of(keep & held)))

    def image(self) -> DeepImage:
        """The frame's deep image: the bands in row order (every row exactly once), holdout
        samples included.

        Raises:
            RuntimeError: the bands collected do not tile the frame's rows.
        """
        return self._joined(self._parts)

    def holdout_image(self) -> DeepImage | None:
        """The holdout samples of :meth:`image` alone (the same samples, in the same pixels), or
        None when the scene has no holdout mesh.

        Raises:
            RuntimeError: the bands collected do not tile the frame's rows.
        """
        return self._joined(self._holdout_parts) if self._holdout_parts else None

    def _joined(self, parts: list[tuple[int, DeepImage]]) -> DeepImage:
        """The band images of ``parts`` stacked in row order (every row exactly once)."""
        parts = sorted(parts, key=lambda p: p[0])
        row = 0
        for row0, part in parts:
            if row0 != row or part.shape[1] != self.width:
                raise RuntimeError(
                    f"deep output: bands cover rows up to {row}, next band starts at {row0} "
                    f"({part.shape[0]}×{part.shape[1]}); frame {self.height}×{self.width}"
                )
            row += part.shape[0]
        if row != self.height:
            raise RuntimeError(f"deep output: bands cover {row} of the frame's {self.height} rows")
        if len(parts) == 1:
            return parts[0][1]
        images = [p for _, p in parts]
        return DeepImage(
            np.concatenate([p.counts for p in images]),
            np.concatenate([p.z for p in images]),
            np.concatenate([p.zback for p in images]),
            np.concatenate([p.rgba for p in images]),
        )
