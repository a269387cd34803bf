"""The main job (``python -m addon.demo``) end to end."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from addon_testing import REPO

from compositing import composite
from compositing.io import read_image


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_demo_renders_composites_and_agrees_with_blender(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    env = dict(os.environ, PYTHONPATH=str(REPO), BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    done = subprocess.run(
        [sys.executable, "-m", "addon.demo", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=240,
        cwd=str(REPO),
        env=env,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "ours vs Blender max error" in done.stdout
    results = json.loads((out / "results.json").read_text())
    assert results["size"] == [320, 180]
    assert results["engine_vs_core_max_abs_error"] <= 1e-5
    assert results["composite_max_abs_error"] <= 1e-5
    # The written composite is src_over of the written render over the bundled backplate.
    render = read_image(out / "render.exr")
    backplate = read_image(REPO / "blend_files" / "images" / "backplate.exr")
    np.testing.assert_allclose(
        read_image(out / "composite_ours.exr"), composite(render, backplate), atol=1e-6
    )
    np.testing.assert_allclose(
        read_image(out / "composite_blender.exr"), composite(render, backplate), atol=1e-5
    )
    for name in ("render.png", "composite_ours.png", "composite_blender.png", "difference.exr"):
        assert (out / name).stat().st_size > 0
    # The textured sample scene: both textures found, the engine's file = the core pipeline.
    textures = results["textures"]
    assert "textured scene" in done.stdout
    assert sorted(n.split("/", 1)[1] for n in textures["textured_meshes"]) == ["Checker floor", "Fence"]
    assert textures["engine_vs_core_max_abs_error"] <= 1e-5
    assert textures["shadows"]
    textured = read_image(out / "textures" / "render.exr")
    assert textured.shape == (180, 320, 4) and 0.3 < textured[..., 3].mean() < 1.0
