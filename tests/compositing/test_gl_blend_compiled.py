"""The compiled blend stage (``engine="numba"``) against the numpy reference and the 8-bit model.

The compiled kernels are generated from the same expression table as the numpy reference, but
they are a separate evaluation (scalar code compiled by LLVM, integer arithmetic for RGBA8), so
these tests compare the two over every factor/equation state on small images. Both evaluate
element-wise in a fixed order without fast-math, so the float results are expected to be
identical; the check allows the 1 ulp the blend stage's contract states. RGBA8 results are
integer codes and must agree exactly. The integer RGBA8 model of ``test_gl_blend.py`` (typed
from the spec there) is the independent source for ``uint8`` input and output.
"""

import itertools

import numpy as np
import pytest

from compositing import _gl_fused
from compositing.gl_blend import gl_blend
from tests.compositing.test_gl_blend import code_blend
from tests.gl_spec import EQUATION_NAMES, FACTOR_NAMES

STATES = list(itertools.product(FACTOR_NAMES, FACTOR_NAMES, EQUATION_NAMES))


def colours(rng, n, dtype):
    """Values in [−0.25, 1.5] with alpha 0 and 1 and exact 0/1 components included."""
    x = rng.uniform(-0.25, 1.5, (n, 4))
    x[rng.random((n, 4)) < 0.2] = 0.0
    x[rng.random((n, 4)) < 0.2] = 1.0
    return x.astype(dtype)


def blend(src, dst, rgb, alpha, constant, target, engine):
    return gl_blend(
        src,
        dst,
        *rgb,
        src_factor_alpha=alpha[0],
        dst_factor_alpha=alpha[1],
        equation_alpha=alpha[2],
        constant=constant,
        target=target,
        engine=engine,
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    ("dtype", "target"),
    [(np.float32, "float32"), (np.float32, "unorm8"), (np.uint8, "unorm8")],
)
def test_every_state_agrees_with_the_numpy_reference(dtype, target):
    """All 1125 RGB states, each with another state on alpha (so every state also runs on alpha)."""
    rng = np.random.default_rng(7)
    order = rng.permutation(len(STATES))
    constant = (0.3, 1.25, -0.2, 0.6)
    if dtype == np.uint8:
        src, dst = (rng.integers(0, 256, (24, 4)).astype(np.uint8) for _ in range(2))
        src[:3], dst[3:6] = 0, 255
    else:
        src, dst = colours(rng, 24, dtype), colours(rng, 24, dtype)
    for k, rgb in enumerate(STATES):
        alpha = STATES[order[k]]
        want = blend(src, dst, rgb, alpha, constant, target, "numpy")
        got = blend(src, dst, rgb, alpha, constant, target, "numba")
        assert got.dtype == want.dtype
        if got.dtype == np.uint8 or target == "unorm8":
            np.testing.assert_array_equal(got, want, err_msg=f"{rgb} {alpha}")
        else:
            np.testing.assert_array_max_ulp(got, want, maxulp=1)


SPECIALISED = [
    (("ONE", "ONE_MINUS_SRC_ALPHA", "FUNC_ADD"),) * 2,
    (("SRC_ALPHA", "ONE_MINUS_SRC_ALPHA", "FUNC_ADD"), ("ONE", "ONE_MINUS_SRC_ALPHA", "MAX")),
    (("CONSTANT_COLOR", "ONE_MINUS_CONSTANT_ALPHA", "FUNC_REVERSE_SUBTRACT"),) * 2,
    (("SRC_ALPHA_SATURATE", "DST_COLOR", "FUNC_SUBTRACT"), ("ZERO", "SRC_ALPHA_SATURATE", "MIN")),
]


