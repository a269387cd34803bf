"""Speed against accuracy: time and error of every method family against its exact reference.

Each family function renders (or composites) one scene with every method the toolkit
offers for that concern, times it (median of interleaved rounds, :func:`time_interleaved`),
and measures its error against a reference computed in the same run
(:func:`testbeds.error_metrics.error_metrics`: max and mean absolute error in 8-bit
steps, PSNR). Where independent software does the same work (Mesa llvmpipe, OpenImageIO,
Pillow) it is measured in the same run and every time is also given as a ratio to it.

Families (key: what varies → reference):

* ``shading`` — flat / Gouraud / Phong × sphere tessellation → Phong on a 384-segment
  sphere; all at 2×2 supersampling so the comparison isolates shading and tessellation.
  Peer: Mesa llvmpipe fixed function (Gouraud) and a GLSL per-pixel shader (1 sample).
* ``antialiasing`` — samples per pixel (k×k ordered grid) → 8×8 samples.
* ``shadows`` — shadow-map resolution × PCF kernel × depth bias → Embree ray tracing
  (exact hard shadows); error of the light's visibility in 8-bit steps (a white receiver
  lit by a unit light: one step per 1/255 of visibility).
* ``transparency`` — sorted objects / sorted triangles / depth peeling k / weighted
  blended OIT, for N interpenetrating layers of opacity α → the A-buffer (exact per-pixel
  sort).
* ``compositing`` — an N-layer ``over`` stack in float64 / float32 / float16 / unorm8,
  premultiplied and straight → float64 premultiplied. Peers: OpenImageIO ``over``
  (float32), Pillow ``alpha_composite`` (straight unorm8).
* ``scaling`` — render time against pixel count and triangle count, with Mesa's GLSL
  renderer at the same sizes.
* ``frame_costs`` — whole ``render()`` calls per transparency method, shading method and
  with fog at two frame sizes each, stage times kept: the data of the planner's frame-aware
  cost models (no error measured; :func:`frame_costs`).

Every family returns a JSON-ready dict ``{"family", "reference", "cases": [...], ...}``;
each case has ``method``, its parameters, ``median_s``, ``ratio_to_<peer>`` and the error
metrics.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

import blinn_phong as bp
from benchmarks._util import time_interleaved
from blinn_phong.model.primitives import uv_sphere
from compositing import composite, composite_stack, premultiply
from compositing.gl_blend import gl_blend
from testbeds.error_metrics import error_metrics
from testbeds.tradeoff_scenes import (
    layered_scene,
    shadow_scene,
    transparency_methods,
    transparent_fragments,
    visible_points,
)

__all__ = [
    "FAMILIES",
    "antialiasing",
    "compositing_precision",
    "frame_costs",
    "mesa_available",
    "scaling",
    "shading",
    "shadows",
    "sphere_scene",
    "transparency",
]

SHINY = bp.Material(
    ambient=(0.2, 0.2, 0.2), diffuse=(0.45, 0.4, 0.35), specular=(0.45, 0.45, 0.45), shininess=40.0
)


def mesa_available() -> str | None:
    """``None`` if a Mesa EGL context can be made, else the reason it cannot."""
    try:
        from oracles.egl import EGLUnavailable, gl_context
    except ImportError as exc:  # pragma: no cover - PyOpenGL missing
        return str(exc)
    try:
        gl_context()
    except EGLUnavailable as exc:
        return str(exc)
    return None


def sphere_scene(segments: int, *, material: bp.Material = SHINY) -> bp.Scene:
    """A unit sphere (``segments`` × ``segments/2``) seen in perspective, lit by a point light.

    Radiance stays below 1 everywhere (ambient 0.2·0.15 + diffuse 0.45 + specular 0.45), so no
    method is clamped and the errors are those of the method alone.
    """
    pos, tris, normals = uv_sphere(segments, max(segments // 2, 2))
    camera = bp.Camera.perspective(34.0, 1.0, 1.0, 20.0, view=bp.look_at((0.0, 0.0, 4.0), (0.0, 0.0, 0.0)))
    light = bp.PointLight((2.0, 2.5, 3.0))
    return bp.Scene([bp.Mesh(pos, tris, normals, material=material)], [light], camera, ambient=(0.15,) * 3)


def _mesa_rgba(image_u8: np.ndarray) -> np.ndarray:
    """Mesa's 8-bit read-back (straight colour, coverage 0 or 255) as float premultiplied RGBA."""
    x = image_u8.astype(np.float64) / 255.0
    return premultiply(x)


# --------------------------------------------------------------------------- shading × tessellation


