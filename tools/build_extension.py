"""Build the installable Blender extension zip and validate it with Blender's own validator.

Usage::

    .venv/bin/python tools/build_extension.py [--out dist] [--bpy-root PATH]
    .venv/bin/python tools/build_extension.py --wheels [--platform linux-x64 ...] [--wheel-cache DIR]

Steps:

1. Stage ``addon/`` (the extension root, holding ``blender_manifest.toml``) into a temporary
   directory (never inside the checkout: a read-only checkout builds).
2. Vendor the core packages (``blinn_phong``, ``compositing``) into the staged add-on as
   sub-packages, then rewrite every absolute import of a core package, in the add-on's own modules
   and in the vendored code alike, into the equivalent relative import: ``from blinn_phong.scene
   import Mesh`` in ``engine.py`` becomes ``from .blinn_phong.scene import Mesh``, and
   ``from compositing.factors import X`` in ``blinn_phong/a.py`` becomes
   ``from ..compositing.factors import X``. In the repository the add-on imports the top-level
   packages by their plain names; the installed extension imports nothing by absolute name and
   cannot pick up another copy of the packages from ``sys.path`` (the approach of pip's
   ``vendoring`` tool).
3. With ``--wheels``: download the compiled dependencies (:data:`WHEEL_PACKAGES`: numba + llvmlite,
   embreex, colour-science and what they need, at the versions pinned in
   ``requirements/main.lock``; numpy is not bundled, every Blender ships its own) with pip, unmodified
   from the package index, once per platform and per Python (3.11 for Blender 4.2–5.0, 3.13 for
   5.1+), into a cache outside the checkout; copy them into ``wheels/`` of the staged add-on and list
   them in the staged manifest's ``wheels = [...]`` with the ``platforms``. Blender installs only the
   wheels matching its own platform and Python.
4. Run Blender's extension CLI (``bl_pkg/cli/blender_ext.py`` inside the installed ``bpy`` package,
   plain Python, no Blender binary) to ``build`` the zip (``--split-platforms`` with wheels: one zip
   per platform), then ``validate`` each zip, with Blender's own list of valid tags.

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
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ADDON_DIR = REPO / "addon"
VENDORED = ("blinn_phong", "compositing")
IGNORED = shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "*.zip", "tests")
LOCK = REPO / "requirements" / "main.lock"

WHEEL_PACKAGES = (
    "numba",
    "llvmlite",
    "embreex",
    "colour-science",
    "scipy",
    "imageio",
    "pillow",
    "typing-extensions",
)
"""Bundled distributions: the compiled kernels (numba, llvmlite), Embree (embreex), colour-science and
its run-time dependencies (scipy, imageio → pillow, typing-extensions). numpy is left out: Blender
bundles it (1.26 in 4.2–5.0, 2.x in 5.1+) and every pinned version here supports both."""

PYTHON_VERSIONS = ("3.11", "3.13")
"""Blender 4.2–5.0 embed CPython 3.11; 5.1 and later 3.13."""

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


def download_wheels(
    platform: str, cache: Path, python_versions: tuple[str, ...] = PYTHON_VERSIONS
) -> list[Path]:
    """Download :data:`WHEEL_PACKAGES` for one Blender platform and every Python in ``python_versions``.

    Uses ``pip download --only-binary=:all: --no-deps`` with the pinned versions (the dependency
    closure is :data:`WHEEL_PACKAGES` itself), into ``cache/<platform>-py<version>``; pip skips
    files already there. Returns the wheel paths.
    """
    if platform not in PLATFORMS:
        raise BuildError(f"platform: expected one of {list(PLATFORMS)}, got {platform!r}")
    requirements = [f"{name}=={version}" for name, version in pinned_versions().items()]
    wheels: dict[str, Path] = {}
    for python in python_versions:
        dest = cache / f"{platform}-py{python}"
        dest.mkdir(parents=True, exist_ok=True)
        command = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check"]
        command += ["--only-binary=:all:", "--no-deps", "--python-version", python, "--dest", str(dest)]
        for tag in PLATFORMS[platform]:
            command += ["--platform", tag]
        done = subprocess.run(
            command + requirements, capture_output=True, text=True, check=False, timeout=1800
        )
        if done.returncode != 0:
            raise BuildError(
                f"pip download for {platform}, Python {python} failed:\n{done.stdout}{done.stderr}"
            )
        wanted = {name.replace("-", "_") for name in WHEEL_PACKAGES}
        for wheel in sorted(dest.glob("*.whl")):
            name, version = wheel.name.split("-")[:2]
            if name.lower() in wanted and version == pinned_versions()[name.lower().replace("_", "-")]:
                wheels.setdefault(wheel.name, wheel)  # pure-Python wheels are shared by both Pythons
    return sorted(wheels.values())


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


def build(
    out_dir: Path,
    bpy_root: Path | None = None,
    build_dir: Path | None = None,
    *,
    wheels: bool = False,
    platforms: tuple[str, ...] = ("linux-x64",),
    wheel_cache: Path | None = None,
) -> Path:
    """Assemble, build and validate the extension; return the path of the zip.

    Args:
        out_dir: directory receiving ``<id>-<version>.zip`` (with ``wheels``:
            ``<id>-<version>-<platform>.zip``, one per platform; the first is returned).
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
    """:func:`build`, returning every zip written (one per platform with ``wheels``)."""
    bpy_root = bpy_root or find_bpy_root()
    with tempfile.TemporaryDirectory(prefix="blinn_phong_extension_") as scratch:
        staged = stage(build_dir or Path(scratch) / "extension")
        manifest = tomllib.loads((staged / "blender_manifest.toml").read_text(encoding="utf-8"))
        out_dir.mkdir(parents=True, exist_ok=True)
        stem = f"{manifest['id']}-{manifest['version']}"
        if not wheels:
            zip_path = out_dir / f"{stem}.zip"
            zip_path.unlink(missing_ok=True)
            run_blender_ext(
                bpy_root, "build", "--source-dir", str(staged), "--output-filepath", str(zip_path)
            )
            run_blender_ext(bpy_root, "validate", str(zip_path))
            return [zip_path]
        cache = wheel_cache or default_wheel_cache()
        files: dict[str, Path] = {}
        for platform in platforms:
            for wheel in download_wheels(platform, cache):
                files.setdefault(wheel.name, wheel)  # pure-Python wheels are shared by every platform
        add_wheels(staged, [files[name] for name in sorted(files)], list(platforms))
        zips = [out_dir / f"{stem}-{platform.replace('-', '_')}.zip" for platform in platforms]
        for zip_path in zips:
            zip_path.unlink(missing_ok=True)
        run_blender_ext(
            bpy_root, "build", "--source-dir", str(staged), "--output-dir", str(out_dir), "--split-platforms"
        )
        for zip_path in zips:
            if not zip_path.exists():
                raise BuildError(f"Blender's build wrote no {zip_path.name} into {out_dir}")
            run_blender_ext(bpy_root, "validate", str(zip_path))
        return zips


def main(argv: list[str] | None = None) -> int:
    """Command-line entry: build + validate, print the zip path(s)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "dist", help="output directory (default dist/)")
    parser.add_argument("--bpy-root", type=Path, default=None, help="site-packages/bpy directory")
    parser.add_argument("--wheels", action="store_true", help="bundle numba, embreex, colour-science wheels")
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
