"""Shadow volumes against Embree's ray-traced hard shadows and the closed-form shadow of a sphere.

Embree: the same visible samples (pixel centres of our rasterizer) are classified by shadow
rays (:mod:`blinn_phong.shadows.raytrace`) and by stencil counting; the two must agree on every sample
not touching a lit/shadowed boundary of the ray-traced mask (a sample next to the boundary
can lie within float rounding of a volume face).

Closed form: the shadow of a sphere of radius r, centre C, on the plane z = 0 under a point
light L is the section of the tangent cone ``((X−L)·â)² = cos²α |X−L|²`` (â = (C−L)/|C−L|,
sin α = r/|C−L|) by the plane: a conic ``[x y 1] M [x y 1]ᵀ = 0`` whose area is
``π |det M| / det(M₂)^{3/2}`` (M₂ its upper 2×2 block; the area of a central conic).
"""

import math

import numpy as np
import pytest

from blinn_phong._numba import numba_available
from blinn_phong.model.lights import DirectionalLight, PointLight
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.model.scene import Camera, Mesh
from blinn_phong.model.transforms import look_at
from blinn_phong.shadows.volume import shadow_volume_visibility, zpass_is_safe
from blinn_phong.shadows.volume_counting import stencil_counts
from blinn_phong.shadows.volume_mesh import analyse_topology, shadow_volume_triangles, silhouette_edges

from .volume_scenes import (
    HEIGHT,
    LIGHTS,
    WIDTH,
    boundary_band,
    casters,
    embree_reference,
    embree_visibility,
    inside_camera,
    outside_camera,
    samples,
    scene_with,
    sphere_mesh,
    world_triangles,
)

pytest.importorskip("embreex")


def _compare(scene, light, method):
    tris = world_triangles(scene)
    pts, nrm, _, ref, band = embree_reference(scene, light, tris)
    got = shadow_volume_visibility(light, tris, pts, nrm, camera=scene.camera, stencil=method)
    return ref, got, band


@pytest.mark.parametrize("light_name", sorted(LIGHTS))
@pytest.mark.parametrize("caster", ["sphere", "torus", "box", "pair"])
@pytest.mark.parametrize("method", ["zfail", "zpass"])
def test_camera_outside_matches_embree(caster, light_name, method):
    light = LIGHTS[light_name]
    scene = scene_with(casters(caster), light, outside_camera())
    ref, got, band = _compare(scene, light, method)
    interior = ~band
    shadowed = np.count_nonzero((ref == 0) & interior)
    assert shadowed > 100, "the scene must show a shadow for the test to mean anything"
    assert np.count_nonzero((ref == 1) & interior) > 100
    wrong = np.count_nonzero((got != ref) & interior)
    assert wrong == 0, f"{wrong} of {np.count_nonzero(interior)} interior samples disagree with Embree"
    # near the boundary the two may differ by rounding only: a thin fringe, not a region
    assert np.count_nonzero(got != ref) <= np.count_nonzero(band)


@pytest.mark.parametrize("light_name", sorted(LIGHTS))
@pytest.mark.parametrize("caster", ["sphere", "pair"])
def test_camera_inside_volume_zfail_matches_embree(caster, light_name):
    light = LIGHTS[light_name]
    first = casters(caster)[0]
    centre = first.transform[:3, 3]
    camera = inside_camera(light, centre, 0.7)
    scene = scene_with(casters(caster), light, camera)
    eye = np.linalg.inv(camera.view)[:3, 3]
    tris = world_triangles(scene)
    # precondition, from the ray tracer: the eye itself is in shadow
    assert embree_visibility(light, tris, eye[None], np.array([[0.0, 0.0, 1.0]]))[0] == 0.0
    ref, got, band = _compare(scene, light, "zfail")
    interior = ~band
    assert np.count_nonzero((ref == 0) & interior) > 100 and np.count_nonzero((ref == 1) & interior) > 100
    assert np.count_nonzero((got != ref) & interior) == 0


