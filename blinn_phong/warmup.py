"""Compile the compiled engine's kernels ahead of the first frame, in a process of their own.

numba compiles a kernel at its first call and keeps the machine code in the per-user kernel cache
(:mod:`compositing._kernel_cache`), so the first frame of each method on a machine waits for its
kernels (seconds per method, ``docs/compile.md``). :func:`warm` renders tiny frames that use
every method — each shadow and transparency method, fog, textures, one and several samples per
pixel, the planner's tolerance — so that every kernel is compiled into the cache, and writes a
marker (:func:`marker_path`) when it has finished: later processes load the kernels.

Run it as ``python -m blinn_phong.warmup`` (a render farm before a batch, a container image, a
CI cache). The Blender extension starts it in a background process (:func:`start_background`)
the first time a session renders while the cache is not warm, and renders with the numpy engine
until it has finished: compiling inside Blender's own process would hold Python's global
interpreter lock, and Blender's interface (its panels are Python) would freeze meanwhile.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["CASES", "is_warm", "main", "marker_path", "selected_cases", "start_background", "warm"]

#: The frames :func:`warm` renders: name and keyword arguments of :func:`blinn_phong.frame.render`
#: (scene ``"opaque"``: a sphere on a floor; ``"glass"``: with a transparent sphere;
#: ``"textured"``: a textured floor).
_SHADOWS = ("planar", "shadow_map", "ray_traced", "shadow_volume", "soft")
_TRANSPARENCY = (
    "draw_last", "sort_objects", "sort_triangles", "depth_peeling", "a_buffer", "weighted_blended",
)  # fmt: skip
CASES: tuple[tuple[str, str, dict[str, object]], ...] = (
    ("plain 1 sample", "opaque", {"shadows": "none"}),
    ("plain 4 samples", "opaque", {"shadows": "none", "samples": 4}),
    ("default plan 4 samples", "opaque", {"samples": 4}),
    ("tolerance 4", "opaque", {"tolerance": 4}),
    *((f"shadows {m}", "opaque", {"shadows": m}) for m in _SHADOWS),
    *((f"transparency {m}", "glass", {"shadows": "none", "transparency": m}) for m in _TRANSPARENCY),
    ("a_buffer 4 samples", "glass", {"shadows": "none", "transparency": "a_buffer", "samples": 4}),
    ("fog", "opaque", {"shadows": "none", "fog": "exp"}),
    ("shadow map and fog", "opaque", {"shadows": "shadow_map", "fog": "exp"}),
    ("textures", "textured", {"shadows": "none"}),
    ("cryptomatte", "opaque", {"shadows": "none", "cryptomatte": "object"}),
)

#: The size of the warm-up frames (pixels): small, as the kernels do not depend on it.
SIZE = (32, 18)


def _scenes() -> dict[str, object]:
    import blinn_phong as bp
    from blinn_phong.model.primitives import grid_plane, uv_sphere

    positions, triangles, normals = uv_sphere(16, 8)
    sphere = bp.Mesh(positions, triangles, normals, material=bp.Material(diffuse=(0.8, 0.1, 0.1)))
    fp, ft, fn = grid_plane(1, 1, size=(8.0, 8.0))
    flat = np.array([[1, 0, 0, 0], [0, 0, 1, -1], [0, -1, 0, 0], [0, 0, 0, 1]], float)
    floor = bp.Mesh(fp, ft, fn, transform=flat)
    lights = [bp.DirectionalLight(direction=(-1.0, -2.0, -1.0)), bp.PointLight(position=(2, 3, 2))]
    camera = bp.Camera.perspective(40.0, 16 / 9, 0.1, 100.0, view=bp.look_at((0, 1.5, 6), (0, 0, 0)))
    moved = np.array([[0.6, 0, 0, 0.8], [0, 0.6, 0, -0.2], [0, 0, 0.6, 0.9], [0, 0, 0, 1]], float)
    glass = bp.Mesh(positions, triangles, normals, transform=moved, material=bp.Material(opacity=0.5))
    checker = ((np.indices((8, 8)).sum(axis=0) // 2) % 2).astype(np.float32)
    image = np.stack([checker, checker, checker, np.ones_like(checker)], axis=-1)
    textured = bp.Mesh(
        fp, ft, fn, transform=flat, uv=fp[:, :2] / 8.0 + 0.5,
        material=bp.Material(base_color_texture=bp.Texture(image)),
    )  # fmt: skip
    return {
        "opaque": bp.Scene([sphere, floor], lights, camera),
        "glass": bp.Scene([sphere, floor, glass], lights, camera),
        "textured": bp.Scene([sphere, textured], lights, camera),
    }


def marker_path() -> Path:
    """The file whose presence says a warm-up of this code has completed on this machine.

    In the kernel cache's directory for this interpreter, numba build and CPU
    (:func:`compositing._kernel_cache.environment_key`), named by the digest of this module's
    sources and of every project module it imports (every kernel's module among them:
    :func:`compositing._kernel_cache.source_stamp`) and of its import name (the Blender
    extension's vendored copy keeps kernels of its own).
    """
    from compositing._kernel_cache import cache_directory, environment_key, source_stamp

    digest = hashlib.sha256(f"{source_stamp(__file__)} {__name__}".encode()).hexdigest()[:20]
    return cache_directory() / environment_key() / f"warm-{digest}"


def is_warm() -> bool:
    """True when :func:`warm` has completed for this code, interpreter and machine."""
    try:
        return marker_path().is_file()
    except OSError:
        return False


def selected_cases(only: list[str] | None = None) -> list[tuple[str, str, dict[str, object]]]:
    """The cases of :data:`CASES` whose names start with one of ``only`` (all for None or empty;
    ``$BLINN_PHONG_WARMUP_CASES``, comma-separated, when ``only`` is None).

    Raises:
        ValueError: a prefix matches no case (the message lists the case names).
    """
    if only is None:
        only = [p.strip() for p in os.environ.get("BLINN_PHONG_WARMUP_CASES", "").split(",") if p.strip()]
    if not only:
        return list(CASES)
    names = [name for name, _, _ in CASES]
    unknown = [p for p in only if not any(n.startswith(p) for n in names)]
    if unknown:
        raise ValueError(f"warm-up cases: {unknown} match no case; the cases are {names}")
    return [case for case in CASES if any(case[0].startswith(p) for p in only)]


def warm(
    report: Callable[[str, int, int], None] | None = None, only: list[str] | None = None
) -> dict[str, float]:
    """Render the frames of :data:`CASES` with the compiled engine; after all of them, write
    :func:`marker_path`.

    Args:
        report: ``report(case, index, total)`` before each frame (progress).
        only: name prefixes of the cases to render (:func:`selected_cases`); the marker is
            written only when every case was rendered.

    Returns:
        Seconds per case (compiling, or loading, its kernels and rendering). A case whose method
        cannot run here (ray-traced and soft shadows without Embree) is skipped and reports -1.

    Raises:
        ImportError: numba is not installed (there is nothing to compile).
    """
    import numba  # noqa: F401  (the compiled engine needs it)

    import blinn_phong as bp
    from blinn_phong.shadows.method import embree_available

    cases = selected_cases(only)
    scenes = _scenes()
    seconds: dict[str, float] = {}
    for index, (name, scene, options) in enumerate(cases):
        if report is not None:
            report(name, index, len(cases))
        needs_embree = options.get("shadows") in ("ray_traced", "soft")
        if needs_embree and not embree_available():
            seconds[name] = -1.0
            continue
        kwargs = dict(options)
        if kwargs.get("fog") == "exp":
            kwargs["fog"] = bp.Fog(mode="exp", density=0.1)
        if kwargs.get("cryptomatte") == "object":
            kwargs["cryptomatte"] = bp.Cryptomatte({"object": ["Sphere", "Floor"]})
        started = time.perf_counter()
        bp.render(scenes[scene], *SIZE, engine="numba", **kwargs)  # type: ignore[arg-type]
        seconds[name] = time.perf_counter() - started
    if len(cases) < len(CASES):
        return seconds
    marker = marker_path()
    marker.parent.mkdir(parents=True, exist_ok=True)
    temporary = marker.with_name(f"{marker.name}.{os.getpid()}.tmp")
    temporary.write_text("".join(f"{name}\t{s:.3f}\n" for name, s in seconds.items()), encoding="utf-8")
    os.replace(temporary, marker)
    return seconds


_BOOTSTRAP = """
import importlib, sys, types
packages, target = sys.argv[1], sys.argv[2]
for entry in packages.split(";") if packages else []:
    name, _, paths = entry.partition("=")
    module = types.ModuleType(name)
    module.__path__ = paths.split("|")
    sys.modules[name] = module
sys.exit(importlib.import_module(target).main(sys.argv[3:]))
"""


def start_background(quiet: bool = True, args: tuple[str, ...] = ("--quiet",)) -> subprocess.Popen:
    """Start :func:`main` in a new Python process and return it (without waiting).

    The child runs this very module under its own import name (inside the Blender extension,
    ``bl_ext.<repository>.<extension>.blinn_phong.warmup``: the kernels it caches are the ones
    this process loads), with this process's ``sys.path`` and environment (the kernel cache's
    ``BLINN_PHONG_KERNEL_CACHE`` among it). The enclosing packages are created empty in the
    child, without running their ``__init__`` (the extension's would need Blender). The child's
    interpreter is ``sys.executable`` (Blender's own Python inside Blender); ``args`` are
    :func:`main`'s.
    """
    parts = __name__.split(".")
    packages = []
    for depth in range(1, len(parts) - 2 + 1):  # the packages enclosing ``blinn_phong``
        name = ".".join(parts[:depth])
        module = sys.modules.get(name)
        paths = list(getattr(module, "__path__", []) or [])
        if paths:
            packages.append(f"{name}={'|'.join(paths)}")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    output = subprocess.DEVNULL if quiet else None
    return subprocess.Popen(
        [sys.executable, "-c", _BOOTSTRAP, ";".join(packages), __name__, *args],
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=output,
        stderr=output,
        start_new_session=True,
    )


def main(argv: list[str] | None = None) -> int:
    """``python -m blinn_phong.warmup [--quiet] [--force] [--list]``: compile every kernel
    (:func:`warm`; ``$BLINN_PHONG_WARMUP_CASES`` limits the cases).

    ``--list`` prints this module's import name and the cases, and compiles nothing. Exits 0 when
    the kernels are cached (at once when :func:`is_warm`, unless ``--force``), 1 when numba is
    not installed, 2 for an unknown case or argument.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    unknown = [a for a in args if a not in ("--quiet", "--force", "--list")]
    if unknown:
        print(
            f"blinn_phong.warmup: unknown argument(s) {unknown}; expected --quiet, --force, --list",
            file=sys.stderr,
        )
        return 2
    try:
        cases = selected_cases()
    except ValueError as error:
        print(f"blinn_phong.warmup: {error}", file=sys.stderr)
        return 2
    if "--list" in args:
        print(__name__)
        for name, _, _ in cases:
            print(name)
        return 0
    quiet = "--quiet" in args
    if "--force" not in args and is_warm():
        if not quiet:
            print(f"kernels already compiled ({marker_path()})")
        return 0
    started = time.perf_counter()

    def say(name: str, index: int, total: int) -> None:
        if not quiet:
            print(f"[{index + 1}/{total}] {name} ({time.perf_counter() - started:.1f} s)", flush=True)

    try:
        warm(say)
    except ImportError as error:
        print(f"blinn_phong.warmup: the compiled engine is unavailable: {error}", file=sys.stderr)
        return 1
    if not quiet:
        print(f"kernels compiled in {time.perf_counter() - started:.1f} s ({marker_path()})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
