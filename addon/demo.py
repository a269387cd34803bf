"""The main job: render the shading showcase with the engine, composite it over the backplate two ways.

``python -m addon.demo --out DIR`` (needs the ``bpy`` module):

1. opens ``blend_files/showcase.blend`` and renders it with the Blinn-Phong engine through Blender
   (``bpy.ops.render.render``, as F12 does; twice, since the first render also compiles the
   renderer's numba kernels), writing ``DIR/render.exr``;
2. renders the same converted scene with the core pipeline in numpy and reports the largest
   difference to Blender's file (the engine's Blender I/O must not change a pixel);
3. composites the render over ``blend_files/images/backplate.exr`` with ``compositing.composite``
   (``src_over``) and with Blender's Alpha Over node (``addon.verify``, a separate Blender process);
4. prints the max error between the two composites and the timings, and writes
   ``render.png``, ``composite_ours.exr/.png``, ``composite_blender.exr/.png``,
   ``difference.exr`` (|ours − Blender|) and ``results.json``;
5. renders ``blend_files/textures.blend`` (an alpha-clipped, image-textured fence casting a sun
   shadow on a checker-textured floor) the same way, into ``DIR/textures/render.exr/.png``, and
   reports its timings, the planner's choices and the engine-vs-core difference
   (``results.json`` key ``"textures"``).

Exit code 0 when every difference is within ``--tolerance`` (default 1e-5), 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from compositing import composite
from compositing.io import read_image, write_image

from .batch_files import atomic_target, write_text_atomic

__all__ = ["main", "run_demo"]

REPO = Path(__file__).resolve().parents[1]
SHOWCASE = REPO / "blend_files" / "showcase.blend"
BACKPLATE = REPO / "blend_files" / "images" / "backplate.exr"
TEXTURED = REPO / "blend_files" / "textures.blend"


def _render_with_engine(blend: Path, out: Path) -> dict:
    """Render ``blend`` with the engine inside this process's Blender; return timings and the core image."""
    import bpy

    from . import convert, engine, properties

    properties.register()
    engine.register()
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend), load_ui=False)
        scene = bpy.context.scene
        scene.render.engine = engine.ENGINE_ID
        settings = scene.render.image_settings
        settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
        scene.render.use_compositing = False
        seconds_blender = []
        for _ in range(2):  # the first render also compiles the renderer's numba kernels
            t = time.perf_counter()
            bpy.ops.render.render()
            seconds_blender.append(time.perf_counter() - t)
        status = dict(engine.LAST_RENDER)
        if not status.get("ok"):
            raise RuntimeError(f"the engine failed: {status.get('error')}")
        with atomic_target(out / "render.exr") as tmp:  # a temporary file, renamed when complete
            bpy.data.images["Render Result"].save_render(filepath=str(tmp), scene=scene)
        t = time.perf_counter()
        converted = convert.scene_from_depsgraph(bpy.context.evaluated_depsgraph_get())
        textured = [
            name
            for name, mesh in zip(converted.mesh_names, converted.scene.meshes, strict=True)
            if mesh.material.base_color_texture is not None
        ]
        core = engine.render_converted(converted)
        seconds_core = time.perf_counter() - t
        return {
            "render_seconds_in_blender": seconds_blender,  # [first (with JIT), second]
            "render_seconds_core": seconds_core,
            "core_rgba": core.rgba,
            "choices": status.get("choices", {}),
            "size": status.get("size"),
            "stages": status.get("stats", {}),
            "textured_meshes": textured,
        }
    finally:
        engine.unregister()
        properties.unregister()


def _render_textured(blend: Path, out: Path) -> dict:
    """Step 5: render the textured scene with the engine, compare with the core pipeline."""
    out.mkdir(parents=True, exist_ok=True)
    rendered = _render_with_engine(blend, out)
    render = read_image(out / "render.exr")
    write_image(out / "render.png", render, clip=True)
    return {
        "scene": str(blend.relative_to(REPO)) if blend.is_relative_to(REPO) else str(blend),
        "size": rendered["size"],
        "render_seconds_in_blender": rendered["render_seconds_in_blender"],
        "render_seconds_core": rendered["render_seconds_core"],
        "planner": rendered["choices"].get("reasons", []),
        "shadows": rendered["choices"].get("shadows", []),
        "textured_meshes": rendered["textured_meshes"],
        "engine_vs_core_max_abs_error": float(np.abs(render - rendered["core_rgba"]).max()),
    }


