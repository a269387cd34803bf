"""Order-independent transparency on synthetic fragments, against closed-form over stacks."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from blinn_phong.effects.oit import (
    depth_complexity,
    depth_test,
    object_draw_order,
    resolve_a_buffer,
    resolve_depth_peeling,
    resolve_in_draw_order,
    resolve_weighted_blended,
    transparency_pass,
    triangle_draw_order,
    wboit_weights,
)
from blinn_phong.geometry.raster import Fragments

N_PIX = 64
BG = np.array([0.2, 0.3, 0.4, 1.0])
# straight colours, alphas, depths of three full-screen quads
COLOURS = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
ALPHAS = np.array([0.5, 0.25, 0.8])
DEPTHS = np.array([0.3, 0.6, 0.9])


def premul(c, a):
    return np.concatenate([np.asarray(c) * a, [a]])


def analytic_stack(colours, alphas, background):
    """Front-to-back closed form: C = Σ αᵢ cᵢ Π_{j<i}(1 − αⱼ) + T·bg, A = 1 − Π(1 − αᵢ) + T·bg.a."""
    out = np.zeros(4)
    t = 1.0
    for c, a in zip(colours, alphas, strict=True):
        out += t * premul(c, a)
        t *= 1.0 - a
    return out + t * background


def quad_fragments(order, dtype=np.float64):
    """Fragments of the three quads on every pixel, submitted in ``order``."""
    pix, depth, rgba, quad = [], [], [], []
    for q in order:
        pix.append(np.arange(N_PIX))
        depth.append(np.full(N_PIX, DEPTHS[q]))
        rgba.append(np.tile(premul(COLOURS[q], ALPHAS[q]), (N_PIX, 1)))
        quad.append(np.full(N_PIX, q))
    return (
        np.concatenate(pix),
        np.concatenate(depth),
        np.concatenate(rgba).astype(dtype),
        np.concatenate(quad),
    )


@pytest.mark.parametrize("order", list(itertools.permutations(range(3))))
def test_a_buffer_equals_the_analytic_stack_in_any_submission_order(order):
    pix, depth, rgba, _ = quad_fragments(order)
    out = resolve_a_buffer(pix, depth, rgba, N_PIX, BG)
    expected = analytic_stack(COLOURS, ALPHAS, BG)
    np.testing.assert_allclose(out, np.tile(expected, (N_PIX, 1)), atol=1e-14)


def test_a_buffer_keeps_float32():
    pix, depth, rgba, _ = quad_fragments((2, 0, 1), np.float32)
    out = resolve_a_buffer(pix, depth, rgba, N_PIX, BG.astype(np.float32))
    assert out.dtype == np.float32
    np.testing.assert_allclose(out[0], analytic_stack(COLOURS, ALPHAS, BG), atol=1e-6)


def test_empty_pixels_show_the_background():
    out = resolve_a_buffer(np.array([3]), np.array([0.5]), np.array([[0.5, 0, 0, 0.5]]), 5, BG)
    np.testing.assert_allclose(out[[0, 1, 2, 4]], np.tile(BG, (4, 1)))
    np.testing.assert_allclose(out[3], [0.5 + 0.5 * 0.2, 0.15, 0.2, 1.0])


@pytest.mark.parametrize("order", [(0, 1, 2), (2, 1, 0), (1, 2, 0)])
def test_sorting_per_object_equals_the_a_buffer_when_objects_do_not_overlap_in_depth(order):
    pix, depth, rgba, quad = quad_fragments(order)
    draw = object_draw_order(quad, np.zeros_like(quad), DEPTHS)
    sorted_img = resolve_in_draw_order(pix, draw, rgba, N_PIX, BG)
    np.testing.assert_allclose(sorted_img, resolve_a_buffer(pix, depth, rgba, N_PIX, BG), atol=1e-14)
    # drawing in submission order instead is wrong unless the submission was back to front
    unsorted = resolve_in_draw_order(pix, np.repeat(np.arange(3), N_PIX), rgba, N_PIX, BG)
    assert np.allclose(unsorted, sorted_img) == (order == (2, 1, 0))


def interpenetrating():
    """Quad A tilts through quad B: depth_A = x (0..1 across the row), depth_B = 0.5.

    Quad A is nearer left of x = 0.5, B nearer on the right."""
    x = (np.arange(N_PIX) + 0.5) / N_PIX
    a = premul([1.0, 0.0, 0.0], 0.6)
    b = premul([0.0, 0.0, 1.0], 0.5)
    pix = np.concatenate([np.arange(N_PIX), np.arange(N_PIX)])
    depth = np.concatenate([x, np.full(N_PIX, 0.5)])
    rgba = np.concatenate([np.tile(a, (N_PIX, 1)), np.tile(b, (N_PIX, 1))])
    obj = np.repeat([0, 1], N_PIX)
    a_front = analytic_stack([[1, 0, 0], [0, 0, 1]], [0.6, 0.5], BG)
    b_front = analytic_stack([[0, 0, 1], [1, 0, 0]], [0.5, 0.6], BG)
    expected = np.where((x < 0.5)[:, None], a_front, b_front)
    return pix, depth, rgba, obj, expected, x


def test_a_buffer_is_exact_for_interpenetrating_quads():
    pix, depth, rgba, _, expected, _ = interpenetrating()
    np.testing.assert_allclose(resolve_a_buffer(pix, depth, rgba, N_PIX, BG), expected, atol=1e-14)
    # and for the reversed submission
    n = len(pix)
    rev = np.r_[n // 2 : n, 0 : n // 2]
    np.testing.assert_allclose(
        resolve_a_buffer(pix[rev], depth[rev], rgba[rev], N_PIX, BG), expected, atol=1e-14
    )


def test_sorting_fails_measurably_on_interpenetrating_quads():
    pix, depth, rgba, obj, expected, x = interpenetrating()
    # object centre depths: A's centre is 0.5 - 1/(2N), nearer than B's 0.5 -> A is drawn last
    object_depth = np.array([depth[:N_PIX].mean() - 1e-3, 0.5])
    out = resolve_in_draw_order(
        pix, object_draw_order(obj, np.zeros_like(obj), object_depth), rgba, N_PIX, BG
    )
    right = x < 0.5
    np.testing.assert_allclose(out[right], expected[right], atol=1e-14)
    # on the other half A is drawn over B although B is nearer: the error is exactly the
    # difference between the two orders of the over operator
    a_front = analytic_stack([[1, 0, 0], [0, 0, 1]], [0.6, 0.5], BG)
    b_front = analytic_stack([[0, 0, 1], [1, 0, 0]], [0.5, 0.6], BG)
    err = np.abs(out[~right] - expected[~right]).max()
    assert err == pytest.approx(np.abs(a_front - b_front).max(), rel=1e-12)
    assert err > 0.1


def test_triangle_draw_order_sorts_far_to_near_with_ties_by_index():
    order = triangle_draw_order(np.array([0, 1, 2, 3, 1]), np.array([0.5, 0.9, 0.1, 0.5]))
    np.testing.assert_array_equal(order, [1, 0, 3, 2, 0])


def test_depth_peeling_with_enough_layers_is_the_a_buffer_and_fewer_lose_the_far_ones():
    pix, depth, rgba, _ = quad_fragments((1, 2, 0))
    exact = resolve_a_buffer(pix, depth, rgba, N_PIX, BG)
    for k in (3, 4, 10):
        np.testing.assert_allclose(resolve_depth_peeling(pix, depth, rgba, N_PIX, k, BG), exact, atol=1e-14)
    for k in (1, 2):
        expected = analytic_stack(COLOURS[:k], ALPHAS[:k], BG)  # only the k nearest quads
        np.testing.assert_allclose(
            resolve_depth_peeling(pix, depth, rgba, N_PIX, k, BG), np.tile(expected, (N_PIX, 1)), atol=1e-14
        )
    with pytest.raises(ValueError, match="layers"):
        resolve_depth_peeling(pix, depth, rgba, N_PIX, 0, BG)


def test_weighted_blended_with_depth_free_weights_follows_equation_6():
    pix, depth, rgba, _ = quad_fragments((0, 1, 2))
    w = wboit_weights(rgba[:, 3], "constant")
    out = resolve_weighted_blended(pix, w, rgba, N_PIX, BG)
    # McGuire & Bavoil eq. 6 with premultiplied Cᵢ = αᵢcᵢ and wᵢ = αᵢ:
    # (Σ Cᵢwᵢ / Σ αᵢwᵢ)(1 − Π(1 − αᵢ)) + bg·Π(1 − αᵢ)
    t = np.prod(1 - ALPHAS)
    w = ALPHAS
    rgb = (w[:, None] * ALPHAS[:, None] * COLOURS).sum(0) / (w * ALPHAS).sum() * (1 - t) + BG[:3] * t
    np.testing.assert_allclose(out[0], np.r_[rgb, 1.0], atol=1e-14)
    # and it is not the exact answer when the colours differ
    exact = resolve_a_buffer(pix, depth, rgba, N_PIX, BG)
    assert np.abs(out - exact).max() > 0.05


def test_weighted_blended_is_exact_for_one_layer_and_for_equal_colours():
    pix = np.arange(N_PIX)
    rgba = np.tile(premul([0.9, 0.5, 0.1], 0.7), (N_PIX, 1))
    depth = np.full(N_PIX, 0.4)
    w = wboit_weights(rgba[:, 3], "eq7", view_distance=np.full(N_PIX, 3.0))
    np.testing.assert_allclose(
        resolve_weighted_blended(pix, w, rgba, N_PIX, BG),
        resolve_a_buffer(pix, depth, rgba, N_PIX, BG),
        atol=1e-14,
    )
    # three layers of one colour with different alphas and depths
    pix3 = np.tile(pix, 3)
    alphas = np.repeat([0.3, 0.6, 0.2], N_PIX)
    rgba3 = np.concatenate(
        [np.full((3 * N_PIX, 3), [0.9, 0.5, 0.1]) * alphas[:, None], alphas[:, None]], axis=1
    )
    depth3 = np.repeat([1.0, 4.0, 9.0], N_PIX)
    w3 = wboit_weights(alphas, "eq8", view_distance=depth3)
    np.testing.assert_allclose(
        resolve_weighted_blended(pix3, w3, rgba3, N_PIX, BG),
        resolve_a_buffer(pix3, depth3, rgba3, N_PIX, BG),
        atol=1e-13,
    )


def test_wboit_weight_equations_at_a_known_distance():
    a = np.array([0.5])
    z = np.array([10.0])
    np.testing.assert_allclose(wboit_weights(a, "eq7", view_distance=z), 0.5 * 10 / (1e-5 + 4 + (0.05) ** 6))
    np.testing.assert_allclose(wboit_weights(a, "eq8", view_distance=z), 0.5 * 10 / (1e-5 + 1 + (0.05) ** 6))
    np.testing.assert_allclose(wboit_weights(a, "eq9", view_distance=z), 0.5 * 0.03 / (1e-5 + 0.05**4))
    np.testing.assert_allclose(wboit_weights(a, "eq7", view_distance=np.array([0.01])), 0.5 * 3e3)  # clamped
    np.testing.assert_allclose(wboit_weights(a, "eq10", window_depth=np.array([0.5])), 0.5 * 3e3 / 8)
    with pytest.raises(ValueError, match="view_distance"):
        wboit_weights(a, "eq7")


def test_depth_test_and_depth_complexity():
    keep = depth_test(np.array([0, 0, 1]), np.array([0.2, 0.7, 0.9]), np.array([0.5, 1.0]))
    np.testing.assert_array_equal(keep, [True, False, True])
    np.testing.assert_array_equal(depth_complexity(np.array([0, 0, 2]), 4), [2, 0, 1, 0])


def test_bad_fragments_are_rejected():
    with pytest.raises(ValueError, match="pixel indices"):
        resolve_a_buffer(np.array([5]), np.array([0.1]), np.ones((1, 4)), 5)
    with pytest.raises(ValueError, match="rgba"):
        resolve_a_buffer(np.array([0]), np.array([0.1]), np.ones((1, 3)), 5)
    with pytest.raises(ValueError, match="depth"):
        resolve_a_buffer(np.array([0]), np.array([np.nan]), np.ones((1, 4)), 5)
    with pytest.raises(TypeError, match="pixel"):
        resolve_a_buffer(np.array([0.0]), np.array([0.1]), np.ones((1, 4)), 5)


def test_a_buffer_on_rasterized_interpenetrating_quads_matches_the_plane_equations():
    from blinn_phong.model.lights import AmbientLight
    from blinn_phong.model.scene import Scene

    from .scenes import horizontal_quad, ortho_camera, quad, render_transparency

    size = 48
    red, blue = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    tilted = quad([[-1.5, -1.5, -0.8], [1.5, -1.5, 0.8], [1.5, 1.5, 0.8], [-1.5, 1.5, -0.8]], red, 0.6)
    flat = horizontal_quad(0.0, colour=blue, opacity=0.5)
    for meshes in ((tilted, flat), (flat, tilted)):
        scene = Scene(meshes, (AmbientLight((1, 1, 1), 1.0),), ortho_camera(), ambient=(0.0, 0.0, 0.0))
        img = render_transparency(scene, "a_buffer", size=size).reshape(size, size, 4)
        # pixel centres in world units (top view, x right, y up, row 0 at the top)
        x = -2 + (np.arange(size) + 0.5) * 4 / size
        inside = np.abs(x) < 1.5
        red_front = analytic_stack([red, blue], [0.6, 0.5], np.zeros(4))
        blue_front = analytic_stack([blue, red], [0.5, 0.6], np.zeros(4))
        # the tilted quad's height is 0.8·x/1.5: above the flat one (nearer the eye) for x > 0
        expected = np.where((x > 0)[:, None], red_front, blue_front)
        row = img[size // 2]
        np.testing.assert_allclose(row[inside], expected[inside], atol=1e-12)
        np.testing.assert_array_equal(row[~inside], 0.0)


def _scalar_over_stack(fragments, background):
    """Per pixel, nearest first: C = Σ cᵢ Π_{j<i}(1 − αⱼ) + T·bg (premultiplied), with Python floats."""
    out = []
    for frags, bg in zip(fragments, background, strict=True):
        acc = [0.0, 0.0, 0.0, 0.0]
        t = 1.0
        for _, rgba in sorted(frags, key=lambda f: f[0]):
            acc = [a + t * c for a, c in zip(acc, rgba, strict=True)]
            t *= 1.0 - rgba[3]
        out.append([a + t * b for a, b in zip(acc, bg, strict=True)])
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(
    data=st.lists(
        st.tuples(
            st.integers(0, 5),
            st.floats(0.0, 1.0),
            st.floats(0.0, 1.0),
            st.floats(0.0, 1.0),
            st.floats(0.0, 2.0),
        ),
        max_size=30,
    ),
    seed=st.integers(0, 2**31 - 1),
)
def test_a_buffer_equals_a_scalar_sorted_over_stack_for_random_fragments(data, seed):
    n_pix = 6
    rng = np.random.default_rng(seed)
    depths = rng.permutation(len(data)) / max(len(data), 1)  # distinct depths, random order
    pix = np.array([d[0] for d in data], dtype=np.int64)
    alpha = np.array([d[1] for d in data])
    colour = np.array([[d[2], d[3], d[4]] for d in data]).reshape(-1, 3)
    rgba = np.c_[colour * alpha[:, None], alpha] if len(data) else np.zeros((0, 4))
    bg = rng.uniform(0, 1, (n_pix, 4))
    per_pixel = [
        [(depths[i], rgba[i].tolist()) for i in range(len(data)) if pix[i] == p] for p in range(n_pix)
    ]
    expected = _scalar_over_stack(per_pixel, bg)
    np.testing.assert_allclose(resolve_a_buffer(pix, depths, rgba, n_pix, bg), expected, atol=1e-12)
    # with enough layers depth peeling is the same
    np.testing.assert_allclose(resolve_depth_peeling(pix, depths, rgba, n_pix, 30, bg), expected, atol=1e-12)


# --------------------------------------------------------------------------- the compiled resolves


def _random_sample_lists(seed: int, n_keys: int = 300, max_layers: int = 7) -> dict:
    """Per-sample lists of random premultiplied fragments, depth ties included, over random opaque ones."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, max_layers + 1, n_keys)
    offsets = np.r_[0, np.cumsum(counts)]
    n_t = int(offsets[-1])
    has_opaque = rng.random(n_keys) < 0.7
    n_o = int(has_opaque.sum())
    opaque_of = np.full(n_keys, -1)
    opaque_of[has_opaque] = np.arange(n_o)
    alpha = rng.random(n_o + n_t)
    alpha[:n_o] = 1.0
    rgba = np.c_[rng.random((n_o + n_t, 3)) * alpha[:, None], alpha]
    depth = np.round(rng.random(n_o + n_t), 1)  # coarse: many equal depths in one sample
    order = rng.permutation(n_o + n_t).astype(np.float64)
    key = np.repeat(np.arange(n_keys), counts)
    background = np.zeros((n_keys, 4))
    background[has_opaque] = rgba[:n_o]
    return {
        "n_o": n_o,
        "opaque_of": opaque_of,
        "offsets": offsets,
        "rgba": rgba,
        "alpha": alpha,
        "depth": depth,
        "order": order,
        "key": key,
        "background": background,
        "weights": wboit_weights(rgba[:, 3], "eq10", window_depth=depth),
    }


