"""Optional compiled (numba) fast path for the z-buffer visibility pass.

The numpy functions in :mod:`blinn_phong.raster` are the reference; this module
runs the same triangle setup (:func:`blinn_phong.raster._setup_triangles`: the
same clipping, snapping, edge functions and fill rule) through a compiled
scan-conversion loop that keeps only the nearest fragment per sample, so no
array of all fragments is ever built. Barycentrics and depths of the winners are
then computed by a compiled twin of :func:`blinn_phong.raster._fragments_from_hits`
(tests/blinn_phong/test_engines_agree.py checks both against the reference).

The depth test is ``GL_LESS`` in draw order, as :func:`blinn_phong.raster.resolve_nearest`:
smaller depth wins, equal depths go to the lower triangle index. The image is
split into horizontal bands processed in parallel (numba ``prange``); each band
owns its rows, so there are no write races.
"""

from __future__ import annotations

import functools
import os

import numpy as np

from blinn_phong.raster import Fragments, _setup_triangles

__all__ = [
    "numba_available",
    "scatter_samples_compiled",
    "surface_at_fragments_compiled",
    "visible_fragments_compiled",
]


@functools.lru_cache(maxsize=1)
def numba_available() -> bool:
    """True when numba imports (the compiled path can be used)."""
    try:
        import numba  # noqa: F401
    except Exception:
        return False
    return True


