"""The planner picks the cheap method where it is exact, and that choice renders like the exact method."""

import numpy as np
import pytest

from blinn_phong.frame.render import render
from blinn_phong.model.lights import AmbientLight, DirectionalLight, PointLight
from blinn_phong.model.scene import LightModel, Material, Mesh
from blinn_phong.planning.calibration import shipped_models
from blinn_phong.planning.frame_plan import Fog, ShadowOptions
from blinn_phong.planning.planner import plan
from blinn_phong.shadows.methods import light_visibility
from tests.effects.scenes import (
    flat_cube,
    horizontal_quad,
    perspective_camera,
    quad,
    render_transparency,
    scene_of,
    sphere,
    visible_surface_points,
    world_triangles,
)

LIGHT = DirectionalLight((0.3, 0.2, -1.0))
FLOOR = horizontal_quad(-1.0, half=3.0, colour=(0.2, 0.3, 0.4))
#: The exact hard-shadow methods: the planner picks the one predicted cheaper for the frame.
EXACT_SHADOWS = ("ray_traced", "shadow_volume")


# --------------------------------------------------------------------------- transparency


def test_no_transparent_objects_means_a_plain_z_buffer():
    p = plan(scene_of([FLOOR, horizontal_quad(0.0)], [LIGHT]))
    assert p.transparency.method == "zbuffer"
    assert "no transparent" in p.transparency.reason


def test_one_planar_transparent_object_is_drawn_last_and_matches_the_a_buffer():
    scene = scene_of([FLOOR, horizontal_quad(0.0, colour=(1, 0, 0), opacity=0.4)], [LIGHT])
    choice = plan(scene).transparency
    assert choice.method == "draw_last"
    np.testing.assert_allclose(
        render_transparency(scene, "draw_last"), render_transparency(scene, "a_buffer"), atol=1e-12
    )


@pytest.mark.parametrize("shape", ["sphere", "slab"])
def test_one_convex_transparent_object_is_drawn_last_back_faces_first(shape):
    if shape == "sphere":
        mesh = sphere((0, 0, 0), 1.0, (0, 1, 0), opacity=0.5)
    else:  # a long thin box: triangles of its top and bottom overlap across their diagonals
        stretch = np.diag([3.0, 0.6, 0.2, 1.0])
        stretch[:3, 3] = (0.0, 0.0, 0.3)
        mesh = flat_cube((0, 0, 0), 1.0, colour=(0.0, 1.0, 0.0), transform=stretch)
        mesh = Mesh(
            mesh.positions,
            mesh.triangles,
            normals=mesh.normals,
            transform=stretch,
            material=Material(ambient=(0, 1, 0), diffuse=(0, 1, 0), opacity=0.5),
        )
    # seen from +y, where the sphere's mesh order (rings from the +y pole down) runs front to back
    scene = scene_of([FLOOR, mesh], [LIGHT], perspective_camera((0.0, 6.0, 5.0)))
    choice = plan(scene).transparency
    assert choice.method == "draw_last"
    assert "convex" in choice.reason
    exact = render_transparency(scene, "a_buffer")
    np.testing.assert_allclose(render_transparency(scene, "draw_last"), exact, atol=1e-12)
    if shape == "slab":
        # sorting triangles by their centroids is not enough for a convex object
        assert np.abs(render_transparency(scene, "sort_triangles") - exact).max() > 0.1


def test_separated_transparent_layers_are_sorted_per_object():
    layers = [
        horizontal_quad(0.0, colour=(1, 0, 0), opacity=0.5),
        horizontal_quad(1.0, half=1.0, colour=(0, 0, 1), opacity=0.3),
        horizontal_quad(-0.5, half=1.2, colour=(0, 1, 0), opacity=0.6),
    ]
    scene = scene_of([FLOOR, *layers], [LIGHT])
    choice = plan(scene).transparency
    assert choice.method == "sort_objects"
    exact = render_transparency(scene, "a_buffer")
    np.testing.assert_allclose(render_transparency(scene, "sort_objects"), exact, atol=1e-12)


