"""The self-contained extension: built with its wheels, installed into a bpy that has none of them.

Runs on the Blender of the interpreter running pytest (``make test-extension``: 5.0; ``make
test-blender42``, ``test-blender45``, ``test-blender52``: 4.2, 4.5, 5.2). The zips are built by
``tools/build_extension.py --wheels`` (one per Python ABI: Blender 4.2–5.0 / CPython 3.11 and 5.1+ /
3.13; Blender's own ``build --split-platforms`` and ``validate``; wheels downloaded by pip into a
cache outside the checkout). The zip for this Blender is installed with
``bpy.ops.extensions.package_install_files`` into a separate virtual environment holding only the
same ``bpy`` and the numpy its lock file pins (plus bpy's own requirements), run without user
site-packages: numba, embreex and scipy can only come from the extension, and OpenImageIO and
colour-science are not there at all. There the sample scene ``shadows.blend`` is rendered (the
render stats must say the compiled kernels and Embree ran, and the image must equal the
repository's add-on's render on the same Blender), the planner sizes a shadow map with scipy's
convex hull, and "Verify Against Blender" compares a render over ``backplate.exr`` with Blender's
Alpha Over. The zip for the other Python is refused by this Blender (``blender_version_min``/``_max``).

Slow (a 110 MB zip, a bpy-only environment, numba compiling in a fresh cache): marked ``slow`` and
run only when ``BLINN_PHONG_TEST_EXTENSION=1`` (set by the Makefile targets above), so ``make test``
leaves it out. Wheel downloads and the bpy-only environments are cached under
``~/.cache/blinn-phong-render`` (``XDG_CACHE_HOME``) and reused.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import json
import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest
from addon_testing import MARK, REPO, run_bpy

from compositing import composite
from compositing.io import read_image

sys.path.insert(0, str(REPO / "tools"))
build_extension = importlib.import_module("build_extension")

pytestmark = [
    pytest.mark.blender,
    pytest.mark.slow,
    pytest.mark.timeout(1800),
    pytest.mark.skipif(
        os.environ.get("BLINN_PHONG_TEST_EXTENSION") != "1",
        reason="slow: set BLINN_PHONG_TEST_EXTENSION=1 (make test-extension, make test-blender42/45/52)",
    ),
]

PACKAGE = "bl_ext.test_repo.blinn_phong_render"
BPY_VERSION = tuple(int(p) for p in importlib.metadata.version("bpy").split(".")[:3])
PLATFORM = "linux-x64"
MAX_ZIP_BYTES = 150_000_000
"""Download budget per zip."""

INSTALLED = f"""
import importlib, importlib.util, json, os, shutil, sys, time
import bpy
import numpy as np
def emit(obj):
    print({MARK!r} + json.dumps(obj), flush=True)
zip_path, other_zip, repo_dir, blends, out, install = sys.argv[1:7]
shadows_blend, compositing_blend, backplate = blends.split(os.pathsep)
MODULES = ("numba", "embreex", "scipy", "colour", "OpenImageIO")
before = {{name: importlib.util.find_spec(name) is not None for name in MODULES}}
prefs = bpy.context.preferences
prefs.extensions.repos.new(name="Test", module="test_repo", custom_directory=repo_dir, source="USER")
refused = None
if install == "1":
    # The other Python's zip: this Blender is outside its blender_version_min/max. Blender prints
    # why and installs nothing (the operator itself still returns FINISHED).
    bpy.ops.extensions.package_install_files(repo="test_repo", filepath=other_zip, enable_on_install=True)
    refused = sorted(os.listdir(repo_dir))
    result = sorted(bpy.ops.extensions.package_install_files(
        repo="test_repo", filepath=zip_path, enable_on_install=True))
else:
    import addon_utils
    addon_utils.enable({PACKAGE!r}, default_set=True, handle_error=print)
    result = ["ENABLED"]
