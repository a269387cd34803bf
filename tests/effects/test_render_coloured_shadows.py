"""render(): transparent casters shadow through their transmittance where shadows are ray traced.

Closed forms: a floor lit by a directional light, a pane of opacity α (or two stacked panes)
above it, camera straight down (orthographic). The floor has no specular term, the light no
ambient term and the scene no global ambient, so a floor pixel's radiance is the light's
diffuse term times the light that reaches it: shadowed = unshadowed × T per channel, with
``T = 1 − α`` for the partial-occlusion and absorption models (docs/transparency_models.md:
the renderer's absorption is the grey filter ``1 − α``), 1 for emission (it hides nothing), 0
for an opaque pane, and the product of the transmittances under stacked panes.

The per-channel visibility that carries this into shading, (N, L, 3), is checked without Embree:
:func:`blinn_phong.frame.lighting.shade` with a coloured visibility equals the unshadowed terms times
it per channel, on the numpy and the compiled engine.
"""

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.frame.lighting import lights_in_eye_space, shade
from blinn_phong.model.primitives import grid_plane
from blinn_phong.shadows.transmittance import caster_transmittance, shadow_transmittance

SIZE = 64  # pixels; the view spans x, y ∈ [-2, 2], 1/16 unit per pixel


def _numba() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def _embree() -> bool:
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


needs_embree = pytest.mark.skipif(not _embree(), reason="ray-traced shadows need Embree (embreex)")


def _quad(x0: float, x1: float, y0: float, y1: float, z: float, material: bp.Material) -> bp.Mesh:
    pos, tris, normals = grid_plane(1, 1, (x1 - x0, y1 - y0))
    transform = np.eye(4)
    transform[:3, 3] = ((x0 + x1) / 2, (y0 + y1) / 2, z)
    return bp.Mesh(pos, tris, normals, transform=transform, material=material)


FLOOR = bp.Material(ambient=(0, 0, 0), diffuse=(0.8, 0.6, 0.4), specular=(0, 0, 0))
# light travelling +x and down at 45°: a pane at height h over x ∈ [a, b] shadows x ∈ [a + h, b + h]
SUN = bp.DirectionalLight((1.0, 0.0, -1.0), color=(1.0, 0.9, 0.7))
CAMERA = bp.Camera.orthographic(-2, 2, -2, 2, 0.1, 20, view=bp.look_at((0, 0, 10), (0, 0, 0), (0, 1, 0)))


def _pane(
    opacity: float, model: str = "partial_occlusion", z: float = 1.0, x: tuple = (-1.5, -0.5)
) -> bp.Mesh:
    """A 1×2 pane at height z over x ∈ [x0, x1]: its shadow falls on x ∈ [x0 + z, x1 + z]."""
    material = bp.Material(
        ambient=(0, 0, 0), diffuse=(0.2, 0.3, 0.9), opacity=opacity, transparency_model=model
    )
    return _quad(x[0], x[1], -1.0, 1.0, z, material)


def _pixel(x: float, y: float) -> tuple[int, int]:
    """(row, column) of the pixel whose centre is nearest to world (x, y) on the floor (row 0 at the top)."""
    col = int(np.floor((x + 2) / 4 * SIZE))
    row = int(np.floor((2 - y) / 4 * SIZE))
    return row, col


def _floor_ratio(meshes: list[bp.Mesh], engine: str = "auto") -> tuple[np.ndarray, bp.RenderResult]:
    """(3,) shadowed / lit floor radiance per channel: floor at (0, 0) (in the panes' shadows, x ∈
    [-0.5, 0.5], seen beside the panes) against (1.6, 0) (in the open), both far from every edge."""
    scene = bp.Scene([_quad(-2, 2, -2, 2, 0.0, FLOOR), *meshes], SUN, CAMERA, ambient=(0, 0, 0))
    result = bp.render(scene, SIZE, SIZE, shadows="ray_traced", transparency="a_buffer", engine=engine)
    shadowed = result.rgba[_pixel(0.0, 0.0)][:3].astype(np.float64)
    lit = result.rgba[_pixel(1.6, 0.0)][:3].astype(np.float64)
    return shadowed / lit, result


