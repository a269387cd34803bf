"""Build the installable Blender extension zip and validate it with Blender's own validator.

Usage::

    .venv/bin/python tools/build_extension.py [--out dist] [--bpy-root PATH]
    .venv/bin/python tools/build_extension.py --wheels [--platform linux-x64 ...] [--wheel-cache DIR]

Steps:

1. Stage ``addon/`` (the extension root, holding ``blender_manifest.toml``) into a temporary
   directory (never inside the checkout: a read-only checkout builds).
2. Vendor the core packages (``blinn_phong``, ``compositing``) into the staged add-on as
   sub-packages, then rewrite every absolute import of a core package, in the add-on's own modules
   and in the vendored code alike, into the equivalent relative import: ``from blinn_phong.model.scene
   import Mesh`` in ``engine.py`` becomes ``from .blinn_phong.model.scene import Mesh``, and
   ``from compositing.factors import X`` in ``blinn_phong/a.py`` becomes
   ``from ..compositing.factors import X``. In the repository the add-on imports the top-level
   packages by their plain names; the installed extension imports nothing by absolute name and
   cannot pick up another copy of the packages from ``sys.path`` (the approach of pip's
   ``vendoring`` tool).
3. With ``--wheels``: one zip per Python ABI and platform (:data:`TARGETS`). Blender 4.2–5.0
   embed CPython 3.11, 5.1 and later 3.13; each zip carries only the wheels of its Python, and its
   manifest says which Blender versions it is for (``blender_version_min``, and
   ``blender_version_max``, which is exclusive: Blender refuses the zip from that version on), so a
   user downloads about half of what a zip for both Pythons weighs. The wheels are
   :data:`WHEEL_PACKAGES` (what the code imports at run time inside Blender: numba + llvmlite,
   embreex, scipy), at the versions pinned in ``requirements/main.lock``, downloaded with pip,
   unmodified from the package index, into a cache outside the checkout; they are copied into
   ``wheels/`` of the staged add-on and listed in the staged manifest's ``wheels = [...]`` with the
   ``platforms``. numpy is not bundled (every Blender ships its own).
4. Run Blender's extension CLI (``bl_pkg/cli/blender_ext.py`` inside the installed ``bpy`` package,
   plain Python, no Blender binary) to ``build`` the zip (``--split-platforms`` with wheels: one zip
   per platform, renamed to say its Blender versions and Python, e.g.
   ``blinn_phong_render-0.1.0-blender4.2-5.0-python3.11-linux_x64.zip``), then ``validate`` each
   zip, with Blender's own list of valid tags.

Prints the zip path(s) on success; exits non-zero with the validator's message otherwise.
"""

from __future__ import annotations

import argparse
import ast
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ADDON_DIR = REPO / "addon"
VENDORED = ("blinn_phong", "compositing")
IGNORED = shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "*.zip", "tests")
LOCK = REPO / "requirements" / "main.lock"

WHEEL_PACKAGES = ("numba", "llvmlite", "embreex", "scipy")
"""Bundled distributions: what the add-on imports at run time inside Blender and Blender lacks.

* numba + llvmlite: the compiled kernels (without them the numpy kernels run, with a warning);
* embreex: Embree, for ray-traced and soft shadows;
* scipy: ``scipy.spatial.ConvexHull`` in :func:`blinn_phong.geometry.mesh_facts._projected_width`, which the
  planner calls to size a shadow map for a directional light (no fallback: a render needs it).

Not bundled: numpy (every Blender ships its own: 1.26 in 4.2–5.0, 2.x in 5.1+, both supported by
the pinned versions), and :data:`NOT_BUNDLED`: OpenImageIO, colour-science and the rest are imported
only by the repository's command lines (``compositing.io`` under ``addon.batch``, ``addon.demo``,
``python -m compositing``), which run in the project's environment; inside Blender the add-on reads
and writes images through Blender's image API (``verify_operator``). colour-science would also pull
in scipy, imageio and typing-extensions at import (``colour.algebra`` imports ``scipy.interpolate``).
``tests/addon/test_addon_packaging.py`` checks both lists against the imports of every module in
the zip."""

NOT_BUNDLED: dict[str, str] = {
    "OpenImageIO": "compositing.io, addon.batch, addon.verify (command lines); the add-on uses Blender's API",
    "colour": "compositing.io only (sRGB transfer functions for 8/16-bit files)",
    "PIL": "compositing.demo only (a repository command line)",
    "dask": "addon.batch's Dask cluster mode (a repository command line)",
    "distributed": "addon.batch's Dask cluster mode (a repository command line)",
    "tqdm": "addon.batch's progress bar (a repository command line)",
}
"""Third-party modules imported somewhere in the zip's code but deliberately not bundled, and why."""


