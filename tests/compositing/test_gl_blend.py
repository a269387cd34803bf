"""``gl_blend`` and ``gl_factors`` against closed forms written out here.

The factor and equation formulas below are typed from the OpenGL 4.6 core specification,
§17.3.6, tables 17.1 and 17.2, and the Porter-Duff closed forms from Porter & Duff (1984),
table 1; none of them is imported from the code under test. The comparison with a real
OpenGL implementation (Mesa) is in ``test_gl_blend_mesa.py``.
"""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from compositing import composite
from compositing.factors import ALL_OPERATORS, PORTER_DUFF
from compositing.gl_blend import GL_BLEND_EQUATIONS, GL_BLEND_FACTORS, gl_blend, gl_factors
from tests.gl_spec import EQUATION_NAMES, FACTOR_NAMES


def spec_factor(name, s, d, c):
    """Table 17.2, one pixel at a time: the (R, G, B, A) factor for source s, destination d, constant c."""
    one = np.ones(4)
    return {
        "ZERO": 0 * one,
        "ONE": one,
        "SRC_COLOR": s,
        "ONE_MINUS_SRC_COLOR": one - s,
        "DST_COLOR": d,
        "ONE_MINUS_DST_COLOR": one - d,
        "SRC_ALPHA": s[3] * one,
        "ONE_MINUS_SRC_ALPHA": (1 - s[3]) * one,
        "DST_ALPHA": d[3] * one,
        "ONE_MINUS_DST_ALPHA": (1 - d[3]) * one,
        "CONSTANT_COLOR": c,
        "ONE_MINUS_CONSTANT_COLOR": one - c,
        "CONSTANT_ALPHA": c[3] * one,
        "ONE_MINUS_CONSTANT_ALPHA": (1 - c[3]) * one,
        "SRC_ALPHA_SATURATE": np.array([*[min(s[3], 1 - d[3])] * 3, 1.0]),
    }[name]


def spec_equation(name, s, d, sf, df):
    """Table 17.1 on one component."""
    return {
        "FUNC_ADD": s * sf + d * df,
        "FUNC_SUBTRACT": s * sf - d * df,
        "FUNC_REVERSE_SUBTRACT": d * df - s * sf,
        "MIN": min(s, d),
        "MAX": max(s, d),
    }[name]


def spec_blend(s, d, sf, df, eq, sfa, dfa, eqa, c):
    """The blend of one pixel, component by component, in float64."""
    rgb_s, rgb_d = spec_factor(sf, s, d, c), spec_factor(df, s, d, c)
    a_s, a_d = spec_factor(sfa, s, d, c), spec_factor(dfa, s, d, c)
    out = [spec_equation(eq, s[i], d[i], rgb_s[i], rgb_d[i]) for i in range(3)]
    out.append(spec_equation(eqa, s[3], d[3], a_s[3], a_d[3]))
    return np.array(out)


RNG = np.random.default_rng(20260521)
# HDR and negative colours, alpha 0 and 1, and glow pixels (rgb > 0, alpha 0): a float buffer holds them all.
SRC = RNG.uniform(-0.25, 1.5, (24, 4))
DST = RNG.uniform(-0.25, 1.5, (24, 4))
SRC[:4, 3], DST[4:8, 3] = 0.0, 1.0
SRC[8:10] = [0.7, 0.4, 0.2, 0.0]
CONSTANT = (0.3, 1.25, -0.2, 0.6)


def test_worked_example_from_the_course_notes():
    # Fragment (0, 0, 1, 0.25) onto (0, 1, 0, 0.75) with (ONE_MINUS_SRC_COLOR, SRC_ALPHA):
    # (0, 0, 1, 0.25)·(1, 1, 0, 0.75) + (0, 1, 0, 0.75)·0.25 = (0, 0.25, 0, 0.375).
    for dtype in (np.float32, np.float64):
        out = gl_blend(
            np.array([0, 0, 1, 0.25], dtype),
            np.array([0, 1, 0, 0.75], dtype),
            "ONE_MINUS_SRC_COLOR",
            "SRC_ALPHA",
        )
        assert out.dtype == dtype
        np.testing.assert_array_equal(out, [0, 0.25, 0, 0.375])


def test_tables_list_the_gl_names():
    assert tuple(GL_BLEND_FACTORS) == FACTOR_NAMES
    assert tuple(GL_BLEND_EQUATIONS) == EQUATION_NAMES


