"""The render pipeline the engine runs: plan, then render with or without effects (no bpy).

1. ``blinn_phong.planner.plan`` decides transparency and shadow methods and says why; the user's
   settings override it per concern ("Auto" keeps the planner's choice).
2. Without transparency, shadows or fog the frame is ``blinn_phong.render`` itself (the reference).
3. Otherwise the frame follows the integration recipe of ``docs/effects.md``: rasterize every
   fragment, shade with per-light visibility (``blinn_phong.shadows.light_visibility``, or
   ``raytrace.area_light_visibility`` for soft shadows), fog each fragment before blending as
   OpenGL does (``blinn_phong.fog``), resolve opaque and transparent fragments with
   ``blinn_phong.oit.transparency_pass`` and box-filter the samples.

Outputs follow the project conventions (float32 premultiplied linear RGBA, row 0 at the top).
Light passes (ambient, diffuse, specular) and the shadow pass describe the nearest *opaque*
surface of each sample, weighted by coverage; without transparent surfaces the light passes sum
to the Combined colour (before fog).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from blinn_phong.fog import apply_fog, eye_distance
from blinn_phong.normals import normalize
from blinn_phong.oit import transparency_pass
from blinn_phong.planner import Choice, plan
from blinn_phong.raster import interpolate, rasterize, resolve_nearest
from blinn_phong.render import prepare_scene, render, resolve_samples, shade_fragments
from blinn_phong.scene import AmbientLight, DirectionalLight, Scene
from blinn_phong.shadows import light_visibility
from blinn_phong.transparency import kay_greenberg_transparency

__all__ = ["TRANSPARENCY_SETTINGS", "EffectOptions", "FrameResult", "render_frame"]

TRANSPARENCY_SETTINGS: dict[str, str | None] = {
    "AUTO": None,
    "OPAQUE": "zbuffer",
    "SORTED": "sort_objects",
    "A_BUFFER": "a_buffer",
    "DEPTH_PEELING": "depth_peeling",
    "WEIGHTED": "weighted_blended",
}
"""Render-setting value -> ``blinn_phong.oit`` method (None: the planner's choice)."""

SHADOW_SETTINGS: dict[str, str | None] = {"AUTO": None, "NONE": "none", "HARD": "ray_traced", "SOFT": "soft"}
"""Render-setting value -> shadow method (``soft`` = area-light sampling over the light's radius)."""


@dataclass(frozen=True)
class EffectOptions:
    """Effect settings (the engine fills them from ``Scene.blinn_phong``).

    Attributes:
        transparency: key of :data:`TRANSPARENCY_SETTINGS`.
        peel_layers: layers for depth peeling.
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
        kay: per entry of ``scene.meshes``, ``(t_min, t_max, power)`` for Kay-Greenberg glass
            (``blinn_phong.transparency.kay_greenberg_transparency``: opacity ``1 − t`` varies with
            the eye-space normal), or None for the material's constant opacity; empty = none.
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
    kay: tuple[tuple[float, float, float] | None, ...] = ()

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
        depth: (H, W) float32 window depth of the nearest opaque surface (1 = empty).
        passes: ``ambient``, ``diffuse``, ``specular`` (H, W, 3) and ``shadow`` (H, W, 1) float32.
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


def embree_available() -> bool:
    """True when ``embreex`` (Embree ray casting) imports; Blender's own Python does not ship it."""
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


def _world_triangles(scene: Scene) -> np.ndarray:
    """(T, 3, 3) world-space triangles in scene order (``blinn_phong.raytrace.world_triangles``).

    ``blinn_phong.raytrace`` imports Embree at module level; without it the same transform is done here.
    """
    try:
        from blinn_phong.raytrace import world_triangles
    except ImportError:
        parts = [
            (np.c_[m.positions, np.ones(len(m.positions))] @ m.transform.T)[:, :3][m.triangles]
            for m in scene.meshes
        ]
        return np.concatenate(parts) if parts else np.zeros((0, 3, 3))
    return world_triangles(scene)[0]


def _without_embree(choice: Choice) -> Choice:
    """A shadow choice that needs no Embree: ray-traced and soft shadows become shadow maps."""
    if choice.method == "ray_traced":
        params = {"resolution": 2048, "kernel": "box3"}
    elif choice.method == "soft":
        params = {"resolution": 2048, "kernel": "box7"}
    else:
        return choice
    reason = (
        f"Embree (embreex) is not available here: shadow map instead of {choice.method} ({choice.reason})"
    )
    return Choice("shadow_map", reason, params)


def _planning_scene(scene: Scene, kay: tuple[tuple[float, float, float] | None, ...]) -> Scene:
    """``scene`` with each Kay-Greenberg mesh at its lowest opacity, ``1 − max(t_min, t_max)``."""
    if not any(kay):
        return scene
    meshes = tuple(
        m
        if k is None
        else replace(m, material=replace(m.material, opacity=min(m.material.opacity, 1 - max(k[:2]))))
        for m, k in zip(scene.meshes, kay, strict=True)
    )
    return replace(scene, meshes=meshes)


def _choices(scene: Scene, options: EffectOptions) -> tuple[Choice, list[Choice], list[str]]:
    """Transparency and per-light shadow choices: the planner's, overridden by the settings."""
    the_plan = plan(_planning_scene(scene, options.kay), options.tolerance)
    lines = []
    transparency = the_plan.transparency
    forced = TRANSPARENCY_SETTINGS[options.transparency]
    if forced is not None:
        params = {"layers": options.peel_layers} if forced == "depth_peeling" else {}
        transparency = Choice(
            forced, f"set in the render settings (planner: {the_plan.transparency.method})", params
        )
    elif transparency.method == "depth_peeling" and "layers" not in transparency.params:
        transparency = Choice(transparency.method, transparency.reason, {"layers": options.peel_layers})
    lines.append(f"transparency: {transparency}")
    shadows = []
    forced_shadow = SHADOW_SETTINGS[options.shadows]
    embree = embree_available()
    for i, (light, choice) in enumerate(zip(scene.lights, the_plan.shadows, strict=True)):
        if isinstance(light, AmbientLight):
            continue
        if forced_shadow is not None:
            choice = Choice(forced_shadow, f"set in the render settings (planner: {choice.method})")
        if not embree:
            choice = _without_embree(choice)
        shadows.append(choice)
        lines.append(f"shadows, light {i}: {choice}")
    return transparency, shadows, lines


def _visibility(
    choice: Choice,
    light: object,
    radius: float,
    tris: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    options: EffectOptions,
    ray_scene: Callable[[], object],
) -> np.ndarray:
    if choice.method != "soft":
        return light_visibility(choice.method, light, tris, points, normals, **choice.params)
    m = max(1, round(math.sqrt(options.shadow_samples)))
    if isinstance(light, DirectionalLight) or radius <= 0.0:
        return light_visibility("ray_traced", light, tris, points, normals)
    # A square of side 2r centred on the light, facing the centroid of the receivers.
    centre = np.asarray(light.position, dtype=np.float64)
    axis = points.mean(axis=0) - centre
    axis /= max(np.linalg.norm(axis), 1e-12)
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    corner = centre - radius * (u + v)
    from blinn_phong.raytrace import area_light_visibility

    return area_light_visibility(
        ray_scene(),
        points,
        normals,
        corner,
        2 * radius * u,
        2 * radius * v,
        samples_per_axis=m,
        offset=options.shadow_bias,
    )


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
        :class:`FrameResult`; ``choices["reasons"]`` holds one line per decision.
    """
    options = options or EffectOptions()
    kay = options.kay or (None,) * len(scene.meshes)
    if len(kay) != len(scene.meshes):
        raise ValueError(f"options.kay: expected one entry per mesh ({len(scene.meshes)}), got {len(kay)}")
    seconds: dict[str, float] = {}
    t = time.perf_counter()
    transparency, shadow_choices, reasons = _choices(scene, options)
    seconds["plan"] = time.perf_counter() - t
    choices: dict[str, object] = {
        "shading": shading,
        "samples": samples,
        "transparency": transparency.method,
        "shadows": [c.method for c in shadow_choices],
        "fog": options.fog,
        "reasons": reasons,
    }
    has_transparent = any(m.material.opacity < 1.0 for m in scene.meshes) or any(kay)
    plain = (
        (transparency.method == "zbuffer" or not has_transparent)
        and all(c.method == "none" for c in shadow_choices)
        and options.fog == "NONE"
    )
    if plain:
        choices["pipeline"] = "z-buffer (blinn_phong.render)"
        result = render(scene, width, height, shading=shading, samples=samples, progress=progress)
        seconds.update(result.stats.seconds)
        passes = dict(result.passes)
        passes["shadow"] = result.rgba[..., 3:4].copy()
        return FrameResult(result.rgba, result.depth, passes, choices, seconds, result.stats.triangles)

    choices["pipeline"] = "effects (docs/effects.md recipe)"
    report = progress or (lambda stage, fraction: None)
    t = time.perf_counter()
    prepared = prepare_scene(scene)
    fragments = rasterize(prepared.clip, prepared.triangles, width, height, samples=samples)
    seconds["rasterize"] = time.perf_counter() - t
    report("rasterize", 0.3)
    tris = _world_triangles(scene)
    radii = options.light_radii or (0.0,) * len(scene.lights)
    if len(radii) != len(scene.lights):
        raise ValueError(f"options.light_radii: expected {len(scene.lights)} radii, got {len(radii)}")
    non_ambient = [i for i, light in enumerate(scene.lights) if not isinstance(light, AmbientLight)]
    lit = [(scene.lights[i], c, radii[i]) for i, c in zip(non_ambient, shadow_choices, strict=True)]
    inv_view = np.linalg.inv(scene.camera.view)
    kay_mesh = np.array([k is not None for k in kay], dtype=bool)
    cache: dict[str, object] = {}
    known = np.zeros(len(fragments), dtype=bool)
    visibility_all = np.ones((len(fragments), len(lit)))

    def ray_scene() -> object:
        if "scene" not in cache:
            from blinn_phong.raytrace import RayScene

            cache["scene"] = RayScene(tris)
        return cache["scene"]

    def visibility_of(index: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        """Per-light visibility of fragments ``index`` (computed once each) and their eye positions."""
        f = fragments.subset(index)
        eye = interpolate(f, prepared.triangles, prepared.eye_position)
        if not lit:
            return None, eye
        todo = index[~known[index]]
        if len(todo):
            g = fragments.subset(todo)
            g_eye = interpolate(g, prepared.triangles, prepared.eye_position)
            world = (np.c_[g_eye, np.ones(len(g_eye))] @ inv_view.T)[:, :3]
            normal = prepared.face_world_normal[g.triangle]
            visibility_all[todo] = np.stack(
                [_visibility(c, light, r, tris, world, normal, options, ray_scene) for light, c, r in lit],
                axis=1,
            )
            known[todo] = True
        return visibility_all[index], eye

    def shade(index: np.ndarray) -> np.ndarray:
        f = fragments.subset(index)
        vis, eye = visibility_of(index)
        s = shade_fragments(prepared, f, shading=shading, visibility=vis)
        alpha = s.alpha
        glass = kay_mesh[prepared.triangle_mesh[f.triangle]]
        if glass.any():
            alpha = alpha.copy()
            normal_z = normalize(
                interpolate(f.subset(np.flatnonzero(glass)), prepared.triangles, prepared.eye_normal)
            )[:, 2]
            owner = prepared.triangle_mesh[f.triangle[glass]]
            for m in np.unique(owner):
                t_min, t_max, power = kay[m]
                here = owner == m
                alpha[np.flatnonzero(glass)[here]] = 1.0 - kay_greenberg_transparency(
                    np.clip(normal_z[here], -1.0, 1.0), t_min, t_max, power
                )
        rgba = np.c_[s.rgb * alpha[:, None], alpha]
        if options.fog != "NONE":
            rgba = apply_fog(
                rgba,
                eye_distance(eye),
                options.fog_color,
                options.fog.lower(),
                density=options.fog_density,
                start=options.fog_start,
                end=options.fog_end,
            )
        return rgba

    t = time.perf_counter()
    opacity = np.array([m.material.opacity for m in scene.meshes])[prepared.triangle_mesh]
    opaque = (opacity[fragments.triangle] >= 1.0) & ~kay_mesh[prepared.triangle_mesh[fragments.triangle]]
    per_sample, depth_samples = transparency_pass(
        fragments,
        opaque,
        shade,
        transparency.method,
        triangle_mesh=prepared.triangle_mesh,
        triangle_eye_distance=-prepared.face_eye_centroid[:, 2],
        **transparency.params,
    )
    seconds["shade_and_resolve"] = time.perf_counter() - t
    report("shade", 0.8)

    # Passes of the nearest opaque surface (coverage-weighted), with the same visibility.
    t = time.perf_counter()
    opaque_index = np.flatnonzero(opaque)
    winner = resolve_nearest(fragments.subset(opaque_index))
    covered = np.flatnonzero(winner >= 0)
    visible_index = opaque_index[winner[covered]]
    visible = fragments.subset(visible_index)
    vis, _ = visibility_of(visible_index)
    terms = shade_fragments(prepared, visible, shading=shading, visibility=vis)
    n_keys = len(winner)

    def per_key(values: np.ndarray) -> np.ndarray:
        buf = np.zeros((n_keys, values.shape[1]))
        buf[covered] = values
        return resolve_samples(buf, width, height, samples).astype(np.float32)

    a = terms.alpha[:, None]
    passes = {name: per_key(getattr(terms, name) * a) for name in ("ambient", "diffuse", "specular")}
    shadow_values = (vis.mean(axis=1, keepdims=True) if vis is not None else np.ones((len(covered), 1))) * a
    passes["shadow"] = per_key(shadow_values)
    seconds["passes"] = time.perf_counter() - t
    rgba = resolve_samples(per_sample, width, height, samples).astype(np.float32)
    depth = depth_samples.reshape(height, width, samples).min(axis=2).astype(np.float32)
    report("done", 1.0)
    return FrameResult(rgba, depth, passes, choices, seconds, len(prepared.triangles))
