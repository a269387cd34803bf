"""Memory of the frame pipeline: proportional to the fragments that survive, bounded per band.

Checked by counting, never by timing:

* the visibility stage keeps exactly the fragments a brute-force depth test keeps (every
  rasterized fragment from the numpy reference rasterizer, each sample's nearest opaque depth by
  ``np.minimum.at``, the transparent ones strictly in front of it: ``GL_LESS``);
* :func:`blinn_phong.frame.visibility.rasterized_count` (compiled) counts what the numpy reference
  rasterizer produces;
* the compiled visibility stage's peak traced memory (``tracemalloc``, which sees numpy's
  allocations) is bounded by the kept fragments, the per-sample arrays and the triangle set-up,
  and does not grow with hidden layers, while the numpy reference (which builds every
  rasterized fragment) does: the bound is one the reference breaks, so the check can fail;
* an opaque frame's peak traced memory is the image buffers plus the kept fragments plus a
  per-band allowance: the shading arrays of the band loop never hold the whole frame.
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable

import numpy as np
import pytest

import blinn_phong as bp
import blinn_phong.frame.pipeline as pipeline
from blinn_phong.frame.visibility import frame_fragments, rasterized_count
from blinn_phong.geometry.raster import rasterize
from blinn_phong.model.primitives import grid_plane, uv_sphere

pytest.importorskip("numba")

W, H = 64, 48


def layers(n_front: int, n_behind: int, opaque_left_half: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Clip-space quads covering the screen: one opaque (triangles 0 and 1) at NDC depth 0, then
    ``n_front`` transparent ones in front of it and ``n_behind`` behind it (all w = 1)."""
    quads = [(0.0, 0.0 if opaque_left_half else -1.3)]  # (NDC z, left edge x)
    quads += [(-0.9 + 0.8 * i / max(1, n_front), -1.3) for i in range(n_front)]
    quads += [(0.1 + 0.8 * (i + 1) / (n_behind + 1), -1.3) for i in range(n_behind)]
    clip: list[tuple[float, ...]] = []
    tris: list[tuple[int, int, int]] = []
    for z, x0 in quads:
        v = len(clip)
        clip += [(x0, -1.3, z, 1.0), (1.3, -1.3, z, 1.0), (1.3, 1.3, z, 1.0), (x0, 1.3, z, 1.0)]
        tris += [(v, v + 1, v + 2), (v, v + 2, v + 3)]
    return np.array(clip), np.array(tris)


def first_quad_opaque(triangle: np.ndarray, front_facing: np.ndarray) -> np.ndarray:
    return triangle < 2


def traced_peak(fn: Callable[[], object]) -> tuple[object, int]:
    """``fn()`` and the peak bytes numpy and Python allocated while it ran (``tracemalloc``)."""
    tracemalloc.start()
    try:
        result = fn()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("samples", [1, 4])
def test_kept_fragments_are_those_in_front_of_the_nearest_opaque_one(samples: int) -> None:
    clip, tris = layers(3, 5, opaque_left_half=True)
    # Brute force on every rasterized fragment of the reference rasterizer.
    every = rasterize(clip, tris, W, H, samples=samples)
    key = every.sample_key
    opaque = first_quad_opaque(every.triangle, every.front_facing)
    nearest = np.ones(W * H * samples)  # the depth buffer's clear value
    np.minimum.at(nearest, key[opaque], every.depth[opaque])
    in_front = ~opaque & (every.depth < nearest[key])
    visible = frame_fragments(clip, tris, W, H, opaque=first_quad_opaque, samples=samples, engine="numba")
    assert visible.n_opaque == np.count_nonzero(nearest < 1.0) == W * H * samples // 2
    assert visible.n_transparent == np.count_nonzero(in_front)
    # Left half: the 3 layers in front; right half (no opaque surface): all 8.
    assert visible.n_transparent == (3 + 8) * W * H * samples // 2
    assert len(every) == (1 + 8) * W * H * samples - W * H * samples // 2
    counts = np.bincount(key[in_front], minlength=W * H * samples)
    np.testing.assert_array_equal(np.diff(visible.offsets), counts)


@pytest.mark.parametrize("samples", [1, 4])
def test_rasterized_count_matches_the_reference_rasterizer(samples: int) -> None:
    pos, tris, normals = uv_sphere(24, 12)
    scene = bp.Scene(
        [bp.Mesh(pos, tris, normals)],
        bp.DirectionalLight((0, 0, -1)),
        bp.Camera.perspective(50, 4 / 3, 0.5, 10, view=bp.look_at((0.3, 0.5, 2.2), (0, 0, 0))),
    )
    prepared = bp.prepare_scene(scene)
    args = (prepared.clip, prepared.triangles, W, H)
    reference = len(rasterize(*args, samples=samples))
    assert reference > 1.5 * W * H * samples * 0.25  # front and back faces: more than one per sample
    assert rasterized_count(*args, samples=samples, engine="numba") == reference
    assert rasterized_count(*args, samples=samples, engine="numpy") == reference
    culled = len(rasterize(*args, samples=samples, cull_backfaces=True))
    assert rasterized_count(*args, samples=samples, cull_backfaces=True) == culled < reference