def _compiled(lists: dict, code: int, max_layers: int, sort_key: np.ndarray) -> np.ndarray:
    from blinn_phong.frame.resolve_kernels import resolve_frame_compiled

    n = len(lists["rgba"])
    zeros = np.zeros((n, 3))
    n_keys = len(lists["opaque_of"])
    out = resolve_frame_compiled(
        n_keys, 1, 1, code, max_layers, lists["n_o"], lists["opaque_of"], lists["offsets"], sort_key,
        lists["weights"], lists["rgba"], lists["alpha"], zeros, zeros, zeros, zeros, lists["depth"], None,
    )  # fmt: skip
    return out[0].reshape(n_keys, 4)


@pytest.mark.parametrize("method", ["a_buffer", "depth_peeling", "draw_order", "weighted_blended"])
@pytest.mark.parametrize("seed", [0, 1])
def test_compiled_resolves_match_the_reference(method: str, seed: int) -> None:
    # The compiled per-sample resolve against the numpy resolves above (themselves checked against
    # the closed-form over stack): same sort (ties in list order), same over, float32 output, so
    # the only differences are float64 rounding (far below 1e-6).
    pytest.importorskip("numba")
    from blinn_phong.frame.resolve_kernels import RESOLVE_CODES

    lists = _random_sample_lists(seed)
    tr = slice(lists["n_o"], None)
    args = (lists["key"], lists["depth"][tr], lists["rgba"][tr], len(lists["opaque_of"]))
    front_to_back = RESOLVE_CODES["front_to_back"]
    if method == "a_buffer":
        expected = resolve_a_buffer(*args, background=lists["background"])
        got = _compiled(lists, front_to_back, 1 << 30, lists["depth"])
    elif method == "depth_peeling":
        expected = resolve_depth_peeling(*args, layers=2, background=lists["background"])
        got = _compiled(lists, front_to_back, 2, lists["depth"])
    elif method == "draw_order":
        order = lists["order"][tr]
        expected = resolve_in_draw_order(lists["key"], order, lists["rgba"][tr], args[3], lists["background"])
        got = _compiled(lists, front_to_back, 1 << 30, -lists["order"])
    else:
        expected = resolve_weighted_blended(
            lists["key"], lists["weights"][tr], lists["rgba"][tr], args[3], lists["background"]
        )
        got = _compiled(lists, RESOLVE_CODES["weighted_blended"], 0, lists["depth"])
    assert np.diff(lists["offsets"]).max() >= 5
    np.testing.assert_allclose(got, expected.astype(np.float32), rtol=0, atol=1e-6)