@dataclass(frozen=True)
class Target:
    """One Python ABI of Blender: the Blender versions embedding it and the zip's name for them.

    ``blender_max`` is exclusive, as the manifest's ``blender_version_max`` (Blender refuses the
    extension from that version on); None: no upper bound.
    """

    python: str
    blender_min: str
    blender_max: str | None
    label: str


TARGETS: tuple[Target, ...] = (
    Target("3.11", "4.2.0", "5.1.0", "blender4.2-5.0-python3.11"),
    Target("3.13", "5.1.0", None, "blender5.1+-python3.13"),
)
"""Blender 4.2–5.0 embed CPython 3.11; 5.1 and later 3.13 (one wheel set and one zip each)."""

PLATFORMS: dict[str, tuple[str, ...]] = {
    "linux-x64": ("manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"),
    "windows-x64": ("win_amd64",),
    "macos-arm64": ("macosx_14_0_arm64", "macosx_12_0_arm64", "macosx_11_0_arm64"),
}
"""Blender platform -> pip ``--platform`` tags accepted for it (newest first). ``macos-x64`` is
absent: numba publishes no macOS x86-64 wheel for the pinned version (the package index offers
them only up to 0.63.0b1), so Intel Macs get the extension without wheels (numpy kernels)."""


class BuildError(RuntimeError):
    """The extension could not be assembled or failed Blender's validation."""


def find_bpy_root(python_root: Path | None = None) -> Path:
    """Return the versioned ``bpy/<X.Y>`` directory of the installed ``bpy`` package.

    Args:
        python_root: an explicit ``.../site-packages/bpy`` directory; default: found through
            ``importlib.util.find_spec("bpy")`` without importing bpy.
    """
    if python_root is None:
        import importlib.util

        spec = importlib.util.find_spec("bpy")
        if spec is None or not spec.submodule_search_locations:
            raise BuildError("the bpy package is not installed in this Python; pass --bpy-root")
        python_root = Path(next(iter(spec.submodule_search_locations)))
    versions = sorted(p for p in python_root.iterdir() if re.fullmatch(r"\d+\.\d+", p.name))
    if not versions:
        raise BuildError(f"no <major>.<minor> directory inside {python_root}")
    return versions[-1]


def relativize_imports(source: str, depth: int, packages: tuple[str, ...] = VENDORED) -> str:
    """Rewrite absolute imports of ``packages`` in ``source`` into relative imports.

    Args:
        source: Python source of one module of a vendored package.
        depth: number of package levels between the extension root and the module's package
            (``engine.py`` -> 0, ``blinn_phong/x.py`` -> 1, ``blinn_phong/sub/y.py`` -> 2).
        packages: top-level package names that are vendored next to each other.

    Returns:
        The rewritten source. ``import pkg`` becomes ``from <dots> import pkg``;
        ``import pkg.sub as name`` becomes ``from <dots>pkg import sub as name``;
        ``from pkg.sub import x`` becomes ``from <dots>pkg.sub import x``, where ``<dots>`` is
        ``depth + 1`` dots.

    Raises:
        BuildError: for forms with no exact relative equivalent (``import pkg.sub`` without ``as``,
            or several names in one ``import`` statement that mixes vendored and other modules).
    """
    dots = "." * (depth + 1)
    lines = source.splitlines(keepends=True)
    edits: list[tuple[int, int, int, str]] = []  # (line index, start col, end col, replacement)
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] not in packages:
                continue
            line = lines[node.lineno - 1]
            match = re.compile(r"from\s+" + re.escape(node.module) + r"\b").match(line, node.col_offset)
            if match is None:
                raise BuildError(f"line {node.lineno}: cannot rewrite {line.strip()!r}")
            edits.append((node.lineno - 1, match.start(), match.end(), f"from {dots}{node.module}"))
        elif isinstance(node, ast.Import):
            names = [a for a in node.names if a.name.split(".")[0] in packages]
            if not names:
                continue
            if len(node.names) != 1 or node.end_lineno != node.lineno:
                raise BuildError(f"line {node.lineno}: split this import into one statement per module")
            alias = names[0]
            head, _, tail = alias.name.rpartition(".")
            if head and alias.asname is None:
                raise BuildError(f"line {node.lineno}: write 'import {alias.name} as <name>' or 'from'")
            target = f"from {dots}{head} import {tail}" if head else f"from {dots} import {tail}"
            if alias.asname:
                target += f" as {alias.asname}"
            line = lines[node.lineno - 1]
            edits.append((node.lineno - 1, node.col_offset, node.end_col_offset, target))
    for index, start, end, text in sorted(edits, reverse=True):
        lines[index] = lines[index][:start] + text + lines[index][end:]
    return "".join(lines)