engine = importlib.import_module({PACKAGE!r} + ".engine")
import numba, embreex, scipy
origins = {{m.__name__: m.__file__ for m in (numba, embreex, scipy)}}
after = {{name: importlib.util.find_spec(name) is not None for name in MODULES}}
bpy.ops.wm.open_mainfile(filepath=shadows_blend, load_ui=False)
scene = bpy.context.scene
scene.render.resolution_percentage = 50
settings = scene.render.image_settings
settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
scene.render.use_compositing = False
renders = []
for i in range(2):
    scene.render.filepath = os.path.join(out, f"installed_{{i}}.exr")
    bpy.ops.render.render(write_still=True)
    renders.append(dict(engine.LAST_RENDER))
cache = bpy.utils.extension_path_user({PACKAGE!r}, path="kernels")
found = {{
    "before": before, "after": after, "refused": refused, "result": result, "origins": origins,
    "user_dir": bpy.utils.extension_path_user({PACKAGE!r}),
    "kernel_cache_dir": os.environ.get("BLINN_PHONG_KERNEL_CACHE"), "cache": cache,
    "numba_cache_dir": numba.config.CACHE_DIR,
    "renders": [{{k: r.get(k) for k in ("ok", "error", "choices", "stats", "status", "seconds", "notes")}}
                for r in renders],
}}
if install == "1":
    # The planner sizes a shadow map by the thinnest caster seen from a directional light, the
    # width of a convex hull (scipy.spatial.ConvexHull): a 0.03-wide slat above a floor, sun above.
    primitives = importlib.import_module({PACKAGE!r} + ".blinn_phong.model.primitives")
    model = importlib.import_module({PACKAGE!r} + ".blinn_phong.model.scene")
    lights = importlib.import_module({PACKAGE!r} + ".blinn_phong.model.lights")
    transforms = importlib.import_module({PACKAGE!r} + ".blinn_phong.model.transforms")
    planner = importlib.import_module({PACKAGE!r} + ".blinn_phong.planning.planner")
    move = np.eye(4)
    move[2, 3] = 0.6
    slat = model.Mesh(*primitives.box((0.015, 1.3, 0.01)), transform=move)
    floor = model.Mesh(*primitives.grid_plane(1, 1, (4.0, 4.0)))
    camera = model.Camera.perspective(
        40.0, 1.0, 0.5, 40.0, view=transforms.look_at((0, -6, 5), (0, 0, 0.5), (0, 0, 1)))
    sun = lights.DirectionalLight((0.0, 0.0, -1.0))
    geometry = planner.shadow_map_geometry(model.Scene((floor, slat), (sun,), camera), 0)
    found["feature"] = geometry.feature
    found["convex_hull_from"] = sys.modules["scipy.spatial"].__file__
    # Verify Against Blender, from the installed extension (no OpenImageIO, no colour-science).
    verify_operator = importlib.import_module({PACKAGE!r} + ".verify_operator")
    bpy.ops.wm.open_mainfile(filepath=compositing_blend, load_ui=False)
    bpy.context.scene.render.use_compositing = False
    bpy.ops.render.render()
    bpy.context.scene.blinn_phong.verify_background = bpy.data.images.load(backplate)
    try:
        status = sorted(bpy.ops.blinn_phong.verify_composite())
    except RuntimeError as error:
        status = str(error)
    last = {{k: v for k, v in verify_operator.LAST_VERIFY.items() if k != "files"}}
    last["files"] = {{}}
    for key, path in verify_operator.LAST_VERIFY.get("files", {{}}).items():
        last["files"][key] = shutil.copy(path, os.path.join(out, "verify_" + os.path.basename(path)))
    found["verify"] = {{"status": status, "last": last}}
emit(found)
"""

REPOSITORY = """
import os, sys
import bpy
from addon import engine, properties
properties.register()
engine.register()
try:
    bpy.ops.wm.open_mainfile(filepath=sys.argv[1], load_ui=False)
    scene = bpy.context.scene
    scene.render.resolution_percentage = 50
    settings = scene.render.image_settings
    settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
    scene.render.use_compositing = False
    renders = []
    for i in range(2):
        scene.render.filepath = os.path.join(sys.argv[2], f"repository_{i}.exr")
        bpy.ops.render.render(write_still=True)
        renders.append({k: engine.LAST_RENDER.get(k) for k in ("ok", "choices", "stats", "seconds")})
