"""The engine's render settings -> ``blinn_phong.render`` (no bpy).

``blinn_phong.render`` plans transparency and shadows (``blinn_phong.planner``), renders the
effects the plan needs (``blinn_phong.frame``) and returns the plan with a reason per decision.
This module only translates the add-on's settings into its arguments ("Auto" = the planner's
choice). In Blender's own Python, which has no Embree (``embreex``), ``render`` itself replaces
ray-traced and planar shadows by shadow volumes and soft shadows by shadow maps, and says so in
the plan.

Outputs follow the project conventions (float32 premultiplied linear RGBA, row 0 at the top).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from blinn_phong import Fog, ShadowOptions, render
from blinn_phong.scene import AmbientLight, Scene

__all__ = [
    "SHADOW_SETTINGS",
    "TRANSPARENCY_SETTINGS",
    "EffectOptions",
    "FrameResult",
    "render_frame",
]

TRANSPARENCY_SETTINGS: dict[str, str | None] = {
    "AUTO": None,
    "OPAQUE": "zbuffer",
    "SORTED": "sort_objects",
    "A_BUFFER": "a_buffer",
    "DEPTH_PEELING": "depth_peeling",
    "WEIGHTED": "weighted_blended",
}
"""Render-setting value -> ``render(transparency=...)`` (None: the planner's choice)."""

SHADOW_SETTINGS: dict[str, str | None] = {
    "AUTO": None,
    "NONE": "none",
    "HARD": "ray_traced",
    "SOFT": "soft",
    "VOLUME": "shadow_volume",
}
"""Render-setting value -> shadow method (None: the planner's choice per light)."""


@dataclass(frozen=True)
class EffectOptions:
    """Effect settings (the engine fills them from ``Scene.blinn_phong``).

    Attributes:
        transparency: key of :data:`TRANSPARENCY_SETTINGS`.
        peel_layers: layers for depth peeling when it is set explicitly (Auto keeps the planner's).
        shadows: key of :data:`SHADOW_SETTINGS`.
        shadow_samples: rays per point toward a light for soft shadows (rounded to m×m).
        shadow_bias: ray-origin offset along the normal for soft shadows, scene units.
        light_radii: radius per entry of ``scene.lights`` (soft shadows), scene units.
        fog: ``"NONE"``, ``"LINEAR"``, ``"EXP"`` or ``"EXP2"``.
        fog_color: linear RGB.
        fog_density: for EXP/EXP2.
        fog_start: for LINEAR, eye distance where fog begins.
        fog_end: for LINEAR, eye distance of full fog.
        tolerance: the planner's tolerance (0: exact methods only).
    """

    transparency: str = "AUTO"
    peel_layers: int = 8
    shadows: str = "AUTO"
    shadow_samples: int = 16
    shadow_bias: float = 1e-3
    light_radii: tuple[float, ...] = ()
    fog: str = "NONE"
    fog_color: tuple[float, float, float] = (0.5, 0.5, 0.5)
    fog_density: float = 0.1
    fog_start: float = 1.0
    fog_end: float = 50.0
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        if self.transparency not in TRANSPARENCY_SETTINGS:
            raise ValueError(
                f"transparency: expected one of {list(TRANSPARENCY_SETTINGS)}, got {self.transparency!r}"
            )
        if self.shadows not in SHADOW_SETTINGS:
            raise ValueError(f"shadows: expected one of {list(SHADOW_SETTINGS)}, got {self.shadows!r}")
        if self.fog not in ("NONE", "LINEAR", "EXP", "EXP2"):
            raise ValueError(f"fog: expected NONE, LINEAR, EXP or EXP2, got {self.fog!r}")


@dataclass
class FrameResult:
    """One rendered frame (row 0 at the top).

    Attributes:
        rgba: (H, W, 4) float32 premultiplied linear RGBA.
        depth: (H, W) float32 window depth of the nearest surface (1 = empty).
        passes: ``ambient``, ``diffuse``, ``specular`` (H, W, 3) and ``shadow`` (H, W, 1) float32,
            premultiplied by coverage; ``shadow`` is the mean light visibility (coverage when
            nothing casts a shadow).
        choices: what was done for each concern and why (for the Render panel and reports).
        seconds: wall time per stage.
        triangles: input triangle count.
    """

    rgba: np.ndarray
    depth: np.ndarray
    passes: dict[str, np.ndarray]
    choices: dict[str, object]
    seconds: dict[str, float] = field(default_factory=dict)
    triangles: int = 0


def _shadow_argument(scene: Scene, options: EffectOptions) -> object:
    """``render(shadows=...)``: None (the planner's choice per light), one method for every light, or
    one ``ShadowOptions`` per light for soft shadows (each light's own radius)."""
    method = SHADOW_SETTINGS[options.shadows]
    if method != "soft":
        return method
    radii = options.light_radii or (0.0,) * len(scene.lights)
    if len(radii) != len(scene.lights):
        raise ValueError(f"options.light_radii: expected {len(scene.lights)} radii, got {len(radii)}")
    return [
        ShadowOptions(
            method="soft", samples=options.shadow_samples, radius=radius, offset=options.shadow_bias
        )
        for radius in radii
    ]


def render_frame(
    scene: Scene,
    width: int,
    height: int,
    *,
    shading: str = "phong",
    samples: int = 1,
    options: EffectOptions | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> FrameResult:
    """Render ``scene`` (``width × height``, ``samples`` = k² per pixel) with the effects in ``options``.

    Returns:
        :class:`FrameResult`; ``choices["reasons"]`` holds one line per decision of the plan that
        was followed.
    """
    options = options or EffectOptions()
    shadows = _shadow_argument(scene, options)
    fog = None
    if options.fog != "NONE":
        fog = Fog(
            mode=options.fog.lower(),
            color=options.fog_color,
            density=options.fog_density,
            start=options.fog_start,
            end=options.fog_end,
        )
    result = render(
        scene,
        width,
        height,
        shading=shading,
        samples=samples,
        progress=progress,
        transparency=TRANSPARENCY_SETTINGS[options.transparency],
        peel_layers=options.peel_layers if options.transparency == "DEPTH_PEELING" else None,
        shadows=shadows,
        fog=fog,
        tolerance=options.tolerance,
    )
    passes = dict(result.passes)
    passes.setdefault("shadow", result.rgba[..., 3:4].copy())
    followed = result.plan
    lit = [i for i, light in enumerate(scene.lights) if not isinstance(light, AmbientLight)]
    choices: dict[str, object] = {
        "shading": shading,
        "samples": samples,
        "transparency": followed.transparency.method,
        "shadows": [followed.shadows[i].method for i in lit],
        "fog": options.fog,
        "reasons": followed.reasons(),
    }
    return FrameResult(
        result.rgba, result.depth, passes, choices, dict(result.stats.seconds), result.stats.triangles
    )
