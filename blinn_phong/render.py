"""The render pipeline: prepare -> rasterize -> resolve visibility -> shade -> resolve samples.

Each stage is a public function so other passes (transparency, shadows, fog) can
reuse or replace one of them:

* :func:`prepare_scene` — every mesh to eye and clip space, normals, lights in eye space;
* :func:`blinn_phong.raster.visible_fragments` — the z-buffer pass: all fragments
  (:func:`~blinn_phong.raster.rasterize`) resolved to the nearest per sample
  (:func:`~blinn_phong.raster.resolve_nearest`), i.e. visibility before shading;
* :func:`shade_fragments` — the lighting equation at any set of fragments, at the
  mesh's shading frequency (flat / Gouraud / Phong);
* :func:`resolve_samples` — the box filter over the k×k samples of each pixel, giving
  coverage alpha.

Shading frequencies (Gouraud 1971; Phong 1975):

* ``flat`` — one evaluation per face with the face normal at the face centroid;
* ``gouraud`` — evaluation per vertex (vertex normals), colours interpolated;
* ``phong`` — position and normal interpolated, evaluation per fragment.

The **GL-compatibility preset** (``gl_compat=True``) reproduces OpenGL 2.1
fixed-function lighting (§2.14.1) bit-for-bit up to rounding: per-vertex evaluation
with vertex colours clamped to [0, 1] before interpolation (primary and secondary
separately under ``separate_specular``), flat shading taking the colour of the
provoking (last) vertex, and the final colour clamped to [0, 1] as an 8-bit
framebuffer does. In ``phong`` mode it models the per-pixel version of the same
equation (a GLSL fragment shader) followed by the framebuffer clamp.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from blinn_phong._feedback import start_feedback
from blinn_phong.lighting import EyeLights, ShadingTerms, gl_clamp, lights_in_eye_space, shade, shade_many
from blinn_phong.normals import face_normals, normalize, transform_normals, vertex_normals
from blinn_phong.planner import Plan
from blinn_phong.raster import Fragments, interpolate, visible_fragments
from blinn_phong.scene import SHADINGS, Material, Mesh, Scene, prepare_render_inputs

if TYPE_CHECKING:
    from blinn_phong.frame import Fog

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


@dataclass(frozen=True, eq=False)
class PreparedScene:
    """A scene flattened into concatenated arrays in eye and clip space.

    Attributes:
        scene: the source scene.
        clip: (V, 4) clip-space positions of all meshes' vertices.
        eye_position: (V, 3) eye-space positions.
        eye_normal: (V, 3) eye-space unit vertex normals (given, or averaged from faces).
        world_normal: (V, 3) world-space unit vertex normals.
        triangles: (T, 3) vertex indices into the concatenated arrays, meshes in scene order.
        triangle_mesh: (T,) index of each triangle's mesh.
        face_eye_normal, face_world_normal: (T, 3) unit face normals (inverse-transpose transformed).
        face_eye_centroid: (T, 3) eye-space centroids.
        vertex_offset: (M + 1,) first vertex of each mesh (and the total).
        lights: lights in eye space.
    """

    scene: Scene
    clip: np.ndarray
    eye_position: np.ndarray
    eye_normal: np.ndarray
    world_normal: np.ndarray
    triangles: np.ndarray
    triangle_mesh: np.ndarray
    face_eye_normal: np.ndarray
    face_world_normal: np.ndarray
    face_eye_centroid: np.ndarray
    vertex_offset: np.ndarray
    lights: EyeLights


def prepare_scene(scene: Scene) -> PreparedScene:
    """Transform every mesh of ``scene`` to eye and clip space and move the lights to eye space.

    Normals use the inverse-transpose of the model(-view) matrix (OpenGL 2.1 §2.11.3);
    meshes without normals get :func:`~blinn_phong.normals.vertex_normals` with the
    mesh's ``normal_weighting``.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a blinn_phong.Scene, got {type(scene).__name__}")
    view, proj = scene.camera.view, scene.camera.projection
    clips, eyes, eye_ns, world_ns, tris, owner = [], [], [], [], [], []
    f_eye, f_world, f_centroid = [], [], []
    offsets = [0]
    for m, mesh in enumerate(scene.meshes):
        model_view = view @ mesh.transform
        hom = np.c_[mesh.positions, np.ones(len(mesh.positions))]
        eye = hom @ model_view.T
        clips.append(eye @ proj.T)
        eyes.append(eye[:, :3])
        obj_n = mesh.normals
        if obj_n is None:
            obj_n = vertex_normals(mesh.positions, mesh.triangles, mesh.normal_weighting)
        eye_ns.append(transform_normals(obj_n, model_view))
        world_ns.append(transform_normals(obj_n, mesh.transform))
        face_obj = face_normals(mesh.positions, mesh.triangles)
        f_eye.append(transform_normals(face_obj, model_view))
        f_world.append(transform_normals(face_obj, mesh.transform))
        f_centroid.append(eye[:, :3][mesh.triangles].mean(axis=1))
        tris.append(mesh.triangles + offsets[-1])
        owner.append(np.full(len(mesh.triangles), m, np.int64))
        offsets.append(offsets[-1] + len(mesh.positions))

    def cat(parts: list[np.ndarray], shape: tuple[int, ...], dtype: type = np.float64) -> np.ndarray:
        return np.concatenate(parts) if parts else np.zeros((0, *shape), dtype)

    return PreparedScene(
        scene=scene,
        clip=cat(clips, (4,)),
        eye_position=cat(eyes, (3,)),
        eye_normal=cat(eye_ns, (3,)),
        world_normal=cat(world_ns, (3,)),
        triangles=cat(tris, (3,), np.int64),
        triangle_mesh=cat(owner, (), np.int64),
        face_eye_normal=cat(f_eye, (3,)),
        face_world_normal=cat(f_world, (3,)),
        face_eye_centroid=cat(f_centroid, (3,)),
        vertex_offset=np.asarray(offsets, np.int64),
        lights=lights_in_eye_space(scene.lights, view),
    )


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
        raise ValueError(f"shading: expected one of {SHADINGS}, got {shading!r}")
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
        fragments: fragments of ``prepared.triangles`` (from :func:`~blinn_phong.raster.rasterize`).
        shading: ``"flat"``, ``"gouraud"`` or ``"phong"``; a mesh's own ``shading`` overrides it.
        gl_compat: the OpenGL 2.1 fixed-function preset (module docstring).
        visibility: optional (N, L) per-fragment, per-light factors in [0, 1] multiplying
            diffuse and specular (L = ``len(prepared.lights)``, light order as in the
            scene without AmbientLights). With Gouraud/flat shading the per-light terms
            are interpolated and then multiplied, which has no per-vertex clamp, so it
            cannot be combined with ``gl_compat``.
        engine: ``"numpy"`` (reference), ``"numba"`` or ``"auto"`` for the lighting
            evaluation (:func:`blinn_phong.lighting.shade`).
    """
    shading = _check_shading(shading)
    count = len(fragments)
    n_lights = len(prepared.lights)
    if visibility is not None:
        visibility = np.asarray(visibility, dtype=np.float64)
        if visibility.shape != (count, n_lights):
            raise ValueError(
                f"visibility: expected shape (n_fragments, n_lights) = ({count}, {n_lights}), "
                f"got {visibility.shape}"
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


def surface_at_fragments(
    prepared: PreparedScene, fragments: Fragments, flip: np.ndarray, *, engine: str = "numpy"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interpolated eye-space position, unit eye-space normal and unit world normal at fragments.

    Perspective-correct interpolation of the vertex attributes (:func:`~blinn_phong.raster.interpolate`),
    normals renormalised after interpolation (Phong 1975); where ``flip`` (N,) is True the
    eye-space normal is negated (back faces under two-sided lighting). Zero-length
    normals stay zero.
    """
    if engine != "numpy":
        from blinn_phong.fast import numba_available, surface_at_fragments_compiled

        if numba_available():
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
    d = np.einsum("nlc,nl->nc", at(terms.diffuse_per_light), vis)
    s = np.einsum("nlc,nl->nc", at(terms.specular_per_light), vis)
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