@pytest.mark.skipif(not numba_available(), reason="numba not installed")
@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("method", ["zfail", "zpass"])
def test_engines_count_identically(method, parallel, monkeypatch):
    """Integer counts from the same float expressions: numba and numpy agree exactly (deterministic),
    on one thread and with the tile rows interleaved between threads (forced on this small image)."""
    import blinn_phong.shadows.volume_counting as sv

    if parallel:
        monkeypatch.setattr(sv, "_PARALLEL_RECEIVERS", 0)
        monkeypatch.setattr(sv, "_threads", lambda: 3)  # three bands, whatever the machine
    light = LIGHTS["point"]
    scene = scene_with(casters("pair") + casters("box"), light, outside_camera())
    pts, _, _, _ = samples(scene, 80, 60)
    volume = shadow_volume_triangles(world_triangles(scene), light, caps=method == "zfail")
    view, proj = scene.camera.view, scene.camera.projection
    a = stencil_counts(volume, view, proj, pts, stencil=method, engine="numpy")
    b = stencil_counts(volume, view, proj, pts, stencil=method, engine="numba")
    np.testing.assert_array_equal(a, b)
    assert np.count_nonzero(a) > 50


@pytest.mark.skipif(not numba_available(), reason="numba not installed")
@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("method", ["zfail", "zpass"])
@pytest.mark.parametrize("light_name", ["directional", "point"])
def test_tile_shortcuts_count_as_each_receiver(light_name, method, parallel, monkeypatch):
    """Receivers lying 1e-4 above the planes of their own light caps (a ground, a floating open
    quad, a closed box's top), as the renderer moves them: the compiled kernel settles whole
    tiles from each tile's depth range and depth plane; the numpy engine tests every receiver.
    The counts agree exactly (integers from the same float expressions), and the quad's cap,
    in front of the ground below it, really counts there."""
    import blinn_phong.shadows.volume_counting as sv

    if parallel:
        monkeypatch.setattr(sv, "_PARALLEL_RECEIVERS", 0)
        monkeypatch.setattr(sv, "_threads", lambda: 3)
    light = LIGHTS[light_name]
    ground_p, ground_t, _ = grid_plane(1, 1, (8.0, 8.0))
    quad_p, quad_t, _ = grid_plane(1, 1, (1.2, 1.0))
    quad = quad_p[quad_t] + np.array([-0.6, 0.2, 1.1])
    box = world_triangles(scene_with(casters("box"), light, outside_camera()))
    tris = np.concatenate([ground_p[ground_t], quad, box + np.array([1.2, -0.4, 0.0])])
    s = 0.01
    gx, gy = np.meshgrid(np.arange(-2.0, 2.0, s), np.arange(-1.6, 2.0, s))
    ground = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, 1e-4)], axis=1)
    qx, qy = np.meshgrid(np.arange(-1.15, -0.05, s), np.arange(-0.25, 0.65, s))
    on_quad = np.stack([qx.ravel(), qy.ravel(), np.full(qx.size, 1.1 + 1e-4)], axis=1)
    bx, by = np.meshgrid(np.arange(0.75, 1.65, s), np.arange(-0.85, 0.05, s))
    on_box = np.stack([bx.ravel(), by.ravel(), np.full(bx.size, 1.0 + 1e-4)], axis=1)
    pts = np.concatenate([ground, on_quad, on_box])
    view = look_at((0.3, -5.0, 4.0), (0.0, 0.0, 0.4), (0.0, 0.0, 1.0))
    camera = Camera.perspective(50.0, 4 / 3, 0.5, 30.0, view=view)
    volume = shadow_volume_triangles(tris, light, caps=True if method == "zfail" else "light")
    a = stencil_counts(volume, camera.view, camera.projection, pts, stencil=method, engine="numpy")
    b = stencil_counts(volume, camera.view, camera.projection, pts, stencil=method, engine="numba")
    np.testing.assert_array_equal(a, b)
    # the scene means something: ground receivers in the quad's and the box's shadows
    assert 500 < np.count_nonzero(a[: len(ground)]) < len(ground) // 2
    assert np.count_nonzero(a[len(ground) :]) == 0  # the tops are lit