@pytest.mark.parametrize("equation", EQUATION_NAMES)
def test_every_factor_pair_matches_the_spec_tables(equation):
    for sf, df in itertools.product(FACTOR_NAMES, FACTOR_NAMES):
        got = gl_blend(SRC, DST, sf, df, equation, constant=CONSTANT)
        want = np.array(
            [
                spec_blend(s, d, sf, df, equation, sf, df, equation, np.array(CONSTANT))
                for s, d in zip(SRC, DST, strict=True)
            ]
        )
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-15, err_msg=f"{sf}, {df}, {equation}")


def test_separate_alpha_state_follows_the_spec():
    rng = np.random.default_rng(7)
    for _ in range(300):
        sf, df, sfa, dfa = rng.choice(FACTOR_NAMES, 4)
        eq, eqa = rng.choice(EQUATION_NAMES, 2)
        got = gl_blend(
            SRC,
            DST,
            sf,
            df,
            eq,
            src_factor_alpha=sfa,
            dst_factor_alpha=dfa,
            equation_alpha=eqa,
            constant=CONSTANT,
        )
        want = np.array(
            [
                spec_blend(s, d, sf, df, eq, sfa, dfa, eqa, np.array(CONSTANT))
                for s, d in zip(SRC, DST, strict=True)
            ]
        )
        np.testing.assert_allclose(
            got, want, rtol=0, atol=1e-15, err_msg=f"{sf} {df} {eq} / {sfa} {dfa} {eqa}"
        )


def test_float_target_clamps_nothing():
    src = np.array([2.0, -0.5, 0.25, 1.5])
    dst = np.array([3.0, 0.5, -1.0, 1.5])
    np.testing.assert_array_equal(gl_blend(src, dst, "ONE", "ONE"), [5.0, 0.0, -0.75, 3.0])
    # SRC_ALPHA_SATURATE's min(As, 1 − Ad) = min(1.5, −0.5): negative when Ad > 1.
    np.testing.assert_array_equal(gl_blend(src, dst, "SRC_ALPHA_SATURATE", "ZERO"), [-1.0, 0.25, -0.125, 1.5])
    np.testing.assert_array_equal(
        gl_blend(src, dst, "CONSTANT_COLOR", "ZERO", constant=(2, -1, 0, 3)), [4.0, 0.5, 0.0, 4.5]
    )


@settings(max_examples=60, deadline=None)
@given(
    sf=st.sampled_from(FACTOR_NAMES),
    df=st.sampled_from(FACTOR_NAMES),
    seed=st.integers(0, 2**32 - 1),
)
def test_subtract_is_minus_reverse_subtract_and_min_max_ignore_factors(sf, df, seed):
    rng = np.random.default_rng(seed)
    src, dst = rng.uniform(-1, 2, (2, 16, 4)).astype(np.float32)
    c = tuple(rng.uniform(-1, 2, 4))
    sub = gl_blend(src, dst, sf, df, "FUNC_SUBTRACT", constant=c)
    rsub = gl_blend(src, dst, sf, df, "FUNC_REVERSE_SUBTRACT", constant=c)
    np.testing.assert_array_equal(sub, -rsub)
    np.testing.assert_array_equal(gl_blend(src, dst, sf, df, "MIN", constant=c), np.minimum(src, dst))
    np.testing.assert_array_equal(gl_blend(src, dst, sf, df, "MAX", constant=c), np.maximum(src, dst))


def test_one_zero_is_the_default_state_copy():
    np.testing.assert_array_equal(gl_blend(SRC, DST, "ONE", "ZERO"), SRC)
    np.testing.assert_array_equal(gl_blend(SRC, DST, "ZERO", "ONE"), DST)


def test_single_colour_broadcasts_against_an_image():
    image = RNG.uniform(0, 1, (3, 5, 4)).astype(np.float32)
    colour = np.array([0.2, 0.1, 0.0, 0.5], np.float32)
    out = gl_blend(colour, image, "ONE", "ONE_MINUS_SRC_ALPHA")
    assert out.shape == (3, 5, 4) and out.dtype == np.float32
    np.testing.assert_allclose(out, colour + image * 0.5, rtol=0, atol=1e-7)


# --- RGBA8 target: the model "clamp, quantise to 8 bits, blend exactly, round to nearest",
# --- written here in integer arithmetic on the 8-bit codes.


