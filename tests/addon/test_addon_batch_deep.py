"""Deep EXR output of the batch (``--deep``) and of the engine (Render Properties › Deep Output).

Oracles: OpenImageIO reads every deep file back (``compositing.deep_io.read_deep``), and its
flatten (OpenEXR's "Interpreting Deep Pixels": the samples composited front to back with
``over``) must equal the flat frame Blender saved from the same render — one sample per pixel
and the A-buffer, where the two are the same sum (``tests/compositing/test_deep_render.py``).
A full disk is a file-size limit on the writing process (as in ``test_addon_batch_faults``).
"""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from addon_testing import REPO, run_bpy

from addon.batch import build_parser, read_back
from compositing.deep import flatten, from_flat
from compositing.deep_io import read_deep, write_deep
from compositing.io import read_image

pytestmark = [pytest.mark.blender, pytest.mark.timeout(400)]

# A glass sphere (Principled Alpha 0.5) in front of an opaque one, 64×48, one sample per pixel,
# the A-buffer, Film › Transparent; argv[1] writes 32-bit EXR to "glass_####" (under --out),
# argv[2] the same with Transparency Auto, argv[3] 8-bit PNG.
SCENE = """
import math, sys
import bpy
from addon import engine, properties
bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
engine.register()
scene = bpy.context.scene
def principled(name, colour, alpha):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    node = mat.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (*colour, 1.0)
    node.inputs["Alpha"].default_value = alpha
    return mat
bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=24, ring_count=12, location=(0.4, 1.0, 0.2))
bpy.context.object.data.materials.append(principled("Solid", (0.8, 0.3, 0.1), 1.0))
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.9, segments=24, ring_count=12, location=(-0.3, -0.5, 0.0))
bpy.context.object.data.materials.append(principled("Glass", (0.2, 0.4, 0.9), 0.5))
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location, cam.rotation_euler = (0, -6, 0), (math.pi / 2, 0, 0)
scene.collection.objects.link(cam)
scene.camera = cam
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.data.energy, sun.rotation_euler = 3.0, (0.5, 0.2, 0.0)
scene.collection.objects.link(sun)
scene.world = None
scene.render.engine = "BLINN_PHONG"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 48, 100
scene.render.film_transparent = True
scene.blinn_phong.samples_per_axis = 1
scene.blinn_phong.shadows = "NONE"
scene.blinn_phong.transparency = "A_BUFFER"
settings = scene.render.image_settings
settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
scene.render.filepath = "glass_####"
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1])
scene.blinn_phong.transparency = "AUTO"
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[2])
scene.blinn_phong.transparency = "A_BUFFER"
settings.file_format, settings.color_depth = "PNG", "8"
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[3])
scene.render.engine = "CYCLES"
engine.unregister()
properties.unregister()
emit(True)
"""

ENV = dict(os.environ, PYTHONPATH=str(REPO))