def shading(quick: bool = False, repeat: int = 3) -> dict:
    """Flat, Gouraud and Phong shading × tessellation against a supersampled per-pixel reference."""
    size = 128 if quick else 256
    tessellations = (8, 16, 32, 64) if quick else (8, 12, 16, 24, 32, 48, 64, 96, 128)
    samples = 4  # a 2×2 grid
    ref_segments = 384
    reference = bp.render(sphere_scene(ref_segments), size, size, shading="phong", samples=samples).rgba
    interior = reference[..., 3] >= 1.0  # fully covered by the reference sphere: shading alone
    mesa_reason = mesa_available()
    cases: list[dict] = []
    for segments in tessellations:
        scene = sphere_scene(segments)
        n_tris = len(scene.meshes[0].triangles)
        runs: dict[str, Callable[[], object]] = {
            shading_: (lambda s=shading_, sc=scene: bp.render(sc, size, size, shading=s, samples=samples))
            for shading_ in ("flat", "gouraud", "phong")
        }
        times = time_interleaved(runs, repeat=repeat)
        mesa_times: dict[str, float] = {}
        mesa_images: dict[str, np.ndarray] = {}
        if mesa_reason is None:
            from oracles import gl_lighting

            for name, fn in (
                (
                    "mesa_fixed_function_gouraud",
                    lambda sc=scene: gl_lighting.render_fixed_function(sc, size, size),
                ),
                ("mesa_glsl_per_pixel", lambda sc=scene: gl_lighting.render_glsl_phong(sc, size, size)),
            ):
                fn()  # warm-up (program compile, buffers)
                renders = [fn() for _ in range(repeat)]
                mesa_times[name] = float(np.median([r.seconds for r in renders]))
                mesa_images[name] = _mesa_rgba(renders[-1].rgba)
        for method in ("flat", "gouraud", "phong"):
            image = runs[method]().rgba  # type: ignore[attr-defined]
            case = {
                "method": method,
                "segments": segments,
                "triangles": n_tris,
                "samples_per_pixel": samples,
                "median_s": times[method]["median_s"],
                "ratio_to_phong": times[method]["median_s"] / times["phong"]["median_s"],
                **error_metrics(image, reference),
                "interior": error_metrics(image, reference, interior & (image[..., 3] >= 1.0)),
            }
            if "mesa_glsl_per_pixel" in mesa_times:
                case["ratio_to_mesa_glsl"] = times[method]["median_s"] / mesa_times["mesa_glsl_per_pixel"]
            cases.append(case)
        for name, seconds in mesa_times.items():
            cases.append(
                {
                    "method": name,
                    "peer": True,
                    "segments": segments,
                    "triangles": n_tris,
                    "samples_per_pixel": 1,
                    "median_s": seconds,
                    "ratio_to_phong": seconds / times["phong"]["median_s"],
                    "ratio_to_mesa_glsl": seconds / mesa_times["mesa_glsl_per_pixel"],
                    **error_metrics(mesa_images[name], reference),
                    "interior": error_metrics(
                        mesa_images[name], reference, interior & (mesa_images[name][..., 3] >= 1.0)
                    ),
                }
            )
    return {
        "family": "shading",
        "title": "Shading frequency × tessellation",
        "scene": "unit sphere in perspective, point light, Blinn-Phong shininess 40",
        "size": [size, size],
        "reference": f"phong, {ref_segments}-segment sphere, {samples} samples per pixel",
        "peer": "Mesa llvmpipe (1 sample per pixel, 8-bit read-back)" if mesa_reason is None else None,
        "peer_unavailable": mesa_reason,
        "cases": cases,
    }


# --------------------------------------------------------------------------- antialiasing


def antialiasing(quick: bool = False, repeat: int = 3) -> dict:
    """Samples per pixel against an 8×8-sample reference of the same scene."""
    size = 128 if quick else 256
    grid = (1, 2, 3, 4) if quick else (1, 2, 3, 4, 6)
    ref_grid = 8
    scene = sphere_scene(48)
    reference = bp.render(scene, size, size, shading="phong", samples=ref_grid**2).rgba
    runs = {
        f"{k}x{k}": (lambda k=k: bp.render(scene, size, size, shading="phong", samples=k * k)) for k in grid
    }
    times = time_interleaved(runs, repeat=repeat)
    cases = []
    for k in grid:
        image = runs[f"{k}x{k}"]().rgba
        cases.append(
            {
                "method": f"{k}x{k}",
                "samples_per_pixel": k * k,
                "median_s": times[f"{k}x{k}"]["median_s"],
                "ratio_to_1x1": times[f"{k}x{k}"]["median_s"] / times["1x1"]["median_s"],
                **error_metrics(image, reference),
            }
        )
    return {
        "family": "antialiasing",
        "title": "Antialiasing: ordered-grid supersampling",
        "scene": "48-segment sphere, Phong shading",
        "size": [size, size],
        "reference": f"{ref_grid}x{ref_grid} samples per pixel",
        "cases": cases,
    }


# --------------------------------------------------------------------------- shadows


#: Depth-bias settings: (name, constant bias in window-depth units, slope factor).
SHADOW_BIASES = (
    ("no bias", 0.0, 0.0),
    ("bias 1e-4 + 2·slope", 1e-4, 2.0),
    ("bias 2e-2 + 8·slope", 2e-2, 8.0),
)


