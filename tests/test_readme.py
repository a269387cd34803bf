"""The README's Python blocks each run on their own, as written, in a fresh interpreter started
in an empty directory (a newcomer pasting one block), and what they compute agrees with
independent values: the worked blend-stage example, Porter & Duff's atop, and the written PNG
decoding to the composite."""

from __future__ import annotations

import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Appended to a block: its results, for the checks below (names the block does not define are skipped).
REPORT = """
import pickle as _pickle, sys as _sys
_names = ("image", "blended", "src", "dst", "atop")
_report = {_n: globals()[_n] for _n in _names if _n in globals()}
for _n in ("gl_like", "exact"):
    if _n in globals():
        _report[_n + "_shadows"] = [_c.method for _c in globals()[_n].plan.shadows]
with open(_sys.argv[1], "wb") as _f:
    _pickle.dump(_report, _f)
"""


def python_blocks(text: str) -> list[str]:
    """The contents of the ```python fenced blocks of a Markdown text, in order."""
    return re.findall(r"^```python\n(.*?)^```$", text, flags=re.S | re.M)


BLOCKS = python_blocks((ROOT / "README.md").read_text(encoding="utf-8"))


def test_the_python_blocks_are_found():
    assert len(BLOCKS) >= 3
    first = BLOCKS[0]
    # the first block is a whole program: imports, a scene, a render, a composite, a file
    needles = ("import blinn_phong", "uv_sphere", "Light(", "Camera.", "bp.render(", "composite(")
    needles += ("write_image(",)
    for needle in needles:
        assert needle in first, needle


def run_block(number: int, directory: Path) -> tuple[str, dict]:
    """Run README block ``number`` alone in a fresh interpreter in ``directory``; stdout and results.

    The interpreter finds the project as a script outside the checkout would: through the
    editable install of ``make setup`` when this is the checkout's own environment, else
    (another checkout's environment, as in a shared set-up) through ``PYTHONPATH``.
    """
    script = directory / f"block{number}.py"
    script.write_text(BLOCKS[number] + REPORT, encoding="utf-8")
    env = dict(os.environ)
    if not _installed_here():
        env["PYTHONPATH"] = os.pathsep.join(filter(None, (str(ROOT), env.get("PYTHONPATH"))))
    done = subprocess.run(
        [sys.executable, str(script), str(directory / "report.pkl")],
        cwd=directory,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, f"README python block {number} alone:\n{done.stderr[-3000:]}"
    with open(directory / "report.pkl", "rb") as f:
        return done.stdout, pickle.load(f)


def _installed_here() -> bool:
    """True when this interpreter's environment is this checkout's ``.venv`` (``make setup``)."""
    return Path(sys.prefix).resolve() == (ROOT / ".venv").resolve() and (ROOT / ".venv").is_dir() and (
        not (ROOT / ".venv").is_symlink()
    )


@pytest.mark.slow
def test_the_quick_start_runs_alone(tmp_path):
    out, got = run_block(0, tmp_path)
    assert "wrote quickstart.png" in out
    from compositing.io import read_image

    written = read_image(tmp_path / "quickstart.png")
    image = np.asarray(got["image"])
    assert written.shape == (180, 320, 4) and np.all(written[..., 3] == 1.0)
    # 8-bit sRGB round trip of the clipped composite: within one step of the encoding
    clipped = np.clip(image[..., :3], 0.0, 1.0)
    assert np.abs(written[..., :3] - clipped).max() <= 1.0 / 255 * 2.4 / 1.055 + 1e-6


@pytest.mark.slow
def test_the_busy_scene_block_runs_alone(tmp_path):
    out, got = run_block(1, tmp_path)
    assert "shadows='none'" in out
    # the GL-like call really draws no shadow, and the default does on this scene
    assert got["gl_like_shadows"] and all(m == "none" for m in got["gl_like_shadows"])
    assert got["exact_shadows"] and all(m != "none" for m in got["exact_shadows"])


def test_the_compositing_block_runs_alone(tmp_path):
    out, got = run_block(2, tmp_path)
    assert "('ONE', 'ONE_MINUS_SRC_ALPHA')" in out
    # the worked example of the blend stage: (0,0,1,.25)·(1 − src) + (0,1,0,.75)·.25
    np.testing.assert_allclose(got["blended"], [0.0, 0.25, 0.0, 0.375], atol=1e-7)
    # Porter & Duff atop, mixed with dst by f = 0.5: dst·(1 − f) + (src·αB + dst·(1 − αA))·f
    src, dst = np.asarray(got["src"], float), np.asarray(got["dst"], float)
    atop = src * dst[3] + dst * (1 - src[3])
    np.testing.assert_allclose(got["atop"], 0.5 * dst + 0.5 * atop, atol=1e-7)


def test_every_block_is_run_by_a_test():
    assert len(BLOCKS) == 3, "a new README block needs its own test here"


def test_a_script_outside_the_checkout_imports_the_packages(tmp_path):
    # After `make setup` the checkout's .venv has the project installed in editable mode: a
    # script in any directory imports this checkout's packages (not another copy).
    if not _installed_here():
        pytest.skip(f"{sys.prefix} is not this checkout's own .venv (made by `make setup`)")
    script = tmp_path / "outside.py"
    script.write_text("import blinn_phong, compositing, addon\nprint(blinn_phong.__file__)\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert Path(done.stdout.strip()).resolve() == (ROOT / "blinn_phong" / "__init__.py").resolve()