def to_code(x):
    """float -> 8-bit code: clamp to [0, 1], round half up (no exact ties occur in these tests)."""
    return np.floor(np.clip(np.asarray(x, np.float64), 0, 1) * 255 + 0.5).astype(np.int64)


def code_factor(name, s, d, c):
    """Table 17.2 on 8-bit codes (factor value = code/255)."""
    one = np.full(4, 255)
    return {
        "ZERO": 0 * one,
        "ONE": one,
        "SRC_COLOR": s,
        "ONE_MINUS_SRC_COLOR": one - s,
        "DST_COLOR": d,
        "ONE_MINUS_DST_COLOR": one - d,
        "SRC_ALPHA": np.full(4, s[3]),
        "ONE_MINUS_SRC_ALPHA": np.full(4, 255 - s[3]),
        "DST_ALPHA": np.full(4, d[3]),
        "ONE_MINUS_DST_ALPHA": np.full(4, 255 - d[3]),
        "CONSTANT_COLOR": c,
        "ONE_MINUS_CONSTANT_COLOR": one - c,
        "CONSTANT_ALPHA": np.full(4, c[3]),
        "ONE_MINUS_CONSTANT_ALPHA": np.full(4, 255 - c[3]),
        "SRC_ALPHA_SATURATE": np.array([*[min(s[3], 255 - d[3])] * 3, 255]),
    }[name]