def test_visibility_memory_follows_the_kept_fragments_not_the_rasterized_ones() -> None:
    peaks = {}
    for n_behind in (8, 64):
        clip, tris = layers(2, n_behind)
        for engine in ("numba", "numpy"):
            frame_fragments(clip, tris, W, H, opaque=first_quad_opaque, engine=engine)  # compile, warm up
            visible, peak = traced_peak(
                lambda c=clip, t=tris, e=engine: frame_fragments(
                    c, t, W, H, opaque=first_quad_opaque, engine=e
                )
            )
            peaks[n_behind, engine] = peak
        rasterized = rasterized_count(clip, tris, W, H)
        assert rasterized == (3 + n_behind) * W * H
        # The hidden layers are dropped.
        assert visible.n_opaque == W * H and visible.n_transparent == 2 * W * H
        # Kept fragments (57 bytes each) and per-sample lists, at most twice over (the compact pass
        # copies them once), 128 bytes per sample of z-buffer/winner/key scratch (16 int64/float64
        # arrays' worth), 2 KB per triangle of set-up: all independent of the hidden layers.
        bound = 2 * visible.nbytes + 128 * W * H + 2048 * len(tris)
        assert peaks[n_behind, "numba"] <= bound
        # An array of every rasterized fragment (57 bytes each) would not fit under it ...
        assert 57 * rasterized > bound or n_behind == 8
        # ... and the numpy reference, which builds one, breaks it: the bound can fail.
        assert peaks[n_behind, "numpy"] > bound or n_behind == 8
    # 8× the hidden layers: the compiled stage grows by their set-up only; the reference with them.
    assert peaks[64, "numba"] - peaks[8, "numba"] <= 2048 * 2 * (64 - 8)
    assert peaks[64, "numpy"] > 4 * peaks[8, "numpy"]


def test_an_opaque_frame_holds_one_band_of_shading_arrays(monkeypatch: pytest.MonkeyPatch) -> None:
    pos, tris, normals = uv_sphere(32, 16)
    plane, ptris, pnormals = grid_plane(1, 1, (6.0, 6.0))
    down = np.eye(4)
    down[2, 3] = -1.0
    scene = bp.Scene(
        [bp.Mesh(pos, tris, normals), bp.Mesh(plane, ptris, pnormals, transform=down)],
        [bp.DirectionalLight((0.3, 0.4, -1.0)), bp.PointLight((2.0, -2.0, 4.0))],
        bp.Camera.perspective(50, 4 / 3, 0.5, 20, view=bp.look_at((0, -4, 2.5), (0, 0, 0), (0, 0, 1))),
    )
    width, height, band = 320, 240, 512
    prepared = bp.prepare_scene(scene)
    visible = frame_fragments(prepared.clip, prepared.triangles, width, height, engine="numba")
    peaks = {}
    # Gouraud shading with the GL preset's per-vertex clamps: the staged path, shading array by
    # band (the other plain frames are fused into one pass with no per-fragment array; checked
    # below).
    options = {"shadows": "none", "shading": "gouraud", "gl_compat": True}
    for band_samples in (band, 1 << 22):  # bands of 512 samples; one band for the whole frame
        monkeypatch.setattr(pipeline, "BAND_SAMPLES", band_samples)
        bp.render(scene, width, height, **options)  # compile, warm up
        result, peaks[band_samples] = traced_peak(lambda: bp.render(scene, width, height, **options))
    image = result.rgba.nbytes + result.depth.nbytes + result.normal.nbytes  # type: ignore[attr-defined]
    image += sum(p.nbytes for p in result.passes.values())  # type: ignore[attr-defined]
    assert result.stats.shaded == len(visible.fragments) > 0.4 * width * height  # type: ignore[attr-defined]
    # The frame's buffers and kept fragments, plus: one float64 scratch value of 32 bytes per
    # sample (per-sample resolve buffers), 1000 bytes per fragment of a band (the shading arrays:
    # positions, normals, light terms, colours — about 250 bytes) and 1000 bytes per triangle
    # (scene preparation and raster set-up).
    bound = image + visible.nbytes + 32 * width * height + 1000 * band + 1000 * len(prepared.triangles)
    assert peaks[band] <= bound
    # One band for the whole frame breaks the bound (its shading arrays hold every fragment):
    # the bound can fail.
    assert peaks[1 << 22] > bound
    # The fused plain frame (per-pixel shading) holds no per-fragment array at all: the frame's
    # buffers, the per-sample z-buffer (winner and depth, 16 bytes per sample) and the set-up.
    for shading in ("phong", "gouraud"):
        fused = {"shadows": "none", "shading": shading}
        bp.render(scene, width, height, **fused)
        _, fused_peak = traced_peak(lambda f=fused: bp.render(scene, width, height, **f))
        assert fused_peak <= image + 32 * width * height + 1000 * len(prepared.triangles) < bound
