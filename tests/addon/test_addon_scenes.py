"""The bundled sample scenes: rendered by the engine inside Blender, compared with the core pipeline.

One Blender process renders every committed scene in ``blend_files/`` (at 50 %, the compositing
scene at 100 % to match its backplate) and, in the same process, converts the same depsgraph and
renders it with ``addon.pipeline`` (the core renderer): the file Blender writes must hold the same
pixels. The compositing scene is also composited by Blender's own Alpha Over node and compared with
``compositing.composite``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from addon_testing import REPO, run_bpy

from compositing import composite
from compositing.io import read_image

pytestmark = [pytest.mark.blender, pytest.mark.timeout(400)]

SCENES = ("showcase", "transparency", "shadows", "compositing", "passes")

RENDER_ALL = """
import sys
from pathlib import Path
import bpy
import numpy as np
from addon import convert, engine, properties

properties.register()
engine.register()
out = Path(sys.argv[1])
facts = {}
try:
    for name in ("showcase", "transparency", "shadows", "compositing", "passes"):
        bpy.ops.wm.open_mainfile(filepath=str(Path(sys.argv[2]) / f"{name}.blend"), load_ui=False)
        scene = bpy.context.scene
        scene.render.resolution_percentage = 100 if name in ("compositing", "passes") else 50
        settings = scene.render.image_settings
        settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
        use_compositing = scene.render.use_compositing
        scene.render.use_compositing = False
        scene.render.filepath = str(out / f"{name}.exr")
        bpy.ops.render.render(write_still=True)
        last = dict(engine.LAST_RENDER)
        converted = convert.scene_from_depsgraph(bpy.context.evaluated_depsgraph_get())
        core = engine.render_converted(
            converted, cryptomatte=engine.cryptomatte_request(bpy.context.view_layer, converted)
        )
        np.save(out / f"{name}_core.npy", core.rgba)
        np.save(out / f"{name}_shadow.npy", core.passes["shadow"])
        if name in ("compositing", "passes"):
            scene.render.use_compositing = use_compositing
            scene.render.filepath = str(out / f"{name}_blender_over.exr")
            bpy.ops.render.render(write_still=True)
        facts[name] = {
            "engine": scene.render.engine, "ok": last["ok"], "error": last["error"],
            "choices": last["choices"], "meshes": len(converted.scene.meshes),
            "lights": [type(l).__name__ for l in converted.scene.lights], "names": converted.mesh_names,
            "holdouts": [n for n, m in zip(converted.mesh_names, converted.scene.meshes) if m.holdout],
            "links": None if converted.scene.light_links is None else [
                None if l is None or l.receivers is None else l.receivers.tolist()
                for l in converted.scene.light_links
            ],
            "crypto": sorted(k for k in core.passes if k.startswith("Crypto")),
        }
finally:
    engine.unregister()
    properties.unregister()
emit(facts)
"""


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("scenes")
    facts = run_bpy(RENDER_ALL, out, args=(str(out), str(REPO / "blend_files")), timeout=300)
    return out, facts


@pytest.mark.parametrize("name", SCENES)
def test_engine_matches_core_renderer(rendered: tuple[Path, dict], name: str) -> None:
    out, facts = rendered
    assert facts[name]["engine"] == "BLINN_PHONG" and facts[name]["ok"] is True, facts[name]
    blender = read_image(out / f"{name}.exr")
    core = np.load(out / f"{name}_core.npy")
    assert blender.shape == core.shape
    assert 0.05 < blender[..., 3].mean() <= 1.0
    np.testing.assert_allclose(blender, core, atol=2e-5)


def test_showcase_content(rendered: tuple[Path, dict]) -> None:
    facts = rendered[1]["showcase"]
    assert facts["meshes"] == 8
    assert sorted(facts["lights"]) == ["DirectionalLight", "PointLight", "SpotLight"]
    materials = sorted(name.split("/", 1)[1] for name in facts["names"])
    assert materials == sorted(
        ["Flat shading", "Gouraud shading", "Phong shading"]
        + [f"Shininess {s}" for s in (4, 16, 64, 256, 1024)]
    )


def test_transparency_scene_uses_an_exact_method_for_interpenetrating_glass(
    rendered: tuple[Path, dict],
) -> None:
    choices = rendered[1]["transparency"]["choices"]
    assert choices["transparency"] == "a_buffer"
    assert any("interpenetrate" in reason for reason in choices["reasons"])


def test_shadows_scene_has_shadows(rendered: tuple[Path, dict]) -> None:
    out, facts = rendered
    choices = facts["shadows"]["choices"]
    assert (
        set(choices["shadows"]) <= {"ray_traced", "planar", "shadow_map", "shadow_volume"}
        and choices["shadows"]
    )
    shadow = np.load(out / "shadows_shadow.npy")[..., 0]
    covered = read_image(out / "shadows.exr")[..., 3] == 1
    # Shadow = mean visibility over the two lights: <= 0.5 where at least one light is blocked.
    assert (shadow[covered] <= 0.5).mean() > 0.02


def test_compositing_scene_blender_alpha_over_equals_our_src_over(rendered: tuple[Path, dict]) -> None:
    out, _ = rendered
    render = read_image(out / "compositing.exr")
    backplate = read_image(REPO / "blend_files" / "images" / "backplate.exr")
    ours = composite(render, backplate, "src_over")
    blender = read_image(out / "compositing_blender_over.exr")
    assert blender.shape == ours.shape == (180, 320, 4)
    np.testing.assert_allclose(blender, ours, atol=1e-5)


def test_passes_scene_holds_out_links_and_picks(rendered: tuple[Path, dict]) -> None:
    """The holdout card makes a hole the compositor fills with the backplate; the rim light is
    linked to the ball alone; Cryptomatte passes are rendered."""
    out, facts = rendered
    passes = facts["passes"]
    assert passes["holdouts"] == ["Holdout card/Holdout"]
    ball = passes["names"].index("Ball/Paint")
    rim = passes["lights"].index("PointLight")
    assert passes["links"][rim] == [i == ball for i in range(len(passes["names"]))]
    assert passes["crypto"] == ["CryptoObject00", "CryptoObject01", "CryptoObject02"]
    render = read_image(out / "passes.exr")
    hole = render[..., 3] == 0  # the sky, and the card in front of the floor and the cone
    assert render[170:, :, 3].min() == 1.0  # the floor covers the bottom rows
    assert 0.02 < hole[110:].mean() < 0.3  # but for the card's hole
    backplate = read_image(REPO / "blend_files" / "images" / "backplate.exr")
    blender = read_image(out / "passes_blender_over.exr")
    np.testing.assert_allclose(blender, composite(render, backplate, "src_over"), atol=1e-5)
    np.testing.assert_allclose(blender[hole], backplate[hole], atol=1e-5)


def test_generator_rebuilds_the_scenes(tmp_path: Path) -> None:
    got = run_bpy(
        f"""
        import runpy, sys
        from pathlib import Path
        sys.argv = ["make_scenes.py", "--out", {str(tmp_path / "scenes")!r}]
        try:
            runpy.run_path({str(REPO / "blend_files" / "make_scenes.py")!r}, run_name="__main__")
        except SystemExit as done:
            assert done.code == 0, done.code
        emit(sorted(p.name for p in Path({str(tmp_path / "scenes")!r}).rglob("*") if p.is_file()))
        """,
        tmp_path,
    )
    assert got == [
        "backplate.exr",
        "compositing.blend",
        "fence.png",
        "floor_checker.png",
        "passes.blend",
        "shadows.blend",
        "showcase.blend",
        "textures.blend",
        "transparency.blend",
    ]