@pytest.mark.parametrize(("rgb", "alpha"), SPECIALISED)
@pytest.mark.parametrize("kind", ["float32", "float64", "unorm8 float", "unorm8 uint8"])
def test_large_images_use_a_kernel_per_state_with_the_same_values(rgb, alpha, kind):
    rng = np.random.default_rng(3)
    shape = (_gl_fused.SPECIALISE_MIN_PIXELS // 256 + 1, 256)  # enough pixels for the specialised kernel
    if kind == "unorm8 uint8":
        src, dst = (rng.integers(0, 256, (*shape, 4)).astype(np.uint8) for _ in range(2))
    else:
        dtype = np.float64 if kind == "float64" else np.float32
        src, dst = (colours(rng, shape[0] * shape[1], dtype).reshape(*shape, 4) for _ in range(2))
    target = "unorm8" if kind.startswith("unorm8") else "float32"
    want = blend(src, dst, rgb, alpha, (0.25, 0.5, 0.75, 0.5), target, "numpy")
    got = blend(src, dst, rgb, alpha, (0.25, 0.5, 0.75, 0.5), target, "numba")
    if target == "float32":
        np.testing.assert_array_max_ulp(got, want, maxulp=1)
    else:
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("equation", EQUATION_NAMES)
def test_uint8_in_and_out_follows_the_integer_model(equation):
    rng = np.random.default_rng(5)
    src, dst = (rng.integers(0, 256, (30, 4)).astype(np.uint8) for _ in range(2))
    src[:4, 3], dst[4:8, 3] = 0, 255
    constant = np.array([0.9, -0.3, 1.7, 0.35])
    c8 = np.rint(np.clip(constant, 0, 1) * 255).astype(np.int64)
    for sf, df in itertools.product(FACTOR_NAMES, FACTOR_NAMES):
        got = gl_blend(src, dst, sf, df, equation, constant=constant, target="unorm8")
        assert got.dtype == np.uint8
        pairs = zip(src.astype(np.int64), dst.astype(np.int64), strict=True)
        want = [code_blend(s, d, sf, df, equation, c8) for s, d in pairs]
        np.testing.assert_array_equal(got, want, err_msg=f"{sf}, {df}, {equation}")


def test_the_8_bit_rounding_is_round_to_nearest_for_every_numerator():
    """round(N/255) by multiply and shift, checked for every N in [0, 255²] (and clamping outside)."""
    n = np.arange(-300, 255 * 255 + 300, dtype=np.int64)
    got = eval(_gl_fused._round_codes("n"), {"np": np, "min": np.minimum, "max": np.maximum, "n": n})
    clamped = np.clip(n, 0, 255 * 255)
    np.testing.assert_array_equal(got, (2 * clamped + 255) // 510)


def test_uint8_mixed_with_float_reads_codes_as_k_over_255():
    rng = np.random.default_rng(9)
    codes = rng.integers(0, 256, (16, 4)).astype(np.uint8)
    other = colours(rng, 16, np.float32)
    mixed = gl_blend(codes, other, "SRC_ALPHA", "ONE_MINUS_SRC_ALPHA", target="unorm8")
    assert mixed.dtype == np.float32
    as_float = codes.astype(np.float32) / np.float32(255)
    np.testing.assert_array_equal(
        mixed, gl_blend(as_float, other, "SRC_ALPHA", "ONE_MINUS_SRC_ALPHA", target="unorm8")
    )


def test_uint8_needs_the_unorm8_target():
    with pytest.raises(TypeError, match=r"src: uint8 arrays are RGBA8 codes and need target='unorm8'"):
        gl_blend(np.zeros((2, 4), np.uint8), np.zeros((2, 4), np.float32), "ONE", "ZERO")
    with pytest.raises(ValueError, match=r"dst: expected RGBA in the last axis.*\(2, 3\)"):
        gl_blend(np.zeros((2, 4), np.uint8), np.zeros((2, 3), np.uint8), "ONE", "ZERO", target="unorm8")
    with pytest.raises(ValueError, match="engine: expected one of"):
        gl_blend(np.zeros(4), np.zeros(4), "ONE", "ZERO", engine="gpu")


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_non_finite_input_and_overflow_are_named_on_both_engines(engine):
    src = np.zeros((70000, 4), np.float32)
    src[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"src.*1 non-finite"):
        gl_blend(src, np.zeros_like(src), "ONE", "ONE", engine=engine)
    big = np.full((8, 4), 3e38, np.float32)
    with pytest.raises(ValueError, match="overflowed float32"):
        gl_blend(big, big, "ONE", "ONE", engine=engine)