def run_demo(
    out: Path, *, blend: Path = SHOWCASE, backplate_path: Path = BACKPLATE, textured: Path | None = TEXTURED
) -> dict:
    """Run the main job into ``out``; return the results (also written to ``out/results.json``).

    ``textured``: the textured scene rendered in step 5 (into ``out/textures``); None skips it.
    """
    from .verify import verify

    out.mkdir(parents=True, exist_ok=True)
    rendered = _render_with_engine(blend, out)
    render = read_image(out / "render.exr")
    engine_vs_core = float(np.abs(render - rendered.pop("core_rgba")).max())
    backplate = read_image(backplate_path)
    if backplate.shape != render.shape:
        raise ValueError(
            f"backplate: {backplate_path} is {backplate.shape[:2]}, the render {render.shape[:2]}"
        )

    t = time.perf_counter()
    ours = composite(render, backplate, "src_over")
    seconds_ours = time.perf_counter() - t
    t = time.perf_counter()
    check = verify(render, backplate, "src_over", via="alpha_over")
    seconds_blender = time.perf_counter() - t

    images = [("render.png", render)]
    for name, image in (("composite_ours", ours), ("composite_blender", check.blender)):
        images += [(f"{name}.exr", image), (f"{name}.png", image)]
    images.append(("difference.exr", np.abs(ours - check.blender).astype(np.float32)))
    for name, image in images:
        with atomic_target(out / name) as tmp:
            write_image(tmp, image, clip=name.endswith(".png"))
    results = {
        "scene": str(blend.relative_to(REPO)) if blend.is_relative_to(REPO) else str(blend),
        "size": rendered["size"],
        "render_seconds_in_blender": rendered["render_seconds_in_blender"],
        "render_seconds_core": rendered["render_seconds_core"],
        "render_stages": rendered["stages"],
        "planner": rendered["choices"].get("reasons", []),
        "engine_vs_core_max_abs_error": engine_vs_core,
        "composite_seconds_ours": seconds_ours,
        "composite_seconds_blender_process": seconds_blender,
        "composite_max_abs_error": check.max_abs_error,
        "composite_mean_abs_error": check.mean_abs_error,
    }
    if textured is not None:
        results["textures"] = _render_textured(textured, out / "textures")
    write_text_atomic(out / "results.json", json.dumps(results, indent=1))
    return results


def main(argv: list[str] | None = None) -> int:
    """Command-line entry; prints a summary and returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m addon.demo", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "out" / "addon_demo", help="output directory")
    parser.add_argument(
        "--blend", type=Path, default=SHOWCASE, help="scene to render (default: the showcase)"
    )
    parser.add_argument("--tolerance", type=float, default=1e-5, help="max allowed |difference|")
    args = parser.parse_args(argv)
    r = run_demo(args.out, blend=args.blend)
    width, height = r["size"]
    print(f"scene                      {r['scene']} ({width}×{height})")
    first, second = r["render_seconds_in_blender"]
    print(f"render (engine in Blender) {second:.3f} s (first render {first:.3f} s, incl. JIT compile)")
    print(f"render (core, numpy)       {r['render_seconds_core']:.3f} s")
    print(f"engine vs core max error   {r['engine_vs_core_max_abs_error']:.3g}")
    print(f"composite, ours (src_over) {r['composite_seconds_ours'] * 1e3:.2f} ms")
    blender_seconds, mean_error = r["composite_seconds_blender_process"], r["composite_mean_abs_error"]
    print(f"composite, Blender process {blender_seconds:.3f} s (Alpha Over, incl. start-up)")
    print(f"ours vs Blender max error  {r['composite_max_abs_error']:.3g} (mean {mean_error:.3g})")
    worst = max(r["engine_vs_core_max_abs_error"], r["composite_max_abs_error"])
    t = r.get("textures")
    if t is not None:
        width, height = t["size"]
        first, second = t["render_seconds_in_blender"]
        meshes = ", ".join(t["textured_meshes"])
        print(f"textured scene             {t['scene']} ({width}×{height}); textured: {meshes}")
        print(
            f"render (engine in Blender) {second:.3f} s (first render {first:.3f} s); shadows {t['shadows']}"
        )
        print(f"render (core, numpy)       {t['render_seconds_core']:.3f} s")
        print(f"engine vs core max error   {t['engine_vs_core_max_abs_error']:.3g}")
        worst = max(worst, t["engine_vs_core_max_abs_error"])
    print(f"images and results.json in {args.out}")
    return 0 if worst <= args.tolerance else 1


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.exit(code)