def code_blend(s, d, sf, df, eq, c):
    """One pixel: exact rational blend of 8-bit codes (numerators over 255²), clamped, rounded half up."""
    fs, fd = code_factor(sf, s, d, c), code_factor(df, s, d, c)
    out = []
    for i in range(4):
        if eq == "MIN":
            out.append(min(s[i], d[i]))
            continue
        if eq == "MAX":
            out.append(max(s[i], d[i]))
            continue
        a, b = s[i] * fs[i], d[i] * fd[i]  # value·255²
        num = {"FUNC_ADD": a + b, "FUNC_SUBTRACT": a - b, "FUNC_REVERSE_SUBTRACT": b - a}[eq]
        num = min(max(num, 0), 255 * 255)
        out.append((2 * num + 255) // (2 * 255))  # round(num / 255), never a tie: num/255 is not k + 1/2
    return np.array(out)


@pytest.mark.parametrize("equation", EQUATION_NAMES)
def test_unorm8_matches_integer_model(equation):
    rng = np.random.default_rng(11)
    src = rng.uniform(-0.25, 1.5, (40, 4))
    dst = rng.uniform(-0.25, 1.5, (40, 4))
    src[:5, 3], dst[5:10, 3] = 0.0, 1.0
    c = np.array([0.9, -0.3, 1.7, 0.35])
    s8, d8, c8 = to_code(src), to_code(dst), to_code(c)
    for sf, df in itertools.product(FACTOR_NAMES, FACTOR_NAMES):
        got = gl_blend(src, dst, sf, df, equation, constant=c, target="unorm8")
        want = np.array([code_blend(s, d, sf, df, equation, c8) for s, d in zip(s8, d8, strict=True)])
        np.testing.assert_array_equal(got * 255, want, err_msg=f"{sf}, {df}, {equation}")
        assert got.dtype == np.float64 and got.min() >= 0 and got.max() <= 1


def test_unorm8_worked_example():
    # Codes: src alpha 0.25 -> 64, dst alpha 0.75 -> 191 (round to nearest).
    # G = 255·64/255 = 64; A = (64·191 + 191·64)/255 = 95.87 -> 96.
    out = gl_blend((0, 0, 1, 0.25), (0, 1, 0, 0.75), "ONE_MINUS_SRC_COLOR", "SRC_ALPHA", target="UNORM8")
    np.testing.assert_array_equal(out * 255, [0, 64, 0, 96])
    assert abs(out[3] - 0.375) <= 1 / 255


# --- gl_factors: the factor pair for each Porter-Duff operator.

CLOSED_FORMS = {  # Porter & Duff 1984, table 1, premultiplied; s = src, d = dst, sa/da their alphas
    "clear": lambda s, d, sa, da: 0 * s,
    "src": lambda s, d, sa, da: s,
    "dst": lambda s, d, sa, da: d,
    "src_over": lambda s, d, sa, da: s + d * (1 - sa),
    "dst_over": lambda s, d, sa, da: s * (1 - da) + d,
    "src_in": lambda s, d, sa, da: s * da,
    "dst_in": lambda s, d, sa, da: d * sa,
    "src_out": lambda s, d, sa, da: s * (1 - da),
    "dst_out": lambda s, d, sa, da: d * (1 - sa),
    "src_atop": lambda s, d, sa, da: s * da + d * (1 - sa),
    "dst_atop": lambda s, d, sa, da: s * (1 - da) + d * sa,
    "xor": lambda s, d, sa, da: s * (1 - da) + d * (1 - sa),
    "plus": lambda s, d, sa, da: s + d,
}


def premultiplied_pairs(n=64, seed=3):
    rng = np.random.default_rng(seed)
    alpha = rng.uniform(0, 1, (2, n, 1))
    alpha[:, :4] = 0.0
    alpha[:, 4:8] = 1.0
    colour = rng.uniform(0, 1, (2, n, 3)) * alpha
    colour[0, :2] = [0.3, 0.2, 0.1]  # glow: rgb > 0 at alpha 0
    colour[1, 8:10] = [1.5, 2.0, 4.0]  # HDR
    src, dst = np.concatenate([colour, alpha], axis=-1)
    return src, dst


def test_gl_factors_covers_porter_duff_and_plus():
    assert set(CLOSED_FORMS) == {*PORTER_DUFF, "plus"}
    realisable = set()
    for name in ALL_OPERATORS:
        try:
            gl_factors(name)
        except ValueError:
            continue
        realisable.add(name)
    assert realisable == set(CLOSED_FORMS)  # exactly the 12 Porter-Duff operators and plus


@pytest.mark.parametrize("op", list(CLOSED_FORMS))
def test_gl_factors_with_func_add_equals_the_closed_form(op):
    src, dst = premultiplied_pairs()
    sf, df = gl_factors(op)
    assert sf in FACTOR_NAMES and df in FACTOR_NAMES
    got = gl_blend(src, dst, sf, df, "FUNC_ADD")
    want = CLOSED_FORMS[op](src, dst, src[..., 3:], dst[..., 3:])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
    assert gl_factors(op.upper()) == (sf, df)


def test_gl_factors_path_agrees_with_composite():
    """The issue's "both paths agree": the blend stage with gl_factors(op) and composite(op)."""
    from compositing import composite

    src, dst = (x.astype(np.float32) for x in premultiplied_pairs(256, seed=8))
    for op in CLOSED_FORMS:
        np.testing.assert_allclose(
            gl_blend(src, dst, *gl_factors(op)), composite(src, dst, op), rtol=0, atol=1e-6, err_msg=op
        )


@pytest.mark.parametrize("op", [name for name in ALL_OPERATORS if "joint" in name])
def test_gl_factors_rejects_disjoint_and_conjoint(op):
    with pytest.raises(ValueError, match=r"no OpenGL blend factor pair") as info:
        gl_factors(op)
    assert "src_over" in str(info.value)


def test_gl_factors_rejects_unknown_names():
    with pytest.raises(ValueError, match=r"unknown operator 'over'.*src_over"):
        gl_factors("over")
    with pytest.raises(TypeError, match="op: expected an operator name"):
        gl_factors(3)


# --- Names and bad input.


def test_names_are_case_insensitive_and_tolerate_the_gl_prefix():
    ref = gl_blend(SRC, DST, "SRC_ALPHA", "ONE_MINUS_SRC_ALPHA", "FUNC_REVERSE_SUBTRACT")
    for sf, df, eq in [
        ("src_alpha", "one_minus_src_alpha", "func_reverse_subtract"),
        ("GL_SRC_ALPHA", "gl_One_Minus_Src_Alpha", "GL_FUNC_REVERSE_SUBTRACT"),
    ]:
        np.testing.assert_array_equal(gl_blend(SRC, DST, sf, df, eq), ref)


@pytest.mark.parametrize(
    ("kwargs", "argument"),
    [
        ({"src_factor": "SRC_ALPHA_SATURATED"}, "src_factor"),
        ({"dst_factor": "ONE_MINUS_SOURCE_ALPHA"}, "dst_factor"),
        ({"src_factor_alpha": "SRC1_ALPHA"}, "src_factor_alpha"),
        ({"dst_factor_alpha": "HALF"}, "dst_factor_alpha"),
    ],
)
def test_unknown_factor_lists_the_valid_ones(kwargs, argument):
    args = {"src_factor": "ONE", "dst_factor": "ZERO", **kwargs}
    with pytest.raises(ValueError) as info:
        gl_blend(SRC, DST, **args)
    message = str(info.value)
    assert message.startswith(argument) and "unknown blend factor" in message
    assert all(name in message for name in FACTOR_NAMES)


@pytest.mark.parametrize("key", ["equation", "equation_alpha"])
def test_unknown_equation_lists_the_valid_ones(key):
    with pytest.raises(ValueError) as info:
        gl_blend(SRC, DST, "ONE", "ZERO", **{key: "FUNC_MULTIPLY"})
    assert str(info.value).startswith(key)
    assert all(name in str(info.value) for name in EQUATION_NAMES)


def test_bad_input_is_rejected_with_a_clear_message():
    with pytest.raises(TypeError, match=r"src.*float32 or float64.*int64"):
        gl_blend(np.zeros((2, 4), np.int64), DST[:2], "ONE", "ZERO")
    with pytest.raises(ValueError, match=r"dst.*\(\.\.\., 4\).*\(2, 3\)"):
        gl_blend(SRC[:2], np.zeros((2, 3)), "ONE", "ZERO")
    with pytest.raises(ValueError, match=r"src \(3, 4\), dst \(2, 4\)"):
        gl_blend(SRC[:3], DST[:2], "ONE", "ZERO")
    nan = SRC[:4].copy()
    nan[0, 0], nan[1, 2] = np.nan, np.inf
    with pytest.raises(ValueError, match=r"src.*2 non-finite"):
        gl_blend(nan, DST[:4], "ONE", "ZERO")
    with pytest.raises(ValueError, match=r"constant.*four numbers.*\(2, 4\)"):
        gl_blend(SRC, DST, "CONSTANT_COLOR", "ZERO", constant=np.zeros((2, 4)))
    with pytest.raises(ValueError, match=r"constant.*finite"):
        gl_blend(SRC, DST, "CONSTANT_COLOR", "ZERO", constant=(0, 0, np.nan, 1))
    with pytest.raises(ValueError, match="target must be one of float32, unorm8, got 'rgba8'"):
        gl_blend(SRC, DST, "ONE", "ZERO", target="rgba8")
    with pytest.raises(TypeError, match="src_factor must be a blend factor name"):
        gl_blend(SRC, DST, 1, "ZERO")


def test_overflow_is_an_error_not_inf():
    big = np.full((1, 4), 3e38, np.float32)
    with pytest.raises(ValueError, match=r"overflowed float32 in 4 value"):
        gl_blend(big, big, "ONE", "ONE")


@pytest.mark.parametrize("target", ["float32", "unorm8"])
def test_inputs_are_never_modified_and_the_output_is_a_new_array(target):
    rng = np.random.default_rng(13)
    src = rng.uniform(0, 1, (6, 4)).astype(np.float32)
    dst = rng.uniform(0, 1, (6, 4)).astype(np.float32)
    src_copy, dst_copy = src.copy(), dst.copy()
    for (sf, df, eq), (sfa, dfa, eqa) in itertools.product(
        itertools.product(
            ["ZERO", "ONE", "SRC_COLOR", "SRC_ALPHA_SATURATE"], ["ONE", "DST_COLOR"], EQUATION_NAMES
        ),
        [(None, None, None), ("ONE", "ZERO", "FUNC_ADD")],
    ):
        out = gl_blend(
            src,
            dst,
            sf,
            df,
            eq,
            src_factor_alpha=sfa,
            dst_factor_alpha=dfa,
            equation_alpha=eqa,
            target=target,
        )
        assert not np.shares_memory(out, src) and not np.shares_memory(out, dst)
        assert out.flags.writeable
        np.testing.assert_array_equal(src, src_copy)
        np.testing.assert_array_equal(dst, dst_copy)


def test_dtypes_are_kept():
    s32, d32 = SRC.astype(np.float32), DST.astype(np.float32)
    assert gl_blend(s32, d32, "SRC_ALPHA", "ONE_MINUS_SRC_ALPHA").dtype == np.float32
    assert gl_blend(SRC, DST, "SRC_ALPHA", "ONE_MINUS_SRC_ALPHA").dtype == np.float64
    assert gl_blend(s32, DST, "ONE", "ZERO").dtype == np.float64
    assert gl_blend(s32, d32, "ONE", "ZERO", target="unorm8").dtype == np.float32


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