@pytest.mark.skipif(not numba_available(), reason="numba not installed")
@pytest.mark.parametrize("parallel", [False, True])
def test_a_reused_binning_counts_as_a_fresh_one(parallel, monkeypatch):
    """The next light of a frame projects its (differently moved) receivers into the previous
    light's tile order; even a stale order (the arrays changed in place) counts exactly as a
    fresh binning does, since every tile's bounds and depths are measured again (on one thread
    and with the tile rows split between threads)."""
    import blinn_phong.shadows.volume_counting as sv

    if parallel:
        monkeypatch.setattr(sv, "_PARALLEL_RECEIVERS", 0)
        monkeypatch.setattr(sv, "_threads", lambda: 3)

    first, second = LIGHTS["directional"], LIGHTS["point"]
    scene = scene_with(casters("pair") + casters("box"), second, outside_camera())
    tris = world_triangles(scene)
    pts, nrm, _, _ = samples(scene, WIDTH, HEIGHT)
    pts, nrm = pts.copy(), nrm.copy()

    def visibility(light, reuse):
        if not reuse:
            sv._BINNING.clear()
        return shadow_volume_visibility(light, tris, pts, nrm, camera=scene.camera, engine="numba")

    for light in (first, second):  # binned for `first`, reused for `second`
        reused = visibility(light, True)
    assert sv._BINNING and sv._BINNING[0][0]() is pts
    np.testing.assert_array_equal(reused, visibility(second, False))
    assert 100 < np.count_nonzero(reused == 0) < len(pts) - 100
    visibility(first, False)
    shuffled = np.random.default_rng(7).permutation(len(pts))
    pts[:], nrm[:] = pts[shuffled], nrm[shuffled]  # same arrays: the cached order is now stale
    np.testing.assert_array_equal(visibility(second, True), visibility(second, False))


def _ellipse_area(light, centre, radius):
    lv, c = np.asarray(light, float), np.asarray(centre, float)
    axis = c - lv
    dist = np.linalg.norm(axis)
    axis /= dist
    cos2 = 1.0 - (radius / dist) ** 2
    q = np.outer(axis, axis) - cos2 * np.eye(3)
    t = np.array([[1.0, 0.0, -lv[0]], [0.0, 1.0, -lv[1]], [0.0, 0.0, -lv[2]]])
    m = t.T @ q @ t
    m2 = np.linalg.det(m[:2, :2])
    assert m2 > 0, "the section must be an ellipse"
    area = math.pi * abs(np.linalg.det(m)) / m2**1.5
    # semi-axes from the centred form: λ_i of M₂ and the constant at the centre
    centre_xy = np.linalg.solve(m[:2, :2], -m[:2, 2])
    k = -(centre_xy @ m[:2, 2] + m[2, 2])
    semi = np.sqrt(k / np.linalg.eigvalsh(m[:2, :2]))
    return area, centre_xy, semi


