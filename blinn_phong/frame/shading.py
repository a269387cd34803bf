"""Stage 4 of the frame: the lighting equation at the visible fragments (``fragments -> shading``).

:func:`shade_fragments` evaluates :mod:`blinn_phong.frame.lighting` at any set of fragments of a
:class:`~blinn_phong.frame.prepared.PreparedScene`, at the mesh's shading frequency (Gouraud 1971;
Phong 1975):

* ``flat`` — one evaluation per face with the face normal at the face centroid;
* ``gouraud`` — evaluation per vertex (vertex normals), colours interpolated;
* ``phong`` — position and normal interpolated, evaluation per fragment.

Under the GL-compatibility preset (``gl_compat=True``) it reproduces OpenGL 2.1
fixed-function lighting (§2.14.1): per-vertex colours clamped to [0, 1] before
interpolation, flat shading taking the provoking (last) vertex's colour, the final colour
clamped to [0, 1]. The frame pipeline (:mod:`blinn_phong.frame.pipeline`) shades only the
fragments that survive the depth test, once each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blinn_phong._checks import choice_error
from blinn_phong._numba import use_compiled
from blinn_phong.frame.fused import PlainTables
from blinn_phong.frame.lighting import (
    ShadingTerms,
    gl_clamp,
    light_tables,
    material_tables,
    shade,
    shade_many,
)
from blinn_phong.frame.prepared import PreparedScene
from blinn_phong.geometry.normals import normalize
from blinn_phong.geometry.raster import Fragments, interpolate
from blinn_phong.geometry.raster_kernels import surface_at_fragments_compiled
from blinn_phong.model.scene import SHADINGS, Material, Mesh, Scene

__all__ = [
    "FragmentShading",
    "check_gl_ranges",
    "fused_shading_applies",
    "plain_tables",
    "shade_fragments",
    "surface_at_fragments",
]


@dataclass(frozen=True, eq=False)
class FragmentShading:
    """Shaded fragments (linear RGB, straight — not premultiplied — colour).

    Attributes:
        rgb: (N, 3) final colour (clamped to [0, 1] only under ``gl_compat``).
        alpha: (N,) material opacity.
        ambient, diffuse, specular: (N, 3) the equation's terms (emission included in
            ambient), unclamped; the passes a compositor or Blender writes.
        normal: (N, 3) world-space unit shading normal (face normal for flat shading).
    """

    rgb: np.ndarray
    alpha: np.ndarray
    ambient: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray
    normal: np.ndarray


def _check_shading(shading: object) -> str:
    if shading not in SHADINGS:
        raise choice_error("shading", shading, SHADINGS)
    return str(shading)


def shade_fragments(
    prepared: PreparedScene,
    fragments: Fragments,
    *,
    shading: str = "phong",
    gl_compat: bool = False,
    visibility: np.ndarray | None = None,
    engine: str = "numpy",
) -> FragmentShading:
    """Shade any set of fragments of ``prepared`` (e.g. the nearest ones, or all of them).

    Args:
        prepared: from :func:`prepare_scene`.
        fragments: fragments of ``prepared.triangles`` (from :func:`~blinn_phong.geometry.raster.rasterize`).
        shading: ``"flat"``, ``"gouraud"`` or ``"phong"``; a mesh's own ``shading`` overrides it.
        gl_compat: the OpenGL 2.1 fixed-function preset (module docstring).
        visibility: optional (N, L) per-fragment, per-light factors in [0, 1] multiplying
            diffuse and specular, or (N, L, 3) one per RGB channel (L = ``len(prepared.lights)``,
            light order as in the scene without AmbientLights). With Gouraud/flat shading the per-light terms
            are interpolated and then multiplied, which has no per-vertex clamp, so it
            cannot be combined with ``gl_compat``.
        engine: ``"numpy"`` (reference), ``"numba"`` or ``"auto"`` for the lighting
            evaluation (:func:`blinn_phong.frame.lighting.shade`).
    """
    shading = _check_shading(shading)
    count = len(fragments)
    n_lights = len(prepared.lights)
    if visibility is not None:
        visibility = np.asarray(visibility, dtype=np.float64)
        if visibility.shape not in ((count, n_lights), (count, n_lights, 3)):
            raise ValueError(
                f"visibility: expected shape (n_fragments, n_lights) = ({count}, {n_lights}) or "
                f"(n_fragments, n_lights, 3) per RGB channel, got {visibility.shape}"
            )
    scene = prepared.scene
    model = scene.light_model
    mesh_of = prepared.triangle_mesh[fragments.triangle]
    modes = [mesh.shading or shading for mesh in scene.meshes]
    phong = np.array([mode == "phong" for mode in modes], bool)
    if count and phong.all():  # the common case: every fragment shaded per pixel, no scatter
        return _shade_phong(prepared, fragments, mesh_of, gl_compat, visibility, engine)

    out = {k: np.zeros((count, 3)) for k in ("rgb", "ambient", "diffuse", "specular", "normal")}
    alpha = np.zeros(count)

    def store(idx: np.ndarray, result: FragmentShading) -> None:
        alpha[idx] = result.alpha
        for k in out:
            out[k][idx] = getattr(result, k)

    if count and phong.any():
        idx = np.flatnonzero(phong[mesh_of])
        vis = None if visibility is None else visibility[idx]
        store(idx, _shade_phong(prepared, fragments.subset(idx), mesh_of[idx], gl_compat, vis, engine))
    for m, mesh in enumerate(scene.meshes):
        if phong[m]:
            continue
        in_mesh = np.flatnonzero(mesh_of == m)
        if len(in_mesh) == 0:
            continue
        mode = modes[m]
        if visibility is not None and gl_compat:
            raise ValueError(
                f"visibility: cannot be combined with gl_compat and {mode!r} shading "
                "(OpenGL clamps per vertex before any per-fragment factor); use phong shading"
            )
        sides: list[tuple[bool, Material, np.ndarray]]
        if model.two_sided:
            facing = fragments.front_facing[in_mesh]
            sides = [
                (True, mesh.material, in_mesh[facing]),
                (False, mesh.back_material or mesh.material, in_mesh[~facing]),
            ]
        else:
            sides = [(True, mesh.material, in_mesh)]
        for front, material, idx in sides:
            if len(idx) == 0:
                continue
            f = fragments.subset(idx)
            vis = None if visibility is None else visibility[idx]
            result = _shade_side(prepared, m, mesh, f, mode, front, material, gl_compat, vis, engine)
            alpha[idx] = result["alpha"]
            for k in out:
                out[k][idx] = result[k]
    return FragmentShading(out["rgb"], alpha, out["ambient"], out["diffuse"], out["specular"], out["normal"])


def _shade_phong(
    prepared: PreparedScene,
    f: Fragments,
    mesh_of: np.ndarray,
    gl_compat: bool,
    vis: np.ndarray | None,
    engine: str,
) -> FragmentShading:
    """Per-fragment lighting of fragments of phong-shaded meshes (any mix of meshes and sides)."""
    scene = prepared.scene
    model = scene.light_model
    back = ~f.front_facing if model.two_sided else np.zeros(len(f), bool)
    materials = [mat for mesh in scene.meshes for mat in (mesh.material, mesh.back_material or mesh.material)]
    material_ids = 2 * mesh_of + back
    points, normals, world_n = surface_at_fragments(prepared, f, back, engine=engine)
    terms = shade_many(
        points,
        normals,
        material_ids,
        materials,
        prepared.lights,
        global_ambient=scene.ambient,
        model=model,
        visibility=vis,
        engine=engine,
    )
    if gl_compat:
        primary, secondary = gl_clamp(terms, separate_specular=model.separate_specular)
        rgb = np.clip(primary + secondary, 0.0, 1.0)
    else:
        rgb = terms.color
    return FragmentShading(rgb, terms.alpha, terms.ambient, terms.diffuse, terms.specular, world_n)


def fused_shading_applies(
    scene: Scene, shading: str, samples: int, *, gl_compat: bool = False, shadows: bool = False
) -> bool:
    """True when the compiled engine may shade and resolve the frame in one fused pass.

    That is: one sample per pixel (fogged or not: the pass applies fog), every mesh shaded per
    pixel (``phong``) — or, without ``gl_compat``, per face (``flat``, lit per pixel at the
    face's centroid) or, without ``shadows`` too, per vertex (``gouraud``, from the tables of
    :func:`plain_tables`) —, no image texture,
    and every material's fragment colour the partial-occlusion ``(α·c, α)`` (no Kay–Greenberg
    opacity, no specular wash-out, no emission/absorption model). Transparency resolves are
    checked by the caller (none may be needed). The fused pass
    (:func:`blinn_phong.frame.fused.shade_plain_fragments_compiled`) gives the images of
    :func:`shade_fragments`, :func:`blinn_phong.frame.texturing.texture_fragments` and
    :func:`blinn_phong.frame.resolve.resolve_frame` for these frames.
    """
    if samples != 1:
        return False
    modes = {mesh.shading or shading for mesh in scene.meshes}
    if (gl_compat and modes != {"phong"}) or (shadows and "gouraud" in modes):
        return False
    materials = [m for mesh in scene.meshes for m in (mesh.material, mesh.back_material or mesh.material)]
    return all(
        not m.textured
        and m.kay_greenberg is None
        and not m.specular_washout
        and (not m.transparent or m.transparency_model == "partial_occlusion")
        for m in materials
    )


def _frequency_tables(prepared: PreparedScene, shading: str) -> tuple[np.ndarray, ...]:
    """``(mode, vertex_terms, winding, view_t)``: what the fused kernels need for flat and Gouraud
    meshes.

    ``mode`` (M,) int64 per mesh: 0 phong, 1 flat, 2 gouraud (``mesh.shading or shading``).
    ``vertex_terms`` (2, V, 9): the ambient, diffuse and specular RGB of
    :func:`blinn_phong.frame.lighting.shade` at each vertex (with its normal) of Gouraud meshes, for the
    front ``[0]`` and, under two-sided lighting, the back ``[1]`` side (negated normal, back
    material) — the evaluations :func:`shade_fragments` makes, which the fused pass
    interpolates; empty (2, 0, 9) when no mesh is Gouraud-shaded. Flat meshes are lit per pixel
    at their face's eye-space centroid with the face normal, which the pass forms from the
    eye-space corners: ``winding`` (M,) is the sign of ``det(view · model)`` (the corners' cross
    product is ``det M · M⁻ᵀ`` times the object-space one, so it points along the transformed
    normal up to that sign), ``view_t`` (3, 3) the view matrix's rotation part transposed (the
    world normal is ``Vᵀ`` times the eye normal, up to length).
    """
    scene = prepared.scene
    model = scene.light_model
    modes = np.array([("phong", "flat", "gouraud").index(mesh.shading or shading) for mesh in scene.meshes])
    modes = modes.astype(np.int64)
    view = scene.camera.view
    winding = np.array(
        [np.sign(np.linalg.det(view[:3, :3] @ mesh.transform[:3, :3])) for mesh in scene.meshes]
    )
    view_t = np.ascontiguousarray(view[:3, :3].T, dtype=np.float64)
    gouraud = bool((modes == 2).any())
    vertex_terms = np.zeros((2, len(prepared.eye_position) if gouraud else 0, 9))
    for m, mesh in enumerate(scene.meshes):
        if modes[m] != 2:
            continue
        a, b = prepared.vertex_offset[m], prepared.vertex_offset[m + 1]
        for side in range(2 if model.two_sided else 1):
            material = mesh.material if side == 0 else (mesh.back_material or mesh.material)
            terms = shade(
                prepared.eye_position[a:b], (-1.0 if side else 1.0) * prepared.eye_normal[a:b], material,
                prepared.lights, global_ambient=scene.ambient, model=model, engine="auto",
            )  # fmt: skip
            vertex_terms[side, a:b, 0:3] = terms.ambient
            vertex_terms[side, a:b, 3:6] = terms.diffuse
            vertex_terms[side, a:b, 6:9] = terms.specular
    return modes, vertex_terms, winding.astype(np.float64), view_t


def plain_tables(prepared: PreparedScene, gl_compat: bool, shading: str = "phong") -> PlainTables:
    """The arrays the fused frame kernels of :mod:`blinn_phong.frame.fused` read (see ``PlainTables`` there):
    geometry in eye and world space, per-side material tables (index ``2·mesh + back``), the
    eye-space lights, the light model's flags, and each mesh's shading frequency with its
    per-face or per-vertex terms (:func:`_frequency_tables`; ``shading`` as for
    :func:`shade_fragments`)."""
    scene = prepared.scene
    model = scene.light_model
    materials = [mat for mesh in scene.meshes for mat in (mesh.material, mesh.back_material or mesh.material)]
    geometry = tuple(
        np.ascontiguousarray(a)
        for a in (
            prepared.triangles,
            prepared.triangle_mesh,
            prepared.eye_position,
            prepared.eye_normal,
            prepared.world_normal,
        )
    )
    flags = (model.local_viewer, model.specular == "blinn", gl_compat, model.separate_specular)
    flags = tuple(bool(v) for v in flags)
    return (
        bool(model.two_sided),
        geometry,
        material_tables(materials, prepared.lights, scene.ambient),
        light_tables(prepared.lights),
        flags,
        _frequency_tables(prepared, _check_shading(shading)),
    )


def surface_at_fragments(
    prepared: PreparedScene, fragments: Fragments, flip: np.ndarray, *, engine: str = "numpy"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interpolated eye-space position, unit eye-space normal and unit world normal at fragments.

    Perspective-correct interpolation of the vertex attributes
    (:func:`~blinn_phong.geometry.raster.interpolate`),
    normals renormalised after interpolation (Phong 1975); where ``flip`` (N,) is True the
    eye-space normal is negated (back faces under two-sided lighting). Zero-length
    normals stay zero.
    """
    if use_compiled(engine):
        return surface_at_fragments_compiled(
            fragments.triangle,
            fragments.bary,
            prepared.triangles,
            prepared.eye_position,
            prepared.eye_normal,
            prepared.world_normal,
            flip,
        )
    tris = prepared.triangles
    points = interpolate(fragments, tris, prepared.eye_position)
    sign = np.where(flip, -1.0, 1.0)[:, None]
    normals = sign * normalize(interpolate(fragments, tris, prepared.eye_normal))
    world_n = normalize(interpolate(fragments, tris, prepared.world_normal))
    return points, normals, world_n


