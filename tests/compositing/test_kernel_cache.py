"""Generated kernels are compiled once per machine: cached on disk, loaded by the next process.

Each case runs fresh Python processes (the cache only matters across processes) with
``BLINN_PHONG_KERNEL_CACHE`` pointing at a temporary directory. The independent checks:

* the second process *loads* the kernel (numba's own counters: a cache hit, no miss);
* its result is bitwise the first process's and that of a kernel compiled in memory (no
  cache directory can be written): the fused kernels are element-wise, one code path on
  identical inputs, so caching may change start-up time and nothing else;
* the result is Porter-Duff ``src_over`` by its closed form ``s + d·(1 − αs)`` to float32
  rounding.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import json, sys
import numpy as np
import compositing
from compositing import _fused, _stack_fused
rng = np.random.default_rng(7)
a = rng.random((300, 200, 4), dtype=np.float32); a[..., :3] *= a[..., 3:]
b = rng.random((300, 200, 4), dtype=np.float32); b[..., :3] *= b[..., 3:]
over = compositing.composite(a, b, "src_over", engine="numba")
stack = compositing.composite_stack([b, a, b[::-1].copy()])
over_kernel = _fused._compiled("src_over", compositing.PORTER_DUFF["src_over"], "float32", False)
stack_kernel = _stack_fused._compiled("back_to_front", "float32")
def counts(k):
    s = k.stats
    return [sum(s.cache_hits.values()), sum(s.cache_misses.values())]
np.save(sys.argv[1], np.stack([over, stack]))
print(json.dumps({"over": counts(over_kernel), "stack": counts(stack_kernel)}))
"""


def _run(tmp_path: Path, cache: str, name: str) -> tuple[np.ndarray, dict]:
    env = {**os.environ, "BLINN_PHONG_KERNEL_CACHE": cache, "PYTHONPATH": str(ROOT)}
    out = tmp_path / f"{name}.npy"
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, str(out)], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr
    return np.load(out), json.loads(proc.stdout.strip().splitlines()[-1])


def test_second_process_loads_the_cached_kernels_and_gets_the_same_bits(tmp_path: Path) -> None:
    cache = tmp_path / "kernels"
    first, first_counts = _run(tmp_path, str(cache), "first")
    assert sorted(p.suffix for p in (cache / "generated").glob("k_*")) == [".py", ".py"]  # src_over, stack
    assert first_counts == {"over": [0, 1], "stack": [0, 1]}  # compiled and stored
    second, second_counts = _run(tmp_path, str(cache), "second")
    assert second_counts == {"over": [1, 0], "stack": [1, 0]}  # loaded, not compiled
    assert np.array_equal(first, second)

    # No writable cache directory (a path below a regular file): compiled in memory, same bits.
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("")
    in_memory, memory_counts = _run(tmp_path, str(blocker / "kernels"), "memory")
    assert memory_counts["over"][0] == memory_counts["stack"][0] == 0  # nothing loaded
    assert blocker.read_text() == ""  # and nothing written
    assert np.array_equal(first, in_memory)

    rng = np.random.default_rng(7)
    a = rng.random((300, 200, 4), dtype=np.float32)
    a[..., :3] *= a[..., 3:]
    b = rng.random((300, 200, 4), dtype=np.float32)
    b[..., :3] *= b[..., 3:]
    closed_form = a.astype(np.float64) + b * (1.0 - a[..., 3:].astype(np.float64))
    np.testing.assert_allclose(first[0], closed_form, rtol=0, atol=2 * np.finfo(np.float32).eps)
