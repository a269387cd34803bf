"""render() follows the planner: transparency, shadows and fog against closed forms.

Every expected value comes from outside the renderer: Porter & Duff's ``over`` of stacked
emissive quads (the straight colour of an emissive, unlit surface is its emission), the
shadow of a square from similar triangles, Lambert's cosine, Kay & Greenberg's formula,
OpenGL's fog equations (§3.10), or the pre-existing z-buffer stages (prepare → visible
fragments → shade → box filter) for the claim that nothing changes without effects.

Every test runs on both engines (the numpy reference stages and the compiled ones): the
autouse ``engine`` fixture gives ``bp.render`` calls without an explicit ``engine`` that engine.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.primitives import uv_sphere


@pytest.fixture(autouse=True, params=["numpy", "numba"])
def engine(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Run the test with ``bp.render(..., engine=<param>)`` unless the test names an engine."""
    if request.param == "numba":
        pytest.importorskip("numba")
    original = bp.render

    def render(*args: object, **kwargs: object) -> bp.RenderResult:
        kwargs.setdefault("engine", request.param)
        return original(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(bp, "render", render)
    return str(request.param)


SIZE = 40  # pixels across the 4 × 4 world-unit view: pixel (row, col) centre is at
# x = -2 + (col + 0.5)·0.1, y = 2 - (row + 0.5)·0.1
ROWS, COLS = np.indices((SIZE, SIZE))
X, Y = -2 + (COLS + 0.5) * 0.1, 2 - (ROWS + 0.5) * 0.1


def emissive(colour: tuple[float, float, float], opacity: float = 1.0, **fields: object) -> bp.Material:
    """Unlit material whose straight colour is exactly ``colour``."""
    return bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=colour, opacity=opacity, **fields)


def quad(z: float, half: float, material: bp.Material, centre: tuple[float, float] = (0.0, 0.0)) -> bp.Mesh:
    """A square facing +Z at height z, counter-clockwise seen from above."""
    cx, cy = centre
    corners = [(cx - half, cy - half), (cx + half, cy - half), (cx + half, cy + half), (cx - half, cy + half)]
    positions = np.array([(x, y, z) for x, y in corners], dtype=float)
    return bp.Mesh(
        positions, np.array([(0, 1, 2), (0, 2, 3)]), np.tile([0.0, 0.0, 1.0], (4, 1)), material=material
    )


def top_camera() -> bp.Camera:
    """Orthographic camera at z = 10 looking down -Z, 4 world units across."""
    return bp.Camera.orthographic(-2, 2, -2, 2, 1.0, 20.0, view=bp.look_at((0, 0, 10), (0, 0, 0)))


def unlit_scene(*meshes: bp.Mesh) -> bp.Scene:
    return bp.Scene(meshes, (), top_camera(), ambient=(0, 0, 0))


def zbuffer_stages(scene: bp.Scene, samples: int = 1, gl_compat: bool = False) -> np.ndarray:
    """The z-buffer render as its public stages compose it: nearest fragment, alpha = opacity."""
    prepared = bp.prepare_scene(scene)
    visible = bp.visible_fragments(prepared.clip, prepared.triangles, SIZE, SIZE, samples=samples)
    shaded = bp.shade_fragments(prepared, visible, gl_compat=gl_compat)
    buffer = np.zeros((SIZE * SIZE * samples, 4), np.float32)
    buffer[visible.sample_key] = np.c_[shaded.rgb * shaded.alpha[:, None], shaded.alpha]
    return bp.resolve_samples(buffer, SIZE, SIZE, samples)


def over(front: np.ndarray, front_alpha: float, behind: np.ndarray) -> np.ndarray:
    """Straight colour ``front`` of opacity α over an opaque ``behind``: α·front + (1 − α)·behind."""
    return front_alpha * np.asarray(front) + (1 - front_alpha) * np.asarray(behind)


FLOOR = np.array([1.0, 0.5, 0.0])
RED, BLUE, GREEN = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])


# --------------------------------------------------------------------------- nothing changes without effects