def _terms_at_fragments(
    terms: ShadingTerms, f: Fragments, triangles: np.ndarray, vis: np.ndarray | None, per_triangle: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Carry per-vertex (interpolated) or per-triangle terms to fragments, applying visibility."""

    def at(values: np.ndarray) -> np.ndarray:
        flat = values.reshape(len(values), -1)
        got = flat[f.triangle] if per_triangle else interpolate(f, triangles, flat)
        return got.reshape((len(f), *values.shape[1:]))

    ambient = at(terms.ambient)
    if vis is None:
        return ambient, at(terms.diffuse), at(terms.specular)
    spec = "nlc,nlc->nc" if vis.ndim == 3 else "nlc,nl->nc"  # (N, L, 3) per channel, or (N, L)
    d = np.einsum(spec, at(terms.diffuse_per_light), vis)
    s = np.einsum(spec, at(terms.specular_per_light), vis)
    return ambient, d, s


def _shade_side(
    prepared: PreparedScene,
    m: int,
    mesh: Mesh,
    f: Fragments,
    mode: str,
    front: bool,
    material: Material,
    gl_compat: bool,
    vis: np.ndarray | None,
    engine: str,
) -> dict[str, np.ndarray]:
    scene = prepared.scene
    model = scene.light_model
    sign = 1.0 if front else -1.0
    tris = prepared.triangles
    world_n = normalize(interpolate(f, tris, prepared.world_normal))
    common = {"global_ambient": scene.ambient, "model": model}

    if mode == "flat" and not gl_compat:
        # One evaluation per face: face normal at the centroid, carried to every fragment of the face.
        used, inverse = np.unique(f.triangle, return_inverse=True)
        terms = shade(
            prepared.face_eye_centroid[used],
            sign * prepared.face_eye_normal[used],
            material,
            prepared.lights,
            per_light=vis is not None,
            engine="numpy" if vis is not None or engine == "numpy" else "auto",
            **common,
        )
        local = Fragments(
            f.width, f.height, f.samples, f.pixel, f.sample, f.depth, inverse, f.bary, f.front_facing
        )
        ambient, diffuse, specular = _terms_at_fragments(terms, local, tris, vis, per_triangle=True)
        rgb = ambient + diffuse + specular
        return _pack(
            rgb,
            ambient,
            diffuse,
            specular,
            np.full(len(f), material.opacity),
            prepared.face_world_normal[f.triangle],
        )

    # Per-vertex evaluation over this mesh's vertices (Gouraud, or GL flat = provoking vertex).
    v0, v1 = prepared.vertex_offset[m], prepared.vertex_offset[m + 1]
    terms = shade(
        prepared.eye_position[v0:v1],
        sign * prepared.eye_normal[v0:v1],
        material,
        prepared.lights,
        per_light=vis is not None,
        engine="numpy" if vis is not None or engine == "numpy" else "auto",
        **common,
    )
    local_tris = tris - v0  # valid for this mesh's triangles
    if mode == "gouraud":
        ambient, diffuse, specular = _terms_at_fragments(terms, f, local_tris, vis, per_triangle=False)
        if gl_compat:
            primary, secondary = gl_clamp(terms, separate_specular=model.separate_specular)
            rgb = np.clip(
                interpolate(f, local_tris, primary) + interpolate(f, local_tris, secondary), 0.0, 1.0
            )
        else:
            rgb = ambient + diffuse + specular
        return _pack(rgb, ambient, diffuse, specular, np.full(len(f), material.opacity), world_n)

    # gl_compat flat: the provoking (last) vertex's clamped colour for the whole triangle.
    provoking = local_tris[f.triangle, 2]
    primary, secondary = gl_clamp(terms, separate_specular=model.separate_specular)
    rgb = np.clip(primary[provoking] + secondary[provoking], 0.0, 1.0)
    return _pack(
        rgb,
        terms.ambient[provoking],
        terms.diffuse[provoking],
        terms.specular[provoking],
        np.full(len(f), material.opacity),
        prepared.face_world_normal[f.triangle],
    )


def _pack(
    rgb: np.ndarray,
    ambient: np.ndarray,
    diffuse: np.ndarray,
    specular: np.ndarray,
    alpha: np.ndarray,
    normal: np.ndarray,
) -> dict[str, np.ndarray]:
    return {
        "rgb": rgb,
        "ambient": ambient,
        "diffuse": diffuse,
        "specular": specular,
        "alpha": alpha,
        "normal": normal,
    }


def check_gl_ranges(scene: Scene) -> None:
    """Raise ValueError where the scene leaves OpenGL 2.1's parameter ranges (§2.14.2, table 2.10).

    ``glMaterial`` accepts shininess in [0, 128] and ``glLight`` a spot exponent in
    [0, 128]; outside them OpenGL raises GL_INVALID_VALUE, so the GL-compatibility
    preset refuses them instead of rendering something OpenGL never would.
    """
    for i, mesh in enumerate(scene.meshes):
        for label, material in (("material", mesh.material), ("back_material", mesh.back_material)):
            if material is not None and material.shininess > 128.0:
                raise ValueError(
                    f"scene.meshes[{i}].{label}.shininess: OpenGL accepts [0, 128] (gl_compat=True), "
                    f"got {material.shininess}"
                )
    for i, light in enumerate(scene.lights):
        exponent = getattr(light, "exponent", 0.0)
        if exponent > 128.0:
            raise ValueError(
                f"scene.lights[{i}].exponent: OpenGL accepts a spot exponent in [0, 128] (gl_compat=True), "
                f"got {exponent}"
            )
