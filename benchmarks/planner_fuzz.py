"""The sweep that records how the planner's promise holds over many random scenes.

The scenes and the per-scene check are :mod:`testbeds.planner_fuzz` (the planner tests use them
too). ``python -m benchmarks.planner_fuzz [N]`` runs seeds ``0 … N−1`` at tolerances 0, 2, 8
and 32 and writes ``benchmarks/results/planner_fuzz.json``: per tolerance, how many cases
exceeded the promise (more than 1 step at tolerance 0, more than T otherwise), by how much, and
the per-concern choices; and the time to plan a 100k-triangle scene (:func:`planning_time`).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

import blinn_phong as bp
from blinn_phong.model.primitives import uv_sphere
from testbeds.planner_fuzz import TOLERANCES, check, faceted_box, random_scene

__all__ = ["planning_time", "sweep"]


def sweep(seeds: range, size: int = 40, progress: bool = True) -> dict:
    """Check every seed at every tolerance of :data:`TOLERANCES`; exceedance rates per tolerance."""
    rows = []
    start = time.perf_counter()
    for seed in seeds:
        scene = random_scene(seed)
        exact = None
        for tolerance in TOLERANCES:
            row = check(scene, tolerance, size, exact)
            exact = row.pop("exact")
            rows.append({"seed": seed, **row})
        if progress:
            print(f"seed {seed}: {time.perf_counter() - start:.0f} s", file=sys.stderr)
    summary = {}
    for tolerance in TOLERANCES:
        sel = [r for r in rows if r["tolerance"] == tolerance]
        over = [r for r in sel if r["exceeded"]]
        limit = 1.0 if tolerance == 0 else tolerance
        summary[str(tolerance)] = {
            "cases": len(sel),
            "exceeded": len(over),
            "rate": len(over) / max(len(sel), 1),
            "worst_excess_steps": max((r["max_steps"] - limit for r in over), default=0.0),
            "approximate_choices": sum(
                r["transparency"] in ("depth_peeling",) or "shadow_map" in r["shadows"] for r in sel
            ),
        }
    return {"size": size, "seeds": [seeds.start, seeds.stop], "summary": summary, "cases": rows}


def planning_time(repeat: int = 5) -> dict:
    """Seconds to plan a 100 172-triangle UV sphere (317×159) over a floor under a sun, against a
    plain z-buffer frame of it at 640×360 measured in the same run (the peer).

    ``cold``: new mesh arrays every call and every cached fact forgotten (the convexity test
    runs; equal arrays would otherwise be recognised by content); ``warm``: the same arrays
    (the object-space facts are cached by array identity, as for repeated renders of a scene).
    """
    from benchmarks._util import time_interleaved
    from blinn_phong.geometry.mesh_facts import _clear_caches

    p, t, n = uv_sphere(317, 159)
    floor = bp.Mesh(*faceted_box(np.array([3.0, 3.0, 0.05])), material=bp.Material(diffuse=(0.6, 0.6, 0.6)))
    lift = np.eye(4)
    lift[2, 3] = 1.2
    camera = bp.Camera.perspective(
        45.0, 16 / 9, 0.5, 40.0, view=bp.look_at((4, -5, 3), (0, 0, 0.8), (0, 0, 1))
    )

    def scene(fresh: bool) -> bp.Scene:
        sphere = bp.Mesh(p.copy() if fresh else p, t, n, transform=lift)
        return bp.Scene([floor, sphere], [bp.DirectionalLight((0.3, 0.2, -1.0))], camera)

    warm_scene = scene(False)
    times = time_interleaved(
        {
            "cold": lambda: (_clear_caches(), bp.plan(scene(True))),
            "warm": lambda: bp.plan(warm_scene),
            "frame 640x360": lambda: bp.render(warm_scene, 640, 360, shadows="none"),
        },
        repeat=repeat,
    )
    frame = times["frame 640x360"]["median_s"]
    return {
        "triangles": int(len(t) + len(floor.triangles)),
        "plan": str(bp.plan(warm_scene)),
        **{k: {"median_s": v["median_s"], "ratio_to_frame": v["median_s"] / frame} for k, v in times.items()},
    }


def main(argv: list[str] | None = None) -> None:
    """``python -m benchmarks.planner_fuzz [N [SIZE]]``: sweep seeds 0 … N−1 (default 200) at SIZE²
    pixels (default 40; other sizes write ``planner_fuzz_<SIZE>.json``: a larger frame makes
    shadow maps cheaper than ray tracing, so they get exercised) and time the planning of a
    100k-triangle scene; ``python -m benchmarks.planner_fuzz planning`` only times."""
    args = sys.argv[1:] if argv is None else argv
    size = int(args[1]) if len(args) > 1 else 40
    name = "planner_fuzz.json" if size == 40 else f"planner_fuzz_{size}.json"
    out = Path(__file__).resolve().parent / "results" / name
    if args and args[0] == "planning":
        result = json.loads(out.read_text()) if out.exists() else {}
    else:
        result = sweep(range(int(args[0]) if args else 200), size)
    result["planning"] = planning_time()
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(result, indent=1) + "\n")
    tmp.replace(out)
    print(json.dumps({k: result[k] for k in ("summary", "planning") if k in result}, indent=1))


if __name__ == "__main__":
    main()