@pytest.fixture(scope="module")
def blends(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("deep")
    files = {name: root / f"{name}.blend" for name in ("glass", "auto", "png")}
    run_bpy(SCENE, root, args=tuple(str(p) for p in files.values()))
    return files


def _limit_file_size(limit: int):
    def limit_size() -> None:  # in the child: writes past `limit` bytes fail with EFBIG
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return limit_size


def _batch(*args: str, limit: int | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "addon.batch", *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=ENV,
        cwd=str(REPO),
        check=False,
        preexec_fn=_limit_file_size(limit) if limit else None,
    )


def _report(out: Path) -> dict:
    return json.loads((out / "report.json").read_text())


def _files(root: Path) -> list[str]:
    return sorted(
        str(p.relative_to(root))
        for p in root.rglob("*")
        if p.is_file() and p.relative_to(root).parts[0] != "reports"
    )


def test_batch_deep_writes_a_deep_exr_whose_flatten_is_the_frame(
    blends: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "out"
    done = _batch(str(blends["glass"]), "--frames", "1-2", "--out", str(out), "--deep")
    assert done.returncode == 0, done.stdout + done.stderr
    report = _report(out)
    for frame in (1, 2):
        flat_path, deep_path = out / f"glass_{frame:04d}.exr", out / f"glass_{frame:04d}.deep.exr"
        task = report["tasks"][frame - 1]
        assert task["outputs"]["deep"] == str(deep_path)
        assert str(deep_path) in report["written"] and f"wrote {deep_path}" in done.stdout
        deep = read_deep(deep_path)
        assert deep.shape == (48, 64)
        assert int(deep.counts.max()) >= 2  # glass over the opaque sphere: two fragments
        assert task["deep"] == {"samples": deep.n_samples, "max_per_pixel": int(deep.counts.max())}
        np.testing.assert_allclose(flatten(deep), read_image(flat_path), rtol=0, atol=1e-6)
    assert _files(out) == [
        "glass_0001.deep.exr", "glass_0001.exr", "glass_0002.deep.exr", "glass_0002.exr", "report.json"
    ]  # fmt: skip


def test_batch_deep_is_refused_before_any_render_without_a_depth_order(
    blends: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "out"
    done = _batch(str(blends["auto"]), "--frames", "1", "--out", str(out), "--deep")
    assert done.returncode == 2, done.stdout + done.stderr
    assert f"--deep: {blends['auto']}: scene 'Scene': Transparency is 'Auto'" in done.stderr, done.stderr
    assert "needs Transparency A-Buffer, Depth Peeling or Opaque" in done.stderr
    assert _files(out) == []  # nothing rendered, nothing written


def test_skip_existing_and_placeholders_count_the_deep_file(blends: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = _batch(str(blends["png"]), "--frames", "1,2", "--out", str(out), "--deep")
    assert done.returncode == 0, done.stdout + done.stderr
    kept = {name: (out / name).stat().st_mtime_ns for name in ("glass_0001.png", "glass_0001.deep.exr")}
    # Frame 2's deep file is an empty placeholder left by a crashed run; frame 1 is whole.
    (out / "glass_0002.deep.exr").write_bytes(b"")
    done = _batch(
        str(blends["png"]),
        "--frames",
        "1,2",
        "--out",
        str(out),
        "--deep",
        "--skip-existing",
        "--placeholders",
    )
    assert done.returncode == 0, done.stdout + done.stderr
    report = _report(out)
    assert [s["frame"] for s in report["skipped"]] == [1]
    assert report["skipped"][0]["outputs"] == [str(out / "glass_0001.png"), str(out / "glass_0001.deep.exr")]
    assert [t["task"]["frame"] for t in report["tasks"]] == [2]
    assert all((out / name).stat().st_mtime_ns == t for name, t in kept.items())
    assert read_back(out / "glass_0002.deep.exr", (64, 48))
    np.testing.assert_allclose(
        flatten(read_deep(out / "glass_0002.deep.exr"))[..., 3],
        read_image(out / "glass_0002.png")[..., 3],
        rtol=0,
        atol=0.5 / 255 + 1e-6,  # the PNG's 8-bit alpha
    )
    # Without the deep output the same frames are done: the deep file is not asked for.
    done = _batch(str(blends["png"]), "--frames", "1,2", "--out", str(out), "--skip-existing")
    assert [s["frame"] for s in _report(out)["skipped"]] == [1, 2]


def test_a_failed_deep_write_keeps_the_previous_file(blends: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = _batch(str(blends["png"]), "--frames", "1", "--out", str(out), "--deep")
    assert done.returncode == 0, done.stdout + done.stderr
    frame, deep = out / "glass_0001.png", out / "glass_0001.deep.exr"
    good = deep.read_bytes()
    limit = (frame.stat().st_size + len(good)) // 2
    assert frame.stat().st_size < limit < len(good)  # the frame fits under the limit, the deep file not
    done = _batch(str(blends["png"]), "--frames", "1", "--out", str(out), "--deep", limit=limit)
    assert done.returncode == 1, done.stdout + done.stderr
    error = _report(out)["tasks"][0]["error"]
    assert f"writing {deep} failed, the previous file is kept" in error, error
    assert deep.read_bytes() == good  # byte for byte
    assert _files(out) == ["glass_0001.deep.exr", "glass_0001.png", "report.json"]  # no temporary left


def test_help_names_the_deep_flag_and_the_file_it_writes() -> None:
    text = " ".join(build_parser().format_help().split())
    assert "--deep" in text and "<output without its extension>.deep.exr" in text
    assert "A-Buffer, Depth Peeling or Opaque" in text


def test_read_back_reads_every_sample_of_a_deep_file(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    rgba = rng.uniform(0, 1, (24, 32, 4)).astype(np.float32)
    rgba[..., :3] *= rgba[..., 3:]
    path = tmp_path / "a.deep.exr"
    write_deep(path, from_flat(rgba, 2.0), compression="none")
    assert read_back(path, (32, 24))
    with pytest.raises(OSError, match="expected 31×24"):
        read_back(path, (31, 24))
    path.write_bytes(path.read_bytes()[: path.stat().st_size * 3 // 4])  # cut off, as by a full disk
    with pytest.raises(OSError, match=r"part 0 cannot be decoded"):
        read_back(path, (32, 24))


ENGINE = """
import sys, json
import bpy
from addon import engine, properties, render_ui
properties.register()
engine.register()
render_ui.register()
bpy.ops.wm.open_mainfile(filepath=sys.argv[1], load_ui=False)
out = sys.argv[2]
scene = bpy.context.scene
scene.blinn_phong.deep_output = True
results = {}

class Layout:
    def __init__(self, log):
        self.log, self.use_property_split = log, False
    def prop(self, data, name, **_):
        assert name in data.bl_rna.properties, name
        self.log.append(["prop", name])
    def label(self, text="", **_):
        self.log.append(["label", text])

def draw():
    import types
    log = []
    ctx = types.SimpleNamespace(engine=engine.ENGINE_ID, scene=scene)
    render_ui.BLINN_PHONG_PT_render_output.draw(types.SimpleNamespace(layout=Layout(log)), ctx)
    return log

# F12 with Render > Save: the still and the deep file next to it (//-relative output path).
scene.render.filepath = "//stills/shot_###"
scene.frame_set(2)
results["panel"] = draw()
bpy.ops.render.render(write_still=True)
results["still"] = {"deep_output": engine.LAST_RENDER.get("deep_output"), "ok": engine.LAST_RENDER.get("ok")}
# An animation render: one deep file per frame.
scene.render.filepath = out + "/anim/frame_"
scene.frame_start, scene.frame_end = 1, 2
bpy.ops.render.render(animation=True)
# A render region, Crop off: Blender saves the full frame; the deep file has the region's samples in it.
scene.render.use_border, scene.render.use_crop_to_border = True, False
scene.render.border_min_x, scene.render.border_max_x = 0.25, 0.75
scene.render.border_min_y, scene.render.border_max_y = 0.5, 1.0
scene.render.filepath = out + "/border/frame_"
scene.frame_set(1)
bpy.ops.render.render(write_still=True)
scene.render.use_border = False
# Transparency Auto: the render fails, naming the setting; no deep file.
scene.blinn_phong.transparency = "AUTO"
results["panel_auto"] = draw()
scene.render.filepath = out + "/auto/frame_"
try:
    bpy.ops.render.render(write_still=True)
    results["auto"] = "rendered"
except RuntimeError as error:
    results["auto"] = str(error)
scene.render.engine = "CYCLES"
render_ui.unregister()
engine.unregister()
properties.unregister()
emit(results)
"""


def test_the_engine_writes_the_deep_exr_next_to_each_frame(blends: dict[str, Path], tmp_path: Path) -> None:
    blend = tmp_path / "shot.blend"
    blend.write_bytes(blends["glass"].read_bytes())
    got = run_bpy(ENGINE, tmp_path, args=(str(blend), str(tmp_path)), timeout=300)
    # Blender saves a still without frame numbers ('#' kept); the deep file is named after the frame.
    still, still_deep = tmp_path / "stills" / "shot_###.exr", tmp_path / "stills" / "shot_002.deep.exr"
    assert got["still"] == {"deep_output": str(still_deep), "ok": True}
    assert ["label", str(still_deep)] in got["panel"] and ["prop", "deep_output"] in got["panel"]
    np.testing.assert_allclose(flatten(read_deep(still_deep)), read_image(still), rtol=0, atol=1e-6)
    for frame in (1, 2):
        flat, deep = (
            tmp_path / "anim" / f"frame_{frame:04d}.exr",
            tmp_path / "anim" / f"frame_{frame:04d}.deep.exr",
        )
        np.testing.assert_allclose(flatten(read_deep(deep)), read_image(flat), rtol=0, atol=1e-6)
    border = read_deep(tmp_path / "border" / "frame_0001.deep.exr")
    assert border.shape == (48, 64)
    rows, cols = np.nonzero(border.counts)  # Blender's border y counts from the bottom: the top half
    assert rows.min() >= 0 and rows.max() < 24 and cols.min() >= 16 and cols.max() < 48
    np.testing.assert_allclose(
        flatten(border), read_image(tmp_path / "border" / "frame_.exr"), rtol=0, atol=1e-6
    )
    assert "Deep EXR" in got["auto"] and "Transparency is 'Auto'" in got["auto"], got["auto"]
    assert any(kind == "label" and "Transparency is 'Auto'" in text for kind, text in got["panel_auto"])
    assert not (tmp_path / "auto").exists() or not list((tmp_path / "auto").glob("*.deep.exr"))
