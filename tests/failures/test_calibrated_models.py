"""The calibrated error models hold on scenes that were not used to fit them.

``blinn_phong/planning/calibration.json`` (read by :mod:`blinn_phong.planning.calibration`) is fitted by
:mod:`benchmarks.error_models` to the measurements of ``python -m benchmarks`` (layered
quads with seed 7, layer counts 2–16 and opacities 0.2/0.5/0.8; one shadow scene; a sphere
with shininess 40 and segments 8–128). Here other scenes — other seeds, layer counts,
opacities, casters, light directions, tessellations and shininess — are measured against
their exact references (the A-buffer, Embree ray tracing, supersampled per-pixel shading of
a fine mesh): every predicted error must bound the measured one, and every method chosen
for a tolerance in 8-bit steps (by the ``choose_*`` functions and by
:func:`blinn_phong.plan`) must stay within it. ``test_planner_calibrated.py`` checks whole
renders that follow the plan.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from benchmarks import error_models as em
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.planning import calibration as cal
from testbeds.error_metrics import error_metrics, has_nonfinite
from testbeds.tradeoff_scenes import (
    layered_scene,
    transparency_methods,
    transparent_fragments,
    visible_points,
)

MODELS = cal.shipped_models()


@pytest.mark.parametrize(("layers", "opacity", "seed"), [(6, 0.6, 21), (12, 0.35, 5), (3, 0.9, 2)])
def test_depth_peeling_model_bounds_held_out_scenes(layers: int, opacity: float, seed: int) -> None:
    fr = transparent_fragments(layered_scene(layers, opacity, seed=seed), 64)
    background = np.tile([0.5, 0.5, 0.5, 1.0], (fr["n_pixels"], 1))
    methods = transparency_methods(fr, background, peel=tuple(range(1, layers)))
    reference = methods["a_buffer"]()
    brightest = cal.brightest_radiance(fr["rgba"])
    for k in range(1, layers):
        image = methods[f"depth_peeling_{k}"]()
        assert not has_nonfinite(image)
        measured = error_metrics(image, reference)["max_steps"]
        assert measured <= cal.predict_depth_peeling(MODELS, k, opacity, brightest) + 1e-9
    for tolerance in (2.0, 8.0, 32.0):
        choice = cal.choose_depth_peeling(MODELS, tolerance, opacity, brightest, max_layers=layers)
        if choice["method"] == "depth_peeling":
            image = methods[f"depth_peeling_{choice['layers']}"]()
        else:
            image = methods[choice["method"]]()
        assert error_metrics(image, reference)["max_steps"] <= tolerance


def _held_out_shadow_scene() -> tuple[bp.Scene, float]:
    gp, gt, gn = grid_plane(1, 1, (7.0, 7.0))
    meshes = [bp.Mesh(gp, gt, gn)]
    radii = []
    # the small sphere hangs between the light and the large one: it shadows a curved receiver
    for centre, radius in (((-1.0, 0.5, 1.0), 0.5), ((1.2, -0.5, 1.6), 0.9), ((1.67, -1.27, 3.17), 0.4)):
        p, t, n = uv_sphere(40, 20, radius)
        move = np.eye(4)
        move[:3, 3] = centre
        meshes.append(bp.Mesh(p, t, n, transform=move))
        radii.append(radius)
    camera = bp.Camera.perspective(
        50.0, 1.0, 0.5, 50.0, view=bp.look_at((1.0, -6.0, 5.0), (0, 0, 0.5), (0, 0, 1))
    )
    return bp.Scene(meshes, [bp.DirectionalLight((-0.3, 0.5, -1.0))], camera), min(radii)


def test_shadow_map_model_bounds_a_held_out_scene() -> None:
    from blinn_phong.shadows.maps import light_shadow_maps, shadow_map_visibility
    from blinn_phong.shadows.raytrace import RayScene, directional_light_visibility, world_triangles

    scene, r_min = _held_out_shadow_scene()
    light = scene.lights[0]
    tris, _ = world_triangles(scene)
    points, normals = visible_points(scene, 128)
    to_light = -np.asarray(light.direction, float)
    facing = normals @ to_light > 0
    points, normals = points[facing], normals[facing]
    exact = directional_light_visibility(RayScene(tris), points, normals, to_light)
    shadowed = float(1 - exact.mean())
    diameter = cal.scene_extent(tris)
    m = MODELS["shadow_map"]
    for res in (128, 256, 512, 1024):
        maps = light_shadow_maps(
            light, tris, res, constant_bias=m["constant_bias"], slope_bias=m["slope_bias"]
        )
        vis = shadow_map_visibility(light, maps, points, normals, kernel=m["kernel"])
        assert not has_nonfinite(vis)
        measured = error_metrics(vis, exact)["mean_steps"]
        assert measured <= cal.predict_shadow_map(MODELS, res, diameter, r_min, shadowed)
    for tolerance in (0.5, 2.0):
        choice = cal.choose_shadow_map(MODELS, tolerance, diameter, r_min, shadowed)
        if choice["method"] == "shadow_map":
            maps = light_shadow_maps(light, tris, choice["resolution"], constant_bias=1e-4, slope_bias=2.0)
            vis = shadow_map_visibility(light, maps, points, normals, kernel="nearest")
        else:
            vis = directional_light_visibility(RayScene(tris), points, normals, to_light)
        assert error_metrics(vis, exact)["mean_steps"] <= tolerance


def _held_out_sphere(segments: int) -> bp.Scene:
    material = bp.Material(
        ambient=(0.2, 0.2, 0.2), diffuse=(0.5, 0.45, 0.4), specular=(0.4, 0.4, 0.4), shininess=30.0
    )
    pos, tris, normals = uv_sphere(segments, segments // 2)
    camera = bp.Camera.perspective(30.0, 1.0, 1.0, 20.0, view=bp.look_at((0.5, 0.3, 4.2), (0, 0, 0)))
    return bp.Scene(
        [bp.Mesh(pos, tris, normals, material=material)],
        [bp.PointLight((-2.0, 1.5, 3.0))],
        camera,
        ambient=(0.1,) * 3,
    )


def test_shading_model_bounds_held_out_tessellations() -> None:
    size = 128
    reference = bp.render(_held_out_sphere(384), size, size, shading="phong", samples=4).rgba
    interior = reference[..., 3] >= 1.0
    for segments in (20, 40, 80):
        scene = _held_out_sphere(segments)
        mesh = scene.meshes[0]
        theta = cal.max_normal_angle(mesh.normals, mesh.triangles)
        for method in ("flat", "gouraud", "phong"):
            image = bp.render(scene, size, size, shading=method, samples=4).rgba
            assert not has_nonfinite(image)
            measured = error_metrics(image, reference, interior & (image[..., 3] >= 1.0))["max_steps"]
            assert measured <= cal.predict_shading(MODELS, method, theta), (segments, method)
        choice = cal.choose_shading(MODELS, 16.0, theta)
        if choice["predicted_steps"] <= 16.0:
            image = bp.render(scene, size, size, shading=choice["method"], samples=4).rgba
            assert error_metrics(image, reference, interior & (image[..., 3] >= 1.0))["max_steps"] <= 16.0


@pytest.mark.parametrize("tolerance", [1.0, 4.0, 16.0])
def test_the_planner_keeps_transparency_within_the_tolerance(tolerance: float) -> None:
    for layers, opacity, seed in ((6, 0.6, 21), (10, 0.3, 4)):
        scene = layered_scene(layers, opacity, seed=seed)
        choice = bp.plan(scene, tolerance).transparency
        assert choice.method in ("depth_peeling", "a_buffer")
        fr = transparent_fragments(scene, 64)
        background = np.tile([0.5, 0.5, 0.5, 1.0], (fr["n_pixels"], 1))
        k = int(choice.params.get("layers", 1))
        methods = transparency_methods(fr, background, peel=(k,))
        name = f"depth_peeling_{k}" if choice.method == "depth_peeling" else "a_buffer"
        measured = error_metrics(methods[name](), methods["a_buffer"]())["max_steps"]
        assert measured <= tolerance, (layers, opacity, choice)


@pytest.mark.parametrize("tolerance", [1.0, 16.0, 64.0])
def test_the_planner_keeps_shadows_within_the_tolerance(tolerance: float) -> None:
    from blinn_phong.shadows.methods import light_visibility
    from blinn_phong.shadows.raytrace import world_triangles

    scene, _ = _held_out_shadow_scene()
    light = scene.lights[0]
    tris, _ = world_triangles(scene)
    points, normals = visible_points(scene, 128)
    facing = normals @ -np.asarray(light.direction, float) > 0
    points, normals = points[facing], normals[facing]
    choice = bp.plan(scene, tolerance).shadows[0]
    # shadow volumes count faces in the camera's screen, as render() passes it
    extra = {"camera": scene.camera} if choice.method == "shadow_volume" else {}
    vis = light_visibility(choice.method, light, tris, points, normals, **choice.params, **extra)
    exact = light_visibility("ray_traced", light, tris, points, normals)
    assert not has_nonfinite(vis)
    assert error_metrics(vis, exact)["max_steps"] <= tolerance, choice


def test_the_shipped_models_are_the_fit_of_the_committed_measurements() -> None:
    import json
    from pathlib import Path

    measured = Path(em.__file__).resolve().parent / "results" / "tradeoffs.json"
    volumes = json.loads((measured.parent / "shadow_volume.json").read_text())
    refit = em.fit(json.loads(measured.read_text()), volumes)
    shipped = cal.load(cal.CALIBRATION_PATH)
    assert shipped == cal.shipped_models()  # the same file read twice: equal by construction
    # The refit is not bitwise reproducible across machines: np.polyfit solves its least-squares
    # problem with LAPACK (gelsd), whose blocked kernels (and so the last bits) depend on the CPU,
    # and np.log/np.exp dispatch to SIMD variants per CPU. LAPACK's solution is backward stable,
    # so its relative forward error is about cond(A)·ε; the column-scaled Vandermonde matrices
    # np.polyfit builds here have cond(A) < 1e3 (checked below), giving ≤ 1e3 · 2.2e-16 ≈ 2e-13
    # per solve. rtol = 1e-9 keeps three orders of margin above that (differences measured
    # between two CPUs were ≤ 2e-14 relative) while any change in the committed measurements —
    # which move the fitted numbers by far more than 1e-9 relative — still fails the test.
    _assert_models_close(refit, shipped, rtol=1e-9, where="calibration")


def _assert_models_close(a: object, b: object, rtol: float, where: str) -> None:
    """Equal structure, equal strings and integers, floats within ``rtol`` relative."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), f"{where}: keys {sorted(a)} != {sorted(b)}"
        for key in a:
            _assert_models_close(a[key], b[key], rtol, f"{where}/{key}")
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), f"{where}: lengths {len(a)} != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_models_close(x, y, rtol, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert np.isclose(a, b, rtol=rtol, atol=0.0), f"{where}: refit {a!r} != shipped {b!r}"
    else:
        assert a == b, f"{where}: refit {a!r} != shipped {b!r}"


