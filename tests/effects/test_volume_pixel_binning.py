"""Shadow volumes counted over a frame's pixel tiles
(:func:`blinn_phong.shadows.volume_counting.pixel_binning`).

A frame's receivers are its pixels' surface points, which the camera projects onto the pixel
centres, so a grid of pixel blocks bins them without projecting or sorting. Checked here:

* the binning is a permutation of the covered pixels, tile by tile, and each pixel's world point
  projects into its own tile (the pixel centre, ``x = 2(col + ½)/W − 1``, ``y = 1 − 2(row + ½)/H``,
  up to rounding): the tiles are tight;
* counting over these tiles gives the same visibility, receiver for receiver, as counting over
  the tiles binned from the projections (the count is exact whatever the tiles: each tile's
  bounds and depths are measured from its receivers), for a point, a spot and a directional
  light, z-pass and z-fail;
* the frame pipeline passes the binning to every shadow-volume light.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.shadows import volume as sv
from blinn_phong.shadows import volume_counting as vc
from blinn_phong.shadows import volume_mesh as vm

pytest.importorskip("numba")

from blinn_phong.frame import pipeline
from blinn_phong.geometry.raster_kernels import (
    nearest_winners_compiled,
    setup_triangles_compiled,
    winner_surfaces_compiled,
)

W, H = 150, 100


def _scene() -> bp.Scene:
    pos, tris, normals = uv_sphere(24, 12)
    meshes = []
    for x in (-0.8, 0.9):
        t = np.eye(4)
        t[:3, 3] = (x, 0.0, 0.8)
        meshes.append(bp.Mesh(pos, tris, normals, transform=t))
    plane, ptris, pnormals = grid_plane(2, 2, (8.0, 8.0))
    meshes.append(bp.Mesh(plane, ptris, pnormals))
    lights = (
        bp.PointLight((1.0, -1.5, 3.0)),
        bp.SpotLight((0.0, -3.0, 3.0), (0.0, 0.8, -0.6), 35.0, 6.0),
        bp.DirectionalLight((0.3, 0.4, -1.0)),
    )
    camera = bp.Camera.perspective(
        50.0, W / H, 0.3, 30.0, view=bp.look_at((0.5, -5.0, 2.5), (0, 0, 0.6), (0, 0, 1))
    )
    return bp.Scene(tuple(meshes), lights, camera)


def _receivers(scene: bp.Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    prepared = bp.prepare_scene(scene)
    setup = setup_triangles_compiled(prepared.clip, prepared.triangles, W, H, 1, False)
    winner = nearest_winners_compiled(setup)
    verts = pipeline._all_world_vertices(scene)
    points, normals, rank, _ = winner_surfaces_compiled(
        setup, winner, prepared.triangles, verts, prepared.triangle_mesh
    )
    return points, normals, rank


def test_pixel_tiles_hold_their_pixels_points() -> None:
    scene = _scene()
    points, _, rank = _receivers(scene)
    grid, order, cell_start = vc.pixel_binning(rank, W, H, tile=6)
    xmin, ymin, cw, ch, nx, ny = grid
    assert (nx, ny) == (25, 17)
    np.testing.assert_array_equal(np.sort(order), np.arange(len(points)))  # a permutation
    assert cell_start[0] == 0 and cell_start[-1] == len(points) and np.all(np.diff(cell_start) >= 0)
    vp = scene.camera.projection @ scene.camera.view
    clip = np.c_[points, np.ones(len(points))] @ vp.T
    x, y = clip[:, 0] / clip[:, 3], clip[:, 1] / clip[:, 3]
    tile_of = np.repeat(np.arange(nx * ny), np.diff(cell_start))  # tile of order[k]
    cx, cy = tile_of % nx, tile_of // nx
    px, py = x[order], y[order]
    eps = 1e-9
    assert np.all(px >= xmin + cx * cw - eps) and np.all(px <= xmin + (cx + 1) * cw + eps)
    assert np.all(py >= ymin + cy * ch - eps) and np.all(py <= ymin + (cy + 1) * ch + eps)
    # the pixel centres themselves
    covered = np.flatnonzero(rank >= 0)
    row, col = covered // W, covered % W
    np.testing.assert_allclose(x[rank[covered]], 2 * (col + 0.5) / W - 1, atol=1e-9)
    np.testing.assert_allclose(y[rank[covered]], 1 - 2 * (row + 0.5) / H, atol=1e-9)
    with pytest.raises(ValueError, match="rank: expected 150×100"):
        vc.pixel_binning(rank[:-1], W, H)


@pytest.mark.parametrize("light_index", [0, 1, 2])
@pytest.mark.parametrize("stencil", ["zpass", "zfail"])
def test_counting_over_pixel_tiles_equals_counting_over_sorted_tiles(light_index: int, stencil: str) -> None:
    scene = _scene()
    points, normals, rank = _receivers(scene)
    tris = pipeline._world_triangles(scene)
    light = scene.lights[light_index]
    binning = vc.pixel_binning(rank, W, H)
    vc._BINNING.clear()  # no earlier binning to reuse: sorted from the projections
    sorted_tiles = sv.shadow_volume_visibility(
        light, tris, points, normals, camera=scene.camera, stencil=stencil, engine="numba"
    )
    pixel_tiles = sv.shadow_volume_visibility(
        light, tris, points, normals, camera=scene.camera, stencil=stencil, engine="numba", binning=binning
    )
    assert 0.05 < 1 - pixel_tiles.mean() < 0.8  # shadows in view
    np.testing.assert_array_equal(pixel_tiles, sorted_tiles)


def test_the_frame_passes_its_pixel_tiles_to_every_volume(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[object] = []
    original = sv.shadow_volume_visibility
    monkeypatch.setattr(
        sv, "shadow_volume_visibility", lambda *a, **k: seen.append(k.get("binning")) or original(*a, **k)
    )
    bp.render(_scene(), W, H, shadows="shadow_volume")
    assert len(seen) == 3 and all(b is not None and len(b) == 3 for b in seen)


def test_one_thread_and_shares_on_threads_count_alike(monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled kernels are serial loops over the items they are given (bands of tile rows,
    rows, faces); a large job runs them in shares on threads, each share writing its own
    outputs. Set-up, tile depths and counting give the same counts either way (the tile rows in
    three bands, whatever the machine's threads)."""
    monkeypatch.setattr(vc, "_threads", lambda: 3)
    scene = _scene()
    points, normals, _rank = _receivers(scene)
    tris = pipeline._world_triangles(scene, pipeline._world_vertices(scene))
    vp = scene.camera.projection @ scene.camera.view
    light = scene.lights[0]
    light_vec, directional = vm._light(light)
    rec = vc._projected(points, normals, light_vec, directional, 1e-4, True, vp, True)
    volume = vm.shadow_volume_triangles(tris, light, caps=True)
    counts = {}
    for threaded in (False, True):  # the receivers' and the volume's sizes decide: force each in turn
        monkeypatch.setattr(vc, "_PARALLEL_RECEIVERS", 0 if threaded else len(points) + 1)
        monkeypatch.setattr(vc, "_PARALLEL_FACES", 0 if threaded else len(volume) + 1)
        counts[threaded] = vc._count(volume, vp, rec, zfail=True)
    assert np.any(counts[False] != 0) and np.any(counts[False] == 0)  # lit and shadowed receivers
    np.testing.assert_array_equal(counts[True], counts[False])
