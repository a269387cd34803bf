"""Stages 5 and 6 of the frame: fragment colours, transparency, and the box filter (``shading -> resolve``).

* :func:`fragment_colours` turns each shaded fragment into a premultiplied fragment by its
  material's transparency model (:func:`blinn_phong.effects.transparency.transparent_fragment`:
  partial occlusion ``(α·c, α)``, emission ``(α·c, 0)``, absorption ``(c, α)``), with
  Kay–Greenberg opacity and specular wash-out, then fogs it (:func:`blinn_phong.model.fog.apply_fog`:
  per fragment, before blending, as OpenGL 2.1 §3.10 does).
* :func:`resolve_frame` composites each sample's transparent fragments over its opaque one
  with the chosen method of :mod:`blinn_phong.effects.oit` (A-buffer, draw-last / sorted objects /
  sorted triangles, depth peeling, weighted blended OIT), box-filters the samples
  (:func:`resolve_samples`) and builds the depth, normal and light-pass buffers of the
  nearest surface of each sample.

Each has a numpy reference (readable, built on :mod:`blinn_phong.effects.oit` and
:mod:`compositing`) and a compiled twin in :mod:`blinn_phong.frame.resolve_kernels`; they agree to 1e-6
(the per-sample colours are rounded to float32 before the box filter in both).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from blinn_phong._numba import use_compiled
from blinn_phong.effects.oit import draw_order, resolve_transparency, wboit_weights
from blinn_phong.effects.transparency import (
    TRANSPARENCY_MODELS,
    kay_greenberg_transparency,
    transparent_fragment,
    washed_out_opacity,
)
from blinn_phong.frame.prepared import PreparedScene
from blinn_phong.frame.resolve_kernels import (
    RESOLVE_CODES,
    fragment_colours_compiled,
    resolve_frame_compiled,
    resolve_plain_compiled,
)
from blinn_phong.frame.shading import FragmentShading
from blinn_phong.frame.visibility import FrameFragments
from blinn_phong.geometry.normals import normalize
from blinn_phong.geometry.raster import interpolate, resolve_nearest
from blinn_phong.geometry.raster_kernels import scatter_samples_compiled
from blinn_phong.model.fog import apply_fog, eye_distance
from blinn_phong.model.scene import Material, Scene

__all__ = [
    "FogParameters",
    "FrameImage",
    "fragment_colours",
    "resolve_frame",
    "resolve_nearest_buffers",
    "resolve_samples",
    "shadow_pass_values",
    "side_tables",
]

_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. ITU-R BT.709 luminance of linear RGB


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


def _scatter_samples(
    n_keys: int, keys: np.ndarray, shaded: FragmentShading, depth: np.ndarray, engine: str
) -> tuple[np.ndarray, ...]:
    """Float32 per-sample buffers: premultiplied rgba, ambient, diffuse, specular; normal; depth (1 empty)."""
    if use_compiled(engine):
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


def shadow_pass_values(visibility: np.ndarray) -> np.ndarray:
    """(N,) the ``shadow`` pass of fragments before their opacity: the mean visibility over the
    lights (and channels) of ``visibility`` (N, L) or (N, L, K).

    Summed column by column in order, then divided by their count (numpy's ``mean`` over a short
    axis of a long array is several times slower).
    """
    # The column count from the trailing axes, never ``-1``: a band or tile with no fragment
    # gives N = 0, and numpy cannot infer the other axis of an empty array.
    v = visibility.reshape(visibility.shape[0], math.prod(visibility.shape[1:]))
    if v.shape[1] == 0:
        return np.full(len(v), np.nan)
    total = v[:, 0].astype(np.float64, copy=True)
    for column in range(1, v.shape[1]):
        total += v[:, column]
    total /= v.shape[1]
    return total


def side_tables(scene: Scene) -> tuple[list[Material], np.ndarray]:
    """Materials indexed ``2·mesh + back`` (back faces under two-sided lighting), and their opacity
    flag (a holdout mesh, ``Mesh.holdout``, is opaque whatever its material)."""
    materials = [m for mesh in scene.meshes for m in (mesh.material, mesh.back_material or mesh.material)]
    holdout = [mesh.holdout for mesh in scene.meshes for _ in (0, 1)]
    opaque = np.array([h or not m.transparent for m, h in zip(materials, holdout, strict=True)], dtype=bool)
    return materials, opaque


def fragment_side(prepared: PreparedScene, triangle: np.ndarray, front_facing: np.ndarray) -> np.ndarray:
    """Material side ``2·mesh + back`` of fragments (back = back-facing under two-sided lighting)."""
    back = ~np.asarray(front_facing, bool) if prepared.scene.light_model.two_sided else False
    return 2 * prepared.triangle_mesh[triangle] + back


def opaque_test(prepared: PreparedScene) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``opaque(triangle, front_facing)``: per fragment, whether its material side
    (:func:`fragment_side`) is opaque — the visibility stage's split of opaque and transparent."""
    _, side_opaque = side_tables(prepared.scene)

    def opaque(triangle: np.ndarray, front_facing: np.ndarray) -> np.ndarray:
        return side_opaque[fragment_side(prepared, triangle, front_facing)]

    return opaque


