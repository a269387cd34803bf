"""Fog: the three OpenGL §3.10 formulas at known distances."""

import math

import numpy as np
import pytest

from blinn_phong.model.fog import apply_fog, eye_distance, fog_factor


def test_linear_fog_is_the_fraction_of_the_way_from_end_to_start():
    d = np.array([0.0, 2.0, 4.0, 6.0, 10.0, 12.0])
    f = fog_factor(d, "linear", start=2.0, end=10.0)
    # (end − c)/(end − start), clamped: before start no fog, past end only fog.
    np.testing.assert_allclose(f, [1.0, 1.0, 0.75, 0.5, 0.0, 0.0], atol=1e-15)


def test_exp_fog_at_one_over_density_is_one_over_e():
    f = fog_factor(np.array([0.0, 4.0, 8.0]), "exp", density=0.25)
    np.testing.assert_allclose(f, [1.0, math.exp(-1.0), math.exp(-2.0)], rtol=1e-15)


def test_exp2_fog_squares_the_exponent():
    f = fog_factor(np.array([0.0, 4.0, 8.0]), "exp2", density=0.25)
    np.testing.assert_allclose(f, [1.0, math.exp(-1.0), math.exp(-4.0)], rtol=1e-15)


def test_gl_defaults_are_exp_with_density_one():
    np.testing.assert_allclose(fog_factor(np.array([2.0])), [math.exp(-2.0)], rtol=1e-15)


def test_apply_fog_on_premultiplied_pixels_keeps_alpha_and_blends_colour():
    # A half-covered red pixel at the distance where linear fog is half done.
    rgba = np.array([[0.5, 0.0, 0.0, 0.5]], dtype=np.float32)
    out = apply_fog(rgba, np.array([6.0], dtype=np.float32), (0.0, 0.0, 1.0), "linear", start=2.0, end=10.0)
    # straight colour (1,0,0) -> 0.5·(1,0,0) + 0.5·(0,0,1) = (0.5, 0, 0.5); premultiplied by α = 0.5
    np.testing.assert_allclose(out, [[0.25, 0.0, 0.25, 0.5]], atol=1e-7)
    assert out.dtype == np.float32


def test_eye_distance_plane_and_radial():
    p = np.array([[3.0, 4.0, -12.0]])
    np.testing.assert_allclose(eye_distance(p, "plane"), [12.0])
    np.testing.assert_allclose(eye_distance(p, "radial"), [13.0])


def test_bad_input_is_rejected_with_the_argument_named():
    with pytest.raises(ValueError, match="mode"):
        fog_factor(np.array([1.0]), "cubic")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="end != start"):
        fog_factor(np.array([1.0]), "linear", start=1.0, end=1.0)
    with pytest.raises(ValueError, match="distance"):
        apply_fog(np.zeros((2, 4)), np.zeros(3), (0, 0, 0))
    with pytest.raises(ValueError, match="finite"):
        fog_factor(np.array([np.nan]))


# --------------------------------------------------------------------------- fog parameters


@pytest.mark.parametrize(
    ("start", "end", "name"),
    [(0.0, np.inf, "end"), (np.nan, 10.0, "start"), (-np.inf, 10.0, "start"), (2.0, np.nan, "end")],
)
def test_linear_fog_needs_finite_start_and_end(start, end, name):
    with pytest.raises(ValueError, match=rf"^{name}: expected a finite number"):
        fog_factor(np.array([1.0, 5.0]), "linear", start=start, end=end)


def test_linear_fog_end_before_start_is_reverse_fog():
    # GL §3.10 f = (end − c)/(end − start) does not require end > start: here f = (c − 2)/8, clamped
    np.testing.assert_allclose(
        fog_factor(np.array([2.0, 6.0, 12.0]), "linear", start=10.0, end=2.0), [0.0, 0.5, 1.0], atol=1e-15
    )


def test_fog_reports_non_finite_counts_in_the_shared_style():
    with pytest.raises(ValueError, match=r"^distance: expected finite values; got 1 NaN and 2 Inf of 4"):
        fog_factor(np.array([np.nan, np.inf, -np.inf, 1.0]))
    with pytest.raises(ValueError, match=r"^rgba: expected shape \(\.\.\., 4\), got shape \(2, 3\)"):
        apply_fog(np.zeros((2, 3)), np.zeros(2), (0, 0, 0))