def test_the_calibration_fits_are_well_conditioned() -> None:
    # The premise of the tolerance above: every polynomial fit's column-scaled design matrix has
    # a condition number below 1e3, so LAPACK's last-bit differences stay below ~2e-13 relative.
    import json
    from pathlib import Path

    data = json.loads((Path(em.__file__).resolve().parent / "results" / "tradeoffs.json").read_text())
    designs = []
    families = data["families"]
    peel = [
        c["peel_layers"]
        for c in families["transparency"]["cases"]
        if c["method"] == "depth_peeling" and c["peel_layers"] < c["layers"]
    ]
    designs.append(np.asarray(peel, float))
    designs.append(
        np.asarray(
            [c["resolution"] for c in families["shadows"]["cases"] if c["method"] == "shadow_map"], float
        )
        ** 2
    )
    for method in ("flat", "gouraud", "phong"):
        segments = [c["segments"] for c in families["shading"]["cases"] if c["method"] == method]
        designs.append(np.log(2 * np.pi / np.asarray(segments, float)))
    for x in designs:
        vander = np.vander(x, 2)
        vander = vander / np.sqrt((vander * vander).sum(axis=0))  # np.polyfit's column scaling
        assert np.linalg.cond(vander) < 1e3
    # the frame-aware shadow cost fit ([1, N] and [1, R², N], unit-norm columns as fitted)
    rows = families["shadows"]["frame_cost"]
    for method in ("ray_traced", "shadow_map"):
        design = em.frame_cost_design([r for r in rows if r["method"] == method])
        design = design / np.sqrt((design * design).sum(axis=0))
        assert np.linalg.cond(design) < 1e3
    # the exact shadow methods' cost fit ([1, T, N] over the crossover rows, unit-norm columns)
    volumes = json.loads((Path(em.__file__).resolve().parent / "results" / "shadow_volume.json").read_text())
    design = em.shadow_volume_cost_design(volumes["crossover"])
    design = design / np.sqrt((design * design).sum(axis=0))
    assert np.linalg.cond(design) < 1e3


def test_bad_model_inputs_name_the_argument() -> None:
    with pytest.raises(ValueError, match="tolerance"):
        cal.choose_depth_peeling(MODELS, 0.0, 0.5, 1.0, 4)
    with pytest.raises(ValueError, match="tolerance"):
        cal.choose_shadow_map(MODELS, float("nan"), 10.0, 1.0)
    with pytest.raises(ValueError, match="alpha_min"):
        cal.choose_depth_peeling(MODELS, 1.0, 0.0, 1.0, 4)
    with pytest.raises(ValueError, match="caster_size"):
        cal.choose_shadow_map(MODELS, 1.0, 10.0, 0.0)
    with pytest.raises(ValueError, match="method"):
        cal.predict_shading(MODELS, "toon", 0.1)
    with pytest.raises(ValueError, match="normals"):
        cal.max_normal_angle(np.zeros((3, 2)), np.zeros((1, 3), int))
