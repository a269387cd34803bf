"""Where stenciled shadow volumes fail, each with the set of wrong samples derived exactly.

Counting identity (every bound below follows from it). Along the camera ray through a sample
p, let F_n, B_n be the front/back volume faces nearer than p and F_f, B_f those not nearer;
z-pass counts ``F_n − B_n`` and z-fail ``B_f − F_f``, so every face is counted by exactly one of
them and ``zfail − zpass = (F_n + F_f) − (B_n + B_f)`` = entries − exits of the whole drawn ray,
from where the near plane cuts it (q_p) to infinity = ``w(q_p)``, the number of volumes q_p lies
in. So z-pass is off by exactly ``w(q_p)``: wrong whenever the eye is inside a volume (q_p ≈ eye)
or the near plane cuts one. And a volume with a missing piece X counts ``w − c_X``, where c_X is
X's own count at p: the wrong samples are among those where ``c_X ≠ 0``.

The "truth" w is Embree's shadow rays (tests/effects/test_shadow_volume.py shows z-fail matching
them); samples touching a lit/shadowed boundary of the compared masks are left out (rounding).
"""

from __future__ import annotations

import numpy as np
import pytest

from blinn_phong.model.lights import DirectionalLight, PointLight
from blinn_phong.model.scene import Camera, Mesh
from blinn_phong.model.transforms import look_at
from blinn_phong.shadows.volume import shadow_volume_visibility, zpass_is_safe
from blinn_phong.shadows.volume_counting import stencil_counts
from blinn_phong.shadows.volume_mesh import analyse_topology, shadow_volume_triangles, silhouette_edges
from tests.effects.volume_scenes import (
    HEIGHT,
    LIGHTS,
    WIDTH,
    boundary_band,
    casters,
    embree_reference,
    embree_visibility,
    image_of,
    inside_camera,
    outside_camera,
    samples,
    scene_with,
    sphere_mesh,
    world_triangles,
)

pytest.importorskip("embreex")


