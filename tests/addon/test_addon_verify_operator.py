"""The "Verify Against Blender" operator, run inside Blender on a real render.

The Blender process runs with OpenImageIO and colour-science made unimportable
(``sys.modules[name] = None``), as in the installed extension: Blender 4.2's bpy has no
OpenImageIO and 4.5/5.0 carry it outside ``sys.path``, and the extension bundles no
colour-science. Every file the operator writes is then read here with OpenImageIO
(``compositing.io``), an independent reader.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from addon_testing import REPO, run_bpy

from compositing import composite
from compositing.io import read_image, write_image

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

SCRIPT = """
import sys
from pathlib import Path
for name in ("OpenImageIO", "colour"):  # as in the installed extension: neither is importable
    sys.modules[name] = None
import bpy
from addon import engine, properties, verify_operator

properties.register()
engine.register()
verify_operator.register()
try:
    bpy.ops.wm.open_mainfile(filepath=sys.argv[1], load_ui=False)
    scene = bpy.context.scene
    scene.render.use_compositing = False
    settings = scene.render.image_settings
    settings.file_format, settings.color_depth = "PNG", "8"  # the user's output format, restored after
    bpy.ops.render.render()
    scene.blinn_phong.verify_background = bpy.data.images.load(sys.argv[2], check_existing=False)
    images_before = {i.name for i in bpy.data.images}
    status = bpy.ops.blinn_phong.verify_composite()
    last = dict(verify_operator.LAST_VERIFY)
    for key, path in last.get("files", {}).items():  # Blender's temp directory goes away at exit
        last["files"][key] = str(Path(sys.argv[3]) / Path(path).name)
        Path(last["files"][key]).write_bytes(Path(path).read_bytes())
    difference = bpy.data.images.get(verify_operator.DIFFERENCE_IMAGE)
    emit({"status": sorted(status), "last": last, "difference_size": list(difference.size),
          "scenes": [s.name for s in bpy.data.scenes],
          "new_images": sorted({i.name for i in bpy.data.images} - images_before),
          "output_format": [settings.file_format, settings.color_depth]})
finally:
    verify_operator.unregister()
    engine.unregister()
    properties.unregister()
"""


def _run(background: Path, tmp_path: Path) -> dict:
    blend = REPO / "blend_files" / "compositing.blend"
    got = run_bpy(SCRIPT, tmp_path, args=(str(blend), str(background), str(tmp_path)))
    assert got["status"] == ["FINISHED"], got["last"]
    assert got["difference_size"] == [320, 180]
    assert got["scenes"] == ["Compositing"]  # the throw-away scene is gone
    # No temporary image is left behind (4.5's compositor adds its own "Viewer Node" image).
    assert set(got["new_images"]) - {"Viewer Node"} == {"Blinn-Phong Verify Difference"}
    assert got["output_format"] == ["PNG", "8"]  # the scene's output settings are restored
    return got["last"]


def _check_files(last: dict, plate: np.ndarray) -> None:
    assert last["operator"] == "src_over" and last["max_abs_error"] <= 1e-5
    render = read_image(last["files"]["render"])
    assert render.shape == (180, 320, 4)
    assert render[..., 3].max() == 1.0 and render[..., 3].min() == 0.0
    # Blender's composite is src_over of the saved render over the background (Porter-Duff).
    expected = composite(render, plate, "src_over")
    np.testing.assert_allclose(read_image(last["files"]["blender"]), expected, atol=1e-5)
    # Ours went through Blender's image writer: bit-exact float32 (same kernel on the same arrays).
    np.testing.assert_array_equal(read_image(last["files"]["ours"]), expected)
    difference = np.abs(read_image(last["files"]["blender"]).astype(np.float64) - expected)
    np.testing.assert_array_equal(read_image(last["files"]["difference"]), difference.astype(np.float32))
    assert last["max_abs_error"] == pytest.approx(float(difference.max()), abs=1e-12)


def test_verify_operator_with_an_exr_background_needs_no_openimageio(tmp_path: Path) -> None:
    plate_path = REPO / "blend_files" / "images" / "backplate.exr"
    last = _run(plate_path, tmp_path)
    plate = read_image(plate_path)
    # Blender's loader and writer move the EXR's float values unchanged.
    np.testing.assert_array_equal(read_image(last["files"]["background"]), plate)
    _check_files(last, plate)


def test_verify_operator_decodes_a_png_background_in_blender(tmp_path: Path) -> None:
    # An 8-bit sRGB PNG with straight alpha (opaque, half-transparent and transparent parts),
    # decoded by Blender; the reference decode is colour-science's IEC 61966-2-1 sRGB EOTF,
    # then premultiplied (compositing.io). Blender's OpenColorIO transform agrees to 2.4e-5
    # (measured, 4.2 and 5.0); 1e-4 is below 1 % of one 8-bit code step in linear (8.9e-3 at 1.0,
    # 2.4e-4 near 0.01).
    plate = read_image(REPO / "blend_files" / "images" / "backplate.exr")
    straight = np.clip(plate[..., :3], 0.0, 1.0)
    alpha = np.ones(plate.shape[:2], np.float32)
    alpha[:, 100:200] = 0.5
    alpha[:, 200:220] = 0.0
    png = tmp_path / "backplate.png"
    write_image(png, np.concatenate([straight * alpha[..., None], alpha[..., None]], axis=-1))
    reference = read_image(png)
    last = _run(png, tmp_path)
    decoded = read_image(last["files"]["background"])
    np.testing.assert_allclose(decoded, reference, rtol=0, atol=1e-4)
    np.testing.assert_array_equal(decoded[:, 200:220, 3], 0.0)
    _check_files(last, decoded)
