"""The shared input checks of compositing.validate, used by every public function."""

from __future__ import annotations

import numpy as np
import pytest

from compositing.validate import as_rgba, broadcast_shapes, check_alpha_range, check_factor


def test_arrays_keep_their_dtype_and_identity():
    for dtype in (np.float32, np.float64):
        x = np.zeros((2, 3, 4), dtype)
        assert as_rgba(x, "x") is x


def test_sequences_become_float32_colours():
    c = as_rgba((0, 0, 1, 0.5), "colour")
    assert c.dtype == np.float32 and c.shape == (4,)
    np.testing.assert_array_equal(c, [0, 0, 1, 0.5])
    with pytest.raises(
        ValueError, match=r"img: expected an image of shape \(\.\.\., 4\) with at least 2 axes"
    ):
        as_rgba((0, 0, 1, 0.5), "img", allow_scalar_colour=False)
    with pytest.raises(TypeError, match="colour: expected numbers"):
        as_rgba(("r", "g", "b", "a"), "colour")
    with pytest.raises(TypeError, match=r"x: expected a numpy float array .* got str"):
        as_rgba("red", "x")


def test_value_checks_can_be_deferred():
    x = np.full((2, 4), np.nan, np.float32)
    assert as_rgba(x, "x", check_values=False) is x
    with pytest.raises(
        ValueError, match=r"x: expected finite values; got 8 non-finite of 8 \(8 NaN, 0 Inf\)"
    ):
        as_rgba(x, "x")


def test_alpha_range_bounds_are_inclusive():
    x = np.array([[0, 0, 0, 0.0], [1, 1, 1, 1.0], [5, 5, 5, 1.0]], np.float32)  # HDR colour is fine
    check_alpha_range(x, "x")
    x[0, 3] = np.nextafter(np.float32(0), np.float32(-1))
    with pytest.raises(ValueError, match=r"x: expected alpha .* got 1 of 3 pixels outside"):
        check_alpha_range(x, "x")


def test_broadcast_shapes_names_every_argument():
    a, b, c = np.zeros((5, 1, 4)), np.zeros((3, 4)), np.zeros((2, 3, 4))
    assert broadcast_shapes(a=a, b=b) == (5, 3, 4)
    with pytest.raises(
        ValueError, match=r"shapes do not broadcast: a \(5, 1, 4\), b \(3, 4\), c \(2, 3, 4\)"
    ):
        broadcast_shapes(a=a, b=b, c=c)


def test_check_factor_accepts_numbers_and_pixel_arrays():
    assert check_factor(1, "f", (2, 3)) == 1.0 and isinstance(check_factor(1, "f", (2, 3)), float)
    assert check_factor(np.float32(0.5), "f", (2, 3)) == 0.5
    f = np.full((2, 1), 0.25, np.float32)
    assert check_factor(f, "f", (2, 3)) is f
    with pytest.raises(TypeError, match="f: expected a number or a float array in"):
        check_factor(True, "f", (2, 3))
    with pytest.raises(TypeError, match="f: expected a number or a float array in"):
        check_factor("0.5", "f", (2, 3))
