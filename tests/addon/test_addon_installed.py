"""The self-contained extension: built with its wheels, installed into a bpy that has none of them.

The zip is built by ``tools/build_extension.py --wheels`` (Blender's own ``build --split-platforms``
and ``validate``; wheels downloaded by pip into a cache outside the checkout) and installed with
``bpy.ops.extensions.package_install_files`` into a separate virtual environment holding only ``bpy``
and the numpy it pins (plus bpy's own requirements), run without user site-packages: numba, embreex
and colour-science can only come from the extension. The sample scene ``shadows.blend`` is rendered
there and by the repository's add-on in the project's environment; the render stats must say the
compiled kernels and Embree ran, and the images must agree.

Slow (pip downloads on the first run, a 240 MB zip, numba compiling in a fresh cache): marked
``slow``; the wheel downloads and the bpy-only environment are cached under
``~/.cache/blinn-phong-render`` (``XDG_CACHE_HOME``) and reused.
"""

from __future__ import annotations

import importlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from addon_testing import MARK, REPO, run_bpy

from compositing.io import read_image

sys.path.insert(0, str(REPO / "tools"))
build_extension = importlib.import_module("build_extension")

pytestmark = [pytest.mark.blender, pytest.mark.slow, pytest.mark.timeout(900)]

PACKAGE = "bl_ext.test_repo.blinn_phong_render"

INSTALLED = f"""
import importlib, importlib.util, json, os, sys, time
import bpy
def emit(obj):
    print({MARK!r} + json.dumps(obj), flush=True)
zip_path, repo_dir, blend, out, install = sys.argv[1:6]
before = {{name: importlib.util.find_spec(name) is not None for name in ("numba", "embreex", "colour")}}
prefs = bpy.context.preferences
prefs.extensions.repos.new(name="Test", module="test_repo", custom_directory=repo_dir, source="USER")
if install == "1":
    result = sorted(bpy.ops.extensions.package_install_files(
        repo="test_repo", filepath=zip_path, enable_on_install=True))
else:
    import addon_utils
    addon_utils.enable({PACKAGE!r}, default_set=True, handle_error=print)
    result = ["ENABLED"]
engine = importlib.import_module({PACKAGE!r} + ".engine")
import numba, embreex, colour
origins = {{m.__name__: m.__file__ for m in (numba, embreex, colour)}}
bpy.ops.wm.open_mainfile(filepath=blend, load_ui=False)
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
emit({{
    "before": before, "result": result, "origins": origins,
    "user_dir": bpy.utils.extension_path_user({PACKAGE!r}),
    "kernel_cache_dir": os.environ.get("BLINN_PHONG_KERNEL_CACHE"), "cache": cache,
    "numba_cache_dir": numba.config.CACHE_DIR,
    "renders": [{{k: r.get(k) for k in ("ok", "error", "choices", "stats", "status", "seconds", "notes")}}
                for r in renders],
}})
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


def _bpy_only_python() -> Path:
    """A virtual environment with only bpy, its pinned numpy and bpy's own requirements (cached)."""
    versions = build_extension.pinned_versions(("bpy", "numpy"))
    venv = _cache_root() / f"venv-bpy-{versions['bpy']}-numpy-{versions['numpy']}"
    python = venv / "bin" / "python"
    if not (venv / ".complete").exists():
        subprocess.run([sys.executable, "-m", "venv", "--clear", str(venv)], check=True, timeout=300)
        uv = Path(sys.executable).with_name("uv")
        subprocess.run(
            [
                str(uv),
                *("pip", "install", "--quiet", "--python", str(python)),
                *("-c", str(REPO / "requirements" / "main.lock")),
                f"bpy=={versions['bpy']}",
                f"numpy=={versions['numpy']}",
            ],
            check=True,
            timeout=900,
        )
        (venv / ".complete").write_text("ok\n")
    return python


def _python313_candidates() -> list[str]:
    """Where a CPython 3.13 may be: ``PYTHON313``, ``python3.13`` on ``PATH``, pyenv's installed 3.13s.

    pyenv's ``python3.13`` shim fails unless 3.13 is among the selected versions, although the
    interpreter is installed under ``$(pyenv root)/versions``; those are tried too.
    """
    found = [os.environ.get("PYTHON313"), shutil.which("python3.13")]
    pyenv = shutil.which("pyenv")
    if pyenv:
        root = subprocess.run([pyenv, "root"], capture_output=True, text=True, check=False, timeout=60)
        if root.returncode == 0 and root.stdout.strip():
            found += sorted(str(p) for p in Path(root.stdout.strip()).glob("versions/3.13*/bin/python3.13"))
    return [c for c in found if c]


def _python313() -> str | None:
    """A working CPython 3.13 (the first of :func:`_python313_candidates` that runs), else None."""
    for candidate in _python313_candidates():
        try:
            done = subprocess.run(
                [candidate, "-c", "import sys; print(sys.version_info[:2])"],
                capture_output=True,
                text=True,
                check=False,
                timeout=60,
            )
        except OSError:
            continue
        if done.returncode == 0 and "(3, 13)" in done.stdout:
            return candidate
    return None


