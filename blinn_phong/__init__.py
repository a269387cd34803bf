"""blinn_phong: a pure numpy local-illumination renderer (no bpy).

Scene model in :mod:`blinn_phong.scene`, the lighting equation in
:mod:`blinn_phong.lighting`, the rasterizer in :mod:`blinn_phong.raster`, the
pipeline in :mod:`blinn_phong.render`, the planner in :mod:`blinn_phong.planner` and
the effects :func:`render` adds when the plan needs them in :mod:`blinn_phong.frame`.
Output follows the project's image conventions: float32 premultiplied linear RGBA,
row 0 at the top.
"""

from blinn_phong.frame import Fog, ShadowOptions
from blinn_phong.lighting import EyeLights, ShadingTerms, gl_clamp, lights_in_eye_space, shade
from blinn_phong.planner import Choice, Plan, plan
from blinn_phong.raster import Fragments, interpolate, rasterize, resolve_nearest
from blinn_phong.render import (
    FragmentShading,
    PreparedScene,
    RenderResult,
    RenderStats,
    prepare_scene,
    render,
    resolve_samples,
    shade_fragments,
)
from blinn_phong.scene import (
    AmbientLight,
    Camera,
    DirectionalLight,
    LightModel,
    Material,
    Mesh,
    PointLight,
    Scene,
    SpotLight,
    look_at,
    orthographic_matrix,
    perspective_matrix,
)
from blinn_phong.visibility import visible_fragments

__all__ = [
    "AmbientLight",
    "Camera",
    "Choice",
    "DirectionalLight",
    "EyeLights",
    "Fog",
    "FragmentShading",
    "Fragments",
    "LightModel",
    "Material",
    "Mesh",
    "Plan",
    "PointLight",
    "PreparedScene",
    "RenderResult",
    "RenderStats",
    "Scene",
    "ShadingTerms",
    "ShadowOptions",
    "SpotLight",
    "gl_clamp",
    "interpolate",
    "lights_in_eye_space",
    "look_at",
    "orthographic_matrix",
    "perspective_matrix",
    "plan",
    "prepare_scene",
    "rasterize",
    "render",
    "resolve_nearest",
    "resolve_samples",
    "shade",
    "shade_fragments",
    "visible_fragments",
]