# ---------------------------------------------------------- transparency_pass opaque z-buffer


def _pass_fragments(pixel, depth, triangle, width=3):
    n = len(pixel)
    return Fragments(
        width,
        1,
        1,
        np.asarray(pixel, np.int64),
        np.zeros(n, np.int64),
        np.asarray(depth, np.float64),
        np.asarray(triangle, np.int64),
        np.full((n, 3), 1 / 3),
        np.ones(n, bool),
    )


# pixel 0: opaque at 0.5 (tri 1) and 0.3 (tri 2) -> the nearer, tri 2;
# pixel 1: two opaque at the same depth 0.4 (tri 3 and tri 0) -> GL_LESS keeps the first drawn, tri 0;
#          a transparent fragment (tri 4) in front at 0.2; pixel 2: empty
PASS_FRAGMENTS = _pass_fragments([0, 0, 1, 1, 1], [0.5, 0.3, 0.4, 0.4, 0.2], [1, 2, 3, 0, 4])
PASS_OPAQUE = np.array([True, True, True, True, False])
PASS_COLOURS = np.array([[0.1, 0, 0, 1], [0.2, 0, 0, 1], [0.3, 0, 0, 1], [0.4, 0, 0, 1], [0, 0, 0.25, 0.5]])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("method", ["zbuffer", "a_buffer"])
def test_transparency_pass_keeps_the_shade_dtype_and_resolves_like_gl_less(dtype, method):
    shaded = []

    def shade(index):
        shaded.append(np.sort(index))
        return PASS_COLOURS[index].astype(dtype)

    rgba, depth = transparency_pass(
        PASS_FRAGMENTS,
        PASS_OPAQUE,
        shade,
        method,
        triangle_mesh=np.zeros(5, int),
        triangle_eye_distance=np.zeros(5),
    )
    assert rgba.dtype == dtype
    np.testing.assert_array_equal(depth, [0.3, 0.4, 1.0])
    np.testing.assert_array_equal(shaded[0], [1, 3])  # only the visible opaque fragments are shaded
    expected_pixel1 = (
        PASS_COLOURS[3] if method == "zbuffer" else PASS_COLOURS[4] + 0.5 * PASS_COLOURS[3]
    )  # over
    np.testing.assert_allclose(rgba, np.array([PASS_COLOURS[1], expected_pixel1, np.zeros(4)]), atol=1e-7)