def _towards(normals: np.ndarray, pts: np.ndarray, light) -> np.ndarray:
    """Unit normals turned to the light's side (the offset shadow_volume_visibility applies)."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    if isinstance(light, DirectionalLight):
        to_light = np.broadcast_to(-np.asarray(light.direction, float), pts.shape)
    else:
        to_light = np.asarray(light.position) - pts
    side = np.sign(np.einsum("ij,ij->i", n, to_light))
    return n * np.where(side == 0, 1.0, side)[:, None]


def _near_points(camera: Camera, pts: np.ndarray) -> np.ndarray:
    """q_p: where the camera ray through each point crosses the near plane (world space)."""
    inv = np.linalg.inv(camera.view)
    eye = inv[:3, 3]
    eye_z = (np.c_[pts, np.ones(len(pts))] @ camera.view.T)[:, 2]
    p = camera.projection
    near = p[2, 3] / (p[2, 2] - 1.0)  # gluPerspective: P22 = (f+n)/(n−f), P23 = 2fn/(n−f)
    return eye + (pts - eye) * (near / -eye_z)[:, None]


def _zpass_vs_zfail(scene, light, band_radius=0):
    pts, nrm, pix, _ = samples(scene)
    pts = pts + 1e-4 * _towards(nrm, pts, light)  # as shadow_volume_visibility moves them
    volume_f = shadow_volume_triangles(world_triangles(scene), light, caps=True)
    volume_p = shadow_volume_triangles(world_triangles(scene), light, caps=False)
    view, proj = scene.camera.view, scene.camera.projection
    zfail = stencil_counts(volume_f, view, proj, pts, stencil="zfail")
    zpass = stencil_counts(volume_p, view, proj, pts, stencil="zpass")
    q = _near_points(scene.camera, pts)
    w_q = 1.0 - embree_visibility(light, world_triangles(scene), q, np.tile([0.0, 0.0, 1.0], (len(q), 1)))
    band = boundary_band(image_of(w_q.astype(np.int64), pix), radius=band_radius).ravel()[pix]
    return pts, nrm, pix, zfail, zpass, w_q, band


@pytest.mark.parametrize("light_name", sorted(LIGHTS))
def test_zpass_with_the_camera_inside_a_volume(light_name):
    light = LIGHTS[light_name]
    camera = inside_camera(light, casters("sphere")[0].transform[:3, 3], 0.7)
    scene = scene_with(casters("sphere"), light, camera)
    _, _, _, zfail, zpass, w_q, band = _zpass_vs_zfail(scene, light)
    ok = ~band
    # the identity, sample by sample: z-pass is short by the near plane's count w(q_p)
    np.testing.assert_array_equal((zfail - zpass)[ok], w_q[ok].astype(np.int64))
    # measured: with the whole near plane inside the sphere's volume, w(q_p) = 1 everywhere, so every
    # count is shifted by one and every lit/shadowed answer is inverted
    wrong = np.count_nonzero(((zpass == 0) != (zfail == 0)) & ok)
    assert wrong >= 0.99 * np.count_nonzero(ok), f"z-pass wrong on {wrong} of {np.count_nonzero(ok)}"
    assert np.all(zpass[ok] == zfail[ok] - 1)


def test_zpass_near_plane_clipping_with_the_eye_outside():
    light = LIGHTS["point"]
    # a far-reaching near plane (6.5 units from the eye) slices through the sphere's shadow volume
    view = look_at((0.0, -6.0, 5.0), (0.0, 0.0, 0.5), (0, 0, 1))
    camera = Camera.perspective(40.0, 4 / 3, 6.5, 40.0, view=view)
    scene = scene_with(casters("sphere"), light, camera)
    eye = np.linalg.inv(view)[:3, 3]
    assert embree_visibility(light, world_triangles(scene), eye[None], np.array([[0, 0, 1.0]]))[0] == 1.0
    # one more pixel of margin: where the near plane slices the sphere, q_p grazes its surface
    _, _, _, zfail, zpass, w_q, band = _zpass_vs_zfail(scene, light, band_radius=1)
    ok = ~band
    np.testing.assert_array_equal((zfail - zpass)[ok], w_q[ok].astype(np.int64))
    wrong = ((zpass == 0) != (zfail == 0)) & ok
    # bound: the wrong samples are exactly those whose near-plane point is shadowed
    assert np.array_equal(wrong, (w_q > 0) & ok)
    assert 50 < np.count_nonzero(wrong) < np.count_nonzero(ok)
    # the near-clip test sees it coming: "auto" would count this view with z-fail
    assert not zpass_is_safe(light, world_triangles(scene), camera.view, camera.projection)
    assert zpass_is_safe(light, world_triangles(scene), outside_camera().view, outside_camera().projection)


def test_open_mesh_leaks_through_its_hole_unless_every_triangle_is_extruded():
    light = PointLight((0.3, 0.2, 4.0))
    sphere = sphere_mesh((0.0, 0.0, 1.2), 0.7)
    world = sphere.positions + sphere.transform[:3, 3]
    centroid_z = world[sphere.triangles].mean(axis=1)[:, 2]
    hole = centroid_z < 1.2 - 0.7 * np.sin(np.radians(50))  # the bottom cap, turned away from the light
    dome = Mesh(
        sphere.positions, sphere.triangles[~hole], transform=sphere.transform, material=sphere.material
    )
    camera = Camera.perspective(
        50.0, 4 / 3, 0.5, 40.0, view=look_at((0.2, 0.1, 6.0), (0.0, 0.0, 0.0), (0, 1, 0))
    )
    scene = scene_with([dome], light, camera)
    tris = world_triangles(scene)
    assert len(analyse_topology(tris).reasons) == 2  # the ground quad and the dome are both open
    pts, nrm, _, truth, band = embree_reference(scene, light, tris)
    ok = ~band
    # the default extrudes every triangle of an open mesh: no leak
    fallback = shadow_volume_visibility(light, tris, pts, nrm, camera=camera)
    assert np.count_nonzero((fallback != truth) & ok) == 0
    # silhouette extrusion as if closed: the dark cap has the hole's shape missing at infinity (X)
    ground_tris, dome_tris = tris[:2], tris[2:]
    forced = np.concatenate(
        [
            shadow_volume_triangles(dome_tris, light, force_silhouette=True),
            shadow_volume_triangles(ground_tris, light),
        ]
    )
    counts = stencil_counts(forced, camera.view, camera.projection, pts + 1e-4 * _towards(nrm, pts, light))
    lp = np.asarray(light.position)
    missing = (np.c_[world[sphere.triangles[hole]].reshape(-1, 3) - lp, np.zeros(3 * hole.sum())]).reshape(
        -1, 3, 4
    )
    c_x = stencil_counts(missing, camera.view, camera.projection, pts + 1e-4 * _towards(nrm, pts, light))
    leaked = ((counts == 0) != (truth == 1)) & ok
    # derived: the sphere would be exact closed, so the wrong samples are exactly where c_X ≠ 0
    assert np.array_equal(leaked, (c_x != 0) & ok)
    assert np.count_nonzero(leaked) > 50, "the camera must look through the hole's cone"
    # z-pass draws no caps, so a hole in the dark cap cannot hurt it (camera outside)
    zpass = np.concatenate(
        [
            shadow_volume_triangles(dome_tris, light, caps=False, force_silhouette=True),
            shadow_volume_triangles(ground_tris, light, caps=False),
        ]
    )
    zp = stencil_counts(
        zpass, camera.view, camera.projection, pts + 1e-4 * _towards(nrm, pts, light), stencil="zpass"
    )
    assert np.count_nonzero(((zp == 0) != (truth == 1)) & ok) == 0


@pytest.mark.parametrize("method", ["zpass", "zfail"])
def test_a_silhouette_with_a_gap_streaks(method):
    light = LIGHTS["point"]
    scene = scene_with(casters("sphere"), light, outside_camera())
    tris = world_triangles(scene)
    topo = analyse_topology(tris)
    pts, nrm, _, truth, band = embree_reference(scene, light, tris)
    q = pts + 1e-4 * _towards(nrm, pts, light)
    ok = ~band
    full = shadow_volume_triangles(topo, light, caps=method == "zfail")
    # the two triangles of one silhouette edge's side quad come first in the volume list (edge order)
    sil = silhouette_edges(topo, light)
    n_sil = len(sil)
    worst = None
    for k in range(0, n_sil, max(1, n_sil // 6)):
        keep = np.ones(len(full), bool)
        keep[[k, n_sil + k]] = False  # side triangles (b, a, a∞) and (b, a∞, b∞) of edge k
        broken = stencil_counts(full[keep], scene.camera.view, scene.camera.projection, q, stencil=method)
        c_x = stencil_counts(full[~keep], scene.camera.view, scene.camera.projection, q, stencil=method)
        wrong = ((broken == 0) != (truth == 1)) & ok
        # derived: counts w − c_X with w, c_X in {0, ±1}: wrong only where the gap is counted
        assert not np.any(wrong & (c_x == 0))
        worst = max(worst or 0, int(np.count_nonzero(wrong)))
    assert worst > 0, "some gap must show as a streak"
    assert WIDTH <= 160


def _every_layer(scene, width=WIDTH, height=HEIGHT):
    """Every fragment at every pixel centre, hidden ones included (what an A-buffer shades):
    (world points, face normals, flat pixel index, nearest-at-its-pixel flag)."""
    from blinn_phong.frame.render import prepare_scene
    from blinn_phong.geometry.raster import interpolate, rasterize, resolve_nearest

    prepared = prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, width, height)
    nearest = np.zeros(len(frags.pixel), bool)
    win = resolve_nearest(frags)
    nearest[win[win >= 0]] = True
    eye = interpolate(frags, prepared.triangles, prepared.eye_position)
    world = (np.c_[eye, np.ones(len(eye))] @ np.linalg.inv(scene.camera.view).T)[:, :3]
    return world, prepared.face_world_normal[frags.triangle], frags.pixel, nearest


@pytest.mark.parametrize("light_name", sorted(LIGHTS))
def test_zpass_without_light_caps_is_wrong_behind_a_caster(light_name):
    """Heidmann's z-pass draws the volume sides only. That counts right at the nearest surface,
    where no caster face can lie in front of the sample, but a receiver hidden behind a caster
    (a layer an A-buffer shades, or a surface seen through a transparent caster) has the
    caster's lit faces — the light cap — between it and the eye. With the cap X left out the
    count is ``w − c_X`` (module docstring), so the wrong samples are exactly those where the
    light cap's own z-pass count ``c_X`` is not 0; for a convex caster the camera ray crosses its
    surface twice, so ``c_X ∈ {−1, 0, 1}`` and it is non-zero exactly when one of the two
    crossings is a lit face and the other is not. Those samples are all hidden from the eye
    (an Embree ray from the eye to them is blocked). The camera is outside every volume and
    ``choose_stencil`` picks z-pass: with the light caps drawn it agrees with Embree."""
    from blinn_phong.shadows.raytrace import RayScene
    from blinn_phong.shadows.volume import choose_stencil

    light = LIGHTS[light_name]
    scene = scene_with(casters("sphere"), light, outside_camera())
    tris = world_triangles(scene)
    pts, nrm, pix, nearest = _every_layer(scene)
    truth = embree_visibility(light, tris, pts, nrm)
    # leave out samples next to a lit/shadowed boundary of Embree's mask, layer by layer
    band = np.zeros(len(pts), bool)
    for layer_nearest in (True, False):
        sel = nearest == layer_nearest
        order = np.flatnonzero(sel)
        img = image_of(truth[sel].astype(np.int64), pix[sel])
        band[order] = boundary_band(img, radius=1).ravel()[pix[sel]]
    ok = ~band
    q = pts + 1e-4 * _towards(nrm, pts, light)
    view, proj = scene.camera.view, scene.camera.projection
    assert choose_stencil(light, tris, view, proj, q)[0] == "zpass"
    sides = shadow_volume_triangles(tris, light, caps=False)
    with_cap = shadow_volume_triangles(tris, light, caps="light")
    # the light caps, built here: every triangle turned to face the light (the sphere's lit faces;
    # the open ground quad's triangles, each its own sliver, reversed where they face away)
    normal = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    if isinstance(light, DirectionalLight):
        facing = -(normal @ np.asarray(light.direction, float))
    else:
        facing = np.einsum("ij,ij->i", normal, np.asarray(light.position) - tris[:, 0])
    ground = np.arange(len(tris)) < 2  # scene_with puts the ground quad first
    turned = np.where((facing < 0)[:, None, None], tris[:, ::-1], tris)
    cap_tris = turned[(facing > 0) | ground]
    cap = np.concatenate([cap_tris, np.ones((len(cap_tris), 3, 1))], axis=2)

    def rows(a):
        return np.unique(a.reshape(len(a), -1), axis=0)

    assert np.array_equal(rows(with_cap), rows(np.concatenate([sides, cap])))
    assert len(with_cap) == len(sides) + len(cap)
    heidmann = stencil_counts(sides, view, proj, q, stencil="zpass")
    capped = stencil_counts(with_cap, view, proj, q, stencil="zpass")
    c_x = stencil_counts(cap, view, proj, q, stencil="zpass")
    # with the light caps z-pass is exact on every sample, hidden layers included
    assert np.count_nonzero(((capped == 0) != (truth == 1)) & ok) == 0
    assert np.count_nonzero(nearest & ~ok) < np.count_nonzero(nearest & ok)  # most samples are judged
    wrong = ((heidmann == 0) != (truth == 1)) & ok
    # derived: wrong exactly where the left-out cap counts, and c_X ∈ {−1, 0, 1} (convex caster)
    assert np.array_equal(wrong, (c_x != 0) & ok)
    assert set(np.unique(c_x)) <= {-1, 0, 1}
    # at the nearest surface Heidmann's omission is harmless: no caster face is in front
    assert not np.any(wrong & nearest)
    # every wrong sample is hidden from the eye by a caster (Embree, eye → sample)
    eye = np.linalg.inv(view)[:3, 3]
    to = q[wrong] - eye
    dist = np.linalg.norm(to, axis=1)
    hidden = RayScene(tris).occluded(np.broadcast_to(eye, to.shape), to / dist[:, None], dist * (1 - 1e-6))
    assert np.all(hidden)
    # measured: a real share of the hidden samples behind the sphere is wrong
    behind = ~nearest & ok
    assert np.count_nonzero(wrong) > 0.05 * np.count_nonzero(behind), (
        f"{np.count_nonzero(wrong)} wrong of {np.count_nonzero(behind)} hidden samples"
    )