def test_opaque_convex_scene_is_bit_identical_to_the_z_buffer_stages() -> None:
    # One convex mesh under two lights: the planner finds no occluder, so no shadow work.
    pos, tris, normals = uv_sphere(24, 12)
    material = bp.Material(diffuse=(0.7, 0.4, 0.3), specular=(0.5, 0.5, 0.5), shininess=30.0)
    camera = bp.Camera.perspective(40, 1, 1, 10, view=bp.look_at((0, 0, 4), (0, 0, 0)))
    lights = (bp.DirectionalLight((-1, -1, -1)), bp.PointLight((2, 1, 2)))
    scene = bp.Scene((bp.Mesh(pos, tris, normals, material=material),), lights, camera)
    result = bp.render(scene, SIZE, SIZE, samples=4, engine="numpy")
    assert [c.method for c in result.plan.shadows] == ["none", "none"]
    assert result.plan.transparency.method == "zbuffer"
    # bitwise: render() and the hand-composed stages run the same numpy stages in the same
    # order (element-wise, no threads, no BLAS-sized products): deterministic by construction
    np.testing.assert_array_equal(result.rgba, zbuffer_stages(scene, samples=4))
    assert "shadow" not in result.passes


def test_shadows_switched_off_give_the_z_buffer_image_bit_for_bit() -> None:
    floor = quad(0.0, 2.0, bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1)))
    occluder = quad(1.0, 0.3, bp.Material(), centre=(-1.0, 0.0))
    scene = bp.Scene((floor, occluder), (bp.DirectionalLight((1, 0, -1)),), top_camera(), ambient=(0, 0, 0))
    assert bp.plan(scene).shadows[0].method != "none"  # the planner does see the occluder
    result = bp.render(scene, SIZE, SIZE, shadows="none", engine="numpy")
    # bitwise: render() and the hand-composed stages run the same numpy stages in the same
    # order (element-wise, no threads, no BLAS-sized products): deterministic by construction
    np.testing.assert_array_equal(result.rgba, zbuffer_stages(scene))
    assert "set by the caller" in result.plan.shadows[0].reason


def test_gl_compat_ignores_the_plan_and_keeps_the_fixed_function_image() -> None:
    glass = quad(1.0, 1.0, emissive(tuple(BLUE), 0.4))
    scene = bp.Scene(
        (quad(0.0, 2.0, bp.Material()), glass, quad(2.0, 0.3, bp.Material(), centre=(1.0, 1.0))),
        (bp.DirectionalLight((1, 0, -1)),),
        top_camera(),
    )
    result = bp.render(scene, SIZE, SIZE, gl_compat=True, engine="numpy")
    # bitwise: render() and the hand-composed stages run the same numpy stages in the same
    # order (element-wise, no threads, no BLAS-sized products): deterministic by construction
    np.testing.assert_array_equal(result.rgba, zbuffer_stages(scene, gl_compat=True))
    assert result.plan.transparency.method == "zbuffer" and "gl_compat" in result.plan.transparency.reason
    assert result.plan.shadows[0].method == "none" and "gl_compat" in result.plan.shadows[0].reason
    with pytest.raises(ValueError, match="shadows"):
        bp.render(scene, 8, 8, gl_compat=True, shadows="ray_traced")
    with pytest.raises(ValueError, match="transparency"):
        bp.render(scene, 8, 8, gl_compat=True, transparency="a_buffer")


# --------------------------------------------------------------------------- transparency


def test_one_transparent_quad_is_drawn_last_and_equals_the_a_buffer() -> None:
    scene = unlit_scene(quad(0.0, 5.0, emissive(tuple(FLOOR))), quad(1.0, 5.0, emissive(tuple(BLUE), 0.4)))
    planned = bp.render(scene, SIZE, SIZE, samples=4)
    assert planned.plan.transparency.method == "draw_last"
    expected = np.r_[over(BLUE, 0.4, FLOOR), 1.0]
    np.testing.assert_allclose(planned.rgba, np.broadcast_to(expected, (SIZE, SIZE, 4)), atol=1e-6)
    exact = bp.render(scene, SIZE, SIZE, samples=4, transparency="a_buffer")
    np.testing.assert_allclose(planned.rgba, exact.rgba, atol=1e-6)
    # Depth and normal describe the nearest surface: the glass at z = 1 (window depth (9 - 1)/19).
    np.testing.assert_allclose(planned.depth, 8 / 19, atol=1e-6)