def test_material_transmittance_by_model():
    """The shadow transmittance of each transparency model (docs/transparency_models.md)."""
    for model in ("partial_occlusion", "absorption"):
        m = bp.Material(opacity=0.3, transparency_model=model)
        np.testing.assert_array_equal(shadow_transmittance(m), [0.7, 0.7, 0.7])
    np.testing.assert_array_equal(
        shadow_transmittance(bp.Material(opacity=0.3, transparency_model="emission")), [1, 1, 1]
    )
    np.testing.assert_array_equal(shadow_transmittance(bp.Material()), [0, 0, 0])  # opaque
    kay = bp.Material(kay_greenberg=(0.2, 0.8, 2.0))  # opacity varies over the surface: full shadow
    np.testing.assert_array_equal(shadow_transmittance(kay), [0, 0, 0])
    scene = bp.Scene([_quad(-2, 2, -2, 2, 0.0, FLOOR), _pane(0.25)], SUN, CAMERA)
    t = caster_transmittance(scene)
    assert t.shape == (4, 3)  # two triangles each, floor first
    np.testing.assert_array_equal(t, [[0, 0, 0]] * 2 + [[0.75, 0.75, 0.75]] * 2)
    assert caster_transmittance(bp.Scene([_quad(-2, 2, -2, 2, 0.0, FLOOR)], SUN, CAMERA)) is None


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_coloured_visibility_in_shading(engine):
    """(N, L, 3) visibility multiplies each light's diffuse and specular per channel (Embree-free)."""
    if engine == "numba" and not _numba():
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(3)
    n = 50
    points = rng.uniform(-1, 1, (n, 3)) + np.array([0.0, 0.0, -5.0])
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[:, 2] = np.abs(normals[:, 2])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    lights = lights_in_eye_space(
        [bp.DirectionalLight((0.2, -0.3, -1.0)), bp.PointLight((1.0, 2.0, 0.0), color=(0.9, 0.8, 1.0))],
        np.eye(4),
    )
    material = bp.Material(diffuse=(0.7, 0.5, 0.3), specular=(0.4, 0.6, 0.8), shininess=20.0)
    vis = rng.uniform(0, 1, (n, 2, 3))
    per = shade(points, normals, material, lights, per_light=True)  # numpy reference per-light terms
    got = shade(points, normals, material, lights, visibility=vis, engine=engine)
    expected_d = np.einsum("nlc,nlc->nc", per.diffuse_per_light, vis)
    expected_s = np.einsum("nlc,nlc->nc", per.specular_per_light, vis)
    np.testing.assert_allclose(got.diffuse, expected_d, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(got.specular, expected_s, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(got.ambient, per.ambient, rtol=1e-12, atol=1e-14)
    # grey (N, L, 3) is the same as (N, L)
    grey = shade(points, normals, material, lights, visibility=vis[:, :, 0], engine=engine)
    repeated = np.repeat(vis[:, :, :1], 3, axis=2)
    again = shade(points, normals, material, lights, visibility=repeated, engine=engine)
    np.testing.assert_allclose(again.diffuse, grey.diffuse, rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="visibility"):
        shade(points, normals, material, lights, visibility=np.ones((n, 2, 2)), engine=engine)


@needs_embree
@pytest.mark.parametrize("model", ["partial_occlusion", "absorption"])
def test_pane_shadow_is_unshadowed_times_transmittance(model):
    ratio, result = _floor_ratio([_pane(0.35, model)])
    # float32 image of float64 shading: a relative error of a few float32 ulps
    np.testing.assert_allclose(ratio, [0.65, 0.65, 0.65], rtol=1e-6)
    reason = result.plan.shadows[0].reason  # ray tracing set by the caller: the reason says coloured
    assert reason.endswith(
        "coloured shadows: light crossing transparent meshes 1 keeps their transmittance per RGB channel"
    )


@needs_embree
def test_stacked_panes_multiply_and_opaque_blocks():
    """Two panes (α = 0.3 at z = 1 and α = 0.6 at z = 0.5, the lower one shifted so that both shadows
    cover the sample point): (1 − 0.3)·(1 − 0.6); an emission pane hides nothing; an opaque one all."""
    lower = _pane(0.6, z=0.5, x=(-1.0, 0.0))
    ratio, _ = _floor_ratio([_pane(0.3), lower])
    np.testing.assert_allclose(ratio, [0.7 * 0.4] * 3, rtol=1e-6)
    ratio, _ = _floor_ratio([_pane(0.3, "emission")])
    np.testing.assert_allclose(ratio, [1.0] * 3, rtol=1e-6)
    ratio, result = _floor_ratio([_pane(1.0)])
    np.testing.assert_allclose(ratio, [0.0] * 3, atol=1e-7)
    assert "coloured" not in result.plan.shadows[0].reason  # nothing lets light through


@needs_embree
def test_engines_agree_with_coloured_shadows():
    panes = [_pane(0.35), _pane(0.5, z=0.5, x=(-1.0, 0.0))]
    _, ra = _floor_ratio(panes, engine="numpy")
    _, rb = _floor_ratio(panes, engine="numba" if _numba() else "numpy")
    np.testing.assert_allclose(ra.rgba, rb.rgba, atol=1e-6)
    np.testing.assert_allclose(ra.passes["shadow"], rb.passes["shadow"], atol=1e-6)
    # the shadow pass is the mean over lights and channels of the light that arrives
    np.testing.assert_allclose(ra.passes["shadow"][_pixel(0.0, 0.0)], [0.65 * 0.5], rtol=1e-6)


@needs_embree
def test_planner_traces_rays_through_see_through_casters():
    """At tolerance 0 the plan is exact: a transparent pane over a floor used to plan projected
    (planar) shadows — binary, so the floor under the pane went black; the plan now traces rays,
    and the default render gives the closed form unshadowed × (1 − α)."""
    scene = bp.Scene([_quad(-2, 2, -2, 2, 0.0, FLOOR), _pane(0.35)], SUN, CAMERA, ambient=(0, 0, 0))
    choice = bp.plan(scene).shadows[0]
    assert choice.method == "ray_traced"
    assert "meshes 1 cast shadows and let light through" in choice.reason
    result = bp.render(scene, SIZE, SIZE, transparency="a_buffer")
    shadowed = result.rgba[_pixel(0.0, 0.0)][:3].astype(np.float64)
    lit = result.rgba[_pixel(1.6, 0.0)][:3].astype(np.float64)
    np.testing.assert_allclose(shadowed / lit, [0.65] * 3, rtol=1e-6)
    # the same geometry with an opaque pane: the projected shadows stay exact and are kept
    opaque = bp.Scene([_quad(-2, 2, -2, 2, 0.0, FLOOR), _pane(1.0)], SUN, CAMERA, ambient=(0, 0, 0))
    assert bp.plan(opaque).shadows[0].method == "planar"
