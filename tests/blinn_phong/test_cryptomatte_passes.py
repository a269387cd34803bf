"""Cryptomatte passes of ``render()`` against coverage recounted from the sample grid.

The scene is made by hand so the test knows which surface covers every sample: an orthographic
camera maps world x, y to window coordinates one to one (pixel column c spans x ∈ [c, c + 1],
row r spans y ∈ [H − r − 1, H − r]); two quads meet along a slanted edge whose vertices are
multiples of 1/64 (exact under the rasterizer's 8 sub-pixel bits) and which passes through no
sample centre ``((i + 0.5)/k, (j + 0.5)/k)`` of the k×k grid. Each pixel's coverage of each
object is then a count of sample centres on either side of the edge, divided by k².
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.frame import pipeline
from compositing.cryptomatte import matte, name_hash, name_id, pass_names

W, H = 6, 4
X0 = 83 / 64  # the edge runs from (X0, 0) to (X0 + 2, H)


def _edge_x(y: np.ndarray) -> np.ndarray:
    return X0 + 2.0 * y / H


def _quad(corners: list[tuple[float, float]], z: float, material: bp.Material) -> bp.Mesh:
    pos = np.array([(x, y, z) for x, y in corners])
    return bp.Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]]), material=material)


def _scene(front: bp.Material | None = None) -> bp.Scene:
    left = _quad([(0, 0), (X0, 0), (X0 + 2, H), (0, H)], -0.5, bp.Material(diffuse=(1, 0, 0)))
    right = _quad([(X0, 0), (W - 0.5, 0), (W - 0.5, H), (X0 + 2, H)], -0.5, bp.Material(diffuse=(0, 1, 0)))
    meshes = [left, right]
    if front is not None:  # a transparent square over columns 1–2, rows 1–2, nearer the camera
        meshes.append(_quad([(1, 1), (3, 1), (3, 3), (1, 3)], -0.25, front))
    return bp.Scene(meshes, [bp.AmbientLight()], bp.Camera.orthographic(0, W, 0, H, 0.1, 2.0))


def _expected(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the fraction of sample centres left of the edge (object "Left") and right of it
    but left of x = W − 0.5 (object "Right")."""
    left = np.zeros((H, W))
    right = np.zeros((H, W))
    offsets = (np.arange(k) + 0.5) / k
    for r in range(H):
        for c in range(W):
            for sy in offsets:
                y = H - r - sy
                for sx in offsets:
                    x = c + sx
                    if x < _edge_x(y):
                        left[r, c] += 1
                    elif x < W - 0.5:
                        right[r, c] += 1
    return left / k**2, right / k**2


NAMES = {"object": ["Left", "Right"], "material": ["Red", "Green"], "asset": ["Set", "Set"]}


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("k", [1, 4])
def test_coverage_is_the_sample_count(engine: str, k: int) -> None:
    result = bp.render(
        _scene(), W, H, samples=k * k, engine=engine, shadows="none", cryptomatte=bp.Cryptomatte(NAMES)
    )
    left, right = _expected(k)
    assert {*pass_names("object"), *pass_names("material"), *pass_names("asset")} <= set(result.passes)
    objects = [result.passes[n] for n in pass_names("object")]
    np.testing.assert_array_equal(matte(objects, [name_id("Left")]), left.astype(np.float32))
    np.testing.assert_array_equal(matte(objects, [name_id("Right")]), right.astype(np.float32))
    materials = [result.passes[n] for n in pass_names("material")]
    np.testing.assert_array_equal(matte(materials, [name_id("Red")]), left.astype(np.float32))
    # one asset name for both meshes: one entry per pixel holding both coverages
    assets = [result.passes[n] for n in pass_names("asset")]
    np.testing.assert_array_equal(matte(assets, [name_id("Set")]), (left + right).astype(np.float32))
    assert not assets[0][..., 2:].any() and not assets[1].any()
    # rank 0 is the larger coverage; the coverages sum to the frame's alpha
    first = objects[0]
    assert np.all(first[..., 1] >= first[..., 3])
    np.testing.assert_array_equal(first[..., 1] + first[..., 3], result.rgba[..., 3])