@pytest.mark.parametrize("order", [(0, 1, 2), (2, 1, 0), (1, 2, 0)])
def test_stacked_quads_are_sorted_in_any_scene_order(order: tuple[int, int, int]) -> None:
    # Floor, red glass (α 0.5) at z = 1, green glass (α 0.25) at z = 2: seen from above,
    # green over red over floor whatever order the meshes come in.
    meshes = [quad(0.0, 5.0, emissive(tuple(FLOOR))), quad(1.0, 1.0, emissive(tuple(RED), 0.5))]
    meshes.append(quad(2.0, 1.0, emissive(tuple(GREEN), 0.25), centre=(0.5, 0.0)))
    scene = unlit_scene(*[meshes[i] for i in order])
    result = bp.render(scene, SIZE, SIZE)
    assert result.plan.transparency.method == "sort_objects"
    red_only = (np.abs(X + 0.75) < 0.2) & (np.abs(Y) < 0.9)
    both = (np.abs(X - 0.5) < 0.4) & (np.abs(Y) < 0.9)
    np.testing.assert_allclose(
        result.rgba[red_only][:, :3], np.broadcast_to(over(RED, 0.5, FLOOR), (red_only.sum(), 3)), atol=1e-6
    )
    expected = over(GREEN, 0.25, over(RED, 0.5, FLOOR))
    np.testing.assert_allclose(
        result.rgba[both][:, :3], np.broadcast_to(expected, (both.sum(), 3)), atol=1e-6
    )
    exact = bp.render(scene, SIZE, SIZE, transparency="a_buffer")
    np.testing.assert_allclose(result.rgba, exact.rgba, atol=1e-6)


def crossing_quads(opacity: float) -> bp.Scene:
    """Red glass z = 0.5·x and blue glass z = -0.5·x crossing along x = 0, over an opaque floor at z = -2."""
    xs, ys = np.array([-2.0, 2.0, 2.0, -2.0]), np.array([-2.0, -2.0, 2.0, 2.0])
    normal_red = np.tile(np.array([-0.5, 0.0, 1.0]) / math.hypot(0.5, 1.0), (4, 1))
    normal_blue = np.tile(np.array([0.5, 0.0, 1.0]) / math.hypot(0.5, 1.0), (4, 1))
    tris = np.array([(0, 1, 2), (0, 2, 3)])
    red = bp.Mesh(np.c_[xs, ys, 0.5 * xs], tris, normal_red, material=emissive(tuple(RED), opacity))
    blue = bp.Mesh(np.c_[xs, ys, -0.5 * xs], tris, normal_blue, material=emissive(tuple(BLUE), opacity))
    return unlit_scene(quad(-2.0, 5.0, emissive(tuple(FLOOR))), red, blue)


def crossing_closed_form(opacity: float) -> np.ndarray:
    """Where x > 0 red (z = x/2) is nearer the camera above, elsewhere blue."""
    front = np.where((X > 0)[..., None], RED, BLUE)
    back = np.where((X > 0)[..., None], BLUE, RED)
    return over(front, opacity, over(back, opacity, FLOOR))


def test_interpenetrating_quads_plan_the_a_buffer_and_match_the_closed_form() -> None:
    scene = crossing_quads(0.5)
    result = bp.render(scene, SIZE, SIZE)
    assert result.plan.transparency.method == "a_buffer"
    assert "interpenetrate" in result.plan.transparency.reason
    np.testing.assert_allclose(result.rgba[..., :3], crossing_closed_form(0.5), atol=1e-6)
    # Overriding with object sorting is wrong by a² = 0.25 on one half of the image
    sorted_objects = bp.render(scene, SIZE, SIZE, transparency="sort_objects")
    # (A + (1 − a)·B against B + (1 − a)·A: a²·(R − B)), exact on the other.
    error = np.abs(sorted_objects.rgba[..., :3] - crossing_closed_form(0.5)).max(axis=-1)
    halves = sorted([error[X > 0.1], error[X < -0.1]], key=lambda half: half.max())
    assert halves[0].max() < 1e-6
    np.testing.assert_allclose(halves[1], 0.25, atol=1e-6)


def test_depth_peeling_keeps_the_nearest_layers_only() -> None:
    # One layer: the nearest glass over the floor, the one behind it lost.
    scene = crossing_quads(0.5)
    result = bp.render(scene, SIZE, SIZE, transparency="depth_peeling", peel_layers=1)
    assert result.plan.transparency.params == {"layers": 1}
    front = np.where((X > 0)[..., None], RED, BLUE)
    np.testing.assert_allclose(result.rgba[..., :3], over(front, 0.5, FLOOR), atol=1e-6)
    two = bp.render(scene, SIZE, SIZE, transparency="depth_peeling", peel_layers=2)
    np.testing.assert_allclose(two.rgba[..., :3], crossing_closed_form(0.5), atol=1e-6)


