"""Properties-editor panels and operators of the Blinn-Phong engine.

Panels show only while the engine is active (``COMPAT_ENGINES`` + ``poll`` on ``context.engine``,
as Cycles' ``ui.py`` does): render settings (panels generated from ``addon/options.py``; Film ›
Transparent; the pipeline settings in a closed sub-panel) and the last render's choices in the Render tab, the
Blinn-Phong coefficients in the Material tab, falloff in the Light tab. Blender's own engine-agnostic
panels (format, output, camera, light basics, ...) get the engine id added to their
``COMPAT_ENGINES`` on register and removed on unregister.
"""

import bpy

from . import convert, engine, options

__all__ = [
    "BLINN_PHONG_OT_copy_derived_light",
    "BLINN_PHONG_OT_copy_derived_material",
    "BLINN_PHONG_PT_light",
    "BLINN_PHONG_PT_material",
    "BLINN_PHONG_PT_render",
    "BLINN_PHONG_PT_render_effects",
    "BLINN_PHONG_PT_render_film",
    "BLINN_PHONG_PT_render_last",
    "BLINN_PHONG_PT_render_output",
    "BLINN_PHONG_PT_render_pipeline",
    "classes",
    "register",
    "unregister",
]

ENGINES = {engine.ENGINE_ID}

#: Blender panels that work for any engine and should show for this one too.
SHARED_PANELS = (
    "RENDER_PT_format",
    "RENDER_PT_format_presets",
    "RENDER_PT_frame_range",
    "RENDER_PT_time_stretching",
    "RENDER_PT_output",
    "RENDER_PT_encoding",
    "RENDER_PT_post_processing",
    "RENDER_PT_color_management",
    "RENDER_PT_stamp",
    "DATA_PT_camera",
    "DATA_PT_lens",
    "DATA_PT_camera_display",
    "DATA_PT_context_camera",
    "DATA_PT_context_light",
    "DATA_PT_light",
    "DATA_PT_spot",
    "DATA_PT_area",
    "MATERIAL_PT_context_material",
    "MATERIAL_PT_viewport",
    "WORLD_PT_context_world",
    "WORLD_PT_viewport_display",
    "EEVEE_MATERIAL_PT_surface",
    "EEVEE_WORLD_PT_surface",
    "VIEWLAYER_PT_layer_passes",  # View Layer › Passes (a header for the two below)
    "VIEWLAYER_PT_layer_passes_cryptomatte",  # Object, Material, Asset, Levels
    "VIEWLAYER_PT_layer_passes_lightgroups",  # the view layer's light groups
)


class _EnginePanel:
    """Mixin: a Properties-editor panel shown only for the Blinn-Phong engine."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = ENGINES

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return context.engine in cls.COMPAT_ENGINES


def _draw_settings(layout: bpy.types.UILayout, settings: bpy.types.PropertyGroup, panel: str) -> None:
    """Draw the settings of ``panel`` (``options.PANELS``) that apply to the current values."""
    current = options.RenderOptions.from_settings(settings)
    for name in options.visible_fields(panel, current):
        layout.prop(settings, name)


def _settings_panel(key: str, idname: str, doc: str, **extra: object) -> type:
    """A Render-tab panel drawing the settings whose ``Setting.panel`` is ``key``."""

    def draw(self: bpy.types.Panel, context: bpy.types.Context) -> None:
        self.layout.use_property_split = True
        _draw_settings(self.layout, context.scene.blinn_phong, key)

    attributes = {"bl_label": options.PANELS[key], "bl_context": "render", "draw": draw, "__doc__": doc}
    attributes.update(extra)
    return type(idname, (_EnginePanel, bpy.types.Panel), attributes)


BLINN_PHONG_PT_render = _settings_panel(
    "main", "BLINN_PHONG_PT_render", "Shading frequency, anti-aliasing and lighting model"
)
BLINN_PHONG_PT_render_effects = _settings_panel(
    "effects",
    "BLINN_PHONG_PT_render_effects",
    'Transparency, shadows and fog ("Auto" lets the planner decide)',
    bl_parent_id="BLINN_PHONG_PT_render",
)
BLINN_PHONG_PT_render_pipeline = _settings_panel(
    "pipeline",
    "BLINN_PHONG_PT_render_pipeline",
    "Kernels and what a failed render does in background mode (render farms, scripts)",
    bl_parent_id="BLINN_PHONG_PT_render",
    bl_options={"DEFAULT_CLOSED"},
)


class BLINN_PHONG_PT_render_output(_EnginePanel, bpy.types.Panel):  # noqa: N801
    """Deep EXR next to each frame's output: the file it goes to, or why it cannot be written"""

    bl_label = options.PANELS["output"]
    bl_context = "render"
    bl_parent_id = "BLINN_PHONG_PT_render"
    bl_options = {"DEFAULT_CLOSED"}  # noqa: RUF012

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        layout.use_property_split = True
        settings = context.scene.blinn_phong
        _draw_settings(layout, settings, "output")
        if not settings.deep_output:
            return
        problem = options.deep_output_problem(settings.transparency)
        if problem:
            layout.label(text=problem, icon="ERROR")
            return
        try:
            path = engine.deep_file_path(context.scene)
        except RuntimeError as error:  # Blender 5.0 path templates: a broken {…} in the output path
            layout.label(text=str(error).strip(), icon="ERROR")
            return
        layout.label(text=path, icon="FILE")


