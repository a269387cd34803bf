"""Every documented input error: the exception type and a message naming the argument,
what was expected and what was received."""

from __future__ import annotations

import numpy as np
import pytest

from compositing import (
    absorption,
    composite,
    composite_stack,
    coverage_union,
    emission,
    premultiply,
    unpremultiply,
)
from compositing.validate import as_rgba

GOOD = np.full((3, 5, 4), 0.25, np.float32)


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_last_axis_not_four(engine):
    with pytest.raises(
        ValueError, match=r"src: expected RGBA in the last axis, shape \(\.\.\., 4\); got shape \(3, 5, 3\)"
    ):
        composite(GOOD[..., :3], GOOD, engine=engine)
    with pytest.raises(ValueError, match=r"dst: .*got shape \(4, 3\)"):
        composite(GOOD, GOOD.reshape(-1, 4)[:12].reshape(4, 3, 4)[..., 0].reshape(4, 3), engine=engine)


def test_shapes_that_do_not_broadcast():
    with pytest.raises(ValueError, match=r"shapes do not broadcast: src \(3, 5, 4\), dst \(2, 5, 4\)"):
        composite(GOOD, GOOD[:2])


@pytest.mark.parametrize("dtype", [np.uint8, np.int32, np.uint16, bool, np.float16, np.complex64])
def test_non_float_arrays_are_rejected(dtype):
    with pytest.raises(
        TypeError, match=rf"src: expected a float32 or float64 array .* got dtype {np.dtype(dtype)}"
    ):
        composite(GOOD.astype(dtype), GOOD)
    with pytest.raises(TypeError, match=rf"dst: .*got dtype {np.dtype(dtype)}"):
        composite(GOOD, GOOD.astype(dtype))


def test_integer_message_says_what_to_do():
    with pytest.raises(TypeError, match="integer and boolean arrays are rejected: decode 8/16-bit pixels"):
        as_rgba(np.zeros((2, 4), np.uint8), "src")


def test_nan_and_inf_are_counted():
    bad = GOOD.copy()
    bad[0, 0, 0] = np.nan
    bad[1, 2, 1] = np.nan
    bad[2, 4, 2] = -np.inf
    with pytest.raises(
        ValueError, match=r"dst: expected finite values; got 3 non-finite of 60 \(2 NaN, 1 Inf\)"
    ):
        composite(GOOD, bad, engine="numpy")
    with pytest.raises(ValueError, match=r"rgba: expected finite values; got 3 non-finite"):
        unpremultiply(bad)


def test_alpha_outside_unit_interval_is_reported_not_clamped():
    bad = GOOD.copy()
    bad[0, 0, 3] = 1.5
    bad[0, 1, 3] = -0.25
    msg = (
        r"src: expected alpha \(last channel\) in \[0, 1\]; "
        r"got 2 of 15 pixels outside, alpha range \[-0.25, 1.5\]"
    )
    with pytest.raises(ValueError, match=msg):
        composite(bad, GOOD)
    with pytest.raises(ValueError, match=r"rgba: expected alpha"):
        premultiply(bad)
    with pytest.raises(ValueError, match=r"layers\[1\]: expected alpha"):
        composite_stack([GOOD, bad])


@pytest.mark.parametrize("factor", [-0.1, 1.5, float("nan")])
def test_factor_outside_unit_interval(factor):
    with pytest.raises(ValueError, match=r"factor: expected a number in \[0, 1\], got"):
        composite(GOOD, GOOD, factor=factor)


def test_factor_array_checks():
    with pytest.raises(
        ValueError, match=r"factor: expected a shape that broadcasts to the pixel shape \(3, 5\)"
    ):
        composite(GOOD, GOOD, factor=np.ones((4,), np.float32))
    with pytest.raises(TypeError, match="factor: expected a float32 or float64 array, got dtype int64"):
        composite(GOOD, GOOD, factor=np.ones((3, 5), np.int64))
    with pytest.raises(ValueError, match=r"factor: expected values in \[0, 1\]; got range \[0, 2\]"):
        composite(GOOD, GOOD, factor=np.linspace(0, 2, 15).reshape(3, 5))


def test_unknown_operator_lists_valid_ones_and_closest_match():
    with pytest.raises(
        ValueError,
        match=r"op: unknown operator 'scr_atop'\. Did you mean 'src_atop'\? Valid operators: clear, src",
    ):
        composite(GOOD, GOOD, "scr_atop")
    with pytest.raises(TypeError, match="op: expected an operator name"):
        composite(GOOD, GOOD, 3)


def test_unknown_engine_and_policy():
    with pytest.raises(ValueError, match=r"engine: expected one of"):
        composite(GOOD, GOOD, engine="cuda")
    with pytest.raises(
        ValueError, match=r"zero_alpha: expected one of \('keep', 'zero', 'raise'\), got 'nan'"
    ):
        unpremultiply(GOOD, "nan")


def test_unpremultiply_raise_policy_and_overflow():
    x = GOOD.copy()
    x[1, 1, 3] = 0.0
    with pytest.raises(
        ValueError, match=r"rgba: expected alpha > 0 everywhere \(zero_alpha='raise'\); got 1 pixels"
    ):
        unpremultiply(x, "raise")
    tiny = np.array([[3e38, 0.0, 0.0, 1e-30]], np.float32)  # 3e38 / 1e-30 overflows float32
    with pytest.raises(ValueError, match=r"rgba: unpremultiplying overflows float32 in 1 pixels"):
        unpremultiply(tiny)


def test_other_functions_check_their_arguments():
    with pytest.raises(ValueError, match=r"transmittance: expected values in \[0, 1\]"):
        absorption((1.2, 0.5, 0.5), GOOD)
    with pytest.raises(
        ValueError, match=r"emitted: expected RGB in the last axis, shape \(\.\.\., 3\); got shape \(4,\)"
    ):
        emission((1, 1, 1, 1), GOOD)
    with pytest.raises(ValueError, match=r"a2: expected coverage in \[0, 1\]"):
        coverage_union(0.5, 1.5)
    with pytest.raises(TypeError, match="layers: expected a non-empty sequence"):
        composite_stack(np.stack([GOOD, GOOD]))
    with pytest.raises(ValueError, match="order: expected one of"):
        composite_stack([GOOD], order="sideways")


def test_nothing_writes_nan_at_zero_alpha():
    x = np.zeros((4, 4), np.float32)  # all alpha 0: every division guard is exercised
    x[:, 0] = 0.5  # glow in red
    for op in ("disjoint_over", "conjoint_over", "conjoint_xor", "disjoint_src_atop"):
        assert np.isfinite(composite(x, x, op)).all()
    assert np.isfinite(unpremultiply(x)).all()


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_overflow_is_reported_not_written(engine):
    big = np.zeros((300, 300, 4), np.float32)
    big[..., 0] = 3e38  # finite, but 3e38 + 3e38 is not
    with pytest.raises(ValueError, match=r"the result overflowed float32 in 90000 values"):
        composite(big, big, "plus", engine=engine)


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