def shadows(quick: bool = False, repeat: int = 3) -> dict:
    """Shadow maps (resolution × PCF kernel × bias) against Embree ray-traced hard shadows."""
    from blinn_phong.shadows.maps import light_shadow_maps, shadow_map_visibility
    from blinn_phong.shadows.raytrace import RayScene, directional_light_visibility, world_triangles

    size = 128 if quick else 256
    resolutions = (256, 1024) if quick else (256, 512, 1024, 2048)
    kernels = ("nearest", "box3") if quick else ("nearest", "bilinear", "box5")
    biases = SHADOW_BIASES if not quick else SHADOW_BIASES[:2]
    scene = shadow_scene()
    light = scene.lights[0]
    tris, _ = world_triangles(scene)
    points, normals = visible_points(scene, size)
    to_light = -np.asarray(light.direction, float)
    facing = normals @ to_light > 0
    points, normals = points[facing], normals[facing]

    def ray_traced() -> np.ndarray:
        return directional_light_visibility(RayScene(tris), points, normals, to_light)

    runs: dict[str, Callable[[], np.ndarray]] = {"ray_traced": ray_traced}
    params: dict[str, dict] = {"ray_traced": {}}
    for res in resolutions:
        for kernel in kernels:
            for bias_name, constant, slope in biases:
                name = f"map {res} {kernel} {bias_name}"

                def run(res=res, kernel=kernel, constant=constant, slope=slope) -> np.ndarray:
                    maps = light_shadow_maps(light, tris, res, constant_bias=constant, slope_bias=slope)
                    return shadow_map_visibility(light, maps, points, normals, kernel=kernel)

                runs[name] = run
                params[name] = {"resolution": res, "kernel": kernel, "bias": bias_name}
    times = time_interleaved(runs, repeat=min(repeat, 3))  # 37 settings: 3 rounds keep it near a minute
    reference = ray_traced()
    cases = []
    for name, fn in runs.items():
        vis = np.asarray(fn(), dtype=np.float64)
        cases.append(
            {
                "method": "ray_traced" if name == "ray_traced" else "shadow_map",
                "label": name,
                **params[name],
                "median_s": times[name]["median_s"],
                "ratio_to_ray_traced": times[name]["median_s"] / times["ray_traced"]["median_s"],
                "misclassified_share": float(np.mean(np.abs(vis - reference) > 0.5)),
                **error_metrics(vis, reference),
            }
        )
    frame_cost = shadow_frame_cost(scene, points, normals, quick=quick, repeat=min(repeat, 3))
    return {
        "family": "shadows",
        "title": "Shadow maps: resolution × PCF × bias",
        "frame_cost": frame_cost,
        "frame_constants": shadow_frame_constants(quick=quick, repeat=min(repeat, 3)),
        "scene": "sphere and box over a ground plane, directional light; visible points facing the light",
        "size": [size, size],
        "points": len(points),
        "shadowed_share": float(1 - reference.mean()),
        "reference": "ray_traced (Embree), exact hard shadows",
        "peer": "Embree (ray_traced)",
        "error_unit": "visibility × 255 (a white receiver under a unit light)",
        "cases": cases,
    }


def shadow_frame_cost(
    scene: bp.Scene, points: np.ndarray, normals: np.ndarray, *, quick: bool = False, repeat: int = 3
) -> list[dict]:
    """Seconds of Embree ray tracing (its BVH built in every call) and of nearest-texel shadow maps
    (bias 1e-4 + 2·slope) for several receiver counts ``N`` (the visible points, repeated or cut),
    resolutions ``R`` and two triangle counts ``T`` (the scene, and the same with a 192-segment
    sphere): the data of the frame-aware cost model
    (:func:`blinn_phong.planning.calibration.shadow_map_cost`), fitted to the fastest round (``min_s``)."""
    from blinn_phong.shadows.maps import light_shadow_maps, shadow_map_visibility
    from blinn_phong.shadows.raytrace import RayScene, directional_light_visibility, world_triangles

    light = scene.lights[0]
    to_light = -np.asarray(light.direction, float)
    counts = (4_000, 64_000) if quick else (4_000, 16_000, 64_000, 256_000)
    resolutions = (64, 512) if quick else (64, 256, 1024)
    rows = []
    # the calibration scene and the same with a 192-segment sphere: the triangle terms
    for tris in (world_triangles(scene)[0], world_triangles(shadow_scene(192))[0]):
        for n in counts:
            pick = np.arange(n) % len(points)
            p, nrm = points[pick], normals[pick]
            runs: dict[str, Callable[[], object]] = {
                "ray_traced": lambda p=p, nrm=nrm, tris=tris: directional_light_visibility(
                    RayScene(tris), p, nrm, to_light
                )
            }
            for res in resolutions:

                def run(res=res, p=p, nrm=nrm, tris=tris) -> np.ndarray:
                    maps = light_shadow_maps(light, tris, res, constant_bias=1e-4, slope_bias=2.0)
                    return shadow_map_visibility(light, maps, p, nrm, kernel="nearest")

                runs[f"map {res}"] = run
            times = time_interleaved(runs, repeat=repeat)
            common = {"receivers": n, "triangles": len(tris)}
            rows.append(
                {
                    **common,
                    "method": "ray_traced",
                    **{k: times["ray_traced"][k] for k in ("median_s", "min_s")},
                }
            )
            rows += [
                {
                    **common,
                    "method": "shadow_map",
                    "resolution": res,
                    **{k: times[f"map {res}"][k] for k in ("median_s", "min_s")},
                }
                for res in resolutions
            ]
    return rows