def stage(build_dir: Path) -> Path:
    """Copy the add-on and vendor the core packages into ``build_dir``; return the staged root."""
    if build_dir.exists():
        shutil.rmtree(build_dir)
    shutil.copytree(ADDON_DIR, build_dir, ignore=IGNORED)
    for package in VENDORED:
        if (build_dir / package).exists():
            raise BuildError(f"addon/{package} exists and would clash with the vendored core package")
        shutil.copytree(REPO / package, build_dir / package, ignore=IGNORED)
    for module in build_dir.rglob("*.py"):
        depth = len(module.relative_to(build_dir).parts) - 1
        original = module.read_text(encoding="utf-8")
        try:
            rewritten = relativize_imports(original, depth)
        except BuildError as error:
            raise BuildError(f"{module.relative_to(build_dir)}: {error}") from None
        if rewritten != original:
            module.write_text(rewritten, encoding="utf-8")
    return build_dir


def run_blender_ext(bpy_root: Path, *args: str) -> str:
    """Run Blender's extension CLI with plain Python; return its output or raise BuildError."""
    cli = bpy_root / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    tags = bpy_root / "scripts" / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    command = [sys.executable, str(cli), *args, f"--valid-tags={tags}"]
    done = subprocess.run(command, capture_output=True, text=True, check=False, timeout=300)
    output = done.stdout + done.stderr
    if done.returncode != 0 or "error" in output.lower():
        raise BuildError(f"{' '.join(args[:1])} failed (exit {done.returncode}):\n{output}")
    return output


def pinned_versions(names: tuple[str, ...] = WHEEL_PACKAGES, lock: Path = LOCK) -> dict[str, str]:
    """``name -> version`` of ``names`` as pinned in the lock file (``name==version`` lines)."""
    pins: dict[str, str] = {}
    for line in lock.read_text(encoding="utf-8").splitlines():
        match = re.fullmatch(r"([A-Za-z0-9_.\-]+)==([^\s;]+)", line.strip())
        if match:
            pins[match.group(1).lower().replace("_", "-")] = match.group(2)
    missing = [n for n in names if n not in pins]
    if missing:
        raise BuildError(f"{lock}: no pinned version for {missing}")
    return {n: pins[n] for n in names}