class BLINN_PHONG_PT_render_film(_EnginePanel, bpy.types.Panel):  # noqa: N801
    """Film › Transparent: alpha from coverage, or the world colour behind the objects"""

    bl_label = "Film"
    bl_context = "render"
    bl_parent_id = "BLINN_PHONG_PT_render"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        layout.use_property_split = True
        layout.prop(context.scene.render, "film_transparent", text="Transparent")


class BLINN_PHONG_PT_render_last(_EnginePanel, bpy.types.Panel):  # noqa: N801
    """What the last render did, and why"""

    bl_label = "Last Render"
    bl_context = "render"
    bl_parent_id = "BLINN_PHONG_PT_render"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        last = engine.LAST_RENDER
        if not last:
            layout.label(text="No render yet in this session")
            return
        if not last.get("ok"):
            layout.label(text=str(last.get("error") or "failed"), icon="ERROR")
            return
        choices = last.get("choices", {})
        col = layout.column(align=True)
        col.label(text=f"{last.get('seconds', 0.0):.2f} s, {last.get('triangles', 0)} triangles", icon="TIME")
        for part in str(last.get("status", "")).split(" | ")[1:]:
            col.label(text=part, icon="SETTINGS")
        col.label(text=f"Shading: {choices.get('shading')}, {choices.get('samples')} samples per pixel")
        for reason in choices.get("reasons", []):
            col.label(text=reason, icon="INFO")
        for note in last.get("notes", []):
            col.label(text=note, icon="ERROR")


class BLINN_PHONG_PT_material(_EnginePanel, bpy.types.Panel):  # noqa: N801
    """Blinn-Phong coefficients of the active material"""

    bl_label = "Blinn-Phong Material"
    bl_context = "material"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return super().poll(context) and getattr(context, "material", None) is not None

    def draw(self, context: bpy.types.Context) -> None:
        material = context.material
        settings = material.blinn_phong
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "source")
        if settings.source == "CUSTOM":
            for name in ("ambient", "diffuse", "specular", "shininess", "emission", "opacity"):
                layout.prop(settings, name)
        else:
            derived, _extras, _notes = convert.material_from_blender(material)
            col = layout.column(align=True)
            for name in ("diffuse", "specular", "emission"):
                value = getattr(derived, name)
                col.label(text=f"{name.title()}: {value[0]:.3f}, {value[1]:.3f}, {value[2]:.3f}")
            col.label(text=f"Shininess: {derived.shininess:.1f}   Opacity: {derived.opacity:.2f}")
            layout.operator(BLINN_PHONG_OT_copy_derived_material.bl_idname, icon="COPYDOWN")
        layout.prop(settings, "shading")
        layout.prop(settings, "transparency_model")
        layout.prop(settings, "use_kay_greenberg")
        if settings.use_kay_greenberg:
            layout.prop(settings, "kay_min_transmission")
            layout.prop(settings, "kay_max_transmission")
            layout.prop(settings, "kay_exponent")
        layout.prop(settings, "specular_washout")


