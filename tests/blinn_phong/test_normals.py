"""blinn_phong.geometry.normals.normalize: dtypes, lengths whose square under- or overflows, zero vectors."""

from __future__ import annotations

import numpy as np
import pytest

from blinn_phong.geometry.normals import normalize


def test_normalize_integer_vectors_gives_float64():
    out = normalize(np.array([[3, 4, 0], [0, 0, -2]]))
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, [[0.6, 0.8, 0.0], [0.0, 0.0, -1.0]], atol=1e-16)


@pytest.mark.parametrize(
    ("vector", "dtype", "expected"),
    [
        ([1e-200, 0, 0], np.float64, [1, 0, 0]),  # |v|² underflows to 0
        ([1e200, 1e200, 0], np.float64, [2**-0.5, 2**-0.5, 0]),  # |v|² overflows to inf
        ([0, -3e-160, 4e-160], np.float64, [0, -0.6, 0.8]),
        ([1e-23, 0, 0], np.float32, [1, 0, 0]),
        ([3e19, 0, 0], np.float32, [1, 0, 0]),
        ([0, 3e20, -4e20], np.float32, [0, 0.6, -0.8]),
    ],
)
def test_normalize_lengths_whose_square_under_or_overflows(vector, dtype, expected):
    out = normalize(np.array(vector, dtype=dtype))
    assert out.dtype == dtype
    np.testing.assert_allclose(out, expected, rtol=4 * np.finfo(dtype).eps, atol=0)


def test_normalize_keeps_zero_vectors_zero():
    np.testing.assert_array_equal(normalize(np.zeros((2, 3), np.float32)), np.zeros((2, 3), np.float32))