def default_wheel_cache() -> Path:
    """Where downloaded wheels are kept between builds (outside the checkout)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "blinn-phong-render" / "wheels"


def download_wheels(platform: str, cache: Path, python: str) -> list[Path]:
    """Download :data:`WHEEL_PACKAGES` for one Blender platform and one Python (``"3.11"``).

    Uses ``pip download --only-binary=:all: --no-deps`` with the pinned versions (the dependency
    closure is :data:`WHEEL_PACKAGES` itself), into ``cache/<platform>-py<python>``; pip skips
    files already there. Returns the paths of the pinned wheels (other files in the cache, from
    builds with other pins or packages, are left out).
    """
    if platform not in PLATFORMS:
        raise BuildError(f"platform: expected one of {list(PLATFORMS)}, got {platform!r}")
    pins = pinned_versions()
    requirements = [f"{name}=={version}" for name, version in pins.items()]
    dest = cache / f"{platform}-py{python}"
    dest.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check"]
    command += ["--only-binary=:all:", "--no-deps", "--python-version", python, "--dest", str(dest)]
    for tag in PLATFORMS[platform]:
        command += ["--platform", tag]
    done = subprocess.run(command + requirements, capture_output=True, text=True, check=False, timeout=1800)
    if done.returncode != 0:
        raise BuildError(f"pip download for {platform}, Python {python} failed:\n{done.stdout}{done.stderr}")
    wheels = []
    for wheel in sorted(dest.glob("*.whl")):
        name, version = wheel.name.split("-")[:2]
        if pins.get(name.lower().replace("_", "-")) == version:
            wheels.append(wheel)
    found = {w.name.split("-")[0].lower().replace("_", "-") for w in wheels}
    if found != set(pins):
        raise BuildError(f"{dest}: no wheel for {sorted(set(pins) - found)} after pip download")
    return wheels


def add_wheels(staged: Path, wheels: list[Path], platforms: list[str]) -> None:
    """Copy ``wheels`` into ``staged/wheels`` and list them (and ``platforms``) in the staged manifest."""
    target = staged / "wheels"
    target.mkdir()
    for wheel in wheels:
        shutil.copy2(wheel, target / wheel.name)
    manifest = staged / "blender_manifest.toml"
    text = manifest.read_text(encoding="utf-8")
    if re.search(r"^(wheels|platforms)\s*=", text, flags=re.MULTILINE):
        raise BuildError(
            "blender_manifest.toml: 'wheels' and 'platforms' are written by the build, remove them"
        )
    listing = ",\n".join(f'  "./wheels/{w.name}"' for w in wheels)
    fields = f"platforms = {json_list(platforms)}\nwheels = [\n{listing},\n]\n\n"
    first_table = re.search(r"^\[", text, flags=re.MULTILINE)
    at = first_table.start() if first_table else len(text)
    manifest.write_text(text[:at] + fields + text[at:], encoding="utf-8")


def json_list(items: list[str]) -> str:
    """A TOML array of strings."""
    return "[" + ", ".join(f'"{item}"' for item in items) + "]"


def set_blender_versions(staged: Path, target: Target) -> None:
    """Narrow the staged manifest's Blender range to ``target``'s (``blender_version_min``/``_max``).

    The range is the intersection of the manifest's and the target's; ``blender_version_max`` is
    exclusive, as Blender reads it.

    Raises:
        BuildError: the manifest's range does not meet the target's.
    """
    manifest_path = staged / "blender_manifest.toml"
    text = manifest_path.read_text(encoding="utf-8")
    manifest = tomllib.loads(text)
    low = max(manifest["blender_version_min"], target.blender_min, key=version_tuple)
    highs = [v for v in (manifest.get("blender_version_max"), target.blender_max) if v]
    high = min(highs, key=version_tuple) if highs else None
    if high is not None and version_tuple(low) >= version_tuple(high):
        raise BuildError(
            f"blender_manifest.toml: Blender {manifest['blender_version_min']}"
            f"–{manifest.get('blender_version_max', '')} does not meet Python {target.python}'s "
            f"Blender {target.blender_min}–{target.blender_max or ''}"
        )
    text = re.sub(r"^blender_version_max\s*=.*\n", "", text, flags=re.MULTILINE)
    line = f'blender_version_min = "{low}"\n' + (f'blender_version_max = "{high}"\n' if high else "")
    text, count = re.subn(r"^blender_version_min\s*=.*\n", line, text, count=1, flags=re.MULTILINE)
    if count != 1:
        raise BuildError("blender_manifest.toml: no blender_version_min line")
    manifest_path.write_text(text, encoding="utf-8")


def version_tuple(version: str) -> tuple[int, ...]:
    """``"4.2.0"`` -> ``(4, 2, 0)``."""
    return tuple(int(part) for part in version.split("."))


def targets_for(manifest: dict) -> list[Target]:
    """The :data:`TARGETS` whose Blender range meets the manifest's."""
    low = version_tuple(manifest["blender_version_min"])
    high = version_tuple(manifest["blender_version_max"]) if manifest.get("blender_version_max") else None
    return [
        t
        for t in TARGETS
        if (t.blender_max is None or low < version_tuple(t.blender_max))
        and (high is None or version_tuple(t.blender_min) < high)
    ]


def target_for_blender(version: tuple[int, ...]) -> Target:
    """The entry of :data:`TARGETS` for a Blender version, e.g. ``(4, 5, 3)`` -> Python 3.11."""
    for target in TARGETS:
        above = tuple(version) >= version_tuple(target.blender_min)
        if above and (target.blender_max is None or tuple(version) < version_tuple(target.blender_max)):
            return target
    raise BuildError(
        f"Blender {'.'.join(map(str, version))}: not supported (supported from {TARGETS[0].blender_min})"
    )


def zip_name(manifest: dict, target: Target, platform: str) -> str:
    """``<id>-<version>-<label>-<platform>.zip``, e.g. ``…-blender4.2-5.0-python3.11-linux_x64.zip``."""
    return f"{manifest['id']}-{manifest['version']}-{target.label}-{platform.replace('-', '_')}.zip"


