"""The extension zip: built, checked by Blender's own validator, installed into bpy as a user would."""

from __future__ import annotations

import ast
import importlib.metadata
import importlib.util
import re
import shutil
import sys
import tomllib
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
        timeout=280,  # the kernels compile into the fresh extension's cache: ~60 s alone, more under load
    )
    assert got["result"] == ["FINISHED"]
    assert got["enabled"] == [True, True]  # (loaded by default, loaded now)
    assert got["render_ok"] is True
    assert got["operators"] == [True, True]  # the add-on registers the panels' and the Verify operators
    from compositing.io import read_image

    image = read_image(tmp_path / "installed.exr")
    assert image.shape == (108, 192, 4) and 0.05 < image[..., 3].mean() < 0.9  # 10 % of 1920×1080
    pkg = "bl_ext.test_repo.blinn_phong_render"
    assert {pkg, pkg + ".mapping", pkg + ".blinn_phong.model.scene", pkg + ".compositing.factors"} <= set(
        got["imported"]
    )
    assert got["ortho_module"] == pkg + ".blinn_phong.model.transforms"
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
        scene_module = importlib.import_module("blinn_phong_render.blinn_phong.model.scene").__name__
        addon_utils.disable("blinn_phong_render")
        emit({"file": module.__file__, "state": state, "scene_module": scene_module,
              "top_level_loaded": sorted({"blinn_phong", "compositing", "addon"} & set(sys.modules))})
        """,
        tmp_path,
        env={"BLENDER_USER_SCRIPTS": str(tmp_path / "scripts")},
    )
    assert Path(got["file"]).is_relative_to(addons)
    assert got["state"] == [True, True]
    assert got["scene_module"] == "blinn_phong_render.blinn_phong.model.scene"
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
    manifest = tomllib.loads((stage / "blender_manifest.toml").read_text())
    assert manifest["platforms"] == ["linux-x64"]
    assert manifest["wheels"] == ["./wheels/numba-0.68.1-cp311-cp311-manylinux_2_28_x86_64.whl"]
    assert manifest["permissions"]["files"]  # the tables after the new fields are intact
    assert (stage / "wheels" / wheel.name).read_bytes() == b"not a real wheel"
    pins = build_extension.pinned_versions()
    assert set(pins) == set(build_extension.WHEEL_PACKAGES) and "numpy" not in pins


BLENDER_MODULES = {"bpy", "gpu", "gpu_extras", "numpy"}
"""What every Blender's Python provides (numpy included: 1.26 in 4.2–5.0, 2.x in 5.1+)."""


def test_bundled_wheels_are_what_the_zip_imports_from_outside_blender(built_zip: Path) -> None:
    # Every absolute import of every module in the zip, lazy ones included: what is neither the
    # standard library nor Blender's must be bundled or listed as deliberately left out.
    imported: set[str] = set()
    with zipfile.ZipFile(built_zip) as zf:
        for name in (n for n in zf.namelist() if n.endswith(".py")):
            for node in ast.walk(ast.parse(zf.read(name).decode("utf-8"))):
                if isinstance(node, ast.Import):
                    imported |= {a.name.split(".")[0] for a in node.names}
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    imported.add(node.module.split(".")[0])
    outside = imported - set(sys.stdlib_module_names) - BLENDER_MODULES
    bundled = set(build_extension.WHEEL_PACKAGES)  # distribution names = module names for these four
    assert outside - set(build_extension.NOT_BUNDLED) <= bundled  # nothing the zip needs is missing
    assert set(build_extension.NOT_BUNDLED) <= outside  # no stale entry
    # Nothing is bundled for nothing: each wheel is imported, or required by one that is (its metadata).
    used = outside & bundled
    for name in bundled - used:
        requires = {
            re.match(r"[A-Za-z0-9_.\-]+", r).group(0).lower()
            for u in used
            for r in importlib.metadata.requires(u) or []
        }
        assert name in requires, (name, sorted(used))
    assert {"numba", "embreex", "scipy"} <= used


def _blender_ext_module():
    """Blender's extension CLI (``bl_pkg/cli/blender_ext.py``) as a module, for its own filter."""
    path = build_extension.find_bpy_root() / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    spec = importlib.util.spec_from_file_location("blender_ext_cli", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_each_zip_is_accepted_by_exactly_the_blender_versions_of_its_python(tmp_path: Path) -> None:
    # Blender's own compatibility filter (the one "Install from Disk" applies) on each target's
    # staged manifest: 4.2-5.0 (CPython 3.11) and 5.1+ (3.13) split every version between them.
    cli = _blender_ext_module()
    manifests = {}
    for target in build_extension.TARGETS:
        stage = tmp_path / target.label
        shutil.copytree(REPO / "addon", stage, ignore=shutil.ignore_patterns("__pycache__"))
        build_extension.set_blender_versions(stage, target)
        build_extension.run_blender_ext(build_extension.find_bpy_root(), "validate", str(stage))
        manifests[target.python] = tomllib.loads((stage / "blender_manifest.toml").read_text())

    def accepts(manifest: dict, version: tuple[int, int, int]) -> bool:
        def error(exception: Exception) -> None:
            raise exception

        return not cli.repository_filter_skip(
            manifest,
            filter_blender_version=version,
            filter_platform="linux-x64",
            filter_python_version=(0, 0, 0),
            skip_message_fn=lambda message: None,
            error_fn=error,
        )

    expected = {
        (4, 1, 99): set(),
        (4, 2, 0): {"3.11"},
        (4, 5, 15): {"3.11"},
        (5, 0, 99): {"3.11"},
        (5, 1, 0): {"3.13"},  # blender_version_max = 5.1.0 is exclusive
        (5, 2, 3): {"3.13"},
        (6, 0, 0): {"3.13"},
    }
    for version, pythons in expected.items():
        assert {p for p, m in manifests.items() if accepts(m, version)} == pythons, version
        if pythons:
            assert build_extension.target_for_blender(version).python in pythons
        else:
            with pytest.raises(build_extension.BuildError, match="not supported"):
                build_extension.target_for_blender(version)
    # The running Blender embeds the Python its target names (this bpy runs on this interpreter).
    bpy_version = tuple(int(p) for p in importlib.metadata.version("bpy").split(".")[:3])
    assert build_extension.target_for_blender(bpy_version).python == "{}.{}".format(*sys.version_info)


def test_a_manifest_range_outside_a_target_is_refused(tmp_path: Path) -> None:
    stage = tmp_path / "stage"
    shutil.copytree(REPO / "addon", stage, ignore=shutil.ignore_patterns("__pycache__"))
    manifest = stage / "blender_manifest.toml"
    text = manifest.read_text().replace('blender_version_min = "4.2.0"', 'blender_version_min = "5.1.0"')
    manifest.write_text(text)
    parsed = tomllib.loads(manifest.read_text())
    assert build_extension.targets_for(parsed) == [build_extension.TARGETS[1]]
    with pytest.raises(build_extension.BuildError, match="does not meet"):
        build_extension.set_blender_versions(stage, build_extension.TARGETS[0])


def test_zip_names_say_blender_python_and_platform() -> None:
    manifest = {"id": "blinn_phong_render", "version": "0.1.0"}
    names = [build_extension.zip_name(manifest, t, "linux-x64") for t in build_extension.TARGETS]
    assert names == [
        "blinn_phong_render-0.1.0-blender4.2-5.0-python3.11-linux_x64.zip",
        "blinn_phong_render-0.1.0-blender5.1+-python3.13-linux_x64.zip",
    ]