def shadow_frame_constants(quick: bool = False, repeat: int = 3) -> list[dict]:
    """What a ``render()`` frame adds to, and saves from, the per-receiver cost of Embree ray tracing.

    In a frame the compiled engine first forms every covered pixel's world point and face normal
    (``surface``, shared by every shadow method), and traces only the shadow rays
    :mod:`blinn_phong.shadows.ray_culling` cannot answer (its pass: ``cull``; the rays left: the
    ``traced`` share). Per scene, frame and light: the seconds of those passes and of Embree
    tracing every ray (BVH cached, as within a frame), their ratios per receiver to Embree's
    (``surface_ratio``, ``cull_ratio``), the traced share and the share of receivers on meshes
    whose rays the culling never answers (``general_share``). Scenes: the shadow calibration
    scene and the frame benchmark's, whose casters are convex or planar.
    """
    from benchmarks.bench_frame import issue_scene
    from blinn_phong.frame.pipeline import _world_triangles, _world_vertices
    from blinn_phong.geometry.raster_kernels import (
        nearest_winners_compiled,
        setup_triangles_compiled,
        winner_surfaces_compiled,
    )
    from blinn_phong.shadows import raytrace
    from blinn_phong.shadows.ray_culling import GENERAL, TRACE, caster_tables
    from blinn_phong.shadows.ray_traced import _ray_answers, ray_target

    frames = [("shadow calibration", shadow_scene(), 256, 256)]
    frames.append(("frame benchmark", issue_scene(48 if quick else 96, 24 if quick else 48), 640, 360))
    rows = []
    for name, scene, width, height in frames:
        prepared = bp.prepare_scene(scene)
        setup = setup_triangles_compiled(prepared.clip, prepared.triangles, width, height, 1, False)
        winner = nearest_winners_compiled(setup)
        verts = _world_vertices(scene)
        every = np.concatenate(verts)

        def surfaces(setup=setup, winner=winner, prepared=prepared, every=every):
            return winner_surfaces_compiled(setup, winner, prepared.triangles, every, prepared.triangle_mesh)

        points, normals, _, mesh_of = surfaces()
        tris = _world_triangles(scene, verts)
        bvh = raytrace.cached_ray_scene(tris)
        tables = caster_tables(scene, bvh.centre)
        general = float(np.mean(tables[0][mesh_of] == GENERAL))
        for j, light in enumerate(scene.lights):
            vec, positional = ray_target(light)
            trace = raytrace.point_light_visibility if positional else raytrace.directional_light_visibility
            trace_all = functools.partial(trace, bvh, points, normals, vec)
            cull = functools.partial(_ray_answers, light, points, normals, mesh_of, bvh.centre, tables)
            times = time_interleaved({"surface": surfaces, "cull": cull, "embree": trace_all}, repeat=repeat)
            traced = float(np.mean(cull() == TRACE))
            rows.append(
                {
                    "scene": name,
                    "width": width,
                    "height": height,
                    "light": j,
                    "receivers": len(points),
                    "triangles": len(tris),
                    **{f"{k}_s": times[k]["min_s"] for k in ("surface", "cull", "embree")},
                    "surface_ratio": times["surface"]["min_s"] / times["embree"]["min_s"],
                    "cull_ratio": times["cull"]["min_s"] / times["embree"]["min_s"],
                    "traced_share": traced,
                    "general_share": general,
                }
            )
    return rows


# --------------------------------------------------------------------------- transparency


def transparency(quick: bool = False, repeat: int = 3) -> dict:
    """Sorted, depth-peeled and weighted-blended transparency vs the A-buffer as layers and opacity grow."""
    size = 96 if quick else 160
    layer_counts = (2, 4, 8) if quick else (2, 4, 8, 16)
    opacities = (0.3, 0.8) if quick else (0.2, 0.5, 0.8)
    peel = (1, 2, 4)
    cases = []
    for n in layer_counts:
        for alpha in opacities:
            fr = transparent_fragments(layered_scene(n, alpha), size)
            background = np.tile([0.5, 0.5, 0.5, 1.0], (fr["n_pixels"], 1))
            methods = transparency_methods(fr, background, peel)
            times = time_interleaved(methods, repeat=repeat)
            reference = methods["a_buffer"]()
            for name, fn in methods.items():
                cases.append(
                    {
                        "method": "depth_peeling" if name.startswith("depth_peeling") else name,
                        "label": name,
                        "layers": n,
                        "opacity": alpha,
                        **({"peel_layers": int(name.rsplit("_", 1)[1])} if name.startswith("depth_") else {}),
                        "median_s": times[name]["median_s"],
                        "ratio_to_a_buffer": times[name]["median_s"] / times["a_buffer"]["median_s"],
                        **error_metrics(fn(), reference),
                    }
                )
    return {
        "family": "transparency",
        "title": "Transparency: sorting, depth peeling, WBOIT vs the A-buffer",
        "scene": "N quads tilted ±30° so neighbours interpenetrate, opacity α, over grey, seen from above",
        "size": [size, size],
        "reference": "a_buffer (exact per-pixel sort)",
        "cases": cases,
    }