finally:
    engine.unregister()
    properties.unregister()
emit(renders)
"""


def _cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "blinn-phong-render"


def _lock_of_this_blender() -> Path:
    """The lock file pinning the running bpy (main.lock: 5.0, blender42/45/52.lock)."""
    version = importlib.metadata.version("bpy")
    for lock in sorted((REPO / "requirements").glob("*.lock")):
        if f"\nbpy=={version}\n" in lock.read_text(encoding="utf-8"):
            return lock
    raise AssertionError(f"no requirements/*.lock pins bpy=={version}")


def _bpy_only_python() -> Path:
    """A virtual environment with only this bpy, its pinned numpy and bpy's own requirements (cached)."""
    lock = _lock_of_this_blender()
    versions = build_extension.pinned_versions(("bpy", "numpy"), lock=lock)
    python_version = f"{sys.version_info[0]}.{sys.version_info[1]}"
    venv = _cache_root() / f"venv-bpy-{versions['bpy']}-numpy-{versions['numpy']}-py{python_version}"
    python = venv / "bin" / "python"
    if not (venv / ".complete").exists():
        subprocess.run([sys.executable, "-m", "venv", "--clear", str(venv)], check=True, timeout=300)
        uv = Path(sys.executable).with_name("uv")
        subprocess.run(
            [
                str(uv),
                *("pip", "install", "--quiet", "--python", str(python), "-c", str(lock)),
                f"bpy=={versions['bpy']}",
                f"numpy=={versions['numpy']}",
            ],
            check=True,
            timeout=1800,
        )
        (venv / ".complete").write_text("ok\n")
    return python


_CACHE_OVERRIDE = "BLINN_PHONG_KERNEL_CACHE"


def _clean_env(root: Path) -> dict[str, str]:
    env = {
        key: value
        for key, value in os.environ.items()
        # the kernel cache override too: the installed extension must choose its own directory
        if key not in ("PYTHONPATH", "NUMBA_CACHE_DIR", "VIRTUAL_ENV", "PYTHONHOME", _CACHE_OVERRIDE)
    }
    env.update(PYTHONNOUSERSITE="1", BLENDER_USER_RESOURCES=str(root / "blender_user"))
    return env


