"""Layer stacks, the three transparency models and coverage union, against closed forms,
OpenGL blend states (``gl_blend``, itself checked against Mesa) and a Monte-Carlo count."""

from __future__ import annotations

import numpy as np
import pytest
from compositing_testdata import premultiplied_pixels

from compositing import (
    absorption,
    composite_stack,
    composite_stack_front_to_back,
    coverage_union,
    emission,
    partial_occlusion,
)


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
