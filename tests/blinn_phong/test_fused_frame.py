"""The compiled plain frame (fused shading and resolve, compiled triangle set-up) against the references.

* the compiled triangle set-up equals :func:`blinn_phong.geometry.raster._setup_triangles` bit for bit
  (the same IEEE operations in the same order, no fast-math: deterministic by construction);
* the fused frame (one pass per pixel: interpolation, the lighting equation, the frame
  buffers) equals the numpy reference engine's frame within 1e-6 on a scene with every light
  type, two-sided lighting with back materials, near-plane clipping, empty pixels and both
  viewer models, with and without the GL-compatibility clamps and with shadows; flat and
  Gouraud meshes (lit per face or per vertex, carried to the pixels by the same pass) too, and
  frames whose transparent fragments the pass sorts and composites (A-buffer, depth peeling);
* fogged frames (linear, exp and exp2 fog, eye-plane and radial distance, with and without
  shadows, both viewer models) stay on the fused pass and equal the numpy engine's
  (which fogs by :mod:`blinn_phong.model.fog`'s numpy formulas) within 1e-6 (fog is refused with
  the GL-compatibility preset);
* per-channel visibility (N, L, 3) weights each light's diffuse and specular terms channel by
  channel: checked against the numpy engine's per-light terms (``shade(..., per_light=True)``)
  combined by hand.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.geometry.raster import _setup_triangles
from blinn_phong.model.primitives import grid_plane, uv_sphere

pytest.importorskip("numba")

from blinn_phong.frame.fused import shade_plain_fragments_compiled
from blinn_phong.geometry.raster_kernels import setup_triangles_compiled


def scene(local_viewer: bool = True, specular: str = "blinn") -> bp.Scene:
    rng = np.random.default_rng(5)
    meshes = []
    for i in range(3):
        pos, tris, normals = uv_sphere(18, 9)
        t = np.eye(4)
        t[:3, :3] = np.diag(rng.uniform(0.5, 1.1, 3))
        t[:3, 3] = (-1.2 + 1.2 * i, 0.2 * i, 0.8 * i)  # the last one crosses the near plane
        front = bp.Material(
            ambient=rng.uniform(0, 1, 3), diffuse=rng.uniform(0, 1, 3), specular=(0.9, 0.8, 0.7),
            shininess=float(rng.uniform(8, 100)), emission=(0.02, 0.0, 0.01), opacity=1.0 if i else 0.6,
        )  # fmt: skip
        back = bp.Material(diffuse=(0.1, 0.9, 0.2), specular=(0.3, 0.3, 0.3))
        meshes.append(bp.Mesh(pos, tris, normals, transform=t, material=front, back_material=back))
    pos, tris, normals = grid_plane(4, 4, (6, 6))
    floor = np.array([[1, 0, 0, 0], [0, 0, 1, -1], [0, -1, 0, 0], [0, 0, 0, 1]], float)
    meshes.append(bp.Mesh(pos, tris, normals, transform=floor))
    lights = [
        bp.DirectionalLight((-1, -1, -1), ambient=(0.05, 0.05, 0.05)),
        bp.PointLight((2, 2, 2), (0.9, 0.7, 0.5), linear=0.2, quadratic=0.05),
        bp.SpotLight((0, 4, 1), (0, -1, -0.2), 40, 8, quadratic=0.05),
        bp.AmbientLight((0.1, 0.1, 0.1)),
    ]
    cam = bp.Camera.perspective(60, 4 / 3, 1.0, 30, view=bp.look_at((0.3, 0.8, 2.6), (0, 0, 0)))
    model = bp.LightModel(specular=specular, two_sided=True, local_viewer=local_viewer)
    return bp.Scene(meshes, lights, cam, light_model=model)


@pytest.mark.parametrize("samples", [1, 4])
@pytest.mark.parametrize("cull", [False, True])
def test_compiled_setup_is_the_reference_bit_for_bit(samples: int, cull: bool) -> None:
    # A real scene (clipped by the near plane) and random clip coordinates, some with w <= 0.
    prepared = bp.prepare_scene(scene())
    rng = np.random.default_rng(3)
    clip = rng.normal(size=(200, 4))
    clip[:, 3] = rng.uniform(-0.5, 2.0, 200)
    cases = [(prepared.clip, prepared.triangles, 64, 48), (clip, rng.integers(0, 200, (300, 3)), 40, 30)]
    for positions, triangles, width, height in cases:
        ref = _setup_triangles(positions, triangles, width, height, samples, cull)
        fast = setup_triangles_compiled(positions, triangles, width, height, samples, cull)
        assert len(ref.selected) > 10
        for field in dataclasses.fields(ref):
            a, b = getattr(ref, field.name), getattr(fast, field.name)
            if isinstance(a, np.ndarray):
                assert a.dtype == b.dtype, field.name
                np.testing.assert_array_equal(b, a, err_msg=field.name)  # bitwise: see the docstring
            else:
                assert a == b, field.name


CASES = [
    {},
    {"local_viewer": False},
    {"specular": "phong"},
    {"gl_compat": True},
    {"gl_compat": True, "local_viewer": False},
    {"shadows": bp.ShadowOptions("shadow_map", resolution=128)},
    {"shadows": "ray_traced"},
    {"shadows": "shadow_volume"},
    {"shading": "flat"},
    {"shading": "flat", "shadows": "ray_traced"},
    {"shading": "gouraud"},
    {"shading": "gouraud", "local_viewer": False, "specular": "phong"},
    {"shading": "mixed"},
    {"transparency": "a_buffer"},
    {"transparency": "a_buffer", "shading": "mixed"},
    {"transparency": "a_buffer", "shadows": "ray_traced"},
    {"transparency": "depth_peeling", "peel_layers": 1},
    {"transparency": "depth_peeling", "peel_layers": 2, "shading": "flat"},
]


def _case_id(case: dict) -> str:
    return "-".join(f"{k}={v}" for k, v in case.items())[:40] or "plain"


def _record_fused(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The names of the fused kernels :func:`blinn_phong.frame.pipeline.render_frame` calls, in order."""
    from blinn_phong.frame import pipeline

    used: list[str] = []
    for name in ("shade_plain_winners_compiled", "shade_plain_fragments_compiled"):
        original = getattr(pipeline, name)
        monkeypatch.setattr(pipeline, name, lambda *a, f=original, n=name: used.append(n) or f(*a))
    return used


