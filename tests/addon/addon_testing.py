"""Run Python code against Blender's ``bpy`` module in a fresh subprocess.

Every Blender test goes through :func:`run_bpy`: the code runs under ``sys.executable`` (so
``.venv-blender42/bin/python -m pytest -m blender`` exercises Blender 4.2), with a timeout, with a
private ``BLENDER_USER_RESOURCES`` so no user configuration leaks in, and with the repository on
``sys.path``. The code reports its findings by calling ``emit(obj)``; :func:`run_bpy` returns the
last emitted object (JSON round-tripped).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
MARK = "@@RESULT@@"

_PRELUDE = f"""
import json, sys
sys.path.insert(0, {str(REPO)!r})
def emit(obj):
    print({MARK!r} + json.dumps(obj), flush=True)
"""


class BlenderRunError(AssertionError):
    """The Blender subprocess failed; the message carries its output."""


def run_bpy(
    code: str,
    tmp_path: Path,
    *,
    timeout: float = 120.0,
    args: tuple[str, ...] = (),
    expect_success: bool = True,
    env: dict[str, str] | None = None,
) -> Any:
    """Run ``code`` in a subprocess with bpy importable; return what it last passed to ``emit``."""
    script = tmp_path / "bpy_script.py"
    script.write_text(_PRELUDE + textwrap.dedent(code), encoding="utf-8")
    env = dict(
        os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"), PYTHONPATH=str(REPO), **(env or {})
    )
    done = subprocess.run(
        [sys.executable, str(script), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=str(tmp_path),
        env=env,
        check=False,
    )
    results = [line[len(MARK) :] for line in done.stdout.splitlines() if line.startswith(MARK)]
    if expect_success and (done.returncode != 0 or not results):
        raise BlenderRunError(
            f"exit {done.returncode}\nstdout:\n{done.stdout[-4000:]}\nstderr:\n{done.stderr[-4000:]}"
        )
    return json.loads(results[-1]) if results else None


def bpy_version() -> tuple[int, int]:
    """Major and minor version of the installed bpy package, without importing it."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    assert spec is not None and spec.submodule_search_locations, "bpy is not installed"
    root = Path(next(iter(spec.submodule_search_locations)))
    names = sorted(p.name for p in root.iterdir() if p.name[:1].isdigit())
    major, minor = names[-1].split(".")
    return int(major), int(minor)


def exr_parts(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str], dict[str, list[str]]]:
    """Every part of a multilayer EXR: pixels by part name, header strings, channel names."""
    import OpenImageIO as oiio  # noqa: N813

    image = oiio.ImageInput.open(str(path))
    assert image is not None, oiio.geterror()
    pixels, header, channels = {}, {}, {}
    try:
        index = 0
        while image.seek_subimage(index, 0):
            spec = image.spec()
            name = spec.get_string_attribute("name")
            pixels[name] = image.read_image(index, 0, 0, spec.nchannels, oiio.FLOAT)
            channels[name] = list(spec.channelnames)
            for attribute in spec.extra_attribs:
                if attribute.name.startswith("cryptomatte/"):
                    header[attribute.name] = str(attribute.value)
            index += 1
    finally:
        image.close()
    return pixels, header, channels


def exr_passes(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str], dict[str, list[str]]]:
    """Pixels, channel names (the part after the pass) by ``<layer>.<pass>``, and the header
    strings, of a multilayer EXR written as one part per pass (Blender 4.5 and later) or as one
    part whose channels are named ``<layer>.<pass>.<channel>`` (Blender 4.2)."""
    parts, header, names = exr_parts(path)
    pixels: dict[str, np.ndarray] = {}
    channels: dict[str, list[str]] = {}
    for part, image in parts.items():
        for index, full in enumerate(names[part]):
            qualified = full if not part or full.startswith(f"{part}.") else f"{part}.{full}"
            stem, _, channel = qualified.rpartition(".")
            channels.setdefault(stem, []).append(channel)
            pixels.setdefault(stem, []).append(image[..., index])  # type: ignore[attr-defined]
    order = "RGBArgbaXYZxyzUVW"  # a single-part file may store a pass's channels sorted by name
    for stem, names_ in channels.items():
        ranked = sorted(range(len(names_)), key=lambda i: order.find(names_[i]) % 99)
        channels[stem] = [names_[i] for i in ranked]
        pixels[stem] = [pixels[stem][i] for i in ranked]  # type: ignore[index]
    return {k: np.stack(v, axis=-1) for k, v in pixels.items()}, header, channels


def engine_scene(width: int, height: int) -> str:
    """Lines of a bpy script: an empty factory scene with the engine's properties, engine and UI
    registered, rendering ``width``×``height`` at 100 % (``scene`` is bound; ``bpy``, ``compat``,
    ``engine``, ``properties`` and ``render_ui`` must be imported before)."""
    return f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
properties.register()
engine.register()
render_ui.register()
scene = bpy.context.scene
scene.render.resolution_x, scene.render.resolution_y = {width}, {height}
scene.render.resolution_percentage = 100
"""
