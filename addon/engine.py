"""The "Blinn-Phong" render engine: F12, ``bpy.ops.render.render`` and command-line renders.

``render()`` converts the evaluated depsgraph (``addon/convert.py``), renders it through
``addon/pipeline.py`` (the planner, then ``blinn_phong.frame.render`` or the effects recipe) and writes
the passes into Blender's render result:

* Combined: premultiplied linear RGBA with coverage alpha;
* Depth: distance along the view axis to the nearest opaque surface (1e10 where empty, as
  Cycles/EEVEE);
* Ambient, Diffuse, Specular: the lighting equation's terms (premultiplied RGB; without
  transparency and fog they sum to Combined's RGB); Shadow: mean light visibility (1 lit, 0 in
  shadow) times coverage. All are registered in ``update_render_passes`` so they appear on the
  Render Layers node.
* Light groups (View Layer › Passes › Light Groups; ``Object.lightgroup`` on lights and emissive
  objects, ``World.lightgroup``): one pass ``Combined_<group>`` (RGB) per group of the view
  layer's list, as Cycles names them: the frame lit by that group's emitters alone
  (``blinn_phong.frame.light_groups``); the passes sum to Combined when every emitter has a group.
* Cryptomatte (View Layer › Passes › Cryptomatte: Object, Material, Asset, Levels): the passes
  ``CryptoObject00`` … as Cycles names and registers them (RGBA, two rank/coverage pairs each),
  counted from the engine's own samples (``blinn_phong.frame.id_passes``), with the layer's header
  entries (``cryptomatte/<key>/name``, ``hash``, ``conversion``, ``manifest``) stored in the
  render result's metadata, so Blender's Cryptomatte node reads them and a multilayer EXR carries
  them (``compositing.cryptomatte``).

Pixels go in with ``foreach_set`` on flat float32 arrays, bottom row first (Blender's order).
``bl_use_postprocess`` lets Blender's compositor run on the result.

Deep EXR (``Scene.blinn_phong.deep_output``, Render Properties › Blinn-Phong › Deep Output): each
frame rendered (F12, an animation, ``bpy.ops.render.render``; not previews or the viewport) is
also rendered as a deep image in the same pass (``blinn_phong.frame.render(..., deep=True)``) and
written with ``compositing.deep_io.write_deep`` (atomic: a failed write keeps an existing file) to
:func:`deep_file_path`: the path an animation render saves the current frame to
(``RenderSettings.frame_path``, ``//`` relative to the .blend) with the format's extension replaced
by ``.deep.exr``, e.g. ``//render/shot_####`` and PNG → ``//render/shot_0001.deep.exr`` for frame
1. An F12 still is named the same way (Blender saves a still with Render › Write Still under the
output path with its ``#`` kept; its deep file carries the frame number). The file has the saved
frame's size (with a render border and Crop off, the border's pixels in the full frame). It
needs Transparency A-Buffer, Depth Peeling or Opaque: with another setting the render fails
before anything is rasterized, naming the setting. A failed deep write fails the render like any other error.
:data:`LAST_DEEP` keeps the image; a caller that writes it itself (``addon.batch``) sets
:data:`WRITE_DEEP_FILES` to False.

Failures: Blender ignores exceptions raised in ``render()`` and writes whatever is in the result
(black) as if it had succeeded. Here every failure is reported through ``report`` (the status bar
and the log), ``error_set``, stderr, and :data:`LAST_RENDER`; the image is filled with a
magenta/black error pattern instead of a plausible black frame; and in background mode, when
``Scene.blinn_phong.abort_on_error`` is set (the default), a ``blender -b`` process then exits
with code 1 so render farms see the failure. Inside the ``bpy`` module (an embedding Python)
``bpy.ops.render.render`` raises ``RuntimeError`` with the message instead.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
import traceback
from typing import TYPE_CHECKING, Any

import bpy
import numpy as np

from blinn_phong import Cryptomatte, LightGroups
from blinn_phong.frame.background import holdout_coverage, holdout_request, world_behind
from compositing import composite
from compositing._kernel_cache import compile_clock
from compositing.cryptomatte import pass_names

from . import convert, mapping, options, pipeline

if TYPE_CHECKING:
    from compositing.deep import DeepImage  # imported where used: it needs numba

__all__ = [
    "CRYPTOMATTE_LAYERS",
    "ENGINE_ID",
    "LAST_DEEP",
    "LAST_PREVIEW",
    "LAST_RENDER",
    "PREVIEW_OPTIONS",
    "PREVIEW_TIMES",
    "WRITE_DEEP_FILES",
    "BlinnPhongRenderEngine",
    "RenderCancelled",
    "ViewportState",
    "classes",
    "cryptomatte_layers",
    "cryptomatte_request",
    "deep_file_path",
    "error_pattern",
    "frame_deep_image",
    "light_group_names",
    "light_groups_request",
    "register",
    "render_converted",
    "unregister",
    "user_cancelled",
    "viewport_frame",
]

ENGINE_ID = "BLINN_PHONG"

LIGHT_PASSES: tuple[tuple[str, str], ...] = (
    ("Ambient", "ambient"),
    ("Diffuse", "diffuse"),
    ("Specular", "specular"),
)
"""Blender pass name and the ``pipeline.FrameResult.passes`` key it is filled from (3 channels, RGB)."""

LAST_RENDER: dict[str, Any] = {}
"""Status of the most recent render in this process: ``ok``, ``error``, ``seconds``, ``notes``,
``choices`` (what was rendered how, and why: including ``engine``, the kernels that ran, and
``embree``), ``stats`` (seconds per stage, ``compile`` apart), ``status`` (the status line), ``size``.
Read by the Render panel and the batch runner. With Deep EXR on, ``deep_output`` is the file written
(None when :data:`WRITE_DEEP_FILES` is False)."""

LAST_DEEP: dict[str, Any] = {}
"""The deep image of the most recent render with Deep EXR on: ``image`` (a
``compositing.deep.DeepImage`` of the saved frame's size, :func:`frame_deep_image`), ``frame``,
``path`` (the file written, or None). Emptied when a render starts."""

WRITE_DEEP_FILES = True
"""True: a render with Deep EXR on writes its deep image to :func:`deep_file_path`. A caller that
writes the image itself, under its own rules (the batch runner: job-named temporary files,
write permits, read-back), sets this False and takes ``LAST_DEEP["image"]``."""


PREVIEW_OPTIONS = options.RenderOptions(samples_per_axis=2, shadows="NONE", transparency="AUTO")
"""Settings of material/world previews: 2×2 anti-aliasing, no shadows (the preview's floor and
backdrop would only add shadow cost to a thumbnail), the planner's transparency."""

LAST_PREVIEW: dict[str, Any] = {}
"""Status of the most recent preview render: ``ok``, ``error``, ``seconds``, ``size``, ``stats``."""

PREVIEW_TIMES: list[tuple[int, int, float]] = []
"""``(width, height, seconds)`` of the latest preview renders in this process (at most 64)."""


class RenderCancelled(Exception):
    """The user cancelled the render (``RenderEngine.test_break``)."""


def user_cancelled(engine: bpy.types.RenderEngine) -> bool:
    """True when Blender asks the render to stop (Esc in the UI): ``RenderEngine.test_break()``."""
    return bool(engine.test_break())


def error_pattern(height: int, width: int, cell: int = 8) -> np.ndarray:
    """A magenta/black checkerboard (opaque, float32 RGBA) marking a failed render.

    Args:
        height: rows.
        width: columns.
        cell: checker cell size in pixels.
    """
    rows, cols = np.indices((height, width))
    magenta = ((rows // cell + cols // cell) % 2 == 0).astype(np.float32)
    out = np.zeros((height, width, 4), np.float32)
    out[..., 0] = magenta
    out[..., 2] = magenta
    out[..., 3] = 1.0
    return out


CRYPTOMATTE_LAYERS: tuple[tuple[str, str], ...] = (
    ("object", "use_pass_cryptomatte_object"),
    ("material", "use_pass_cryptomatte_material"),
    ("asset", "use_pass_cryptomatte_asset"),
)
"""Cryptomatte layer type and the ``ViewLayer`` switch that asks for it."""


def cryptomatte_layers(view_layer: Any) -> tuple[list[str], int]:
    """The Cryptomatte layer types ``view_layer`` asks for (in Cycles' pass order) and its levels."""
    if view_layer is None:
        return [], 0
    layers = [layer for layer, flag in CRYPTOMATTE_LAYERS if getattr(view_layer, flag, False)]
    return layers, min(16, int(getattr(view_layer, "pass_cryptomatte_depth", 6)))


def cryptomatte_request(view_layer: Any, converted: convert.ConvertedScene) -> Cryptomatte | None:
    """The :class:`blinn_phong.Cryptomatte` request of ``view_layer``'s switches for the converted
    scene's meshes (None when no layer is asked for)."""
    layers, levels = cryptomatte_layers(view_layer)
    if not layers:
        return None
    names = {layer: converted.cryptomatte_names.get(layer, []) for layer in layers}
    return Cryptomatte(names, levels)


def light_group_names(view_layer: Any) -> list[str]:
    """The names of ``view_layer``'s light groups (``ViewLayer.lightgroups``), in list order."""
    return [group.name for group in getattr(view_layer, "lightgroups", ())] if view_layer is not None else []


def light_groups_request(view_layer: Any, converted: convert.ConvertedScene) -> LightGroups | None:
    """The :class:`blinn_phong.LightGroups` of ``view_layer``'s list for the converted scene (an
    emitter whose group is not in the list belongs to none, as in Cycles); None without groups."""
    names = light_group_names(view_layer)
    if not names:
        return None
    members = converted.light_group_names

    def member(group: object) -> str | None:
        return str(group) if group in names else None

    return LightGroups(
        tuple(names),
        tuple(member(g) for g in members.get("lights", [])),  # type: ignore[union-attr]
        tuple(member(g) for g in members.get("meshes", [])),  # type: ignore[union-attr]
        member(members.get("world", "")),
    )


def render_converted(
    converted: convert.ConvertedScene,
    progress: Any = None,
    cryptomatte: Cryptomatte | None = None,
    light_groups: LightGroups | None = None,
) -> pipeline.FrameResult:
    """Render a converted scene over its region with the settings it carries (``addon/pipeline.py``).

    The compiled kernels every frame needs are loaded (read from the disk cache, or compiled)
    before the frame (:func:`pipeline.warm_kernels`); ``result.seconds["compile"]`` holds every
    second numba spent compiling for this call — that warm-up, the kernels of the frame's own
    effects (ray-traced shadows, …) and the background composite — and is absent when nothing
    was compiled.
    """
    width, height = converted.region_size
    holdout = None
    if converted.background is not None and any(m.holdout for m in converted.scene.meshes):
        holdout = holdout_request(converted.scene.meshes, cryptomatte)
        cryptomatte = holdout.request
    engine, note = pipeline.frame_engine(converted.options.engine)
    frame_options = converted.options
    if engine != frame_options.engine:  # compiling in the background: numpy meanwhile
        frame_options = dataclasses.replace(frame_options, engine=engine)
    with compile_clock() as compiling:
        pipeline.warm_kernels(engine)
        result = pipeline.render_frame(
            converted.scene,
            width,
            height,
            frame_options,
            light_radii=tuple(converted.light_radii),
            casts_shadows=tuple(converted.casts_shadows),
            progress=progress,
            cryptomatte=cryptomatte,
            light_groups=light_groups,
        )
        result.choices["region"] = list(converted.region)
        if note:
            result.choices["compile_note"] = note
        if converted.background is not None:
            # Film → Transparent off: the world shows behind the objects (Porter-Duff src over),
            # except where a holdout is seen: that coverage stays transparent black, as in Cycles.
            world = np.array([*converted.background, 1.0], dtype=np.float32)
            held = None if holdout is None else holdout_coverage(result.passes, holdout)
            if held is None:
                result.rgba = composite(result.rgba, np.broadcast_to(world, result.rgba.shape), "src_over")
            else:
                result.rgba = world_behind(result.rgba, world, held)
            result.choices["background"] = "world colour (Film → Transparent is off)"
    result.seconds.pop("compile", None)  # the frame's own count, included in this one
    if compiling.seconds:
        result.seconds["compile"] = compiling.seconds
    return result


def frame_deep_image(deep: DeepImage, converted: convert.ConvertedScene, crop: bool) -> DeepImage:
    """The deep image of the saved frame: ``deep`` (rendered over ``converted.region``) as it is
    when the region is the whole frame or ``crop`` (Render Region with Crop to Render Region: the
    saved frame is the region), else placed in the full frame with no samples outside the region
    (Blender saves such a frame at full size, transparent outside the region)."""
    from compositing.deep import DeepImage

    x0, y0, x1, y1 = converted.region
    if crop or (x0, y0, x1, y1) == (0, 0, converted.width, converted.height):
        return deep
    counts = np.zeros((converted.height, converted.width), np.uint32)
    counts[y0:y1, x0:x1] = deep.counts  # rows from the top; samples stay in row-major order
    return DeepImage(counts, deep.z, deep.zback, deep.rgba)


def deep_file_path(scene: bpy.types.Scene, frame: int | None = None) -> str:
    """The deep EXR of ``frame`` (default: the current one): the frame's output path
    (``RenderSettings.frame_path``, made absolute) with the format's extension replaced by
    ``.deep.exr`` (:func:`addon.options.deep_output_path`)."""
    render_settings = scene.render
    frame = scene.frame_current if frame is None else int(frame)
    output = bpy.path.abspath(render_settings.frame_path(frame=frame))
    extension = render_settings.file_extension if render_settings.use_file_extension else ""
    return os.path.abspath(options.deep_output_path(output, extension))


VIEWPORT_REDUCTION = 4
"""The viewport's first frame after a change is rendered at 1/4 of the region per axis."""


class ViewportState:
    """What the viewport keeps between redraws: object-space geometry per object name.

    ``apply_updates(depsgraph.updates)`` (from ``view_update``) drops the geometry of the objects
    whose geometry changed (``DepsgraphUpdate.is_updated_geometry``: edits, modifiers); a moved
    object keeps its arrays (transforms are read on every conversion, as are materials, lights and
    the world, which cost little).
    """

    def __init__(self) -> None:
        self.geometry: dict[str, tuple] = {}

    def apply_updates(self, updates: Any) -> list[str]:
        """Forget the geometry of updated objects (and of every object using an updated mesh);
        return the names forgotten."""
        dropped: list[str] = []
        for update in updates:
            if not update.is_updated_geometry:
                continue
            changed = update.id
            if isinstance(changed, bpy.types.Object):
                names = [changed.name]
            else:  # a Mesh, Curve, ... data-block: every cached object that uses it
                names = [
                    name
                    for name in self.geometry
                    if (obj := bpy.data.objects.get(name)) is not None and obj.data == changed.original
                ]
            for name in names:
                if self.geometry.pop(name, None) is not None:
                    dropped.append(name)
        return dropped


def viewport_frame(
    depsgraph: bpy.types.Depsgraph,
    camera: Any,
    region_width: int,
    region_height: int,
    reduction: int = 1,
    state: ViewportState | None = None,
) -> tuple[np.ndarray, int, int]:
    """The pixels handed to ``gpu`` for the 3D view: ``(flat float32 RGBA, width, height)``.

    Renders the depsgraph's scene from ``camera`` (``convert.viewport_camera``) at
    ``mapping.viewport_size(region, reduction)`` with the scene's settings (1 sample per pixel at
    reduced resolution), premultiplied linear RGBA, bottom row first (OpenGL texture order).
    """
    width, height = mapping.viewport_size(int(region_width), int(region_height), reduction)
    cache = state.geometry if state is not None else None
    converted = convert.scene_from_depsgraph(depsgraph, view=(camera, width, height), geometry_cache=cache)
    converted.options = dataclasses.replace(converted.options, deep_output=False)  # frames only
    if reduction > 1:
        converted.options = dataclasses.replace(converted.options, samples_per_axis=1)
    result = render_converted(converted)
    return np.ascontiguousarray(result.rgba[::-1], dtype=np.float32).ravel(), width, height


class BlinnPhongRenderEngine(bpy.types.RenderEngine):
    """Local Blinn-Phong shading with OpenGL conventions (``blinn_phong`` package)."""

    bl_idname = ENGINE_ID
    bl_label = "Blinn-Phong"
    bl_use_preview = True  # material and world previews are rendered by this engine
    bl_use_postprocess = True
    bl_use_shading_nodes_custom = False
    bl_use_eevee_viewport = True  # the 3D viewport's Material Preview mode uses EEVEE

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        # Blender 4.4+ passes arguments to RenderEngine.__init__; 4.2 passes none. Forward both.
        super().__init__(*args, **kwargs)

    def update_render_passes(
        self, scene: bpy.types.Scene = None, renderlayer: bpy.types.ViewLayer = None
    ) -> None:
        """Declare the passes so the compositor's Render Layers node shows them."""
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        self.register_pass(scene, renderlayer, "Depth", 1, "Z", "VALUE")
        for name, _key in LIGHT_PASSES:
            self.register_pass(scene, renderlayer, name, 3, "RGB", "COLOR")
        self.register_pass(scene, renderlayer, "Shadow", 1, "X", "VALUE")
        for group in light_group_names(renderlayer):
            self.register_pass(scene, renderlayer, LightGroups.pass_name(group), 3, "RGB", "COLOR")
        layers, levels = cryptomatte_layers(renderlayer)
        for layer in layers:
            for name in pass_names(layer, levels):
                self.register_pass(scene, renderlayer, name, 4, "rgba", "COLOR")

    def render(self, depsgraph: bpy.types.Depsgraph) -> None:
        """Render one view layer of ``depsgraph`` into a render result (or a material preview)."""
        if self.is_preview:
            self._render_preview(depsgraph)
            return
        scene = depsgraph.scene
        render_settings = scene.render
        full_w, full_h = mapping.render_size(
            render_settings.resolution_x, render_settings.resolution_y, render_settings.resolution_percentage
        )
        layer = depsgraph.view_layer.name  # render() runs once per view layer
        started = time.perf_counter()
        LAST_RENDER.clear()
        LAST_RENDER.update({"ok": False, "error": None, "scene": scene.name, "frame": scene.frame_current})
        LAST_DEEP.clear()
        try:
            self.update_stats("", "Blinn-Phong: converting the scene")
            converted = convert.scene_from_depsgraph(depsgraph)
            if user_cancelled(self):
                raise RenderCancelled

            def progress(stage: str, fraction: float) -> None:
                self.update_progress(float(fraction))
                self.update_stats("", f"Blinn-Phong: {stage}")
                if user_cancelled(self):
                    raise RenderCancelled

            request = cryptomatte_request(depsgraph.view_layer, converted)
            groups = light_groups_request(depsgraph.view_layer, converted)
            self._first_image_while_compiling(converted, progress, layer)
            result = render_converted(converted, progress, request, groups)
            deep_path = None
            if result.deep is not None:
                deep_path = self._keep_deep(scene, converted, result.deep)
            self._write(converted, result, layer, cryptomatte=request, light_groups=groups)
        except RenderCancelled:
            LAST_RENDER.update({"error": "cancelled", "seconds": time.perf_counter() - started})
            # Blender crashes saving a still (write_still) after a render that produced no result,
            # so a cancelled render leaves the error pattern: never a frame that looks finished.
            self._write_error_pattern(full_w, full_h, layer)
            return
        except Exception as error:
            self._fail(scene, full_w, full_h, error, started, layer)
            return
        notes = [*result.choices.get("warnings", []), *converted.notes]
        LAST_RENDER.update(
            {
                "ok": True,
                "seconds": time.perf_counter() - started,
                "choices": result.choices,
                "notes": notes,
                "size": [full_w, full_h],
                "stats": result.seconds,
                "triangles": result.triangles,
            }
        )
        if result.deep is not None:
            LAST_RENDER["deep_output"] = deep_path
        LAST_RENDER["status"] = pipeline.status_line(result.choices, LAST_RENDER["seconds"], result.seconds)
        self.update_stats("", LAST_RENDER["status"])
        for warning in result.choices.get("warnings", []):
            print(f"Blinn-Phong: warning: {warning}", file=sys.stderr, flush=True)
        for note in notes:
            self.report({"WARNING"}, note)

    def _first_image_while_compiling(
        self, converted: convert.ConvertedScene, progress: Any, layer: str
    ) -> None:
        """While the kernels compile in the background (:func:`pipeline.frame_engine`), frames
        render with the numpy engine, which is slow at several samples per pixel (a 1080p frame:
        3.7 s at one sample, 13.7 s at four on the 2-core VM). Show a one-sample Combined image
        first, as a progressive render would; the full frame then replaces it."""
        engine, note = pipeline.frame_engine(converted.options.engine)
        if engine != "NUMPY" or note is None or converted.options.samples_per_axis <= 1:
            return
        self.update_stats("", "Blinn-Phong: a first image at one sample while the kernels compile")
        quick = dataclasses.replace(
            converted, options=dataclasses.replace(converted.options, samples_per_axis=1)
        )
        self._write(converted, render_converted(quick, progress), layer, combined_only=True)
        LAST_RENDER["first_image"] = True

    def _keep_deep(
        self, scene: bpy.types.Scene, converted: convert.ConvertedScene, deep: DeepImage
    ) -> str | None:
        """Keep the frame's deep image in :data:`LAST_DEEP` and, with :data:`WRITE_DEEP_FILES`,
        write it (atomically) to :func:`deep_file_path`; returns the path written, or None."""
        image = frame_deep_image(
            deep, converted, bool(scene.render.use_border and scene.render.use_crop_to_border)
        )
        LAST_DEEP.update({"image": image, "frame": scene.frame_current, "path": None})
        if not WRITE_DEEP_FILES:
            return None
        from compositing.deep_io import write_deep

        path = deep_file_path(scene)
        self.update_stats("", f"Blinn-Phong: writing {path}")
        os.makedirs(os.path.dirname(path), exist_ok=True)
        try:
            write_deep(path, image)
        except OSError as error:
            raise OSError(f"Deep EXR: writing {path} failed, the previous file is kept: {error}") from None
        LAST_DEEP["path"] = path
        return path

    def _render_preview(self, depsgraph: bpy.types.Depsgraph) -> None:
        """A material/world preview (``bl_use_preview``): Blender's preview scene, rendered with
        :data:`PREVIEW_OPTIONS`; recorded in :data:`LAST_PREVIEW`, never in :data:`LAST_RENDER`.

        A failure fills the preview with the error pattern and is recorded; it never ends the
        process (previews are not frames a render farm waits for).
        """
        started = time.perf_counter()
        layer = depsgraph.view_layer.name
        render_settings = depsgraph.scene.render
        full_w, full_h = mapping.render_size(
            render_settings.resolution_x, render_settings.resolution_y, render_settings.resolution_percentage
        )
        try:
            converted = convert.scene_from_depsgraph(depsgraph)
            converted.options = PREVIEW_OPTIONS
            converted_at = time.perf_counter()
            result = render_converted(converted)
            rendered_at = time.perf_counter()
            self._write(converted, result, layer, combined_only=True)
        except Exception as error:
            LAST_PREVIEW.update({"ok": False, "error": f"{type(error).__name__}: {error}"})
            self._write_error_pattern(full_w, full_h, layer)
            return
        LAST_PREVIEW.clear()
        LAST_PREVIEW.update(
            {
                "ok": True,
                "size": [full_w, full_h],
                "seconds": time.perf_counter() - started,
                "stats": {
                    **result.seconds,
                    "convert": converted_at - started,
                    "render": rendered_at - converted_at,
                    "write": time.perf_counter() - rendered_at,
                },
                "choices": result.choices,
                "triangles": result.triangles,
            }
        )
        PREVIEW_TIMES.append((full_w, full_h, LAST_PREVIEW["seconds"]))
        del PREVIEW_TIMES[:-64]

    # ----------------------------------------------------------------- viewport (Rendered shading)

    def view_update(self, context: bpy.types.Context, depsgraph: bpy.types.Depsgraph) -> None:
        """The scene changed (or the viewport opened): the next ``view_draw`` renders it again,
        reading again only the geometry of objects the depsgraph reports as changed
        (:class:`ViewportState`)."""
        if not hasattr(self, "_view_state"):
            self._view_state = ViewportState()
        self._view_state.apply_updates(depsgraph.updates)
        self._view_frames = {}
        self._view_scene_dirty = True

    def view_draw(self, context: bpy.types.Context, depsgraph: bpy.types.Depsgraph) -> None:
        """Draw the viewport frame: first at 1/:data:`VIEWPORT_REDUCTION` of the region, then full.

        The frame is rendered by :func:`viewport_frame` (testable without a display) and drawn through
        Blender's ``gpu`` module with the display colour management (``bind_display_space_shader``),
        as Blender's own engines do. The bpy module cannot draw (no GPU context in background mode).
        """
        import gpu
        from gpu_extras.presets import draw_texture_2d

        region = context.region
        camera = convert.viewport_camera(context.space_data, region, context.region_data)
        key = (camera.view.tobytes(), camera.projection.tobytes(), region.width, region.height)
        frames = getattr(self, "_view_frames", {})
        if getattr(self, "_view_key", None) != key or getattr(self, "_view_scene_dirty", True):
            frames = {}  # the view or the scene changed: start again at reduced resolution
        reduction = 1 if VIEWPORT_REDUCTION in frames else VIEWPORT_REDUCTION
        if reduction not in frames:
            state = getattr(self, "_view_state", None)
            frames[reduction] = viewport_frame(
                depsgraph, camera, region.width, region.height, reduction, state
            )
        self._view_frames, self._view_key, self._view_scene_dirty = frames, key, False
        pixels, width, height = frames[reduction]
        texture = gpu.types.GPUTexture(
            (width, height), format="RGBA16F", data=gpu.types.Buffer("FLOAT", pixels.size, pixels)
        )
        gpu.state.blend_set("ALPHA_PREMULT")
        self.bind_display_space_shader(depsgraph.scene)
        draw_texture_2d(texture, (0, 0), region.width, region.height)
        self.unbind_display_space_shader()
        gpu.state.blend_set("NONE")
        if reduction != 1:
            self.tag_redraw()  # the full-resolution frame follows in the next draw

    # ----------------------------------------------------------------- result

    def _write(
        self,
        converted: convert.ConvertedScene,
        result: Any,
        layer: str,
        combined_only: bool = False,
        cryptomatte: Cryptomatte | None = None,
        light_groups: LightGroups | None = None,
    ) -> None:
        x0, y0, x1, y1 = converted.region
        width, height = x1 - x0, y1 - y0
        group_passes = [] if light_groups is None else [LightGroups.pass_name(g) for g in light_groups.groups]
        if not combined_only:  # previews show Combined only: no extra passes to fill
            self.add_pass("Depth", 1, "Z")
            for name, _key in LIGHT_PASSES:
                self.add_pass(name, 3, "RGB")
            self.add_pass("Shadow", 1, "X")
            for name in group_passes:
                self.add_pass(name, 3, "RGB")
            for name in [] if cryptomatte is None else cryptomatte.pass_names():
                self.add_pass(name, 4, "rgba")  # lowercase: data, as Cycles registers them
        # begin_result takes the full frame; with a border Blender clips it to the border itself.
        render_result = self.begin_result(0, 0, converted.width, converted.height, layer=layer)
        try:
            result_layer = render_result.layers[0]
            got = (render_result.resolution_x, render_result.resolution_y)
            if got != (width, height):
                raise RuntimeError(
                    f"render result is {got[0]}×{got[1]} but the converted region is {width}×{height}"
                )
            buffers = {"Combined": result.rgba}
            if not combined_only:
                depth = mapping.window_depth_to_distance(result.depth, converted.scene.camera.projection)
                buffers["Depth"] = depth[..., None]
                for name, key in LIGHT_PASSES:
                    buffers[name] = result.passes[key]
                buffers["Shadow"] = result.passes["shadow"]
                for name in group_passes:
                    buffers[name] = result.passes[name]
                if cryptomatte is not None:
                    for name in cryptomatte.pass_names():
                        buffers[name] = result.passes[name]
            for name, image in buffers.items():
                render_pass = result_layer.passes.get(name)
                if render_pass is None:
                    continue
                flat = np.ascontiguousarray(image[::-1], dtype=np.float32).ravel()
                render_pass.rect.foreach_set(flat)
        except Exception:
            self.end_result(render_result, cancel=True)
            raise
        self.end_result(render_result)
        if cryptomatte is not None:  # the whole result's metadata (EXR header), as Cycles stores it
            whole = self.get_result()
            for key, value in cryptomatte.metadata(layer).items():
                whole.stamp_data_add_field(key, value)

    def _write_error_pattern(self, width: int, height: int, layer: str) -> None:
        """Fill Combined with :func:`error_pattern` (the result Blender shows and saves)."""
        try:
            render_result = self.begin_result(0, 0, width, height, layer=layer)
            combined = render_result.layers[0].passes["Combined"]
            pattern = error_pattern(render_result.resolution_y, render_result.resolution_x)
            combined.rect.foreach_set(pattern.ravel())
            self.end_result(render_result)
        except Exception as secondary:
            print(f"Blinn-Phong: could not write the error image: {secondary}", file=sys.stderr, flush=True)

    def _fail(
        self, scene: bpy.types.Scene, width: int, height: int, error: Exception, started: float, layer: str
    ) -> None:
        message = f"Blinn-Phong render failed: {type(error).__name__}: {error}"
        details = traceback.format_exc()
        LAST_RENDER.update(
            {"ok": False, "error": message, "traceback": details, "seconds": time.perf_counter() - started}
        )
        print(details, file=sys.stderr, flush=True)
        print(message, file=sys.stderr, flush=True)
        self.report({"ERROR"}, message)
        self.error_set(message)
        self._write_error_pattern(width, height, layer)
        settings = getattr(scene, "blinn_phong", None)
        # Only under Blender's own command line (``blender -b``): inside an embedding Python (the
        # ``bpy`` module, empty ``binary_path``) the error report above already makes
        # ``bpy.ops.render.render`` raise RuntimeError, so the caller's try/except/finally runs.
        if bpy.app.background and bpy.app.binary_path and (settings is None or settings.abort_on_error):
            print(
                "Blinn-Phong: exiting with code 1 (Scene.blinn_phong.abort_on_error)",
                file=sys.stderr,
                flush=True,
            )
            sys.stdout.flush()
            os._exit(1)


classes = (BlinnPhongRenderEngine,)


def register() -> None:
    """Register the engine class; with Blender's interface, kernels compile in a background
    process while the first frames render with numpy (:func:`pipeline.frame_engine`)."""
    pipeline.BACKGROUND_COMPILE = not bpy.app.background
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister() -> None:
    """Unregister the engine.

    A RenderEngine left registered at interpreter exit crashes bpy 4.2 and hangs 4.5, so callers
    that register it by hand must call this (Blender calls the add-on's ``unregister`` at exit).
    """
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
