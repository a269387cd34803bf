"""``composite`` against closed forms written out from their sources.

* The 12 Porter-Duff operators and plus: the premultiplied results of Porter & Duff
  (1984), table 1 (also W3C Compositing Level 1 §9.1), e.g. A over B = A + B(1 − αA).
* disjoint/conjoint over: Blender 5.0 ``node_composite_alpha_over.cc``, branch by branch.
* the rest of the disjoint/conjoint family: pixman ``pixman-combine-float.c``'s factors
  (clamped to [0, 1], documented defaults at a zero denominator), result unclamped.
* the mix factor: ``interpolate(bg, m, Factor) = bg·(1 − f) + m·f`` (Blender, Nuke ``mix``).

Data include α = 0, α = 1, glow pixels (rgb > 0 at α = 0) and HDR colour above 1.
"""

from __future__ import annotations

import numpy as np
import pytest
from compositing_testdata import image_pair

from compositing import ALL_OPERATORS, OPERATORS, composite

# Premultiplied results, Porter & Duff table 1; a, b are the two images, sa/da their alphas.
PAPER = {
    "clear": lambda a, b, sa, da: 0 * a,
    "src": lambda a, b, sa, da: a,
    "dst": lambda a, b, sa, da: b,
    "src_over": lambda a, b, sa, da: a + b * (1 - sa),
    "dst_over": lambda a, b, sa, da: a * (1 - da) + b,
    "src_in": lambda a, b, sa, da: a * da,
    "dst_in": lambda a, b, sa, da: b * sa,
    "src_out": lambda a, b, sa, da: a * (1 - da),
    "dst_out": lambda a, b, sa, da: b * (1 - sa),
    "src_atop": lambda a, b, sa, da: a * da + b * (1 - sa),
    "dst_atop": lambda a, b, sa, da: a * (1 - da) + b * sa,
    "xor": lambda a, b, sa, da: a * (1 - da) + b * (1 - sa),
    "plus": lambda a, b, sa, da: a + b,
}


def _pixman_factor(name: str, sa: float, da: float) -> float:
    """pixman-combine-float.c, ``get_factor``: every factor clamped to [0, 1], defaults at 0."""

    def clamp(x: float) -> float:
        return min(1.0, max(0.0, x))

    table = {
        "ZERO": lambda: 0.0,
        "ONE": lambda: 1.0,
        "SA_OVER_DA": lambda: 1.0 if da == 0 else clamp(sa / da),
        "DA_OVER_SA": lambda: 1.0 if sa == 0 else clamp(da / sa),
        "INV_SA_OVER_DA": lambda: 1.0 if da == 0 else clamp((1 - sa) / da),
        "INV_DA_OVER_SA": lambda: 1.0 if sa == 0 else clamp((1 - da) / sa),
        "ONE_MINUS_SA_OVER_DA": lambda: 0.0 if da == 0 else clamp(1 - sa / da),
        "ONE_MINUS_DA_OVER_SA": lambda: 0.0 if sa == 0 else clamp(1 - da / sa),
        "ONE_MINUS_INV_DA_OVER_SA": lambda: 0.0 if sa == 0 else clamp(1 - (1 - da) / sa),
        "ONE_MINUS_INV_SA_OVER_DA": lambda: 0.0 if da == 0 else clamp(1 - (1 - sa) / da),
    }
    return table[name]()


# pixman-combine-float.c, the PD_COMBINE lines of the disjoint and conjoint families: (Fa, Fb).
PIXMAN = {
    "disjoint_dst_over": ("INV_DA_OVER_SA", "ONE"),
    "disjoint_src_in": ("ONE_MINUS_INV_DA_OVER_SA", "ZERO"),
    "disjoint_dst_in": ("ZERO", "ONE_MINUS_INV_SA_OVER_DA"),
    "disjoint_src_out": ("INV_DA_OVER_SA", "ZERO"),
    "disjoint_dst_out": ("ZERO", "INV_SA_OVER_DA"),
    "disjoint_src_atop": ("ONE_MINUS_INV_DA_OVER_SA", "INV_SA_OVER_DA"),
    "disjoint_dst_atop": ("INV_DA_OVER_SA", "ONE_MINUS_INV_SA_OVER_DA"),
    "disjoint_xor": ("INV_DA_OVER_SA", "INV_SA_OVER_DA"),
    "conjoint_dst_over": ("ONE_MINUS_DA_OVER_SA", "ONE"),
    "conjoint_src_in": ("DA_OVER_SA", "ZERO"),
    "conjoint_dst_in": ("ZERO", "SA_OVER_DA"),
    "conjoint_src_out": ("ONE_MINUS_DA_OVER_SA", "ZERO"),
    "conjoint_dst_out": ("ZERO", "ONE_MINUS_SA_OVER_DA"),
    "conjoint_src_atop": ("DA_OVER_SA", "ONE_MINUS_SA_OVER_DA"),
    "conjoint_dst_atop": ("ONE_MINUS_DA_OVER_SA", "SA_OVER_DA"),
    "conjoint_xor": ("ONE_MINUS_DA_OVER_SA", "ONE_MINUS_SA_OVER_DA"),
}


