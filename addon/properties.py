"""Blender property groups of the Blinn-Phong engine: render settings, per material, per light.

``Scene.blinn_phong``, ``Material.blinn_phong`` and ``Light.blinn_phong`` (the layout of Cycles'
``properties.py``). Materials and lights default to *derived* values: a material in the mode
"From Principled BSDF" reads its Blinn-Phong coefficients from the material's Principled BSDF at render
time, a light in the mode "From Blender light" derives attenuation and spot exponent from Blender's own
light values (``addon/mapping.py`` holds the formulas), so an existing scene renders sensibly without
edits. Switching to "Custom" uses the values stored here; the "Copy Derived Values" operator fills
them from the derived ones first.
"""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    PointerProperty,
)

from . import options
from .mapping import MAX_SHININESS

__all__ = [
    "BLINN_PHONG_LightSettings",
    "BLINN_PHONG_MaterialSettings",
    "BLINN_PHONG_RenderSettings",
    "classes",
    "register",
    "unregister",
]

SHADING_ITEMS = options.SHADING_ITEMS


def _render_settings_class() -> type:
    """``Scene.blinn_phong``: one Blender property per field of ``options.RenderOptions`` (labels,
    limits and defaults come from there), plus the Verify operator's inputs."""
    annotations: dict[str, object] = {}
    for name, _default, _spec in options.settings():
        kind, kwargs = options.blender_property_arguments(name)
        annotations[name] = getattr(bpy.props, kind)(**kwargs)
    annotations["verify_background"] = PointerProperty(
        name="Background",
        type=bpy.types.Image,
        description="Image of the render's size to composite the last render over (Verify Against Blender)",
    )
    annotations["verify_operator"] = EnumProperty(
        name="Operator",
        items=(
            ("src_over", "Over", "Alpha Over, mode Over: Porter-Duff src-over"),
            ("disjoint_over", "Disjoint Over", "Alpha Over, mode Disjoint Over (Blender 5.0)"),
            ("conjoint_over", "Conjoint Over", "Alpha Over, mode Conjoint Over (Blender 5.0)"),
        ),
        default="src_over",
    )
    return type(
        "BLINN_PHONG_RenderSettings",
        (bpy.types.PropertyGroup,),
        {
            "__annotations__": annotations,
            "__doc__": "Render settings of the Blinn-Phong engine (``Scene.blinn_phong``).",
            "__module__": __name__,
        },
    )


BLINN_PHONG_RenderSettings = _render_settings_class()


MATERIAL_SOURCE_ITEMS = (
    (
        "PRINCIPLED",
        "From Principled BSDF",
        "Derive the coefficients from the material's Principled BSDF at render time",
    ),
    ("CUSTOM", "Custom", "Use the coefficients below"),
)