def resolve_samples(values: np.ndarray, width: int, height: int, samples: int) -> np.ndarray:
    """Box-filter per-sample values to pixels: the mean over each pixel's samples.

    Args:
        values: (height·width·samples, C) values ordered by ``Fragments.sample_key``
            (uncovered samples hold zeros, so premultiplied colour and coverage average correctly).
        width: image width in pixels.
        height: image height in pixels.
        samples: samples per pixel.

    Returns:
        (height, width, C) means (row 0 at the top), in the dtype of ``values``
        (accumulated in float64).
    """
    values = np.asarray(values)
    if values.ndim != 2 or values.shape[0] != width * height * samples:
        raise ValueError(
            f"values: expected shape ({width * height * samples}, C) for {height}×{width}×{samples} samples, "
            f"got {values.shape}"
        )
    grid = values.reshape(height, width, samples, -1)
    if samples == 1:
        return grid[:, :, 0]
    return grid.mean(axis=2, dtype=np.float64).astype(values.dtype, copy=False)


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


def _scatter_samples(
    n_keys: int, keys: np.ndarray, shaded: FragmentShading, depth: np.ndarray, engine: str
) -> tuple[np.ndarray, ...]:
    """Float32 per-sample buffers: premultiplied rgba, ambient, diffuse, specular; normal; depth (1 empty)."""
    if engine != "numpy":
        from blinn_phong.fast import numba_available, scatter_samples_compiled

        if numba_available():
            return scatter_samples_compiled(
                n_keys,
                keys,
                shaded.rgb,
                shaded.alpha,
                shaded.ambient,
                shaded.diffuse,
                shaded.specular,
                shaded.normal,
                depth,
            )
    a = shaded.alpha[:, None]
    out = []
    for values, channels in (
        (np.concatenate([shaded.rgb * a, a], axis=1), 4),
        (shaded.ambient * a, 3),
        (shaded.diffuse * a, 3),
        (shaded.specular * a, 3),
        (shaded.normal, 3),
    ):
        buf = np.zeros((n_keys, channels), np.float32)
        buf[keys] = values
        out.append(buf)
    depth_buf = np.ones(n_keys, np.float32)
    depth_buf[keys] = depth
    out.append(depth_buf)
    return tuple(out)


