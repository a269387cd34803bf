"""The warm-up process: after it, a fresh process loads every kernel its frames need and compiles
none (counted by numba's own compile events, ``compositing._kernel_cache.compile_clock``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from blinn_phong import warmup

REPO = Path(__file__).resolve().parents[2]
CASE = "plain 1 sample"

#: A fresh process renders the warm-up's first frame and reports what numba compiled for it.
RENDER_AND_COUNT = """
import json
import blinn_phong as bp
from blinn_phong import warmup
from compositing._kernel_cache import compile_clock

scene = warmup._scenes()["opaque"]
with compile_clock() as log:
    bp.render(scene, *warmup.SIZE, engine="numba", shadows="none")
print(json.dumps({"compiled": log.compiled, "warm": warmup.is_warm()}))
"""


def _env(cache: Path, **extra: str) -> dict[str, str]:
    env = dict(os.environ, BLINN_PHONG_KERNEL_CACHE=str(cache), PYTHONPATH=str(REPO), **extra)
    env.pop("NUMBA_DISABLE_JIT", None)
    return env


def test_cases_cover_every_method() -> None:
    from blinn_phong.effects.oit import TRANSPARENCY_METHODS
    from blinn_phong.shadows.methods import SHADOW_METHODS

    names = " ".join(name for name, _, _ in warmup.CASES)
    for method in (*SHADOW_METHODS, "soft", *TRANSPARENCY_METHODS):
        if method in ("none", "auto", "zbuffer"):
            continue
        assert method in names, method


def test_an_unknown_case_is_refused_with_the_names() -> None:
    with pytest.raises(ValueError, match=r"\['fgo'\] match no case; the cases are \[.*'fog'"):
        warmup.selected_cases(["fgo"])
    assert [c[0] for c in warmup.selected_cases(["fog"])] == ["fog"]


def test_a_background_warm_up_leaves_nothing_to_compile(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("numba")
    for name, value in _env(tmp_path / "kernels", BLINN_PHONG_WARMUP_CASES=CASE).items():
        monkeypatch.setenv(name, value)  # the child inherits this process's environment
    process = warmup.start_background()
    assert process.wait(timeout=600) == 0
    out = subprocess.run(
        [sys.executable, "-c", RENDER_AND_COUNT], env=_env(tmp_path / "kernels"), capture_output=True,
        text=True, timeout=600, check=True,
    )  # fmt: skip
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["compiled"] == 0
    assert report["warm"] is False  # one case only: the marker says "every kernel", so it is absent


def test_the_child_runs_under_the_import_name_of_a_vendored_copy(tmp_path: Path) -> None:
    """Inside the extension the module is ``bl_ext.<repo>.<ext>.blinn_phong.warmup``: the child
    imports it under that name, without running the enclosing packages' ``__init__``."""
    ext = tmp_path / "fake_repo" / "fake_ext"
    ext.mkdir(parents=True)
    (tmp_path / "fake_repo" / "__init__.py").write_text("raise ImportError('ran the repository __init__')\n")
    (ext / "__init__.py").write_text("raise ImportError('ran the extension __init__ (needs bpy)')\n")
    (ext / "blinn_phong").symlink_to(REPO / "blinn_phong")
    code = (
        "import sys, types\n"
        f"sys.path.insert(0, {str(tmp_path)!r})\n"
        "for name, path in (('fake_repo', %r), ('fake_repo.fake_ext', %r)):\n"
        "    m = types.ModuleType(name); m.__path__ = [path]; sys.modules[name] = m\n"
        "import importlib\n"
        "w = importlib.import_module('fake_repo.fake_ext.blinn_phong.warmup')\n"
        "p = w.start_background(quiet=False, args=('--list',))\n"
        "sys.exit(p.wait(timeout=120))\n"
    ) % (str(tmp_path / "fake_repo"), str(ext))
    out = subprocess.run(
        [sys.executable, "-c", code], env=_env(tmp_path / "kernels"), capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    lines = out.stdout.split()
    assert "fake_repo.fake_ext.blinn_phong.warmup" in out.stdout.splitlines()[0]
    assert "textures" in lines


def test_the_command_line_rejects_unknown_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    assert warmup.main(["--fast"]) == 2
    assert "unknown argument(s) ['--fast']" in capsys.readouterr().err
