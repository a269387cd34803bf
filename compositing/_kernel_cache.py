"""One numba kernel cache per user and machine, shared by every checkout, install and process.

numba caches a ``cache=True`` kernel next to its source file (``__pycache__``), so every clone,
worktree or install location compiled every kernel again (minutes for the renderer). This
module gives the kernels of the project's packages (:mod:`blinn_phong`, :mod:`compositing`,
registered with :func:`register_package`) a cache locator of their own
(:class:`numba.core.caching._CacheLocator`, put first in numba's list of locators when numba is
imported); every other numba user in the process keeps numba's default.

Layout, below :func:`cache_directory`::

    <environment>/<package>/<module>-<sources>/   numba's index (.nbi) and machine code (.nbc)
    generated/k_<digest>.py                         generated kernel sources (:func:`compile_kernel`)
    <environment>/generated/k_<digest>-<sources>/   their machine code

* ``<environment>`` (:func:`environment_key`) names what the machine code depends on beside the
  sources: the interpreter, numba, llvmlite and numpy versions, numba's code-generation options
  and the CPU (numba's own ``magic_tuple()``: target triple, CPU name, CPU features). Virtual
  environments with other versions, or a home directory shared by other machines, never read
  each other's entries.
* ``<sources>`` (:func:`source_stamp`) is a SHA-256 of the *contents* — not the path, not the
  modification time — of the module's file and of every project module it imports, directly
  or not. A second clone of the same code at another path finds the same directory and loads
  its kernels; code that differs (another branch, an edit) gets its own directory, so two
  checkouts never overwrite each other's entries, and a kernel that inlines a function of
  another file is compiled again when that file changes (numba alone tracks only the
  kernel's own file).

The project's version number is deliberately not part of the key: the sources' digest is
finer (it changes with every edit between releases, and stays when a release does not touch
the kernels).

Processes share the directory safely: numba writes every file under a temporary name and
renames it into place, and the read-modify-write of an index (:meth:`IndexDataCacheFile.save`)
runs under an exclusive lock of the entry's directory (``fcntl.flock``; without ``fcntl`` —
Windows — numba's own behaviour), so two workers compiling different signatures of one kernel
at once cannot lose or mix entries. Entries not used for :data:`MAX_AGE_DAYS` days (other
versions of the sources, other numba versions) are removed at most once a day
(:func:`prune`): a directory is first renamed away, so a process reading it at that moment
sees it whole or not at all, and at worst compiles again.

Cache directory: ``$BLINN_PHONG_KERNEL_CACHE`` if set, else the platform's user cache
directory: ``$XDG_CACHE_HOME/blinn-phong-render/kernels`` (default ``~/.cache/…``) on Linux,
``~/Library/Caches/blinn-phong-render/kernels`` on macOS,
``%LOCALAPPDATA%\\blinn-phong-render\\kernels`` on Windows. The Blender extension sets the
variable to its own user directory (``addon/__init__.py``). Where the directory cannot be
written, numba's default locators apply (``__pycache__``), and generated kernels compile in
memory: caching changes start-up time, never results.

:func:`compile_clock` measures the seconds numba spends compiling (numba's ``numba:compile``
event, which fires for a compilation and never for a cache load), per module.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.abc
import importlib.util
import os
import re
import shutil
import sys
import threading
import time
import uuid
from collections import defaultdict
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

from ._atomic import write_text_atomic

__all__ = [
    "ENVIRONMENT_VARIABLE",
    "MAX_AGE_DAYS",
    "CompileLog",
    "cache_directory",
    "compile_clock",
    "compile_kernel",
    "environment_key",
    "kernel_module",
    "prune",
    "register_package",
    "source_stamp",
]

#: The variable naming the cache directory (overrides the platform default).
ENVIRONMENT_VARIABLE = "BLINN_PHONG_KERNEL_CACHE"
#: Entries (and generated sources) unused for this many days are removed by :func:`prune`.
MAX_AGE_DAYS = 30.0
#: Seconds between two automatic prunes of one cache directory (any process).
PRUNE_INTERVAL = 86400.0
#: Bumped when the layout of the directory changes.
_LAYOUT = "2"
#: The directory of generated kernel sources, below the cache directory.
GENERATED = "generated"

# --------------------------------------------------------------------------- where


def _user_cache_base() -> Path:
    """The platform's per-user cache directory."""
    if sys.platform == "win32":
        local = os.environ.get("LOCALAPPDATA")
        return Path(local) if local else Path.home() / "AppData" / "Local"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches"
    xdg = os.environ.get("XDG_CACHE_HOME")
    # The XDG specification: a relative path is invalid and must be ignored.
    return Path(xdg) if xdg and os.path.isabs(xdg) else Path.home() / ".cache"


