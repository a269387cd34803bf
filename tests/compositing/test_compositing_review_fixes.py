"""Regression tests for review findings in the compositing package (documented behaviour, closed forms)."""

from __future__ import annotations

import numpy as np
import pytest

from compositing import composite
from compositing.gl_blend import gl_blend, gl_factors


@pytest.mark.parametrize(
    ("name", "factors"),
    [
        # Porter & Duff 1984 table 1 on premultiplied colours: over = (1, 1 − αA), in = (αB, 0)
        ("src-over", ("ONE", "ONE_MINUS_SRC_ALPHA")),
        (" Dst-In ", ("ZERO", "SRC_ALPHA")),
        ("SRC_ATOP", ("DST_ALPHA", "ONE_MINUS_SRC_ALPHA")),
    ],
)
def test_gl_factors_reads_operator_names_as_composite_does(name, factors):
    assert gl_factors(name) == factors
    src = np.array([[0.2, 0.1, 0.0, 0.4]])
    dst = np.array([[0.3, 0.6, 0.9, 0.75]])
    np.testing.assert_allclose(gl_blend(src, dst, *gl_factors(name)), composite(src, dst, name), atol=1e-15)


def test_gl_factors_suggests_the_closest_name():
    with pytest.raises(ValueError, match=r"^op: unknown operator 'src_ovr'\. Did you mean 'src_over'\?"):
        gl_factors("src_ovr")


def test_numba_engine_names_the_failing_condition_for_single_colours():
    red = np.array([1.0, 0.0, 0.0, 1.0])
    with pytest.raises(
        ValueError, match=r"needs images \(at least one pixel axis before RGBA\), got shape \(4,\)"
    ):
        composite(red, red, "src_over", engine="numba")


def test_numba_engine_names_each_other_condition():
    a = np.zeros((2, 3, 4))
    with pytest.raises(ValueError, match=r"same shape, got \(2, 3, 4\) and \(3, 4\)"):
        composite(a, a[0], "src_over", engine="numba")
    with pytest.raises(ValueError, match=r"scalar factor, got a factor array of shape \(2, 3\)"):
        composite(a, a, "src_over", factor=np.ones((2, 3)), engine="numba")
    with pytest.raises(ValueError, match=r"C-contiguous arrays, dst is not"):
        composite(a, np.zeros((3, 2, 4)).transpose(1, 0, 2), "src_over", engine="numba")
