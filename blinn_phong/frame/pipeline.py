"""The frame: one pipeline from scene to image, the same stages with or without effects.

``scene -> prepared -> fragments -> visibility -> shading -> resolve``:

1. :func:`blinn_phong.frame.prepared.prepare_scene` — meshes to eye and clip space, lights to eye space;
2. :func:`blinn_phong.frame.visibility.frame_fragments` — rasterize and keep the fragments that can be
   seen: the nearest opaque one per sample and the transparent ones in front of it (with the
   plain z-buffer every triangle is opaque, so this is the z-buffer pass);
3. per light, the visibility of those fragments by the plan's shadow method, once per light
   and frame (:func:`blinn_phong.shadows.methods.light_visibility`, or
   :func:`blinn_phong.shadows.raytrace.area_light_visibility` for soft shadows) — skipped when no
   light casts shadows;
4. :func:`blinn_phong.frame.shading.shade_fragments` — shade them once, with that visibility;
5. :func:`blinn_phong.frame.resolve.fragment_colours` — premultiplied fragments by each material's
   transparency model, fogged per fragment before blending (as OpenGL does);
6. :func:`blinn_phong.frame.resolve.resolve_frame` — the transparency method per sample, then the
   box filter and the nearest surface's depth, normal and light passes.

Holdout meshes (``Mesh.holdout``) are opaque fragments of colour ``(0, 0, 0, 0)`` after step 5,
which every resolve of step 6 composites as it does any opaque fragment; light and shadow linking
(``Scene.light_links``) acts in step 3 (:mod:`blinn_phong.model.linking`). Frames with either take the
general stages (the fused passes have neither).

With transparency ``zbuffer``, no shadow and no fog, steps 3 and the transparency part of 6
do nothing: the plain z-buffer render *is* this pipeline with no effects. Every stage has a
numpy reference and a compiled (numba) twin, selected by ``engine``.

Imports flow one way: this module uses the stage modules, :mod:`blinn_phong.frame.render` uses this
module and :mod:`blinn_phong.planning.frame_plan` (the plan); no stage imports a later one.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from blinn_phong._numba import use_compiled
from blinn_phong._scratch import carve, carved_bytes
from blinn_phong.frame.fused import shade_plain_fragments_compiled, shade_plain_winners_compiled
from blinn_phong.frame.id_passes import Cryptomatte, passes_from_fragments, passes_from_winners
from blinn_phong.frame.light_groups import LightGroups
from blinn_phong.frame.prepared import PreparedScene, prepare_scene
from blinn_phong.frame.resolve import (
    FogParameters,
    FrameImage,
    fragment_colours,
    opaque_test,
    resolve_frame,
    shadow_pass_values,
    side_tables,
)
from blinn_phong.frame.shading import fused_shading_applies, plain_tables, shade_fragments
from blinn_phong.frame.texturing import texture_fragments
from blinn_phong.frame.visibility import FrameFragments, frame_fragments
from blinn_phong.geometry.normals import face_normals
from blinn_phong.geometry.raster import Fragments, interpolate
from blinn_phong.geometry.raster_kernels import (
    nearest_winners_compiled,
    setup_triangles_compiled,
    winner_surfaces_compiled,
)
from blinn_phong.model.lights import AmbientLight
from blinn_phong.model.linking import holdout_meshes, linked_visibility, lit_links
from blinn_phong.model.scene import Camera, Scene
from blinn_phong.planning.planner import Plan
from blinn_phong.shadows.method import ShadowFrame
from blinn_phong.shadows.methods import frame_visibility, shadow_method, trusted_arrays
from blinn_phong.shadows.transmittance import caster_transmittance

if TYPE_CHECKING:
    from blinn_phong.frame.deep_fragments import DeepFragments

__all__ = ["BAND_SAMPLES", "FrameResult", "light_visibilities", "render_frame"]


#: The world geometry of the last few scenes: per scene, the key of :func:`_geometry_key`, each
#: mesh's arrays (kept to check their identity) and ``{"verts", "tris", "bvh_key"}``. Mesh arrays
#: are not to be changed in place (the mesh facts assume it too); the cached arrays are read-only.
_WORLD_CACHE: list[tuple[tuple, list[np.ndarray], dict[str, object]]] = []
_WORLD_CACHE_SIZE = 4
_WORLD_LOCK = threading.Lock()


def _geometry_key(scene: Scene) -> tuple:
    return tuple(
        (id(m.positions), id(m.triangles), m.transform.tobytes(), bool(m.casts_shadows)) for m in scene.meshes
    )


def _world_entry(scene: Scene) -> dict[str, object]:
    """The cached world geometry of ``scene`` (computed on first use; a static scene rendered again,
    e.g. from another camera, reuses it)."""
    key = _geometry_key(scene)
    arrays = [a for m in scene.meshes for a in (m.positions, m.triangles)]
    with _WORLD_LOCK:  # renders may run in threads of one process
        for i, (k, kept, entry) in enumerate(_WORLD_CACHE):
            if k == key and all(a is b for a, b in zip(kept, arrays, strict=True)):
                _WORLD_CACHE.insert(0, _WORLD_CACHE.pop(i))
                return entry
    verts = []
    for m in scene.meshes:
        hom = np.empty((len(m.positions), 4))
        hom[:, :3] = m.positions
        hom[:, 3] = 1.0
        v = (hom @ m.transform.T)[:, :3]
        v.flags.writeable = False
        verts.append(v)
    parts = [v[m.triangles] for m, v in zip(scene.meshes, verts, strict=True) if m.casts_shadows]
    tris = np.concatenate(parts) if parts else np.zeros((0, 3, 3))
    tris.flags.writeable = False
    entry: dict[str, object] = {"verts": verts, "tris": tris, "bvh_key": None}
    with _WORLD_LOCK:
        _WORLD_CACHE.insert(0, (key, arrays, entry))
        del _WORLD_CACHE[_WORLD_CACHE_SIZE:]
    return entry


def _world_vertices(scene: Scene) -> list[np.ndarray]:
    """(V_m, 3) world-space vertex positions of each mesh, ``(p, 1)·Mᵀ`` with the mesh's model matrix
    (read-only arrays, cached for the scene's geometry)."""
    return list(_world_entry(scene)["verts"])  # type: ignore[call-overload]


def _world_triangles(scene: Scene, world_vertices: list[np.ndarray] | None = None) -> np.ndarray:
    """(T, 3, 3) world-space triangles of the meshes that cast shadows (``Mesh.casts_shadows``), in
    scene order, as :func:`blinn_phong.shadows.raytrace.world_triangles` (read-only, cached with the
    scene's world vertices; ``world_vertices`` other than those are used as given).

    Computed here so that shadow maps and planar shadows work where Embree (``embreex``, which
    :mod:`blinn_phong.shadows.raytrace` imports) is not installed, e.g. in Blender's own Python.
    """
    entry = _world_entry(scene)
    verts = entry["verts"]
    if world_vertices is None or all(a is b for a, b in zip(world_vertices, verts, strict=True)):  # type: ignore[call-overload]
        return entry["tris"]  # type: ignore[return-value]
    parts = [v[m.triangles] for m, v in zip(scene.meshes, world_vertices, strict=True) if m.casts_shadows]
    return np.concatenate(parts) if parts else np.zeros((0, 3, 3))


def _all_world_vertices(scene: Scene) -> np.ndarray:
    """(V, 3) every mesh's world vertices in scene order (read-only, cached with them)."""
    entry = _world_entry(scene)
    if "all" not in entry:
        verts = entry["verts"]
        every = np.concatenate(verts) if verts else np.zeros((0, 3))  # type: ignore[arg-type]
        every.flags.writeable = False
        entry["all"] = every
    return entry["all"]  # type: ignore[return-value]


def _bvh_key(scene: Scene, tris: np.ndarray) -> object:
    """The ray tracer's cache key of the scene's cached caster triangles (hashed once per geometry)."""
    from blinn_phong.shadows import raytrace  # Embree: imported only when used

    entry = _world_entry(scene)
    if entry["tris"] is not tris:
        return raytrace._key(tris)
    if entry["bvh_key"] is None:
        entry["bvh_key"] = raytrace._key(tris)
    return entry["bvh_key"]


def _fragment_surface(
    prepared: PreparedScene, fragments: Fragments, world_vertices: list[np.ndarray], compiled: bool
) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) world-space points and (N, 3) unit world face normals of fragments, contiguous float64.

    The face normal is :func:`blinn_phong.geometry.normals.face_normals` of the world-space corners (the
    direction of the model matrix's inverse transpose applied to the object-space normal, up to
    the sign of its determinant: shadow methods face each normal towards the light, so the
    sign does not matter).

    The point is the perspective-correct interpolation of the world-space corners (equal to the
    interpolated eye-space point mapped back by the inverse view matrix: the map is affine and
    the barycentrics sum to 1). Compiled: one pass
    (:func:`blinn_phong.shadows.ray_setup_kernels.fragment_surface`);
    numpy: :func:`blinn_phong.geometry.raster.interpolate` and a gather.
    """
    verts = np.concatenate(world_vertices) if world_vertices else np.zeros((0, 3))
    faces = face_normals(verts, prepared.triangles)
    if compiled:
        from blinn_phong.shadows.ray_setup_kernels import fragment_surface

        n = len(fragments)
        points = np.empty((n, 3))
        normals = np.empty((n, 3))
        if n:
            fragment_surface(
                np.ascontiguousarray(fragments.triangle, dtype=np.int64),
                np.ascontiguousarray(fragments.bary, dtype=np.float64),
                np.ascontiguousarray(prepared.triangles, dtype=np.int64),
                np.ascontiguousarray(verts),
                faces,
                points,
                normals,
            )
        return points, normals
    points = np.ascontiguousarray(interpolate(fragments, prepared.triangles, verts))
    return points, np.ascontiguousarray(faces[fragments.triangle])


def _shadow_lights(scene: Scene, the_plan: Plan) -> list[tuple[object, object]] | None:
    """The scene's non-ambient lights with their shadow choices; None when none casts shadows
    and none has a receiver mask (:class:`blinn_phong.model.scene.LightLink`)."""
    lit = [
        (light, c)
        for light, c in zip(scene.lights, the_plan.shadows, strict=True)
        if not isinstance(light, AmbientLight)
    ]
    links = lit_links(scene) or ()
    receivers = any(link is not None and link.receivers is not None for link in links)
    return lit if receivers or any(c.method != "none" for _, c in lit) else None


def light_visibilities(
    prepared: PreparedScene, visible: FrameFragments, the_plan: Plan, *, engine: str = "auto"
) -> np.ndarray | None:
    """Visibility of the visible fragments per non-ambient light; None when no light casts shadows.

    One evaluation per light and frame, by the plan's method for that light
    (:func:`blinn_phong.shadows.methods.light_visibility`, Embree area-light sampling for ``soft``),
    at the fragments' world positions with their face normals. The world-space points, face
    normals and caster triangles are computed once per frame (one compiled pass with
    ``engine`` numba/auto, :func:`_fragment_surface`) and shared by every light; ray-traced
    lights share one BVH.

    Coloured shadows: where a light's method is ``ray_traced`` and a caster is transparent
    (:func:`blinn_phong.shadows.transmittance.caster_transmittance`: ``1 − opacity`` per channel for the
    partial-occlusion and absorption models, 1 for emission, 0 for opaque casters), that
    light's visibility is the per-channel fraction of its light that arrives
    (:func:`blinn_phong.shadows.raytrace.transmitted_light`), and the result is (N, L, 3) — the other
    lights' (N,) visibility repeated over the three channels. Otherwise it is (N, L).

    Args:
        prepared: the frame's prepared scene.
        visible: its visible fragments.
        the_plan: the frame's plan (one shadow choice per light of the scene).
        engine: ``numpy`` (reference stages), ``numba`` or ``auto``: fragment surfaces and
            shadow-map kernels.

    Returns:
        (N, L) or (N, L, 3) float64 in [0, 1], L the non-ambient lights in scene order; or None.
    """
    scene = prepared.scene
    lit = _shadow_lights(scene, the_plan)
    if lit is None:
        return None
    verts = _world_vertices(scene)
    compiled = use_compiled(engine)
    world, normal = _fragment_surface(prepared, visible.fragments, verts, compiled)
    linked = scene.light_links is not None
    mesh_of = prepared.triangle_mesh[visible.fragments.triangle] if compiled or linked else None
    return _visibility_at(scene, lit, verts, world, normal, compiled, mesh_of)


def _visibility_at(
    scene: Scene,
    lit: list[tuple[object, object]],
    verts: list[np.ndarray],
    world: np.ndarray,
    normal: np.ndarray,
    compiled: bool,
    mesh_of: np.ndarray | None = None,
    binning: tuple | None = None,
) -> np.ndarray:
    """:func:`light_visibilities` at (N, 3) world points with their (N, 3) face normals.

    ``mesh_of``: (N,) the scene mesh of each point; given to the compiled engine, ray-traced
    hard shadows trace only the rays that may be occluded (:func:`_traced_hard`).
    ``binning``: the points' screen tiles for shadow volumes
    (:func:`blinn_phong.shadows.volume_counting.pixel_binning` of a frame's pixels), or None.
    With ``scene.light_links`` (``mesh_of`` required) each light with blockers is computed
    against them alone and receiver masks zero their lights
    (:func:`blinn_phong.model.linking.linked_visibility`).
    """
    if scene.light_links is not None:
        assert mesh_of is not None
        tris = _world_triangles(scene, verts)
        aim = (tris.reshape(-1, 3).min(axis=0) + tris.reshape(-1, 3).max(axis=0)) / 2 if len(tris) else None

        def unlinked(part: Scene, lights: list[tuple[object, object]]) -> np.ndarray:
            return _unlinked_visibility_at(
                part, lights, verts, world, normal, compiled, mesh_of, binning, aim
            )

        return linked_visibility(scene, lit, mesh_of, unlinked)
    return _unlinked_visibility_at(scene, lit, verts, world, normal, compiled, mesh_of, binning)


def _unlinked_visibility_at(
    scene: Scene,
    lit: list[tuple[object, object]],
    verts: list[np.ndarray],
    world: np.ndarray,
    normal: np.ndarray,
    compiled: bool,
    mesh_of: np.ndarray | None = None,
    binning: tuple | None = None,
    aim: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`_visibility_at` of lights without links (``aim``: where soft lights face): each
    light by its method (:func:`blinn_phong.shadows.methods.frame_visibility`), the frame's
    points, casters and BVH shared (:class:`blinn_phong.shadows.method.ShadowFrame`)."""
    tris = _world_triangles(scene, verts)
    if len(tris) == 0:  # no mesh casts shadows: every light reaches every fragment
        return np.ones((len(world), len(lit)))
    transmittance = caster_transmittance(scene)
    if not any(shadow_method(c.method).coloured for _, c in lit):  # type: ignore[attr-defined]
        transmittance = None  # full shadows only: (N, L)
    frame = ShadowFrame(scene, tris, world, normal, compiled, mesh_of, binning, aim, transmittance)
    one_bvh: contextlib.AbstractContextManager[None] = contextlib.nullcontext()
    if any(shadow_method(c.method).uses_rays for _, c in lit):  # type: ignore[attr-defined]
        from blinn_phong.shadows.raytrace import frame_triangles  # Embree: imported only when used

        one_bvh = frame_triangles(tris, _bvh_key(scene, tris))  # hashed once per geometry, not per light
    # world, normal and tris are this frame's own finite float64 arrays: checked once, here
    with trusted_arrays(world, normal, tris), one_bvh:
        return frame_visibility(frame, lit)


FrameResult = tuple[FrameImage, int]


def _empty_frame(height: int, width: int, shadow: bool) -> FrameImage:
    """Uninitialised float32 frame buffers (for a pass that writes every element).

    ``rgba`` is an allocation of its own (a caller may keep it alone); depth, normal and the
    light passes are C-contiguous views of one more. Fresh buffers of a few MB each are mapped
    anew and faulted in page by page while the shading threads write them (with seven of them,
    about 1,800 page faults and 2 ms of a 640×360 frame); two are reused by the allocator from
    the previous frame or mapped with huge pages."""
    names = ("ambient", "diffuse", "specular") + (("shadow",) if shadow else ())
    parts = [((height, width), np.float32), ((height, width, 3), np.float32)]
    parts += [((height, width, 1 if n == "shadow" else 3), np.float32) for n in names]
    depth, normal, *passes = carve(np.empty(carved_bytes(*parts), np.uint8), *parts)
    rgba = np.empty((height, width, 4), np.float32)
    return FrameImage(rgba, depth, normal, dict(zip(names, passes, strict=True)))


def _targets(image: FrameImage) -> tuple[np.ndarray, ...]:
    """The buffers of ``image`` in the order the compiled resolve kernels write them."""
    p = image.passes
    shadow = p["shadow"] if "shadow" in p else np.zeros((0, 0, 1), np.float32)
    return (image.rgba, p["ambient"], p["diffuse"], p["specular"], image.normal, image.depth, shadow)


def _id_passes(
    request: Cryptomatte | None, seconds: dict[str, float], make: Callable[..., dict], *args: object
) -> dict[str, np.ndarray]:
    """The Cryptomatte passes of ``request`` by ``make(request, *args)``, timed as ``cryptomatte``;
    nothing (and no work) without a request."""
    if request is None:
        return {}
    t = time.perf_counter()
    out = make(request, *args)
    seconds["cryptomatte"] = seconds.get("cryptomatte", 0.0) + time.perf_counter() - t
    return out


#: Shadow-mapped opaque frames look their pixels up inside the fused shading kernel
#: (:func:`_frame_map_stack`); False takes the general path (world points, then each light's
#: visibility) — the tests compare the two.
_IN_KERNEL_MAPS = True


def _frame_map_stack(
    prepared: PreparedScene,
    lit: list[tuple[object, object]],
    verts: list[np.ndarray],
    all_verts: np.ndarray,
    setup: object,
    winner: np.ndarray,
) -> object | None:
    """The frame's :class:`blinn_phong.shadows.frame_maps.MapStack` when every shadowed light of ``lit``
    is shadow-mapped by the compiled engine with one resolution (the fused kernel then looks
    the pixels up itself), else None."""
    from blinn_phong.shadows import frame_maps  # compiled engine only: imports numba

    if prepared.scene.light_links is not None:
        return None  # linked lights: the general path's visibilities (blinn_phong.model.linking)
    options = []
    for light, c in lit:
        params = dict(c.params)  # type: ignore[attr-defined]
        if c.method == "none":  # type: ignore[attr-defined]
            options.append((light, "none", params))
        elif c.method == "shadow_map" and set(params) <= set(frame_maps.MAP_PARAMETERS):  # type: ignore[attr-defined]
            options.append((light, "shadow_map", params))
        else:
            return None
    resolutions = {
        p.get("resolution", frame_maps.MAP_PARAMETERS["resolution"]) for _, m, p in options if m != "none"
    }
    tris = _world_triangles(prepared.scene, verts)
    if len(resolutions) != 1 or len(tris) == 0:
        return None
    seen = frame_maps.visible_triangles(winner, setup.source, len(prepared.triangles))  # type: ignore[attr-defined]
    receivers = all_verts[prepared.triangles[seen]]
    return frame_maps.frame_maps(options, tris, receivers)  # a context: the stack's memory is reused


def _opaque_from_winners(
    prepared: PreparedScene,
    width: int,
    height: int,
    lit: list[tuple[object, object]] | None,
    shading: str,
    gl_compat: bool,
    cull_backfaces: bool,
    fog: tuple | None,
    seconds: dict[str, float],
    say: Callable[[str, float], None],
    cryptomatte: Cryptomatte | None = None,
    holdout: np.ndarray | None = None,
    light_groups: LightGroups | None = None,
) -> FrameResult:
    """The opaque z-buffer frame (no transparency, one sample, per-pixel shading, fog or not,
    shadows or not) by the compiled engine: the z-buffer, then (with shadows: ``lit`` from
    :func:`_shadow_lights`) each covered pixel's world point and face normal and each light's
    visibility there, then each pixel's winner interpolated, lit, fogged (``fog`` as
    :meth:`FogParameters.compiled_args` gives it) and written into the frame buffers (no
    fragment arrays at all).

    The same images as the stages of :func:`render_frame` (the same operations in the same
    order: :func:`blinn_phong.frame.fused.shade_plain_winners_compiled`). ``holdout``: (M,) bool per mesh
    (:func:`blinn_phong.model.linking.holdout_meshes`) or None; pixels a holdout wins are then set to
    transparent black (colour, alpha and light passes), as the general path's alpha-weighted
    passes give. ``light_groups``: their passes made in the same pass (:func:`_group_buffers`).
    """
    t = time.perf_counter()
    setup = setup_triangles_compiled(prepared.clip, prepared.triangles, width, height, 1, cull_backfaces)
    winner = nearest_winners_compiled(setup)
    seconds["visibility"] = time.perf_counter() - t
    say("visibility", 0.4)
    ids = _id_passes(
        cryptomatte, seconds, passes_from_winners, winner, setup.source, prepared.triangle_mesh, height, width
    )
    with contextlib.ExitStack() as resources:  # the shadow maps' memory, until shaded
        vis = maps = None
        if lit is not None:  # shadows: each covered pixel's world point, then each light's visibility there
            t = time.perf_counter()
            verts = _world_vertices(prepared.scene)
            all_verts = _all_world_vertices(prepared.scene)
            stacked = (
                _frame_map_stack(prepared, lit, verts, all_verts, setup, winner) if _IN_KERNEL_MAPS else None
            )
            if stacked is not None:  # every light shadow-mapped: looked up by the shading kernel
                maps = (resources.enter_context(stacked), all_verts)
            else:
                vis = _winner_visibility(prepared, lit, verts, all_verts, setup, winner)
            seconds["shadows"] = time.perf_counter() - t
            say("shadows", 0.6)
        t = time.perf_counter()
        image = _empty_frame(height, width, lit is not None)
        tables = plain_tables(prepared, gl_compat, shading)
        groups = _group_buffers(light_groups, prepared, tables, height, width)
        shaded = shade_plain_winners_compiled(setup, winner, tables, _targets(image), fog, vis, maps, groups)
        if maps is not None and maps[0].miss[0]:  # type: ignore[attr-defined]
            # a pixel's point lay farther off its triangle than the cube's rectangles allow for
            # (snapped coverage): shaded again from the general path's visibilities
            vis = _winner_visibility(prepared, lit, verts, all_verts, setup, winner)  # type: ignore[arg-type]
            shaded = shade_plain_winners_compiled(
                setup, winner, tables, _targets(image), fog, vis, None, groups
            )
        image.passes.update(_group_passes(light_groups, groups))  # (held out below, as the colour)
        if holdout is not None:
            pixel = np.flatnonzero(winner >= 0)
            held = pixel[holdout[prepared.triangle_mesh[setup.source[winner[pixel]]]]]
            for buffer in (image.rgba, *image.passes.values()):
                buffer.reshape(-1, buffer.shape[-1])[held] = 0.0
        seconds["shade"] = time.perf_counter() - t
        seconds["resolve_samples"] = 0.0
        say("shade", 1.0)
    image.passes.update(ids)
    return image, shaded


def _group_buffers(
    light_groups: LightGroups | None, prepared: PreparedScene, tables: tuple, height: int, width: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The fused kernels' ``groups`` argument for ``light_groups`` (``(group_of, base, out)``:
    :meth:`blinn_phong.frame.light_groups.LightGroups.kernel_tables` and an uninitialised (G, H, W, 3)
    float32 buffer), or None: no request, or a Gouraud-shaded mesh (its interpolated vertex terms
    are not split by group)."""
    if light_groups is None or (tables[5][0] == 2).any():
        return None
    group_of, base = light_groups.kernel_tables(prepared.scene, prepared.lights.source)
    return group_of, base, np.empty((len(light_groups.groups), height, width, 3), np.float32)


def _group_passes(
    light_groups: LightGroups | None, groups: tuple[np.ndarray, np.ndarray, np.ndarray] | None
) -> dict[str, np.ndarray]:
    """``Combined_<group>`` → its (H, W, 3) view of the buffer :func:`_group_buffers` made (none
    without one)."""
    if light_groups is None or groups is None:
        return {}
    return {light_groups.pass_name(g): groups[2][i] for i, g in enumerate(light_groups.groups)}


def _winner_visibility(
    prepared: PreparedScene,
    lit: list[tuple[object, object]],
    verts: list[np.ndarray],
    all_verts: np.ndarray,
    setup: object,
    winner: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The general path's ``(vis (N, L, K), shadow pass (N,), rank)`` of the z-buffer's winners:
    their world points and face normals
    (:func:`blinn_phong.geometry.raster_kernels.winner_surfaces_compiled`),
    then each light's visibility there (:func:`_visibility_at`)."""
    points, normals, rank, mesh_of = winner_surfaces_compiled(
        setup,
        winner,
        prepared.triangles,
        all_verts,
        prepared.triangle_mesh,  # type: ignore[arg-type]
    )
    binning = None
    if any(c.method == "shadow_volume" for _, c in lit):  # type: ignore[attr-defined]
        from blinn_phong.shadows.volume_counting import pixel_binning

        binning = pixel_binning(rank, setup.width, setup.height)  # type: ignore[attr-defined]  # the pixels' tiles: no sort
    visibility = _visibility_at(prepared.scene, lit, verts, points, normals, True, mesh_of, binning)
    return (
        visibility if visibility.ndim == 3 else visibility[:, :, None],
        shadow_pass_values(visibility),
        rank,
    )


#: Samples shaded and resolved per band of pixel rows: bounds the memory of the shading arrays
#: (about 250 bytes per visible fragment) whatever the image size.
BAND_SAMPLES = 1 << 19
#: Samples per horizontal strip of a large frame. Every stage of a strip (visibility lists,
#: shadow visibilities, shading) holds only the strip's fragments: a frame with transparency and
#: ray-traced coloured shadows peaks near 320 bytes per sample, so a strip stays near 1.3 GB
#: whatever the frame's size and sample count (1920×1080 at 6×6 samples is 18 strips).
STRIP_SAMPLES = 1 << 22


def strip_camera(camera: Camera, height: int, row0: int, row1: int) -> Camera:
    """The camera that renders rows ``row0 … row1 − 1`` of a ``height``-row frame as a frame of its own.

    Window y is affine in clip y, so the strip's clip y is ``(H/h)·y + (1 − H/h + 2·row0/h)·w``
    (``h = row1 − row0``): the sample at strip row ``j`` is the frame's sample at row
    ``row0 + j``, at the same window depth. Only the projection's y row changes; eye space,
    lighting and shadows see the same scene.
    """
    h = row1 - row0
    strip = np.eye(4)
    strip[1, 1] = height / h
    strip[1, 3] = 1.0 - height / h + 2.0 * row0 / h
    return Camera(camera.view, strip @ camera.projection, camera.kind)


def _render_in_strips(
    prepared: PreparedScene,
    width: int,
    height: int,
    the_plan: Plan,
    *,
    seconds: dict[str, float],
    report: Callable[[str, float], None] | None,
    **options: object,
) -> FrameResult:
    """:func:`render_frame` strip by strip (whole pixel rows, :data:`STRIP_SAMPLES` samples each),
    each strip through every stage with its own :func:`strip_camera`, following the frame's plan."""
    samples = int(options["samples"])  # type: ignore[call-overload]
    deep: DeepFragments | None = options.pop("deep", None)  # type: ignore[assignment]
    rows = max(1, STRIP_SAMPLES // (width * samples))
    bounds = [(r, min(height, r + rows)) for r in range(0, height, rows)]
    scene = prepared.scene
    image: FrameImage | None = None
    shaded = 0
    for i, (row0, row1) in enumerate(bounds):
        strip_scene = replace(scene, camera=strip_camera(scene.camera, height, row0, row1))  # type: ignore[arg-type]
        t = time.perf_counter()
        strip_prepared = prepare_scene(strip_scene)
        seconds["prepare"] = seconds.get("prepare", 0.0) + time.perf_counter() - t
        strip_seconds: dict[str, float] = {}

        def say(stage: str, fraction: float, i: int = i) -> None:
            if report is not None:
                report(stage, (i + fraction) / len(bounds))

        part, n = render_frame(
            strip_prepared, width, row1 - row0, the_plan, seconds=strip_seconds, report=say,
            deep=None if deep is None else deep.strip(row0), **options,  # type: ignore[arg-type]
        )  # fmt: skip
        for stage, value in strip_seconds.items():
            seconds[stage] = seconds.get(stage, 0.0) + value
        if image is None:
            image = FrameImage(
                np.empty((height, width, 4), np.float32),
                np.empty((height, width), np.float32),
                np.empty((height, width, 3), np.float32),
                {name: np.empty((height, width, p.shape[-1]), np.float32) for name, p in part.passes.items()},
            )
        if set(part.passes) != set(image.passes):
            raise RuntimeError(
                f"strip rows {row0}–{row1}: passes {sorted(part.passes)}, frame {sorted(image.passes)}"
            )
        image.rgba[row0:row1] = part.rgba
        image.depth[row0:row1] = part.depth
        image.normal[row0:row1] = part.normal
        for name, p in part.passes.items():
            image.passes[name][row0:row1] = p
        shaded += n
        del part
    assert image is not None
    return image, shaded


def render_frame(
    prepared: PreparedScene,
    width: int,
    height: int,
    the_plan: Plan,
    *,
    shading: str = "phong",
    samples: int = 1,
    gl_compat: bool = False,
    cull_backfaces: bool = False,
    fog: object = None,
    engine: str = "auto",
    seconds: dict[str, float] | None = None,
    report: Callable[[str, float], None] | None = None,
    cryptomatte: Cryptomatte | None = None,
    deep: DeepFragments | None = None,
    light_groups: LightGroups | None = None,
) -> FrameResult:
    """Render ``prepared`` by the stages of the module docstring, following ``the_plan``.

    Args:
        prepared: from :func:`blinn_phong.frame.prepared.prepare_scene`.
        width: image width in pixels.
        height: image height in pixels.
        the_plan: from :func:`blinn_phong.planning.frame_plan.frame_plan` (choices carry their parameters).
        shading: ``"flat"``, ``"gouraud"`` or ``"phong"`` (a mesh's own ``shading`` wins).
        samples: k² samples per pixel.
        gl_compat: the OpenGL 2.1 fixed-function preset for shading (no effects in the plan).
        cull_backfaces: discard clockwise triangles.
        fog: a :class:`blinn_phong.planning.frame_plan.Fog` (any object with its fields), or None.
        engine: ``"numpy"`` (reference stages), ``"numba"`` (compiled stages) or ``"auto"``.
        seconds: per-stage wall times are stored here (``visibility``, ``shadows`` when a light
            casts shadows, ``shade`` (with the fragment colours and fog), ``resolve_samples``
            (the transparency resolve and the box filter)).
        report: ``report(stage, fraction_done)``.
        cryptomatte: a :class:`blinn_phong.frame.id_passes.Cryptomatte` request (for ``prepared``'s
            meshes) or None: its passes (``CryptoObject00`` …) are added to the image's passes,
            computed from the visibility stage's samples (:mod:`blinn_phong.frame.id_passes`).
        deep: a :class:`blinn_phong.frame.deep_fragments.DeepFragments` that receives each band's
            fragment colours (the band path runs: the fused passes keep no fragment colours).
        light_groups: a :class:`blinn_phong.frame.light_groups.LightGroups` (for ``prepared``'s scene)
            or None. When the frame takes a fused pass (compiled engine, one sample, no Gouraud
            mesh, no strips), its passes ``Combined_<group>`` are made in that pass and added to
            the image's passes; otherwise none are added (the caller renders them apart).

    Returns:
        ``(image, shaded)``: the :class:`~blinn_phong.frame.resolve.FrameImage` and the number of
        fragments shaded (each visible fragment once).
    """
    seconds = {} if seconds is None else seconds
    if height > 1 and width * height * samples > STRIP_SAMPLES:
        return _render_in_strips(
            prepared, width, height, the_plan, shading=shading, samples=samples, gl_compat=gl_compat,
            cull_backfaces=cull_backfaces, fog=fog, engine=engine, seconds=seconds, report=report,
            cryptomatte=cryptomatte,
            deep=deep,
        )  # fmt: skip

    def say(stage: str, fraction: float) -> None:
        if report is not None:
            report(stage, fraction)

    compiled = use_compiled(engine)
    stage_engine = "numba" if compiled else "numpy"
    scene: Scene = prepared.scene
    method = the_plan.transparency.method
    opaque = None if method == "zbuffer" else opaque_test(prepared)

    fog_parameters = FogParameters.of(fog)
    fog_args = None if fog_parameters is None else fog_parameters.compiled_args()
    # Fog does not keep a frame off the fused pass: that pass fogs each fragment itself, before
    # any blending, with the colour stage's compiled fog.
    lit = _shadow_lights(scene, the_plan)
    holdout = holdout_meshes(scene)
    fused = (
        deep is None
        and compiled
        and fused_shading_applies(scene, shading, samples, gl_compat=gl_compat, shadows=lit is not None)
    )
    if fused and method == "zbuffer":
        return _opaque_from_winners(
            prepared, width, height, lit, shading, gl_compat, cull_backfaces, fog_args, seconds, say,
            cryptomatte, holdout, light_groups,
        )  # fmt: skip
    fused = fused and holdout is None  # the fused fragment pass has no holdouts: the band path below

    t = time.perf_counter()
    visible = frame_fragments(
        prepared.clip,
        prepared.triangles,
        width,
        height,
        opaque=opaque,
        samples=samples,
        cull_backfaces=cull_backfaces,
        engine=stage_engine,
        progress=None if report is None else (lambda f: say("visibility", 0.05 + 0.35 * f)),
    )
    seconds["visibility"] = time.perf_counter() - t
    say("visibility", 0.4)
    ids = _id_passes(cryptomatte, seconds, passes_from_fragments, prepared, visible, method)

    t = time.perf_counter()
    visibility = light_visibilities(prepared, visible, the_plan)
    if visibility is not None:
        seconds["shadows"] = time.perf_counter() - t
        say("shadows", 0.6)

    sorted_resolve = method in ("a_buffer", "depth_peeling")
    if fused and (method == "zbuffer" or not visible.n_transparent or sorted_resolve):
        # One fused pass over the pixels (no per-fragment shading arrays, so no bands needed); the
        # A-buffer and depth peeling sort and composite each pixel's transparent fragments in it.
        t = time.perf_counter()
        image = _empty_frame(height, width, visibility is not None)
        f = visible.fragments
        transparent = None
        if visible.n_transparent and sorted_resolve:
            layers = the_plan.transparency.params.get("layers") if method == "depth_peeling" else None
            transparent = (visible.n_opaque, visible.offsets, int(layers) if layers else len(f))  # type: ignore[call-overload]
        tables = plain_tables(prepared, gl_compat, shading)
        groups = _group_buffers(light_groups, prepared, tables, height, width)
        shade_plain_fragments_compiled(
            width, height, visible.opaque_of, f.triangle, f.bary, f.depth, f.front_facing,
            tables,
            None if visibility is None else (visibility if visibility.ndim == 3 else visibility[:, :, None]),
            None if visibility is None else shadow_pass_values(visibility),
            _targets(image),
            fog_args,
            transparent,
            groups,
        )  # fmt: skip
        seconds["shade"] = time.perf_counter() - t
        seconds["resolve_samples"] = 0.0
        say("shade", 1.0)
        image.passes.update(_group_passes(light_groups, groups))
        image.passes.update(ids)
        return image, len(f)

    # Shade, colour and resolve band by band (whole pixel rows): the shading arrays never hold more
    # than one band's fragments, and every stage works per fragment or per sample, so bands give
    # the image one pass would.
    f_all = visible.fragments
    rows_per_band = max(1, BAND_SAMPLES // (width * f_all.samples))
    rgba = np.zeros((height, width, 4), np.float32)
    depth = np.ones((height, width), np.float32)
    normal = np.zeros((height, width, 3), np.float32)
    passes = {name: np.zeros((height, width, 3), np.float32) for name in ("ambient", "diffuse", "specular")}
    if visibility is not None:
        passes["shadow"] = np.zeros((height, width, 1), np.float32)
    seconds["shade"] = seconds["resolve_samples"] = 0.0
    materials, _ = side_tables(scene)
    # Fragment colours (α·c, α) of partial occlusion without fog: the compiled resolve computes
    # them in its own pass (resolve_frame with rgba None), no (N, 4) colour array per band.
    plain_colours = (
        holdout is None
        and deep is None
        and compiled
        and fog_parameters is None
        and f_all.samples == 1
        and (method == "zbuffer" or not visible.n_transparent)
        and all(
            m.kay_greenberg is None
            and not m.specular_washout
            and (not m.transparent or m.transparency_model == "partial_occlusion")
            for m in materials
        )
    )
    for row0 in range(0, height, rows_per_band):
        row1 = min(height, row0 + rows_per_band)
        band = visible if (row0, row1) == (0, height) else visible.rows(row0, row1)
        band_vis = None
        if visibility is not None:
            o0, o1, t0, t1 = visible.fragment_range(row0, row1)
            n_op = visible.n_opaque
            band_vis = np.concatenate([visibility[o0:o1], visibility[n_op + t0 : n_op + t1]])
        t = time.perf_counter()
        shaded = shade_fragments(
            prepared,
            band.fragments,
            shading=shading,
            gl_compat=gl_compat,
            visibility=band_vis,
            engine=stage_engine,
        )
        shaded = texture_fragments(  # image textures
            prepared, band.fragments, shaded, gl_compat=gl_compat, engine=stage_engine
        )
        colour = alpha = None
        if not plain_colours:
            colour, alpha = fragment_colours(prepared, band, shaded, fog_parameters, engine=stage_engine)
        if holdout is not None:  # transparent black, opaque (blinn_phong.model.linking)
            held = holdout[prepared.triangle_mesh[band.fragments.triangle]]
            colour[held] = 0.0  # type: ignore[index]
            alpha[held] = 0.0  # type: ignore[index]
        if deep is not None:
            deep.add(prepared, band, colour, row0)
        seconds["shade"] += time.perf_counter() - t
        t = time.perf_counter()
        resolve_frame(  # writes straight into the band's rows of the frame buffers
            prepared,
            band,
            shaded,
            colour,
            alpha,
            method,
            visibility=band_vis,
            engine=stage_engine,
            out=FrameImage(
                rgba[row0:row1],
                depth[row0:row1],
                normal[row0:row1],
                {name: buffer[row0:row1] for name, buffer in passes.items()},
            ),
            **the_plan.transparency.params,  # type: ignore[arg-type]
        )
        del shaded, colour, alpha
        seconds["resolve_samples"] += time.perf_counter() - t
        say("shade", 0.6 + 0.4 * row1 / height)
    return FrameImage(rgba, depth, normal, {**passes, **ids}), len(f_all)