@functools.lru_cache(maxsize=1)
def _kernel() -> object:  # a numba dispatcher
    import numba

    @numba.njit(parallel=True, cache=True, fastmath=False)
    def zbuffer(
        n_bands, fine_w, fine_h, selected, x0, x1, y0, y1, a, b, c, top_left, xe, ye, area, z, source
    ):  # pragma: no cover - compiled
        n_keys = fine_w * fine_h
        zbuf = np.full(n_keys, np.inf)
        winner = np.full(n_keys, -1, np.int64)
        band_h = (fine_h + n_bands - 1) // n_bands
        for band in numba.prange(n_bands):
            r0 = band * band_h
            r1 = min(fine_h, r0 + band_h) - 1
            for s in range(selected.shape[0]):
                t = selected[s]
                lo = max(y0[t], r0)
                hi = min(y1[t], r1)
                if lo > hi:
                    continue
                # Exact (unsnapped) barycentric set-up, as _exact_barycentrics.
                ex_area = (xe[t, 1] - xe[t, 0]) * (ye[t, 2] - ye[t, 0]) - (xe[t, 2] - xe[t, 0]) * (
                    ye[t, 1] - ye[t, 0]
                )
                exact = ex_area * area[t] > 0 and abs(ex_area) > 1e-12
                abs_area = abs(area[t])
                for py in range(lo, hi + 1):
                    cy = py + 0.5
                    for px in range(x0[t], x1[t] + 1):
                        cx = px + 0.5
                        e0 = a[t, 0] * cx + (b[t, 0] * cy + c[t, 0])
                        if e0 < 0 or (e0 == 0 and not top_left[t, 0]):
                            continue
                        e1 = a[t, 1] * cx + (b[t, 1] * cy + c[t, 1])
                        if e1 < 0 or (e1 == 0 and not top_left[t, 1]):
                            continue
                        e2 = a[t, 2] * cx + (b[t, 2] * cy + c[t, 2])
                        if e2 < 0 or (e2 == 0 and not top_left[t, 2]):
                            continue
                        if exact:
                            l0 = (
                                (xe[t, 2] - xe[t, 1]) * (cy - ye[t, 1])
                                - (ye[t, 2] - ye[t, 1]) * (cx - xe[t, 1])
                            ) / ex_area
                            l1 = (
                                (xe[t, 0] - xe[t, 2]) * (cy - ye[t, 2])
                                - (ye[t, 0] - ye[t, 2]) * (cx - xe[t, 2])
                            ) / ex_area
                            l2 = (
                                (xe[t, 1] - xe[t, 0]) * (cy - ye[t, 0])
                                - (ye[t, 1] - ye[t, 0]) * (cx - xe[t, 0])
                            ) / ex_area
                        else:
                            l0 = e0 / abs_area
                            l1 = e1 / abs_area
                            l2 = e2 / abs_area
                        depth = l0 * z[t, 0] + l1 * z[t, 1] + l2 * z[t, 2]
                        if depth > 1.0:
                            continue
                        depth = max(depth, 0.0)
                        key = py * fine_w + px
                        old = winner[key]
                        if depth < zbuf[key] or (depth == zbuf[key] and old >= 0 and source[t] < source[old]):
                            zbuf[key] = depth
                            winner[key] = t
        return winner

    @numba.njit(parallel=True, cache=True)
    def finish(
        fine_key,
        sub,
        fine_w,
        k,
        width,
        xe,
        ye,
        area,
        a,
        b,
        c,
        z,
        w,
        weights,
        depth_out,
        bary_out,
        pixel,
        sample,
    ):  # pragma: no cover - compiled
        # The compiled twin of raster._fragments_from_hits for the winners (already depth-tested).
        for i in numba.prange(fine_key.shape[0]):
            t = sub[i]
            fx = fine_key[i] % fine_w
            fy = fine_key[i] // fine_w
            cx = fx + 0.5
            cy = fy + 0.5
            ex_area = (xe[t, 1] - xe[t, 0]) * (ye[t, 2] - ye[t, 0]) - (xe[t, 2] - xe[t, 0]) * (
                ye[t, 1] - ye[t, 0]
            )
            if ex_area * area[t] > 0 and abs(ex_area) > 1e-12:
                l0 = (
                    (xe[t, 2] - xe[t, 1]) * (cy - ye[t, 1]) - (ye[t, 2] - ye[t, 1]) * (cx - xe[t, 1])
                ) / ex_area
                l1 = (
                    (xe[t, 0] - xe[t, 2]) * (cy - ye[t, 2]) - (ye[t, 0] - ye[t, 2]) * (cx - xe[t, 2])
                ) / ex_area
                l2 = (
                    (xe[t, 1] - xe[t, 0]) * (cy - ye[t, 0]) - (ye[t, 1] - ye[t, 0]) * (cx - xe[t, 0])
                ) / ex_area
            else:
                aa = abs(area[t])
                l0 = (a[t, 0] * cx + b[t, 0] * cy + c[t, 0]) / aa
                l1 = (a[t, 1] * cx + b[t, 1] * cy + c[t, 1]) / aa
                l2 = (a[t, 2] * cx + b[t, 2] * cy + c[t, 2]) / aa
            depth_out[i] = max(l0 * z[t, 0] + l1 * z[t, 1] + l2 * z[t, 2], 0.0)
            q0 = l0 / w[t, 0]
            q1 = l1 / w[t, 1]
            q2 = l2 / w[t, 2]
            qs = q0 + q1 + q2
            q0 /= qs
            q1 /= qs
            q2 /= qs
            for m in range(3):
                bary_out[i, m] = q0 * weights[t, 0, m] + q1 * weights[t, 1, m] + q2 * weights[t, 2, m]
            pixel[i] = (fy // k) * width + fx // k
            sample[i] = (fy % k) * k + fx % k

    return zbuffer, finish


def visible_fragments_compiled(
    clip_xyzw: np.ndarray,
    triangles: np.ndarray,
    width: int,
    height: int,
    *,
    samples: int = 1,
    cull_backfaces: bool = False,
) -> Fragments:
    """The nearest fragment of every covered sample, ordered by ``Fragments.sample_key``.

    Same arguments, conventions and result as
    ``rasterize(...)`` followed by ``resolve_nearest`` and keeping the winners
    (:func:`blinn_phong.raster.visible_fragments` with ``engine="numpy"``), computed
    by a compiled loop. Requires numba (:func:`numba_available`).
    """
    setup = _setup_triangles(clip_xyzw, triangles, width, height, samples, cull_backfaces)
    fine_w, fine_h = setup.width * setup.k, setup.height * setup.k
    threads = max(1, int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1)))
    n_bands = max(1, min(fine_h, 4 * threads))
    zbuffer, finish = _kernel()
    winner = zbuffer(
        n_bands,
        fine_w,
        fine_h,
        setup.selected.astype(np.int64),
        setup.x0,
        setup.x1,
        setup.y0,
        setup.y1,
        setup.a,
        setup.b,
        setup.c,
        setup.top_left,
        setup.x_exact,
        setup.y_exact,
        setup.area,
        setup.z,
        setup.source,
    )
    fine_key = np.flatnonzero(winner >= 0)
    sub = winner[fine_key]
    n = len(fine_key)
    depth = np.empty(n)
    bary = np.empty((n, 3))
    pixel = np.empty(n, np.int64)
    sample = np.empty(n, np.int64)
    finish(
        fine_key,
        sub,
        fine_w,
        setup.k,
        setup.width,
        setup.x_exact,
        setup.y_exact,
        setup.area,
        setup.a,
        setup.b,
        setup.c,
        setup.z,
        setup.w,
        setup.weights,
        depth,
        bary,
        pixel,
        sample,
    )
    frags = Fragments(
        setup.width,
        setup.height,
        setup.k * setup.k,
        pixel,
        sample,
        depth,
        setup.source[sub],
        bary,
        setup.front[sub],
    )
    if setup.k == 1:
        return frags  # fine keys are already sample keys, in increasing order
    return frags.subset(np.argsort(frags.sample_key, kind="stable"))