def test_weighted_blended_oit_is_exact_for_a_single_layer() -> None:
    scene = unlit_scene(quad(0.0, 5.0, emissive(tuple(FLOOR))), quad(1.0, 5.0, emissive(tuple(BLUE), 0.4)))
    for weight in ("eq10", "constant"):
        result = bp.render(scene, 8, 8, transparency="weighted_blended", wboit_weight=weight)
        assert result.plan.transparency.params == {"wboit_equation": weight}
        np.testing.assert_allclose(
            result.rgba[..., :3], np.broadcast_to(over(BLUE, 0.4, FLOOR), (8, 8, 3)), atol=1e-6
        )


@pytest.mark.parametrize(
    ("model", "expected_rgb", "expected_alpha"),
    [
        ("partial_occlusion", 0.3 * BLUE + 0.7 * FLOOR, 1.0),  # α·c + (1 − α)·behind
        ("emission", 0.3 * BLUE + FLOOR, 1.0),  # α·c + behind, nothing hidden
        ("absorption", BLUE + 0.7 * FLOOR, 1.0),  # c + T·behind, T = 1 − α
    ],
)
def test_transparency_models_over_an_opaque_floor(
    model: str, expected_rgb: np.ndarray, expected_alpha: float
) -> None:
    glass = quad(1.0, 5.0, emissive(tuple(BLUE), 0.3, transparency_model=model))
    result = bp.render(unlit_scene(quad(0.0, 5.0, emissive(tuple(FLOOR))), glass), 8, 8)
    np.testing.assert_allclose(result.rgba[..., :3], np.broadcast_to(expected_rgb, (8, 8, 3)), atol=1e-6)
    np.testing.assert_allclose(result.rgba[..., 3], expected_alpha, atol=1e-7)


def test_emission_model_adds_light_without_covering_the_background() -> None:
    glass = quad(1.0, 5.0, emissive(tuple(BLUE), 0.3, transparency_model="emission"))
    result = bp.render(unlit_scene(glass), 8, 8)
    np.testing.assert_allclose(result.rgba, np.broadcast_to(np.r_[0.3 * BLUE, 0.0], (8, 8, 4)), atol=1e-7)


def test_transparent_back_material_under_two_sided_lighting() -> None:
    # A quad facing down (clockwise seen from above): the camera sees its back face, whose
    # material is red glass (α 0.5) while the front is opaque; two-sided lighting picks the back.
    facing_down = quad(1.0, 5.0, emissive(tuple(GREEN)))
    glass_back = bp.Mesh(
        facing_down.positions,
        facing_down.triangles[:, ::-1],
        -facing_down.normals,
        material=emissive(tuple(GREEN)),
        back_material=emissive(tuple(RED), 0.5),
    )
    scene = bp.Scene(
        (quad(0.0, 5.0, emissive(tuple(FLOOR))), glass_back),
        (),
        top_camera(),
        ambient=(0, 0, 0),
        light_model=bp.LightModel(two_sided=True),
    )
    result = bp.render(scene, 8, 8)
    assert result.plan.transparency.method == "draw_last"
    np.testing.assert_allclose(
        result.rgba[..., :3], np.broadcast_to(over(RED, 0.5, FLOOR), (8, 8, 3)), atol=1e-6
    )


@pytest.mark.parametrize("tilt_degrees", [0.0, 60.0])
def test_kay_greenberg_opacity_follows_the_eye_space_normal(tilt_degrees: float) -> None:
    # t = t_min + (t_max − t_min)·[1 − (1 − |N_z|)^p], N_z = cos(tilt) under an orthographic view.
    c, s = math.cos(math.radians(tilt_degrees)), math.sin(math.radians(tilt_degrees))
    rotate = np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 1.0], [0, 0, 0, 1]])  # about x, lifted to z = 1
    glass = emissive(tuple(BLUE), kay_greenberg=(0.1, 0.8, 2.0))
    tilted = bp.Mesh(
        quad(0.0, 1.0, glass).positions, np.array([(0, 1, 2), (0, 2, 3)]), transform=rotate, material=glass
    )
    result = bp.render(unlit_scene(quad(0.0, 5.0, emissive(tuple(RED))), tilted), SIZE, SIZE)
    t = 0.1 + 0.7 * (1 - (1 - c) ** 2)
    centre = result.rgba[18:22, 18:22]
    np.testing.assert_allclose(centre[..., :3], np.broadcast_to(over(BLUE, 1 - t, RED), (4, 4, 3)), atol=1e-6)
    assert result.plan.transparency.method == "draw_last"


