"""blinn_phong: a pure numpy local-illumination renderer (no bpy).

Scene model in :mod:`blinn_phong.scene`, the lighting equation in
:mod:`blinn_phong.lighting`, the rasterizer in :mod:`blinn_phong.raster`, the
pipeline in :mod:`blinn_phong.render`. Output follows the project's image
conventions: float32 premultiplied linear RGBA, row 0 at the top.
"""

from blinn_phong.lighting import EyeLights, ShadingTerms, gl_clamp, lights_in_eye_space, shade
from blinn_phong.raster import Fragments, interpolate, rasterize, resolve_nearest, visible_fragments
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

__all__ = [
    "AmbientLight",
    "Camera",
    "DirectionalLight",
    "EyeLights",
    "FragmentShading",
    "Fragments",
    "LightModel",
    "Material",
    "Mesh",
    "PointLight",
    "PreparedScene",
    "RenderResult",
    "RenderStats",
    "Scene",
    "ShadingTerms",
    "SpotLight",
    "gl_clamp",
    "interpolate",
    "lights_in_eye_space",
    "look_at",
    "orthographic_matrix",
    "perspective_matrix",
    "prepare_scene",
    "rasterize",
    "render",
    "resolve_nearest",
    "resolve_samples",
    "shade",
    "shade_fragments",
    "visible_fragments",
]
