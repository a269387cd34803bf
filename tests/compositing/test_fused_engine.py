"""The fused numba engine is bitwise equal to the numpy reference engine.

Both evaluate the same factor trees with the same float operations in the same order,
so the comparison is exact (``assert_array_equal``, not a tolerance). The fused pass
also flags bad input, after which the same errors as the numpy engine are raised.
"""

from __future__ import annotations

import numpy as np
import pytest
from compositing_testdata import image_pair
from hypothesis import given, settings
from hypothesis import strategies as st

from compositing import ALL_OPERATORS, composite
from compositing.factors import FACTORS, evaluate

pytest.importorskip("numba", reason="numba is optional; the fused engine needs it")

from compositing._fused import factor_source


@pytest.mark.parametrize("name", list(FACTORS))
def test_generated_factor_code_matches_evaluate(name):
    # Every factor of the table, on every pair of a grid of alphas that hits each branch.
    import numba

    grid = np.array([0.0, 1e-7, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0 - 1e-7, 1.0], dtype=np.float32)
    sa, da = (x.ravel() for x in np.meshgrid(grid, grid))
    consts: set[float] = set()
    code = factor_source(FACTORS[name], consts)
    ns = {f"K_{repr(v).replace('.', '_').replace('-', 'm')}": np.float32(v) for v in consts}
    exec(f"def f(sa, da):\n    return {code}\n", ns)
    scalar = numba.njit(error_model="numpy")(ns["f"])
    got = np.array([scalar(s, d) for s, d in zip(sa, da, strict=True)], dtype=np.float32)
    want = np.broadcast_to(evaluate(FACTORS[name], sa, da), sa.shape)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("op", list(ALL_OPERATORS))
def test_fused_equals_numpy_bitwise_float32(op):
    a, b = image_pair((64, 67), seed=11)
    for factor in (1.0, 0.35):
        want = composite(a, b, op, factor=factor, engine="numpy")
        got = composite(a, b, op, factor=factor, engine="numba")
        assert got.dtype == np.float32 and got.shape == want.shape
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("op", ["src_over", "xor", "disjoint_over", "conjoint_over"])
def test_fused_equals_numpy_bitwise_float64(op):
    a, b = image_pair((40, 33), seed=12, dtype=np.float64)
    for factor in (1.0, 0.6):
        np.testing.assert_array_equal(
            composite(a, b, op, factor=factor, engine="numba"),
            composite(a, b, op, factor=factor, engine="numpy"),
        )


def test_auto_engine_uses_the_fused_pass_on_large_images():
    a, b = image_pair((300, 260), seed=13)  # 78 000 pixels, above the threshold: 2 ranges
    np.testing.assert_array_equal(composite(a, b), composite(a, b, engine="numpy"))
    a, b = image_pair((601, 599), seed=14)  # 11 uneven ranges shared by the threads
    for factor in (1.0, 0.5):
        np.testing.assert_array_equal(
            composite(a, b, "xor", factor=factor), composite(a, b, "xor", factor=factor, engine="numpy")
        )
    a[600, 598, 3] = 2.0  # in the last range
    with pytest.raises(ValueError, match=r"src: expected alpha \(last channel\) in \[0, 1\]; got 1 of"):
        composite(a, b)


@pytest.mark.parametrize(
    ("where", "value", "message"),
    [
        ((5, 7, 1), np.nan, r"src: expected finite values; got 1 non-finite of \d+ \(1 NaN, 0 Inf\)"),
        ((0, 0, 0), np.inf, r"src: expected finite values; got 1 non-finite of \d+ \(0 NaN, 1 Inf\)"),
        ((3, 3, 3), np.nan, r"src: expected finite values"),
        ((3, 3, 3), 1.25, r"src: expected alpha \(last channel\) in \[0, 1\]; got 1 of"),
        ((9, 2, 3), -0.5, r"src: expected alpha \(last channel\) in \[0, 1\]; got 1 of"),
    ],
)
def test_fused_engine_reports_bad_input_like_numpy(where, value, message):
    a, b = image_pair((20, 20), seed=14)
    a[where] = value
    for engine in ("numpy", "numba"):
        with pytest.raises(ValueError, match=message):
            composite(a, b, "src_over", engine=engine)
    b[where] = value
    with pytest.raises(ValueError, match=message.replace("src", "dst")):
        composite(np.full_like(a, 0.5), b, "xor", engine="numba")


def test_fused_engine_refuses_what_it_cannot_do():
    a, b = image_pair((8, 8), seed=15)
    with pytest.raises(ValueError, match="same shape"):
        composite(a[:1], b, engine="numba")
    with pytest.raises(ValueError, match="scalar factor"):
        composite(a, b, factor=np.full((8, 8), 0.5, np.float32), engine="numba")


@pytest.mark.parametrize("op", ["clear", "src", "dst", "dst_in", "src_in"])
@pytest.mark.parametrize("factor", [1.0, 0.5, 0.0])
@pytest.mark.parametrize("which", ["src", "dst"])
def test_fused_engine_sees_inputs_an_operator_ignores(op, factor, which):
    # clear reads nothing, src ignores dst, dst ignores src: bad values there are still reported.
    a, b = image_pair((30, 30), seed=16)
    for value, message in ((np.inf, "expected finite values"), (np.nan, "expected finite values")):
        x, y = a.copy(), b.copy()
        (x if which == "src" else y)[17, 3, 1] = value
        for engine in ("numpy", "numba"):
            with pytest.raises(ValueError, match=f"{which}: {message}"):
                composite(x, y, op, factor=factor, engine=engine)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    op=st.sampled_from(["src_over", "xor", "disjoint_over", "conjoint_over", "disjoint_src_atop"]),
    factor=st.one_of(st.just(1.0), st.just(0.0), st.floats(0.0, 1.0)),
    rows=st.integers(1, 40),
    dtype=st.sampled_from([np.float32, np.float64]),
)
def test_fused_equals_numpy_bitwise_on_random_inputs(seed, op, factor, rows, dtype):
    a, b = image_pair((rows, 37), seed=seed % 10_000, dtype=dtype)
    np.testing.assert_array_equal(
        composite(a, b, op, factor=factor, engine="numba"), composite(a, b, op, factor=factor, engine="numpy")
    )