def test_specular_highlight_washes_out_transparency() -> None:
    # Overhead sun, shininess 0: the specular term is s_cm·s_cl = 0.2 on the glass (n·l = 1 > 0),
    # its luminance 0.2; opacity α' = min(1, 0.3 + 0.2) = 0.5 over the floor.
    glass = bp.Material(
        ambient=(0, 0, 0),
        diffuse=(0, 0, 0),
        specular=(0.2, 0.2, 0.2),
        emission=tuple(BLUE),
        opacity=0.3,
        specular_washout=True,
    )
    scene = bp.Scene(
        (quad(0.0, 5.0, emissive(tuple(FLOOR))), quad(1.0, 5.0, glass)),
        (bp.DirectionalLight((0, 0, -1)),),
        top_camera(),
        ambient=(0, 0, 0),
    )
    result = bp.render(scene, 8, 8)
    expected = over(BLUE + 0.2, 0.5, FLOOR)
    np.testing.assert_allclose(result.rgba[..., :3], np.broadcast_to(expected, (8, 8, 3)), atol=1e-6)


# --------------------------------------------------------------------------- shadows


def sun_scene() -> bp.Scene:
    """White floor, a 0.6-wide square at height 1 centred on x = -1, sun along (1, 0, -1)/√2."""
    floor = quad(0.0, 2.0, bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1)))
    occluder = quad(1.0, 0.3, bp.Material(ambient=(0, 0, 0), diffuse=(0.5, 0.5, 0.5)), centre=(-1.0, 0.0))
    return bp.Scene((floor, occluder), (bp.DirectionalLight((1, 0, -1)),), top_camera(), ambient=(0, 0, 0))


def test_planar_shadow_of_a_square_under_a_slanted_sun() -> None:
    # The shadow is the square shifted by height·tan 45° = 1 in x; lit floor: kd·(n·l) = 1/√2.
    result = bp.render(sun_scene(), SIZE, SIZE)
    assert result.plan.shadows[0].method == "planar"
    shadow = (np.abs(X) < 0.25) & (np.abs(Y) < 0.25)
    lit = ((np.abs(X) > 0.35) | (np.abs(Y) > 0.35)) & ((np.abs(X + 1) > 0.35) | (np.abs(Y) > 0.35))
    np.testing.assert_array_equal(result.rgba[..., 0][shadow], 0.0)
    np.testing.assert_allclose(result.rgba[..., 0][lit], 1 / math.sqrt(2), atol=1e-6)
    np.testing.assert_array_equal(result.passes["shadow"][..., 0][shadow], 0.0)
    np.testing.assert_allclose(result.passes["shadow"][..., 0][lit], 1.0, atol=1e-6)
    calls: list[tuple[str, float]] = []
    ray_traced = bp.render(sun_scene(), SIZE, SIZE, shadows="ray_traced", progress=lambda *c: calls.append(c))
    # bitwise: both methods give visibilities of exactly 0 or 1 here, then the same shading arithmetic
    np.testing.assert_array_equal(result.rgba, ray_traced.rgba)
    fractions = [fraction for _, fraction in calls]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0 and "shadows" in {s for s, _ in calls}


def point_light_scene() -> bp.Scene:
    """Point light at (0, 0, 4); a square of half-side 0.25 at height 2 over a white floor."""
    floor = quad(0.0, 2.0, bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1)))
    occluder = quad(2.0, 0.25, bp.Material(ambient=(0, 0, 0), diffuse=(0.5, 0.5, 0.5)))
    return bp.Scene((floor, occluder), (bp.PointLight((0, 0, 4)),), top_camera(), ambient=(0, 0, 0))


@pytest.mark.parametrize("shadows", [None, "ray_traced", bp.ShadowOptions("shadow_map", resolution=2048)])
def test_point_light_shadow_is_the_occluder_scaled_by_similar_triangles(shadows: object) -> None:
    # Light 4 above the floor, occluder 2 above: its shadow is the square scaled by 4 / (4 − 2) = 2.
    result = bp.render(point_light_scene(), SIZE, SIZE, shadows=shadows)
    r = np.maximum(np.abs(X), np.abs(Y))
    ring = (r > 0.3) & (r < 0.45)  # floor seen beside the occluder, inside its shadow
    outside = r > 0.55
    np.testing.assert_array_equal(result.rgba[..., 0][ring], 0.0)
    distance = np.sqrt(X**2 + Y**2 + 16.0)
    lambert = 4.0 / distance  # kd·I·(n·l), attenuation 1
    np.testing.assert_allclose(result.rgba[..., 0][outside], lambert[outside], rtol=1e-5)
    if shadows is None:
        assert result.plan.shadows[0].method == "planar"


