"""The three transparency models, Kay–Greenberg transparency and specular wash-out, in closed form."""

import numpy as np
import pytest

from blinn_phong.effects.transparency import (
    TRANSPARENCY_MODELS,
    blend_transparent_surface,
    kay_greenberg_transparency,
    transparent_fragment,
    washed_out_opacity,
)

BEHIND = np.array([[0.2, 0.4, 0.6, 1.0], [0.1, 0.0, 0.3, 0.5]])


def test_emission_adds_light_and_keeps_coverage():
    c = np.array([0.5, 0.25, 0.0])
    out = blend_transparent_surface(c, BEHIND, "emission")
    np.testing.assert_allclose(out[:, :3], BEHIND[:, :3] + c, atol=1e-15)
    np.testing.assert_allclose(out[:, 3], BEHIND[:, 3])
    # two glowing surfaces commute (a sum)
    d = np.array([0.1, 0.2, 0.3])
    ab = blend_transparent_surface(d, blend_transparent_surface(c, BEHIND, "emission"), "emission")
    ba = blend_transparent_surface(c, blend_transparent_surface(d, BEHIND, "emission"), "emission")
    np.testing.assert_allclose(ab, ba, atol=1e-15)


def test_partial_occlusion_is_coverage_weighted():
    c = np.array([1.0, 0.0, 0.0])
    out = blend_transparent_surface(c, BEHIND, "partial_occlusion", opacity=0.25)
    np.testing.assert_allclose(out[:, :3], 0.25 * c + 0.75 * BEHIND[:, :3], atol=1e-15)
    np.testing.assert_allclose(out[:, 3], 0.25 + 0.75 * BEHIND[:, 3], atol=1e-15)
    # order matters: red over blue differs from blue over red
    blue = np.array([0.0, 0.0, 1.0])
    rb = blend_transparent_surface(
        c,
        blend_transparent_surface(blue, BEHIND, "partial_occlusion", opacity=0.5),
        "partial_occlusion",
        opacity=0.5,
    )
    br = blend_transparent_surface(
        blue,
        blend_transparent_surface(c, BEHIND, "partial_occlusion", opacity=0.5),
        "partial_occlusion",
        opacity=0.5,
    )
    assert np.abs(rb - br).max() > 0.1


def test_absorption_multiplies_per_channel_and_stacked_filters_commute():
    t1 = np.array([0.9, 0.5, 0.1])
    t2 = np.array([0.2, 1.0, 0.5])
    black = np.zeros(3)
    one = blend_transparent_surface(black, BEHIND, "absorption", transmittance=t1)
    np.testing.assert_allclose(one[:, :3], BEHIND[:, :3] * t1, atol=1e-15)
    np.testing.assert_allclose(one[:, 3], BEHIND[:, 3])
    both = blend_transparent_surface(black, one, "absorption", transmittance=t2)
    other = blend_transparent_surface(
        black,
        blend_transparent_surface(black, BEHIND, "absorption", transmittance=t2),
        "absorption",
        transmittance=t1,
    )
    np.testing.assert_allclose(both, other, atol=1e-15)
    # Beer–Lambert: two slabs of transmittance t are one slab of t²
    np.testing.assert_allclose(
        blend_transparent_surface(black, one, "absorption", transmittance=t1)[:, :3],
        BEHIND[:, :3] * t1**2,
        atol=1e-15,
    )
    # the glass's own highlight is added on top
    lit = blend_transparent_surface(np.array([0.3, 0.3, 0.3]), BEHIND, "absorption", transmittance=t1)
    np.testing.assert_allclose(lit[:, :3], BEHIND[:, :3] * t1 + 0.3, atol=1e-15)


def test_kay_greenberg_endpoints_and_shape():
    nz = np.array([1.0, -1.0, 0.0, 0.5])
    t = kay_greenberg_transparency(nz, t_min=0.1, t_max=0.9, power=2.0)
    # facing: t_max; silhouette: t_min; |N_z| = 0.5: 0.1 + 0.8·(1 − 0.25) = 0.7
    np.testing.assert_allclose(t, [0.9, 0.9, 0.1, 0.7], atol=1e-15)
    # p = 1 is linear in |N_z|
    x = np.linspace(0, 1, 11)
    np.testing.assert_allclose(kay_greenberg_transparency(x, 0.2, 0.6, 1.0), 0.2 + 0.4 * x, atol=1e-15)
    # the simple model is the constant t_min = t_max
    np.testing.assert_allclose(kay_greenberg_transparency(x, 0.3, 0.3, 3.0), 0.3, atol=1e-15)
    # more opaque towards the silhouette, monotonically
    assert np.all(np.diff(kay_greenberg_transparency(x, 0.1, 0.9, 3.0)) > 0)