def crossing_quads(opacity):
    """Two transparent quads crossing each other along the line x = 0, z = 0, and a third one."""
    tilted = quad(
        [[-1.5, -1.5, -0.8], [1.5, -1.5, 0.8], [1.5, 1.5, 0.8], [-1.5, 1.5, -0.8]], (1, 0, 0), opacity
    )
    flat = horizontal_quad(0.0, colour=(0, 0, 1), opacity=opacity)
    other = quad(
        [[-1.5, -1.5, 0.8], [1.5, -1.5, -0.8], [1.5, 1.5, -0.8], [-1.5, 1.5, 0.8]], (0, 1, 0), opacity
    )
    return [FLOOR, tilted, flat, other]


def test_interpenetrating_transparent_objects_need_the_a_buffer():
    scene = scene_of(crossing_quads(0.5), [LIGHT])
    choice = plan(scene).transparency
    assert choice.method == "a_buffer"
    assert "overlap" in choice.reason
    # why: sorting per object is measurably wrong here
    diff = np.abs(render_transparency(scene, "sort_objects") - render_transparency(scene, "a_buffer"))
    assert diff.max() > 0.05


def test_with_a_tolerance_depth_peeling_stops_when_the_rest_is_invisible():
    scene = scene_of(crossing_quads(0.9), [AmbientLight((1, 1, 1), 1.0)])
    tolerance = 4.0  # 8-bit steps
    # planned for a 1080p frame, where the fitted frame cost predicts peeling cheaper than the
    # A-buffer (in small frames it is not, and the A-buffer is kept); the error bound and the
    # rendered error do not depend on the frame size
    hd = {"width": 1920, "height": 1080}
    choice = plan(scene, tolerance=tolerance, **hd).transparency
    assert choice.method == "depth_peeling"
    k = choice.params["layers"]
    # closed form: the rest behind k layers of opacity 0.9 is at most 0.1^k of the brightest
    # radiance 1.2 (ambient 1 + the scene's 0.2): 255·1.2·0.1^k <= 4 first holds at k = 2 (30.6
    # steps at k = 1, 3.06 at k = 2); the planner multiplies by max(c, 1) with c measured
    c = max(shipped_models()["depth_peeling"]["c"], 1.0)
    assert k == next(j for j in range(1, 10) if 255 * c * 1.2 * 0.1**j <= tolerance) == 2
    assert choice.predicted_steps == pytest.approx(255 * c * 1.2 * 0.1**2)
    assert f"predicted max error {choice.predicted_steps:.2g} steps ≤ tolerance 4" in choice.reason
    assert 0 < choice.relative_cost < 1 and "× A-buffer" in choice.reason
    err = np.abs(
        render_transparency(scene, "depth_peeling", layers=k) - render_transparency(scene, "a_buffer")
    )
    assert 255 * err.max() <= tolerance
    assert err.max() > 0  # it is an approximation, and the bound is not vacuous
    # a looser tolerance peels fewer layers, predicted cheaper
    loose = plan(scene, tolerance=40.0, **hd).transparency
    # fewer layers, never predicted dearer (the fitted per-layer cost may be 0: in render() the
    # layers share the A-buffer's per-sample sort)
    assert loose.params["layers"] == 1 and loose.relative_cost <= choice.relative_cost
    assert plan(scene).transparency.method == "a_buffer"  # exact was asked for


# --------------------------------------------------------------------------- shadows


def shadow_agreement(scene, choice, light_index=0):
    """Visibility by the chosen method and by ray tracing at the visible points that face the
    light (elsewhere N·L <= 0 and a shadow changes nothing in the image)."""
    points, normals = visible_surface_points(scene)
    light = scene.lights[light_index]
    if isinstance(light, DirectionalLight):
        to_light = -np.asarray(light.direction)[None, :]
    else:
        to_light = np.asarray(light.position) - points
    facing = np.einsum("ij,ij->i", normals, np.broadcast_to(to_light, points.shape)) > 0
    points, normals = points[facing], normals[facing]
    tris = world_triangles(scene)
    cheap = light_visibility(choice.method, light, tris, points, normals, **choice.params)
    exact = light_visibility("ray_traced", light, tris, points, normals)
    return cheap, exact


