"""The "Blinn-Phong" render engine: F12, ``bpy.ops.render.render`` and command-line renders.

``render()`` converts the evaluated depsgraph (``addon/convert.py``), renders it through
``addon/pipeline.py`` (the planner, then ``blinn_phong.render`` or the effects recipe) and writes
the passes into Blender's render result:

* Combined: premultiplied linear RGBA with coverage alpha;
* Depth: distance along the view axis to the nearest opaque surface (1e10 where empty, as
  Cycles/EEVEE);
* Ambient, Diffuse, Specular: the lighting equation's terms (premultiplied RGB; without
  transparency and fog they sum to Combined's RGB); Shadow: mean light visibility (1 lit, 0 in
  shadow) times coverage. All are registered in ``update_render_passes`` so they appear on the
  Render Layers node.

Pixels go in with ``foreach_set`` on flat float32 arrays, bottom row first (Blender's order).
``bl_use_postprocess`` lets Blender's compositor run on the result.

Failures: Blender ignores exceptions raised in ``render()`` and writes whatever is in the result
(black) as if it had succeeded. Here every failure is reported through ``report`` (the status bar
and the log), ``error_set``, stderr, and :data:`LAST_RENDER`; the image is filled with a
magenta/black error pattern instead of a plausible black frame; and in background mode, when
``Scene.blinn_phong.abort_on_error`` is set (the default), a ``blender -b`` process then exits
with code 1 so render farms see the failure. Inside the ``bpy`` module (an embedding Python)
``bpy.ops.render.render`` raises ``RuntimeError`` with the message instead.
"""

from __future__ import annotations

import os
import sys
import time
import traceback
from typing import Any

import bpy
import numpy as np

from compositing import composite

from . import convert, mapping, pipeline

__all__ = [
    "ENGINE_ID",
    "LAST_RENDER",
    "BlinnPhongRenderEngine",
    "RenderCancelled",
    "classes",
    "error_pattern",
    "register",
    "render_converted",
    "unregister",
    "user_cancelled",
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
``choices`` (what was rendered how, and why), ``size``. Read by the Render panel and the batch
runner."""


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


def render_converted(converted: convert.ConvertedScene, progress: Any = None) -> pipeline.FrameResult:
    """Render a converted scene over its region with the settings it carries (``addon/pipeline.py``)."""
    o = converted.options
    options = pipeline.EffectOptions(
        transparency=o.transparency,
        peel_layers=o.peel_layers,
        shadows=o.shadows,
        shadow_samples=o.shadow_samples,
        shadow_bias=o.shadow_bias,
        light_radii=tuple(converted.light_radii),
        fog=o.fog,
        fog_color=o.fog_color,
        fog_density=o.fog_density,
        fog_start=o.fog_start,
        fog_end=o.fog_end,
        tolerance=o.tolerance,
    )
    width, height = converted.region_size
    result = pipeline.render_frame(
        converted.scene,
        width,
        height,
        shading=o.shading,
        samples=o.samples,
        options=options,
        progress=progress,
    )
    result.choices["region"] = list(converted.region)
    if converted.background is not None:
        # Film → Transparent off: the world shows behind the objects (Porter-Duff src over).
        world = np.array([*converted.background, 1.0], dtype=np.float32)
        result.rgba = composite(result.rgba, np.broadcast_to(world, result.rgba.shape), "src_over")
        result.choices["background"] = "world colour (Film → Transparent is off)"
    return result


class BlinnPhongRenderEngine(bpy.types.RenderEngine):
    """Local Blinn-Phong shading with OpenGL conventions (``blinn_phong`` package)."""

    bl_idname = ENGINE_ID
    bl_label = "Blinn-Phong"
    bl_use_preview = False
    bl_use_postprocess = True
    bl_use_shading_nodes_custom = False
    bl_use_eevee_viewport = True  # Material Preview in the 3D viewport uses EEVEE

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

    def render(self, depsgraph: bpy.types.Depsgraph) -> None:
        """Render one view layer of ``depsgraph`` into a render result."""
        scene = depsgraph.scene
        render_settings = scene.render
        full_w, full_h = mapping.render_size(
            render_settings.resolution_x, render_settings.resolution_y, render_settings.resolution_percentage
        )
        layer = depsgraph.view_layer.name  # render() runs once per view layer
        started = time.perf_counter()
        LAST_RENDER.clear()
        LAST_RENDER.update({"ok": False, "error": None, "scene": scene.name, "frame": scene.frame_current})
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

            result = render_converted(converted, progress)
            self._write(converted, result, layer)
        except RenderCancelled:
            LAST_RENDER.update({"error": "cancelled", "seconds": time.perf_counter() - started})
            # Blender crashes saving a still (write_still) after a render that produced no result,
            # so a cancelled render leaves the error pattern: never a frame that looks finished.
            self._write_error_pattern(full_w, full_h, layer)
            return
        except Exception as error:
            self._fail(scene, full_w, full_h, error, started, layer)
            return
        LAST_RENDER.update(
            {
                "ok": True,
                "seconds": time.perf_counter() - started,
                "choices": result.choices,
                "notes": converted.notes,
                "size": [full_w, full_h],
                "stats": result.seconds,
                "triangles": result.triangles,
            }
        )
        self.update_stats("", f"Blinn-Phong: done in {LAST_RENDER['seconds']:.2f} s")
        for note in converted.notes:
            self.report({"WARNING"}, note)

    # ----------------------------------------------------------------- result

    def _write(self, converted: convert.ConvertedScene, result: Any, layer: str) -> None:
        x0, y0, x1, y1 = converted.region
        width, height = x1 - x0, y1 - y0
        self.add_pass("Depth", 1, "Z")
        for name, _key in LIGHT_PASSES:
            self.add_pass(name, 3, "RGB")
        self.add_pass("Shadow", 1, "X")
        # begin_result takes the full frame; with a border Blender clips it to the border itself.
        render_result = self.begin_result(0, 0, converted.width, converted.height, layer=layer)
        try:
            result_layer = render_result.layers[0]
            got = (render_result.resolution_x, render_result.resolution_y)
            if got != (width, height):
                raise RuntimeError(
                    f"render result is {got[0]}×{got[1]} but the converted region is {width}×{height}"
                )
            depth = mapping.window_depth_to_distance(result.depth, converted.scene.camera.projection)
            buffers = {"Combined": result.rgba, "Depth": depth[..., None]}
            for name, key in LIGHT_PASSES:
                buffers[name] = result.passes[key]
            buffers["Shadow"] = result.passes["shadow"]
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
    """Register the engine class."""
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister() -> None:
    """Unregister the engine.

    A RenderEngine left registered at interpreter exit crashes bpy 4.2 and hangs 4.5, so callers
    that register it by hand must call this (Blender calls the add-on's ``unregister`` at exit).
    """
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
