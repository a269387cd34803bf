"""``render()``: plan the frame, then run the one pipeline (:mod:`blinn_phong.frame.pipeline`).

The stages, each a public function in its own module, in the order the data flows:

* :func:`blinn_phong.frame.prepared.prepare_scene` — every mesh to eye and clip space, lights to eye space;
* :func:`blinn_phong.frame.visibility.frame_fragments` — the fragments that can be seen (the z-buffer
  pass, plus the transparent fragments in front of the opaque depth);
  :func:`blinn_phong.frame.visibility.visible_fragments` is the z-buffer pass alone;
* :func:`blinn_phong.frame.shading.shade_fragments` — the lighting equation at any set of fragments, at
  the mesh's shading frequency (flat / Gouraud / Phong);
* :func:`blinn_phong.frame.resolve.fragment_colours` and :func:`blinn_phong.frame.resolve.resolve_frame` —
  transparency models, fog, the transparency resolve and the box filter
  (:func:`blinn_phong.frame.resolve.resolve_samples`), giving coverage alpha.

The names those modules define are re-exported here (``blinn_phong.frame.render.shade_fragments`` …)
as before. With no transparency, no shadow and no fog the pipeline is the plain z-buffer
render; effects are stages of the same frame.

The **GL-compatibility preset** (``gl_compat=True``) reproduces OpenGL 2.1 fixed-function
lighting (§2.14.1) bit-for-bit up to rounding: per-vertex evaluation with vertex colours
clamped to [0, 1] before interpolation (primary and secondary separately under
``separate_specular``), flat shading taking the colour of the provoking (last) vertex, and the
final colour clamped to [0, 1] as an 8-bit framebuffer does. In ``phong`` mode it models the
per-pixel version of the same equation (a GLSL fragment shader) followed by the framebuffer clamp.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from blinn_phong._numba import use_compiled
from blinn_phong.frame._feedback import start_feedback
from blinn_phong.frame.id_passes import Cryptomatte
from blinn_phong.frame.light_groups import LightGroups
from blinn_phong.frame.pipeline import render_frame
from blinn_phong.frame.prepared import PreparedScene, prepare_scene
from blinn_phong.frame.resolve import resolve_nearest_buffers, resolve_samples
from blinn_phong.frame.shading import (
    FragmentShading,
    _check_shading,
    check_gl_ranges,
    shade_fragments,
    surface_at_fragments,
)
from blinn_phong.model.scene import Scene, prepare_render_inputs
from blinn_phong.planning.frame_plan import Fog, frame_plan, scene_with_planned_shading
from blinn_phong.planning.planner import Plan

__all__ = [
    "FragmentShading",
    "PreparedScene",
    "RenderResult",
    "RenderStats",
    "check_gl_ranges",
    "prepare_scene",
    "render",
    "resolve_nearest_buffers",
    "resolve_samples",
    "shade_fragments",
    "surface_at_fragments",
]

ProgressCallback = Callable[[str, float], None]


@dataclass(frozen=True)
class RenderStats:
    """Timing and counts of one render.

    Attributes:
        seconds: wall time per stage (``prepare``, ``visibility`` — rasterization and
            depth resolve —, ``shade`` — with the deep fragments of ``deep=True`` —,
            ``resolve_samples``, ``deep`` — joining the deep image's bands) in seconds.
        triangles: input triangles.
        shaded: samples shaded (visible samples; each shaded once).
    """

    seconds: dict[str, float] = field(default_factory=dict)
    triangles: int = 0
    shaded: int = 0

    @property
    def total_seconds(self) -> float:
        """Sum of the stage times."""
        return float(sum(self.seconds.values()))


@dataclass(frozen=True, eq=False)
class RenderResult:
    """A rendered image and its auxiliary buffers (row 0 at the top).

    Attributes:
        rgba: (H, W, 4) float32 premultiplied linear RGBA; alpha = coverage × opacity.
        depth: (H, W) float32 nearest window depth over the pixel's samples; 1.0 where empty
            (the OpenGL clear value).
        normal: (H, W, 3) float32 world-space unit normal (mean over covered samples,
            renormalised); zero where empty.
        passes: ``"ambient"`` (with emission), ``"diffuse"``, ``"specular"``: (H, W, 3)
            float32 premultiplied light passes of the nearest surface; they sum to
            ``rgba[..., :3]`` outside the GL preset when nothing is transparent and there is no
            fog. With shadows they include the shadowing, and ``"shadow"`` (H, W, 1) holds the
            mean visibility of the lights, weighted like the passes.
        stats: :class:`RenderStats`.
        plan: the :class:`~blinn_phong.planning.planner.Plan` the render followed (``plan.reasons()``
            gives one line per decision; the caller's overrides say so).
        deep: with ``render(..., deep=True)`` the frame's fragments as a
            :class:`compositing.deep.DeepImage` (:mod:`blinn_phong.frame.deep_output`), else None.
            Holdout meshes are in it as samples ``(0, 0, 0, coverage)``.
        deep_holdout: with ``deep=True`` and a holdout mesh in the scene, those holdout samples
            alone (a :class:`compositing.deep.DeepImage`), else None.

    ``depth``, ``normal`` and ``passes`` of a compiled one-pass frame may be views of one
    allocation (``rgba`` is always an array of its own): keeping one of them keeps them all; a
    ``.copy()`` keeps one alone.
    """

    rgba: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    passes: dict[str, np.ndarray]
    stats: RenderStats
    plan: Plan | None = None
    deep: object = None
    deep_holdout: object = None


def _numpy_engine_compiles_nothing(func: Callable[..., RenderResult]) -> Callable[..., RenderResult]:
    """``engine="numpy"`` renders without compiling any kernel: the planner's mesh facts use
    their numpy reference too (:func:`blinn_phong.geometry.mesh_facts.reference_only`)."""

    @functools.wraps(func)
    def wrapper(*args: object, **kwargs: object) -> RenderResult:
        if kwargs.get("engine") != "numpy":
            return func(*args, **kwargs)
        from blinn_phong.geometry.mesh_facts import reference_only

        with reference_only():
            return func(*args, **kwargs)

    return wrapper


@_numpy_engine_compiles_nothing
def render(
    scene: Scene,
    width: int,
    height: int,
    *,
    shading: str = "auto",
    samples: int = 1,
    gl_compat: bool = False,
    cull_backfaces: bool = False,
    engine: str = "auto",
    progress: ProgressCallback | None = None,
    transparency: str | None = None,
    peel_layers: int | None = None,
    wboit_weight: str = "eq10",
    shadows: object = None,
    fog: Fog | None = None,
    tolerance: float = 0.0,
    layers: int | None = None,
    deep: bool = False,
    cryptomatte: Cryptomatte | None = None,
    light_groups: LightGroups | None = None,
) -> RenderResult:
    """Render ``scene`` with a z-buffer and local (Blinn-)Phong lighting, plus the effects the plan needs.

    The planner (:func:`blinn_phong.planning.planner.plan`) picks the transparency method and each
    light's shadow method; an argument other than ``None``/``"auto"`` replaces the
    planner's choice for that concern only (:func:`blinn_phong.frame_plan`). The
    plan followed, with one reason per decision, is ``result.plan``. With no transparent
    material, no shadow to cast and no fog the image is the plain z-buffer render.

    Args:
        scene: the :class:`~blinn_phong.model.scene.Scene` (camera required).
        width: image width in pixels.
        height: image height in pixels.
        shading: ``"auto"`` — the planner's per-mesh shading frequency (flat where it is exact,
            else Phong at tolerance 0); or ``"flat"``, ``"gouraud"``, ``"phong"`` for every mesh
            (a mesh's ``shading`` overrides it).
        samples: supersampling: k² samples per pixel on an ordered k×k grid; the result's
            alpha is the covered fraction.
        gl_compat: the OpenGL 2.1 fixed-function preset (see the module docstring).
        cull_backfaces: discard clockwise (back-facing) triangles.
        engine: ``"numpy"`` — the reference stages; ``"numba"`` — the compiled stages
            (visibility lists, lighting, transparency models, fog, transparency resolves and
            box filter; the buffers agree with the reference to 1e-6); ``"auto"`` — numba when
            it can be imported, else numpy.
        progress: ``callback(stage, fraction_done)`` called as stages finish; ``None`` (default)
            prints ``render: <stage> <percent>`` to stderr, if it is a terminal, once the render
            has run 3 s; ``True`` from the start, ``False`` never (:mod:`blinn_phong.frame._feedback`).
            When numba compiles the kernels (once per machine) ``compiling kernels (once per
            machine)…`` is printed to stderr.
        transparency: ``None``/``"auto"`` (the planner's choice) or one of
            :data:`blinn_phong.planning.frame_plan.TRANSPARENCY_CHOICES`: ``zbuffer`` (nearest fragment,
            alpha = opacity), ``draw_last``, ``sort_objects``, ``sort_triangles``,
            ``depth_peeling``, ``a_buffer`` (exact), ``weighted_blended``.
        peel_layers: layers for depth peeling (None: the planner's, else 8); older name of ``layers``.
        wboit_weight: weighted blended OIT weight, ``"eq10"`` (McGuire & Bavoil eq. 10) or ``"constant"``.
        shadows: ``None``/``"auto"`` (the planner's choice per light), a method of
            :data:`blinn_phong.planning.frame_plan.SHADOW_CHOICES` or a
            :class:`blinn_phong.planning.frame_plan.ShadowOptions`
            (method and parameters) for every light, or a list with one such entry per
            ``scene.lights`` entry.
        fog: a :class:`blinn_phong.Fog` applied per fragment before blending, or None.
        tolerance: the planner's tolerance in 8-bit steps (0: exact methods only; see
            :func:`blinn_phong.planning.planner.plan` for the error each concern bounds).
        layers: layers for depth peeling, the name the plan's parameters use
            (``result.plan.transparency.params["layers"]``); same as ``peel_layers``.
        deep: also return the frame's fragments as a deep image (``result.deep``,
            :mod:`blinn_phong.frame.deep_output`): the fragments each band resolves, collected in the
            same pass (:class:`blinn_phong.frame.deep_fragments.DeepFragments`); the plan's
            transparency method must be ``a_buffer``, ``depth_peeling`` or ``zbuffer`` (else
            ``ValueError`` before anything is rasterized).
        cryptomatte: a :class:`blinn_phong.frame.id_passes.Cryptomatte` request (one name per entry of
            ``scene.meshes`` in each layer) or None (default: no work). Its passes
            (``CryptoObject00`` … as Cycles names them, (H, W, 4) float32 rank/coverage pairs,
            :mod:`compositing.cryptomatte`) are added to ``result.passes``, counted from the
            frame's own samples (:mod:`blinn_phong.frame.id_passes`); the header entries (manifests)
            are ``cryptomatte.metadata(view_layer)``.
        light_groups: a :class:`blinn_phong.frame.light_groups.LightGroups` (the group of each light,
            of each mesh's emission and of the world's ambient) or None (default: no work). Adds
            one pass ``Combined_<group>`` per group, (H, W, 3) float32: the frame's colour from
            that group's emitters alone, rendered by the frame's own plan; the passes sum to
            ``rgba[..., :3]`` when every emitter has a group and there is no fog
            (:mod:`blinn_phong.frame.light_groups`). Refused with ``gl_compat`` (its clamp is not linear).

    ``gl_compat=True`` renders with the plain z-buffer and no shadows or fog (asking for them
    raises ``ValueError``).

    Returns:
        :class:`RenderResult`, with ``plan`` the plan followed.
    """
    if layers is not None:
        if peel_layers is not None and peel_layers != layers:
            raise ValueError(
                f"layers, peel_layers: two names for one setting, got {layers!r} and {peel_layers!r}"
            )
        peel_layers = layers

    if shading != "auto":
        shading = _check_shading(shading)
    use_compiled(engine)  # checked before the scene: a bad name is named first
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a blinn_phong.Scene, got {type(scene).__name__}")
    if cryptomatte is not None:
        if not isinstance(cryptomatte, Cryptomatte):
            raise TypeError(
                f"cryptomatte: expected a blinn_phong.Cryptomatte or None, got {type(cryptomatte).__name__}"
            )
        if cryptomatte.mesh_count != len(scene.meshes):
            raise ValueError(
                f"cryptomatte: expected one name per mesh ({len(scene.meshes)} meshes), "
                f"got {cryptomatte.mesh_count} names per layer"
            )
        cryptomatte = cryptomatte.subset([len(m.triangles) > 0 for m in scene.meshes])
    if light_groups is not None:
        if not isinstance(light_groups, LightGroups):
            raise TypeError(
                f"light_groups: expected a blinn_phong.LightGroups or None, got {type(light_groups).__name__}"
            )
        if gl_compat:
            raise ValueError("light_groups: not available with gl_compat (its colour clamp is not linear)")
        light_groups.check(scene)
        light_groups = light_groups.subset_meshes([len(m.triangles) > 0 for m in scene.meshes])
    # Size/memory, gl_compat light model, meshes without triangles dropped (blinn_phong/model/scene.py).
    scene = prepare_render_inputs(scene, width, height, samples, gl_compat)
    progress = start_feedback(engine, progress)  # compile notice, progress lines (frame/_feedback.py)
    if fog is not None and not isinstance(fog, Fog):
        raise TypeError(f"fog: expected a blinn_phong.Fog or None, got {type(fog).__name__}")
    if gl_compat:
        check_gl_ranges(scene)
        if fog is not None:
            raise ValueError("fog: not available with gl_compat (the preset renders the plain z-buffer)")
    seconds: dict[str, float] = {}

    def report(stage: str, fraction: float) -> None:
        if progress is not None:
            progress(stage, fraction)

    t = time.perf_counter()
    the_plan = frame_plan(
        scene,
        tolerance=tolerance,
        shading=shading,
        transparency=transparency,
        peel_layers=peel_layers,
        wboit_weight=wboit_weight,
        shadows=shadows,
        gl_compat=gl_compat,
        width=width,
        height=height,
        samples=samples,
        fog=fog,
    )
    seconds["plan"] = time.perf_counter() - t
    if shading == "auto":
        scene, shading = scene_with_planned_shading(scene, the_plan, shading), "phong"
    collector = None
    if deep:
        from blinn_phong.frame.deep_fragments import DeepFragments

        method = the_plan.transparency.method
        collector = DeepFragments(height, width, method, the_plan.transparency.params.get("layers"))

    t = time.perf_counter()
    prepared = prepare_scene(scene)
    seconds["prepare"] = time.perf_counter() - t
    report("prepare", 0.05)

    image, n_shaded = render_frame(
        prepared,
        width,
        height,
        the_plan,
        shading=shading,
        samples=samples,
        gl_compat=gl_compat,
        cull_backfaces=cull_backfaces,
        fog=fog,
        engine=engine,
        seconds=seconds,
        report=report,
        cryptomatte=cryptomatte,
        deep=collector,
        light_groups=light_groups,
    )
    deep_image = deep_holdout = None
    if collector is not None:
        t = time.perf_counter()
        deep_image = collector.image()
        deep_holdout = collector.holdout_image()
        seconds["deep"] = time.perf_counter() - t
    if light_groups is not None and not all(
        light_groups.pass_name(g) in image.passes for g in light_groups.groups
    ):
        # Not made in the frame's own pass (numpy engine, band path, strips, Gouraud meshes,
        # several samples): each group's frame rendered with its emitters alone.
        t = time.perf_counter()
        group_fog = None if fog is None else replace(fog, color=(0.0, 0.0, 0.0))
        for group in light_groups.groups:
            split = light_groups.group_scene(scene, group)
            name = light_groups.pass_name(group)
            if split is None:
                image.passes[name] = np.zeros((height, width, 3), np.float32)
                continue
            group_scene, kept = split
            group_plan = replace(the_plan, shadows=tuple(the_plan.shadows[i] for i in kept))
            part, _ = render_frame(
                prepare_scene(group_scene), width, height, group_plan, shading=shading, samples=samples,
                cull_backfaces=cull_backfaces, fog=group_fog, engine=engine,
            )  # fmt: skip
            image.passes[name] = np.ascontiguousarray(part.rgba[..., :3])
        seconds["light_groups"] = time.perf_counter() - t
    report("done", 1.0)
    stats = RenderStats(seconds, len(prepared.triangles), n_shaded)
    return RenderResult(
        image.rgba, image.depth, image.normal, image.passes, stats,
        plan=the_plan, deep=deep_image, deep_holdout=deep_holdout,
    )  # fmt: skip
