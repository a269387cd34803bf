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
    IntProperty,
    PointerProperty,
)

from .mapping import MAX_SHININESS

__all__ = [
    "BLINN_PHONG_LightSettings",
    "BLINN_PHONG_MaterialSettings",
    "BLINN_PHONG_RenderSettings",
    "classes",
    "register",
    "unregister",
]

SHADING_ITEMS = (
    ("FLAT", "Flat", "One colour per triangle, lit at its provoking vertex with the face normal"),
    ("GOURAUD", "Gouraud", "Lighting at the vertices, colours interpolated (OpenGL fixed function)"),
    ("PHONG", "Phong", "Normals interpolated, lighting per pixel"),
)

TRANSPARENCY_ITEMS = (
    ("AUTO", "Auto", "Let the planner pick a method for the scene and explain why"),
    ("OPAQUE", "Opaque", "Ignore opacity: every surface is opaque"),
    ("SORTED", "Sorted", "Draw transparent triangles back to front and blend (order-dependent)"),
    ("A_BUFFER", "A-Buffer", "Keep every fragment per pixel, sort and composite them exactly"),
    ("DEPTH_PEELING", "Depth Peeling", "Peel layers front to back (exact up to the layer count)"),
    ("WEIGHTED", "Weighted Blended", "Weighted blended order-independent transparency (approximate)"),
)

SHADOW_ITEMS = (
    ("AUTO", "Auto", "Let the planner pick a method for the scene and explain why"),
    ("NONE", "None", "No shadows"),
    ("HARD", "Hard", "Ray-traced hard shadows from point, spot and sun lights"),
    ("SOFT", "Soft", "Ray-traced soft shadows sampling the light's radius"),
    ("VOLUME", "Shadow Volumes", "Exact hard shadows by stencil counting (z-fail), no ray tracer needed"),
)

FOG_ITEMS = (
    ("NONE", "None", "No fog"),
    ("LINEAR", "Linear", "OpenGL GL_LINEAR fog between start and end"),
    ("EXP", "Exponential", "OpenGL GL_EXP fog, exp(-density·z)"),
    ("EXP2", "Exponential Squared", "OpenGL GL_EXP2 fog, exp(-(density·z)²)"),
)


class BLINN_PHONG_RenderSettings(bpy.types.PropertyGroup):  # noqa: N801 (Blender naming rule)
    """Render settings of the Blinn-Phong engine (``Scene.blinn_phong``)."""

    shading: EnumProperty(
        name="Shading",
        items=(
            ("AUTO", "Auto", "The planner's choice per mesh: flat where it is exact, else Phong"),
            *SHADING_ITEMS,
        ),
        default="PHONG",
        description="Shading frequency for materials that do not override it",
    )
    tolerance: FloatProperty(
        name="Tolerance",
        min=0.0,
        soft_max=64.0,
        default=0.0,
        precision=1,
        description="Error the planner may accept to choose a faster method, in 8-bit steps "
        "(1/255; max for transparency, mean for shadows; 0: exact only)",
    )
    samples_per_axis: IntProperty(
        name="Anti-Aliasing", min=1, max=8, default=2, description="k×k ordered-grid samples per pixel"
    )
    specular_model: EnumProperty(
        name="Specular",
        items=(
            ("BLINN", "Blinn (half vector)", "(n·h)^s, the OpenGL equation"),
            ("PHONG", "Phong (reflection)", "(r·v)^s"),
        ),
        default="BLINN",
    )
    two_sided: BoolProperty(
        name="Two-Sided Lighting", default=True, description="Light back faces with the flipped normal"
    )
    transparency: EnumProperty(name="Transparency", items=TRANSPARENCY_ITEMS, default="AUTO")
    peel_layers: IntProperty(name="Layers", min=1, max=64, default=8, description="Depth-peeling layers")
    shadows: EnumProperty(name="Shadows", items=SHADOW_ITEMS, default="AUTO")
    shadow_samples: IntProperty(
        name="Shadow Samples",
        min=1,
        max=256,
        default=16,
        description="Rays per pixel toward a light for soft shadows",
    )
    shadow_bias: FloatProperty(
        name="Bias",
        min=0.0,
        max=1.0,
        default=1e-3,
        precision=5,
        description="Ray origin offset along the normal, in scene units",
    )
    fog: EnumProperty(name="Fog", items=FOG_ITEMS, default="NONE")
    fog_color: FloatVectorProperty(
        name="Fog Colour", subtype="COLOR", size=3, min=0.0, default=(0.5, 0.5, 0.5)
    )
    fog_density: FloatProperty(name="Density", min=0.0, default=0.1)
    fog_start: FloatProperty(name="Start", min=0.0, default=1.0, unit="LENGTH")
    fog_end: FloatProperty(name="End", min=0.0, default=50.0, unit="LENGTH")
    abort_on_error: BoolProperty(
        name="Exit on Error in Background",
        default=True,
        description="In background mode (blender -b), end the process with exit code 1 when a render "
        "fails, so render farms and scripts see the failure",
    )
    verify_background: PointerProperty(
        name="Background",
        type=bpy.types.Image,
        description="Image of the render's size to composite the last render over (Verify Against Blender)",
    )
    verify_operator: EnumProperty(
        name="Operator",
        items=(
            ("src_over", "Over", "Alpha Over, mode Over: Porter-Duff src-over"),
            ("disjoint_over", "Disjoint Over", "Alpha Over, mode Disjoint Over (Blender 5.0)"),
            ("conjoint_over", "Conjoint Over", "Alpha Over, mode Conjoint Over (Blender 5.0)"),
        ),
        default="src_over",
    )


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