class BLINN_PHONG_MaterialSettings(bpy.types.PropertyGroup):  # noqa: N801 (Blender naming rule)
    """Blinn-Phong coefficients of one material (``Material.blinn_phong``)."""

    source: EnumProperty(name="Coefficients", items=MATERIAL_SOURCE_ITEMS, default="PRINCIPLED")
    ambient: FloatVectorProperty(
        name="Ambient (ka)", subtype="COLOR", size=3, min=0.0, default=(0.8, 0.8, 0.8)
    )
    diffuse: FloatVectorProperty(
        name="Diffuse (kd)", subtype="COLOR", size=3, min=0.0, default=(0.8, 0.8, 0.8)
    )
    specular: FloatVectorProperty(
        name="Specular (ks)", subtype="COLOR", size=3, min=0.0, default=(0.5, 0.5, 0.5)
    )
    shininess: FloatProperty(name="Shininess", min=0.0, max=MAX_SHININESS, soft_max=256.0, default=32.0)
    emission: FloatVectorProperty(name="Emission", subtype="COLOR", size=3, min=0.0, default=(0.0, 0.0, 0.0))
    opacity: FloatProperty(name="Opacity", min=0.0, max=1.0, default=1.0, subtype="FACTOR")
    shading: EnumProperty(
        name="Shading",
        items=(("SCENE", "Scene Setting", "Use the render setting"), *SHADING_ITEMS),
        default="SCENE",
    )
    transparency_model: EnumProperty(
        name="Transparency Model",
        items=(
            ("PARTIAL_OCCLUSION", "Alpha", "Covers the fraction α of what is behind: α·c + (1 − α)·behind"),
            ("EMISSION", "Emission", "Only adds light, hides nothing: α·c + behind"),
            (
                "ABSORPTION",
                "Absorption",
                "A grey filter of transmittance 1 − α plus its own light: c + (1 − α)·behind",
            ),
        ),
        default="PARTIAL_OCCLUSION",
    )
    use_kay_greenberg: BoolProperty(
        name="Kay-Greenberg",
        default=False,
        description="Opacity from the eye-space normal: more opaque at grazing angles (curved glass)",
    )
    specular_washout: BoolProperty(
        name="Specular Wash-Out",
        default=False,
        description="Highlights make a transparent surface more opaque: min(1, α + specular luminance)",
    )
    kay_min_transmission: FloatProperty(
        name="Min Transmission",
        min=0.0,
        max=1.0,
        default=0.1,
        subtype="FACTOR",
        description="Transmission at grazing angles",
    )
    kay_max_transmission: FloatProperty(
        name="Max Transmission",
        min=0.0,
        max=1.0,
        default=0.9,
        subtype="FACTOR",
        description="Transmission facing the viewer",
    )
    kay_exponent: FloatProperty(
        name="Exponent",
        min=0.1,
        soft_max=8.0,
        default=2.0,
        description="p in t = t_min + (t_max - t_min)·(1 - (1 - |n_z|)^p) (Kay-Greenberg)",
    )


LIGHT_SOURCE_ITEMS = (
    (
        "BLENDER",
        "From Blender Light",
        "Attenuation from the light's radius (inverse square) and spot exponent from Spot Blend",
    ),
    ("CUSTOM", "Custom", "Use the OpenGL attenuation and exponent below"),
)


class BLINN_PHONG_LightSettings(bpy.types.PropertyGroup):  # noqa: N801 (Blender naming rule)
    """OpenGL-style attenuation and spot exponent of one light (``Light.blinn_phong``)."""

    source: EnumProperty(name="Falloff", items=LIGHT_SOURCE_ITEMS, default="BLENDER")
    constant: FloatProperty(name="Constant (kc)", min=0.0, default=1.0)
    linear: FloatProperty(name="Linear (kl)", min=0.0, default=0.0)
    quadratic: FloatProperty(name="Quadratic (kq)", min=0.0, default=0.0)
    spot_exponent: FloatProperty(name="Spot Exponent", min=0.0, soft_max=128.0, default=0.0)
    intensity_scale: FloatProperty(
        name="Intensity Scale",
        min=0.0,
        soft_max=10.0,
        default=1.0,
        description="Multiplier on the intensity derived from the light's power",
    )


classes = (BLINN_PHONG_RenderSettings, BLINN_PHONG_MaterialSettings, BLINN_PHONG_LightSettings)

_POINTERS = (
    (bpy.types.Scene, BLINN_PHONG_RenderSettings),
    (bpy.types.Material, BLINN_PHONG_MaterialSettings),
    (bpy.types.Light, BLINN_PHONG_LightSettings),
)


def register() -> None:
    """Register the property groups and attach them as ``<ID>.blinn_phong``."""
    for cls in classes:
        bpy.utils.register_class(cls)
    for owner, cls in _POINTERS:
        owner.blinn_phong = PointerProperty(type=cls)


def unregister() -> None:
    """Detach and unregister everything :func:`register` added, in reverse order."""
    for owner, _cls in reversed(_POINTERS):
        del owner.blinn_phong
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