@dataclass(frozen=True)
class RenderStats:
    """Timing and counts of one render.

    Attributes:
        seconds: wall time per stage (``prepare``, ``visibility`` — rasterization and
            depth resolve —, ``shade``, ``resolve_samples``) in seconds.
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
        plan: the :class:`~blinn_phong.planner.Plan` the render followed (``plan.reasons()``
            gives one line per decision; the caller's overrides say so).
    """

    rgba: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    passes: dict[str, np.ndarray]
    stats: RenderStats
    plan: Plan | None = None


def resolve_nearest_buffers(
    shaded: FragmentShading,
    keys: np.ndarray,
    depth: np.ndarray,
    width: int,
    height: int,
    samples: int,
    engine: str = "numpy",
) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """Image buffers of one shaded fragment per covered sample (the nearest surface).

    Args:
        shaded: the fragments' shading (straight colour and opacity).
        keys: (N,) their sample keys (``Fragments.sample_key``), distinct.
        depth: (N,) their window depths.
        width: image width in pixels.
        height: image height in pixels.
        samples: samples per pixel.
        engine: ``"numpy"``, or ``"numba"``/``"auto"`` for the compiled scatter.

    Returns:
        ``(rgba, passes, normal, depth)``: (H, W, 4) float32 premultiplied RGBA (coverage ×
        opacity in alpha), the ``ambient``/``diffuse``/``specular`` (H, W, 3) premultiplied
        passes, the (H, W, 3) world normal (mean over covered samples, renormalised) and the
        (H, W) nearest window depth (1.0 where empty, the OpenGL clear value).
    """
    n_keys = width * height * samples
    buffers = _scatter_samples(n_keys, keys, shaded, depth, engine)
    rgba, ambient, diffuse, specular, normal = (
        resolve_samples(b, width, height, samples) for b in buffers[:5]
    )
    passes = {"ambient": ambient, "diffuse": diffuse, "specular": specular}
    if samples > 1:
        normal = normalize(normal)  # the mean of unit normals; one sample is unit already
    depth_img = buffers[5].reshape(height, width, samples).min(axis=2)
    return rgba, passes, normal, depth_img


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
) -> RenderResult:
    """Render ``scene`` with a z-buffer and local (Blinn-)Phong lighting, plus the effects the plan needs.

    The planner (:func:`blinn_phong.planner.plan`) picks the transparency method and each
    light's shadow method; an argument other than ``None``/``"auto"`` replaces the
    planner's choice for that concern only (:func:`blinn_phong.frame.frame_plan`). The
    plan followed, with one reason per decision, is ``result.plan``. With no transparent
    material, no shadow to cast and no fog the image is the plain z-buffer render.

    Args:
        scene: the :class:`~blinn_phong.scene.Scene` (camera required).
        width: image width in pixels.
        height: image height in pixels.
        shading: ``"auto"`` — the planner's per-mesh shading frequency (flat where it is exact,
            else Phong at tolerance 0); or ``"flat"``, ``"gouraud"``, ``"phong"`` for every mesh
            (a mesh's ``shading`` overrides it).
        samples: supersampling: k² samples per pixel on an ordered k×k grid; the result's
            alpha is the covered fraction.
        gl_compat: the OpenGL 2.1 fixed-function preset (see the module docstring).
        cull_backfaces: discard clockwise (back-facing) triangles.
        engine: ``"numpy"`` — the reference implementation; ``"numba"`` — the compiled
            visibility pass and lighting kernel (same results to ~1e-12); ``"auto"`` —
            numba when it can be imported, else numpy.
        progress: ``callback(stage, fraction_done)`` called as stages finish; ``None`` (default)
            prints ``render: <stage> <percent>`` to stderr, if it is a terminal, once the render
            has run 3 s; ``True`` from the start, ``False`` never (:mod:`blinn_phong._feedback`).
            When numba compiles the kernels (once per machine) ``compiling kernels (once per
            machine)…`` is printed to stderr.
        transparency: ``None``/``"auto"`` (the planner's choice) or one of
            :data:`blinn_phong.frame.TRANSPARENCY_CHOICES`: ``zbuffer`` (nearest fragment,
            alpha = opacity), ``draw_last``, ``sort_objects``, ``sort_triangles``,
            ``depth_peeling``, ``a_buffer`` (exact), ``weighted_blended``.
        peel_layers: layers for depth peeling (None: the planner's, else 8); older name of ``layers``.
        wboit_weight: weighted blended OIT weight, ``"eq10"`` (McGuire & Bavoil eq. 10) or ``"constant"``.
        shadows: ``None``/``"auto"`` (the planner's choice per light), a method of
            :data:`blinn_phong.frame.SHADOW_CHOICES` or a :class:`blinn_phong.frame.ShadowOptions`
            (method and parameters) for every light, or a list with one such entry per
            ``scene.lights`` entry.
        fog: a :class:`blinn_phong.frame.Fog` applied per fragment before blending, or None.
        tolerance: the planner's tolerance in 8-bit steps (0: exact methods only; see
            :func:`blinn_phong.planner.plan` for the error each concern bounds).
        layers: layers for depth peeling, the name the plan's parameters use
            (``result.plan.transparency.params["layers"]``); same as ``peel_layers``.

    ``gl_compat=True`` renders with the plain z-buffer and no shadows or fog (asking for them
    raises ``ValueError``).

    Returns:
        :class:`RenderResult`, with ``plan`` the plan followed.
    """
    from blinn_phong import frame  # the effects stages build on this module's stages

    if layers is not None:
        if peel_layers is not None and peel_layers != layers:
            raise ValueError(
                f"layers, peel_layers: two names for one setting, got {layers!r} and {peel_layers!r}"
            )
        peel_layers = layers

    if shading != "auto":
        shading = _check_shading(shading)
    if engine not in ("numpy", "numba", "auto"):
        raise ValueError(f"engine: expected 'numpy', 'numba' or 'auto', got {engine!r}")
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a blinn_phong.Scene, got {type(scene).__name__}")
    # Size/memory, gl_compat light model, meshes without triangles dropped (blinn_phong/scene.py).
    scene = prepare_render_inputs(scene, width, height, samples, gl_compat)
    progress = start_feedback(engine, progress)  # compile notice, progress lines (blinn_phong/_feedback.py)
    if fog is not None and not isinstance(fog, frame.Fog):
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
    the_plan = frame.frame_plan(
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
    )
    seconds["plan"] = time.perf_counter() - t
    if shading == "auto":
        scene, shading = frame.scene_with_planned_shading(scene, the_plan, shading), "phong"

    t = time.perf_counter()
    prepared = prepare_scene(scene)
    seconds["prepare"] = time.perf_counter() - t
    report("prepare", 0.05)

    if frame.needs_effects(scene, the_plan, fog):

        def shade(fragments: Fragments, visibility: np.ndarray | None) -> FragmentShading:
            return shade_fragments(prepared, fragments, shading=shading, visibility=visibility, engine=engine)

        rgba, depth, normal, passes, n_shaded = frame.render_effects(
            prepared,
            width,
            height,
            the_plan,
            shade=shade,
            samples=samples,
            cull_backfaces=cull_backfaces,
            fog=fog,
            seconds=seconds,
            report=report,
        )
        report("done", 1.0)
        stats = RenderStats(seconds, len(prepared.triangles), n_shaded)
        return RenderResult(rgba, depth, normal, passes, stats, plan=the_plan)

    t = time.perf_counter()
    visible = visible_fragments(
        prepared.clip,
        prepared.triangles,
        width,
        height,
        samples=samples,
        cull_backfaces=cull_backfaces,
        engine=engine,
        progress=None if progress is None else (lambda f: report("visibility", 0.05 + 0.45 * f)),
    )
    seconds["visibility"] = time.perf_counter() - t
    report("visibility", 0.5)

    t = time.perf_counter()
    shaded = shade_fragments(prepared, visible, shading=shading, gl_compat=gl_compat, engine=engine)
    seconds["shade"] = time.perf_counter() - t
    report("shade", 0.9)

    t = time.perf_counter()
    # Scatter each per-sample quantity into a float32 sample buffer, then the box filter.
    rgba, passes, normal, depth = resolve_nearest_buffers(
        shaded, visible.sample_key, visible.depth, width, height, visible.samples, engine
    )
    seconds["resolve_samples"] = time.perf_counter() - t
    report("done", 1.0)

    stats = RenderStats(seconds, len(prepared.triangles), len(visible))
    return RenderResult(rgba=rgba, depth=depth, normal=normal, passes=passes, stats=stats, plan=the_plan)