def test_specular_washes_out_transparency():
    t = np.array([0.8, 0.8, 0.8, 0.2])
    s = np.array([0.0, 0.3, 0.9, 0.05])
    np.testing.assert_allclose(washed_out_opacity(t, s), [0.2, 0.5, 1.0, 0.85], atol=1e-15)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="opacity"):
        blend_transparent_surface(np.zeros(3), BEHIND, "partial_occlusion")
    with pytest.raises(ValueError, match="transmittance"):
        blend_transparent_surface(np.zeros(3), BEHIND, "absorption", transmittance=np.array([1.5, 0, 0]))
    with pytest.raises(ValueError, match="model"):
        blend_transparent_surface(np.zeros(3), BEHIND, "refraction")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="t_min"):
        kay_greenberg_transparency(0.5, -0.1, 0.5)
    with pytest.raises(ValueError, match="specular"):
        washed_out_opacity(0.5, -1.0)


# ------------------------------------------------------------- one meaning per transparency model

OPAQUE_BEHIND = np.array([[0.2, 0.4, 0.6, 1.0], [0.05, 0.5, 0.25, 1.0]])
TRANSLUCENT_BEHIND = np.array([[0.1, 0.0, 0.3, 0.5], [0.0, 0.0, 0.0, 0.0]])
LIT = np.array([[0.7, 0.2, 0.1], [1.5, 0.3, 0.0]])  # may exceed 1 (unclamped light)
ALPHA = np.array([0.25, 0.6])


def test_emission_is_scaled_by_opacity():
    # Material docstring: emission adds α·c and hides nothing.
    for behind in (OPAQUE_BEHIND, TRANSLUCENT_BEHIND):
        out = blend_transparent_surface(LIT, behind, "emission", opacity=ALPHA)
        np.testing.assert_allclose(out[:, :3], ALPHA[:, None] * LIT + behind[:, :3], atol=1e-15)
        np.testing.assert_array_equal(out[:, 3], behind[:, 3])


def test_absorption_takes_the_grey_filter_of_an_opacity():
    # a material of opacity α filters with T = 1 − α and adds its own light: c + (1 − α)·behind
    out = blend_transparent_surface(LIT[0], OPAQUE_BEHIND, "absorption", transmittance=0.75)
    np.testing.assert_allclose(out[:, :3], LIT[0] + 0.75 * OPAQUE_BEHIND[:, :3], atol=1e-15)
    np.testing.assert_array_equal(out[:, 3], OPAQUE_BEHIND[:, 3])


@pytest.mark.parametrize(
    ("model", "kwargs", "name"),
    [
        ("absorption", {"opacity": 0.5, "transmittance": 0.5}, "opacity"),
        ("emission", {"transmittance": 0.5}, "transmittance"),
        ("partial_occlusion", {"opacity": 0.5, "transmittance": np.ones(3)}, "transmittance"),
    ],
)
def test_a_parameter_the_model_does_not_use_is_refused(model, kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name}: the .* does not use it"):
        blend_transparent_surface(LIT, OPAQUE_BEHIND, model, **kwargs)


@pytest.mark.parametrize("model", TRANSPARENCY_MODELS)
def test_fragment_over_an_opaque_background_is_the_model(model):
    # the renderer resolves fragments with src over: (α·c, α), (α·c, 0), (c, α) must give the models
    frag = transparent_fragment(LIT, ALPHA, model)
    over = frag[:, :3] + (1 - frag[:, 3:]) * OPAQUE_BEHIND[:, :3]  # Porter–Duff over, premultiplied
    if model == "absorption":
        expected = blend_transparent_surface(
            LIT, OPAQUE_BEHIND, model, transmittance=np.repeat(1 - ALPHA[:, None], 3, axis=1)
        )
    else:
        expected = blend_transparent_surface(LIT, OPAQUE_BEHIND, model, opacity=ALPHA)
    np.testing.assert_allclose(over, expected[:, :3], atol=1e-15)
    np.testing.assert_allclose(
        frag[:, 3] + (1 - frag[:, 3]) * OPAQUE_BEHIND[:, 3], expected[:, 3], atol=1e-15
    )


def test_transparency_inputs_are_checked_in_the_shared_style():
    bad = np.array([[np.nan, 0.0, 0.0], [0.0, np.inf, 0.0]])
    with pytest.raises(ValueError, match=r"^surface_rgb: expected finite values; got 1 NaN and 1 Inf of 6"):
        blend_transparent_surface(bad, OPAQUE_BEHIND, "emission")
    with pytest.raises(ValueError, match=r"^opacity: expected values in \[0, 1\]; got 1 of 2 outside"):
        blend_transparent_surface(LIT, OPAQUE_BEHIND, "partial_occlusion", opacity=np.array([0.5, 1.5]))
    with pytest.raises(TypeError, match=r"^behind: expected real numbers, got dtype <U1"):
        blend_transparent_surface(LIT, np.array(["a", "b", "c", "d"]), "emission")


def test_fragments_of_emission_and_partial_occlusion_match_over_any_background():
    for model in ("emission", "partial_occlusion"):
        frag = transparent_fragment(LIT, ALPHA, model)
        over = frag + (1 - frag[:, 3:]) * TRANSLUCENT_BEHIND
        np.testing.assert_allclose(
            over, blend_transparent_surface(LIT, TRANSLUCENT_BEHIND, model, opacity=ALPHA), atol=1e-15
        )