def cache_directory() -> Path:
    """The directory holding every cached kernel (see the module docstring for the choice)."""
    explicit = os.environ.get(ENVIRONMENT_VARIABLE)
    if explicit:
        return Path(explicit).expanduser()
    return _user_cache_base() / "blinn-phong-render" / "kernels"


@functools.cache
def environment_key() -> str:
    """The name of the sub-directory for this interpreter, numba build and CPU.

    Readable head (``cpython-311-numba0.68.1-rocketlake``) and a SHA-256 prefix of everything
    the machine code depends on beside the sources: Python's cache tag and ABI flags, the
    numba, llvmlite and numpy (major.minor) versions, numba's optimisation level, bounds
    checking and debug-info defaults, and numba's ``magic_tuple()`` — the target triple, the
    CPU name and the CPU features numba compiles for (``NUMBA_CPU_NAME``/``NUMBA_CPU_FEATURES``
    respected, as numba does).
    """
    import llvmlite
    import numba
    import numpy as np
    from numba.core import config
    from numba.core.registry import cpu_target

    triple, cpu, features = cpu_target.target_context.codegen().magic_tuple()
    details = (
        _LAYOUT,
        sys.implementation.cache_tag,
        getattr(sys, "abiflags", ""),
        numba.__version__,
        llvmlite.__version__,
        ".".join(np.__version__.split(".")[:2]),
        config.OPT,
        config.BOUNDSCHECK,
        config.DEBUGINFO_DEFAULT,
        triple,
        cpu,
        features,
    )
    digest = hashlib.sha256(repr(details).encode()).hexdigest()[:12]
    safe_cpu = re.sub(r"[^A-Za-z0-9_.-]", "_", str(cpu)) or "cpu"
    return f"{sys.implementation.cache_tag}-numba{numba.__version__}-{safe_cpu}-{digest}"


# --------------------------------------------------------------------------- which sources

#: Registered package directories (resolved) → the package's name (its directory's name).
_PACKAGES: dict[Path, str] = {}
_packages_lock = threading.Lock()

# ``import a.b, c`` and ``from .x import (y, z)`` at any indentation (lazy imports count).
_IMPORT = re.compile(
    rb"^[ \t]*(?:from[ \t]+(\.*[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#;]*)|import[ \t]+([^\n#;]*))",
    re.M,
)


def register_package(directory: str | os.PathLike) -> None:
    """Cache the kernels of the modules in ``directory`` (a package) in :func:`cache_directory`.

    Called by the project's packages when imported (before any of their kernels is compiled).
    Registering makes numba use this module's locator for those files: at once when numba is
    already imported, else as soon as it is.
    """
    path = Path(directory).resolve()
    if path.is_file():
        path = path.parent
    with _packages_lock:
        _PACKAGES[path] = path.name
    _install_locator()


def _package_of(path: Path) -> tuple[Path, str] | None:
    """The registered package directory holding ``path`` and its name, or None."""
    for directory, name in _PACKAGES.items():
        if path.is_relative_to(directory):
            return directory, name
    return None


