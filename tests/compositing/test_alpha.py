"""premultiply / unpremultiply against OpenImageIO's ImageBufAlgo.premult, unpremult and
repremult (an independent implementation) and against the closed forms."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio  # noqa: N813
import pytest
from compositing_testdata import premultiplied_pixels

from compositing import premultiply, unpremultiply


def _oiio(fn, pixels: np.ndarray) -> np.ndarray:
    img = pixels.reshape(1, -1, 4).astype(np.float32)
    buf = oiio.ImageBuf(img)
    spec = buf.specmod()
    spec.alpha_channel = 3
    out = fn(buf)
    assert not out.has_error, out.geterror()
    return np.asarray(out.get_pixels(oiio.FLOAT)).reshape(-1, 4)


def _straight(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = rng.random((n, 4)).astype(np.float32)
    x[::5, 3] = 0.0
    x[1::5, 3] = 1.0
    x[2::5, :3] *= 6.0  # HDR
    return x


def test_premultiply_matches_oiio_premult_and_closed_form():
    x = _straight(200, 1)
    got = premultiply(x)
    np.testing.assert_array_equal(got, _oiio(oiio.ImageBufAlgo.premult, x))
    np.testing.assert_array_equal(got[:, :3], x[:, :3] * x[:, 3:])
    np.testing.assert_array_equal(got[:, 3], x[:, 3])


def test_keep_zero_alpha_matches_oiio_repremult():
    x = _straight(200, 2)
    np.testing.assert_array_equal(premultiply(x, keep_zero_alpha=True), _oiio(oiio.ImageBufAlgo.repremult, x))


def test_unpremultiply_keep_matches_oiio_unpremult():
    x = premultiplied_pixels(300, 3)  # includes glow (rgb > 0, α = 0) and HDR
    want = _oiio(oiio.ImageBufAlgo.unpremult, x)
    np.testing.assert_allclose(unpremultiply(x, "keep"), want, rtol=1.2e-7, atol=0)
    zero = x[:, 3] == 0
    np.testing.assert_array_equal(unpremultiply(x, "keep")[zero], x[zero])  # untouched, like OIIO


def test_unpremultiply_zero_policy_as_skia():
    x = premultiplied_pixels(120, 4)
    got = unpremultiply(x, "zero")
    zero = x[:, 3] == 0
    np.testing.assert_array_equal(got[zero], np.zeros((zero.sum(), 4)))  # Skia: scale = 0 when 1/a is inf
    np.testing.assert_allclose(got[~zero, :3], x[~zero, :3] / x[~zero, 3:], rtol=1.2e-7)


def test_glow_survives_a_round_trip_only_when_asked():
    glow = np.array([[0.8, 0.4, 0.1, 0.0], [0.2, 0.2, 0.2, 0.5]], np.float32)
    straight = unpremultiply(glow, "keep")
    np.testing.assert_array_equal(premultiply(straight, keep_zero_alpha=True)[0], glow[0])
    np.testing.assert_array_equal(premultiply(straight)[0], [0, 0, 0, 0])  # plain premultiply drops it


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_dtype_and_shape_are_kept(dtype):
    x = premultiplied_pixels(24, 5, dtype).reshape(2, 3, 4, 4)
    for out in (premultiply(x), unpremultiply(x), unpremultiply(x, "zero")):
        assert out.dtype == dtype and out.shape == x.shape and not np.shares_memory(out, x)