@pytest.mark.parametrize("kind", ["orthographic", "perspective"])
def test_sphere_shadow_is_the_closed_form_ellipse(kind):
    light_pos, centre, radius = (-1.5, 0.4, 3.0), (0.0, 0.0, 1.0), 0.5
    p, t, _ = uv_sphere(64, 32, radius)
    sphere_tris = (p + np.asarray(centre))[t]
    # the tessellated sphere lies between its inscribed ball (min face-plane distance) and r
    v = sphere_tris - np.asarray(centre)
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    r_in = float(np.min(np.abs(np.einsum("ij,ij->i", n, v[:, 0])) / np.linalg.norm(n, axis=1)))
    area_out, ell_c, semi = _ellipse_area(light_pos, centre, radius)
    area_in, _, _ = _ellipse_area(light_pos, centre, r_in)
    s = 0.02  # receiver grid spacing on the plane (world units)
    half_x, half_y = ell_c[0] + 2.0, 1.6
    xs = np.arange(-half_x, half_x, s) + s / 2
    ys = np.arange(-half_y, half_y, s) + s / 2
    assert abs(ell_c[0]) + semi.max() < half_x - 0.1 and abs(ell_c[1]) + semi.max() < half_y - 0.1
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    nrm = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    ground_p, ground_t, _ = grid_plane(1, 1, (2 * half_x + 1, 2 * half_y + 1))
    tris = np.concatenate([sphere_tris, ground_p[ground_t]])
    view = look_at((0.0, 0.0, 8.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    if kind == "orthographic":
        camera = Camera.orthographic(-half_x, half_x, -half_y, half_y, 1.0, 20.0, view=view)
    else:
        camera = Camera.perspective(60.0, half_x / half_y, 1.0, 20.0, view=view)
    vis = shadow_volume_visibility(PointLight(light_pos), tris, pts, nrm, camera=camera)
    measured = np.count_nonzero(vis == 0) * s * s
    # centre sampling misclassifies only cells the boundary passes through: within a tube of
    # half-width s/√2 around a curve of length P ≤ 2π·a, area ≤ √2·P·s
    perimeter = 2 * math.pi * semi.max()
    slack = math.sqrt(2) * perimeter * s
    assert area_in - slack <= measured <= area_out + slack, (area_in, area_out, measured, slack)
    # and the bound is tight enough to catch a wrong radius: 5 % less radius is outside it
    assert _ellipse_area(light_pos, centre, 0.95 * radius)[0] < area_in - slack


def test_topology_classifies_closed_open_and_inside_out():
    p, t, _ = uv_sphere(12, 6)
    sphere = p[t]
    inside_out = (p + 3.0)[t[:, ::-1]]
    open_quad = grid_plane(2, 2)[0][grid_plane(2, 2)[1]] + np.array([0, 0, -2.0])
    topo = analyse_topology(np.concatenate([sphere, inside_out, open_quad]))
    n1, n2 = len(sphere), len(inside_out)
    assert topo.closed[: n1 + n2].all() and not topo.closed[n1 + n2 :].any()
    assert len(topo.reasons) == 1 and "8 boundary edges" in topo.reasons[0]
    # the inside-out sphere was flipped: its faces are now the reverse of the input
    v = topo.vertices[topo.triangles[n1 : n1 + n2]]
    np.testing.assert_array_equal(v, inside_out[:, ::-1])
    # a sphere lit from +y: its silhouette is one closed loop of `segments` edges around the equator
    sil = silhouette_edges(analyse_topology(sphere), DirectionalLight((0.0, -1.0, 0.0)))
    assert len(sil) == 12
    assert sorted(sil[:, 0].tolist()) == sorted(sil[:, 1].tolist())  # each vertex starts and ends one edge


def test_bad_input_is_named():
    light = PointLight((0.0, 0.0, 3.0))
    tris = sphere_mesh((0, 0, 1), 0.5).positions[sphere_mesh((0, 0, 1), 0.5).triangles]
    with pytest.raises(ValueError, match="points"):
        shadow_volume_visibility(light, tris, np.zeros((3, 2)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="stencil"):
        stencil_counts(np.zeros((1, 3, 4)), np.eye(4), np.eye(4), np.zeros((1, 3)), stencil="zmiddle")
    with pytest.raises(TypeError, match="light"):
        shadow_volume_visibility(object(), tris, np.zeros((3, 3)), np.ones((3, 3)))
    for points in (np.zeros((0, 3)), np.zeros((3, 3))):  # no receiver: the names are still checked
        with pytest.raises(ValueError, match="stencil: expected"):
            shadow_volume_visibility(light, tris, points, np.ones_like(points), stencil="zmiddle")
        with pytest.raises(ValueError, match="engine: expected"):
            shadow_volume_visibility(light, tris, points, np.ones_like(points), engine="gpu")
        with pytest.raises(TypeError, match="light"):
            shadow_volume_visibility(object(), tris, points, np.ones_like(points))
    with pytest.raises(ValueError, match="behind the camera"):
        cam = outside_camera()
        shadow_volume_visibility(light, tris, np.array([[0.0, -20.0, 15.0]]), np.ones((1, 3)), camera=cam)


def test_render_accepts_shadow_volume_and_matches_ray_traced():
    from blinn_phong import ShadowOptions, render

    light = LIGHTS["spot"]
    scene = scene_with(casters("sphere"), light, outside_camera())
    traced = render(scene, 48, 36, shadows="ray_traced")
    volume = render(scene, 48, 36, shadows=ShadowOptions("shadow_volume"))
    assert volume.plan.shadows[0].method == "shadow_volume"
    diff = np.abs(volume.rgba - traced.rgba).max(axis=2)
    shadow_img = traced.passes["shadow"][..., 0]
    assert (shadow_img < 0.5).sum() > 20  # the frame shows a shadow
    # pixels away from a shadow edge are identical
    edge = boundary_band((shadow_img > 0.5).astype(np.int64), radius=0)
    assert diff[~edge].max() == 0.0


def test_mesh_object_is_not_needed_for_soups():
    """Faces given as separate triangles (no shared indices) weld back into a closed mesh."""
    mesh: Mesh = sphere_mesh((0, 0, 1), 0.5)
    soup = (np.c_[mesh.positions, np.ones(len(mesh.positions))] @ mesh.transform.T)[:, :3][mesh.triangles]
    assert analyse_topology(soup).closed.all()
    assert HEIGHT <= 120 and WIDTH <= 160


@pytest.mark.parametrize("light_name", sorted(LIGHTS))
def test_auto_matches_embree_from_outside_and_inside(light_name):
    """The near-clip test tells outside from inside; "auto" (z-fail) matches Embree in both."""
    light = LIGHTS[light_name]
    outside = scene_with(casters("pair"), light, outside_camera())
    inside_cam = inside_camera(light, casters("pair")[0].transform[:3, 3], 0.7)
    inside = scene_with(casters("pair"), light, inside_cam)
    tris = world_triangles(outside)
    assert zpass_is_safe(light, tris, outside.camera.view, outside.camera.projection)
    assert not zpass_is_safe(light, tris, inside_cam.view, inside_cam.projection)
    for scene in (outside, inside):
        pts, nrm, _, ref, band = embree_reference(scene, light, tris)
        got = shadow_volume_visibility(light, tris, pts, nrm, camera=scene.camera)  # stencil="auto"
        assert np.count_nonzero((got != ref) & ~band) == 0


@pytest.mark.skipif(not numba_available(), reason="numba not installed")
@pytest.mark.parametrize("pairing", ["grouped", "hashed"])
def test_topology_is_the_same_without_numba(monkeypatch, pairing):
    """Compiled welding and edge pairing (edges grouped by start vertex, or a hash table where
    degrees are high) and sorting (numpy) build the same volumes, bit for bit — also for
    non-manifold input: a triangle given twice, and an edge shared by three faces."""
    import blinn_phong._numba
    import blinn_phong.shadows.volume_mesh as sv

    scene = scene_with(casters("pair") + casters("torus") + casters("box"), LIGHTS["point"], outside_camera())
    p, t, _ = uv_sphere(12, 6)
    fin = np.array([[[5.0, 0, 0], [6.0, 0, 0], [5.5, 1, 0]], [[6.0, 0, 0], [5.0, 0, 0], [5.5, -1, 0]]])
    third = np.array([[[5.0, 0, 0], [6.0, 0, 0], [5.5, 0, 1]]])  # a third face on the fin's edge
    tris = np.concatenate(
        [world_triangles(scene), (p + 3.0)[t[:, ::-1]], fin, third, fin[:1]]  # + inside-out sphere
    )
    monkeypatch.setattr(sv, "_NUMPY_BELOW", 0)  # compiled whatever the size
    if pairing == "hashed":
        monkeypatch.setattr(sv, "_GROUP_STEPS_PER_EDGE", 0)
    compiled = sv._analyse(tris)
    assert any("more than two faces" in r for r in compiled.reasons)  # the fin is non-manifold
    monkeypatch.setattr(blinn_phong._numba, "numba_available", lambda: False)
    reference = sv._analyse(tris)
    for name in ("valid", "closed", "component", "neighbour"):
        np.testing.assert_array_equal(getattr(compiled, name), getattr(reference, name))
    assert compiled.reasons == reference.reasons
    for light in LIGHTS.values():
        np.testing.assert_array_equal(
            shadow_volume_triangles(compiled, light), shadow_volume_triangles(reference, light)
        )


def test_without_embree_hard_shadows_fall_back_to_shadow_volumes(monkeypatch):
    import blinn_phong.planning.frame_plan as frame

    light = LIGHTS["point"]
    scene = scene_with(casters("sphere"), light, outside_camera())
    monkeypatch.setattr(frame, "embree_available", lambda: False)
    choice = frame.frame_plan(scene, shadows="ray_traced").shadows[0]
    assert choice.method == "shadow_volume" and "Embree" in choice.reason
    assert (
        frame.frame_plan(scene, shadows=frame.ShadowOptions("soft", radius=0.2)).shadows[0].method
        == "shadow_map"
    )


def test_addon_shadow_setting_selects_shadow_volumes():
    """The add-on's "Shadow Volumes" setting reaches render() and matches ray tracing off the edges."""
    from addon.pipeline import RenderOptions, render_frame

    light = LIGHTS["directional"]
    scene = scene_with(casters("box"), light, outside_camera())
    volume = render_frame(scene, 48, 36, options=RenderOptions(samples_per_axis=1, shadows="VOLUME"))
    traced = render_frame(scene, 48, 36, options=RenderOptions(samples_per_axis=1, shadows="HARD"))
    assert volume.choices["shadows"] == ["shadow_volume"] and traced.choices["shadows"] == ["ray_traced"]
    shadow = traced.passes["shadow"][..., 0]
    assert (shadow < 0.5).sum() > 20
    edge = boundary_band((shadow > 0.5).astype(np.int64), radius=0)
    assert np.abs(volume.rgba - traced.rgba).max(axis=2)[~edge].max() == 0.0