@functools.lru_cache(maxsize=1)
def _surface_kernel() -> object:  # a numba dispatcher
    import math

    import numba

    @numba.njit(parallel=True, cache=True)
    def surface(
        tri_ids, bary, triangles, eye_pos, eye_n, world_n, flip, out_p, out_n, out_w
    ):  # pragma: no cover
        for i in numba.prange(tri_ids.shape[0]):
            t = tri_ids[i]
            v0, v1, v2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            b0, b1, b2 = bary[i, 0], bary[i, 1], bary[i, 2]
            for ch in range(3):
                out_p[i, ch] = b0 * eye_pos[v0, ch] + b1 * eye_pos[v1, ch] + b2 * eye_pos[v2, ch]
            nx = b0 * eye_n[v0, 0] + b1 * eye_n[v1, 0] + b2 * eye_n[v2, 0]
            ny = b0 * eye_n[v0, 1] + b1 * eye_n[v1, 1] + b2 * eye_n[v2, 1]
            nz = b0 * eye_n[v0, 2] + b1 * eye_n[v1, 2] + b2 * eye_n[v2, 2]
            length = math.sqrt(nx * nx + ny * ny + nz * nz)
            scale = (1.0 / length if length > 0 else 0.0) * (-1.0 if flip[i] else 1.0)
            out_n[i, 0], out_n[i, 1], out_n[i, 2] = nx * scale, ny * scale, nz * scale
            wx = b0 * world_n[v0, 0] + b1 * world_n[v1, 0] + b2 * world_n[v2, 0]
            wy = b0 * world_n[v0, 1] + b1 * world_n[v1, 1] + b2 * world_n[v2, 1]
            wz = b0 * world_n[v0, 2] + b1 * world_n[v1, 2] + b2 * world_n[v2, 2]
            length = math.sqrt(wx * wx + wy * wy + wz * wz)
            scale = 1.0 / length if length > 0 else 0.0
            out_w[i, 0], out_w[i, 1], out_w[i, 2] = wx * scale, wy * scale, wz * scale

    return surface


def surface_at_fragments_compiled(
    triangle: np.ndarray,
    bary: np.ndarray,
    triangles: np.ndarray,
    eye_position: np.ndarray,
    eye_normal: np.ndarray,
    world_normal: np.ndarray,
    flip: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compiled twin of :func:`blinn_phong.render.surface_at_fragments` (same formulas)."""
    n = len(triangle)
    out_p = np.empty((n, 3))
    out_n = np.empty((n, 3))
    out_w = np.empty((n, 3))
    _surface_kernel()(
        np.ascontiguousarray(triangle, dtype=np.int64),
        np.ascontiguousarray(bary),
        np.ascontiguousarray(triangles, dtype=np.int64),
        np.ascontiguousarray(eye_position),
        np.ascontiguousarray(eye_normal),
        np.ascontiguousarray(world_normal),
        np.ascontiguousarray(flip, dtype=np.bool_),
        out_p,
        out_n,
        out_w,
    )
    return out_p, out_n, out_w


@functools.lru_cache(maxsize=1)
def _scatter_kernel() -> object:  # a numba dispatcher
    import numba

    @numba.njit(parallel=True, cache=True)
    def scatter(
        keys, rgb, alpha, ambient, diffuse, specular, normal, depth, o_rgba, o_amb, o_dif, o_spe, o_nrm, o_z
    ):  # pragma: no cover
        for i in numba.prange(keys.shape[0]):
            key = keys[i]
            a = alpha[i]
            for ch in range(3):
                o_rgba[key, ch] = rgb[i, ch] * a
                o_amb[key, ch] = ambient[i, ch] * a
                o_dif[key, ch] = diffuse[i, ch] * a
                o_spe[key, ch] = specular[i, ch] * a
                o_nrm[key, ch] = normal[i, ch]
            o_rgba[key, 3] = a
            o_z[key] = depth[i]

    return scatter


def scatter_samples_compiled(
    n_keys: int,
    keys: np.ndarray,
    rgb: np.ndarray,
    alpha: np.ndarray,
    ambient: np.ndarray,
    diffuse: np.ndarray,
    specular: np.ndarray,
    normal: np.ndarray,
    depth: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """Per-sample float32 buffers: premultiplied rgba, ambient, diffuse, specular; normal; depth.

    The compiled twin of the numpy scatter in :func:`blinn_phong.render.render`: samples
    not in ``keys`` hold 0 (depth 1, the OpenGL clear value).
    """
    out = (
        np.zeros((n_keys, 4), np.float32),
        np.zeros((n_keys, 3), np.float32),
        np.zeros((n_keys, 3), np.float32),
        np.zeros((n_keys, 3), np.float32),
        np.zeros((n_keys, 3), np.float32),
        np.ones(n_keys, np.float32),
    )
    _scatter_kernel()(keys, rgb, alpha, ambient, diffuse, specular, normal, depth, *out)
    return out