def test_a_light_with_nothing_between_it_and_anything_needs_no_shadow_work():
    # The sphere sits beside the floor and the light shines away from the floor.
    scene = scene_of(
        [horizontal_quad(0.0, half=1.0), sphere((2.5, 0.0, 1.0), 0.5)], [DirectionalLight((1.0, 0.0, -0.2))]
    )
    choice = plan(scene).shadows[0]
    assert choice.method == "none"
    cheap, exact = shadow_agreement(scene, choice)
    np.testing.assert_array_equal(cheap, exact)


def test_ambient_lights_cast_no_shadows():
    assert plan(scene_of([FLOOR], [AmbientLight()])).shadows[0].method == "none"


@pytest.mark.parametrize("light", [DirectionalLight((0.3, 0.2, -1.0)), PointLight((0.5, 0.3, 4.0))])
def test_objects_over_a_plane_get_exact_planar_shadows(light):
    scene = scene_of([FLOOR, sphere((0.0, 0.0, 0.2), 0.6), flat_cube((-1.2, 1.0, -0.5), 0.3)], [light])
    choice = plan(scene).shadows[0]
    assert choice.method == "planar", choice
    cheap, exact = shadow_agreement(scene, choice)
    assert (exact == 0).sum() > 100
    # identical up to points whose ray grazes a silhouette edge
    assert np.mean(cheap != exact) < 2e-3


def test_objects_shadowing_each_other_need_ray_tracing_unless_the_light_is_faint():
    spheres = [FLOOR, sphere((0.0, 0.0, 1.2), 0.5), sphere((-0.3, -0.2, -0.2), 0.6)]
    scene = scene_of(spheres, [DirectionalLight((0.2, 0.1, -1.0))])
    assert plan(scene).shadows[0].method in EXACT_SHADOWS
    # The tolerance bounds every pixel. A shadow map misplaces some hard edge, where a pixel
    # changes by the light's whole contribution: diffuse 1 + specular 0.3 of the spheres'
    # materials under a white light, 255·1.3 = 331.5 steps. No tolerance below that allows a map.
    choice = plan(scene, tolerance=255.0).shadows[0]
    assert choice.method in EXACT_SHADOWS and "332 steps > tolerance 255" in choice.reason, choice
    # A light of intensity 0.1 changes a pixel by at most 0.13, 33.15 steps: within 40 a map is
    # allowed, the coarsest whose texel resolves the thinnest caster (the 1.0-wide sphere).
    faint = scene_of(spheres, [DirectionalLight((0.2, 0.1, -1.0), intensity=0.1), AmbientLight()])
    tolerance = 40.0
    choice = plan(faint, tolerance=tolerance).shadows[0]
    assert choice.method == "shadow_map", choice
    assert choice.predicted_steps == pytest.approx(255 * 0.13)
    assert 0 < choice.relative_cost < 1
    cheap, exact = shadow_agreement(faint, choice)
    assert (exact == 0).sum() > 100
    assert np.sum(cheap != exact) > 0  # the map is an approximation
    size = 64
    # the plan is for the default 640×480 frame; at 64² the cost model predicts ray tracing cheaper,
    # so the planned map is passed on: its error bound does not depend on the frame
    planned = render(
        faint, size, size, shadows=ShadowOptions("shadow_map", resolution=choice.params["resolution"])
    )
    assert planned.plan.shadows[0].method == "shadow_map"
    reference = render(faint, size, size, shadows="ray_traced").rgba
    worst = 255 * np.abs(planned.rgba - reference).max()
    assert 0 < worst <= tolerance
    assert plan(faint, tolerance=30.0).shadows[0].method in EXACT_SHADOWS  # 33.15 > 30