@dataclass(frozen=True)
class FogParameters:
    """Fog as the colour stage applies it (OpenGL 2.1 §3.10; see
    :class:`blinn_phong.planning.frame_plan.Fog`).

    Attributes:
        mode: ``"linear"``, ``"exp"`` or ``"exp2"``.
        color: linear RGB fog colour.
        density: exponential density per world unit.
        start: linear start distance.
        end: linear end distance.
        distance: ``"plane"`` (``|z_eye|``) or ``"radial"`` (``‖p_eye‖``).
    """

    mode: str
    color: tuple[float, float, float]
    density: float
    start: float
    end: float
    distance: str

    def compiled_args(self) -> tuple[str, bool, tuple[float, float, float], np.ndarray]:
        """``(mode, radial, (density, start, end), colour)``: the ``fog`` argument of the compiled
        kernels (:func:`blinn_phong.frame.resolve_kernels.fragment_colours_compiled`, the fused plain
        frame)."""
        radial = self.distance == "radial"
        return (self.mode, radial, (self.density, self.start, self.end), np.array(self.color))

    @classmethod
    def of(cls, fog: object) -> FogParameters | None:
        """The parameters of any object with a ``Fog``'s fields (or None for None)."""
        if fog is None:
            return None
        return cls(
            str(fog.mode),  # type: ignore[attr-defined]
            tuple(fog.color),  # type: ignore[attr-defined]
            float(fog.density),  # type: ignore[attr-defined]
            float(fog.start),  # type: ignore[attr-defined]
            float(fog.end),  # type: ignore[attr-defined]
            str(fog.distance),  # type: ignore[attr-defined]
        )


def fragment_colours(
    prepared: PreparedScene,
    fragments: FrameFragments,
    shaded: FragmentShading,
    fog: FogParameters | None = None,
    *,
    engine: str = "numpy",
) -> tuple[np.ndarray, np.ndarray]:
    """Premultiplied fragment RGBA by each material's transparency model, fogged, and the opacity used.

    Opacity is the material's, or Kay–Greenberg's ``1 − t(N_z)`` (Kay & Greenberg 1979, with the
    unit eye-space normal's z); wash-out raises it to ``min(1, α + luminance(specular))``
    (BT.709 luminance). The fragment is :func:`blinn_phong.effects.transparency.transparent_fragment` of
    ``Material.transparency_model``; opaque materials give ``(c, 1)``. Fog then blends it
    towards the fog colour by eye distance (:func:`blinn_phong.model.fog.apply_fog`).

    Args:
        prepared: the prepared scene.
        fragments: the visible fragments (:func:`blinn_phong.frame.visibility.frame_fragments`).
        shaded: their shading (straight colour, material opacity, light terms).
        fog: fog parameters, or None.
        engine: ``"numpy"`` (reference) or ``"numba"``/``"auto"`` (compiled, one pass).

    Returns:
        ``(rgba, alpha)``: (N, 4) float64 premultiplied RGBA and (N,) float64 opacity.
    """
    f = fragments.fragments
    materials, _ = side_tables(prepared.scene)
    side = fragment_side(prepared, f.triangle, f.front_facing)
    if use_compiled(engine):
        kg = np.zeros((len(materials), 4))
        for i, m in enumerate(materials):
            if m.kay_greenberg is not None:
                kg[i] = (1.0, *m.kay_greenberg)
        washout = np.array([m.specular_washout for m in materials], dtype=bool)
        model = np.array(
            [TRANSPARENCY_MODELS.index(m.transparency_model) if m.transparent else 0 for m in materials],
            dtype=np.int64,
        )
        fog_args = None if fog is None else fog.compiled_args()
        return fragment_colours_compiled(
            f.triangle,
            f.bary,
            prepared.triangles,
            prepared.eye_position,
            prepared.eye_normal,
            side,
            shaded.rgb,
            shaded.alpha,
            shaded.specular,
            (kg, washout, model),
            fog_args,
        )
    alpha = np.asarray(shaded.alpha, dtype=np.float64).copy()
    rgba = np.empty((len(alpha), 4))
    eye_nz = None
    for s in np.unique(side):
        material = materials[s]
        here = side == s
        if material.kay_greenberg is not None:
            if eye_nz is None:
                eye_nz = normalize(interpolate(f, prepared.triangles, prepared.eye_normal))[:, 2]
            t_min, t_max, power = material.kay_greenberg
            alpha[here] = 1.0 - kay_greenberg_transparency(
                np.clip(eye_nz[here], -1.0, 1.0), t_min, t_max, power
            )
        if material.specular_washout:
            highlight = np.maximum(shaded.specular[here] @ _LUMINANCE, 0.0)
            alpha[here] = washed_out_opacity(1.0 - alpha[here], highlight)
        model = material.transparency_model if material.transparent else "partial_occlusion"
        rgba[here] = transparent_fragment(shaded.rgb[here], alpha[here], model)
    if fog is not None:
        eye = interpolate(f, prepared.triangles, prepared.eye_position)
        rgba = apply_fog(
            rgba,
            eye_distance(eye, fog.distance),  # type: ignore[arg-type]
            fog.color,
            fog.mode,  # type: ignore[arg-type]
            density=fog.density,
            start=fog.start,
            end=fog.end,
        )
    return rgba, alpha


