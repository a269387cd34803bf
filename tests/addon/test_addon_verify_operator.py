"""The "Verify Against Blender" operator, run inside Blender on a real render."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from addon_testing import REPO, run_bpy

from compositing import composite
from compositing.io import read_image

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

SCRIPT = """
import sys
from pathlib import Path
import bpy
from addon import engine, properties, verify_operator

properties.register()
engine.register()
verify_operator.register()
try:
    bpy.ops.wm.open_mainfile(filepath=sys.argv[1], load_ui=False)
    scene = bpy.context.scene
    scene.render.use_compositing = False
    bpy.ops.render.render()
    scene.blinn_phong.verify_background = bpy.data.images.load(sys.argv[2])
    status = bpy.ops.blinn_phong.verify_composite()
    last = dict(verify_operator.LAST_VERIFY)
    for key, path in last["files"].items():  # Blender's temp directory goes away at exit: keep copies
        last["files"][key] = str(Path(sys.argv[3]) / Path(path).name)
        Path(last["files"][key]).write_bytes(Path(path).read_bytes())
    difference = bpy.data.images.get(verify_operator.DIFFERENCE_IMAGE)
    emit({"status": sorted(status), "last": last, "difference_size": list(difference.size),
          "scenes": [s.name for s in bpy.data.scenes]})
finally:
    verify_operator.unregister()
    engine.unregister()
    properties.unregister()
"""


def test_verify_operator_compares_with_blender_alpha_over(tmp_path: Path) -> None:
    blend = REPO / "blend_files" / "compositing.blend"
    plate_path = REPO / "blend_files" / "images" / "backplate.exr"
    got = run_bpy(SCRIPT, tmp_path, args=(str(blend), str(plate_path), str(tmp_path)))
    assert got["status"] == ["FINISHED"]
    last = got["last"]
    assert last["operator"] == "src_over" and last["max_abs_error"] <= 1e-5
    assert got["difference_size"] == [320, 180]
    assert got["scenes"] == ["Compositing"]  # the throw-away scene is gone
    # Blender's composite is src_over of the saved render over the backplate (Porter-Duff).
    render = read_image(last["files"]["render"])
    assert render[..., 3].max() == 1.0 and render[..., 3].min() == 0.0
    expected = composite(render, read_image(plate_path), "src_over")
    np.testing.assert_allclose(read_image(last["files"]["blender"]), expected, atol=1e-5)
    np.testing.assert_allclose(read_image(last["files"]["ours"]), expected, atol=1e-7)