def _module_path(base: Path, parts: list[str]) -> Path | None:
    """The file of module ``parts`` below ``base`` (a ``.py`` file or a package's ``__init__``)."""
    if not parts:
        init = base / "__init__.py"
        return init if init.is_file() else None
    target = base.joinpath(*parts)
    for candidate in (target.with_suffix(".py"), target / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _resolve(file: Path, module: str, names: list[str]) -> list[Path]:
    """The registered project files an import statement in ``file`` names.

    ``from package import submodule`` depends on the submodule, not on the package's
    ``__init__``; ``from module import name`` on the module.
    """
    level = len(module) - len(module.lstrip("."))
    parts = [p for p in module.lstrip(".").split(".") if p]
    if level:
        base = file.parent
        for _ in range(level - 1):
            base = base.parent
    else:
        if not parts:
            return []
        roots = [d for d, name in _PACKAGES.items() if name == parts[0]]
        if not roots:
            return []
        # Two copies registered (two checkouts in one process): the one beside the importer's package.
        home = _package_of(file)
        beside = [d for d in roots if home is not None and d.parent == home[0].parent]
        base, parts = (beside or roots)[0], parts[1:]
    found: list[Path] = []
    whole_module = not names
    for name in names:
        sub = _module_path(base, [*parts, name])
        if sub is not None:
            found.append(sub)
        else:
            whole_module = True
    if whole_module:
        target = _module_path(base, parts)
        if target is not None:
            found.append(target)
    return [f.resolve() for f in found if _package_of(f.resolve()) is not None]


@functools.cache
def _file_facts(path: Path, mtime_ns: int, size: int) -> tuple[str, tuple[Path, ...]]:
    """SHA-256 of a file's bytes and the project files it imports (memoized per mtime and size)."""
    data = path.read_bytes()
    deps: list[Path] = []
    for match in _IMPORT.finditer(data):
        source, imported, plain = (g.decode("utf-8", "replace") if g else "" for g in match.groups())
        if plain:
            for item in plain.split(","):
                name = item.strip().split(" as ")[0].strip()
                if name:
                    deps += _resolve(path, name, [])
        else:
            listed = re.sub(r"#[^\n]*", "", imported).strip().strip("()").replace("\\", " ")
            names = [item.strip().split(" as ")[0].strip() for item in listed.split(",")]
            deps += _resolve(path, source, [n for n in names if n and n != "*"])
    return hashlib.sha256(data).hexdigest(), tuple(dict.fromkeys(d for d in deps if d != path))


def _facts(path: Path) -> tuple[str, tuple[Path, ...]]:
    st = path.stat()
    return _file_facts(path, st.st_mtime_ns, st.st_size)


def _label(path: Path) -> str:
    """``package/relative/path.py`` of a registered file (never its absolute path)."""
    found = _package_of(path)
    if found is None:
        return path.name
    directory, name = found
    return "/".join((name, *path.relative_to(directory).parts))


def source_stamp(*files: str | os.PathLike) -> str:
    """SHA-256 (hex) of the contents of ``files`` and of every project module they import.

    The imports are followed transitively among the registered packages (import statements
    anywhere in a file, including inside functions); each file enters as its label inside its
    package and its content hash, so the stamp does not depend on where the checkout is.
    """
    seen: dict[Path, str] = {}
    todo = [Path(f).resolve() for f in files]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        digest, deps = _facts(path)
        seen[path] = digest
        todo += [d for d in deps if d not in seen]
    text = "\n".join(sorted(f"{_label(p)} {d}" for p, d in seen.items()))
    return hashlib.sha256(text.encode()).hexdigest()


@functools.cache
def _generated_stamp() -> str:
    """The stamp of generated kernels: every module of the generating package (this one's)."""
    here = Path(__file__).resolve().parent
    return source_stamp(*sorted(here.glob("*.py")))


def _place(py_file: str) -> tuple[str, str] | None:
    """``(directory below the environment, stamp)`` for a kernel defined in ``py_file``, or None."""
    path = Path(py_file)
    if not path.is_absolute() or not path.is_file():
        return None
    path = path.resolve()
    root = cache_directory()
    generated = root / GENERATED
    with contextlib.suppress(OSError):
        generated = generated.resolve()
    if path.parent == generated and path.name.startswith("k_"):
        stamp = _generated_stamp()
        return f"{GENERATED}/{path.stem}-{stamp[:16]}", stamp
    found = _package_of(path)
    if found is None:
        return None
    stamp = source_stamp(path)
    label = _label(path)
    return f"{label.removesuffix('.py')}-{stamp[:16]}", stamp


# --------------------------------------------------------------------------- numba's side

#: Entry directories this process's locators use (their index saves are locked).
_OURS: set[str] = set()
_touched: set[str] = set()
_install_lock = threading.Lock()
_state = {"installed": False, "hooked": False}


@contextlib.contextmanager
def _directory_lock(directory: str) -> Iterator[None]:
    """An exclusive lock of an entry directory across processes (no-op without ``fcntl``)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    os.makedirs(directory, exist_ok=True)
    fd = os.open(os.path.join(directory, ".lock"), os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def _use(directory: str) -> None:
    """Create an entry directory (again, if pruned meanwhile) and mark it used, once a process."""
    os.makedirs(directory, exist_ok=True)
    if directory not in _touched:
        probe = os.path.join(directory, f".probe-{os.getpid()}-{uuid.uuid4().hex[:8]}")
        with open(probe, "wb"):
            pass
        os.unlink(probe)  # writable; and the directory's mtime now says "used"
        _touched.add(directory)


@functools.cache
def _locator_class() -> type:
    from numba.core import caching

    class ProjectCacheLocator(caching._CacheLocator):
        """numba locator for the registered packages' kernels (module docstring of
        :mod:`compositing._kernel_cache`)."""

        def __init__(self, py_func: object, py_file: str, directory: str, stamp: str) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path = directory
            self._stamp = stamp

        def ensure_cache_path(self) -> None:
            _use(self._cache_path)

        def get_cache_path(self) -> str:
            return self._cache_path

        def get_source_stamp(self) -> str:
            return self._stamp

        def get_disambiguator(self) -> str:
            return str(self._lineno)

        @classmethod
        def from_function(cls, py_func: object, py_file: str) -> ProjectCacheLocator | None:
            try:
                place = _place(py_file)
                if place is None:
                    return None
                root = cache_directory()
                subpath, stamp = place
                # The module's import name too: a vendored copy (the Blender extension's
                # ``bl_ext.….blinn_phong.frame.fused``) may have the same sources as
                # ``blinn_phong.frame.fused``,
                # but its cached kernels refer to its own modules by name.
                module = str(getattr(py_func, "__module__", "") or "")
                subpath += "-" + hashlib.sha256(module.encode()).hexdigest()[:8]
                directory = os.path.join(root, environment_key(), *subpath.split("/"))
                locator = cls(py_func, py_file, directory, stamp)
                locator.ensure_cache_path()
            except OSError:
                return None  # not writable: numba's own locators decide
            _OURS.add(directory)
            _maybe_prune(root)
            return locator

    return ProjectCacheLocator


def _register_with_numba() -> None:
    """Put the project locator first in numba's list and lock index saves in its directories."""
    with _install_lock:
        if _state["installed"]:
            return
        from numba.core import caching

        locator = _locator_class()
        if locator not in caching.CacheImpl._locator_classes:
            caching.CacheImpl._locator_classes.insert(0, locator)
        original = caching.IndexDataCacheFile.save
        if not getattr(original, "_project_locked", False):

            def save(self: object, key: object, data: object) -> None:
                directory = self._cache_path
                if directory not in _OURS:
                    return original(self, key, data)
                with _directory_lock(directory):
                    return original(self, key, data)

            save._project_locked = True
            caching.IndexDataCacheFile.save = save
        _state["installed"] = True


