"""Run compositing cases through Blender's compositor (executed inside Blender's Python).

``python -m addon.compositor_job JOB.json`` with ``bpy`` importable. The job (written by
:mod:`addon.verify` or the benchmark) names two premultiplied RGBA EXR files and a
list of cases; each case is one branch of a compositor tree:

* ``{"kind": "node_group", "operator": "src_atop", "factor": 0.5}`` — the generated
  Porter-Duff group (Source = src, Destination = dst);
* ``{"kind": "alpha_over", "operator": "disjoint_over", "factor": 1, "straight_alpha": true}``
  — Blender's Alpha Over node (Foreground = src, Background = dst);
* ``{"kind": "alpha_convert", "operator": "premultiply" | "unpremultiply"}`` — Blender's
  Alpha Convert node on src;
* ``{"kind": "copy"}`` — src unchanged (a baseline for timings).

Mode ``"verify"`` puts every case in one tree and renders once; a File Output node
writes one 32-bit multilayer EXR with a layer per case key. Mode ``"benchmark"``
gives each case its own scene whose tree holds only that case, renders each once to
warm up, then renders all of them round-robin ``repeat`` times, recording wall-clock
seconds per render. A report JSON (Blender version,
Alpha Over modes available, timings) is written next to the job.

Images are loaded as ``Non-Color`` with alpha mode ``Channel Packed`` so that no colour
or alpha conversion touches them; the Image node then passes the stored values on.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import bpy

from . import compat, node_groups

__all__ = ["main", "run_job"]


def _load_image(path: str) -> bpy.types.Image:
    image = bpy.data.images.load(path, check_existing=False)
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "CHANNEL_PACKED"
    return image


def _add_case(
    tree: bpy.types.NodeTree,
    case: dict,
    src: bpy.types.NodeSocket,
    dst: bpy.types.NodeSocket,
) -> bpy.types.NodeSocket:
    """Add the nodes of one case to ``tree`` and return its image output."""
    kind = case["kind"]
    if kind == "copy":
        return src
    if kind == "node_group":
        node = tree.nodes.new("CompositorNodeGroup")
        node.node_tree = node_groups.ensure_group(case["operator"])
        tree.links.new(src, node.inputs["Source"])
        tree.links.new(dst, node.inputs["Destination"])
        node.inputs["Factor"].default_value = float(case.get("factor", 1.0))
        return node.outputs[0]
    if kind == "alpha_over":
        node = tree.nodes.new("CompositorNodeAlphaOver")
        compat.link_alpha_over(tree, node, background=dst, foreground=src)
        compat.configure_alpha_over(
            node,
            case["operator"],
            straight_alpha=bool(case.get("straight_alpha", False)),
            factor=float(case.get("factor", 1.0)),
        )
        return node.outputs[0]
    if kind == "alpha_convert":
        node = tree.nodes.new("CompositorNodePremulKey")
        compat.configure_alpha_convert(node, to_premultiplied=case["operator"] == "premultiply")
        tree.links.new(src, node.inputs["Image"])
        return node.outputs[0]
    raise ValueError(f"case kind: expected node_group, alpha_over, alpha_convert or copy, got {kind!r}")


def _new_tree(scene: bpy.types.Scene, images: dict[str, bpy.types.Image]) -> tuple:
    tree = compat.compositor_tree(scene)
    sockets = []
    for name in ("src", "dst"):
        node = tree.nodes.new("CompositorNodeImage")
        node.image = images[name]
        sockets.append(node.outputs["Image"])
    return tree, sockets[0], sockets[1]


def _render(scene: bpy.types.Scene) -> float:
    start = time.perf_counter()
    bpy.ops.render.render(write_still=False, scene=scene.name)
    return time.perf_counter() - start


def _configure(scene: bpy.types.Scene, width: int, height: int) -> None:
    scene.render.resolution_x = width
    scene.render.resolution_y = height
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    compat.set_full_precision(scene)


def run_job(job: dict) -> dict:
    """Run one job (see the module docstring) and return its report."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    size = int(job["width"]), int(job["height"])
    _configure(scene, *size)

    registered = bool(job.get("register_addon", False))
    if registered:
        from . import register

        register()
    try:
        if registered:
            # The groups artists get from the operator are the groups that are verified.
            bpy.ops.node.porter_duff_add_groups()
        images = {name: _load_image(job[name]) for name in ("src", "dst")}
        report: dict = {
            "blender_version": bpy.app.version_string,
            "alpha_over_modes": list(compat.alpha_over_modes()),
            "groups_in_file": sorted(
                g.name for g in bpy.data.node_groups if g.name.startswith("Porter-Duff")
            ),
            "timings": {},
        }
        if job["mode"] == "verify":
            tree, src, dst = _new_tree(scene, images)
            outputs = compat.add_file_output(tree, job["output_dir"], job["file_name"], list(job["cases"]))
            for key, case in job["cases"].items():
                tree.links.new(_add_case(tree, case, src, dst), outputs[key])
            report["timings"]["render"] = _render(scene)
        elif job["mode"] == "benchmark":
            # One scene per case, rendered round-robin, so that load from other processes
            # spreads over all cases alike.
            scenes = {}
            for key, case in job["cases"].items():
                scenes[key] = bpy.data.scenes.new(f"Benchmark {key}")
                _configure(scenes[key], *size)
                tree, src, dst = _new_tree(scenes[key], images)
                tree.links.new(_add_case(tree, case, src, dst), compat.add_render_output(tree))
                _render(scenes[key])  # warm-up: image loading, first allocation
            report["timings"] = {key: [] for key in scenes}
            for _ in range(int(job["repeat"])):
                for key, case_scene in scenes.items():
                    report["timings"][key].append(_render(case_scene))
        else:
            raise ValueError(f"job mode: expected 'verify' or 'benchmark', got {job['mode']!r}")
        return report
    finally:
        if registered:
            from . import unregister

            unregister()


def main(argv: list[str] | None = None) -> int:
    """Entry point: ``python -m addon.compositor_job JOB.json``; writes ``JOB.report.json``."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m addon.compositor_job JOB.json", file=sys.stderr)
        return 2
    job_path = Path(args[0])
    report = run_job(json.loads(job_path.read_text()))
    report_path = job_path.with_suffix(".report.json")
    from compositing._atomic import write_json_atomic

    write_json_atomic(report_path, report, indent=1)  # the reader never sees a half-written report
    return 0


if __name__ == "__main__":
    sys.exit(main())
