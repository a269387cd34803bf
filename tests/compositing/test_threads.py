"""compositing._threads: shares cover the items once, in order; errors surface; the OpenMP
wait policy set at import."""

from __future__ import annotations

import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from compositing import _threads


@numba.njit(nogil=True)
def _square_sum(values, out):  # pragma: no cover - compiled
    total = 0.0
    for i in range(values.shape[0]):
        out[int(values[i])] = values[i] * values[i]
        total += values[i] * values[i]
    return total


@pytest.mark.parametrize("n", [0, 1, 7, 1000])
def test_shares_cover_every_item_once(n: int) -> None:
    items = np.arange(n, dtype=np.float64)
    out = np.full(n, -1.0)
    totals = _threads.run_shares(lambda share: _square_sum(share, out), items)
    # every item written by exactly one share: the closed form of the squares, and their sum
    np.testing.assert_array_equal(out, items * items)
    assert sum(totals) == pytest.approx(n * (n - 1) * (2 * n - 1) / 6, rel=1e-12)


def test_shares_are_contiguous_and_in_order() -> None:
    items = np.arange(103)
    shares = _threads.run_shares(lambda share: share.copy(), items)
    np.testing.assert_array_equal(np.concatenate(shares), items)
    if _threads.thread_count() > 1:
        assert len(shares) == min(_threads.thread_count() * _threads.SHARES_PER_THREAD, 103)


def test_an_error_in_a_share_is_raised() -> None:
    def work(share: np.ndarray) -> int:
        if 50 in share:
            raise ZeroDivisionError("share with 50")
        return len(share)

    with pytest.raises(ZeroDivisionError, match="share with 50"):
        _threads.run_shares(work, np.arange(100))


def test_one_thread_runs_once_on_the_caller(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_threads, "thread_count", lambda: 1)
    calls = _threads.run_shares(lambda share: len(share), np.arange(100))
    assert calls == [100]


def test_items_must_be_one_dimensional() -> None:
    with pytest.raises(ValueError, match=r"items: expected a 1-D array, got shape \(2, 2\)"):
        _threads.run_shares(len, np.zeros((2, 2)))



def _after_import(module: str, environment: dict[str, str]) -> list[str]:
    """In a fresh interpreter with ``environment``: ``OMP_WAIT_POLICY`` after ``import module``,
    and whether numba's threads had been started by then (they must not: libgomp reads the
    policy when they start)."""
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"} | environment
    script = (
        f"import os, sys, {module}\n"
        "parallel = sys.modules.get('numba.np.ufunc.parallel')\n"
        "print(os.environ.get('OMP_WAIT_POLICY'), bool(getattr(parallel, '_is_initialized', False)))"
    )
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    return done.stdout.split()


@pytest.mark.parametrize("module", ["compositing", "blinn_phong"])
def test_importing_makes_openmp_threads_sleep_unless_the_process_chose(module: str) -> None:
    # the package's pool threads and numba's OpenMP threads share the cores: spinning OpenMP
    # threads would hold them (compositing._threads' docstring); a chosen policy is kept
    assert _after_import(module, {}) == ["PASSIVE", "False"]
    assert _after_import(module, {"OMP_WAIT_POLICY": "ACTIVE"}) == ["ACTIVE", "False"]


def test_the_policy_is_not_claimed_once_numba_threads_run() -> None:
    # libgomp has read its environment already: nothing can change, and the function says so
    script = (
        "import numba, numpy as np\n"
        "@numba.njit(parallel=True)\n"
        "def f(a):\n"
        "    for i in numba.prange(a.size):\n"
        "        a[i] += 1\n"
        "f(np.zeros(4))\n"
        "from compositing._threads import prefer_passive_openmp\n"
        "print(prefer_passive_openmp())"
    )
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["None"]
