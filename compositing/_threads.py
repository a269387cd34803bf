"""Run a compiled kernel's work in shares on threads.

numba's ``parallel=True`` turns a loop into a multi-threaded one, but its transformation of a
large loop body is slow to compile (seconds to minutes, and gigabytes, for the fused frame kernel:
``docs/compile.md``). A kernel compiled with ``nogil=True`` runs without Python's global
interpreter lock, so plain Python threads run shares of its work at once; the kernel itself
compiles as ordinary serial code.

The rasterizer's few loops that stay numba-parallel run on numba's OpenMP threads. OpenMP's
threads spin for a while after each parallel loop (libgomp's default wait policy), holding the
cores the next stage's threads need: on a 2-core machine the second thread of a 640×360 frame's
shading started 1.5–3 ms late, and the stage took 6.7 ms instead of 4.6 ms. Importing the
package therefore sets ``OMP_WAIT_POLICY=PASSIVE`` (:func:`prefer_passive_openmp`) unless the
process already chose a policy; libgomp reads it when numba first starts its threads (too late
if they were started before the import).
"""

from __future__ import annotations

import atexit
import itertools
import os
import sys
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numpy as np

_Result = TypeVar("_Result")

#: Shares per thread: more than one, so a thread that finishes its share early takes another.
SHARES_PER_THREAD = 4

#: The OpenMP wait policy set at import when the process has none (module docstring).
OPENMP_WAIT_POLICY = "PASSIVE"


def prefer_passive_openmp() -> str | None:
    """Make OpenMP's threads sleep, not spin, between numba's parallel loops, unless the process
    chose a policy (``OMP_WAIT_POLICY`` already set).

    Returns the policy numba's OpenMP threads will follow, or None when they were already
    started in this process (libgomp reads the variable once, when numba starts its threads:
    then nothing changes). The variable is set in the process environment, so child processes
    inherit it, and so does any other OpenMP library loaded later in the process; a caller that
    set ``OMP_WAIT_POLICY`` before the import keeps its value. Under numba's TBB or workqueue
    threading layers it has no effect.
    """
    parallel = sys.modules.get("numba.np.ufunc.parallel")
    if parallel is not None and getattr(parallel, "_is_initialized", False):
        return None
    return os.environ.setdefault("OMP_WAIT_POLICY", OPENMP_WAIT_POLICY)


prefer_passive_openmp()

_pool: ThreadPoolExecutor | None = None
_pool_threads = 0
_lock = threading.Lock()


def thread_count() -> int:
    """The number of threads kernels run on: numba's (``NUMBA_NUM_THREADS``, or
    ``numba.set_num_threads``), at least 1."""
    try:
        import numba

        return max(1, int(numba.get_num_threads()))
    except ImportError:  # pragma: no cover - numba is a dependency of the compiled engine
        return 1


def _executor(threads: int) -> ThreadPoolExecutor:
    global _pool, _pool_threads
    with _lock:
        if _pool is None or _pool_threads != threads:
            if _pool is not None:
                _pool.shutdown(wait=False)
            _pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="kernel")
            _pool_threads = threads
        return _pool


@atexit.register
def _shutdown() -> None:  # pragma: no cover - at exit
    if _pool is not None:
        _pool.shutdown(wait=True)


def in_shares(kernel: Callable[..., _Result], n: int, *args: object) -> Sequence[_Result]:
    """``kernel(share, *args)`` for shares of ``range(n)`` (C-contiguous int64 arrays) on threads:
    :func:`run_shares` for a compiled kernel whose loop runs over ``share``'s indices.

    Such a kernel is a serial loop (``numba.njit(nogil=True)``) where each index writes its own
    outputs, so there are no write races and its results do not depend on the number of
    threads. Returns each share's result, in order (e.g. a count to sum).
    """
    items = np.arange(n, dtype=np.int64)
    if thread_count() > 1 and n > 1 and not getattr(kernel, "signatures", True):
        # not compiled yet: an empty share first, on this thread, so that the kernel is compiled
        # (or loaded) here, where warnings and the compile clock's listeners see it
        kernel(items[:0], *args)
    return run_shares(lambda share: kernel(share, *args), items)


def run_shares(work: Callable[[np.ndarray], _Result], items: np.ndarray) -> Sequence[_Result]:
    """``work(share)`` for contiguous shares of ``items`` (1-D), on :func:`thread_count` threads.

    ``work`` must release the GIL (a ``nogil=True`` kernel) and write disjoint outputs per
    share. The calling thread works too: it and ``thread_count() − 1`` pool threads take the
    shares in order, each the next one left, until none is (a thread that finishes early takes
    another). With one thread, or fewer items than two shares, ``work`` runs once on the
    caller's thread with all of ``items``. Results come back in share order; an exception in any
    share is raised here (the first share's that failed), after every thread has stopped.
    """
    items = np.asarray(items)
    if items.ndim != 1:
        raise ValueError(f"items: expected a 1-D array, got shape {items.shape}")
    threads = thread_count()
    n_shares = min(threads * SHARES_PER_THREAD, len(items))
    if threads == 1 or n_shares < 2:
        return [work(items)]
    shares = np.array_split(items, n_shares)
    results: list[_Result | None] = [None] * n_shares
    errors: dict[int, BaseException] = {}
    next_share = itertools.count()  # next() is atomic: each share is taken once

    def drain() -> None:
        for index in iter(next_share.__next__, None):
            if index >= n_shares or errors:
                return
            try:
                results[index] = work(shares[index])
            except BaseException as error:  # raised again by the caller
                errors[index] = error

    helpers = [_executor(threads - 1).submit(drain) for _ in range(threads - 1)]
    drain()
    for helper in helpers:
        helper.result()
    if errors:
        raise errors[min(errors)]
    return results  # type: ignore[return-value]