@pytest.mark.parametrize("method", ["a_buffer", "zbuffer"])
def test_transparent_surfaces_share_the_sample_and_sum_to_alpha(method: str) -> None:
    glass = bp.Material(diffuse=(0, 0, 1), opacity=0.25)
    k = 2
    result = bp.render(
        _scene(glass), W, H, samples=k * k, engine="numpy", shadows="none", transparency=method,
        cryptomatte=bp.Cryptomatte({"object": ["Left", "Right", "Glass"]}, levels=4),
    )  # fmt: skip
    objects = [result.passes[n] for n in pass_names("object", 4)]
    left, _ = _expected(k)
    inside = np.zeros((H, W), bool)
    inside[1:3, 1:3] = True  # the glass covers these pixels whole
    glass_cover = matte(objects, [name_id("Glass")])
    if method == "a_buffer":  # over: the glass takes 0.25 of each sample, what is behind the rest
        np.testing.assert_allclose(glass_cover, np.where(inside, 0.25, 0.0), rtol=0, atol=1e-7)
        np.testing.assert_allclose(
            matte(objects, [name_id("Left")]), np.where(inside, 0.75, 1.0) * left, rtol=0, atol=1e-7
        )
    else:  # the plain z-buffer: the nearest fragment only, weighing its opacity (the frame's alpha)
        np.testing.assert_allclose(glass_cover, np.where(inside, 0.25, 0.0), rtol=0, atol=1e-7)
        np.testing.assert_allclose(
            matte(objects, [name_id("Left")]), np.where(inside, 0.0, left), rtol=0, atol=1e-7
        )
    total = sum(p[..., 1] + p[..., 3] for p in objects)
    np.testing.assert_allclose(total, result.rgba[..., 3], rtol=0, atol=1e-6)


def test_strips_give_the_frame_in_one_piece(monkeypatch: pytest.MonkeyPatch) -> None:
    request = bp.Cryptomatte(NAMES, levels=3)
    whole = bp.render(_scene(), W, H, samples=4, engine="numpy", shadows="none", cryptomatte=request)
    monkeypatch.setattr(pipeline, "STRIP_SAMPLES", 2 * W * 4)  # strips of two rows
    strips = bp.render(_scene(), W, H, samples=4, engine="numpy", shadows="none", cryptomatte=request)
    for name in request.pass_names():
        np.testing.assert_array_equal(strips.passes[name], whole.passes[name])


def test_without_a_request_nothing_is_added() -> None:
    result = bp.render(_scene(), W, H, engine="numpy", shadows="none")
    assert not any(name.startswith("Crypto") for name in result.passes)
    assert "cryptomatte" not in result.stats.seconds


def test_empty_meshes_keep_names_aligned() -> None:
    empty = bp.Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    scene = _scene()
    scene = bp.Scene([scene.meshes[0], empty, scene.meshes[1]], scene.lights, scene.camera)
    result = bp.render(
        scene,
        W,
        H,
        engine="numpy",
        shadows="none",
        cryptomatte=bp.Cryptomatte({"object": ["Left", "E", "Right"]}),
    )
    objects = [result.passes[n] for n in pass_names("object")]
    np.testing.assert_array_equal(matte(objects, [name_id("Right")]), _expected(1)[1].astype(np.float32))


def test_request_checks() -> None:
    with pytest.raises(ValueError, match="one name per mesh"):
        bp.render(_scene(), W, H, engine="numpy", cryptomatte=bp.Cryptomatte({"object": ["Left"]}))
    with pytest.raises(ValueError, match="layer type"):
        bp.Cryptomatte({"objects": ["a"]})
    with pytest.raises(ValueError, match="levels"):
        bp.Cryptomatte({"object": ["a"]}, levels=17)
    with pytest.raises(ValueError, match="one name per mesh"):
        bp.Cryptomatte({"object": ["a"], "material": ["b", "c"]})
    meta = bp.Cryptomatte(NAMES).metadata("ViewLayer")
    assert meta["cryptomatte/542cafa/name"] == "ViewLayer.CryptoObject"
    assert meta["cryptomatte/aa21542/manifest"] == f'{{"Set":"{name_hash("Set"):08x}"}}'
