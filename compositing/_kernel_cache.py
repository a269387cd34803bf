"""Generated numba kernels compiled once per machine, not once per process.

The fused kernels of :mod:`compositing._fused`, :mod:`compositing._gl_fused` and
:mod:`compositing._stack_fused` are generated as Python source from the factor tables
(one kernel per operator, blend state and dtype). Source made by ``exec`` has no file, so
numba cannot cache its machine code and every new process compiled each kernel again
(about 2.5 s before the first 1024² ``src_over`` of a batch job).

:func:`compile_kernel` writes the generated source to a file in a per-user cache
directory instead, named by a SHA-256 of everything the machine code depends on (the
source, the scalar constants injected into its globals, the caller's label — e.g. the
dtype —, numba's and numpy's versions), imports it, and compiles it with
``numba.njit(cache=True)``: numba stores the machine code next to the file and the next
process loads it. A file's name changes whenever its content would, so a cached kernel is
never stale. Files are written atomically (:mod:`compositing._atomic`), so two processes
compiling the same kernel at once each see a whole file.

Where no cache directory can be written (read-only home, sandbox), the kernel is
compiled in memory as before: caching changes start-up time, never results.

Cache directory: ``$BLINN_PHONG_KERNEL_CACHE`` if set, else
``$XDG_CACHE_HOME/blinn-phong-render/kernels`` (default ``~/.cache/…``).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from types import ModuleType

import numba
import numpy as np

from ._atomic import write_text_atomic

__all__ = ["cache_directory", "compile_kernel"]

#: Bumped when the way files are laid out changes.
_LAYOUT = "1"


def cache_directory() -> Path:
    """The directory holding generated kernel sources and numba's cached machine code."""
    explicit = os.environ.get("BLINN_PHONG_KERNEL_CACHE")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "blinn-phong-render" / "kernels"


def _scalar_items(namespace: Mapping[str, object]) -> str:
    """The injected scalar constants as text (their values are frozen into the machine code)."""
    items = []
    for name in sorted(namespace):
        value = namespace[name]
        if isinstance(value, np.generic | int | float | bool | str):
            items.append(f"{name}={type(value).__name__}:{value!r}")
        elif isinstance(value, type):
            items.append(f"{name}=type:{value.__module__}.{value.__qualname__}")
    return ";".join(items)


def _module_from(path: Path, namespace: Mapping[str, object]) -> ModuleType:
    """Import the file at ``path`` as a fresh module whose globals start as ``namespace``."""
    name = f"_compositing_kernel_{path.stem}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:  # pragma: no cover - a .py path always has a loader
        raise ImportError(f"cannot import generated kernel {path}")
    module = importlib.util.module_from_spec(spec)
    module.__dict__.update(namespace)
    sys.modules[name] = module  # numba's cache locator imports nothing, but pickling needs the name
    spec.loader.exec_module(module)
    return module


@functools.cache
def _writable(directory: Path) -> bool:
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError:
        return False
    return True


def compile_kernel(
    src: str,
    namespace: Mapping[str, object],
    label: str,
    *,
    helpers: tuple[str, ...] = (),
    parallel: bool = False,
) -> object:
    """``numba.njit(error_model="numpy", nogil=True)`` of ``kernel`` in ``src``, cached on disk.

    Args:
        src: Python source defining ``kernel`` (and the functions named in ``helpers``).
        namespace: globals the source uses (numpy, constants, intrinsics).
        label: what else the machine code depends on that ``namespace``'s scalars do not show
            (e.g. the kernel kind and dtype); part of the file's hash.
        helpers: functions of ``src`` compiled first (``njit(error_model="numpy")``) so that
            ``kernel`` calls compiled code.
        parallel: compile ``kernel`` with ``parallel=True``.

    Returns:
        The numba dispatcher of ``kernel``.
    """
    options = {"error_model": "numpy", "nogil": True, **({"parallel": True} if parallel else {})}
    directory = cache_directory()
    if not _writable(directory):
        scope = dict(namespace)
        exec(compile(src, f"<generated kernel {label}>", "exec"), scope)
        for name in helpers:
            scope[name] = numba.njit(error_model="numpy")(scope[name])
        return numba.njit(**options)(scope["kernel"])
    digest = hashlib.sha256(
        "\0".join(
            (
                _LAYOUT,
                label,
                numba.__version__,
                np.__version__,
                repr(sorted(options.items())),
                ",".join(helpers),
                _scalar_items(namespace),
                src,
            )
        ).encode()
    ).hexdigest()[:24]
    path = directory / f"k_{digest}.py"
    if not path.exists():
        header = f"# Generated compositing kernel ({label}); safe to delete: it is made again when needed.\n"
        write_text_atomic(path, header + src)
    module = _module_from(path, namespace)
    for name in helpers:
        setattr(module, name, numba.njit(error_model="numpy", cache=True)(getattr(module, name)))
    return numba.njit(cache=True, **options)(module.kernel)
