"""addon.options: the one declaration of the render settings drives properties, panels and the core call."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import pytest

from addon import options
from addon.options import RenderOptions


def test_every_field_has_a_blender_property_of_its_type() -> None:
    kinds = {
        name: options.blender_property_arguments(name)[0]
        for name in (f.name for f in dataclasses.fields(RenderOptions))
    }
    assert kinds["shading"] == "EnumProperty"
    assert kinds["samples_per_axis"] == "IntProperty"
    assert kinds["two_sided"] == "BoolProperty"
    assert kinds["tolerance"] == "FloatProperty"
    assert kinds["fog_color"] == "FloatVectorProperty"
    _kind, kwargs = options.blender_property_arguments("samples_per_axis")
    assert kwargs == {
        "name": "Anti-Aliasing",
        "description": "k×k ordered-grid samples per pixel",
        "default": 2,
        "min": 1,
        "max": 8,
    }
    with pytest.raises(ValueError, match="name"):
        options.blender_property_arguments("nope")


def test_from_settings_reads_every_field_and_derives_the_core_arguments() -> None:
    values = {f.name: f.default for f in dataclasses.fields(RenderOptions)}
    values.update(shading="GOURAUD", samples_per_axis=3, fog_color=[0.1, 0.2, 0.3], abort_on_error=0)
    got = RenderOptions.from_settings(SimpleNamespace(**values))
    assert got.core_shading == "gouraud" and got.samples == 9
    assert got.fog_color == (0.1, 0.2, 0.3) and got.abort_on_error is False
    assert RenderOptions.from_settings(None) == RenderOptions()


def test_panels_show_the_dependent_settings_only_when_they_apply() -> None:
    assert options.visible_fields("main", RenderOptions()) == [
        "shading",
        "samples_per_axis",
        "specular_model",
        "two_sided",
    ]
    plain = options.visible_fields("effects", RenderOptions())
    assert plain == ["tolerance", "transparency", "shadows", "fog"]
    busy = options.visible_fields(
        "effects", RenderOptions(transparency="DEPTH_PEELING", shadows="SOFT", fog="LINEAR")
    )
    assert busy == [
        "tolerance",
        "transparency",
        "peel_layers",
        "shadows",
        "shadow_samples",
        "shadow_bias",
        "fog",
        "fog_color",
        "fog_start",
        "fog_end",
    ]
    assert "fog_density" in options.visible_fields("effects", RenderOptions(fog="EXP2"))
    # Exit on Error is a pipeline setting, not in the artist's main panel.
    assert options.visible_fields("pipeline", RenderOptions()) == ["engine", "abort_on_error"]
    with pytest.raises(ValueError, match="panel"):
        options.visible_fields("nope", RenderOptions())


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"shadows": "MAGIC"}, "shadows: expected one of"),
        ({"samples_per_axis": 0}, r"samples_per_axis: expected a value >= 1"),
        ({"samples_per_axis": 2.5}, "samples_per_axis: expected an integer"),
        ({"tolerance": float("nan")}, "tolerance: expected a finite number"),
        ({"two_sided": 1}, "two_sided: expected a bool"),
    ],
)
def test_bad_values_are_named(kwargs: dict, message: str) -> None:
    with pytest.raises((ValueError, TypeError), match=message):
        RenderOptions(**kwargs)


def test_deep_output_setting_its_file_name_and_the_transparency_it_needs() -> None:
    assert options.visible_fields("output", RenderOptions()) == ["deep_output"]
    assert RenderOptions().deep_output is False
    # The format's extension (any case) is replaced; a name without it is kept whole.
    assert options.deep_output_path("/r/shot_0001.png", ".png") == "/r/shot_0001.deep.exr"
    assert options.deep_output_path("/r/shot_0001.EXR", ".exr") == "/r/shot_0001.deep.exr"
    assert options.deep_output_path("/r/shot.v2_0001", ".png") == "/r/shot.v2_0001.deep.exr"
    assert options.deep_output_path("/r/shot.v2_0001", "") == "/r/shot.v2_0001.deep.exr"
    # Exactly the settings whose core method keeps a per-pixel depth order (blinn_phong.frame.deep_output).
    from blinn_phong.frame.deep_output import DEEP_METHODS

    keeps_order = [k for k, method in options.TRANSPARENCY_SETTINGS.items() if method in DEEP_METHODS]
    assert sorted(keeps_order) == sorted(options.DEEP_TRANSPARENCY)
    for key in options.TRANSPARENCY_SETTINGS:
        problem = options.deep_output_problem(key)
        assert (problem is None) == (key in keeps_order), key
    assert options.deep_output_problem("WEIGHTED") == (
        "Transparency is 'Weighted Blended': deep output keeps each pixel's fragments in depth order "
        "and needs Transparency A-Buffer, Depth Peeling or Opaque (Render Properties › Blinn-Phong › "
        "Transparency, Shadows, Fog; scene.blinn_phong.transparency)"
    )
