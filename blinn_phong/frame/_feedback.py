"""What a render tells the user on standard error while it works (private).

* The first compiled render on a machine compiles the renderer's numba kernels (several
  seconds; numba caches them on disk, later processes load them). :func:`announce_compiles`
  listens to numba's ``numba:compile`` event, which fires only for a real compile (not
  for a cache load), and prints ``compiling kernels (once per machine)…`` to stderr the
  first time one of this package's kernels compiles in the process.
* A long render shows progress: :func:`progress_callback` turns ``render``'s
  ``progress`` argument into a callback; the default (``None``) prints
  ``render: <stage> <percent>`` lines to stderr once the render has run for
  :data:`PROGRESS_AFTER` seconds, when stderr is a terminal: short renders, batch
  workers and logs stay silent. ``progress=True``
  prints from the start, ``progress=False`` never; a callable receives
  ``(stage, fraction_done)`` itself and nothing is printed.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

#: Seconds a render runs before the default progress lines start.
PROGRESS_AFTER = 3.0
COMPILE_NOTICE = "compiling kernels (once per machine)…"

_state = {"listening": False, "announced": False}
_lock = threading.Lock()


def _compiling_our_kernel(data: object) -> bool:
    dispatcher = data.get("dispatcher") if isinstance(data, dict) else None
    module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
    return module.startswith("blinn_phong")


def announce_compiles(engine: str) -> None:
    """Print :data:`COMPILE_NOTICE` to stderr when numba first compiles one of our kernels.

    Installs (once per process, and not for ``engine="numpy"`` or without numba) a
    listener on numba's ``numba:compile`` event, which numba triggers only when it
    compiles, never when it loads a kernel from its disk cache.
    """
    if engine == "numpy":
        return
    with _lock:
        if _state["listening"]:
            return
        _state["listening"] = True
    from blinn_phong._numba import numba_available

    if not numba_available():
        return
    from numba.core import event

    class _Notice(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            if not _state["announced"] and _compiling_our_kernel(ev.data):
                _state["announced"] = True
                print(COMPILE_NOTICE, file=sys.stderr, flush=True)

        def on_end(self, ev: event.Event) -> None:
            pass

    event.register("numba:compile", _Notice())


def _interactive() -> bool:
    """True when standard error is a terminal (someone is watching)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def progress_callback(progress: object) -> Callable[[str, float], None] | None:
    """The callback ``render`` reports to, from its ``progress`` argument (module docstring).

    Raises:
        TypeError: ``progress`` is not None, a bool or a callable.
    """
    if progress is False:
        return None
    if callable(progress) and not isinstance(progress, bool):
        return progress
    if progress is not None and progress is not True:
        raise TypeError(
            f"progress: expected None (stderr lines after {PROGRESS_AFTER:g} s), True, False or a "
            f"callable(stage, fraction), got {type(progress).__name__}"
        )
    if progress is None and not _interactive():
        return None
    start = time.perf_counter()
    delay = 0.0 if progress is True else PROGRESS_AFTER

    def report(stage: str, fraction: float) -> None:
        if time.perf_counter() - start >= delay:
            print(f"render: {stage} {fraction:.0%}", file=sys.stderr, flush=True)

    return report


def start_feedback(engine: str, progress: object) -> Callable[[str, float], None] | None:
    """:func:`announce_compiles` for ``engine``, then the progress callback for ``progress``."""
    announce_compiles(engine)
    return progress_callback(progress)