class _AfterImport(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Runs :func:`_register_with_numba` right after ``numba.core.caching`` is executed.

    The project's packages do not import numba when they are imported (the numpy engine
    needs no compiler), and numba creates a kernel's cache when the kernel is decorated; so
    the locator is registered when numba's caching module is first imported, before numba
    can decorate anything.
    """

    target = "numba.core.caching"

    def __init__(self) -> None:
        self._loader: importlib.abc.Loader | None = None

    def find_spec(self, fullname: str, path: object, target: object = None) -> object:
        if fullname != self.target:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None:
                break
        else:
            return None
        self._loader = spec.loader
        spec.loader = self
        return spec

    def create_module(self, spec: object) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        module.__spec__.loader = module.__loader__ = self._loader
        self._loader.exec_module(module)
        with contextlib.suppress(ValueError):
            sys.meta_path.remove(self)
        _register_with_numba()


def _install_locator() -> None:
    """Register the locator now (numba imported) or when numba's caching module is imported."""
    if _state["installed"]:
        return
    if "numba.core.caching" in sys.modules:
        _register_with_numba()
        return
    with _install_lock:
        if not _state["hooked"]:
            sys.meta_path.insert(0, _AfterImport())
            _state["hooked"] = True


def kernel_module(dispatcher: object) -> str:
    """The project module (``blinn_phong.frame.fused``) or other module a numba dispatcher's function is in.

    Named by its file inside the registered package, so vendored copies (the Blender
    extension's ``bl_ext.….blinn_phong.frame.fused``) read the same; generated compositing kernels
    are ``compositing (generated)``.
    """
    func = getattr(dispatcher, "py_func", None)
    module = getattr(func, "__module__", None) or "?"
    code = getattr(func, "__code__", None)
    if code is None:
        return module
    path = Path(code.co_filename)
    if path.name.startswith("k_") and path.parent.name == GENERATED:
        return "compositing (generated)"
    if path.is_absolute() and _package_of(path.resolve()) is not None:
        return _label(path.resolve()).removesuffix(".py").removesuffix("/__init__").replace("/", ".")
    return module


