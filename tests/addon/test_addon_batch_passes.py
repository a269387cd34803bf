"""The batch's multilayer EXR carries the compositor passes: the bundled ``passes.blend`` (object
Cryptomatte on its view layer) through ``python -m addon.batch --format OPEN_EXR_MULTILAYER``.

Independent sources: the Cryptomatte specification's layout (the header's
``cryptomatte/<key>/name``, ``hash`` = MurmurHash3_32, ``conversion`` = uint32_to_float32, the
manifest of ``name: hex hash``; :mod:`compositing.cryptomatte`, whose hash is checked against the
published MurmurHash3 vectors and against Cycles in ``test_addon_cryptomatte.py``) and the frame's
own alpha: coverage is counted from the same samples, so a pixel's coverages sum to its alpha
plus the coverage of the holdout card (a holdout keeps its object's coverage, as an ID matte
must, and makes alpha 0).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from addon_testing import REPO, exr_passes

from compositing.cryptomatte import layer_key, matte, name_hash, name_id

pytestmark = [pytest.mark.blender, pytest.mark.slow, pytest.mark.timeout(600)]


def _bits(name: str) -> int:
    return int(np.array([name_id(name)], np.float32).view(np.uint32)[0])


def test_batch_multilayer_exr_holds_the_cryptomatte_passes(tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "addon.batch", str(REPO / "blend_files" / "passes.blend"), "--out", str(out),
         "--output-pattern", "passes_####", "--format", "OPEN_EXR_MULTILAYER", "--quiet"],
        capture_output=True, text=True, timeout=600, cwd=str(REPO), check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    (exr,) = out.glob("passes_*.exr")
    pixels, header, channels = exr_passes(exr)
    layer = next(name.split(".")[0] for name in pixels if name.endswith(".CryptoObject00"))
    prefix = layer_key(f"{layer}.CryptoObject")
    assert header[prefix + "name"] == f"{layer}.CryptoObject"
    assert header[prefix + "hash"] == "MurmurHash3_32"
    assert header[prefix + "conversion"] == "uint32_to_float32"
    manifest = json.loads(header[prefix + "manifest"])
    assert manifest["Crate"] == f"{name_hash('Crate'):08x}"
    levels = sorted(name for name in pixels if ".CryptoObject" in name)
    assert levels == [f"{layer}.CryptoObject{i:02d}" for i in range(len(levels))] and len(levels) >= 3
    assert all(channels[name] == ["r", "g", "b", "a"] for name in levels)
    passes = [pixels[name] for name in levels]
    ids = {
        int(v) for p in passes for c in (0, 2) for v in p[..., c][p[..., c + 1] > 0].view(np.uint32).ravel()
    }
    crate = int(np.array([name_id("Crate")], np.float32).view(np.uint32)[0])
    assert crate in ids and ids <= {
        int(np.array([name_id(n)], np.float32).view(np.uint32)[0]) for n in manifest
    }
    coverage = sum(p[..., 1] + p[..., 3] for p in passes)
    held_out = matte(passes, [name_id("Holdout card")])  # covered samples that alpha leaves out
    assert held_out.max() == 1.0  # the card covers whole pixels ...
    alpha = pixels[f"{layer}.Combined"][..., 3]
    np.testing.assert_allclose(coverage - held_out, alpha, atol=1e-6)  # ... and every other sample counts