def _blender_alpha_over(kind: str, fg: np.ndarray, bg: np.ndarray) -> np.ndarray:
    """Blender 5.0 Alpha Over (premultiplied input, Straight Alpha off), per pixel, Factor = 1."""
    out = np.empty_like(fg)
    for i, (f, b) in enumerate(zip(fg.astype(np.float64), bg.astype(np.float64), strict=True)):
        fa, ba = min(max(f[3], 0.0), 1.0), min(max(b[3], 0.0), 1.0)
        if kind == "disjoint_over":
            out[i] = f + b if fa + ba < 1 else f + (b / ba if ba != 0 else 0 * b) * (1 - fa)
        else:  # conjoint_over
            out[i] = f if fa > ba else f + b * (1 - (fa / ba if ba != 0 else 0.0))
    return out


def _close(got: np.ndarray, want: np.ndarray, dtype) -> None:
    # A few roundings of float32 on values up to ~10 (HDR): relative 1e-6 plus a small absolute slack.
    tol = 1e-6 if dtype == np.float32 else 1e-14
    np.testing.assert_allclose(got, want, rtol=tol, atol=tol)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("op", [*OPERATORS, "plus"])
def test_porter_duff_closed_forms(op, dtype):
    a, b = image_pair((37, 41), seed=1, dtype=dtype)
    got = composite(a, b, op, engine="numpy")
    assert got.dtype == dtype and got.shape == a.shape
    want = PAPER[op](a.astype(np.float64), b.astype(np.float64), a[..., 3:4], b[..., 3:4])
    _close(got, want, dtype)


@pytest.mark.parametrize("op", ["disjoint_over", "conjoint_over"])
def test_blender_disjoint_conjoint_over(op):
    a, b = image_pair((23, 29), seed=2)
    # Also the branch edges: sa + da == 1 exactly, sa == da, da == 0.
    a[0, :3, 3], b[0, :3, 3] = 0.25, 0.75
    a[1, :3, 3], b[1, :3, 3] = 0.5, 0.5
    b[2, :5] = 0.0
    got = composite(a, b, op, engine="numpy")
    want = _blender_alpha_over(op, a.reshape(-1, 4), b.reshape(-1, 4)).reshape(a.shape)
    _close(got, want, np.float32)


@pytest.mark.parametrize("op", list(PIXMAN))
def test_pixman_disjoint_conjoint_family(op):
    a, b = image_pair((19, 17), seed=3)
    got = composite(a, b, op, engine="numpy").reshape(-1, 4)
    fa_name, fb_name = PIXMAN[op]
    want = np.array(
        [
            s * _pixman_factor(fa_name, s[3], d[3]) + d * _pixman_factor(fb_name, s[3], d[3])
            for s, d in zip(
                a.reshape(-1, 4).astype(np.float64), b.reshape(-1, 4).astype(np.float64), strict=True
            )
        ]
    )
    _close(got, want, np.float32)


def test_every_operator_is_tested_against_a_closed_form():
    assert set(ALL_OPERATORS) == set(PAPER) | set(PIXMAN) | {"disjoint_over", "conjoint_over"}


@pytest.mark.parametrize("op", ["src_over", "src_atop", "disjoint_over", "conjoint_xor"])
def test_mix_factor_interpolates_towards_dst(op):
    a, b = image_pair((16, 16), seed=4)
    full = composite(a, b, op, engine="numpy").astype(np.float64)
    for f in (0.0, 0.3, 0.75):
        got = composite(a, b, op, factor=f, engine="numpy")
        _close(got, b * (1 - f) + full * f, np.float32)
    np.testing.assert_array_equal(composite(a, b, op, factor=0.0), b)  # exact: dst·1 + m·0
    per_pixel = np.random.default_rng(5).random((16, 16)).astype(np.float32)
    got = composite(a, b, op, factor=per_pixel, engine="numpy")
    f = per_pixel[..., None].astype(np.float64)
    _close(got, b * (1 - f) + full * f, np.float32)


def test_single_colour_broadcasts_against_an_image():
    _, b = image_pair((8, 9), seed=6)
    colour = (0.0, 0.0, 0.5, 0.5)  # half-transparent blue, premultiplied
    got = composite(colour, b, "src_over")
    want = np.array(colour) + b.astype(np.float64) * 0.5
    assert got.shape == b.shape and got.dtype == np.float32
    _close(got, want, np.float32)
    got = composite(b, colour, "src")  # the result has the broadcast shape and is a copy
    np.testing.assert_array_equal(got, b)
    assert got is not b and not np.shares_memory(got, b)


def test_dtype_promotion_and_no_aliasing():
    a, b = image_pair((4, 5), seed=7)
    assert composite(a.astype(np.float64), b).dtype == np.float64
    for op in ("src", "dst"):
        out = composite(a, b, op)
        assert not np.shares_memory(out, a) and not np.shares_memory(out, b)


def test_src_over_matches_openimageio_over():
    oiio = pytest.importorskip("OpenImageIO")
    a, b = image_pair((31, 45), seed=8)
    got = composite(a, b, "src_over", engine="numpy")
    want = oiio.ImageBufAlgo.over(oiio.ImageBuf(a), oiio.ImageBuf(b))
    want = np.asarray(want.get_pixels(oiio.FLOAT)).reshape(a.shape)
    # OIIO computes a + (1 − αa)·b in float32 SIMD, possibly fused: agree to an ulp or two.
    np.testing.assert_allclose(got, want, rtol=3e-7, atol=1e-7)
