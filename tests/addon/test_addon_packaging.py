"""The extension zip: built, checked by Blender's own validator, installed into bpy as a user would."""

from __future__ import annotations

import ast
import importlib.util
import shutil
import sys
import zipfile
from pathlib import Path

import pytest
from addon_testing import REPO, run_bpy

sys.path.insert(0, str(REPO / "tools"))
build_extension = importlib.import_module("build_extension")


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The extension zip, built once per module into a temporary directory."""
    root = tmp_path_factory.mktemp("extension")
    return build_extension.build(root / "dist", build_dir=root / "stage")


def test_relativize_rewrites_every_absolute_core_import() -> None:
    source = (
        "import numpy as np\n"
        "import compositing\n"
        "import compositing.factors as cf\n"
        "from blinn_phong._checks import number\n"
        "from compositing.factors import (\n    FACTORS,\n)\n"
        "def f():\n    from blinn_phong import scene\n    return scene\n"
    )
    got = build_extension.relativize_imports(source, depth=1)
    assert got == (
        "import numpy as np\n"
        "from .. import compositing\n"
        "from ..compositing import factors as cf\n"
        "from ..blinn_phong._checks import number\n"
        "from ..compositing.factors import (\n    FACTORS,\n)\n"
        "def f():\n    from ..blinn_phong import scene\n    return scene\n"
    )
    ast.parse(got)


def test_relativize_refuses_a_form_without_relative_equivalent() -> None:
    with pytest.raises(build_extension.BuildError, match=r"import compositing\.factors"):
        build_extension.relativize_imports("import compositing.factors\n", depth=1)


def test_zip_layout_and_no_absolute_core_imports(built_zip: Path) -> None:
    with zipfile.ZipFile(built_zip) as zf:
        names = set(zf.namelist())
        assert {
            "blender_manifest.toml",
            "__init__.py",
            "mapping.py",
            "blinn_phong/__init__.py",
            "compositing/__init__.py",
        } <= names
        assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
        for name in (n for n in names if n.endswith(".py")):
            tree = ast.parse(zf.read(name).decode("utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.level == 0:
                    assert node.module.split(".")[0] not in ("blinn_phong", "compositing", "addon"), (
                        name,
                        node.module,
                    )
                if isinstance(node, ast.Import):
                    tops = {a.name.split(".")[0] for a in node.names}
                    assert not tops & {"blinn_phong", "compositing", "addon"}, (name, tops)


def test_blender_validator_rejects_a_bad_manifest(tmp_path: Path) -> None:
    # The validator is really consulted: an unknown tag must fail the build.
    stage = tmp_path / "bad"
    shutil.copytree(REPO / "addon", stage, ignore=shutil.ignore_patterns("__pycache__"))
    manifest = stage / "blender_manifest.toml"
    manifest.write_text(manifest.read_text().replace('"Compositing"]', '"Not A Real Tag"]'))
    with pytest.raises(build_extension.BuildError, match="Not A Real Tag"):
        build_extension.run_blender_ext(build_extension.find_bpy_root(), "validate", str(stage))


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_install_zip_into_bpy_as_a_user(built_zip: Path, tmp_path: Path) -> None:
    got = run_bpy(
        """
        import importlib, pathlib, sys
        import bpy
        zip_path, repo_dir = sys.argv[1], sys.argv[2]
        prefs = bpy.context.preferences
        prefs.extensions.repos.new(name="Test", module="test_repo", custom_directory=repo_dir, source="USER")
        result = bpy.ops.extensions.package_install_files(repo="test_repo", filepath=zip_path,
                                                          enable_on_install=True)
        import addon_utils
        enabled = list(addon_utils.check("bl_ext.test_repo.blinn_phong_render"))
        operators = [hasattr(bpy.ops.blinn_phong, n) for n in ("verify_composite", "copy_derived_material")]
        pkg = "bl_ext.test_repo.blinn_phong_render"
        installed = pathlib.Path(repo_dir) / "blinn_phong_render"
        imported = []
        for path in sorted(installed.rglob("*.py")):
            parts = path.relative_to(installed).with_suffix("").parts
            name = ".".join((pkg, *parts[:-1])) if parts[-1] == "__init__" else ".".join((pkg, *parts))
            importlib.import_module(name)
            imported.append(name)
        mapping = importlib.import_module(pkg + ".mapping")
        # The installed engine renders Blender's start-up scene (cube, camera, light).
        scene = bpy.context.scene
        scene.render.engine = "BLINN_PHONG"
        scene.render.resolution_percentage = 10
        scene.render.film_transparent = True
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.filepath = sys.argv[3]
        bpy.ops.render.render(write_still=True)
        last = dict(importlib.import_module(pkg + ".engine").LAST_RENDER)
        addon_utils.disable(pkg)
        emit({
            "result": sorted(result),
            "enabled": enabled,
            "operators": operators,
            "render_ok": last.get("ok"),
            "imported": imported,
            "ortho_module": mapping.orthographic_matrix.__module__,
            "top_level_loaded": sorted({"blinn_phong", "compositing", "addon"} & set(sys.modules)),
        })
        """,
        tmp_path,
        args=(str(built_zip), str(tmp_path / "repo"), str(tmp_path / "installed.exr")),
    )
    assert got["result"] == ["FINISHED"]
    assert got["enabled"] == [True, True]  # (loaded by default, loaded now)
    assert got["render_ok"] is True
    assert got["operators"] == [True, True]  # the add-on registers the panels' and the Verify operators
    from compositing.io import read_image

    image = read_image(tmp_path / "installed.exr")
    assert image.shape == (108, 192, 4) and 0.05 < image[..., 3].mean() < 0.9  # 10 % of 1920×1080
    pkg = "bl_ext.test_repo.blinn_phong_render"
    assert {pkg, pkg + ".mapping", pkg + ".blinn_phong.scene", pkg + ".compositing.factors"} <= set(
        got["imported"]
    )
    assert got["ortho_module"] == pkg + ".blinn_phong.scene"
    assert got["top_level_loaded"] == []


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_loads_the_legacy_way_from_scripts_addons(built_zip: Path, tmp_path: Path) -> None:
    # Unzipped into <user scripts>/addons, the same package enables as a legacy add-on.
    addons = tmp_path / "scripts" / "addons"
    with zipfile.ZipFile(built_zip) as zf:
        zf.extractall(addons / "blinn_phong_render")
    got = run_bpy(
        """
        import importlib, sys
        import bpy
        import addon_utils
        module = addon_utils.enable("blinn_phong_render", default_set=True, handle_error=print)
        state = list(addon_utils.check("blinn_phong_render"))
        scene_module = importlib.import_module("blinn_phong_render.blinn_phong.scene").__name__
        addon_utils.disable("blinn_phong_render")
        emit({"file": module.__file__, "state": state, "scene_module": scene_module,
              "top_level_loaded": sorted({"blinn_phong", "compositing", "addon"} & set(sys.modules))})
        """,
        tmp_path,
        env={"BLENDER_USER_SCRIPTS": str(tmp_path / "scripts")},
    )
    assert Path(got["file"]).is_relative_to(addons)
    assert got["state"] == [True, True]
    assert got["scene_module"] == "blinn_phong_render.blinn_phong.scene"
    assert got["top_level_loaded"] == []


def test_build_stages_outside_the_checkout(tmp_path: Path) -> None:
    # The default staging directory is temporary: building leaves the repository as it was (a
    # read-only checkout builds), and the manifest in the checkout lists no wheels.
    before = sorted(p.name for p in REPO.iterdir())
    zip_path = build_extension.build(tmp_path / "dist")
    assert zip_path.parent == tmp_path / "dist" and zip_path.exists()
    assert sorted(p.name for p in REPO.iterdir()) == before
    assert "wheels" not in (REPO / "addon" / "blender_manifest.toml").read_text()


def test_wheel_list_and_platforms_are_written_into_the_staged_manifest(tmp_path: Path) -> None:
    stage = tmp_path / "stage"
    shutil.copytree(REPO / "addon", stage, ignore=shutil.ignore_patterns("__pycache__"))
    wheel = tmp_path / "numba-0.68.1-cp311-cp311-manylinux_2_28_x86_64.whl"
    wheel.write_bytes(b"not a real wheel")
    build_extension.add_wheels(stage, [wheel], ["linux-x64"])
    import tomllib

    manifest = tomllib.loads((stage / "blender_manifest.toml").read_text())
    assert manifest["platforms"] == ["linux-x64"]
    assert manifest["wheels"] == ["./wheels/numba-0.68.1-cp311-cp311-manylinux_2_28_x86_64.whl"]
    assert manifest["permissions"]["files"]  # the tables after the new fields are intact
    assert (stage / "wheels" / wheel.name).read_bytes() == b"not a real wheel"
    pins = build_extension.pinned_versions()
    assert set(pins) == set(build_extension.WHEEL_PACKAGES) and "numpy" not in pins
