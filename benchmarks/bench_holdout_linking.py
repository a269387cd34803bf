"""Holdouts and light/shadow linking: their cost against the same frame without them.

Scene: :func:`benchmarks.bench_frame.issue_scene` (two 65 536-triangle UV spheres over a ground
plane, a directional and a point light), 1920×1080, one sample per pixel, the planner's choices.
Rows, timed interleaved in one process (:func:`benchmarks._util.time_interleaved`, medians of wall
time), reported as ratios to the ``frame`` row of the same run:

* ``frame`` — ``render()`` of the scene;
* ``links_unused`` — the same scene given ``light_links=(LightLink(), None)`` (entries that link
  nothing: stored as no links, the frame's own path);
* ``receivers`` — the point light linked to the two spheres (not the ground);
* ``blockers`` — the sun's shadows cast by the first sphere only;
* ``holdout`` — the second sphere a holdout (the frame leaves the fused pass for the band path).

Usage::

    .venv/bin/python -m benchmarks.bench_holdout_linking [--out benchmarks/results] [--repeat 5] [--quick]

``--quick`` renders 960×540 with 16k-triangle spheres and writes ``holdout_linking_quick.json``;
the full run writes ``holdout_linking.json``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

import blinn_phong as bp
from benchmarks._util import machine_info, ratio_main, time_interleaved, write_json
from benchmarks.bench_frame import issue_scene

__all__ = ["main", "run", "scenes"]


def scenes(plain: bp.Scene) -> dict[str, bp.Scene]:
    """The rows' scenes built from ``plain`` (two spheres then the ground; the sun, then the lamp)."""
    spheres = np.array([True, True, False])
    first = np.array([True, False, False])
    held = (plain.meshes[0], replace(plain.meshes[1], holdout=True), plain.meshes[2])
    return {
        "frame": plain,
        "links_unused": replace(plain, light_links=(bp.LightLink(), None)),
        "receivers": replace(plain, light_links=(None, bp.LightLink(receivers=spheres))),
        "blockers": replace(plain, light_links=(bp.LightLink(blockers=first), None)),
        "holdout": replace(plain, meshes=held),
    }


def run(out: Path, *, repeat: int = 5, quick: bool = False) -> dict[str, object]:
    """Time the rows and write ``holdout_linking[_quick].json`` into ``out``; return the data."""
    width, height, segments = (960, 540, 128) if quick else (1920, 1080, 256)
    built = scenes(issue_scene(segments, segments // 2))
    rows: dict[str, Callable[[], object]] = {
        name: (lambda s=s: bp.render(s, width, height)) for name, s in built.items()
    }
    times = time_interleaved(rows, repeat=repeat, warmup=1)
    base = times["frame"]["median_s"]
    data: dict[str, object] = {
        "scene": f"two UV spheres ({2 * segments * (segments // 2 - 1)} triangles each), plane, 2 lights",
        "size": [width, height],
        "samples": 1,
        "rows": {name: {**t, "ratio_to_frame": t["median_s"] / base} for name, t in times.items()},
        "shadow_methods": {
            name: [c.method for c in bp.render(s, 64, 36).plan.shadows] for name, s in built.items()
        },
        "machine": machine_info(),
    }
    write_json(Path(out) / ("holdout_linking_quick.json" if quick else "holdout_linking.json"), data)
    return data


def main(argv: list[str] | None = None) -> None:
    """Command line: ``--out``, ``--repeat``, ``--quick``."""
    ratio_main(run, __doc__.split("\n")[0], argv)


if __name__ == "__main__":
    main()