class BLINN_PHONG_PT_light(_EnginePanel, bpy.types.Panel):  # noqa: N801
    """OpenGL-style attenuation and spot exponent of the active light"""

    bl_label = "Blinn-Phong Light"
    bl_context = "data"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return super().poll(context) and isinstance(getattr(context, "light", None), bpy.types.Light)

    def draw(self, context: bpy.types.Context) -> None:
        light = context.light
        settings = light.blinn_phong
        layout = self.layout
        layout.use_property_split = True
        layout.prop(settings, "intensity_scale")
        if light.type == "SUN":
            layout.label(text="Sun: no attenuation", icon="INFO")
            return
        layout.prop(settings, "source")
        if settings.source == "CUSTOM":
            for name in ("constant", "linear", "quadratic"):
                layout.prop(settings, name)
            if light.type in ("SPOT", "AREA"):
                layout.prop(settings, "spot_exponent")
        else:
            values = convert.derived_light_values(light)
            col = layout.column(align=True)
            col.label(
                text=f"kc {values['constant']:.4g}  kl {values['linear']:.4g}  kq {values['quadratic']:.4g}"
            )
            if light.type == "SPOT":
                col.label(text=f"Spot exponent {values['spot_exponent']:.3f}")
            layout.operator(BLINN_PHONG_OT_copy_derived_light.bl_idname, icon="COPYDOWN")


class BLINN_PHONG_OT_copy_derived_material(bpy.types.Operator):  # noqa: N801
    """Store the coefficients derived from the Principled BSDF as custom values, to edit them"""

    bl_idname = "blinn_phong.copy_derived_material"
    bl_label = "Copy Derived Values"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return getattr(context, "material", None) is not None

    def execute(self, context: bpy.types.Context) -> set[str]:
        material = context.material
        settings = material.blinn_phong
        settings.source = "PRINCIPLED"
        derived, _extras, _notes = convert.material_from_blender(material)
        for name in ("ambient", "diffuse", "specular", "emission", "shininess", "opacity"):
            setattr(settings, name, getattr(derived, name))
        settings.source = "CUSTOM"
        return {"FINISHED"}


class BLINN_PHONG_OT_copy_derived_light(bpy.types.Operator):  # noqa: N801
    """Store the attenuation and exponent derived from the Blender light as custom values"""

    bl_idname = "blinn_phong.copy_derived_light"
    bl_label = "Copy Derived Values"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return isinstance(getattr(context, "light", None), bpy.types.Light)

    def execute(self, context: bpy.types.Context) -> set[str]:
        light = context.light
        for name, value in convert.derived_light_values(light).items():
            setattr(light.blinn_phong, name, value)
        light.blinn_phong.source = "CUSTOM"
        return {"FINISHED"}


classes = (
    BLINN_PHONG_OT_copy_derived_material,
    BLINN_PHONG_OT_copy_derived_light,
    BLINN_PHONG_PT_render,
    BLINN_PHONG_PT_render_film,
    BLINN_PHONG_PT_render_effects,
    BLINN_PHONG_PT_render_output,
    BLINN_PHONG_PT_render_pipeline,
    BLINN_PHONG_PT_render_last,
    BLINN_PHONG_PT_material,
    BLINN_PHONG_PT_light,
)


def _shared_panels() -> list[type]:
    return [p for p in (getattr(bpy.types, name, None) for name in SHARED_PANELS) if p is not None]


def register() -> None:
    """Register the panels and operators; show Blender's shared panels for this engine."""
    for cls in classes:
        bpy.utils.register_class(cls)
    for panel in _shared_panels():
        if hasattr(panel, "COMPAT_ENGINES"):
            panel.COMPAT_ENGINES.add(engine.ENGINE_ID)


def unregister() -> None:
    """Undo :func:`register`, in reverse order."""
    for panel in _shared_panels():
        if hasattr(panel, "COMPAT_ENGINES"):
            panel.COMPAT_ENGINES.discard(engine.ENGINE_ID)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
