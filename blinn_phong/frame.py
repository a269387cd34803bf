"""Effects inside :func:`blinn_phong.render`: the plan, the caller's overrides and the frame.

:func:`blinn_phong.render` asks :func:`blinn_phong.planner.plan` for one method per concern and
replaces a concern's choice only where the caller set one (:func:`frame_plan`). When the final
plan needs no effect — transparency ``zbuffer`` with no per-fragment transparency model,
every light's shadow ``none``, no fog — the frame is the plain z-buffer pipeline of
:mod:`blinn_phong.render`, unchanged. Otherwise :func:`render_effects` runs the order of the
effects issue on the same stages:

1. rasterize every fragment (:func:`blinn_phong.raster.rasterize`);
2. find the fragments that can be seen: the nearest opaque one per sample and the transparent
   ones in front of it (the same depth tests :func:`blinn_phong.oit.transparency_pass` makes);
3. per light, the visibility of those fragments by the chosen shadow method, once per light
   and frame (:func:`blinn_phong.shadows.light_visibility`, or
   :func:`blinn_phong.raytrace.area_light_visibility` for soft shadows);
4. shade them with that visibility (:func:`blinn_phong.render.shade_fragments`), turn each into
   a premultiplied fragment by its material's transparency model (Kay–Greenberg opacity and
   specular wash-out included), then fog it (:func:`blinn_phong.fog.apply_fog`: per fragment,
   before blending, as OpenGL does);
5. resolve opaque and transparent fragments with the chosen transparency method
   (:func:`blinn_phong.oit.transparency_pass`) and box-filter the samples.

The depth, normal and light-pass buffers describe the nearest surface of each sample (opaque or
transparent), exactly as the plain pipeline does; light passes carry the shadowing, not the fog.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from blinn_phong._checks import colour3, number
from blinn_phong.fog import FOG_MODES, apply_fog, eye_distance
from blinn_phong.normals import normalize
from blinn_phong.oit import TRANSPARENCY_METHODS, transparency_pass
from blinn_phong.planner import Choice, Plan, plan
from blinn_phong.raster import interpolate, rasterize, resolve_nearest
from blinn_phong.render import FragmentShading, PreparedScene, resolve_nearest_buffers, resolve_samples
from blinn_phong.scene import SHADINGS, AmbientLight, DirectionalLight, Material, Scene, SpotLight
from blinn_phong.shadows import PCF_KERNELS, SHADOW_METHODS, light_visibility
from blinn_phong.transparency import kay_greenberg_transparency, transparent_fragment, washed_out_opacity

__all__ = [
    "SHADOW_CHOICES",
    "TRANSPARENCY_CHOICES",
    "WBOIT_WEIGHTS",
    "Fog",
    "ShadowOptions",
    "embree_available",
    "frame_plan",
    "needs_effects",
    "render_effects",
    "scene_with_planned_shading",
]

#: Transparency methods render() accepts: the plain z-buffer and every :mod:`blinn_phong.oit` method.
TRANSPARENCY_CHOICES: tuple[str, ...] = ("zbuffer", *TRANSPARENCY_METHODS)
#: Shadow methods render() accepts per light: :data:`blinn_phong.shadows.SHADOW_METHODS` and ``soft``.
SHADOW_CHOICES: tuple[str, ...] = (*SHADOW_METHODS, "soft")
#: Weighted blended OIT weights available on rasterized fragments (they carry window depth):
#: McGuire & Bavoil's eq. 10 and the depth-free α weight.
WBOIT_WEIGHTS: tuple[str, ...] = ("eq10", "constant")
_AUTO = (None, "auto")
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. ITU-R BT.709 luminance of linear RGB


@dataclass(frozen=True)
class ShadowOptions:
    """Shadow settings for one light (or for every light), passed to ``render(shadows=...)``.

    Attributes:
        method: ``None``/``"auto"`` — the planner's choice; or one of :data:`SHADOW_CHOICES`:
            ``none``, ``planar`` (Blinn's projected shadows), ``shadow_map``, ``ray_traced``
            (Embree, exact hard shadows) or ``soft`` (area light of side ``2·radius`` sampled
            on a stratified m×m grid; a directional light or radius 0 falls back to ``ray_traced``).
        resolution: shadow-map size in texels per side (None: the planner's, else 1024).
        constant_bias: shadow-map constant bias in window-depth units (None: 1e-4).
        slope_bias: shadow-map slope-scaled bias (None: 2.0), as ``glPolygonOffset``.
        kernel: percentage-closer filter, one of :data:`blinn_phong.shadows.PCF_KERNELS` (None: nearest).
        plane: ``(a, b, c, d)`` receiving plane for ``planar`` (None: the planner's).
        samples: rays per point for ``soft``; a stratified grid is square, so ``m×m`` rays with
            ``m = round(√samples)`` are cast and, when that differs from ``samples``, the plan's
            reason says so (e.g. 20 → 4×4 = 16).
        radius: half-side of the square area light for ``soft``, world units.
        offset: ray-origin offset along the normal for ``soft``, world units.

    Parameters left at None that the method does not use are ignored.
    """

    method: str | None = None
    resolution: int | None = None
    constant_bias: float | None = None
    slope_bias: float | None = None
    kernel: str | None = None
    plane: tuple[float, float, float, float] | None = None
    samples: int = 16
    radius: float = 0.0
    offset: float = 1e-3

    def __post_init__(self) -> None:
        if self.method not in _AUTO and self.method not in SHADOW_CHOICES:
            raise ValueError(
                f"ShadowOptions.method: expected None, 'auto' or one of {SHADOW_CHOICES}, got {self.method!r}"
            )
        if self.resolution is not None and (
            not isinstance(self.resolution, int | np.integer)
            or isinstance(self.resolution, bool)
            or self.resolution < 1
        ):
            raise ValueError(
                f"ShadowOptions.resolution: expected an integer >= 1 or None, got {self.resolution!r}"
            )
        for name in ("constant_bias", "slope_bias"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, number(getattr(self, name), f"ShadowOptions.{name}", low=0.0))
        if self.kernel is not None and self.kernel not in PCF_KERNELS:
            raise ValueError(
                f"ShadowOptions.kernel: expected one of {PCF_KERNELS} or None, got {self.kernel!r}"
            )
        if self.plane is not None:
            plane = np.asarray(self.plane, dtype=np.float64)
            if plane.shape != (4,) or not np.isfinite(plane).all() or np.linalg.norm(plane[:3]) == 0:
                raise ValueError(
                    f"ShadowOptions.plane: expected finite (a, b, c, d), (a, b, c) != 0, got {self.plane!r}"
                )
            plane = plane / np.linalg.norm(plane[:3])
            object.__setattr__(self, "plane", tuple(float(v) for v in plane))
        if (
            not isinstance(self.samples, int | np.integer)
            or isinstance(self.samples, bool)
            or self.samples < 1
        ):
            raise ValueError(f"ShadowOptions.samples: expected an integer >= 1, got {self.samples!r}")
        object.__setattr__(self, "radius", number(self.radius, "ShadowOptions.radius", low=0.0))
        object.__setattr__(self, "offset", number(self.offset, "ShadowOptions.offset", low=0.0))


@dataclass(frozen=True)
class Fog:
    """Fog by eye distance (OpenGL 2.1 §3.10), passed to ``render(fog=...)``.

    Attributes:
        mode: ``"linear"`` — ``f = (end − c)/(end − start)``; ``"exp"`` — ``f = e^(−density·c)``;
            ``"exp2"`` — ``f = e^(−(density·c)²)``; f clamped to [0, 1] (:func:`blinn_phong.fog.fog_factor`).
        color: linear RGB fog colour ``C_f``.
        density: for ``exp``/``exp2``, per world unit, ≥ 0.
        start: for ``linear``, eye distance where fog begins.
        end: for ``linear``, eye distance of full fog (≠ start).
        distance: ``"plane"`` — ``c = |z_eye|`` (OpenGL's usual); ``"radial"`` — ``c = ‖p_eye‖``.

    Defaults are OpenGL's (GL_EXP, density 1, start 0, end 1, colour black).
    """

    mode: str = "exp"
    color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    density: float = 1.0
    start: float = 0.0
    end: float = 1.0
    distance: str = "plane"

    def __post_init__(self) -> None:
        if self.mode not in FOG_MODES:
            raise ValueError(f"Fog.mode: expected one of {FOG_MODES}, got {self.mode!r}")
        object.__setattr__(self, "color", colour3(self.color, "Fog.color"))
        object.__setattr__(self, "density", number(self.density, "Fog.density", low=0.0))
        object.__setattr__(self, "start", number(self.start, "Fog.start"))
        object.__setattr__(self, "end", number(self.end, "Fog.end"))
        if self.mode == "linear" and self.start == self.end:
            raise ValueError(f"Fog.end: linear fog needs end != start, got start = end = {self.start}")
        if self.distance not in ("plane", "radial"):
            raise ValueError(f"Fog.distance: expected 'plane' or 'radial', got {self.distance!r}")


# --------------------------------------------------------------------------- choices


def _shadow_list(shadows: object, n_lights: int) -> list[ShadowOptions]:
    """Normalise ``render(shadows=...)`` to one :class:`ShadowOptions` per entry of ``scene.lights``."""

    def one(value: object, name: str) -> ShadowOptions:
        if isinstance(value, ShadowOptions):
            return value
        if value in _AUTO or value in SHADOW_CHOICES:
            return ShadowOptions(method=value)  # type: ignore[arg-type]
        raise ValueError(
            f"{name}: expected None, 'auto', one of {SHADOW_CHOICES} or a ShadowOptions, got {value!r}"
        )

    if isinstance(shadows, list | tuple):
        if len(shadows) != n_lights:
            raise ValueError(
                f"shadows: expected one entry per scene light ({n_lights}), got {len(shadows)} entries"
            )
        return [one(v, f"shadows[{i}]") for i, v in enumerate(shadows)]
    return [one(shadows, "shadows")] * n_lights


def _overridden(planned: Choice, what: str) -> str:
    return f"{what} (planner: {planned.method} — {planned.reason})"


#: Shadow methods that cast rays with Embree (:mod:`blinn_phong.raytrace`); ``planar`` tests its
#: points against the projected casters with it too.
_NEEDS_EMBREE = ("ray_traced", "soft", "planar")


def embree_available() -> bool:
    """True when ``embreex`` (Intel Embree) can be imported; Blender's own Python lacks it."""
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


def _shadow_choice(light: object, options: ShadowOptions, planned: Choice) -> Choice:
    """The planner's choice for one light unless ``options.method`` overrides it, with full parameters."""
    if isinstance(light, AmbientLight):
        return planned
    method, reason = planned.method, planned.reason
    if options.method not in _AUTO:
        method = str(options.method)
        if method != planned.method:
            reason = _overridden(planned, "set by the caller")
    if method == "soft" and (isinstance(light, DirectionalLight) or options.radius <= 0.0):
        why = "a directional light" if isinstance(light, DirectionalLight) else "radius 0"
        method, reason = (
            "ray_traced",
            f"soft shadows asked for, but {why} has no area: hard ray-traced shadows",
        )
    if method in ("ray_traced", "planar") and not embree_available():
        method, reason = (
            "shadow_volume",
            f"Embree (embreex) is not installed: shadow volumes, exact too, instead of {method} ({reason})",
        )
    if method in _NEEDS_EMBREE and not embree_available():
        method, reason = (
            "shadow_map",
            f"Embree (embreex) is not installed: a shadow map instead of {method} ({reason})",
        )
        options = replace(options, resolution=options.resolution or 2048)
    params: dict[str, object] = {}
    if method == "shadow_map":
        params["resolution"] = options.resolution or planned.params.get("resolution", 1024)
        for name in ("constant_bias", "slope_bias", "kernel"):
            if getattr(options, name) is not None:
                params[name] = getattr(options, name)
    elif method == "planar":
        plane = options.plane if options.plane is not None else planned.params.get("plane")
        if plane is None:
            raise ValueError(
                "shadows: 'planar' needs the receiving plane; pass ShadowOptions(method='planar', "
                f"plane=(a, b, c, d)) (the planner chose {planned.method!r}, which gives none)"
            )
        params["plane"] = plane
    elif method == "soft":
        m = max(1, round(math.sqrt(options.samples)))
        params = {"samples_per_axis": m, "radius": options.radius, "offset": options.offset}
        if m * m != options.samples:
            reason = f"{reason}; {options.samples} samples asked, {m}×{m} = {m * m} cast (strata are square)"
    if method == planned.method and reason == planned.reason:
        return replace(planned, params=params)  # the planner's choice keeps its predictions
    return Choice(method, reason, params)


def frame_plan(
    scene: Scene,
    *,
    tolerance: float = 0.0,
    shading: str = "auto",
    transparency: str | None = None,
    peel_layers: int | None = None,
    wboit_weight: str = "eq10",
    shadows: object = None,
    gl_compat: bool = False,
    width: int | None = None,
    height: int | None = None,
    samples: int = 1,
) -> Plan:
    """The plan a render follows: :func:`blinn_phong.planner.plan`, with the caller's choices replacing it.

    Each concern is independent: a method the caller sets replaces the planner's choice for that
    concern only, and its reason says so and keeps the planner's own choice and reason.

    Args:
        scene: the scene.
        tolerance: the planner's tolerance in 8-bit steps (see :func:`blinn_phong.planner.plan`), ≥ 0.
        shading: ``"auto"`` — the planner's per-mesh shading frequency; otherwise the render's
            ``shading`` (a mesh's own ``shading`` still wins), as :func:`blinn_phong.render.render` uses it.
        transparency: ``None``/``"auto"`` or one of :data:`TRANSPARENCY_CHOICES`.
        peel_layers: layers for ``depth_peeling`` (None: the planner's, else 8), ≥ 1.
        wboit_weight: weight for ``weighted_blended``, one of :data:`WBOIT_WEIGHTS`.
        shadows: ``None``/``"auto"``, a method of :data:`SHADOW_CHOICES`, a :class:`ShadowOptions`,
            or a list of those with one entry per ``scene.lights`` entry.
        gl_compat: the OpenGL 2.1 preset: no effects (fixed-function OpenGL has neither shadows
            nor order-independent transparency); asking for one raises ``ValueError``.
        width: frame width in pixels, for the cost models (None: the planner's default frame).
        height: frame height in pixels (None: the planner's default frame).
        samples: k for k×k samples per pixel.

    Returns:
        A :class:`~blinn_phong.planner.Plan` whose choices carry the keyword parameters of the
        functions that carry them out.
    """
    if shading != "auto" and shading not in SHADINGS:
        raise ValueError(f"shading: expected 'auto' or one of {SHADINGS}, got {shading!r}")
    if transparency not in _AUTO and transparency not in TRANSPARENCY_CHOICES:
        raise ValueError(
            f"transparency: expected None, 'auto' or one of {TRANSPARENCY_CHOICES}, got {transparency!r}"
        )
    if peel_layers is not None and (
        not isinstance(peel_layers, int | np.integer) or isinstance(peel_layers, bool) or peel_layers < 1
    ):
        raise ValueError(f"peel_layers: expected an integer >= 1 or None, got {peel_layers!r}")
    if wboit_weight not in WBOIT_WEIGHTS:
        raise ValueError(f"wboit_weight: expected one of {WBOIT_WEIGHTS}, got {wboit_weight!r}")
    per_light = _shadow_list(shadows, len(scene.lights))
    planned = plan(scene, tolerance, width=width, height=height, samples=samples)

    if gl_compat:
        if transparency not in (*_AUTO, "zbuffer"):
            raise ValueError(f"transparency: gl_compat renders with the plain z-buffer, got {transparency!r}")
        if any(o.method not in (*_AUTO, "none") for o in per_light):
            raise ValueError(
                "shadows: gl_compat (fixed-function OpenGL 2.1) has no shadows; pass None or 'none'"
            )
        t_choice = Choice(
            "zbuffer", "gl_compat: the nearest fragment, as the fixed-function z-buffer writes it"
        )
        s_choices = tuple(
            c if c.method == "none" else Choice("none", "gl_compat: fixed-function OpenGL 2.1 has no shadows")
            for c in planned.shadows
        )
    else:
        t_choice = planned.transparency
        if transparency not in _AUTO and transparency != t_choice.method:
            t_choice = Choice(str(transparency), _overridden(t_choice, "set by the caller"))
        if t_choice.method == "depth_peeling":
            layers = peel_layers or planned.transparency.params.get("layers", 8)
            t_choice = replace(t_choice, params={"layers": int(layers)})  # type: ignore[arg-type]
        elif t_choice.method == "weighted_blended":
            t_choice = replace(t_choice, params={"wboit_equation": wboit_weight})
        else:
            t_choice = replace(t_choice, params={})  # sorting and the A-buffer take no parameters
        s_choices = tuple(
            _shadow_choice(light, options, c)
            for light, options, c in zip(scene.lights, per_light, planned.shadows, strict=True)
        )

    if shading == "auto":
        shading_choices = planned.shading
    else:
        shading_choices = tuple(
            c
            if mesh.shading is not None or c.method == shading
            else Choice(shading, _overridden(c, f"render(shading={shading!r})"))
            for mesh, c in zip(scene.meshes, planned.shading, strict=True)
        )
    return Plan(t_choice, s_choices, shading_choices, planned.tolerance)


def needs_effects(scene: Scene, the_plan: Plan, fog: Fog | None) -> bool:
    """False when the plain z-buffer pipeline renders ``the_plan`` exactly.

    That is: transparency ``zbuffer``, every shadow ``none``, no fog, and no transparent material
    whose fragment is more than ``(α·c, α)`` with its constant opacity (a transparency model
    other than partial occlusion, Kay–Greenberg or wash-out).
    """
    if fog is not None or the_plan.transparency.method != "zbuffer":
        return True
    if any(c.method != "none" for c in the_plan.shadows):
        return True
    materials = [m for mesh in scene.meshes for m in (mesh.material, mesh.back_material) if m is not None]
    return any(
        m.transparent
        and (m.transparency_model != "partial_occlusion" or m.kay_greenberg is not None or m.specular_washout)
        for m in materials
    )


# --------------------------------------------------------------------------- the frame


def _world_triangles(scene: Scene) -> np.ndarray:
    """(T, 3, 3) world-space triangles in scene order, as :func:`blinn_phong.raytrace.world_triangles`.

    Computed here so that shadow maps and planar shadows work where Embree (``embreex``, which
    :mod:`blinn_phong.raytrace` imports) is not installed, e.g. in Blender's own Python.
    """
    parts = [
        (np.c_[m.positions, np.ones(len(m.positions))] @ m.transform.T)[:, :3][m.triangles]
        for m in scene.meshes
    ]
    return np.concatenate(parts) if parts else np.zeros((0, 3, 3))


def _soft_visibility(
    light: object, params: dict[str, object], ray_scene: object, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """Area-light visibility: a square of side ``2·radius`` at the light, facing along a spot light's
    axis, else towards the centre of the scene's bounding box (never the camera's view)."""
    from blinn_phong.raytrace import area_light_visibility  # Embree: imported only when used

    radius = float(params["radius"])  # type: ignore[arg-type]
    centre = np.asarray(light.position, dtype=np.float64)  # type: ignore[attr-defined]
    corners = ray_scene.triangles.reshape(-1, 3)  # type: ignore[attr-defined]
    axis = (corners.min(axis=0) + corners.max(axis=0)) / 2 - centre
    if isinstance(light, SpotLight):
        axis = np.array(light.direction, dtype=np.float64)
    if float(np.linalg.norm(axis)) < 1e-12:
        axis = np.array([0.0, 0.0, -1.0])  # the light at the scene's centre: any orientation
    axis /= float(np.linalg.norm(axis))
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    return area_light_visibility(
        ray_scene,
        points,
        normals,
        centre - radius * (u + v),
        2 * radius * u,
        2 * radius * v,
        samples_per_axis=int(params["samples_per_axis"]),  # type: ignore[call-overload]
        offset=float(params["offset"]),  # type: ignore[arg-type]
    )


def _side_tables(scene: Scene) -> tuple[list[Material], np.ndarray]:
    """Materials indexed ``2·mesh + back`` (back faces under two-sided lighting), and their opacity flag."""
    materials = [m for mesh in scene.meshes for m in (mesh.material, mesh.back_material or mesh.material)]
    opaque = np.array([not m.transparent for m in materials], dtype=bool)
    return materials, opaque


def _fragment_rgba(
    shaded: FragmentShading,
    eye_normal_z: np.ndarray,
    side: np.ndarray,
    materials: list[Material],
) -> tuple[np.ndarray, np.ndarray]:
    """Premultiplied fragment RGBA by each material's transparency model, and the opacity used.

    Opacity is the material's, or Kay–Greenberg's ``1 − t(N_z)``; wash-out raises it to
    ``min(1, α + luminance(specular))``. The fragment is
    :func:`blinn_phong.transparency.transparent_fragment` of ``Material.transparency_model``
    (partial occlusion ``(α·c, α)``, emission ``(α·c, 0)``, absorption ``(c, α)``); opaque
    materials give ``(c, 1)``.
    """
    alpha = shaded.alpha.copy()
    rgba = np.empty((len(alpha), 4))
    for s in np.unique(side):
        material = materials[s]
        here = side == s
        if material.kay_greenberg is not None:
            t_min, t_max, power = material.kay_greenberg
            alpha[here] = 1.0 - kay_greenberg_transparency(
                np.clip(eye_normal_z[here], -1.0, 1.0), t_min, t_max, power
            )
        if material.specular_washout:
            highlight = np.maximum(shaded.specular[here] @ _LUMINANCE, 0.0)
            alpha[here] = washed_out_opacity(1.0 - alpha[here], highlight)
        model = material.transparency_model if material.transparent else "partial_occlusion"
        rgba[here] = transparent_fragment(shaded.rgb[here], alpha[here], model)
    return rgba, alpha


def render_effects(
    prepared: PreparedScene,
    width: int,
    height: int,
    the_plan: Plan,
    *,
    shade: Callable[..., FragmentShading],
    samples: int = 1,
    cull_backfaces: bool = False,
    fog: Fog | None = None,
    seconds: dict[str, float],
    report: Callable[[str, float], None],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray], int]:
    """Render ``prepared`` with the transparency and shadow methods of ``the_plan`` and ``fog``.

    Args:
        prepared: from :func:`blinn_phong.render.prepare_scene`.
        width: image width in pixels.
        height: image height in pixels.
        the_plan: from :func:`frame_plan` (choices carry their parameters).
        shade: ``shade(fragments, visibility) -> FragmentShading`` — the render's
            :func:`~blinn_phong.render.shade_fragments` with its shading and engine bound.
        samples: k² samples per pixel, as for :func:`blinn_phong.render.render`.
        cull_backfaces: discard clockwise triangles.
        fog: per-fragment fog, or None.
        seconds: per-stage wall times are added to this dict.
        report: ``report(stage, fraction_done)``.

    Returns:
        ``(rgba, depth, normal, passes, shaded)``: (H, W, 4) float32 premultiplied linear RGBA,
        (H, W) float32 nearest window depth (1 = empty), (H, W, 3) float32 world normal of the
        nearest surface, ``ambient``/``diffuse``/``specular`` (H, W, 3) float32 premultiplied
        passes of the nearest surface (plus ``shadow`` (H, W, 1), the mean light visibility
        weighted like them, when a light casts shadows), and the number of fragments shaded.
    """
    scene = prepared.scene
    t = time.perf_counter()
    fragments = rasterize(
        prepared.clip, prepared.triangles, width, height, samples=samples, cull_backfaces=cull_backfaces
    )
    seconds["visibility"] = time.perf_counter() - t
    report("visibility", 0.3)

    # Which fragments can be seen: the opaque z-buffer, then transparent ones in front of it.
    materials, side_opaque = _side_tables(scene)
    two_sided = scene.light_model.two_sided
    back = ~fragments.front_facing if two_sided else np.zeros(len(fragments), dtype=bool)
    side = 2 * prepared.triangle_mesh[fragments.triangle] + back
    method = the_plan.transparency.method
    opaque = np.ones(len(fragments), dtype=bool) if method == "zbuffer" else side_opaque[side]
    key = fragments.sample_key
    n_keys = width * height * fragments.samples
    opaque_depth = np.ones(n_keys)
    np.minimum.at(opaque_depth, key[opaque], fragments.depth[opaque])
    seen = np.where(opaque, fragments.depth == opaque_depth[key], fragments.depth < opaque_depth[key])
    needed = np.flatnonzero(seen)
    row_of = np.full(len(fragments), -1, dtype=np.int64)
    row_of[needed] = np.arange(len(needed))
    visible = fragments.subset(needed)
    eye = interpolate(visible, prepared.triangles, prepared.eye_position)

    # Shadows: per light, the visibility of every fragment that can be seen, once.
    t = time.perf_counter()
    lit = [
        (light, c)
        for light, c in zip(scene.lights, the_plan.shadows, strict=True)
        if not isinstance(light, AmbientLight)
    ]
    visibility = None
    if any(c.method != "none" for _, c in lit):
        world = (np.c_[eye, np.ones(len(eye))] @ np.linalg.inv(scene.camera.view).T)[:, :3]
        normal = prepared.face_world_normal[visible.triangle]
        tris = _world_triangles(scene)
        ray_scene: list[object] = []
        columns = []
        for light, c in lit:
            if c.method == "soft":
                if not ray_scene:
                    from blinn_phong.raytrace import RayScene  # Embree: imported only when used

                    ray_scene.append(RayScene(tris))
                columns.append(_soft_visibility(light, c.params, ray_scene[0], world, normal))
            else:
                extra = {"camera": scene.camera} if c.method == "shadow_volume" else {}
                columns.append(light_visibility(c.method, light, tris, world, normal, **c.params, **extra))  # type: ignore[arg-type]
        visibility = np.stack(columns, axis=1) if columns else None
    seconds["shadows"] = time.perf_counter() - t
    report("shadows", 0.5)

    # Shade what can be seen, once; fragments by transparency model; fog per fragment.
    t = time.perf_counter()
    shaded = shade(visible, visibility)
    eye_nz = normalize(interpolate(visible, prepared.triangles, prepared.eye_normal))[:, 2]
    frag_rgba, frag_alpha = _fragment_rgba(shaded, eye_nz, side[needed], materials)
    if fog is not None:
        frag_rgba = apply_fog(
            frag_rgba,
            eye_distance(eye, fog.distance),  # type: ignore[arg-type]
            fog.color,
            fog.mode,  # type: ignore[arg-type]
            density=fog.density,
            start=fog.start,
            end=fog.end,
        )
    seconds["shade"] = time.perf_counter() - t
    report("shade", 0.8)

    t = time.perf_counter()
    per_sample, _ = transparency_pass(
        fragments,
        opaque,
        lambda index: frag_rgba[row_of[index]],
        method,
        triangle_mesh=prepared.triangle_mesh,
        triangle_eye_distance=-prepared.face_eye_centroid[:, 2],
        **the_plan.transparency.params,  # type: ignore[arg-type]
    )
    seconds["transparency"] = time.perf_counter() - t

    # The nearest surface of each sample (opaque or transparent): depth, normal and light passes.
    t = time.perf_counter()
    winner = resolve_nearest(visible)
    covered = np.flatnonzero(winner >= 0)
    nearest = winner[covered]
    near = FragmentShading(
        shaded.rgb[nearest],
        frag_alpha[nearest],
        shaded.ambient[nearest],
        shaded.diffuse[nearest],
        shaded.specular[nearest],
        shaded.normal[nearest],
    )
    _, passes, normal_img, depth = resolve_nearest_buffers(
        near, covered, visible.depth[nearest], width, height, fragments.samples, "numpy"
    )
    if visibility is not None:
        buf = np.zeros((n_keys, 1), np.float32)
        buf[covered, 0] = visibility[nearest].mean(axis=1) * frag_alpha[nearest]
        passes["shadow"] = resolve_samples(buf, width, height, fragments.samples)
    rgba = resolve_samples(per_sample, width, height, fragments.samples).astype(np.float32)
    seconds["resolve_samples"] = time.perf_counter() - t
    return rgba, depth, normal_img, passes, len(needed)


def scene_with_planned_shading(scene: Scene, the_plan: Plan, shading: str) -> Scene:
    """``scene`` with each mesh's shading from ``the_plan`` when ``shading == "auto"`` (else unchanged)."""
    if shading != "auto":
        return scene
    meshes = tuple(
        m if m.shading == c.method else replace(m, shading=c.method)  # type: ignore[arg-type]
        for m, c in zip(scene.meshes, the_plan.shading, strict=True)
    )
    return replace(scene, meshes=meshes)
