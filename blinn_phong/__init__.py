"""blinn_phong: a local-illumination renderer (numpy reference, compiled numba engine; no bpy).

Scene model in :mod:`blinn_phong.model.scene`, the lighting equation in :mod:`blinn_phong.frame.lighting`,
the planner in :mod:`blinn_phong.planning.planner` and the plan of a frame with the caller's options in
:mod:`blinn_phong.planning.frame_plan`. :func:`render` runs one pipeline
(:mod:`blinn_phong.frame.pipeline`) whose
stages flow one way: :mod:`~blinn_phong.frame.prepared` → :mod:`~blinn_phong.geometry.raster` (fragments) →
:mod:`~blinn_phong.frame.visibility` → :mod:`~blinn_phong.frame.shading` → :mod:`~blinn_phong.frame.resolve`;
effects (transparency, shadows, fog) are stages of that frame. Output follows the project's
image conventions: float32 premultiplied linear RGBA, row 0 at the top.
"""

from blinn_phong._scratch import release_scratch
from blinn_phong.frame.id_passes import Cryptomatte
from blinn_phong.frame.light_groups import LightGroups
from blinn_phong.frame.lighting import EyeLights, ShadingTerms, gl_clamp, lights_in_eye_space, shade
from blinn_phong.frame.render import (
    FragmentShading,
    PreparedScene,
    RenderResult,
    RenderStats,
    prepare_scene,
    render,
    resolve_samples,
    shade_fragments,
)
from blinn_phong.frame.visibility import visible_fragments
from blinn_phong.geometry.raster import Fragments, interpolate, rasterize, resolve_nearest
from blinn_phong.model.lights import AmbientLight, DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Camera, LightLink, LightModel, Material, Mesh, Scene
from blinn_phong.model.texture import Texture
from blinn_phong.model.transforms import look_at, orthographic_matrix, perspective_matrix
from blinn_phong.planning.frame_plan import Fog, ShadowOptions
from blinn_phong.planning.planner import Choice, Plan, plan
from compositing._kernel_cache import register_package

# The compiled kernels are cached once per user and machine, shared by every checkout
# (compositing/_kernel_cache.py); registered before any kernel module is imported.
register_package(__path__[0])

__all__ = [
    "AmbientLight",
    "Camera",
    "Choice",
    "Cryptomatte",
    "DirectionalLight",
    "EyeLights",
    "Fog",
    "FragmentShading",
    "Fragments",
    "LightGroups",
    "LightLink",
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
    "Texture",
    "gl_clamp",
    "interpolate",
    "lights_in_eye_space",
    "look_at",
    "orthographic_matrix",
    "perspective_matrix",
    "plan",
    "prepare_scene",
    "rasterize",
    "release_scratch",
    "render",
    "resolve_nearest",
    "resolve_samples",
    "shade",
    "shade_fragments",
    "visible_fragments",
]
