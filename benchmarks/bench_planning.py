"""First-time planning of 100k-triangle scenes, against peers measured in the same run.

``bp.plan(scene)`` first decides per-mesh facts (closed, convex, planar, bounds:
:mod:`blinn_phong.geometry.mesh_facts`) and then each concern. This benchmark times that on a fresh
scene with every cached fact forgotten, for three scenes:

* ``renderer``: :func:`benchmarks.bench_renderer.build_scene` (four 25,440-triangle spheres
  built separately — equal arrays — and a floor; 101,920 triangles, 4 lights);
* ``issue``: :func:`benchmarks.bench_frame.issue_scene` (two 65,280-triangle spheres sharing one
  set of arrays, a ground plane, 2 lights);
* ``sphere_100k``: one ``uv_sphere(317, 159)`` (100,172 triangles; nothing to share).

Rows per scene: ``compiled`` (the default), ``numpy`` (the numpy reference of the same
facts, what runs without numba), and two peers on the same geometry: ``qhull`` —
:class:`scipy.spatial.ConvexHull` of every non-flat mesh's world vertices (what a hull-based
convexity test would run at least) — and ``frame`` — one plain compiled z-buffer frame of
the scene at 640×360 (``render(..., shadows="none")``). Each scene also runs in a new
process (``cold``): importing ``blinn_phong``, the first ``plan`` (numba loading the
compiled passes from its disk cache included) and a second fresh scene's ``plan``.

Usage::

    python -m benchmarks.bench_planning [--out benchmarks/results] [--repeat 7] [--baseline DIR]

``--baseline DIR`` also runs the cold measurement on another checkout of the project (e.g. an
export of an earlier commit) for a before/after comparison. Writes ``planning.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from benchmarks._util import machine_info, markdown_table, write_json

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("renderer", "issue", "sphere_100k")


def make_scene(name: str) -> object:  # a blinn_phong.Scene
    """A fresh scene (new arrays, new Scene) of benchmark ``name``."""
    import blinn_phong as bp

    if name == "renderer":
        from benchmarks.bench_renderer import build_scene

        return build_scene()
    if name == "issue":
        from benchmarks.bench_frame import issue_scene

        return issue_scene()
    if name == "sphere_100k":
        from blinn_phong.model.primitives import uv_sphere

        p, t, n = uv_sphere(317, 159)
        camera = bp.Camera.perspective(40.0, 16 / 9, 0.5, 50.0, view=bp.look_at((0, 1, 4), (0, 0, 0)))
        return bp.Scene([bp.Mesh(p, t, n)], [bp.DirectionalLight((-1.0, -1.0, -1.0))], camera)
    raise ValueError(f"scene: expected one of {SCENES}, got {name!r}")


def _forget() -> None:
    """Forget every cached mesh fact (new layout: mesh_facts; earlier: the planner's dicts)."""
    try:
        from blinn_phong.geometry import mesh_facts
    except ImportError:
        from blinn_phong.planning import planner

        for cache in ("_OBJECT_FACTS", "_WORLD_FACTS"):
            getattr(planner, cache, {}).clear()
        return
    mesh_facts._clear_caches()


def _variant(mode: str) -> Callable[[], None]:
    """Switch the mesh-fact passes to ``mode`` (compiled or numpy)."""
    from blinn_phong.geometry import mesh_facts

    original = mesh_facts._kernels

    def apply() -> None:
        mesh_facts._kernels = (lambda: None) if mode == "numpy" else original

    return apply


def _peer(name: str, scene: object) -> Callable[[], object]:
    import blinn_phong as bp

    if name == "qhull":
        from scipy.spatial import ConvexHull, QhullError

        def hulls() -> object:
            out = []
            for m in scene.meshes:  # a flat mesh has no 3-D hull (Qhull refuses it): skipped
                try:
                    out.append(ConvexHull(m.positions @ m.transform[:3, :3].T + m.transform[:3, 3]))
                except QhullError:
                    pass
            return out

        return hulls
    return lambda: bp.render(scene, 640, 360, shadows="none")


def measure(name: str, repeat: int) -> dict[str, dict[str, float]]:
    """Interleaved rounds: each round plans a fresh scene with every fact forgotten, per mode,
    then runs the peers once; median and minimum milliseconds per row."""
    import blinn_phong as bp

    modes = ("compiled", "numpy")
    switch = {m: _variant(m) for m in modes}
    samples: dict[str, list[float]] = {m: [] for m in (*modes, "qhull", "frame")}
    peer_scene = make_scene(name)
    peers = {p: _peer(p, peer_scene) for p in ("qhull", "frame")}
    for p in peers.values():  # warm-up: compile and load everything once
        p()
    for m in modes:
        switch[m]()
        _forget()
        bp.plan(make_scene(name))
    methods = None
    for _ in range(repeat):
        for m in modes:
            switch[m]()
            scene = make_scene(name)
            _forget()
            start = time.perf_counter()
            result = bp.plan(scene)
            samples[m].append(time.perf_counter() - start)
            methods = methods or [c.method for c in result.shadows]
        for p, fn in peers.items():
            start = time.perf_counter()
            fn()
            samples[p].append(time.perf_counter() - start)
    switch["compiled"]()
    triangles = sum(len(m.triangles) for m in peer_scene.meshes)
    out = {
        row: {"median_ms": 1e3 * statistics.median(ts), "min_ms": 1e3 * min(ts), "runs": len(ts)}
        for row, ts in samples.items()
    }
    out["scene"] = {"triangles": triangles, "meshes": len(peer_scene.meshes), "shadows": methods}
    return out


_CHILD = """
import json, sys, time
t0 = time.perf_counter()
import blinn_phong as bp
t1 = time.perf_counter()
sys.path.insert(0, {bench!r})
from benchmarks.bench_planning import make_scene, _forget
scene = make_scene({name!r})
t2 = time.perf_counter(); bp.plan(scene); t3 = time.perf_counter()
second = make_scene({name!r}); _forget()
t4 = time.perf_counter(); bp.plan(second); t5 = time.perf_counter()
ms = {{"import_ms": t1 - t0, "first_plan_ms": t3 - t2, "second_plan_ms": t5 - t4}}
print(json.dumps({{k: 1e3 * v for k, v in ms.items()}}))
"""


def cold(name: str, project: Path) -> dict[str, float]:
    """A new process on ``project``: import, first plan, second fresh plan (milliseconds). Run
    twice; the second process's figures are kept (numba's disk cache filled by the first)."""
    env = dict(os.environ, PYTHONPATH=str(project))
    code = _CHILD.format(bench=str(ROOT), name=name)
    for _ in range(2):
        done = subprocess.run(
            [sys.executable, "-c", code], cwd=project, env=env, capture_output=True, text=True, check=True
        )
    return json.loads(done.stdout.strip().splitlines()[-1])


def run(out_dir: str | os.PathLike, *, repeat: int = 7, baseline: Path | None = None) -> dict:
    """Measure every scene; write ``planning.json`` into ``out_dir``; return the results."""
    results: dict[str, object] = {"benchmark": "planning", "machine": machine_info(), "repeat": repeat}
    rows = []
    for name in SCENES:
        print(f"-- {name}", flush=True)
        timing = measure(name, repeat)
        timing["cold"] = cold(name, ROOT)
        if baseline is not None:
            timing["cold_baseline"] = cold(name, baseline)
        results[name] = timing
        c = timing["compiled"]["median_ms"]
        rows.append(
            [
                name,
                timing["scene"]["triangles"],
                f"{c:.2f}",
                f"{timing['numpy']['median_ms']:.1f}",
                f"{timing['qhull']['median_ms']:.1f} ({c / timing['qhull']['median_ms']:.2f}×)",
                f"{timing['frame']['median_ms']:.0f} ({c / timing['frame']['median_ms']:.3f}×)",
                f"{timing['cold']['first_plan_ms']:.0f} / {timing['cold']['second_plan_ms']:.1f}",
            ]
        )
    results["table"] = markdown_table(
        [
            "scene",
            "triangles",
            "plan ms (compiled)",
            "numpy",
            "qhull peer (plan ×)",
            "640×360 frame (plan ×)",
            "cold: first / second plan ms",
        ],
        rows,
    )
    print(results["table"])
    write_json(Path(out_dir) / "planning.json", results)
    return results


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--baseline", type=Path, default=None, help="another checkout, measured cold")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error(f"--repeat must be >= 1, got {args.repeat}")
    run(args.out, repeat=args.repeat, baseline=args.baseline)


if __name__ == "__main__":
    main()
