"""Compositor passes: the cost of Cryptomatte and light groups against the frame without them.

Scene: :func:`benchmarks.bench_frame.issue_scene` (two 65 536-triangle UV spheres over a ground
plane, a directional and a point light), 1920×1080, one sample per pixel, the planner's default
choices (hard shadows from both lights). Rows, timed interleaved in one process
(:func:`benchmarks._util.time_interleaved`, medians of wall time), reported as ratios to the
``frame`` row of the same run:

* ``frame`` — ``render()`` with no extra pass;
* ``cryptomatte`` — object, material and asset layers at 6 levels (9 RGBA passes);
* ``light_groups`` — four groups: the sun, the point light, the world's ambient and the
  spheres' emission (each a ``Combined_<group>`` pass; the spheres are given a small emission
  so that every group has an emitter);
* ``both`` — the two together (the issue's target: at most 1.3× the frame).

Usage::

    .venv/bin/python -m benchmarks.bench_compositor_passes [--out benchmarks/results] [--repeat 5] [--quick]

``--quick`` renders 960×540 with 16k-triangle spheres and writes ``compositor_passes_quick.json``;
the full run writes ``compositor_passes.json``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import blinn_phong as bp
from benchmarks._util import machine_info, ratio_main, time_interleaved, write_json
from benchmarks.bench_frame import issue_scene

__all__ = ["TARGET_RATIO", "main", "requests", "run"]

#: The issue's bound on ``both`` / ``frame``.
TARGET_RATIO = 1.3


def requests(scene: bp.Scene) -> tuple[bp.Cryptomatte, bp.LightGroups]:
    """The benchmark's Cryptomatte request (3 layers, 6 levels) and four light groups for ``scene``."""
    n = len(scene.meshes)
    names = {
        "object": [f"Object{i}" for i in range(n)],
        "material": [f"Material{i}" for i in range(n)],
        "asset": ["Spheres"] * (n - 1) + ["Ground"],
    }
    groups = bp.LightGroups(
        ("sun", "lamp", "world", "glow"),
        lights=("sun", "lamp"),
        meshes=tuple(["glow"] * (n - 1) + [None]),
        world="world",
    )
    return bp.Cryptomatte(names, levels=6), groups


def run(out: Path, *, repeat: int = 5, quick: bool = False) -> dict[str, object]:
    """Time the four rows and write ``compositor_passes[_quick].json`` into ``out``; return the data."""
    width, height, segments = (960, 540, 128) if quick else (1920, 1080, 256)
    plain = issue_scene(segments, segments // 2)
    glow = (0.05, 0.02, 0.0)
    glowing = [replace(m, material=replace(m.material, emission=glow)) for m in plain.meshes[:-1]]
    scene = replace(plain, meshes=(*glowing, plain.meshes[-1]))  # the spheres glow a little
    crypto, groups = requests(scene)
    rows: dict[str, Callable[[], object]] = {
        "frame": lambda: bp.render(scene, width, height),
        "cryptomatte": lambda: bp.render(scene, width, height, cryptomatte=crypto),
        "light_groups": lambda: bp.render(scene, width, height, light_groups=groups),
        "both": lambda: bp.render(scene, width, height, cryptomatte=crypto, light_groups=groups),
    }
    times = time_interleaved(rows, repeat=repeat, warmup=1)
    base = times["frame"]["median_s"]
    stages = bp.render(scene, width, height, cryptomatte=crypto, light_groups=groups).stats.seconds
    data: dict[str, object] = {
        "scene": f"two UV spheres ({2 * segments * (segments // 2 - 1)} triangles each), plane, 2 lights",
        "size": [width, height],
        "samples": 1,
        "rows": {name: {**t, "ratio_to_frame": t["median_s"] / base} for name, t in times.items()},
        "stage_seconds_both": stages,
        "target_ratio_both": TARGET_RATIO,
        "meets_target": times["both"]["median_s"] / base <= TARGET_RATIO,
        "machine": machine_info(),
    }
    write_json(Path(out) / ("compositor_passes_quick.json" if quick else "compositor_passes.json"), data)
    return data


def main(argv: list[str] | None = None) -> None:
    """Command line: ``--out``, ``--repeat``, ``--quick``."""
    ratio_main(run, __doc__.split("\n")[0], argv)


if __name__ == "__main__":
    main()
