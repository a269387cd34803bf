"""Algebraic identities of premultiplied compositing (hypothesis), and the course exercises.

* ``over`` is associative on premultiplied colour (Porter & Duff 1984, §4);
  ``A over B == B under A``; ``xor`` is symmetric; clear/src/dst are identities.
* Averaging two colours then compositing over a third equals compositing each then
  averaging, because premultiplied ``over`` is affine in the source (Blinn 1994);
  with straight colours it is not (a concrete counterexample below).
* Resampling straight colour and alpha separately makes coloured fringes over a
  grey or white backdrop; resampling premultiplied colour does not. The resampler
  is OpenImageIO's ``ImageBufAlgo.resize`` (an independent implementation).
"""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio  # noqa: N813
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from compositing import composite, premultiply, unpremultiply

unit = st.floats(0.0, 1.0, width=32)
hdr = st.floats(0.0, 4.0, width=32)


@st.composite
def premultiplied(draw, n=8):
    """n premultiplied pixels: straight colour (HDR allowed) times alpha (0 and 1 included)."""
    alpha = draw(arrays(np.float64, (n, 1), elements=unit))
    straight = draw(arrays(np.float64, (n, 3), elements=hdr))
    return np.concatenate([straight * alpha, alpha], axis=1)


# Per test, not a global profile: other test modules keep their own settings.
SETTINGS = settings(max_examples=60, deadline=None)


@SETTINGS
@given(premultiplied(), premultiplied(), premultiplied())
def test_over_is_associative(a, b, c):
    left = composite(composite(a, b), c)
    right = composite(a, composite(b, c))
    np.testing.assert_allclose(left, right, rtol=1e-12, atol=1e-12)


@SETTINGS
@given(premultiplied(), premultiplied())
def test_src_over_is_dst_over_swapped(a, b):
    np.testing.assert_array_equal(composite(a, b, "src_over"), composite(b, a, "dst_over"))


@SETTINGS
@given(premultiplied(), premultiplied())
def test_swapped_operators(a, b):
    for op, swapped in [
        ("src_in", "dst_in"),
        ("src_out", "dst_out"),
        ("src_atop", "dst_atop"),
        ("xor", "xor"),
    ]:
        np.testing.assert_array_equal(composite(a, b, op), composite(b, a, swapped))
    np.testing.assert_array_equal(composite(a, b, "plus"), composite(b, a, "plus"))


@SETTINGS
@given(premultiplied(), premultiplied())
def test_clear_src_dst_identities(a, b):
    np.testing.assert_array_equal(composite(a, b, "clear"), np.zeros_like(a))
    np.testing.assert_array_equal(composite(a, b, "src"), a)
    np.testing.assert_array_equal(composite(a, b, "dst"), b)


@SETTINGS
@given(premultiplied(), premultiplied())
def test_over_alpha_is_the_union_of_coverages(a, b):
    out = composite(a, b)
    sa, da = a[:, 3], b[:, 3]
    np.testing.assert_allclose(out[:, 3], 1 - (1 - sa) * (1 - da), atol=1e-15)
    # and the partition of Porter & Duff: in + out + atop regions add up.
    np.testing.assert_allclose(
        composite(a, b, "src_over"),
        composite(a, b, "src_in") + composite(a, b, "src_out") + composite(a, b, "dst_out"),
        atol=1e-14,
    )


@SETTINGS
@given(premultiplied(), premultiplied(), premultiplied(), unit)
def test_average_then_composite_equals_composite_then_average(a1, a2, c, w):
    mixed = w * a1 + (1 - w) * a2
    np.testing.assert_allclose(
        composite(mixed, c), w * composite(a1, c) + (1 - w) * composite(a2, c), rtol=1e-12, atol=1e-12
    )