def test_soft_shadow_penumbra_is_linear_across_the_edge() -> None:
    # Square light of half-side r = 0.2 at height 4, occluder edge at |x| = 0.25, height 2: a floor
    # point (x, y≈0) sees the light sample x_L when |x + x_L| ≥ 0.5, so its visibility is
    # clip((|x| + r − 0.5)/(2r), 0, 1); m×m stratified samples are within 1/m of it.
    shadows = bp.ShadowOptions("soft", samples=16, radius=0.2)
    result = bp.render(point_light_scene(), SIZE, SIZE, shadows=shadows)
    assert result.plan.shadows[0].params["samples_per_axis"] == 4
    row = 19  # y = 0.05
    x = X[row]
    floor = np.abs(x) > 0.3
    exact = np.clip((np.abs(x) + 0.2 - 0.5) / 0.4, 0.0, 1.0)
    got = result.passes["shadow"][row, :, 0]
    assert np.abs(got[floor] - exact[floor]).max() <= 0.25 + 1e-9
    assert ((got[floor] > 0) & (got[floor] < 1)).any()  # a penumbra, not a hard edge


def test_an_override_replaces_only_its_own_concern() -> None:
    glass = quad(1.5, 0.5, emissive(tuple(BLUE), 0.5), centre=(1.0, 1.0))
    scene = bp.Scene((*sun_scene().meshes, glass), sun_scene().lights, top_camera(), ambient=(0, 0, 0))
    planned = bp.plan(scene)
    forced_transparency = bp.render(scene, 16, 16, transparency="a_buffer").plan
    assert forced_transparency.shadows == planned.shadows
    assert forced_transparency.transparency.method == "a_buffer"
    assert planned.transparency.method in forced_transparency.transparency.reason
    # the glass lets light through, so the plan traces rays (coloured shadows); force another method
    other = "shadow_map" if planned.shadows[0].method == "ray_traced" else "ray_traced"
    forced_shadows = bp.render(scene, 16, 16, shadows=[other]).plan
    assert forced_shadows.transparency == planned.transparency
    assert forced_shadows.shadows[0].method == other
    assert "set by the caller" in forced_shadows.shadows[0].reason
    lines = forced_shadows.reasons()
    assert len(lines) == 1 + len(scene.lights) + len(scene.meshes)


def test_planner_choices_render_like_the_exact_methods() -> None:
    # For each planner case, its choice against the A-buffer with ray-traced shadows.
    cases = [sun_scene(), point_light_scene(), crossing_quads(0.5)]
    stacked = unlit_scene(quad(0.0, 5.0, emissive(tuple(FLOOR))), quad(1.0, 1.0, emissive(tuple(RED), 0.5)))
    cases.append(stacked)
    for scene in cases:
        planned = bp.render(scene, SIZE, SIZE, samples=4)
        exact = bp.render(scene, SIZE, SIZE, samples=4, transparency="a_buffer", shadows="ray_traced")
        np.testing.assert_allclose(planned.rgba, exact.rgba, atol=1e-6)


# --------------------------------------------------------------------------- fog


@pytest.mark.parametrize(
    ("mode", "factor"),
    [
        ("exp", math.exp(-0.15 * 10)),
        ("exp2", math.exp(-((0.15 * 10) ** 2))),
        ("linear", (12.0 - 10.0) / (12.0 - 2.0)),
    ],
)
def test_fog_at_a_known_eye_distance(mode: str, factor: float) -> None:
    # Floor at eye distance 10, glass (α 0.4) at 9: each fragment fogged, then blended.
    fog = bp.Fog(mode, (0.3, 0.5, 0.7), density=0.15, start=2.0, end=12.0)
    colour = np.array(fog.color)
    floor_only = bp.render(unlit_scene(quad(0.0, 5.0, emissive(tuple(FLOOR)))), 8, 8, fog=fog)
    fogged_floor = factor * FLOOR + (1 - factor) * colour
    np.testing.assert_allclose(floor_only.rgba[..., :3], np.broadcast_to(fogged_floor, (8, 8, 3)), atol=1e-6)
    f9 = {"exp": math.exp(-0.15 * 9), "exp2": math.exp(-((0.15 * 9) ** 2)), "linear": (12.0 - 9.0) / 10.0}[
        mode
    ]
    scene = unlit_scene(quad(0.0, 5.0, emissive(tuple(FLOOR))), quad(1.0, 5.0, emissive(tuple(BLUE), 0.4)))
    result = bp.render(scene, 8, 8, fog=fog)
    expected = over(f9 * BLUE + (1 - f9) * colour, 0.4, fogged_floor)
    np.testing.assert_allclose(result.rgba[..., :3], np.broadcast_to(expected, (8, 8, 3)), atol=1e-6)