# --------------------------------------------------------------------------- compositing precision


def layer_stack(n: int, shape: tuple[int, int], seed: int = 11) -> tuple[np.ndarray, np.ndarray]:
    """``n`` straight-alpha float64 layers (colour in [0, 1], α in [0.02, 0.3]) and an opaque background."""
    rng = np.random.default_rng(seed)
    straight = rng.uniform(0.0, 1.0, (n, *shape, 4))
    straight[..., 3] = rng.uniform(0.02, 0.3, (n, *shape))
    background = np.empty((*shape, 4))
    background[..., :3] = rng.uniform(0.0, 1.0, (*shape, 3))
    background[..., 3] = 1.0
    return straight, background


def _unorm8(x: np.ndarray) -> np.ndarray:
    """Values rounded to the nearest multiple of 1/255 (an 8-bit buffer), as float32."""
    return (np.rint(np.clip(x, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)


def compositing_pipelines(
    straight: np.ndarray, background: np.ndarray
) -> dict[str, Callable[[], np.ndarray]]:
    """The ``over`` stack in every precision and alpha convention; each returns premultiplied float64."""
    premult64 = np.stack([premultiply(layer) for layer in straight])
    premult32 = premult64.astype(np.float32)
    premult16 = premult64.astype(np.float16)
    premult8 = _unorm8(premult64)

    def stack(layers: np.ndarray, dtype: type) -> np.ndarray:
        # composite_stack: one pass per tile, bitwise equal to a loop of composite(layer, acc).
        return composite_stack([background.astype(dtype), *layers]).astype(np.float64)

    def float16_storage() -> np.ndarray:
        # Blending arithmetic in float32, the framebuffer stored as float16 (RGBA16F).
        acc = background.astype(np.float16)
        for layer in premult16:
            acc = composite(layer.astype(np.float32), acc.astype(np.float32), "src_over").astype(np.float16)
        return acc.astype(np.float64)

    def unorm8_premultiplied() -> np.ndarray:
        acc = _unorm8(background)
        for layer in premult8:
            acc = gl_blend(layer, acc, "ONE", "ONE_MINUS_SRC_ALPHA", target="unorm8")
        return acc.astype(np.float64)

    codes8 = [np.rint(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8) for x in (background, *straight)]

    def unorm8_straight() -> np.ndarray:
        # Straight 8-bit layers and an 8-bit straight buffer: premultiply, over, unpremultiply, store
        # (composite_stack on uint8 layers; the same values as that loop on _unorm8 floats).
        acc = composite_stack(codes8)
        return premultiply((acc.astype(np.float32) / np.float32(255.0)).astype(np.float64))

    return {
        "float64 premultiplied": lambda: stack(premult64, np.float64),
        "float32 premultiplied": lambda: stack(premult32, np.float32),
        "float16 premultiplied": float16_storage,
        "unorm8 premultiplied": unorm8_premultiplied,
        "unorm8 straight": unorm8_straight,
    }


def compositing_peers(straight: np.ndarray, background: np.ndarray) -> dict[str, Callable[[], np.ndarray]]:
    """OpenImageIO ``over`` (float32 premultiplied) and Pillow ``alpha_composite`` (straight 8-bit)."""
    peers: dict[str, Callable[[], np.ndarray]] = {}
    premult32 = np.stack([premultiply(layer) for layer in straight]).astype(np.float32)
    try:
        import OpenImageIO as oiio  # noqa: N813 - the project's usual alias
    except ImportError:  # pragma: no cover
        oiio = None
    if oiio is not None:
        bufs = [oiio.ImageBuf(np.ascontiguousarray(layer)) for layer in premult32]
        bg = oiio.ImageBuf(np.ascontiguousarray(background.astype(np.float32)))

        def oiio_over() -> np.ndarray:
            acc = bg
            for buf in bufs:
                acc = oiio.ImageBufAlgo.over(buf, acc)
            return acc.get_pixels(oiio.FLOAT).astype(np.float64)

        peers["OpenImageIO over (float32)"] = oiio_over
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover
        Image = None
    if Image is not None:
        imgs = [Image.fromarray(np.rint(layer * 255).astype(np.uint8), "RGBA") for layer in straight]
        bg8 = Image.fromarray(np.rint(background * 255).astype(np.uint8), "RGBA")

        def pillow() -> np.ndarray:
            acc = bg8
            for img in imgs:
                acc = Image.alpha_composite(acc, img)
            return premultiply(np.asarray(acc, dtype=np.float64) / 255.0)

        peers["Pillow alpha_composite (straight unorm8)"] = pillow
    return peers


def compositing_precision(quick: bool = False, repeat: int = 3) -> dict:
    """An N-layer ``over`` stack in every precision/convention against float64 premultiplied."""
    shape = (128, 128) if quick else (256, 256)
    counts = (2, 8, 32) if quick else (2, 8, 32, 128)
    cases = []
    for n in counts:
        straight, background = layer_stack(n, shape)
        runs = {**compositing_pipelines(straight, background), **compositing_peers(straight, background)}
        times = time_interleaved(runs, repeat=repeat)
        reference = runs["float64 premultiplied"]()
        peer = (
            "OpenImageIO over (float32)" if "OpenImageIO over (float32)" in times else "float32 premultiplied"
        )
        for name, fn in runs.items():
            cases.append(
                {
                    "method": name,
                    "peer": name not in ("float64 premultiplied",) and "(" in name,
                    "layers": n,
                    "median_s": times[name]["median_s"],
                    "ratio_to_oiio": times[name]["median_s"] / times[peer]["median_s"],
                    **error_metrics(fn(), reference),
                }
            )
    return {
        "family": "compositing",
        "title": "Compositing precision: N-layer over stack",
        "scene": "N random layers (α in [0.02, 0.3]) over an opaque random background",
        "size": list(shape),
        "reference": "float64 premultiplied",
        "peer": "OpenImageIO ImageBufAlgo.over (ratios); Pillow alpha_composite",
        "cases": cases,
    }


# --------------------------------------------------------------------------- scaling


def scaling(quick: bool = False, repeat: int = 3) -> dict:
    """Render time against pixel count and triangle count, ours (Phong) and Mesa's GLSL shader."""
    sizes = (128, 256, 512) if quick else (128, 256, 512, 1024)
    segments = (16, 64, 256) if quick else (16, 32, 64, 128, 256, 512)
    mesa_reason = mesa_available()

    def measure(scene: bp.Scene, size: int) -> dict:
        runs: dict[str, Callable] = {
            "phong": lambda: bp.render(
                scene, size, size, shading="phong", shadows="none", transparency="zbuffer"
            )
        }
        times = time_interleaved(runs, repeat=repeat)
        row = {"ours_s": times["phong"]["median_s"]}
        if mesa_reason is None:
            from oracles import gl_lighting

            gl_lighting.render_glsl_phong(scene, size, size)
            row["mesa_glsl_s"] = float(
                np.median([gl_lighting.render_glsl_phong(scene, size, size).seconds for _ in range(repeat)])
            )
            row["ratio_to_mesa_glsl"] = row["ours_s"] / row["mesa_glsl_s"]
        return row

    pixel_rows = []
    scene = sphere_scene(64)
    for size in sizes:
        pixel_rows.append({"pixels": size * size, "size": size, **measure(scene, size)})
    triangle_rows = []
    for seg in segments:
        sc = sphere_scene(seg)
        triangle_rows.append({"triangles": len(sc.meshes[0].triangles), "segments": seg, **measure(sc, 256)})
    return {
        "family": "scaling",
        "title": "Scaling: time against pixels and triangles",
        "scene": "sphere_scene, Phong shading, 1 sample per pixel",
        "peer": "Mesa llvmpipe GLSL per-pixel shader" if mesa_reason is None else None,
        "peer_unavailable": mesa_reason,
        "pixels": pixel_rows,
        "triangles": triangle_rows,
    }


# --------------------------------------------------------------------------- frame costs


def timed_renders(
    runs: dict[str, Callable[[], bp.RenderResult]], repeat: int = 5
) -> dict[str, dict[str, float]]:
    """Seconds of whole ``render()`` calls and of each stage (``RenderStats.seconds``), interleaved
    round-robin after one untimed call each (:func:`benchmarks._util.time_interleaved`'s scheme):
    ``<stage>_s`` the smallest over the rounds (on a shared machine the least disturbed run:
    contention only adds time), ``<stage>_median_s`` the median; ``total`` is the whole call's
    wall time and ``cpu`` its process CPU time (every thread; unlike wall time it does not
    grow when other processes preempt this one)."""
    import statistics
    import time

    for fn in runs.values():
        fn()
    stages: dict[str, dict[str, list[float]]] = {name: {"total": [], "cpu": []} for name in runs}
    for _ in range(repeat):
        for name, fn in runs.items():
            start, cpu = time.perf_counter(), time.process_time()
            result = fn()
            stages[name]["total"].append(time.perf_counter() - start)
            stages[name]["cpu"].append(time.process_time() - cpu)
            for stage, sec in result.stats.seconds.items():
                stages[name].setdefault(stage, []).append(sec)
    out: dict[str, dict[str, float]] = {}
    for name, table in stages.items():
        out[name] = {}
        for stage, v in table.items():
            out[name][f"{stage}_s"] = min(v)
            out[name][f"{stage}_median_s"] = statistics.median(v)
    return out


#: Shadow-map resolutions timed per directional light by :func:`shadow_stage_rows`.
STAGE_MAP_RESOLUTIONS = (256, 1024)


def uncached(fn: Callable[[], bp.RenderResult]) -> Callable[[], bp.RenderResult]:
    """``fn`` run with the ray tracer's scene cache and the shadow volumes' adjacency and volume
    caches emptied first: every frame builds its BVH and its volumes, as the first frame of a
    scene or every frame of an animation does (``render()`` reuses both while the same
    triangles come back)."""
    from blinn_phong.shadows import raytrace, volume_mesh
    from blinn_phong.shadows import volume as shadow_volume
    def run() -> bp.RenderResult:
        raytrace._SCENE_CACHE.clear()
        volume_mesh._TOPOLOGY_CACHE.clear()
        shadow_volume._DERIVED_CACHE.clear()
        return fn()

    return run


def shadow_runs(
    render: Callable[..., bp.RenderResult], scene: bp.Scene, light: int, resolutions: tuple[int, ...]
) -> dict[str, Callable[[], bp.RenderResult]]:
    """Frames with light ``light`` alone shadowed (the others ``"none"``), each building its BVH and
    volumes (:func:`uncached`): ``ray_traced``, ``shadow_volume`` and, for a directional light,
    ``shadow_map <R>`` for each of ``resolutions``. ``render(shadows=...)`` renders the frame."""
    n = len(scene.lights)

    def only(method: object) -> list[object]:
        return [method if i == light else "none" for i in range(n)]

    runs = {
        "ray_traced": uncached(functools.partial(render, shadows=only("ray_traced"))),
        "shadow_volume": uncached(functools.partial(render, shadows=only("shadow_volume"))),
    }
    if isinstance(scene.lights[light], bp.DirectionalLight):
        for res in resolutions:
            options = bp.ShadowOptions("shadow_map", resolution=res)
            runs[f"shadow_map {res}"] = uncached(functools.partial(render, shadows=only(options)))
    return runs


def shadow_stage_rows(quick: bool = False, repeat: int = 3) -> list[dict]:
    """``shadows``-stage seconds of whole ``render()`` frames, one light shadowed at a time.

    For the shadow calibration scene (:func:`shadow_scene`) and the frame benchmark's opaque scene
    (:func:`benchmarks.bench_frame.issue_scene`, two sizes of spheres) at a few sizes: Embree
    ray tracing, shadow volumes and, for directional lights, shadow maps (256², 1024²), each
    frame building its BVH and volumes (:func:`uncached`), interleaved; with the frame's
    samples ``N``, triangles ``T`` and the planner's estimate of the traced share
    (:func:`blinn_phong.planning.planner.traced_share`) — the data of the frame-stage cost fit
    (:func:`blinn_phong.planning.calibration.shadow_volume_cost`,
    :func:`blinn_phong.planning.calibration.shadow_map_cost`).
    """
    from benchmarks.bench_frame import issue_scene
    from blinn_phong.planning.planner import traced_share

    frames = [
        ("shadow calibration", shadow_scene(), 128, 128),
        ("shadow calibration", shadow_scene(), 384, 384),
        ("issue", issue_scene(48 if quick else 96, 24 if quick else 48), 320, 180),
        ("issue", issue_scene(48 if quick else 96, 24 if quick else 48), 640, 360),
    ]
    if not quick:
        frames.append(("issue 256", issue_scene(256, 128), 320, 180))
    rows = []
    for name, scene, w, h in frames:
        render = functools.partial(bp.render, scene, w, h)
        share = traced_share(scene)
        for j, light in enumerate(scene.lights):
            if isinstance(light, bp.AmbientLight):
                continue

            runs = shadow_runs(render, scene, j, STAGE_MAP_RESOLUTIONS)
            times = timed_renders(runs, repeat)
            for label, t in times.items():
                method, _, res = label.partition(" ")
                rows.append(
                    {
                        "kind": "shadows",
                        "scene": name,
                        "light": j,
                        "method": method,
                        **({"resolution": int(res)} if res else {}),
                        "width": w,
                        "height": h,
                        "samples": w * h,
                        "triangles": sum(len(m.triangles) for m in scene.meshes),
                        "traced_share": share,
                        "shadows_s": t["shadows_s"],
                        "shadows_median_s": t["shadows_median_s"],
                    }
                )
    return rows


#: Transparency methods timed per frame by :func:`frame_costs` (``depth_peeling`` with these layers).
FRAME_COST_PEEL = (1, 2, 4)


def frame_costs(quick: bool = False, repeat: int = 3) -> dict:
    """``render()`` timings for the frame-aware cost models of the planner
    (:func:`blinn_phong.planning.calibration.resolve_cost`,
    :func:`blinn_phong.planning.calibration.frame_seconds`).

    Transparency rows: the transparency calibration scene (:func:`layered_scene`, 4 and 12
    layers) and the frame benchmark's scene with its transparent sphere
    (:func:`benchmarks.bench_frame.issue_scene`, 96 × 48 segments), each at two sizes (and the
    benchmark's 256 × 128-segment scene at 320×180, for the triangle terms), rendered
    with the A-buffer, draw-last, sorted objects and depth peeling (1, 2, 4 layers), no shadows:
    the whole frame's process CPU time (the fits' data; the methods differ in the
    ``resolve_samples`` stage only, whose wall times are kept but, a few milliseconds, are
    swamped by preemption on a loaded machine), wall time and stage times. Opaque rows:
    :func:`sphere_scene` and the frame benchmark's opaque scene at two sizes (one with 2×2
    samples), Phong, Gouraud, flat and Phong with exp fog: the whole frame (CPU and wall). Every method of a
    frame is timed in the same interleaved rounds; the fits use the fastest round of each
    (:func:`timed_renders`), the medians are kept.
    """
    from benchmarks.bench_frame import issue_scene

    small = quick
    transparent_frames = [
        ("layered 4", layered_scene(4, 0.5), 96, 96, 1),
        ("layered 4", layered_scene(4, 0.5), 192, 192, 1),
        ("layered 12", layered_scene(12, 0.5), 96, 96, 1),
        ("layered 12", layered_scene(12, 0.5), 192, 192, 1),
        ("issue transparent", issue_scene(48 if small else 96, 24 if small else 48, True), 320, 180, 1),
        ("issue transparent", issue_scene(48 if small else 96, 24 if small else 48, True), 640, 360, 1),
    ]
    if not small:  # the benchmark's own triangle count: anchors the triangle terms
        transparent_frames.append(("issue 256 transparent", issue_scene(256, 128, True), 320, 180, 1))
    opaque_frames = [
        ("sphere 32", sphere_scene(32), 128, 128, 1),
        ("sphere 32", sphere_scene(32), 256, 256, 1),
        ("issue", issue_scene(48 if small else 96, 24 if small else 48), 320, 180, 1),
        ("issue", issue_scene(48 if small else 96, 24 if small else 48), 320, 180, 2),
        ("issue", issue_scene(48 if small else 96, 24 if small else 48), 640, 360, 1),
    ]
    if not small:
        opaque_frames.append(("issue 256", issue_scene(256, 128), 320, 180, 1))
    rows = []
    for name, scene, w, h, k in transparent_frames:
        frame = functools.partial(bp.render, scene, w, h, samples=k * k, shadows="none")
        runs: dict[str, Callable[[], bp.RenderResult]] = {
            method: functools.partial(frame, transparency=method)
            for method in ("a_buffer", "draw_last", "sort_objects")
        }
        for layers in FRAME_COST_PEEL:
            runs[f"depth_peeling {layers}"] = functools.partial(
                frame, transparency="depth_peeling", layers=layers
            )
        times = timed_renders(runs, repeat)
        for label, t in times.items():
            method, _, layers = label.partition(" ")
            rows.append(
                {
                    "kind": "transparency",
                    "scene": name,
                    "method": method,
                    **({"layers": int(layers)} if layers else {}),
                    "width": w,
                    "height": h,
                    "samples_per_axis": k,
                    "samples": w * h * k * k,
                    "triangles": sum(len(m.triangles) for m in scene.meshes),
                    "resolve_s": t["resolve_samples_s"],
                    "resolve_median_s": t["resolve_samples_median_s"],
                    "total_s": t["total_s"],
                    "total_median_s": t["total_median_s"],
                    "cpu_s": t["cpu_s"],
                    "cpu_median_s": t["cpu_median_s"],
                    "ratio_to_a_buffer": t["cpu_s"] / times["a_buffer"]["cpu_s"],
                }
            )
    fog = bp.Fog("exp", (0.5, 0.6, 0.7), density=0.05)
    for name, scene, w, h, k in opaque_frames:
        frame = functools.partial(bp.render, scene, w, h, samples=k * k, shadows="none")
        runs = {
            shading: functools.partial(frame, shading=shading) for shading in ("phong", "gouraud", "flat")
        }
        runs["fog"] = functools.partial(frame, shading="phong", fog=fog)
        times = timed_renders(runs, repeat)
        for variant, t in times.items():
            rows.append(
                {
                    "kind": "frame",
                    "scene": name,
                    "method": variant,
                    "width": w,
                    "height": h,
                    "samples_per_axis": k,
                    "samples": w * h * k * k,
                    "triangles": sum(len(m.triangles) for m in scene.meshes),
                    "total_s": t["total_s"],
                    "total_median_s": t["total_median_s"],
                    "cpu_s": t["cpu_s"],
                    "cpu_median_s": t["cpu_median_s"],
                    "ratio_to_phong": t["cpu_s"] / times["phong"]["cpu_s"],
                }
            )
    rows += shadow_stage_rows(quick=quick, repeat=repeat)
    return {
        "family": "frame_costs",
        "title": "Frame costs: transparency resolve, shading and fog in whole render() calls",
        "scene": "layered quads, the frame benchmark's scene (transparent and opaque), a sphere; "
        "two sizes each",
        "reference": "a_buffer (transparency), phong (shading, fog)",
        "rows": rows,
    }


#: Family name → measurement function ``(quick, repeat) -> dict``.
FAMILIES: dict[str, Callable[..., dict]] = {
    "shading": shading,
    "antialiasing": antialiasing,
    "shadows": shadows,
    "transparency": transparency,
    "compositing": compositing_precision,
    "scaling": scaling,
    "frame_costs": frame_costs,
}