# --------------------------------------------------------------------------- pruning


def _age(path: Path, now: float) -> float:
    try:
        return now - path.stat().st_mtime
    except OSError:
        return 0.0


def _remove(path: Path, root: Path) -> bool:
    """Rename ``path`` away (atomic) then delete it; False when another process got there first."""
    trash = root / f".trash-{uuid.uuid4().hex}"
    try:
        os.replace(path, trash)
    except OSError:
        return False
    if trash.is_dir():
        shutil.rmtree(trash, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            trash.unlink()
    return True


def prune(
    root: str | os.PathLike | None = None, max_age_days: float = MAX_AGE_DAYS, now: float | None = None
) -> list[Path]:
    """Remove cache entries not used for ``max_age_days`` days; return what was removed.

    An entry is one kernel module's directory for one version of its sources in one
    environment (its modification time is refreshed by every process that uses it), a
    generated kernel source, or anything of an older layout at the top. Removal renames
    first, so no process ever reads a half-deleted entry; a process still holding a removed
    entry compiles and writes it again.

    Args:
        root: the cache directory (default :func:`cache_directory`).
        max_age_days: age in days (modification time) beyond which an entry is removed; ≥ 0.
        now: the current time (seconds since the epoch; default ``time.time()``).
    """
    if not max_age_days >= 0:
        raise ValueError(f"max_age_days: expected a number of days >= 0, got {max_age_days!r}")
    root = Path(root) if root is not None else cache_directory()
    now = time.time() if now is None else now
    limit = max_age_days * 86400.0
    removed: list[Path] = []
    if not root.is_dir():
        return removed
    for top in list(root.iterdir()):
        if top.name.startswith(".trash-"):
            if _age(top, now) > 3600.0:  # left by a prune that was killed
                shutil.rmtree(top, ignore_errors=True)
            continue
        if top.name.startswith("."):
            continue
        if top.name == GENERATED and top.is_dir():
            entries = [p for p in top.iterdir() if p.name.startswith("k_")]
        elif top.is_dir() and "-numba" in top.name:
            entries = [leaf for group in top.iterdir() if group.is_dir() for leaf in group.iterdir()]
        else:
            entries = [top]  # a file or directory of an older layout
        for entry in entries:
            if _age(entry, now) > limit and _remove(entry, root):
                removed.append(entry)
        if top.is_dir() and top.name != GENERATED and top not in removed:
            for group in [g for g in top.iterdir() if g.is_dir()] + [top]:
                with contextlib.suppress(OSError):
                    group.rmdir()  # only when empty
    return removed


_pruned: set[str] = set()


def _maybe_prune(root: Path) -> None:
    """:func:`prune` once a :data:`PRUNE_INTERVAL` per cache directory (first process to notice)."""
    key = str(root)
    if key in _pruned:
        return
    _pruned.add(key)
    marker = root / ".last-prune"
    try:
        if marker.exists() and _age(marker, time.time()) < PRUNE_INTERVAL:
            return
        marker.touch()
        prune(root)
    except OSError:
        pass


# --------------------------------------------------------------------------- compile time


@dataclass
class CompileLog:
    """Seconds numba spent compiling while a :func:`compile_clock` was running.

    Attributes:
        seconds: wall seconds inside outermost compilations (a kernel compiled while another
            one is being compiled — a callee — counts once, inside its caller).
        cpu_seconds: the compiling thread's CPU seconds over the same compilations (numba
            compiles in the calling thread; on a busy machine this moves less than ``seconds``).
        by_module: wall seconds per module of the compiled functions (:func:`kernel_module`),
            each compilation's own time: the project kernels it called and compiled are
            subtracted, numba's library functions it compiled (``np.full``, …) are included;
            the values sum to ``seconds``.
        cpu_by_module: the same in CPU seconds (sum: ``cpu_seconds``).
        by_kernel, cpu_by_kernel: the same per kernel (``module.qualname``).
        compiled: number of compilations (callees and numba's library functions included).
    """

    seconds: float = 0.0
    cpu_seconds: float = 0.0
    by_module: dict[str, float] = field(default_factory=lambda: defaultdict(float))
    cpu_by_module: dict[str, float] = field(default_factory=lambda: defaultdict(float))
    by_kernel: dict[str, float] = field(default_factory=lambda: defaultdict(float))
    cpu_by_kernel: dict[str, float] = field(default_factory=lambda: defaultdict(float))
    compiled: int = 0


def _is_project(module: str) -> bool:
    return module == "compositing (generated)" or module.split(".")[0] in _PACKAGES.values()


@contextlib.contextmanager
def compile_clock() -> Iterator[CompileLog]:
    """Count numba compilations (every thread) while the block runs; yields the live log.

    Listens to numba's ``numba:compile`` event, which numba triggers around a compilation and
    never for a kernel loaded from the disk cache. Without numba, the log stays at zero.
    """
    log = CompileLog()
    try:
        from numba.core import event
    except Exception:  # no numba (or a broken wheel): nothing can compile
        yield log
        return
    stacks = threading.local()
    lock = threading.Lock()

    class _Listener(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            stack = getattr(stacks, "stack", None)
            if stack is None:
                stack = stacks.stack = []
            data = ev.data if isinstance(ev.data, Mapping) else {}
            dispatcher = data.get("dispatcher")
            module = kernel_module(dispatcher)
            name = getattr(getattr(dispatcher, "py_func", None), "__qualname__", "?")
            stack.append([time.perf_counter(), time.thread_time(), 0.0, 0.0, module, f"{module}.{name}"])

        def on_end(self, ev: event.Event) -> None:
            stack = getattr(stacks, "stack", None)
            if not stack:
                return  # started before the clock
            wall0, cpu0, callees, callees_cpu, module, kernel = stack.pop()
            took, cpu = time.perf_counter() - wall0, time.thread_time() - cpu0
            with lock:
                log.compiled += 1
                if stack and not _is_project(module):
                    return  # numba's own helpers (np.full, …) count as their caller's time
                log.by_module[module] += took - callees
                log.cpu_by_module[module] += cpu - callees_cpu
                log.by_kernel[kernel] += took - callees
                log.cpu_by_kernel[kernel] += cpu - callees_cpu
                if stack:
                    stack[-1][2] += took
                    stack[-1][3] += cpu
                else:
                    log.seconds += took
                    log.cpu_seconds += cpu

    with event.install_listener("numba:compile", _Listener()):
        yield log


# --------------------------------------------------------------------------- generated kernels


def _scalar_items(namespace: Mapping[str, object]) -> str:
    """The injected scalar constants as text (their values are frozen into the machine code)."""
    import numpy as np

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
    sys.modules[name] = module  # pickling the compiled kernel needs the module's name
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
    """``numba.njit(error_model="numpy", nogil=True)`` of ``kernel`` in generated ``src``, cached on disk.

    Source made by ``exec`` has no file, so numba could not cache its machine code. The
    source is written instead to ``<cache>/generated/k_<digest>.py``, named by a SHA-256 of
    everything the machine code depends on that the file's content does not show (the scalar
    constants injected into its globals, ``label``, numba's and numpy's versions), imported,
    and compiled with ``cache=True``: its machine code is cached like any project kernel's.
    Files are written atomically (:mod:`compositing._atomic`), so two processes writing the
    same kernel at once each see a whole file. Without a writable cache directory the kernel
    is compiled in memory.

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
    import numba
    import numpy as np

    options = {"error_model": "numpy", "nogil": True, **({"parallel": True} if parallel else {})}
    directory = cache_directory() / GENERATED
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
    if path.exists():
        with contextlib.suppress(OSError):
            os.utime(path)  # used: not pruned
    else:
        header = f"# Generated compositing kernel ({label}); safe to delete: it is made again when needed.\n"
        write_text_atomic(path, header + src)
    module = _module_from(path, namespace)
    for name in helpers:
        setattr(module, name, numba.njit(error_model="numpy", cache=True)(getattr(module, name)))
    return numba.njit(cache=True, **options)(module.kernel)


register_package(Path(__file__).resolve().parent)