def _straight_over(fg: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """``over`` on straight colours, the textbook formula.

    αo = αf + αb(1 − αf), Co = (αf Cf + αb Cb (1 − αf)) / αo.
    """
    af, ab = fg[..., 3:], bg[..., 3:]
    ao = af + ab * (1 - af)
    return np.concatenate([(af * fg[..., :3] + ab * bg[..., :3] * (1 - af)) / ao, ao], axis=-1)


def test_averaging_straight_colours_is_wrong_counterexample():
    red = np.array([1.0, 0.0, 0.0, 1.0])  # opaque red, straight
    clear_green = np.array([0.0, 1.0, 0.0, 0.0])  # fully transparent, its colour is irrelevant
    black = np.array([0.0, 0.0, 0.0, 1.0])
    # Straight: averaging first gives (0.5, 0.5, 0, 0.5), half-covered yellow: over black it
    # makes (0.25, 0.25, 0), a dark olive instead of half red: the invisible green leaks in.
    avg_first = _straight_over((red + clear_green) / 2, black)
    avg_after = (_straight_over(red, black) + _straight_over(clear_green, black)) / 2
    np.testing.assert_allclose(avg_first, [0.25, 0.25, 0.0, 1.0])
    np.testing.assert_allclose(avg_after, [0.5, 0.0, 0.0, 1.0])
    # Premultiplied: both ways give half red.
    pr, pg = premultiply(red), premultiply(clear_green)
    np.testing.assert_allclose(composite((pr + pg) / 2, black), [0.5, 0.0, 0.0, 1.0])
    np.testing.assert_allclose((composite(pr, black) + composite(pg, black)) / 2, [0.5, 0.0, 0.0, 1.0])


def _resize(img: np.ndarray, width: int, height: int) -> np.ndarray:
    buf = oiio.ImageBuf(np.ascontiguousarray(img, np.float32))
    # A triangle (bilinear) filter: no negative lobes, so alpha stays in [0, 1].
    out = oiio.ImageBufAlgo.resize(buf, filtername="triangle", roi=oiio.ROI(0, width, 0, height, 0, 1, 0, 4))
    pixels = np.asarray(out.get_pixels(oiio.FLOAT), np.float64).reshape(height, width, 4)
    # The filter weights sum to 1 in float32, so alpha may land an ulp above 1: clip that rounding.
    assert pixels[..., 3].min() > -1e-6 and pixels[..., 3].max() < 1 + 1e-6
    pixels[..., 3] = np.clip(pixels[..., 3], 0.0, 1.0)
    return pixels


def test_resampling_straight_alpha_makes_fringes_premultiplied_does_not():
    # A red sprite with a hard edge on transparent pixels whose stored straight colour is green.
    h, w = 32, 32
    yy, xx = np.mgrid[0:h, 0:w]
    inside = (xx - 15.5) ** 2 + (yy - 15.5) ** 2 < 10.0**2
    straight = np.zeros((h, w, 4))
    straight[..., 1] = 1.0  # garbage colour of the transparent pixels
    straight[inside] = [1.0, 0.0, 0.0, 1.0]
    for backdrop_grey in (0.5, 1.0):
        backdrop = np.array([backdrop_grey] * 3 + [1.0])
        results = {}
        for name in ("straight", "premultiplied"):
            img = straight if name == "straight" else premultiply(straight)
            small = _resize(img, 12, 12)
            big = _resize(small, 41, 41)  # down then up: both filters mix neighbours
            pre = premultiply(np.clip(big, 0, 1)) if name == "straight" else big
            results[name] = composite(pre, backdrop)
        # Red over grey never raises green above blue: any excess is a fringe from the garbage colour.
        for name, comp in results.items():
            fringe = np.max(comp[..., 1] - comp[..., 2])
            if name == "straight":
                assert fringe > 0.1, f"expected a visible green fringe with straight alpha, got {fringe}"
            else:
                assert fringe < 1e-5, f"premultiplied resampling must not fringe, got {fringe}"


def test_unpremultiply_then_premultiply_recovers_coloured_pixels():
    rng = np.random.default_rng(3)
    x = premultiply(rng.random((50, 4)))
    x[::7, 3] = 1.0
    np.testing.assert_allclose(premultiply(unpremultiply(x)), x, rtol=1e-14, atol=1e-15)