def test_shadow_maps_for_point_lights_are_outside_the_calibration_so_ray_tracing_stays():
    scene = scene_of(
        [FLOOR, sphere((0.0, 0.0, 1.2), 0.5), sphere((-0.3, -0.2, -0.2), 0.6)], [PointLight((0.3, 0.2, 5.0))]
    )
    choice = plan(scene, tolerance=255.0).shadows[0]
    assert choice.method in EXACT_SHADOWS
    assert "directional lights only" in choice.reason


# --------------------------------------------------------------------------- shading frequency


def test_planar_faces_under_directional_light_and_a_distant_viewer_are_flat_shaded_exactly():
    tilt = np.eye(4)
    c, s = np.cos(0.5), np.sin(0.5)
    tilt[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    cube = flat_cube((0, 0, 0), 0.8, transform=tilt)
    lights = [DirectionalLight((0.4, 0.3, -1.0)), AmbientLight()]
    scene = scene_of([cube], lights, light_model=LightModel(local_viewer=False))
    choice = plan(scene).shading[0]
    assert choice.method == "flat"
    flat = render(scene, 48, 48, shading="flat").rgba
    phong = render(scene, 48, 48, shading="phong").rgba
    np.testing.assert_allclose(flat, phong, atol=1e-6)
    assert flat[..., 3].sum() > 100
    # with a local viewer the half vector varies across each face: not exact, and not chosen
    local = scene_of([cube], lights, light_model=LightModel(local_viewer=True))
    assert plan(local).shading[0].method == "phong"
    assert (
        np.abs(render(local, 48, 48, shading="flat").rgba - render(local, 48, 48, shading="phong").rgba).max()
        > 1e-3
    )


def test_a_point_light_or_curved_surface_needs_per_pixel_shading():
    cube = flat_cube((0, 0, 0), 0.8)
    choice = plan(scene_of([cube], [PointLight((0.0, 0.0, 3.0))])).shading[0]
    assert choice.method == "phong"
    assert "PointLight" in choice.reason
    scene = scene_of([cube], [PointLight((1.0, 1.0, 2.0))])
    flat = render(scene, 48, 48, shading="flat").rgba
    phong = render(scene, 48, 48, shading="phong").rgba
    assert np.abs(flat - phong).max() > 0.01  # flat is not exact here
    curved = plan(scene_of([sphere((0, 0, 0), 1.0)], [LIGHT])).shading[0]
    assert curved.method == "phong"


def test_plan_explains_every_concern_and_rejects_bad_tolerance():
    scene = scene_of([FLOOR, horizontal_quad(0.0, opacity=0.5)], [LIGHT, AmbientLight()])
    p = plan(scene)
    lines = p.reasons()
    assert len(lines) == 1 + 2 + 2
    assert all(": " in line for line in lines)
    with pytest.raises(ValueError, match="tolerance"):
        plan(scene, tolerance=-1.0)
    with pytest.raises(ValueError, match="8-bit steps"):
        plan(scene, tolerance=float("inf"))
    with pytest.raises(TypeError, match="scene"):
        plan("scene")  # type: ignore[arg-type]


# --------------------------------------------------------------------------- convexity and self-shadowing


def _box_mesh(lid: bool, colour=(0.8, 0.6, 0.4), opacity: float = 1.0) -> Mesh:
    """A 2×2×1 box on z = 0, 4 vertices and one normal per face, outward winding; no lid: open at the top."""
    from testbeds.planner_fuzz import faceted_box

    p, t, n = faceted_box(np.array([1.0, 1.0, 0.5]), lid=lid)
    move = np.eye(4)
    move[2, 3] = 0.5
    return Mesh(p, t, n, transform=move, material=Material(ambient=colour, diffuse=colour, opacity=opacity))


def test_a_closed_uv_sphere_is_convex_and_needs_no_shadow_work():
    from blinn_phong.geometry.mesh_facts import _mesh_facts
    from blinn_phong.model.primitives import uv_sphere

    for segments, rings in ((64, 32), (317, 159)):  # 3 968 and 100 172 triangles
        p, t, n = uv_sphere(segments, rings)
        facts = _mesh_facts(Mesh(p, t, n))
        assert facts.closed and facts.convex, (segments, rings)
    p, t, n = uv_sphere(64, 32)
    scene = scene_of([Mesh(p, t, n)], [LIGHT], perspective_camera())
    assert plan(scene).shadows[0].method == "none"
    # float32 coordinates (rounded sin/cos): the tolerance follows their precision
    assert _mesh_facts(Mesh(p.astype(np.float32), t, n)).convex
    # not convex: a dent, a mirror (inside-out winding), an open cap
    dented = p.copy()
    dented[np.argmax(p[:, 2])] *= 0.7
    assert not _mesh_facts(Mesh(dented, t, n)).convex
    assert not _mesh_facts(Mesh(p, t, n, transform=np.diag([1.0, 1.0, -1.0, 1.0]))).convex
    assert not _mesh_facts(Mesh(p, t[64:], n)).convex


def test_a_cube_with_split_vertices_is_welded_closed_and_convex():
    from blinn_phong.geometry.mesh_facts import _mesh_facts

    facts = _mesh_facts(flat_cube((0, 0, 0), 0.8))
    assert facts.closed and facts.convex
    facts = _mesh_facts(_box_mesh(lid=False))
    assert not facts.closed and not facts.convex


@pytest.mark.parametrize("two_sided", [False, True])
def test_an_open_box_shades_its_own_floor_under_two_sided_lighting(two_sided):
    # One-sided lighting lights the inside with the outward normals: a lit inside point sees
    # the light through its own plane, never through the other walls. Two-sided lighting
    # flips them: the inner floor faces the sun and the walls shade it.
    sun = DirectionalLight((0.5, 0.3, -1.0))
    camera = perspective_camera((2.5, -3.5, 4.0))
    scene = scene_of([_box_mesh(lid=False)], [sun], camera, LightModel(two_sided=two_sided))
    choice = plan(scene).shadows[0]
    planned = render(scene, 48, 48)
    exact = render(scene, 48, 48, shadows="ray_traced")
    unshadowed = render(scene, 48, 48, shadows="none").rgba
    if two_sided:
        assert choice.method in EXACT_SHADOWS and "can shade itself" in choice.reason
        # the shadow is real: without shadow work the inner floor is wrong by > 100 steps
        assert 255 * np.abs(unshadowed - exact.rgba).max() > 100
    else:
        # no self-shadow (an open mesh is not proven convex, so the plan stays conservative)
        np.testing.assert_allclose(unshadowed, exact.rgba, atol=1 / 255)
    np.testing.assert_allclose(planned.rgba, exact.rgba, atol=1 / 255)
    # a closed box hides its inside: no shadow work under either lighting, unless transparent
    closed = scene_of([_box_mesh(lid=True)], [sun], camera, LightModel(two_sided=two_sided))
    assert plan(closed).shadows[0].method == "none"
    glass = scene_of([_box_mesh(lid=True, opacity=0.5)], [sun], camera, LightModel(two_sided=two_sided))
    assert plan(glass).shadows[0].method in (EXACT_SHADOWS if two_sided else ("none",))


# --------------------------------------------------------------------------- bounds with every factor


def test_the_radiance_bound_includes_attenuation_above_one():
    from blinn_phong.geometry.mesh_facts import _mesh_facts
    from blinn_phong.planning.bounds import _light_factor_bound, _max_radiance

    # a point light 0.5 above a quad at z = 0: the nearest distance to its bounding box is 0.5,
    # so att ≤ 1/(0.01 + 1·0.25) = 3.846 — and the quad's centre reaches it exactly
    light = PointLight((0.0, 0.0, 0.5), constant=0.01, quadratic=1.0)
    quad_mesh = horizontal_quad(0.0, half=1.0, colour=(0.5, 0.5, 0.5))
    scene = scene_of([quad_mesh], [light])
    facts = [_mesh_facts(m) for m in scene.meshes]
    factor = _light_factor_bound(light, facts)
    assert factor == pytest.approx(1 / (0.01 + 0.25))
    # emission 0 + ambient 0.5·0.2 (the scene's default global ambient) + F·(0.5·1 diffuse)
    bound = _max_radiance(scene, quad_mesh, [factor])
    assert bound == pytest.approx(0.5 * 0.2 + factor * 0.5)
    lit = render(scene, 32, 32, shading="phong").rgba
    assert lit[..., :3].max() <= bound + 1e-6
    assert lit[..., :3].max() > 0.9 * bound  # the bound is reached near the light's foot


def test_depth_peeling_under_a_close_point_light_stays_within_the_tolerance():
    light = PointLight((0.2, 0.1, 1.6), constant=0.01, quadratic=1.0)
    scene = scene_of(crossing_quads(0.8), [light, AmbientLight((1, 1, 1), 0.3)])
    exact = render_transparency(scene, "a_buffer")
    peeled = 0
    for tolerance in (8.0, 64.0, 255.0):
        # planned for 1080p, where peeling is predicted cheaper than the A-buffer (the bound and the
        # rendered error do not depend on the frame size)
        choice = plan(scene, tolerance=tolerance, width=1920, height=1080).transparency
        if choice.method == "depth_peeling":
            peeled += 1
            image = render_transparency(scene, "depth_peeling", layers=choice.params["layers"])
            assert 255 * np.abs(image - exact).max() <= tolerance
            assert choice.predicted_steps <= tolerance
    assert peeled >= 1


# --------------------------------------------------------------------------- shadow maps by feature size


def test_thin_casters_need_texels_finer_than_their_width():
    from blinn_phong.planning.planner import shadow_map_geometry

    slat = np.diag([0.03, 2.6, 0.02, 1.0])
    slats = []
    for i in range(6):
        cube = flat_cube((0, 0, 0), 1.0)
        move = slat.copy()
        move[:3, 3] = (-1.5 + 0.6 * i, 0.0, 0.6)
        slats.append(
            Mesh(cube.positions, cube.triangles, cube.normals, transform=move, material=cube.material)
        )
    sun = DirectionalLight((0.0, 0.0, -1.0), intensity=0.05)  # faint: 255·0.05·(0.8 + 0.5) = 16.6
    scene = scene_of([FLOOR, *slats], [sun, AmbientLight()], perspective_camera())
    geometry = shadow_map_geometry(scene, 0)
    assert geometry.feature == pytest.approx(0.06)  # a slat's width seen from straight above
    hd = {"width": 1920, "height": 1080}
    choice = plan(scene, tolerance=32.0, **hd).shadows[0]
    assert choice.method == "shadow_map", choice
    resolution = choice.params["resolution"]
    assert geometry.span / resolution <= 0.03 < geometry.span / (resolution // 2)
    assert plan(scene, tolerance=16.0, **hd).shadows[0].method in EXACT_SHADOWS  # 16.6 > 16
    # on a small frame that map is predicted slower than an exact method: the cost follows the frame
    small = plan(scene, tolerance=32.0, width=160, height=120).shadows[0]
    assert small.method in EXACT_SHADOWS and "not below" in small.reason, small


# --------------------------------------------------------------------------- the plan render() follows


def test_plan_is_the_plan_render_follows_for_kay_greenberg_and_the_default_shading():
    glass = sphere((0.0, 0.0, 0.3), 0.8, (0.2, 0.5, 0.9))
    kg = Material(ambient=(0.2, 0.5, 0.9), diffuse=(0.2, 0.5, 0.9), kay_greenberg=(0.2, 0.9, 2.0))
    glass = Mesh(glass.positions, glass.triangles, glass.normals, transform=glass.transform, material=kg)
    pane = horizontal_quad(1.4, half=0.6, colour=(1, 0, 0), opacity=0.5)
    cube = flat_cube((1.5, 1.5, -0.5), 0.3)
    for meshes, light_model in (
        ([FLOOR, glass], None),
        ([FLOOR, glass, pane, cube], LightModel(local_viewer=False)),
    ):
        scene = scene_of(meshes, [LIGHT], perspective_camera(), light_model)
        for tolerance in (0.0, 8.0):
            for fog in (None, Fog("exp2", (0.3, 0.3, 0.3), density=0.15), Fog("linear", start=2.0, end=14.0)):
                followed = render(scene, 40, 30, tolerance=tolerance, fog=fog).plan
                planned = plan(scene, tolerance, width=40, height=30, fog=fog)
                assert followed.transparency.method == planned.transparency.method
                assert [c.method for c in followed.shadows] == [c.method for c in planned.shadows]
                assert [c.method for c in followed.shading] == [c.method for c in planned.shading]
                assert followed.fog == planned.fog  # the same range, cost and reason
                assert (followed.fog is None) == (fog is None)
    assert plan(scene_of([FLOOR, glass], [LIGHT])).transparency.method == "draw_last"


def test_soft_shadows_do_not_depend_on_the_camera_and_say_how_many_rays(monkeypatch):
    from blinn_phong.planning.frame_plan import ShadowOptions, _shadow_choice
    from blinn_phong.shadows import raytrace
    from blinn_phong.shadows.method import embree_available
    from blinn_phong.shadows.soft import soft_visibility

    if not embree_available():
        pytest.skip("soft shadows cast rays with embreex")
    light = PointLight((0.5, 0.3, 3.0))
    scene = scene_of([FLOOR, sphere((0.0, 0.0, 0.8), 0.5)], [light])
    points, normals = visible_surface_points(scene, 48)
    squares = []
    monkeypatch.setattr(
        raytrace, "area_light_visibility", lambda _s, _p, _n, *square, **_kw: squares.append(square)
    )
    params = {"samples_per_axis": 3, "radius": 0.4, "offset": 1e-3}
    tris = world_triangles(scene)
    ray_scene = raytrace.RayScene(tris)
    soft_visibility(light, tris, points, normals, **params, ray_scene=ray_scene)
    near = points[:, 0] < 0  # what another camera might see
    soft_visibility(light, tris, points[near], normals[near], **params, ray_scene=ray_scene)
    for a, b in zip(*squares, strict=True):
        np.testing.assert_array_equal(a, b)  # the same square light, whatever is visible
    corner, edge_u, edge_v = squares[0]
    np.testing.assert_allclose(np.linalg.norm(edge_u), 0.8)
    np.testing.assert_allclose(corner + (edge_u + edge_v) / 2, light.position)
    planned = plan(scene).shadows[0]
    choice = _shadow_choice(light, ShadowOptions("soft", samples=20, radius=0.4), planned)
    assert choice.params["samples_per_axis"] == 4 and "20 samples asked, 4×4 = 16 cast" in choice.reason
    exact = _shadow_choice(light, ShadowOptions("soft", samples=16, radius=0.4), planned)
    assert "samples asked" not in exact.reason


def test_render_takes_layers_as_the_plan_names_them_and_peel_layers_as_before():
    scene = scene_of(crossing_quads(0.5), [LIGHT])
    new = render(scene, 32, 32, transparency="depth_peeling", layers=2)
    old = render(scene, 32, 32, transparency="depth_peeling", peel_layers=2)
    assert new.plan.transparency.params == {"layers": 2} == old.plan.transparency.params
    np.testing.assert_array_equal(new.rgba, old.rgba)  # the same call, deterministic
    with pytest.raises(ValueError, match="layers, peel_layers"):
        render(scene, 32, 32, transparency="depth_peeling", layers=2, peel_layers=3)