def _bpy52_only_python(python313: str) -> Path:
    """Python 3.13 with only bpy 5.2, its numpy 2 and bpy's own requirements (cached)."""
    lock = REPO / "requirements" / "blender52.lock"
    versions = build_extension.pinned_versions(("bpy", "numpy"), lock=lock)
    venv = _cache_root() / f"venv-bpy-{versions['bpy']}-numpy-{versions['numpy']}"
    python = venv / "bin" / "python"
    if not (venv / ".complete").exists():
        subprocess.run([python313, "-m", "venv", "--clear", str(venv)], check=True, timeout=300)
        uv = Path(sys.executable).with_name("uv")
        subprocess.run(
            [
                str(uv),
                "pip",
                "install",
                "--quiet",
                "--python",
                str(python),
                "-c",
                str(lock),
                f"bpy=={versions['bpy']}",
                f"numpy=={versions['numpy']}",
            ],
            check=True,
            timeout=900,
        )
        (venv / ".complete").write_text("ok\n")
    return python


def _clean_env(root: Path) -> dict[str, str]:
    env = {
        key: value
        for key, value in os.environ.items()
        if key not in ("PYTHONPATH", "NUMBA_CACHE_DIR", "VIRTUAL_ENV", "PYTHONHOME")
    }
    env.update(PYTHONNOUSERSITE="1", BLENDER_USER_RESOURCES=str(root / "blender_user"))
    return env


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The self-contained linux-x64 zip (wheels for CPython 3.11 and 3.13)."""
    return build_extension.build(
        tmp_path_factory.mktemp("dist"),
        wheels=True,
        platforms=("linux-x64",),
        wheel_cache=_cache_root() / "wheels",
    )


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory, built_zip: Path) -> dict:
    root = tmp_path_factory.mktemp("installed")
    zip_path = built_zip
    python = _bpy_only_python()
    env = _clean_env(root)
    script = root / "installed.py"
    script.write_text(INSTALLED, encoding="utf-8")
    runs = []
    for install in ("1", "0"):  # install + two renders; then a new process enabling the installed copy
        done = subprocess.run(
            [
                str(python),
                "-s",
                str(script),
                str(zip_path),
                str(root / "repo"),
                str(REPO / "blend_files" / "shadows.blend"),
                str(root),
                install,
            ],
            capture_output=True,
            text=True,
            timeout=600,
            cwd=str(root),
            env=env,
            check=False,
        )
        lines = [line[len(MARK) :] for line in done.stdout.splitlines() if line.startswith(MARK)]
        assert done.returncode == 0 and lines, (
            f"exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        )
        runs.append(json.loads(lines[-1]))
        if install == "1":
            cache = Path(runs[0]["cache"])
            stamps = {p.name: p.stat().st_mtime_ns for p in cache.rglob("*") if p.is_file()}
    repository = run_bpy(
        REPOSITORY, root, args=(str(REPO / "blend_files" / "shadows.blend"), str(root)), timeout=600
    )
    cache = Path(runs[0]["cache"])
    stamps_after = {p.name: p.stat().st_mtime_ns for p in cache.rglob("*") if p.is_file()}
    return {
        "root": root,
        "zip": zip_path,
        "runs": runs,
        "repository": repository,
        "stamps": stamps,
        "stamps_after": stamps_after,
    }


def test_the_bpy_only_environment_lacks_the_compiled_dependencies(installed: dict) -> None:
    assert installed["runs"][0]["before"] == {"numba": False, "embreex": False, "colour": False}
    assert installed["runs"][0]["result"] == ["FINISHED"]
    # Blender unpacks extension wheels into <user resources>/extensions/.local/lib/python3.X/site-packages.
    wheels_dir = installed["root"] / "blender_user" / "extensions" / ".local"
    for name, origin in installed["runs"][0]["origins"].items():
        assert Path(origin).is_relative_to(wheels_dir), (name, origin)


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
    # Same kernels (numba), same Embree, same scene: the per-pixel work is identical; 1e-6 absorbs
    # summation-order differences of threaded (prange) loops between processes.
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


def test_installed_on_blender_52_uses_the_cp313_wheels(
    installed: dict, built_zip: Path, tmp_path: Path
) -> None:
    # Blender 5.2 LTS (CPython 3.13, numpy 2): the same zip installs its cp313 wheels. The image is
    # compared with the repository's render on Blender 5.0 / numpy 1.26: same kernels, but numpy's
    # own reductions may round differently between major versions, hence 1e-5 (float32 output).
    python313 = _python313()
    if python313 is None:
        pytest.skip(
            "no working python3.13 (set PYTHON313; tried PATH and pyenv) to build the Blender 5.2 environment"
        )
    python = _bpy52_only_python(python313)
    script = tmp_path / "installed.py"
    script.write_text(INSTALLED, encoding="utf-8")
    done = subprocess.run(
        [
            str(python),
            "-s",
            str(script),
            str(built_zip),
            str(tmp_path / "repo"),
            str(REPO / "blend_files" / "shadows.blend"),
            str(tmp_path),
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=str(tmp_path),
        env=_clean_env(tmp_path),
        check=False,
    )
    lines = [line[len(MARK) :] for line in done.stdout.splitlines() if line.startswith(MARK)]
    assert done.returncode == 0 and lines, (
        f"exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    )
    got = json.loads(lines[-1])
    assert got["before"] == {"numba": False, "embreex": False, "colour": False}
    assert "python3.13" in got["origins"]["numba"]
    render = got["renders"][1]
    assert render["ok"] and render["choices"]["engine"] == "numba" and render["choices"]["embree"], render
    np.testing.assert_allclose(
        read_image(tmp_path / "installed_1.exr"),
        read_image(installed["root"] / "repository_1.exr"),
        rtol=0,
        atol=1e-5,
    )
