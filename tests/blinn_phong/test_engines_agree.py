"""The compiled (numba) fast path agrees with the numpy reference.

The reference itself is checked against closed forms and Mesa elsewhere; here the
two engines must produce the same visible fragments (same triangle per sample,
barycentrics and depth equal up to summation order) and the same shading to float
rounding, on scenes that exercise near-plane clipping,
interpenetrating and coplanar surfaces (depth ties), supersampling, back faces,
all shading frequencies, every light type and both specular forms.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.frame.visibility import visible_fragments
from blinn_phong.model.primitives import grid_plane, uv_sphere

pytest.importorskip("numba")


def busy_scene(specular: str = "blinn", two_sided: bool = True) -> bp.Scene:
    meshes = []
    rng = np.random.default_rng(11)
    for i in range(5):
        pos, tris, normals = uv_sphere(20, 10)
        t = np.eye(4)
        t[:3, :3] = np.diag(rng.uniform(0.4, 1.2, 3))
        t[:3, 3] = rng.uniform(-1.5, 1.5, 3) + np.array([0, 0, 0.5 * i])  # some cross the near plane
        mat = bp.Material(
            diffuse=rng.uniform(0, 1, 3), specular=(0.8, 0.8, 0.8), shininess=float(rng.uniform(5, 90))
        )
        meshes.append(bp.Mesh(pos, tris, normals, transform=t, material=mat, back_material=bp.Material()))
    pos, tris, normals = grid_plane(6, 6, (8, 8))
    floor = np.array([[1, 0, 0, 0], [0, 0, 1, -1], [0, -1, 0, 0], [0, 0, 0, 1]], float)
    meshes.append(bp.Mesh(pos, tris, normals, transform=floor))
    meshes.append(bp.Mesh(pos, tris, normals, transform=floor))  # coplanar duplicate: exact depth ties
    lights = [
        bp.DirectionalLight((-1, -1, -1), ambient=(0.05, 0.05, 0.05)),
        bp.PointLight((2, 2, 2), linear=0.2, quadratic=0.05),
        bp.SpotLight((0, 4, 1), (0, -1, -0.2), 40, 8, quadratic=0.05),
        bp.AmbientLight((0.1, 0.1, 0.1)),
    ]
    cam = bp.Camera.perspective(60, 4 / 3, 0.5, 30, view=bp.look_at((0.3, 0.8, 3.0), (0, 0, 0)))
    return bp.Scene(meshes, lights, cam, light_model=bp.LightModel(specular=specular, two_sided=two_sided))


@pytest.mark.parametrize("samples", [1, 4])
def test_visible_fragments_are_identical(samples: int) -> None:
    prepared = bp.prepare_scene(busy_scene())
    ref = visible_fragments(prepared.clip, prepared.triangles, 96, 72, samples=samples, engine="numpy")
    fast = visible_fragments(prepared.clip, prepared.triangles, 96, 72, samples=samples, engine="numba")
    assert len(ref) > 0.5 * 96 * 72 * samples
    near_side = (prepared.clip[:, 2] + prepared.clip[:, 3] >= 0)[prepared.triangles].sum(axis=1)
    assert ((near_side == 1) | (near_side == 2)).any()  # near-plane clipping is exercised
    np.testing.assert_array_equal(fast.sample_key, ref.sample_key)
    np.testing.assert_array_equal(fast.triangle, ref.triangle)
    np.testing.assert_allclose(fast.depth, ref.depth, rtol=0, atol=1e-15)  # summation order only
    np.testing.assert_allclose(fast.bary, ref.bary, rtol=0, atol=1e-12)


@pytest.mark.parametrize("shading", ["flat", "gouraud", "phong"])
@pytest.mark.parametrize("specular", ["blinn", "phong"])
def test_renders_agree(shading: str, specular: str) -> None:
    scene = busy_scene(specular)
    ref = bp.render(scene, 80, 60, shading=shading, samples=4, engine="numpy")
    fast = bp.render(scene, 80, 60, shading=shading, samples=4, engine="numba")
    np.testing.assert_array_equal(fast.rgba[..., 3], ref.rgba[..., 3])
    np.testing.assert_allclose(fast.rgba, ref.rgba, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(fast.depth, ref.depth, rtol=0, atol=1e-7)
    for name in ("ambient", "diffuse", "specular"):
        np.testing.assert_allclose(fast.passes[name], ref.passes[name], rtol=1e-6, atol=1e-7)


def test_shade_engines_agree_with_visibility() -> None:
    rng = np.random.default_rng(5)
    n = 5000
    points = rng.normal(size=(n, 3)) - [0, 0, 4]
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    lights = bp.lights_in_eye_space([lt for lt in busy_scene().lights], np.eye(4))
    vis = rng.uniform(0, 1, (n, len(lights)))
    mat = bp.Material(emission=(0.1, 0, 0), specular=(1, 0.5, 0.2), shininess=33.0)
    for model in (bp.LightModel(), bp.LightModel(specular="phong", local_viewer=False)):
        a = bp.shade(points, normals, mat, lights, model=model, visibility=vis, engine="numpy")
        b = bp.shade(points, normals, mat, lights, model=model, visibility=vis, engine="numba")
        for name in ("ambient", "diffuse", "specular"):
            np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=1e-12, atol=1e-14)


# --------------------------------------------------------------------------- the frame pipeline's effects


def effects_scene(two_sided: bool) -> bp.Scene:
    """Interpenetrating transparent spheres of every transparency model over opaque geometry."""
    pos, tris, normals = uv_sphere(20, 10)
    rng = np.random.default_rng(5)
    materials = [
        bp.Material(diffuse=(0.2, 0.4, 0.9), specular=(0.9, 0.9, 0.9), shininess=40, opacity=0.5),
        bp.Material(diffuse=(0.9, 0.3, 0.2), opacity=0.4, transparency_model="emission"),
        bp.Material(diffuse=(0.3, 0.9, 0.3), opacity=0.6, transparency_model="absorption"),
        bp.Material(diffuse=(0.8, 0.8, 0.2), opacity=0.5, kay_greenberg=(0.1, 0.8, 2.5)),
        bp.Material(
            diffuse=(0.5, 0.5, 0.5), specular=(1, 1, 1), shininess=20, opacity=0.3, specular_washout=True
        ),
    ]
    meshes = []
    for i, material in enumerate(materials):
        t = np.eye(4)
        t[:3, :3] *= rng.uniform(0.5, 0.9)
        t[:3, 3] = rng.uniform(-0.8, 0.8, 3)
        back = bp.Material(diffuse=(0.1, 0.1, 0.8), opacity=0.7) if i == 0 else None
        meshes.append(bp.Mesh(pos, tris, normals, transform=t, material=material, back_material=back))
    plane, ptris, pnormals = grid_plane(2, 2, (6, 6))
    floor = np.eye(4)
    floor[2, 3] = -1.2
    meshes.append(bp.Mesh(plane, ptris, pnormals, transform=floor))
    t = np.eye(4)
    t[:3, :3] *= 0.4
    meshes.append(bp.Mesh(pos, tris, normals, transform=t))  # an opaque ball inside the glass
    lights = [bp.DirectionalLight((0.3, 0.4, -1)), bp.PointLight((1.5, -1, 2.5), quadratic=0.1)]
    cam = bp.Camera.perspective(50, 4 / 3, 1.0, 12, view=bp.look_at((0.5, -4.0, 2.0), (0, 0, 0), (0, 0, 1)))
    return bp.Scene(meshes, lights, cam, light_model=bp.LightModel(two_sided=two_sided))


@pytest.mark.parametrize("samples", [1, 4])
def test_frame_fragments_are_identical(samples: int) -> None:
    # The visible-fragment lists: same opaque winners, same transparent fragments in the same order.
    from blinn_phong.frame.resolve import side_tables
    from blinn_phong.frame.visibility import frame_fragments

    scene = effects_scene(two_sided=True)
    prepared = bp.prepare_scene(scene)
    _, side_opaque = side_tables(scene)

    def opaque(triangle: np.ndarray, front: np.ndarray) -> np.ndarray:
        return side_opaque[2 * prepared.triangle_mesh[triangle] + ~front]

    args = (prepared.clip, prepared.triangles, 64, 48)
    ref = frame_fragments(*args, opaque=opaque, samples=samples, engine="numpy")
    fast = frame_fragments(*args, opaque=opaque, samples=samples, engine="numba")
    assert ref.n_opaque > 0 and np.diff(ref.offsets).max() >= 3  # layers of glass in front of opaque ones
    assert fast.n_opaque == ref.n_opaque
    np.testing.assert_array_equal(fast.opaque_of, ref.opaque_of)
    np.testing.assert_array_equal(fast.offsets, ref.offsets)
    np.testing.assert_array_equal(fast.fragments.sample_key, ref.fragments.sample_key)
    np.testing.assert_array_equal(fast.fragments.triangle, ref.fragments.triangle)
    np.testing.assert_array_equal(fast.fragments.front_facing, ref.fragments.front_facing)
    np.testing.assert_allclose(fast.fragments.depth, ref.fragments.depth, rtol=0, atol=1e-15)
    np.testing.assert_allclose(fast.fragments.bary, ref.fragments.bary, rtol=0, atol=1e-12)


FRAME_CASES = [
    {"transparency": method}
    for method in (
        "zbuffer",
        "a_buffer",
        "draw_last",
        "sort_objects",
        "sort_triangles",
        "depth_peeling",
        "weighted_blended",
    )
] + [
    {"transparency": "depth_peeling", "peel_layers": 2},
    {"transparency": "weighted_blended", "wboit_weight": "constant"},
    {"transparency": "a_buffer", "fog": bp.Fog("exp", (0.5, 0.6, 0.7), density=0.3)},
    {"transparency": "a_buffer", "fog": bp.Fog("exp2", (0.2, 0.2, 0.2), density=0.2, distance="radial")},
    {"transparency": "zbuffer", "fog": bp.Fog("linear", (1, 1, 1), start=3.0, end=7.0)},
    {"transparency": "a_buffer", "shadows": bp.ShadowOptions("shadow_map", resolution=128)},
    {"transparency": "a_buffer", "shading": "gouraud"},
]


@pytest.mark.parametrize("samples", [1, 4])
@pytest.mark.parametrize("options", FRAME_CASES, ids=lambda o: "-".join(str(v) for v in o.values())[:40])
def test_frame_engines_agree_on_every_effect(options: dict, samples: int) -> None:
    # Every buffer of the compiled frame equals the numpy reference's within 1e-6: the stages
    # compute the same formulas in the same order, so only libm and rounding of float64 sums could
    # differ, far below float32's step near 1 (6e-8) — 1e-6 leaves room for that.
    scene = effects_scene(two_sided=options.get("shading") != "gouraud")
    options = {"shadows": "none", **options}
    ref = bp.render(scene, 48, 36, samples=samples, engine="numpy", **options)
    fast = bp.render(scene, 48, 36, samples=samples, engine="numba", **options)
    assert ref.stats.shaded == fast.stats.shaded
    if options["transparency"] != "zbuffer":
        assert (ref.rgba[..., 3] > 0).mean() > 0.3 and ((ref.rgba[..., 3] > 0) & (ref.rgba[..., 3] < 1)).any()
    for name, a, b in [("rgba", ref.rgba, fast.rgba), ("depth", ref.depth, fast.depth)] + [
        (name, ref.passes[name], fast.passes[name]) for name in ref.passes
    ]:
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-6, err_msg=name)
    np.testing.assert_allclose(fast.normal, ref.normal, rtol=0, atol=1e-6)
    assert set(fast.passes) == set(ref.passes)


def test_bands_give_the_single_pass_image(monkeypatch: pytest.MonkeyPatch) -> None:
    # Shading and resolving in bands of rows changes nothing: each stage works per fragment or per
    # sample, so the images are equal bit for bit (deterministic by construction).
    from blinn_phong.frame import pipeline

    scene = effects_scene(two_sided=True)
    options = {
        "transparency": "a_buffer",
        "shadows": bp.ShadowOptions("shadow_map", resolution=64),
        "samples": 4,
    }
    for engine in ("numpy", "numba"):
        monkeypatch.setattr(pipeline, "BAND_SAMPLES", 1 << 30)
        whole = bp.render(scene, 48, 36, engine=engine, **options)
        monkeypatch.setattr(pipeline, "BAND_SAMPLES", 7 * 48 * 4)  # 7 rows per band, the last one shorter
        banded = bp.render(scene, 48, 36, engine=engine, **options)
        for a, b in [(whole.rgba, banded.rgba), (whole.depth, banded.depth), (whole.normal, banded.normal)]:
            # bitwise: per-sample kernels with no reduction across bands: deterministic by construction
            np.testing.assert_array_equal(a, b)
        for name in whole.passes:
            np.testing.assert_array_equal(whole.passes[name], banded.passes[name])