# --------------------------------------------------------------------------- robustness


def test_no_nan_or_inf_under_any_combination() -> None:
    pos, tris, normals = uv_sphere(12, 6)
    glassy = bp.Material(specular=(1, 1, 1), shininess=200.0, opacity=0.3, specular_washout=True)
    sphere = bp.Mesh(pos * 0.6 + [0, 0, 1], tris, normals, material=glassy)
    degenerate = bp.Mesh(
        np.array([[0, 0, 0.5], [1, 1, 0.5], [2, 2, 0.5]]), np.array([[0, 1, 2]]), np.zeros((3, 3))
    )
    scene = bp.Scene(
        (quad(0.0, 2.0, bp.Material()), sphere, degenerate, crossing_quads(0.0).meshes[1]),
        (
            bp.PointLight((0.5, 0.5, 3)),
            bp.SpotLight((0, 0, 4), (0, 0, -1), 30.0),
            bp.DirectionalLight((1, 1, -1)),
        ),
        top_camera(),
    )
    configurations = [
        {"transparency": method, "shadows": shadow}
        for method in bp.planning.frame_plan.TRANSPARENCY_CHOICES
        for shadow in ("none", bp.ShadowOptions("shadow_map", resolution=128), "ray_traced")
    ]
    configurations += [
        {"shadows": bp.ShadowOptions("soft", radius=0.3, samples=4), "fog": bp.Fog("exp2", density=0.3)},
        {"shadows": bp.ShadowOptions("shadow_map", resolution=64, kernel="box3", slope_bias=0.0)},
        {"shading": "gouraud", "shadows": "ray_traced", "transparency": "a_buffer"},
        {"shading": "flat", "shadows": "ray_traced", "fog": bp.Fog("linear", start=5.0, end=15.0)},
        {"shading": "auto", "tolerance": 16.0},
    ]
    for options in configurations:
        result = bp.render(scene, 16, 16, samples=4, **options)
        for image in (result.rgba, result.depth, result.normal, *result.passes.values()):
            assert np.isfinite(image).all(), options


def test_bad_options_name_the_argument() -> None:
    scene = sun_scene()
    with pytest.raises(ValueError, match="transparency"):
        bp.render(scene, 8, 8, transparency="magic")
    with pytest.raises(ValueError, match="shadows"):
        bp.render(scene, 8, 8, shadows=["ray_traced", "none"])
    with pytest.raises(ValueError, match="peel_layers"):
        bp.render(scene, 8, 8, peel_layers=0)
    with pytest.raises(ValueError, match="wboit_weight"):
        bp.render(scene, 8, 8, wboit_weight="eq7")
    with pytest.raises(TypeError, match="fog"):
        bp.render(scene, 8, 8, fog="exp")
    with pytest.raises(ValueError, match=r"Fog\.mode"):
        bp.Fog("smoke")
    with pytest.raises(ValueError, match=r"ShadowOptions\.kernel"):
        bp.ShadowOptions(kernel="box4")
    pos, tris, normals = uv_sphere(12, 6)
    lone_sphere = bp.Scene((bp.Mesh(pos, tris, normals),), (bp.DirectionalLight((0, 0, -1)),), top_camera())
    assert bp.plan(lone_sphere).shadows[0].method == "none"  # so the planner offers no plane
    with pytest.raises(ValueError, match="planar"):
        bp.render(lone_sphere, 8, 8, shadows=[bp.ShadowOptions("planar")])
    with pytest.raises(ValueError, match=r"Material\.transparency_model"):
        bp.Material(transparency_model="glass")


# --------------------------------------------------------------------------- shading frequency