@dataclass(frozen=True, eq=False)
class FrameImage:
    """The resolved frame (row 0 at the top).

    Attributes:
        rgba: (H, W, 4) float32 premultiplied linear RGBA.
        depth: (H, W) float32 nearest window depth (1 = empty).
        normal: (H, W, 3) float32 world-space unit normal of the nearest surface (0 = empty).
        passes: ``ambient``/``diffuse``/``specular`` (H, W, 3) float32 premultiplied passes of the
            nearest surface, plus ``shadow`` (H, W, 1) when a light casts shadows.
    """

    rgba: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    passes: dict[str, np.ndarray]


def resolve_frame(
    prepared: PreparedScene,
    fragments: FrameFragments,
    shaded: FragmentShading,
    rgba: np.ndarray | None,
    alpha: np.ndarray | None,
    method: str,
    *,
    visibility: np.ndarray | None = None,
    layers: int | None = None,
    wboit_equation: str = "eq10",
    engine: str = "numpy",
    out: FrameImage | None = None,
) -> FrameImage:
    """Resolve each sample (transparency over the opaque fragment), then the box filter.

    Per sample: the opaque fragment's RGBA (transparent black where none), and over it the
    sample's transparent fragments resolved by ``method``
    (:func:`blinn_phong.effects.oit.resolve_transparency`:
    ``a_buffer``, ``draw_last``, ``sort_objects``, ``sort_triangles``, ``depth_peeling`` with
    ``layers``, ``weighted_blended`` with :func:`blinn_phong.effects.oit.wboit_weights` of
    ``wboit_equation`` on window depth; ``zbuffer``: none). Per-sample colours are rounded to
    float32, then :func:`resolve_samples` averages them. Depth, normal and light passes describe
    the nearest surface of each sample (opaque or transparent), weighted by ``alpha``.

    Args:
        prepared: the prepared scene.
        fragments: the visible fragments.
        shaded: their shading.
        rgba: (N, 4) premultiplied fragment colours (:func:`fragment_colours`), or None for
            partial occlusion ``(α·c, α)`` of ``shaded`` with no fog (what :func:`fragment_colours`
            gives when no material has Kay–Greenberg opacity, wash-out or another model and
            there is no fog; the compiled engine then computes it inside the resolve pass).
        alpha: (N,) opacity used (weights the passes); None with ``rgba`` None (``shaded.alpha``).
        method: ``zbuffer`` or one of :data:`blinn_phong.effects.oit.TRANSPARENCY_METHODS`.
        visibility: (N, L) per-light visibility of the fragments, or None (no shadow pass).
        layers: passes for ``depth_peeling``.
        wboit_equation: weight of ``weighted_blended``.
        engine: ``"numpy"`` (reference) or ``"numba"``/``"auto"`` (compiled, one pass per pixel).
        out: buffers to write the result into (C-contiguous float32 of the frame's shapes, with
            a ``shadow`` pass when ``visibility`` is given), or None for new ones.

    Returns:
        :class:`FrameImage` (``out`` when given).
    """
    f = fragments.fragments
    width, height, samples = f.width, f.height, f.samples
    n_keys = width * height * samples
    n_op = fragments.n_opaque
    vis_mean = None if visibility is None else shadow_pass_values(visibility)
    if rgba is None:
        compiled = use_compiled(engine)
        if compiled and samples == 1 and (method == "zbuffer" or not fragments.n_transparent):
            if out is None:
                names = ("ambient", "diffuse", "specular") + (() if vis_mean is None else ("shadow",))
                out = FrameImage(
                    np.empty((height, width, 4), np.float32),
                    np.empty((height, width), np.float32),
                    np.empty((height, width, 3), np.float32),
                    {n: np.empty((height, width, 1 if n == "shadow" else 3), np.float32) for n in names},
                )
            p = out.passes
            shadow_out = p["shadow"] if vis_mean is not None else np.zeros((0, 0, 1), np.float32)
            resolve_plain_compiled(
                width, height, fragments.opaque_of, shaded.rgb, shaded.alpha, shaded.ambient,
                shaded.diffuse, shaded.specular, shaded.normal, f.depth, vis_mean,
                (out.rgba, p["ambient"], p["diffuse"], p["specular"], out.normal, out.depth, shadow_out),
            )  # fmt: skip
            return out
        alpha = np.asarray(shaded.alpha, dtype=np.float64)
        rgba = np.concatenate([shaded.rgb * alpha[:, None], alpha[:, None]], axis=1)
    assert alpha is not None
    tr = slice(n_op, len(f))
    key = f.sample_key
    weights = sort_key = None
    if fragments.n_transparent and method == "weighted_blended":
        weights = wboit_weights(rgba[tr, 3], wboit_equation, window_depth=f.depth[tr])
    sorted_drawing = fragments.n_transparent and method in ("draw_last", "sort_objects", "sort_triangles")
    # the centroids' eye distances order the sorted-drawing methods only (a gather of every triangle)
    tri_dist = -prepared.face_eye_centroid[:, 2] if sorted_drawing else np.zeros(len(prepared.triangles))
    if use_compiled(engine):
        code, max_layers = RESOLVE_CODES["zbuffer"], 0
        n = len(f)
        if fragments.n_transparent and method != "zbuffer":
            sort_key = np.zeros(n)
            weight_all = np.zeros(n)
            if method == "weighted_blended":
                code = RESOLVE_CODES["weighted_blended"]
                weight_all[tr] = weights
            else:
                code, max_layers = RESOLVE_CODES["front_to_back"], len(f)
                if method in ("a_buffer", "depth_peeling"):
                    sort_key[tr] = f.depth[tr]
                    if method == "depth_peeling":
                        max_layers = int(layers)  # type: ignore[arg-type]
                else:  # last drawn = front
                    sort_key[tr] = -draw_order(
                        method,
                        f.triangle[tr],
                        triangle_mesh=prepared.triangle_mesh,
                        triangle_eye_distance=tri_dist,
                        front_facing=f.front_facing[tr],
                    ).astype(np.float64)
        else:
            sort_key = weight_all = np.zeros(0)
        targets = None
        if out is not None:
            p = out.passes
            shadow_out = p["shadow"] if vis_mean is not None else np.zeros((0, 0, 1), np.float32)
            targets = (out.rgba, p["ambient"], p["diffuse"], p["specular"], out.normal, out.depth, shadow_out)
        buffers = resolve_frame_compiled(
            width, height, samples, code, max_layers, n_op, fragments.opaque_of, fragments.offsets,
            sort_key, weight_all, rgba, alpha, shaded.ambient, shaded.diffuse, shaded.specular,
            shaded.normal, f.depth, vis_mean, targets,
        )  # fmt: skip
        image, ambient, diffuse, specular, normal, depth, shadow = buffers
        if samples > 1:
            normal[...] = normalize(normal)  # the mean of unit normals; one sample is unit already
        passes = {"ambient": ambient, "diffuse": diffuse, "specular": specular}
        if vis_mean is not None:
            passes["shadow"] = shadow
        return FrameImage(image, depth, normal, passes) if out is None else out

    per_sample = np.zeros((n_keys, 4))
    per_sample[key[:n_op]] = rgba[:n_op]
    if fragments.n_transparent and method != "zbuffer":
        per_sample = resolve_transparency(
            method,
            key[tr],
            f.depth[tr],
            rgba[tr],
            n_keys,
            triangle=f.triangle[tr],
            triangle_mesh=prepared.triangle_mesh,
            triangle_eye_distance=tri_dist,
            background=per_sample,
            layers=layers,
            weights=weights,
            front_facing=f.front_facing[tr],
        )
    image = resolve_samples(per_sample.astype(np.float32), width, height, samples)

    # The nearest surface of each sample (opaque or transparent): depth, normal and light passes.
    winner = resolve_nearest(f)
    covered = np.flatnonzero(winner >= 0)
    nearest = winner[covered]
    near = FragmentShading(
        shaded.rgb[nearest],
        alpha[nearest],
        shaded.ambient[nearest],
        shaded.diffuse[nearest],
        shaded.specular[nearest],
        shaded.normal[nearest],
    )
    _, passes, normal, depth = resolve_nearest_buffers(
        near, covered, f.depth[nearest], width, height, samples
    )
    if vis_mean is not None:
        buf = np.zeros((n_keys, 1), np.float32)
        buf[covered, 0] = vis_mean[nearest] * alpha[nearest]
        passes["shadow"] = resolve_samples(buf, width, height, samples)
    if out is None:
        return FrameImage(image, depth, normal, passes)
    out.rgba[...], out.depth[...], out.normal[...] = image, depth, normal
    for name, buffer in passes.items():
        out.passes[name][...] = buffer
    return out
