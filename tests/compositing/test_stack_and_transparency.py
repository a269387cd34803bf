"""Layer stacks, the three transparency models and coverage union, against closed forms,
OpenGL blend states (``gl_blend``, itself checked against Mesa) and a Monte-Carlo count."""

from __future__ import annotations

import numpy as np
import pytest
from compositing_testdata import premultiplied_pixels

from compositing import (
    absorption,
    composite,
    composite_stack,
    composite_stack_front_to_back,
    coverage_union,
    emission,
    partial_occlusion,
)
from compositing._stack_fused import TILE


def _layers(n: int, seed: int, shape=(9, 11)) -> list[np.ndarray]:
    size = shape[0] * shape[1]
    return [premultiplied_pixels(size, seed + i, np.float64).reshape(*shape, 4) for i in range(n)]


def _painter(layers):
    """Back to front with the closed form of over written out: acc = L + acc·(1 − αL)."""
    acc = layers[0]
    for layer in layers[1:]:
        acc = layer + acc * (1 - layer[..., 3:])
    return acc


def test_both_orders_give_the_painters_result():
    layers = _layers(6, 10)
    want = _painter(layers)
    np.testing.assert_allclose(composite_stack(layers, "back_to_front"), want, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(composite_stack(layers, "front_to_back"), want, rtol=1e-13, atol=1e-13)


def test_front_to_back_stops_once_opaque():
    layers = _layers(8, 20)
    layers[5][..., :3] = 0.3  # an opaque layer in the middle: nothing behind it shows
    layers[5][..., 3] = 1.0
    image, used = composite_stack_front_to_back(layers)
    assert used == 3  # layers 7, 6, 5
    np.testing.assert_allclose(image, _painter(layers[5:]), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(image, _painter(layers), rtol=1e-13, atol=1e-13)
    layers[3] = np.full_like(layers[3], np.nan)  # never read
    assert composite_stack_front_to_back(layers)[1] == 3


def test_front_to_back_threshold_bounds_the_error():
    layers = _layers(5, 30)
    for layer in layers:
        layer[..., 3] = np.maximum(layer[..., 3], 0.9)
        layer[..., :3] = np.minimum(layer[..., :3], layer[..., 3:])
    exact = _painter(layers)
    image, used = composite_stack_front_to_back(layers, opaque_threshold=0.99)
    assert used < len(layers)
    assert np.abs(image - exact).max() <= 0.01 + 1e-12  # what is behind weighs at most 1 − 0.99


def test_single_layer_and_broadcast_colour():
    layers = _layers(2, 40)
    backdrop = np.array([0.5, 0.5, 0.5, 1.0])
    got = composite_stack([backdrop, *layers])
    np.testing.assert_allclose(
        got, _painter([np.broadcast_to(backdrop, layers[0].shape), *layers]), atol=1e-13
    )
    np.testing.assert_array_equal(composite_stack(layers[:1]), layers[0])


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("order", ["back_to_front", "front_to_back"])
def test_an_opaque_broadcast_front_layer_gives_the_full_image(engine, order):
    # Porter & Duff: an opaque A over anything is A (Fb = 1 − αA = 0), at every pixel of the
    # broadcast shape, even when the front layer is a single colour that stops front to back.
    back = _layers(1, 41)[0]
    front = np.array([[[0.2, 0.3, 0.4, 1.0]]])
    got = composite_stack([back, front], order, engine=engine)
    np.testing.assert_array_equal(got, np.broadcast_to(front, back.shape))


@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
def test_an_empty_image_gives_an_empty_stack_on_both_engines(dtype):
    layers = [np.zeros((0, 5, 4), dtype) for _ in range(3)]
    for engine in ("numpy", "numba"):
        image, used = composite_stack_front_to_back(layers, engine=engine)
        assert image.shape == (0, 5, 4) and image.dtype == dtype
        assert used == (1 if dtype == np.float32 else 3), engine  # nothing to stop on: the front layer
        assert composite_stack(layers, engine=engine).shape == (0, 5, 4)


def test_emission_adds_light_without_coverage():
    b = premultiplied_pixels(50, 50)
    e = np.random.default_rng(1).random((50, 3)).astype(np.float32) * 3
    got = emission(e, b)
    np.testing.assert_array_equal(got[:, :3], b[:, :3] + e)
    np.testing.assert_array_equal(got[:, 3], b[:, 3])


def test_partial_occlusion_is_alpha_blending():
    s, b = premultiplied_pixels(50, 60), premultiplied_pixels(50, 61)
    np.testing.assert_allclose(partial_occlusion(s, b), s + b * (1 - s[:, 3:]), rtol=1e-6, atol=1e-7)


def test_absorption_filters_the_background():
    b = premultiplied_pixels(50, 70)
    t = np.random.default_rng(2).random((50, 3)).astype(np.float32)
    got = absorption(t, b)
    np.testing.assert_array_equal(got[:, :3], b[:, :3] * t)
    np.testing.assert_array_equal(got[:, 3], b[:, 3])
    np.testing.assert_array_equal(absorption((1.0, 1.0, 1.0), b), b)  # a clear filter changes nothing


def test_models_are_the_opengl_blend_states():
    gl = pytest.importorskip("compositing.gl_blend")
    b = premultiplied_pixels(64, 80)
    rng = np.random.default_rng(3)
    e = rng.random((64, 3)).astype(np.float32)
    t = rng.random((64, 3)).astype(np.float32)
    s = premultiplied_pixels(64, 81)
    zero_alpha = np.zeros((64, 1), np.float32)
    np.testing.assert_allclose(
        emission(e, b), gl.gl_blend(np.concatenate([e, zero_alpha], 1), b, "ONE", "ONE"), rtol=1e-7
    )
    np.testing.assert_allclose(
        partial_occlusion(s, b), gl.gl_blend(s, b, "ONE", "ONE_MINUS_SRC_ALPHA"), rtol=1e-6, atol=1e-7
    )
    np.testing.assert_allclose(
        absorption(t, b),
        gl.gl_blend(np.concatenate([t, zero_alpha + 1], 1), b, "ZERO", "SRC_COLOR"),
        rtol=1e-7,
    )


def test_coverage_union_closed_form_and_monte_carlo():
    a1 = np.array([0.0, 0.25, 0.5, 1.0, 0.3])
    a2 = np.array([0.0, 0.5, 0.5, 0.2, 0.9])
    np.testing.assert_allclose(coverage_union(a1, a2), 1 - (1 - a1) * (1 - a2), atol=1e-15)
    np.testing.assert_allclose(coverage_union(a1, a2), coverage_union(a2, a1), atol=0)
    # Two shapes placed independently: a random sub-sample point hits either with that probability.
    rng = np.random.default_rng(4)
    n = 200_000
    for p, q in zip(a1, a2, strict=True):
        hit = (rng.random(n) < p) | (rng.random(n) < q)
        assert abs(hit.mean() - coverage_union(p, q)) < 4 * np.sqrt(0.25 / n)


# --- The compiled stack (one pass per tile) and 8-bit straight-alpha stacks.


@pytest.mark.parametrize("n", [2, 7, 8])  # odd and even counts: layers go through the tile two at a time
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_compiled_stack_equals_the_layer_by_layer_loop(n, dtype):
    # 150 × 131 pixels: several tiles, the last one partial. Both evaluate element-wise, in the
    # same order, without fast-math, so the values are identical (deterministic by construction).
    layers = _layers(n, 50, shape=(150, 131))
    layers = [layer.astype(dtype) for layer in layers]
    want = layers[0]
    for layer in layers[1:]:
        want = composite(layer, want, "src_over", engine="numpy")
    got = composite_stack(layers, engine="numba")
    assert got.dtype == dtype
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got, composite_stack(layers, engine="numpy"))
    np.testing.assert_allclose(got, _painter(layers), rtol=1e-6 if dtype == np.float32 else 1e-13, atol=1e-6)


def test_compiled_front_to_back_stops_per_tile():
    # Four tiles of TILE pixels, 64 pixels a row. The front layer is opaque on the top half:
    # those two tiles read one layer, the others all of them.
    rows = TILE // 64
    layers = _layers(6, 60, shape=(4 * rows, 64))
    layers[5][: 2 * rows, :, 3] = 1.0
    layers[5][: 2 * rows, :, :3] = 0.25
    exact = _painter(layers)
    image, used = composite_stack_front_to_back(layers, engine="numba")
    assert used == 6
    np.testing.assert_allclose(image, exact, rtol=1e-13, atol=1e-13)
    np.testing.assert_array_equal(image[: 2 * rows], layers[5][: 2 * rows])
    layers[2][: 2 * rows] = np.nan  # behind the opaque tiles: never read
    image, _ = composite_stack_front_to_back(layers, engine="numba")
    np.testing.assert_allclose(image, exact, rtol=1e-13, atol=1e-13)
    layers[2][3 * rows, 3] = np.nan  # in a tile that reads every layer
    with pytest.raises(ValueError, match=r"layers\[2\]: expected finite values"):
        composite_stack_front_to_back(layers, engine="numba")


def test_compiled_stack_names_the_bad_layer():
    layers = _layers(4, 70)
    layers[2] = layers[2].copy()
    layers[2][0, 0, 3] = 1.5
    with pytest.raises(ValueError, match=r"layers\[2\]: expected alpha \(last channel\) in \[0, 1\]"):
        composite_stack(layers, engine="numba")
    with pytest.raises(ValueError, match=r"layers\[2\]: expected alpha"):
        composite_stack(layers, engine="numpy")


def test_layers_of_different_shapes_are_named():
    layers = [np.zeros((8, 8, 4)), np.zeros((8, 8, 4)), np.zeros((4, 4, 4))]
    for engine in ("numpy", "numba"):
        with pytest.raises(
            ValueError, match=r"layers\[2\]: shape \(4, 4, 4\) does not broadcast.*\(8, 8, 4\)"
        ):
            composite_stack(layers, engine=engine)
    with pytest.raises(TypeError, match=r"layers\[1\]: expected dtype uint8 like layers\[0\]"):
        composite_stack([np.zeros((2, 2, 4), np.uint8), np.zeros((2, 2, 4))])


def _straight8(n, seed, shape=(37, 45)):
    rng = np.random.default_rng(seed)
    layers = [rng.integers(0, 256, (*shape, 4)).astype(np.uint8) for _ in range(n)]
    for layer in layers:  # exact 0 and 255 alphas occur
        layer[rng.random(shape) < 0.15, 3] = 0
        layer[rng.random(shape) < 0.15, 3] = 255
    return layers


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_straight_8_bit_stack_agrees_with_pillow(engine):
    """Pillow's ``alpha_composite`` chain stores each step in 8 bits too; its fixed-point
    arithmetic rounds differently, by at most one step (AlphaComposite.c)."""
    image_module = pytest.importorskip("PIL.Image")
    layers = _straight8(9, 80)
    got = composite_stack(layers, engine=engine)
    assert got.dtype == np.uint8
    acc = image_module.fromarray(layers[0], "RGBA")
    for layer in layers[1:]:
        acc = image_module.alpha_composite(acc, image_module.fromarray(layer, "RGBA"))
    pillow = np.asarray(acc).astype(np.int64)
    visible = pillow[..., 3] > 0  # Pillow zeroes the colour where alpha is 0
    diff = np.abs(got.astype(np.int64) - pillow)
    assert diff[visible].max() <= 1
    assert np.mean(diff[visible] > 0) < 0.01
    np.testing.assert_array_equal(got[..., 3], pillow[..., 3])


def test_straight_8_bit_stack_closed_form_and_identities():
    layers = _straight8(2, 90)
    got = composite_stack(layers).astype(np.float64)
    # Two layers: the straight-alpha over (Porter & Duff 1984 on premultiplied values, then divided).
    back, front = (layer.astype(np.float64) / 255 for layer in layers)
    a = front[..., 3:] + back[..., 3:] * (1 - front[..., 3:])
    rgb = front[..., :3] * front[..., 3:] + back[..., :3] * back[..., 3:] * (1 - front[..., 3:])
    rgb = np.where(a > 0, rgb / np.where(a > 0, a, 1), rgb)
    want = np.rint(np.concatenate([rgb, a], axis=-1) * 255)
    assert np.abs(got - want).max() <= 1  # float32 arithmetic next to a rounding boundary
    assert np.mean(got != want) < 0.001
    # An opaque layer hides everything behind it; a fully transparent one changes nothing.
    layers = _straight8(5, 91)
    layers[3][..., 3] = 255
    np.testing.assert_array_equal(composite_stack(layers[:4]), layers[3])
    layers[4][..., 3] = 0
    np.testing.assert_array_equal(composite_stack(layers), layers[3])


def test_straight_8_bit_stack_has_one_order():
    layers = _straight8(6, 1)
    want = composite_stack(layers, engine="numpy")
    np.testing.assert_array_equal(composite_stack(layers, "front_to_back"), want)
    image, used = composite_stack_front_to_back(layers)
    np.testing.assert_array_equal(image, want)
    assert used == 6


@pytest.mark.parametrize("kind", ["float32", "uint8"])
def test_back_to_front_starts_at_the_frontmost_opaque_layer_of_each_tile(kind):
    # Four tiles; layer 4 is opaque on the top half only. Behind it, those tiles read nothing:
    # a NaN there is never seen, and the image is what the full loop gives.
    rows = TILE // 64
    if kind == "uint8":
        layers = _straight8(6, 2, shape=(4 * rows, 64))
        layers[4][: 2 * rows, :, 3] = 255
    else:
        layers = [layer.astype(np.float32) for layer in _layers(6, 3, shape=(4 * rows, 64))]
        layers[4][: 2 * rows, :, 3] = 1.0
    want = composite_stack(layers, engine="numpy")
    got = composite_stack(layers, engine="numba")
    np.testing.assert_array_equal(got, want)
    if kind == "float32":
        layers[1][: 2 * rows] = np.nan
        np.testing.assert_array_equal(composite_stack(layers, engine="numba"), want)
        layers[1][3 * rows, 5, 0] = np.nan  # in a tile with no opaque layer: read, and reported
        with pytest.raises(ValueError, match=r"layers\[1\]: expected finite values"):
            composite_stack(layers, engine="numba")
