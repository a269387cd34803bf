"""Build the installable Blender extension zip and validate it with Blender's own validator.

Usage::

    .venv/bin/python tools/build_extension.py [--out dist] [--bpy-root PATH]

Steps:

1. Stage ``addon/`` (the extension root, holding ``blender_manifest.toml``) into ``build/extension``.
2. Vendor the core packages (``blinn_phong``, ``compositing``) into the staged add-on as
   sub-packages, then rewrite every absolute import of a core package, in the add-on's own modules
   and in the vendored code alike, into the equivalent relative import: ``from blinn_phong.scene
   import Mesh`` in ``engine.py`` becomes ``from .blinn_phong.scene import Mesh``, and
   ``from compositing.factors import X`` in ``blinn_phong/a.py`` becomes
   ``from ..compositing.factors import X``. In the repository the add-on imports the top-level
   packages by their plain names; the installed extension imports nothing by absolute name and
   cannot pick up another copy of the packages from ``sys.path`` (the approach of pip's
   ``vendoring`` tool).
3. Run Blender's extension CLI (``bl_pkg/cli/blender_ext.py`` inside the installed ``bpy`` package,
   plain Python, no Blender binary) to ``build`` the zip, then ``validate`` the zip, with Blender's own
   list of valid tags.

Prints the zip path on success; exits non-zero with the validator's message otherwise.
"""

from __future__ import annotations

import argparse
import ast
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ADDON_DIR = REPO / "addon"
VENDORED = ("blinn_phong", "compositing")
IGNORED = shutil.ignore_patterns("__pycache__", "*.pyc", ".*", "*.zip", "tests")


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


def build(out_dir: Path, bpy_root: Path | None = None, build_dir: Path | None = None) -> Path:
    """Assemble, build and validate the extension; return the path of the zip.

    Args:
        out_dir: directory receiving ``<id>-<version>.zip``.
        bpy_root: ``bpy/<X.Y>`` directory holding Blender's scripts (default: the installed bpy).
        build_dir: staging directory (default ``build/extension`` in the repository).
    """
    bpy_root = bpy_root or find_bpy_root()
    staged = stage(build_dir or REPO / "build" / "extension")
    manifest = tomllib.loads((staged / "blender_manifest.toml").read_text(encoding="utf-8"))
    out_dir.mkdir(parents=True, exist_ok=True)
    zip_path = out_dir / f"{manifest['id']}-{manifest['version']}.zip"
    zip_path.unlink(missing_ok=True)
    run_blender_ext(bpy_root, "build", "--source-dir", str(staged), "--output-filepath", str(zip_path))
    run_blender_ext(bpy_root, "validate", str(zip_path))
    return zip_path


def main(argv: list[str] | None = None) -> int:
    """Command-line entry: build + validate, print the zip path."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "dist", help="output directory (default dist/)")
    parser.add_argument("--bpy-root", type=Path, default=None, help="site-packages/bpy directory")
    args = parser.parse_args(argv)
    try:
        bpy_root = find_bpy_root(args.bpy_root) if args.bpy_root else None
        zip_path = build(args.out, bpy_root)
    except BuildError as error:
        print(f"build_extension: {error}", file=sys.stderr)
        return 1
    print(zip_path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