@pytest.fixture(scope="module")
def built_zips(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The self-contained linux-x64 zips, by Python version (``"3.11"``, ``"3.13"``)."""
    zips = build_extension.build_all(
        tmp_path_factory.mktemp("dist"),
        wheels=True,
        platforms=(PLATFORM,),
        wheel_cache=_cache_root() / "wheels",
    )
    manifest = tomllib.loads((REPO / "addon" / "blender_manifest.toml").read_text(encoding="utf-8"))
    expected = [build_extension.zip_name(manifest, t, PLATFORM) for t in build_extension.TARGETS]
    assert [z.name for z in zips] == expected
    return {t.python: z for t, z in zip(build_extension.TARGETS, zips, strict=True)}


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory, built_zips: dict[str, Path]) -> dict:
    root = tmp_path_factory.mktemp("installed")
    target = build_extension.target_for_blender(BPY_VERSION)
    zip_path = built_zips[target.python]
    (other_zip,) = (z for python, z in built_zips.items() if python != target.python)
    python = _bpy_only_python()
    env = _clean_env(root)
    script = root / "installed.py"
    script.write_text(INSTALLED, encoding="utf-8")
    files = REPO / "blend_files"
    blends = os.pathsep.join(
        str(files / name) for name in ("shadows.blend", "compositing.blend", "images/backplate.exr")
    )
    arguments = [str(script), str(zip_path), str(other_zip), str(root / "repo"), blends, str(root)]
    runs = []
    for install in ("1", "0"):  # install + renders; then a new process enabling the installed copy
        done = subprocess.run(
            [str(python), "-s", *arguments, install],
            capture_output=True,
            text=True,
            timeout=900,
            cwd=str(root),
            env=env,
            check=False,
        )
        lines = [line[len(MARK) :] for line in done.stdout.splitlines() if line.startswith(MARK)]
        assert done.returncode == 0 and lines, (
            f"exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        )
        runs.append({**json.loads(lines[-1]), "stdout": done.stdout})
        if install == "1":
            cache = Path(runs[0]["cache"])
            stamps = {p.name: p.stat().st_mtime_ns for p in cache.rglob("*") if p.is_file()}
    repository = run_bpy(
        REPOSITORY, root, args=(str(REPO / "blend_files" / "shadows.blend"), str(root)), timeout=900
    )
    cache = Path(runs[0]["cache"])
    stamps_after = {p.name: p.stat().st_mtime_ns for p in cache.rglob("*") if p.is_file()}
    print(f"\nBlender {'.'.join(map(str, BPY_VERSION))}: installed {zip_path.name}")
    return {
        "root": root,
        "zip": zip_path,
        "target": target,
        "runs": runs,
        "repository": repository,
        "stamps": stamps,
        "stamps_after": stamps_after,
    }


def test_one_zip_per_python_within_the_download_budget(built_zips: dict[str, Path]) -> None:
    for python, zip_path in built_zips.items():
        tag = "cp" + python.replace(".", "")
        with zipfile.ZipFile(zip_path) as zf:
            wheels = sorted(n.split("/")[-1] for n in zf.namelist() if n.endswith(".whl"))
            manifest = tomllib.loads(zf.read("blender_manifest.toml").decode("utf-8"))
        names = sorted(w.split("-")[0].lower().replace("_", "-") for w in wheels)
        assert names == sorted(build_extension.WHEEL_PACKAGES)
        assert all(f"-{tag}-{tag}-" in w for w in wheels), wheels  # only this Python's wheels
        assert manifest["wheels"] == [f"./wheels/{w}" for w in wheels]
        target = next(t for t in build_extension.TARGETS if t.python == python)
        assert manifest["blender_version_min"] == target.blender_min
        assert manifest.get("blender_version_max") == target.blender_max
        size = zip_path.stat().st_size
        print(f"\n{zip_path.name}: {size / 1e6:.1f} MB")
        assert size <= MAX_ZIP_BYTES, (zip_path.name, size)


def test_the_zip_for_this_python_is_the_one_installed(installed: dict) -> None:
    assert installed["target"].python == f"{sys.version_info[0]}.{sys.version_info[1]}"
    first = installed["runs"][0]
    expected = {name: False for name in ("numba", "embreex", "scipy", "colour", "OpenImageIO")}
    assert first["before"] == expected
    assert first["result"] == ["FINISHED"]
    # numba, embreex and scipy come with the extension; colour-science and OpenImageIO do not.
    assert first["after"] == {**expected, "numba": True, "embreex": True, "scipy": True}
    # Blender unpacks extension wheels into <user resources>/extensions/.local/lib/python3.X/site-packages.
    wheels_dir = installed["root"] / "blender_user" / "extensions" / ".local"
    for name, origin in first["origins"].items():
        assert Path(origin).is_relative_to(wheels_dir), (name, origin)
        assert f"python{installed['target'].python}" in origin


def test_this_blender_refuses_the_other_pythons_zip(installed: dict) -> None:
    first = installed["runs"][0]
    assert "blinn_phong_render" not in first["refused"]  # nothing was installed from it
    version = importlib.metadata.version("bpy")
    if installed["target"].blender_max:  # the 3.11 zip fits; the 3.13 zip needs Blender 5.1+
        why = f"This Blender version ({version}) doesn't meet the minimum supported version (5.1.0)"
    else:  # the 3.13 zip fits; the 3.11 zip stops before 5.1 (blender_version_max is exclusive)
        why = f"This Blender version ({version}) must be less than the maximum version (5.1.0)"
    assert f"blinn_phong_render: {why}" in first["stdout"], first["stdout"][-2000:]


def test_installed_extension_renders_with_numba_and_embree(installed: dict) -> None:
    for run in installed["runs"]:
        for render in run["renders"]:
            assert render["ok"], render
            choices = render["choices"]
            assert choices["engine"] == "numba" and choices["embree"] is True, render["status"]
            assert not choices["warnings"]
            assert "numba, Embree" in render["status"]
            assert not any("Embree (embreex) is not installed" in r for r in choices["reasons"])
    # The sample scene's soft spot light needs Embree: the plan kept a ray-traced method.
    assert {"soft", "ray_traced"} & set(installed["runs"][0]["renders"][0]["choices"]["shadows"])


def test_installed_planner_measures_casters_with_scipy(installed: dict) -> None:
    first = installed["runs"][0]
    assert first["feature"] == pytest.approx(0.03, rel=1e-9)  # the slat's width seen from above
    wheels_dir = installed["root"] / "blender_user" / "extensions" / ".local"
    assert Path(first["convex_hull_from"]).is_relative_to(wheels_dir)


def test_installed_verify_operator_runs_without_openimageio(installed: dict) -> None:
    verify = installed["runs"][0]["verify"]
    assert verify["status"] == ["FINISHED"], verify
    last = verify["last"]
    assert last["operator"] == "src_over" and last["max_abs_error"] <= 1e-5
    plate = read_image(REPO / "blend_files" / "images" / "backplate.exr")
    np.testing.assert_array_equal(read_image(last["files"]["background"]), plate)
    expected = composite(read_image(last["files"]["render"]), plate, "src_over")
    np.testing.assert_allclose(read_image(last["files"]["blender"]), expected, rtol=0, atol=1e-5)
    # Ours ran the extension's kernels: same arithmetic as the repository's (≤ 1 rounding per op).
    np.testing.assert_allclose(read_image(last["files"]["ours"]), expected, rtol=0, atol=1e-6)


def test_kernels_compile_once_into_the_extension_user_directory(installed: dict) -> None:
    first, second = installed["runs"]
    assert first["kernel_cache_dir"] == first["cache"]
    assert not first["numba_cache_dir"]  # numba's own setting, followed by other add-ons, untouched
    assert Path(first["cache"]).is_relative_to(Path(first["user_dir"]))
    assert any(name.endswith(".nbi") for name in installed["stamps"])  # numba's cache index files
    # The seconds each frame spent compiling (numba's compile events): the first frame after the
    # install compiles, the second frame and a new Blender process load every kernel.
    assert first["renders"][0]["stats"]["compile"] > 0 and "compile" not in first["renders"][1]["stats"]
    assert "compile" not in second["renders"][0]["stats"], second["renders"][0]["status"]
    # A new Blender process loads the cached kernels: every compiled kernel (.nbc) the first
    # process wrote is still there, unchanged (a recompile rewrites it). A call with argument
    # types the first process never used may add a specialization (a new .nbc, its index .nbi
    # updated), so the index files and new files are not compared.
    before = {name: stamp for name, stamp in installed["stamps"].items() if name.endswith(".nbc")}
    after = installed["stamps_after"]
    assert before and {name: after.get(name) for name in before} == before
    added = [name for name in after if name.endswith(".nbc") and name not in before]
    assert len(added) <= max(1, len(before) // 10), added  # nearly every kernel was reused


def test_installed_image_equals_the_repository_render(installed: dict) -> None:
    # Same Blender, same numpy, same kernels (numba), same Embree, same scene: the per-pixel work is
    # identical; 1e-6 absorbs summation-order differences of threaded (prange) loops between processes.
    root = installed["root"]
    for i in (0, 1):
        np.testing.assert_allclose(
            read_image(root / f"installed_{i}.exr"),
            read_image(root / f"repository_{i}.exr"),
            rtol=0,
            atol=1e-6,
        )
    repo = installed["repository"]
    assert repo[0]["choices"]["shadows"] == installed["runs"][0]["renders"][0]["choices"]["shadows"]
    print(
        "\ninstalled warm render {:.3f} s, repository warm render {:.3f} s; compile after install {:.2f} s, "
        "first frame of a new process {:.2f} s".format(
            installed["runs"][0]["renders"][1]["seconds"],
            repo[1]["seconds"],
            installed["runs"][0]["renders"][0]["stats"]["compile"],
            installed["runs"][1]["renders"][0]["seconds"],
        )
    )