def build(
    out_dir: Path,
    bpy_root: Path | None = None,
    build_dir: Path | None = None,
    *,
    wheels: bool = False,
    platforms: tuple[str, ...] = ("linux-x64",),
    wheel_cache: Path | None = None,
) -> Path:
    """Assemble, build and validate the extension; return the path of the (first) zip.

    Args:
        out_dir: directory receiving ``<id>-<version>.zip`` (with ``wheels``: one zip per
            :data:`TARGETS` entry and platform, named by :func:`zip_name`).
        bpy_root: ``bpy/<X.Y>`` directory holding Blender's scripts (default: the installed bpy).
        build_dir: staging directory (default: a temporary directory, removed afterwards).
        wheels: bundle the compiled dependencies (:func:`download_wheels`).
        platforms: Blender platforms to bundle wheels for (keys of :data:`PLATFORMS`).
        wheel_cache: download cache (default :func:`default_wheel_cache`).
    """
    zips = build_all(
        out_dir, bpy_root, build_dir, wheels=wheels, platforms=platforms, wheel_cache=wheel_cache
    )
    return zips[0]


def build_all(
    out_dir: Path,
    bpy_root: Path | None = None,
    build_dir: Path | None = None,
    *,
    wheels: bool = False,
    platforms: tuple[str, ...] = ("linux-x64",),
    wheel_cache: Path | None = None,
) -> list[Path]:
    """:func:`build`, returning every zip written (with ``wheels``: per target, then per platform)."""
    bpy_root = bpy_root or find_bpy_root()
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="blinn_phong_extension_") as scratch:
        root = build_dir or Path(scratch) / "extension"
        if not wheels:
            staged = stage(root)
            manifest = tomllib.loads((staged / "blender_manifest.toml").read_text(encoding="utf-8"))
            zip_path = out_dir / f"{manifest['id']}-{manifest['version']}.zip"
            zip_path.unlink(missing_ok=True)
            run_blender_ext(
                bpy_root, "build", "--source-dir", str(staged), "--output-filepath", str(zip_path)
            )
            run_blender_ext(bpy_root, "validate", str(zip_path))
            return [zip_path]
        cache = wheel_cache or default_wheel_cache()
        manifest = tomllib.loads((ADDON_DIR / "blender_manifest.toml").read_text(encoding="utf-8"))
        zips: list[Path] = []
        for target in targets_for(manifest):
            staged = stage(root / target.label)
            set_blender_versions(staged, target)
            files: dict[str, Path] = {}
            for platform in platforms:
                for wheel in download_wheels(platform, cache, target.python):
                    files.setdefault(wheel.name, wheel)  # pure-Python wheels are shared by every platform
            add_wheels(staged, [files[name] for name in sorted(files)], list(platforms))
            built = Path(scratch) / "zips" / target.label
            built.mkdir(parents=True)
            run_blender_ext(
                bpy_root,
                *("build", "--source-dir", str(staged), "--output-dir", str(built), "--split-platforms"),
            )
            for platform in platforms:
                written = built / f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"
                if not written.exists():
                    raise BuildError(f"Blender's build wrote no {written.name} for Python {target.python}")
                run_blender_ext(bpy_root, "validate", str(written))
                zip_path = out_dir / zip_name(manifest, target, platform)
                shutil.move(written, zip_path)  # replaces an older build only once this one validated
                zips.append(zip_path)
        return zips


def main(argv: list[str] | None = None) -> int:
    """Command-line entry: build + validate, print the zip path(s)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "dist", help="output directory (default dist/)")
    parser.add_argument("--bpy-root", type=Path, default=None, help="site-packages/bpy directory")
    parser.add_argument(
        "--wheels", action="store_true", help="bundle numba, llvmlite, embreex, scipy: one zip per Python ABI"
    )
    parser.add_argument(
        "--platform",
        action="append",
        choices=sorted(PLATFORMS),
        help="with --wheels: a Blender platform to build for (repeatable; default linux-x64)",
    )
    parser.add_argument("--wheel-cache", type=Path, default=None, help="download cache for the wheels")
    args = parser.parse_args(argv)
    try:
        bpy_root = find_bpy_root(args.bpy_root) if args.bpy_root else None
        zips = build_all(
            args.out,
            bpy_root,
            wheels=args.wheels,
            platforms=tuple(args.platform or ("linux-x64",)),
            wheel_cache=args.wheel_cache,
        )
    except BuildError as error:
        print(f"build_extension: {error}", file=sys.stderr)
        return 1
    for zip_path in zips:
        print(zip_path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
