"""Deep output of a frame: the fragments the A-buffer (or depth peeling) resolves, as a deep image.

:func:`render_deep` runs the stages of :func:`blinn_phong.render` up to the fragment colours
(plan, preparation, visible fragments, shadows, shading, textures,
:func:`blinn_phong.resolve.fragment_colours` — transparency models, Kay–Greenberg opacity,
wash-out and fog included) and, instead of resolving each sample, returns the fragments as a
:class:`compositing.deep.DeepImage`:

* one point sample per fragment kept by the method: each sample's nearest opaque fragment and
  the transparent fragments in front of it (``a_buffer``: all of them; ``depth_peeling``: the
  nearest ``layers``; ``zbuffer``: the nearest fragment only);
* ``Z = ZBack`` = the fragment's eye-space depth (distance along the view axis, ``-z_eye``,
  interpolated perspective-correctly from the vertices: the same camera gives the same depths
  in every render, so separate renders merge);
* RGBA = the premultiplied fragment colour the resolve composites with ``over``.

With one sample per pixel, :func:`compositing.deep.flatten` of the result is the A-buffer
image (the resolve sorts by window depth, a monotonic function of eye depth; fragments at
exactly the same depth are the exception: the resolve keeps their draw order, the deep image
merges them as coincident samples). With ``samples = k²`` each subpixel's fragment enters its
pixel with weight ``1/k²`` and the fragments of one surface (mesh and facing) in one pixel are
summed into one sample at their nearest depth (:func:`compositing.deep.from_fragments`);
flattening then differs from the supersampled A-buffer where surfaces cover a pixel in part
(docs/compositing.md gives the bound).
"""

from __future__ import annotations

import numpy as np

from blinn_phong.frame import Fog, frame_plan, scene_with_planned_shading
from blinn_phong.pipeline import light_visibilities
from blinn_phong.prepared import prepare_scene
from blinn_phong.raster import interpolate
from blinn_phong.resolve import FogParameters, fragment_colours, opaque_test
from blinn_phong.scene import Scene, prepare_render_inputs
from blinn_phong.shading import shade_fragments
from blinn_phong.texturing import texture_fragments
from blinn_phong.visibility import frame_fragments, use_compiled
from compositing.deep import DeepImage, from_fragments

__all__ = ["DEEP_METHODS", "render_deep"]

#: Transparency methods whose fragments have a depth order a deep image can hold.
DEEP_METHODS = ("a_buffer", "depth_peeling", "zbuffer")


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
    """The frame's fragments as a deep image (module docstring); arguments as :func:`blinn_phong.render`.

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
        shadows: as for :func:`blinn_phong.render`.
        fog: a :class:`blinn_phong.Fog` or None.
        tolerance: the planner's error tolerance.

    Raises:
        ValueError: ``transparency`` is not one of :data:`DEEP_METHODS`, or what
            :func:`blinn_phong.render` refuses.
    """
    if transparency not in DEEP_METHODS:
        raise ValueError(
            f"transparency: deep output keeps depth-sorted fragments; expected one of {DEEP_METHODS}, "
            f"got {transparency!r}"
        )
    if engine not in ("numpy", "numba", "auto"):
        raise ValueError(f"engine: expected 'numpy', 'numba' or 'auto', got {engine!r}")
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a blinn_phong.Scene, got {type(scene).__name__}")
    scene = prepare_render_inputs(scene, width, height, samples, gl_compat)
    the_plan = frame_plan(
        scene,
        tolerance=tolerance,
        shading=shading,
        transparency=transparency,
        peel_layers=layers,
        shadows=shadows,
        gl_compat=gl_compat,
        width=width,
        height=height,
        samples=samples,
        fog=fog,
    )
    if shading == "auto":
        scene, shading = scene_with_planned_shading(scene, the_plan, shading), "phong"
    prepared = prepare_scene(scene)
    stage_engine = "numba" if use_compiled(engine) else "numpy"
    method = the_plan.transparency.method
    opaque = None if method == "zbuffer" else opaque_test(prepared)

    visible = frame_fragments(
        prepared.clip,
        prepared.triangles,
        width,
        height,
        opaque=opaque,
        samples=samples,
        cull_backfaces=cull_backfaces,
        engine=stage_engine,
    )
    visibility = light_visibilities(prepared, visible, the_plan)
    f = visible.fragments
    shaded = shade_fragments(
        prepared, f, shading=shading, gl_compat=gl_compat, visibility=visibility, engine=stage_engine
    )
    shaded = texture_fragments(prepared, f, shaded, gl_compat=gl_compat, engine=stage_engine)
    rgba, _ = fragment_colours(prepared, visible, shaded, FogParameters.of(fog), engine=stage_engine)

    keep = np.ones(len(f), bool)
    if method == "depth_peeling" and visible.n_transparent:
        n_layers = int(the_plan.transparency.params.get("layers") or len(f))
        tr = np.arange(visible.n_opaque, len(f))
        order = tr[np.lexsort((f.depth[tr], f.sample_key[tr]))]  # by sample, nearest first
        key = f.sample_key[order]
        first = np.searchsorted(key, key, side="left")
        rank = np.arange(len(order)) - first
        keep[order[rank >= n_layers]] = False
    eye_depth = -interpolate(f, prepared.triangles, prepared.eye_position[:, 2])
    # Near-plane clipping keeps fragments in front of the camera: eye depth >= near > 0 (a
    # rounding step below 0 at worst is clamped, as OpenEXR depths are >= 0).
    eye_depth = np.maximum(eye_depth, 0.0)
    surface = 2 * prepared.triangle_mesh[f.triangle] + (~f.front_facing)
    return from_fragments(
        (height, width),
        f.pixel[keep],
        eye_depth[keep],
        rgba[keep],
        samples_per_pixel=f.samples,
        surface=surface[keep] if f.samples > 1 else None,
    )