def test_shading_auto_takes_flat_where_the_planner_proves_it_exact() -> None:
    # A flat quad, a sun along (-1, 0, -1)/√2, viewer at infinity: l = (1, 0, 1)/√2, v = (0, 0, 1),
    # so n·l = 1/√2 and n·h = (1 + 1/√2)/|l + v| everywhere: kd·n·l + ks·(n·h)^s.
    material = bp.Material(
        ambient=(0, 0, 0), diffuse=(0.5, 0.5, 0.5), specular=(0.4, 0.4, 0.4), shininess=10.0
    )
    scene = bp.Scene(
        (quad(0.0, 5.0, material),),
        (bp.DirectionalLight((-1, 0, -1)),),
        top_camera(),
        ambient=(0, 0, 0),
        light_model=bp.LightModel(local_viewer=False),
    )
    auto = bp.render(scene, 8, 8, shading="auto")
    assert auto.plan.shading[0].method == "flat"
    half = np.array([1 / math.sqrt(2), 0.0, 1 + 1 / math.sqrt(2)])
    expected = 0.5 / math.sqrt(2) + 0.4 * (half[2] / np.linalg.norm(half)) ** 10
    np.testing.assert_allclose(auto.rgba[..., :3], expected, atol=1e-6)
    assert bp.render(scene, 8, 8).plan.shading[0].method == "flat"  # the default follows the plan
    phong = bp.render(scene, 8, 8, shading="phong")
    assert phong.plan.shading[0].method == "phong" and "planner: flat" in phong.plan.shading[0].reason
    np.testing.assert_allclose(phong.rgba, auto.rgba, atol=1e-6)


def test_engines_agree_on_the_effects_path() -> None:
    scene = bp.Scene(
        (*point_light_scene().meshes, quad(1.0, 0.8, emissive(tuple(BLUE), 0.5))),
        point_light_scene().lights,
        top_camera(),
    )
    numpy_image = bp.render(scene, SIZE, SIZE, engine="numpy", samples=4).rgba
    numba_image = bp.render(scene, SIZE, SIZE, engine="numba", samples=4).rgba
    np.testing.assert_allclose(numba_image, numpy_image, atol=1e-6)


def test_without_embree_shadows_fall_back_to_shadow_volumes() -> None:
    # Blender's own Python has no embreex: blinn_phong imports, and the exact shadow methods that cast
    # rays (ray_traced, planar's point test) become shadow volumes, exact too, with the reason given.
    import subprocess
    import sys
    from pathlib import Path

    code = """
import sys
sys.modules["embreex"] = None
import numpy as np
import blinn_phong as bp
square = np.array([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], float)
white = bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1))
floor = bp.Mesh(2 * square, np.array([(0, 1, 2), (0, 2, 3)]), material=white)
block = bp.Mesh(0.25 * square + [0, 0, 2], np.array([(0, 1, 2), (0, 2, 3)]))
camera = bp.Camera.orthographic(-2, 2, -2, 2, 1, 20, view=bp.look_at((0, 0, 10), (0, 0, 0)))
scene = bp.Scene((floor, block), (bp.PointLight((0, 0, 4)),), camera, ambient=(0, 0, 0))
for shadows in (None, "ray_traced", bp.ShadowOptions("shadow_map", resolution=1024)):
    result = bp.render(scene, 40, 40, shadows=shadows)
    print(result.rgba[20, 16, 0], result.rgba[20, 2, 0], result.plan.shadows[0].method)
print("blinn_phong.shadows.raytrace" in sys.modules, bp.plan(scene).shadows[0].method,
      result.plan.shadows[0].reason)
"""
    root = Path(__file__).resolve().parents[2]
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=120)
    assert run.returncode == 0, run.stderr
    # Pixel (20, 16): floor point (-0.35, -0.05) in the shadow ring (|x| < 0.5); (20, 2): (-1.75, -0.05) lit,
    # kd·(n·l) = 4 / √(1.75² + 0.05² + 16).
    lit = 4 / math.sqrt(1.75**2 + 0.05**2 + 16)
    lines = run.stdout.split("\n")
    for line, expected in zip(lines[:3], ("shadow_volume", "shadow_volume", "shadow_map"), strict=True):
        shadowed, lit_value, method = line.split()
        assert float(shadowed) == 0.0 and abs(float(lit_value) - lit) < 1e-5 and method == expected
    assert lines[3].startswith("False shadow_volume")  # Embree never imported; the plan itself says volumes
    planned = bp.render(point_light_scene(), 8, 8).plan.shadows[0]
    assert planned.method == "planar"  # with Embree the planner's choice stands