def _assert_same_frames(ref: bp.RenderResult, fast: bp.RenderResult) -> None:
    """Every buffer of the two renders float32, of one shape, within 1e-6 (see the tests' comments)."""
    assert set(fast.passes) == set(ref.passes)
    pairs = [("rgba", ref.rgba, fast.rgba), ("depth", ref.depth, fast.depth)]
    pairs.append(("normal", ref.normal, fast.normal))
    for name, a, b in pairs + [(n, ref.passes[n], fast.passes[n]) for n in ref.passes]:
        assert a.dtype == b.dtype == np.float32 and a.shape == b.shape, name
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-6, err_msg=name)


@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_fused_frame_equals_the_numpy_reference(case: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    # Same formulas in the same order in both engines; only libm (pow, sqrt) and float64 rounding
    # could differ, far below float32's step near 1 (6e-8): 1e-6 leaves room for that.
    case = dict(case)
    s = scene(case.pop("local_viewer", True), case.pop("specular", "blinn"))
    if case.get("shading") == "mixed":  # each mesh its own frequency (Mesh.shading wins)
        frequencies = ("flat", "gouraud", "phong", "gouraud")
        meshes = tuple(dataclasses.replace(m, shading=f) for m, f in zip(s.meshes, frequencies, strict=True))
        s = dataclasses.replace(s, meshes=meshes)
        case["shading"] = "phong"
    options = {"shadows": "none", "shading": "phong", "transparency": "zbuffer", **case}
    ref = bp.render(s, 64, 48, engine="numpy", **options)
    used = _record_fused(monkeypatch)
    fast = bp.render(s, 64, 48, engine="numba", **options)
    # opaque frames, shadowed or not: from the z-buffer; sorted transparency: from the kept fragments
    opaque = options["transparency"] == "zbuffer"
    assert used == ["shade_plain_winners_compiled" if opaque else "shade_plain_fragments_compiled"]
    assert 0.2 < (ref.rgba[..., 3] > 0).mean() < 1.0  # covered and empty pixels
    assert ref.stats.shaded == fast.stats.shaded
    _assert_same_frames(ref, fast)


FOGS = [
    bp.Fog("linear", (0.5, 0.6, 0.7), start=2.0, end=5.0, distance=distance)
    for distance in ("plane", "radial")
] + [
    bp.Fog(mode, (0.9, 0.3, 0.1), density=density, distance=distance)
    for mode, density in (("exp", 0.3), ("exp2", 0.25))
    for distance in ("plane", "radial")
]


FOG_EXTRAS = {
    "plain": {},
    "infinite_viewer-phong": {"local_viewer": False, "specular": "phong"},
    "shadows": {"shadows": "shadow_map"},
    "flat": {"shading": "flat"},
    "gouraud": {"shading": "gouraud"},
    "a_buffer": {"transparency": "a_buffer"},
}


@pytest.mark.parametrize("extra", list(FOG_EXTRAS.values()), ids=list(FOG_EXTRAS))
@pytest.mark.parametrize("fog", FOGS, ids=lambda f: f"{f.mode}-{f.distance}")
def test_fogged_frame_stays_fused_and_equals_the_numpy_reference(
    fog: bp.Fog, extra: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The numpy engine fogs by blinn_phong.model.fog's numpy formulas (fog_factor, apply_fog) on the
    # staged fragment colours; the fused pass by the compiled per-fragment fog. Same float64
    # operations in the same order, so 1e-6 as above (float32 step near 1: 6e-8).
    extra = dict(extra)
    s = scene(extra.pop("local_viewer", True), extra.pop("specular", "blinn"))
    options = {"shadows": "none", "shading": "phong", "transparency": "zbuffer", **extra}
    if options["shadows"] == "shadow_map":
        options["shadows"] = bp.ShadowOptions("shadow_map", resolution=128)
    ref = bp.render(s, 64, 48, engine="numpy", fog=fog, **options)
    used = _record_fused(monkeypatch)
    fast = bp.render(s, 64, 48, engine="numba", fog=fog, **options)
    opaque = options["transparency"] == "zbuffer"
    assert used == ["shade_plain_winners_compiled" if opaque else "shade_plain_fragments_compiled"]
    unfogged = bp.render(s, 64, 48, engine="numpy", **options)
    # The fog really acts, and only on the colour (the light passes and alpha are not fogged).
    assert np.abs(ref.rgba[..., :3] - unfogged.rgba[..., :3]).max() > 0.05
    np.testing.assert_array_equal(ref.rgba[..., 3], unfogged.rgba[..., 3])
    assert 0.2 < (ref.rgba[..., 3] > 0).mean() < 1.0  # covered and empty pixels
    if opaque:  # (the A-buffer composites the glass over the floor: α = 1 wherever it is seen)
        assert (ref.rgba[..., 3][ref.rgba[..., 3] > 0] < 1).any()  # premultiplied: α·C_f with α < 1
    _assert_same_frames(ref, fast)


def test_per_channel_visibility_weights_each_light_per_channel() -> None:
    # One covered pixel per fragment; the expected terms from the numpy engine's per-light terms.
    s = scene()
    prepared = bp.prepare_scene(s)
    from blinn_phong.frame.shading import plain_tables
    from blinn_phong.frame.visibility import frame_fragments

    visible = frame_fragments(prepared.clip, prepared.triangles, 32, 24, engine="numba")
    f = visible.fragments
    n, n_lights = len(f), len(prepared.lights)
    rng = np.random.default_rng(9)
    vis = rng.uniform(0, 1, (n, n_lights, 3))
    out = (
        np.empty((24, 32, 4), np.float32), *(np.empty((24, 32, 3), np.float32) for _ in range(4)),
        np.empty((24, 32), np.float32), np.empty((24, 32, 1), np.float32),
    )  # fmt: skip
    shade_plain_fragments_compiled(
        32, 24, visible.opaque_of, f.triangle, f.bary, f.depth, f.front_facing,
        plain_tables(prepared, False), vis, vis.mean(axis=(1, 2)), out,
    )  # fmt: skip
    from blinn_phong.frame.shading import surface_at_fragments

    back = ~f.front_facing
    points, normals, _ = surface_at_fragments(prepared, f, back)
    materials = [m for mesh in s.meshes for m in (mesh.material, mesh.back_material or mesh.material)]
    ids = 2 * prepared.triangle_mesh[f.triangle] + back
    diffuse = np.zeros((n, 3))
    specular = np.zeros((n, 3))
    alpha = np.zeros(n)
    for mid in np.unique(ids):
        sel = ids == mid
        terms = bp.shade(
            points[sel], normals[sel], materials[mid], prepared.lights, global_ambient=s.ambient,
            model=s.light_model, per_light=True,
        )  # fmt: skip
        diffuse[sel] = np.einsum("nlc,nlc->nc", terms.diffuse_per_light, vis[sel])
        specular[sel] = np.einsum("nlc,nlc->nc", terms.specular_per_light, vis[sel])
        alpha[sel] = materials[mid].opacity
    pixel = f.pixel
    rows, cols = pixel // 32, pixel % 32
    np.testing.assert_allclose(out[2][rows, cols], diffuse * alpha[:, None], rtol=0, atol=1e-6)
    np.testing.assert_allclose(out[3][rows, cols], specular * alpha[:, None], rtol=0, atol=1e-6)
    np.testing.assert_allclose(out[6][rows, cols, 0], vis.mean(axis=(1, 2)) * alpha, rtol=0, atol=1e-6)
    assert np.abs(diffuse[:, 0] - diffuse[:, 1]).max() > 1e-3  # the channels really differ
