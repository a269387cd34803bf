"""Material previews rendered by the engine (``bl_use_preview``) through Blender's own preview job.

The bpy module renders previews in background mode through ``bpy.ops.wm.previews_ensure``, and
the preview is readable afterwards: ``Material.preview.image_size`` is 128×128 and
``image_pixels_float`` holds the displayed 8-bit image (checked with bpy 4.2.23, 4.5.15, 5.0.1 and
5.2.3). The frame the engine hands to Blender is also captured at ``engine.render_converted``.
Checks: the Diffuse pass is ``kd · Σ (light colour · n·l)`` with white preview lights, so its
red/green ratio on every lit pixel is the Base Color's, 0.8/0.1 = 8 (Principled → Blinn-Phong:
``kd = base_color`` for a dielectric; ``addon/mapping.py``); and the preview Blender stores is that
frame through the scene's view transform, as Blender's own ``save_render`` to an 8-bit PNG
displays it (within one 8-bit step), the right way up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from addon_testing import run_bpy

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]


def test_material_preview_is_rendered_by_the_engine(tmp_path: Path) -> None:
    got = run_bpy(
        """
import sys
import bpy
import numpy as np
from addon import engine, properties
properties.register()
engine.register()
frames = []
original = engine.render_converted
def capture(converted, progress=None):
    result = original(converted, progress)
    is_material = any(name.startswith("preview_sphere/") for name in converted.mesh_names)
    frames.append((converted.region_size, result.passes["diffuse"], result.rgba, is_material))
    return result
engine.render_converted = capture
try:
    bpy.context.scene.render.engine = engine.ENGINE_ID
    material = bpy.data.materials["Material"]  # the start-up cube's material (a used material)
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.8, 0.1, 0.05, 1.0)
    material.preview_ensure()
    bpy.ops.wm.previews_ensure()
    # The job renders the previews of the world, the light and the material (32² icon, 128² preview).
    big = [f for f in frames if f[0] == (128, 128) and f[3]]
    np.save(sys.argv[1] + "/diffuse.npy", big[0][1])
    np.save(sys.argv[1] + "/rgba.npy", big[0][2])
    # The stored preview (bottom row first) against Blender's display of the captured frame.
    width, height = material.preview.image_size
    preview = np.array(material.preview.image_pixels_float[:], np.float32).reshape(height, width, 4)
    frame = bpy.data.images.new("frame", 128, 128, alpha=True, float_buffer=True)
    frame.pixels.foreach_set(np.ascontiguousarray(big[-1][2][::-1]).ravel())
    output = bpy.context.scene.render.image_settings
    output.file_format, output.color_depth, output.color_mode = "PNG", "8", "RGBA"
    frame.save_render(sys.argv[1] + "/displayed.png", scene=bpy.context.scene)
    displayed = np.empty(128 * 128 * 4, np.float32)
    bpy.data.images.load(sys.argv[1] + "/displayed.png").pixels.foreach_get(displayed)
    displayed = displayed.reshape(128, 128, 4)
    np.save(sys.argv[1] + "/preview.npy", preview)
    np.save(sys.argv[1] + "/displayed.npy", displayed)
    emit({"sizes": sorted({tuple(f[0]) for f in frames}), "preview": {k: engine.LAST_PREVIEW.get(k)
          for k in ("ok", "error", "size")}, "engine": engine.LAST_PREVIEW["choices"]["engine"],
          "last_render": dict(engine.LAST_RENDER)})
finally:
    engine.render_converted = original
    bpy.context.scene.render.engine = "CYCLES"
    engine.unregister()
    properties.unregister()
""",
        tmp_path,
        args=(str(tmp_path),),
    )
    assert got["preview"]["ok"] and got["preview"]["size"] == [128, 128], got
    assert [32, 32] in got["sizes"] and [128, 128] in got["sizes"]  # icon and preview
    assert got["engine"] == "numba"
    assert got["last_render"] == {}  # previews do not replace the last render's report
    diffuse = np.load(tmp_path / "diffuse.npy")
    rgba = np.load(tmp_path / "rgba.npy")
    assert rgba.shape == (128, 128, 4) and np.isfinite(rgba).all()
    lit = diffuse[..., 1] > 1e-3
    assert lit.sum() > 500  # the preview object covers a good part of the image
    # Only pixels where the red object is the sole contributor: R/G = 8 exactly (float32 rounding).
    ratio = diffuse[..., 0][lit] / diffuse[..., 1][lit]
    assert np.count_nonzero(np.abs(ratio - 8.0) < 1e-4) > 500
    # The preview Blender keeps is the engine's frame as displayed: equal to Blender's own view
    # transform of the frame within one 8-bit step (rounding), and not upside down.
    preview = np.load(tmp_path / "preview.npy")
    displayed = np.load(tmp_path / "displayed.npy")
    assert preview.shape == (128, 128, 4)
    assert np.abs(preview - displayed).max() <= 1.0 / 255 + 1e-6
    assert np.abs(preview - displayed[::-1]).max() > 0.1