# --------------------------------------------------------------------------- WBOIT floor on one layer


def test_wboit_one_layer_is_exact_above_the_floor_and_scaled_below_it():
    # McGuire & Bavoil 2013, eq. 10 weight α·max(1e-2, 3e3·(1 − d)³) and the listing's max(accum.a, 1e-5)
    alpha = np.array([0.01, 0.01, 0.5, 0.05, 0.9])
    depth = np.array([0.99, 0.5, 0.99, 0.9, 0.999])
    colour = 0.8
    w = wboit_weights(alpha, "eq10", window_depth=depth)
    np.testing.assert_allclose(w, alpha * np.maximum(1e-2, 3e3 * (1 - depth) ** 3), rtol=1e-15)
    rgba = np.c_[np.full((5, 3), colour) * alpha[:, None], alpha]
    out = resolve_weighted_blended(np.arange(5), w, rgba, 5)
    accum_a = w * alpha
    np.testing.assert_allclose(out[:, 3], alpha, rtol=1e-15)  # coverage always exact
    expected = colour * alpha * np.minimum(1.0, accum_a / 1e-5)
    np.testing.assert_allclose(out[:, 0], expected, rtol=1e-12)
    # the reviewer's case: α = 0.01 at depth 0.99 resolves to 0.0008 instead of 0.008
    np.testing.assert_allclose(out[0, 0], 0.0008, rtol=1e-12)
    above = accum_a >= 1e-5
    assert above.any() and (~above).any()
    np.testing.assert_allclose(out[above, 0], colour * alpha[above], rtol=1e-12)
