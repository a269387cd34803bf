"""The compiled (numba) twins of the colour and resolve stages of :mod:`blinn_phong.frame.resolve`.

* :func:`fragment_colours_compiled`: transparency models, Kay–Greenberg, wash-out and fog per
  fragment (twin of :func:`blinn_phong.frame.resolve.fragment_colours`).
* :func:`resolve_frame_compiled`: per pixel, each sample's transparent list sorted and
  composited over its opaque fragment (or accumulated for weighted blended OIT), then the box
  filter and the nearest surface's buffers (twin of :func:`blinn_phong.frame.resolve.resolve_frame`).
* :func:`_fog_function`: the per-fragment fog every compiled kernel applies (OpenGL 2.1 §3.10),
  shared with the fused frame pass (:mod:`blinn_phong.frame.fused`).

Serial loops that release the GIL, run on shares of their fragments or pixels on threads
(:mod:`compositing._threads`); each share owns its outputs.
"""

from __future__ import annotations

import functools

import numpy as np

from blinn_phong.geometry.raster_kernels import _shares

#: Fog modes of the compiled kernels (index = code), as :data:`blinn_phong.model.fog.FOG_MODES`.
_FOG_CODES = ("linear", "exp", "exp2")
#: The compiled per-fragment fog, set by :func:`_fog_function` (a module global: see
#: :func:`blinn_phong.frame.fused._row_kernels`).
_fogged: object = None
#: ``fog`` argument of the compiled kernels without fog (see :func:`_fog_scalars`).
_NO_FOG = (-1, False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

FogArgs = tuple[str, bool, tuple[float, float, float], np.ndarray] | None


def _fog_scalars(fog: FogArgs) -> tuple[int, bool, float, float, float, float, float, float]:
    """``(mode code, radial, density, start, end, r, g, b)`` of ``fog = (mode, radial, (density,
    start, end), colour)`` for the compiled kernels, or :data:`_NO_FOG` (mode −1) for None."""
    if fog is None:
        return _NO_FOG
    density, start, end = (float(v) for v in fog[2])
    r, g, b = (float(v) for v in np.asarray(fog[3], np.float64).reshape(3))
    return (_FOG_CODES.index(fog[0]), bool(fog[1]), density, start, end, r, g, b)


@functools.lru_cache(maxsize=1)
def _fog_function() -> object:  # a numba dispatcher
    """The per-fragment fog of every compiled kernel (colour stage and fused plain frame).

    ``_fog_function()(mode, radial, density, start, end, cr, cg, cb, px, py, pz, r, g, b, a)``
    returns the fogged premultiplied ``(r, g, b)`` of a fragment at eye-space point ``p`` with
    premultiplied colour ``(r, g, b)`` and alpha ``a``: OpenGL 2.1 §3.10 as
    :mod:`blinn_phong.model.fog` states it, ``f`` of the mode code (:data:`_FOG_CODES`) at distance
    ``‖p‖`` (radial) or ``|p_z|`` (eye plane), clamped to [0, 1], then
    ``f·rgb + (1 − f)·α·C_f``. Scalars only (no arrays: no reference counts per fragment).
    """
    import math

    import numba

    @numba.njit(inline="always", cache=True)
    def fogged(mode, radial, density, start, end, cr, cg, cb, px, py, pz, r, g, b, a):  # pragma: no cover
        dist = math.sqrt(px * px + py * py + pz * pz) if radial else abs(pz)
        if mode == 0:
            f = (end - dist) / (end - start)
        elif mode == 1:
            f = math.exp(-(density * dist))
        else:
            dc = density * dist
            f = math.exp(-(dc * dc))
        f = min(max(f, 0.0), 1.0)
        return f * r + (1.0 - f) * a * cr, f * g + (1.0 - f) * a * cg, f * b + (1.0 - f) * a * cb

    return fogged


#: Transparency models of the compiled colour kernel (index = code).
_MODEL_CODES = ("partial_occlusion", "emission", "absorption")


@functools.lru_cache(maxsize=1)
def _colour_kernel() -> object:  # a numba dispatcher
    import math

    import numba

    global _fogged
    _fogged = _fog_function()  # a module global, not a closure variable: see fused._row_kernels

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def colours(
        share,
        tri,
        bary,
        triangles,
        eye_pos,
        eye_n,
        side,
        rgb,
        alpha_in,
        specular,
        kg,
        washout,
        model,
        fog,
        out_rgba,
        out_alpha,
    ):  # pragma: no cover - compiled
        fog_mode, fog_radial, density, start, end, cr, cg, cb = fog
        for i in share:
            t = tri[i]
            v0, v1, v2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            b0, b1, b2 = bary[i, 0], bary[i, 1], bary[i, 2]
            s = side[i]
            alpha = alpha_in[i]
            if kg[s, 0] > 0.0:  # Kay–Greenberg: opacity 1 − t(|N_z|) of the unit eye-space normal
                nx = b0 * eye_n[v0, 0] + b1 * eye_n[v1, 0] + b2 * eye_n[v2, 0]
                ny = b0 * eye_n[v0, 1] + b1 * eye_n[v1, 1] + b2 * eye_n[v2, 1]
                nz = b0 * eye_n[v0, 2] + b1 * eye_n[v1, 2] + b2 * eye_n[v2, 2]
                big = max(abs(nx), abs(ny), abs(nz))
                unit_z = 0.0
                if big > 0.0:
                    sx, sy, sz = nx / big, ny / big, nz / big
                    unit_z = sz / math.sqrt(sx * sx + sy * sy + sz * sz)
                m = min(abs(min(max(unit_z, -1.0), 1.0)), 1.0)
                alpha = 1.0 - (kg[s, 1] + (kg[s, 2] - kg[s, 1]) * (1.0 - (1.0 - m) ** kg[s, 3]))
            if washout[s]:  # specular wash-out: min(1, (1 − t) + luminance(specular))
                lum = specular[i, 0] * 0.2126 + specular[i, 1] * 0.7152 + specular[i, 2] * 0.0722
                alpha = min(1.0, (1.0 - (1.0 - alpha)) + max(lum, 0.0))
            out_alpha[i] = alpha
            code = model[s]
            for ch in range(3):  # (α·c, α) partial occlusion, (α·c, 0) emission, (c, α) absorption
                out_rgba[i, ch] = rgb[i, ch] if code == 2 else alpha * rgb[i, ch]
            out_rgba[i, 3] = 0.0 if code == 1 else alpha
            if fog_mode >= 0:  # OpenGL 2.1 §3.10 on premultiplied colour: f·rgb + (1 − f)·α·C_f
                px = b0 * eye_pos[v0, 0] + b1 * eye_pos[v1, 0] + b2 * eye_pos[v2, 0]
                py = b0 * eye_pos[v0, 1] + b1 * eye_pos[v1, 1] + b2 * eye_pos[v2, 1]
                pz = b0 * eye_pos[v0, 2] + b1 * eye_pos[v1, 2] + b2 * eye_pos[v2, 2]
                out_rgba[i, 0], out_rgba[i, 1], out_rgba[i, 2] = _fogged(
                    fog_mode, fog_radial, density, start, end, cr, cg, cb, px, py, pz,
                    out_rgba[i, 0], out_rgba[i, 1], out_rgba[i, 2], out_rgba[i, 3],
                )  # fmt: skip

    return colours


def fragment_colours_compiled(
    triangle: np.ndarray,
    bary: np.ndarray,
    triangles: np.ndarray,
    eye_position: np.ndarray,
    eye_normal: np.ndarray,
    side: np.ndarray,
    rgb: np.ndarray,
    alpha: np.ndarray,
    specular: np.ndarray,
    side_params: tuple[np.ndarray, np.ndarray, np.ndarray],
    fog: FogArgs,
) -> tuple[np.ndarray, np.ndarray]:
    """Compiled twin of :func:`blinn_phong.frame.resolve.fragment_colours` (same formulas, one pass).

    ``side_params`` are per material side: (n, 4) Kay–Greenberg ``(on, t_min, t_max, power)``,
    (n,) wash-out flags and (n,) transparency-model codes; ``fog`` is ``(mode, radial,
    (density, start, end), colour)`` or None. Returns (N, 4) premultiplied RGBA and (N,) opacity.
    """
    n = len(triangle)
    out_rgba = np.empty((n, 4))
    out_alpha = np.empty(n)
    kg, washout, model = side_params
    _shares(
        _colour_kernel(),
        n,
        np.ascontiguousarray(triangle, dtype=np.int64),
        np.ascontiguousarray(bary),
        np.ascontiguousarray(triangles, dtype=np.int64),
        np.ascontiguousarray(eye_position),
        np.ascontiguousarray(eye_normal),
        np.ascontiguousarray(side, dtype=np.int64),
        np.ascontiguousarray(rgb),
        np.ascontiguousarray(alpha, dtype=np.float64),
        np.ascontiguousarray(specular),
        kg,
        washout,
        model,
        _fog_scalars(fog),
        out_rgba,
        out_alpha,
    )
    return out_rgba, out_alpha


#: Transparency resolves of the compiled kernel: 0 none (z-buffer), 1 front to back by a sort
#: key (A-buffer, depth peeling, the draw orders), 2 weighted blended.
RESOLVE_CODES = {"zbuffer": 0, "front_to_back": 1, "weighted_blended": 2}


@functools.lru_cache(maxsize=1)
def _resolve_kernel() -> object:  # a numba dispatcher
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def resolve(
        share,
        width,
        height,
        n_samples,
        code,
        max_layers,
        max_list,
        n_opaque,
        opaque_of,
        offsets,
        sort_key,
        weight,
        rgba,
        alpha,
        ambient,
        diffuse,
        specular,
        normal,
        depth,
        has_vis,
        vis_mean,
        o_rgba,
        o_amb,
        o_dif,
        o_spe,
        o_nrm,
        o_depth,
        o_shadow,
    ):  # pragma: no cover - compiled
        inv = 1.0 / n_samples
        scale_exact = (n_samples & (n_samples - 1)) == 0
        for row in share:
            # Scratch space per row (one thread each), reused for every pixel of the row.
            order = np.empty(max(max_list, 1), np.int64)
            res = np.empty(4)
            acc = np.empty(4)
            # Sums over the samples: rgba 0-3, ambient 4-6, diffuse 7-9, specular 10-12, normal 13-15,
            # shadow 16.
            tot = np.empty(17)
            for col in range(width):
                for ch in range(17):
                    tot[ch] = 0.0
                zmin = np.float32(1.0)
                for smp in range(n_samples):
                    key = (row * width + col) * n_samples + smp
                    o = opaque_of[key]
                    for ch in range(4):
                        res[ch] = rgba[o, ch] if o >= 0 else 0.0
                    start = offsets[key]
                    count = offsets[key + 1] - start
                    nearest = o
                    if count > 0:
                        nearest = n_opaque + start
                        for j in range(1, count):  # the first of the smallest depths (draw order)
                            if depth[n_opaque + start + j] < depth[nearest]:
                                nearest = n_opaque + start + j
                    if count > 0 and code == 1:
                        for j in range(count):  # insertion sort by (sort key, draw position): stable
                            f = n_opaque + start + j
                            pos = j
                            while pos > 0 and sort_key[order[pos - 1]] > sort_key[f]:
                                order[pos] = order[pos - 1]
                                pos -= 1
                            order[pos] = f
                        for ch in range(4):
                            acc[ch] = 0.0
                        for j in range(min(count, max_layers)):  # B over A: the farther one goes under
                            f = order[j]
                            cover = 1.0 - acc[3]
                            for ch in range(4):
                                acc[ch] = rgba[f, ch] * cover + acc[ch]
                        cover = 1.0 - acc[3]  # src over the opaque sample
                        for ch in range(4):
                            res[ch] = acc[ch] + res[ch] * cover
                    elif count > 0 and code == 2:
                        for ch in range(4):
                            acc[ch] = 0.0
                        reveal = 1.0
                        for j in range(count):  # ONE, ONE accumulation and the product of (1 − α)
                            f = n_opaque + start + j
                            for ch in range(4):
                                acc[ch] += rgba[f, ch] * weight[f]
                            reveal *= 1.0 - rgba[f, 3]
                        cover = 1.0 - reveal
                        safe = max(acc[3], 1e-5)
                        for ch in range(3):
                            res[ch] = acc[ch] / safe * cover + res[ch] * (1.0 - cover)
                        res[3] = cover + res[3] * (1.0 - cover)
                    for ch in range(4):
                        tot[ch] += np.float32(res[ch])
                    if nearest >= 0:
                        a = alpha[nearest]
                        for ch in range(3):
                            tot[4 + ch] += np.float32(ambient[nearest, ch] * a)
                            tot[7 + ch] += np.float32(diffuse[nearest, ch] * a)
                            tot[10 + ch] += np.float32(specular[nearest, ch] * a)
                            tot[13 + ch] += np.float32(normal[nearest, ch])
                        if has_vis:
                            tot[16] += np.float32(vis_mean[nearest] * a)
                        zmin = min(zmin, np.float32(depth[nearest]))
                # The box filter: the mean as numpy's (sum, then divide); 1/n is exact for n a
                # power of two (1, 4, 16, ...), so multiplying gives the same bits more cheaply.
                if scale_exact:
                    for ch in range(17):
                        tot[ch] *= inv
                else:
                    for ch in range(17):
                        tot[ch] /= n_samples
                for ch in range(4):
                    o_rgba[row, col, ch] = tot[ch]
                for ch in range(3):
                    o_amb[row, col, ch] = tot[4 + ch]
                    o_dif[row, col, ch] = tot[7 + ch]
                    o_spe[row, col, ch] = tot[10 + ch]
                    o_nrm[row, col, ch] = tot[13 + ch]
                o_depth[row, col] = zmin
                if has_vis:
                    o_shadow[row, col, 0] = tot[16]

    return resolve


@functools.lru_cache(maxsize=1)
def _resolve_plain_kernel() -> object:  # a numba dispatcher
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def resolve_plain(
        share,
        width,
        height,
        opaque_of,
        rgb,
        alpha,
        ambient,
        diffuse,
        specular,
        normal,
        depth,
        has_vis,
        vis_mean,
        o_rgba,
        o_amb,
        o_dif,
        o_spe,
        o_nrm,
        o_depth,
        o_shadow,
    ):  # pragma: no cover - compiled
        # The resolve kernel's code 0 with one sample per pixel and the fragment colour
        # (α·c, α) of partial occlusion computed here: the same float32 values, since a sum of
        # one term is that term (``0.0 + x`` keeps numpy's sign of zero) and 1/1 scales exactly.
        one = np.float32(1.0)
        for row in share:
            for col in range(width):
                o = opaque_of[row * width + col]
                if o < 0:
                    for ch in range(4):
                        o_rgba[row, col, ch] = 0.0
                    for ch in range(3):
                        o_amb[row, col, ch] = 0.0
                        o_dif[row, col, ch] = 0.0
                        o_spe[row, col, ch] = 0.0
                        o_nrm[row, col, ch] = 0.0
                    o_depth[row, col] = one
                    if has_vis:
                        o_shadow[row, col, 0] = 0.0
                    continue
                a = alpha[o]
                for ch in range(3):
                    o_rgba[row, col, ch] = 0.0 + np.float32(a * rgb[o, ch])
                    o_amb[row, col, ch] = 0.0 + np.float32(ambient[o, ch] * a)
                    o_dif[row, col, ch] = 0.0 + np.float32(diffuse[o, ch] * a)
                    o_spe[row, col, ch] = 0.0 + np.float32(specular[o, ch] * a)
                    o_nrm[row, col, ch] = 0.0 + np.float32(normal[o, ch])
                o_rgba[row, col, 3] = 0.0 + np.float32(a)
                o_depth[row, col] = min(one, np.float32(depth[o]))
                if has_vis:
                    o_shadow[row, col, 0] = 0.0 + np.float32(vis_mean[o] * a)

    return resolve_plain


def resolve_plain_compiled(
    width: int,
    height: int,
    opaque_of: np.ndarray,
    rgb: np.ndarray,
    alpha: np.ndarray,
    ambient: np.ndarray,
    diffuse: np.ndarray,
    specular: np.ndarray,
    normal: np.ndarray,
    depth: np.ndarray,
    vis_mean: np.ndarray | None,
    out: tuple[np.ndarray, ...],
) -> tuple[np.ndarray, ...]:
    """:func:`resolve_frame_compiled` with code 0 (z-buffer), one sample per pixel and the fragment
    colours ``(α·c, α)`` (partial occlusion, no fog) computed in the same pass: the same float32
    images without the (N, 4) fragment-colour array. ``out`` as there (C-contiguous float32)."""
    _shares(
        _resolve_plain_kernel(), height,
        width, height, opaque_of, np.ascontiguousarray(rgb), np.ascontiguousarray(alpha),
        np.ascontiguousarray(ambient), np.ascontiguousarray(diffuse), np.ascontiguousarray(specular),
        np.ascontiguousarray(normal), np.ascontiguousarray(depth), vis_mean is not None,
        np.zeros(0) if vis_mean is None else np.ascontiguousarray(vis_mean),
        *out,
    )  # fmt: skip
    return out


def resolve_frame_compiled(
    width: int,
    height: int,
    n_samples: int,
    code: int,
    max_layers: int,
    n_opaque: int,
    opaque_of: np.ndarray,
    offsets: np.ndarray,
    sort_key: np.ndarray,
    weight: np.ndarray,
    rgba: np.ndarray,
    alpha: np.ndarray,
    ambient: np.ndarray,
    diffuse: np.ndarray,
    specular: np.ndarray,
    normal: np.ndarray,
    depth: np.ndarray,
    vis_mean: np.ndarray | None,
    out: tuple[np.ndarray, ...] | None = None,
) -> tuple[np.ndarray, ...]:
    """Compiled twin of :func:`blinn_phong.frame.resolve.resolve_frame`: transparency resolve + box filter.

    One pass per pixel (rows in parallel; every pixel is written by one thread, and its samples
    are summed in sample order, so the result does not depend on the thread count). Returns
    float32 ``(rgba, ambient, diffuse, specular, normal_sum_mean, depth, shadow)`` images; the
    normal is the mean of the samples' unit normals (not renormalised). ``out``: C-contiguous
    float32 arrays of those shapes to write into (e.g. row bands of the frame's buffers).
    """
    f32 = np.float32
    if out is None:
        out = (
            np.empty((height, width, 4), f32),
            np.empty((height, width, 3), f32),
            np.empty((height, width, 3), f32),
            np.empty((height, width, 3), f32),
            np.empty((height, width, 3), f32),
            np.empty((height, width), f32),
            np.zeros((height, width, 1), f32) if vis_mean is not None else np.zeros((0, 0, 1), f32),
        )
    max_list = int(np.diff(offsets).max()) if code != 0 and len(offsets) > 1 else 0
    _shares(
        _resolve_kernel(), height,
        width, height, n_samples, code, max_layers, max_list, n_opaque, opaque_of, offsets,
        np.ascontiguousarray(sort_key, dtype=np.float64), np.ascontiguousarray(weight, dtype=np.float64),
        np.ascontiguousarray(rgba), np.ascontiguousarray(alpha), np.ascontiguousarray(ambient),
        np.ascontiguousarray(diffuse), np.ascontiguousarray(specular), np.ascontiguousarray(normal),
        np.ascontiguousarray(depth), vis_mean is not None,
        np.zeros(0) if vis_mean is None else np.ascontiguousarray(vis_mean),
        *out,
    )  # fmt: skip
    return out
