"""The engine's render settings, declared once (no bpy).

:class:`RenderOptions` is the only description of the render settings. Each field carries a
:class:`Setting` (label, tooltip, kind, limits, the panel it is drawn in and when it is shown),
and everything else is generated from it:

* ``addon/properties.py`` builds the ``Scene.blinn_phong`` property group (one Blender property
  per field, :func:`blender_property_arguments`);
* ``addon/render_ui.py`` draws the Render-tab panels from :data:`PANELS` (:func:`visible_fields`);
* ``addon/convert.py`` reads the property group into a :class:`RenderOptions`
  (:meth:`RenderOptions.from_settings`);
* ``addon/pipeline.py`` turns a :class:`RenderOptions` into the arguments of
  ``blinn_phong.frame.render``.

Field values are the values Blender stores (enum identifiers such as ``"PHONG"``, samples per axis),
so a property group and an options object compare field by field.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from blinn_phong._checks import choice_error

__all__ = [
    "DEEP_SUFFIX",
    "DEEP_TRANSPARENCY",
    "PANELS",
    "SHADOW_SETTINGS",
    "TRANSPARENCY_SETTINGS",
    "RenderOptions",
    "Setting",
    "blender_property_arguments",
    "deep_output_path",
    "deep_output_problem",
    "settings",
    "visible_fields",
]

TRANSPARENCY_SETTINGS: dict[str, str | None] = {
    "AUTO": None,
    "OPAQUE": "zbuffer",
    "SORTED": "sort_objects",
    "A_BUFFER": "a_buffer",
    "DEPTH_PEELING": "depth_peeling",
    "WEIGHTED": "weighted_blended",
}
"""Transparency setting -> ``blinn_phong.frame.render(transparency=...)`` (None: the planner's choice)."""

SHADOW_SETTINGS: dict[str, str | None] = {
    "AUTO": None,
    "NONE": "none",
    "HARD": "ray_traced",
    "SOFT": "soft",
    "VOLUME": "shadow_volume",
}
"""Shadow setting -> shadow method (None: the planner's choice per light)."""

DEEP_TRANSPARENCY = ("A_BUFFER", "DEPTH_PEELING", "OPAQUE")
"""Transparency settings whose fragments a deep image can hold (``blinn_phong.frame.deep_output``): the
A-buffer (every fragment), depth peeling (the nearest ``peel_layers``) and Opaque (the nearest
fragment). The planner's choice (Auto), sorted drawing and weighted blending keep no per-pixel
depth order, so deep output refuses them."""

DEEP_SUFFIX = ".deep.exr"
"""A frame's deep image is written to its output path with the format's extension replaced by this."""

SHADING_ITEMS = (
    ("FLAT", "Flat", "One colour per triangle, lit at its provoking vertex with the face normal"),
    ("GOURAUD", "Gouraud", "Lighting at the vertices, colours interpolated (OpenGL fixed function)"),
    ("PHONG", "Phong", "Normals interpolated, lighting per pixel"),
)
"""Shading frequencies (shared with the per-material override in ``addon/properties.py``)."""


@dataclass(frozen=True)
class Setting:
    """How one render setting appears in Blender.

    Attributes:
        label: the property's name in the UI.
        description: its tooltip.
        panel: key of :data:`PANELS` the setting is drawn in.
        items: enum items ``(identifier, label, description)``; empty for other kinds.
        minimum: hard minimum (numbers), or None.
        maximum: hard maximum (numbers), or None.
        soft_max: slider maximum, or None.
        precision: displayed decimals (floats), or None.
        subtype: Blender property subtype (``"COLOR"``, ``"FACTOR"``), or None.
        unit: Blender unit (``"LENGTH"``), or None.
        shown: predicate on the current :class:`RenderOptions`: draw the setting only when True.
    """

    label: str
    description: str = ""
    panel: str = "main"
    items: tuple[tuple[str, str, str], ...] = ()
    minimum: float | None = None
    maximum: float | None = None
    soft_max: float | None = None
    precision: int | None = None
    subtype: str | None = None
    unit: str | None = None
    shown: Callable[[Any], bool] | None = None


def _setting(default: Any, **kwargs: Any) -> Any:
    """A dataclass field with default ``default`` described by ``Setting(**kwargs)``."""
    return field(default=default, metadata={"setting": Setting(**kwargs)})


def _choices(mapping: dict[str, str | None], labels: dict[str, tuple[str, str]]) -> tuple:
    return tuple((key, *labels[key]) for key in mapping)


PANELS: dict[str, str] = {
    "main": "Blinn-Phong",
    "effects": "Transparency, Shadows, Fog",
    "pipeline": "Pipeline",
    "output": "Deep Output",
}
"""Render-tab panels by key -> label; ``main`` is the parent, the others its sub-panels."""


@dataclass(frozen=True)
class RenderOptions:
    """Render settings of the Blinn-Phong engine (``Scene.blinn_phong``), in Blender's own values.

    Each field's ``Setting`` (``dataclasses.fields(RenderOptions)[i].metadata["setting"]``) holds
    its label, tooltip, limits and panel.
    """

    shading: str = _setting(
        "PHONG",
        label="Shading",
        description="Shading frequency for materials that do not override it",
        items=(
            ("AUTO", "Auto", "The planner's choice per mesh: flat where it is exact, else Phong"),
            *SHADING_ITEMS,
        ),
    )
    samples_per_axis: int = _setting(
        2, label="Anti-Aliasing", description="k×k ordered-grid samples per pixel", minimum=1, maximum=8
    )
    specular_model: str = _setting(
        "BLINN",
        label="Specular",
        description="Specular lobe of the lighting equation",
        items=(
            ("BLINN", "Blinn (half vector)", "(n·h)^s, the OpenGL equation"),
            ("PHONG", "Phong (reflection)", "(r·v)^s"),
        ),
    )
    two_sided: bool = _setting(
        True, label="Two-Sided Lighting", description="Light back faces with the flipped normal"
    )
    tolerance: float = _setting(
        0.0,
        label="Tolerance",
        panel="effects",
        minimum=0.0,
        soft_max=64.0,
        precision=1,
        description="Error the planner may accept to choose a faster method, in 8-bit steps "
        "(1/255; max for transparency, mean for shadows; 0: exact only)",
    )
    transparency: str = _setting(
        "AUTO",
        label="Transparency",
        panel="effects",
        description="How transparent surfaces are composited",
        items=_choices(
            TRANSPARENCY_SETTINGS,
            {
                "AUTO": ("Auto", "Let the planner pick a method for the scene and explain why"),
                "OPAQUE": ("Opaque", "Ignore opacity: every surface is opaque"),
                "SORTED": ("Sorted", "Draw transparent triangles back to front and blend (order-dependent)"),
                "A_BUFFER": ("A-Buffer", "Keep every fragment per pixel, sort and composite them exactly"),
                "DEPTH_PEELING": ("Depth Peeling", "Peel layers front to back (exact up to the layer count)"),
                "WEIGHTED": (
                    "Weighted Blended",
                    "Weighted blended order-independent transparency (approximate)",
                ),
            },
        ),
    )
    peel_layers: int = _setting(
        8,
        label="Layers",
        panel="effects",
        description="Depth-peeling layers",
        minimum=1,
        maximum=64,
        shown=lambda o: o.transparency == "DEPTH_PEELING",
    )
    shadows: str = _setting(
        "AUTO",
        label="Shadows",
        panel="effects",
        description="Shadow method for every light that casts shadows (Light › Cast Shadow)",
        items=_choices(
            SHADOW_SETTINGS,
            {
                "AUTO": ("Auto", "Let the planner pick a method for the scene and explain why"),
                "NONE": ("None", "No shadows"),
                "HARD": ("Hard", "Ray-traced hard shadows from point, spot and sun lights"),
                "SOFT": ("Soft", "Ray-traced soft shadows sampling the light's radius"),
                "VOLUME": ("Shadow Volumes", "Exact hard shadows by stencil counting, no ray tracer needed"),
            },
        ),
    )
    shadow_samples: int = _setting(
        16,
        label="Shadow Samples",
        panel="effects",
        description="Rays per pixel toward a light for soft shadows",
        minimum=1,
        maximum=256,
        shown=lambda o: o.shadows == "SOFT",
    )
    shadow_bias: float = _setting(
        1e-3,
        label="Bias",
        panel="effects",
        description="Ray origin offset along the normal, in scene units",
        minimum=0.0,
        maximum=1.0,
        precision=5,
        shown=lambda o: o.shadows in ("HARD", "SOFT"),
    )
    fog: str = _setting(
        "NONE",
        label="Fog",
        panel="effects",
        description="OpenGL fog mode",
        items=(
            ("NONE", "None", "No fog"),
            ("LINEAR", "Linear", "OpenGL GL_LINEAR fog between start and end"),
            ("EXP", "Exponential", "OpenGL GL_EXP fog, exp(-density·z)"),
            ("EXP2", "Exponential Squared", "OpenGL GL_EXP2 fog, exp(-(density·z)²)"),
        ),
    )
    fog_color: tuple[float, float, float] = _setting(
        (0.5, 0.5, 0.5),
        label="Fog Colour",
        panel="effects",
        description="Linear RGB colour of the fog",
        minimum=0.0,
        subtype="COLOR",
        shown=lambda o: o.fog != "NONE",
    )
    fog_start: float = _setting(
        1.0,
        label="Start",
        panel="effects",
        description="Eye distance where linear fog begins",
        minimum=0.0,
        unit="LENGTH",
        shown=lambda o: o.fog == "LINEAR",
    )
    fog_end: float = _setting(
        50.0,
        label="End",
        panel="effects",
        description="Eye distance of full linear fog",
        minimum=0.0,
        unit="LENGTH",
        shown=lambda o: o.fog == "LINEAR",
    )
    fog_density: float = _setting(
        0.1,
        label="Density",
        panel="effects",
        description="Density of exponential fog",
        minimum=0.0,
        shown=lambda o: o.fog in ("EXP", "EXP2"),
    )
    deep_output: bool = _setting(
        False,
        label="Deep EXR",
        panel="output",
        description="Also write each rendered frame's deep image (OpenEXR with R, G, B, A, Z, ZBack: "
        "every fragment the transparency resolve composites, at its camera depth) next to the "
        "frame's output file, named <output path without its extension>.deep.exr. Needs "
        "Transparency A-Buffer, Depth Peeling or Opaque",
    )
    engine: str = _setting(
        "AUTO",
        label="Kernels",
        panel="pipeline",
        description="Which implementation of the renderer's kernels runs",
        items=(
            ("AUTO", "Auto", "Compiled (numba) when it loads, else numpy with a warning"),
            ("NUMPY", "numpy", "The numpy reference implementation"),
        ),
    )
    abort_on_error: bool = _setting(
        True,
        label="Exit on Error in Background",
        panel="pipeline",
        description="In background mode (blender -b), end the process with exit code 1 when a render "
        "fails, so render farms and scripts see the failure",
    )

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            spec: Setting = f.metadata["setting"]
            value = getattr(self, f.name)
            if spec.items:
                allowed = [item[0] for item in spec.items]
                if value not in allowed:
                    raise choice_error(f.name, value, allowed)
            elif isinstance(f.default, bool):
                if not isinstance(value, bool):
                    raise TypeError(f"{f.name}: expected a bool, got {value!r}")
            elif isinstance(f.default, int | float):
                number = int | float | np.integer | np.floating
                if isinstance(value, bool | np.bool_) or not isinstance(value, number):
                    raise ValueError(f"{f.name}: expected a finite number, got {value!r}")
                if not math.isfinite(value):
                    raise ValueError(f"{f.name}: expected a finite number, got {value!r}")
                if isinstance(f.default, int) and not float(value).is_integer():
                    raise ValueError(f"{f.name}: expected an integer, got {value!r}")
                # stored as the field's own type, so every consumer receives what it declares
                value = int(value) if isinstance(f.default, int) else float(value)
                object.__setattr__(self, f.name, value)
                if spec.minimum is not None and value < spec.minimum:
                    raise ValueError(f"{f.name}: expected a value >= {spec.minimum}, got {value!r}")
                if spec.maximum is not None and value > spec.maximum:
                    raise ValueError(f"{f.name}: expected a value <= {spec.maximum}, got {value!r}")

    @property
    def samples(self) -> int:
        """Samples per pixel: ``samples_per_axis²``."""
        return int(self.samples_per_axis) ** 2

    @property
    def core_shading(self) -> str:
        """``blinn_phong.frame.render(shading=...)``: the lower-case shading name."""
        return self.shading.lower()

    @classmethod
    def from_settings(cls, settings: object | None) -> RenderOptions:
        """Read every field from a ``Scene.blinn_phong`` property group (or any object with the same
        attributes); defaults when ``settings`` is None."""
        if settings is None:
            return cls()
        values: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            value = getattr(settings, f.name)
            if isinstance(f.default, tuple):
                value = tuple(float(v) for v in value)
            elif isinstance(f.default, bool):
                value = bool(value)
            elif isinstance(f.default, int):
                value = int(value)
            elif isinstance(f.default, float):
                value = float(value)
            values[f.name] = value
        return cls(**values)


def deep_output_problem(transparency: str) -> str | None:
    """Why a frame with the Transparency setting ``transparency`` cannot have deep output, or None.

    The message names the setting, its value and the values that work (:data:`DEEP_TRANSPARENCY`).
    """
    if transparency in DEEP_TRANSPARENCY:
        return None
    labels = {key: label for key, label, _ in _field_setting("transparency").items}
    names = [labels[key] for key in DEEP_TRANSPARENCY]
    allowed = f"{', '.join(names[:-1])} or {names[-1]}"
    return (
        f"Transparency is {labels.get(transparency, transparency)!r}: deep output keeps each pixel's "
        f"fragments in depth order and needs Transparency {allowed} (Render Properties › "
        f"{PANELS['main']} › {PANELS['effects']}; scene.blinn_phong.transparency)"
    )


def deep_output_path(output: str, extension: str = "") -> str:
    """Where the deep image of a frame whose output file is ``output`` goes.

    ``output`` with its file extension ``extension`` (``RenderSettings.file_extension``, e.g.
    ``".png"``; compared without case) removed, then :data:`DEEP_SUFFIX`:
    ``shot_0001.png`` → ``shot_0001.deep.exr``, ``shot_0001.exr`` → ``shot_0001.deep.exr``. An
    output without that extension (Blender's File Extensions off) keeps its whole name:
    ``shot.v2_0001`` → ``shot.v2_0001.deep.exr``.
    """
    if extension and output.lower().endswith(extension.lower()):
        output = output[: -len(extension)]
    return output + DEEP_SUFFIX


def _field_setting(name: str) -> Setting:
    return next(f.metadata["setting"] for f in dataclasses.fields(RenderOptions) if f.name == name)


def settings() -> tuple[tuple[str, Any, Setting], ...]:
    """``(field name, default, Setting)`` for every field of :class:`RenderOptions`, in order."""
    return tuple((f.name, f.default, f.metadata["setting"]) for f in dataclasses.fields(RenderOptions))


def visible_fields(panel: str, current: RenderOptions) -> list[str]:
    """Names of the fields drawn in ``panel`` for the current values (``Setting.shown``)."""
    if panel not in PANELS:
        raise ValueError(f"panel: expected one of {list(PANELS)}, got {panel!r}")
    return [
        name
        for name, _default, spec in settings()
        if spec.panel == panel and (spec.shown is None or spec.shown(current))
    ]


def blender_property_arguments(name: str) -> tuple[str, dict[str, Any]]:
    """The ``bpy.props`` function name and keyword arguments of the property for field ``name``.

    Returns:
        ``("EnumProperty" | "BoolProperty" | "IntProperty" | "FloatProperty" | "FloatVectorProperty",
        kwargs)``; kwargs hold only what the :class:`Setting` specifies.
    """
    table = {n: (d, s) for n, d, s in settings()}
    if name not in table:
        raise ValueError(f"name: expected a field of RenderOptions, got {name!r}")
    default, spec = table[name]
    kwargs: dict[str, Any] = {"name": spec.label, "description": spec.description, "default": default}
    if spec.items:
        return "EnumProperty", {**kwargs, "items": spec.items}
    if isinstance(default, bool):
        return "BoolProperty", kwargs
    for key, value in (
        ("min", spec.minimum),
        ("max", spec.maximum),
        ("soft_max", spec.soft_max),
        ("precision", spec.precision),
        ("subtype", spec.subtype),
        ("unit", spec.unit),
    ):
        if value is not None:
            kwargs[key] = value
    if isinstance(default, tuple):
        return "FloatVectorProperty", {**kwargs, "size": len(default)}
    if isinstance(default, int):
        for key in ("min", "max", "soft_max"):
            if key in kwargs:
                kwargs[key] = int(kwargs[key])
        kwargs.pop("precision", None)
        return "IntProperty", kwargs
    return "FloatProperty", kwargs
