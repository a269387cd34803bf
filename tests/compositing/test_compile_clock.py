"""``compile_clock`` counts the seconds numba compiles, and only those (``compositing/_kernel_cache.py``).

Independent source: numba's own per-overload timer (``overloads[sig].metadata["timers"]
["compiler_lock"]``: how long the dispatcher held the compiler lock for that compilation) and
its cache counters. Tiny functions (a fraction of a second to compile each), compiled fresh.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from compositing._kernel_cache import compile_clock  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def _lock_seconds(dispatcher: object) -> float:
    (overload,) = dispatcher.overloads.values()
    return overload.metadata["timers"]["compiler_lock"]


def test_a_compilation_is_counted_once_with_its_callee() -> None:
    @numba.njit
    def callee(x):
        return x * 2.0 + 1.0

    @numba.njit
    def caller(values):
        total = 0.0
        for v in values:
            total += callee(v)
        return total

    with compile_clock() as log:
        assert caller(np.arange(4.0)) == 2.0 * 6.0 + 4.0
    held = _lock_seconds(caller)  # the caller's whole compilation, its callee's included
    assert log.compiled >= 2 and len(callee.signatures) == 1
    assert 0 < log.seconds <= held
    # the lock is held a little longer than the compile event (signature checks, add_overload:
    # milliseconds against a compilation of a tenth of a second or more)
    assert log.seconds >= 0.8 * held
    # the callee ran inside the caller's compilation: counted once, not added again
    assert log.seconds < held + 0.5 * _lock_seconds(callee)
    assert sum(log.by_module.values()) == pytest.approx(log.seconds)
    # the compiling thread's CPU time: positive, never more than the wall time it took
    assert 0 < log.cpu_seconds <= log.seconds + 0.01
    assert sum(log.cpu_by_module.values()) == pytest.approx(log.cpu_seconds)
    caller_name = f"{__name__}.{caller.py_func.__qualname__}"
    assert set(log.by_kernel) == {caller_name}  # the non-project callee is part of its caller

    with compile_clock() as again:
        caller(np.arange(3.0))  # same signature: nothing compiles
    assert again.seconds == 0.0 and again.compiled == 0


def test_a_kernel_loaded_from_the_disk_cache_counts_nothing(tmp_path: Path) -> None:
    source = tmp_path / "clock_probe.py"
    source.write_text("import numba\n\n@numba.njit(cache=True)\ndef triple(x):\n    return 3 * x\n")

    def fresh(name: str):
        spec = importlib.util.spec_from_file_location(name, source)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    with compile_clock() as first:
        one = fresh("clock_probe_one")
        assert one.triple(7) == 21
    assert first.seconds > 0 and sum(one.triple.stats.cache_misses.values()) == 1
    with compile_clock() as second:
        two = fresh("clock_probe_two")  # a new dispatcher of the same function: loaded
        assert two.triple(7) == 21
    assert sum(two.triple.stats.cache_hits.values()) == 1 and not two.triple.stats.cache_misses
    assert second.seconds == 0.0 and second.compiled == 0


def test_project_kernels_are_counted_per_module(tmp_path: Path) -> None:
    # A registered package of two modules, the caller's kernel calling the callee's: each module
    # gets its own compile time, numba's library code (np.zeros) goes to the kernel that used it.
    package = tmp_path / "clockpkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "low.py").write_text(
        "import numba\nimport numpy as np\n\n@numba.njit\ndef ramp(n):\n"
        "    out = np.zeros(n)\n    for i in range(n):\n        out[i] = i\n    return out\n"
    )
    (package / "high.py").write_text(
        "import numba\nfrom clockpkg.low import ramp\n\n"
        "@numba.njit\ndef total(n):\n    return ramp(n).sum()\n"
    )
    code = textwrap.dedent(
        f"""
        import json, sys
        sys.path.insert(0, {str(tmp_path)!r})
        from compositing._kernel_cache import compile_clock, register_package
        register_package({str(package)!r})
        from clockpkg import high, low
        with compile_clock() as log:
            assert high.total(5) == 10.0
        timers = {{name: next(iter(d.overloads.values())).metadata["timers"]["compiler_lock"]
                  for name, d in (("high", high.total), ("low", low.ramp))}}
        print(json.dumps({{"seconds": log.seconds, "by_module": dict(log.by_module), "timers": timers}}))
        """
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert set(got["by_module"]) == {"clockpkg.high", "clockpkg.low"}
    assert sum(got["by_module"].values()) == pytest.approx(got["seconds"])
    # the callee's own time is its compilation (numba's timer of it), not the caller's
    assert got["by_module"]["clockpkg.low"] <= got["timers"]["low"]
    assert got["by_module"]["clockpkg.low"] >= 0.8 * got["timers"]["low"]
    assert got["seconds"] <= got["timers"]["high"]
