"""Deep output of a frame: the fragments the A-buffer (or depth peeling) resolves, as a deep image.

``render(..., deep=True)`` (or :func:`render_deep`, its deep image alone) collects the
fragments inside :func:`blinn_phong.frame.pipeline.render_frame`: each band of pixel rows (and each
strip of a large frame) hands the fragment colours it resolves — the output of
:func:`blinn_phong.frame.resolve.fragment_colours`, transparency models, Kay–Greenberg opacity,
wash-out and fog included — to a :class:`blinn_phong.frame.deep_fragments.DeepFragments`, which
keeps them as a deep image of the band's rows. One pass of the stages gives the flat frame and
the deep image:

* one point sample per fragment kept by the method: each sample's nearest opaque fragment and
  the transparent fragments in front of it (``a_buffer``: all of them; ``depth_peeling``: the
  nearest ``layers``; ``zbuffer``: the nearest fragment only);
* ``Z = ZBack`` = the fragment's eye-space depth (distance along the view axis, ``-z_eye``,
  interpolated perspective-correctly from the vertices: the same camera gives the same depths
  in every render, and in every strip of one, so separate renders merge);
* RGBA = the premultiplied fragment colour the resolve composites with ``over``; a holdout mesh's
  fragment is ``(0, 0, 0, 1)`` (weighted by its coverage), so a deep merge is cut behind it, where
  the flat frame has ``(0, 0, 0, 0)``: flattening gives the flat frame's colour and its alpha plus
  the holdout's visible coverage (``render(..., deep=True).deep_holdout``: those samples alone).

With one sample per pixel, :func:`compositing.deep.flatten` of the result is the A-buffer
image (the resolve sorts by window depth, a monotonic function of eye depth; fragments at
exactly the same depth are the exception: the resolve keeps their draw order, the deep image
merges them as coincident samples). With ``samples = k²`` each subpixel's fragment enters its
pixel with weight ``1/k²`` and the fragments of one surface (mesh and facing) in one pixel are
summed into one sample at their nearest depth (:func:`compositing.deep.from_fragments`);
flattening then differs from the supersampled A-buffer where surfaces cover a pixel in part
(docs/compositing.md gives the bound). Bands and strips are whole pixel rows, so the band
images stacked are the image one call of ``from_fragments`` over the frame would give.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from blinn_phong.frame.deep_fragments import DEEP_METHODS, DeepFragments, check_deep_method

if TYPE_CHECKING:
    from blinn_phong.model.scene import Scene
    from blinn_phong.planning.frame_plan import Fog
    from compositing.deep import DeepImage

__all__ = ["DEEP_METHODS", "DeepFragments", "check_deep_method", "render_deep"]


def render_deep(
    scene: Scene,
    width: int,
    height: int,
    *,
    shading: str = "auto",
    samples: int = 1,
    gl_compat: bool = False,
    cull_backfaces: bool = False,
    engine: str = "auto",
    transparency: str = "a_buffer",
    layers: int | None = None,
    shadows: object = None,
    fog: Fog | None = None,
    tolerance: float = 0.0,
) -> DeepImage:
    """The frame's fragments as a deep image: ``render(..., deep=True).deep`` (module docstring).

    Args:
        scene: the scene.
        width: image width in pixels.
        height: image height in pixels.
        shading: ``"auto"``, ``"flat"``, ``"gouraud"`` or ``"phong"``.
        samples: k² samples per pixel (coverage ``1/k²`` per fragment).
        gl_compat: the OpenGL 2.1 fixed-function preset.
        cull_backfaces: discard clockwise triangles.
        engine: ``"numpy"``, ``"numba"`` or ``"auto"`` for the stages.
        transparency: one of :data:`DEEP_METHODS` (the sorted-drawing and weighted-blended
            methods have no depth order to keep).
        layers: depth-peeling layers (None: the plan's).
        shadows: as for :func:`blinn_phong.frame.render`.
        fog: a :class:`blinn_phong.Fog` or None.
        tolerance: the planner's error tolerance.

    Raises:
        ValueError: ``transparency`` is not one of :data:`DEEP_METHODS`, or what
            :func:`blinn_phong.frame.render` refuses.
    """
    from blinn_phong.frame.render import render

    check_deep_method(transparency)
    result = render(
        scene, width, height, shading=shading, samples=samples, gl_compat=gl_compat,
        cull_backfaces=cull_backfaces, engine=engine, progress=False, transparency=transparency,
        layers=layers, shadows=shadows, fog=fog, tolerance=tolerance, deep=True,
    )  # fmt: skip
    return result.deep
