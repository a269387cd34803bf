"""The README's Python blocks run as written, in order, in an empty directory (a newcomer's
copy-paste), and what they compute agrees with independent values: the worked blend-stage
example, Porter & Duff's atop, and the written PNG decoding to the composite."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def python_blocks(text: str) -> list[str]:
    """The contents of the ```python fenced blocks of a Markdown text, in order."""
    return re.findall(r"^```python\n(.*?)^```$", text, flags=re.S | re.M)


def test_the_python_blocks_are_found():
    blocks = python_blocks((ROOT / "README.md").read_text(encoding="utf-8"))
    assert len(blocks) >= 3
    first = blocks[0]
    # the first block is a whole program: imports, a scene, a render, a composite, a file
    needles = ("import blinn_phong", "uv_sphere", "Light(", "Camera.", "bp.render(", "composite(")
    needles += ("write_image(",)
    for needle in needles:
        assert needle in first, needle


@pytest.mark.slow
def test_readme_python_blocks_run_in_an_empty_directory(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__readme__"}
    for number, block in enumerate(python_blocks((ROOT / "README.md").read_text(encoding="utf-8"))):
        exec(compile(block, f"README.md python block {number}", "exec"), namespace)
    out = capsys.readouterr().out
    assert "wrote quickstart.png" in out and "shadows, light 0:" in out
    from compositing.io import read_image

    written = read_image(tmp_path / "quickstart.png")
    image = np.asarray(namespace["image"])
    assert written.shape == (180, 320, 4) and np.all(written[..., 3] == 1.0)
    # 8-bit sRGB round trip of the clipped composite: within one step of the encoding
    clipped = np.clip(image[..., :3], 0.0, 1.0)
    assert np.abs(written[..., :3] - clipped).max() <= 1.0 / 255 * 2.4 / 1.055 + 1e-6
    # the worked example of the blend stage: (0,0,1,.25)·(1 − src) + (0,1,0,.75)·.25
    np.testing.assert_allclose(namespace["blended"], [0.0, 0.25, 0.0, 0.375], atol=1e-7)
    # Porter & Duff atop, mixed with dst by f = 0.5: dst·(1 − f) + (src·αB + dst·(1 − αA))·f
    src, dst = np.asarray(namespace["src"], float), np.asarray(namespace["dst"], float)
    atop = src * dst[3] + dst * (1 - src[3])
    np.testing.assert_allclose(namespace["atop"], 0.5 * dst + 0.5 * atop, atol=1e-7)
    # the GL-like call really draws no shadow, and the default does on this scene
    assert all(c.method == "none" for c in namespace["gl_like"].plan.shadows)
    assert all(c.method != "none" for c in namespace["exact"].plan.shadows)
