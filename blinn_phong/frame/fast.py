"""The compiled (numba) engine of the frame stages; :mod:`blinn_phong.geometry.raster`,
:mod:`blinn_phong.frame.visibility`
and :mod:`blinn_phong.frame.resolve` hold the numpy references.

* Visibility: the same triangle setup as the reference (:func:`blinn_phong.geometry.raster._setup_triangles`,
  computed to the same bits by :func:`setup_triangles_compiled`: the same clipping, snapping,
  edge functions and fill rule) through compiled scan-conversion
  loops. :func:`visible_fragments_compiled` keeps only the nearest fragment per sample;
  :func:`frame_fragments_compiled` also builds, per sample, the list of transparent fragments
  in front of the opaque depth (a counting pass, a prefix sum, a filling pass), so no array of
  all fragments is ever built. Barycentrics and depths of the kept fragments come from a
  compiled twin of :func:`blinn_phong.geometry.raster._fragments_from_hits`.
* The plain frame fused (:func:`shade_plain_winners_compiled`, :func:`shade_plain_fragments_compiled`):
  one sample per pixel, no transparency resolve, per-pixel shading: each pixel's nearest
  fragment interpolated, lit by :func:`blinn_phong.frame.lighting.point_terms` (the lighting kernel's
  own compiled equation), fogged by the colour stage's compiled fog (:func:`_fog_function`) and
  written into the float32 frame buffers in one pass over the rows (shares of rows on threads,
  :mod:`compositing._threads`), with the operations of the separate stages in their order (the
  same images, no (N, 3) arrays).
* :func:`fragment_colours_compiled`: transparency models, Kay–Greenberg, wash-out and fog per
  fragment (twin of :func:`blinn_phong.frame.resolve.fragment_colours`).
* :func:`resolve_frame_compiled`: per pixel, each sample's transparent list sorted and
  composited over its opaque fragment (or accumulated for weighted blended OIT), then the box
  filter and the nearest surface's buffers (twin of :func:`blinn_phong.frame.resolve.resolve_frame`).

The depth test is ``GL_LESS`` in draw order, as :func:`blinn_phong.geometry.raster.resolve_nearest`:
smaller depth wins, equal depths go to the lower triangle index. Rasterization splits the image
into horizontal bands processed in parallel (numba ``prange``); the other kernels are serial
loops that release the GIL, run on shares of their rows or fragments on threads
(:mod:`compositing._threads`: a numba-parallel loop costs seconds more to compile, and most of
them ran no faster); each band, row or fragment owns its outputs, so there are no write races
and the results do not depend on the thread count (tests/blinn_phong/test_engines_agree.py checks every kernel
against the reference).
"""

from __future__ import annotations

import functools
import os
import warnings

import numpy as np

from blinn_phong._numba import numba_available
from blinn_phong.geometry.raster import Fragments, _TriangleSetup

__all__ = [
    "numba_available",
    "scatter_samples_compiled",
    "surface_at_fragments_compiled",
    "visible_fragments_compiled",
]


#: The fused kernel's interpolation of per-vertex terms, set by :func:`_plain_kernel`.
_lerp: object = None
#: The z-buffer kernels' inlined helpers, set by :func:`_kernel`.
_triangle_setup: object = None
_sample_depth: object = None
_winner_point: object = None
_unit_face_normal: object = None
_interpolated: object = None
#: The shadow-map look-ups (shadow_kernels.stacked_visibility per point, nearest_run per run of
#: points), set by :func:`_plain_kernel`.
_stacked_visibility: object = None
_nearest_run: object = None


def _shares(kernel: object, n: int, *args: object) -> None:
    """``kernel(share, *args)`` for shares of ``range(n)`` on threads
    (:func:`compositing._threads.in_shares`)."""
    from compositing._threads import in_shares

    in_shares(kernel, n, *args)  # type: ignore[arg-type]


@functools.lru_cache(maxsize=1)
def _kernel() -> object:  # a numba dispatcher
    import math

    import numba

    @numba.njit(inline="always", cache=True)
    def triangle_setup(t, xe, ye, area):  # pragma: no cover - compiled
        """Per-triangle constants of sample_depth: the exact (unsnapped) doubled area, whether the
        exact barycentrics apply, and |snapped area| (hoisted out of the sample loops)."""
        ex_area = (xe[t, 1] - xe[t, 0]) * (ye[t, 2] - ye[t, 0]) - (xe[t, 2] - xe[t, 0]) * (
            ye[t, 1] - ye[t, 0]
        )
        return ex_area, ex_area * area[t] > 0 and abs(ex_area) > 1e-12, abs(area[t])

    @numba.njit(inline="always", cache=True)
    def sample_depth(t, cx, cy, a, b, c, top_left, xe, ye, ex_area, exact, abs_area, z):  # pragma: no cover
        """Window depth of sub-triangle t at the fine sample centred at (cx, cy), or -1 where not
        covered / beyond far.

        The edge tests with the top-left rule and the exact (unsnapped) barycentrics of
        raster._exact_barycentrics (``ex_area, exact, abs_area`` from triangle_setup), then
        depth linear in screen space, clamped at 0.
        """
        e0 = a[t, 0] * cx + (b[t, 0] * cy + c[t, 0])
        if e0 < 0 or (e0 == 0 and not top_left[t, 0]):
            return -1.0
        e1 = a[t, 1] * cx + (b[t, 1] * cy + c[t, 1])
        if e1 < 0 or (e1 == 0 and not top_left[t, 1]):
            return -1.0
        e2 = a[t, 2] * cx + (b[t, 2] * cy + c[t, 2])
        if e2 < 0 or (e2 == 0 and not top_left[t, 2]):
            return -1.0
        if exact:
            l0 = ((xe[t, 2] - xe[t, 1]) * (cy - ye[t, 1]) - (ye[t, 2] - ye[t, 1]) * (cx - xe[t, 1])) / ex_area
            l1 = ((xe[t, 0] - xe[t, 2]) * (cy - ye[t, 2]) - (ye[t, 0] - ye[t, 2]) * (cx - xe[t, 2])) / ex_area
            l2 = ((xe[t, 1] - xe[t, 0]) * (cy - ye[t, 0]) - (ye[t, 1] - ye[t, 0]) * (cx - xe[t, 0])) / ex_area
        else:
            l0 = e0 / abs_area
            l1 = e1 / abs_area
            l2 = e2 / abs_area
        depth = l0 * z[t, 0] + l1 * z[t, 1] + l2 * z[t, 2]
        if depth > 1.0:
            return -1.0
        return max(depth, 0.0)

    @numba.njit(inline="always", cache=True)
    def winner_point(t, cx, cy, xe, ye, area, a, b, c, z, w, weights):  # pragma: no cover - compiled
        """Window depth and perspective-correct barycentrics ``(depth, b0, b1, b2)`` of a depth-test
        winner, sub-triangle t, at the sample centred at (cx, cy): the compiled twin of
        raster._fragments_from_hits (exact barycentrics where triangle_setup allows them, else the
        snapped edge functions; then 1/w weighting and the sub-triangle's corner weights)."""
        ex_area, exact, abs_area = triangle_setup(t, xe, ye, area)
        if exact:
            l0 = ((xe[t, 2] - xe[t, 1]) * (cy - ye[t, 1]) - (ye[t, 2] - ye[t, 1]) * (cx - xe[t, 1])) / ex_area
            l1 = ((xe[t, 0] - xe[t, 2]) * (cy - ye[t, 2]) - (ye[t, 0] - ye[t, 2]) * (cx - xe[t, 2])) / ex_area
            l2 = ((xe[t, 1] - xe[t, 0]) * (cy - ye[t, 0]) - (ye[t, 1] - ye[t, 0]) * (cx - xe[t, 0])) / ex_area
        else:
            l0 = (a[t, 0] * cx + b[t, 0] * cy + c[t, 0]) / abs_area
            l1 = (a[t, 1] * cx + b[t, 1] * cy + c[t, 1]) / abs_area
            l2 = (a[t, 2] * cx + b[t, 2] * cy + c[t, 2]) / abs_area
        depth = max(l0 * z[t, 0] + l1 * z[t, 1] + l2 * z[t, 2], 0.0)
        q0 = l0 / w[t, 0]
        q1 = l1 / w[t, 1]
        q2 = l2 / w[t, 2]
        qs = q0 + q1 + q2
        q0 /= qs
        q1 /= qs
        q2 /= qs
        b0 = q0 * weights[t, 0, 0] + q1 * weights[t, 1, 0] + q2 * weights[t, 2, 0]
        b1 = q0 * weights[t, 0, 1] + q1 * weights[t, 1, 1] + q2 * weights[t, 2, 1]
        b2 = q0 * weights[t, 0, 2] + q1 * weights[t, 1, 2] + q2 * weights[t, 2, 2]
        return depth, b0, b1, b2

    @numba.njit(inline="always", cache=True)
    def unit_face_normal(points, v0, v1, v2):  # pragma: no cover - compiled
        """normals.face_normals of one triangle: (p1 − p0) × (p2 − p0), scaled by its largest
        component before the length is taken; zero for a zero-area triangle."""
        ux = points[v1, 0] - points[v0, 0]
        uy = points[v1, 1] - points[v0, 1]
        uz = points[v1, 2] - points[v0, 2]
        vx = points[v2, 0] - points[v0, 0]
        vy = points[v2, 1] - points[v0, 1]
        vz = points[v2, 2] - points[v0, 2]
        nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        largest = max(abs(nx), abs(ny), abs(nz))
        if largest > 0:
            nx, ny, nz = nx / largest, ny / largest, nz / largest
            length = math.sqrt(nx * nx + ny * ny + nz * nz)
            nx, ny, nz = nx / length, ny / length, nz / length
        return nx, ny, nz

    @numba.njit(inline="always", cache=True)
    def interpolated(points, v0, v1, v2, b0, b1, b2, k):  # pragma: no cover - compiled
        """Coordinate k of the point with barycentrics (b0, b1, b2) on the triangle of vertices
        v0, v1, v2 of ``points``, summed as raster.interpolate sums it (j = 0, 1, 2)."""
        return (b0 * points[v0, k] + b1 * points[v1, k]) + b2 * points[v2, k]

    # Module globals, not closure variables: numba's disk-cache key hashes closure variables, and
    # a compiled function in one changes it in every process (the kernels were never cached).
    global _triangle_setup, _sample_depth, _winner_point, _unit_face_normal, _interpolated
    _triangle_setup, _sample_depth, _winner_point = triangle_setup, sample_depth, winner_point
    _unit_face_normal, _interpolated = unit_face_normal, interpolated

    # The rasterization loops stay numba-parallel: as serial loops over shares they ran 2–5×
    # slower (their inner loops re-read the triangle's arrays after every store into an output
    # that LLVM cannot prove distinct; a parallel loop's body is compiled knowing it is).
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
                ex_area, exact, abs_area = _triangle_setup(t, xe, ye, area)
                for py in range(lo, hi + 1):
                    cy = py + 0.5
                    for px in range(x0[t], x1[t] + 1):
                        depth = _sample_depth(
                            t, px + 0.5, cy, a, b, c, top_left, xe, ye, ex_area, exact, abs_area, z
                        )
                        if depth < 0.0:
                            continue
                        key = py * fine_w + px
                        old = winner[key]
                        if depth < zbuf[key] or (depth == zbuf[key] and old >= 0 and source[t] < source[old]):
                            zbuf[key] = depth
                            winner[key] = t
        return winner, zbuf

    @numba.njit(parallel=True, cache=True, fastmath=False)
    def in_front(
        fill,
        n_bands,
        fine_w,
        fine_h,
        k,
        width,
        selected,
        x0,
        x1,
        y0,
        y1,
        a,
        b,
        c,
        top_left,
        xe,
        ye,
        area,
        z,
        zbuf,
        winner,
        counts,
        offsets,
        out_sub,
        out_fine,
    ):  # pragma: no cover - compiled
        # Transparent fragments in front of the opaque depth (GL_LESS against 1.0 where empty),
        # counted per sample key (fill=False) or written into their sample's slots (fill=True),
        # in the order of ``selected`` (draw order). Bands own fine rows, hence sample keys.
        band_h = (fine_h + n_bands - 1) // n_bands
        n_samples = k * k
        for band in numba.prange(n_bands):
            r0 = band * band_h
            r1 = min(fine_h, r0 + band_h) - 1
            for s in range(selected.shape[0]):
                t = selected[s]
                lo = max(y0[t], r0)
                hi = min(y1[t], r1)
                if lo > hi:
                    continue
                ex_area, exact, abs_area = _triangle_setup(t, xe, ye, area)
                for py in range(lo, hi + 1):
                    cy = py + 0.5
                    for px in range(x0[t], x1[t] + 1):
                        depth = _sample_depth(
                            t, px + 0.5, cy, a, b, c, top_left, xe, ye, ex_area, exact, abs_area, z
                        )
                        if depth < 0.0:
                            continue
                        fine = py * fine_w + px
                        limit = zbuf[fine] if winner[fine] >= 0 else 1.0
                        if not depth < limit:
                            continue
                        key = ((py // k) * width + px // k) * n_samples + (py % k) * k + px % k
                        if fill:
                            slot = offsets[key] + counts[key]
                            out_sub[slot] = t
                            out_fine[slot] = fine
                        counts[key] += 1

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
            depth_out[i], b0, b1, b2 = _winner_point(t, cx, cy, xe, ye, area, a, b, c, z, w, weights)
            bary_out[i, 0] = b0
            bary_out[i, 1] = b1
            bary_out[i, 2] = b2
            pixel[i] = (fy // k) * width + fx // k
            sample[i] = (fy % k) * k + fx % k

    @numba.njit(cache=True)
    def compact(winner, fine_key, sub, rank):  # pragma: no cover - compiled
        # One serial pass: the covered fine keys in increasing order, their winners, and each
        # key's rank among them (-1 where empty): flatnonzero, a gather and the inverse map at once.
        n = 0
        for key in range(winner.shape[0]):
            t = winner[key]
            if t >= 0:
                fine_key[n] = key
                sub[n] = t
                rank[key] = n
                n += 1
            else:
                rank[key] = -1
        return n

    return zbuffer, finish, in_front, compact


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
    (:func:`blinn_phong.frame.visibility.visible_fragments` with ``engine="numpy"``), computed
    by a compiled loop. Requires numba (:func:`numba_available`).
    """
    setup = setup_triangles_compiled(clip_xyzw, triangles, width, height, samples, cull_backfaces)
    fine_w, fine_h = setup.width * setup.k, setup.height * setup.k
    threads = max(1, int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1)))
    n_bands = max(1, min(fine_h, 4 * threads))
    zbuffer, finish, _, _ = _kernel()
    winner, _ = zbuffer(
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

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def surface(
        share, tri_ids, bary, triangles, eye_pos, eye_n, world_n, flip, out_p, out_n, out_w
    ):  # pragma: no cover
        for i in share:
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
    """Compiled twin of :func:`blinn_phong.frame.shading.surface_at_fragments` (same formulas)."""
    n = len(triangle)
    out_p = np.empty((n, 3))
    out_n = np.empty((n, 3))
    out_w = np.empty((n, 3))
    _shares(
        _surface_kernel(),
        n,
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

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def scatter(
        share,
        keys,
        rgb,
        alpha,
        ambient,
        diffuse,
        specular,
        normal,
        depth,
        o_rgba,
        o_amb,
        o_dif,
        o_spe,
        o_nrm,
        o_z,
    ):  # pragma: no cover
        for i in share:
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

    The compiled twin of the numpy scatter in :func:`blinn_phong.frame.resolve.resolve_nearest_buffers`:
    samples
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
    _shares(_scatter_kernel(), len(keys), keys, rgb, alpha, ambient, diffuse, specular, normal, depth, *out)
    return out


def _bands(fine_h: int) -> int:
    threads = max(1, int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1)))
    return max(1, min(fine_h, 4 * threads))


def frame_fragments_compiled(
    setup: _TriangleSetup, sub_opaque: np.ndarray | None
) -> tuple[Fragments, int, np.ndarray, np.ndarray]:
    """The fragments a frame can see, by compiled loops (twin of the numpy visibility stage).

    Args:
        setup: :func:`blinn_phong.geometry.raster._setup_triangles` of the frame.
        sub_opaque: (S,) bool per sub-triangle, True where it is opaque (writes depth); None:
            every triangle is opaque (the plain z-buffer).

    Returns:
        ``(fragments, n_opaque, opaque_of, offsets)`` as
        :class:`blinn_phong.frame.visibility.FrameFragments` holds them: the nearest opaque
        fragment of every covered sample (ordered by sample key), then the transparent
        fragments in front of the opaque depth, grouped by sample key and in draw order inside
        a sample. No array of all rasterized fragments is built: memory is the per-sample
        z-buffer plus the fragments that survive the depth test.
    """
    fine_w, fine_h, k = setup.width * setup.k, setup.height * setup.k, setup.k
    n_samples = k * k
    n_keys = setup.width * setup.height * n_samples
    n_bands = _bands(fine_h)
    zbuffer, finish, in_front, compact = _kernel()
    sel = setup.selected.astype(np.int64)
    if sub_opaque is None:
        op_sel, tr_sel = sel, np.zeros(0, np.int64)
    else:
        flags = np.asarray(sub_opaque, dtype=bool)[sel]
        op_sel, tr_sel = sel[flags], sel[~flags]
        tr_sel = tr_sel[np.argsort(setup.source[tr_sel], kind="stable")]  # draw order = source order
    geometry = (
        setup.x0, setup.x1, setup.y0, setup.y1, setup.a, setup.b, setup.c,
        setup.top_left, setup.x_exact, setup.y_exact, setup.area, setup.z,
    )  # fmt: skip
    winner, zbuf = zbuffer(n_bands, fine_w, fine_h, op_sel, *geometry, setup.source)
    fine_key = np.empty(n_keys, np.int64)
    sub = np.empty(n_keys, np.int64)
    rank = np.empty(n_keys, np.int64)
    covered = compact(winner, fine_key, sub, rank)
    fine_key, sub = fine_key[:covered], sub[:covered]
    offsets = np.zeros(n_keys + 1, np.int64)
    t_sub = t_fine = np.zeros(0, np.int64)
    if len(tr_sel):
        counts = np.zeros(n_keys, np.int64)
        args = (n_bands, fine_w, fine_h, k, setup.width, tr_sel, *geometry, zbuf, winner, counts)
        in_front(False, *args, offsets, t_sub, t_fine)
        np.cumsum(counts, out=offsets[1:])
        t_sub = np.empty(int(offsets[-1]), np.int64)
        t_fine = np.empty(int(offsets[-1]), np.int64)
        counts[:] = 0
        in_front(True, *args, offsets, t_sub, t_fine)
    del winner, zbuf
    n_opaque = len(fine_key)
    all_fine = np.concatenate([fine_key, t_fine]) if len(t_fine) else fine_key
    all_sub = np.concatenate([sub, t_sub]) if len(t_sub) else sub
    n = len(all_fine)
    depth = np.empty(n)
    bary = np.empty((n, 3))
    pixel = np.empty(n, np.int64)
    sample = np.empty(n, np.int64)
    finish(
        all_fine, all_sub, fine_w, k, setup.width, setup.x_exact, setup.y_exact, setup.area,
        setup.a, setup.b, setup.c, setup.z, setup.w, setup.weights, depth, bary, pixel, sample,
    )  # fmt: skip
    frags = Fragments(
        setup.width,
        setup.height,
        n_samples,
        pixel,
        sample,
        depth,
        setup.source[all_sub],
        bary,
        setup.front[all_sub],
    )
    if k > 1 and n_opaque:  # fine keys -> sample keys: reorder the opaque winners
        order = np.argsort(frags.sample_key[:n_opaque], kind="stable")
        frags = frags.subset(np.concatenate([order, np.arange(n_opaque, n)]))
    if k == 1:
        opaque_of = rank  # fine keys are sample keys: each key's rank among the covered ones
    else:
        opaque_of = np.full(n_keys, -1, np.int64)
        opaque_of[frags.sample_key[:n_opaque]] = np.arange(n_opaque)
    return frags, n_opaque, opaque_of, offsets


#: Fog modes of the compiled kernels (index = code), as :data:`blinn_phong.model.fog.FOG_MODES`.
_FOG_CODES = ("linear", "exp", "exp2")
#: The compiled per-fragment fog, set by :func:`_fog_function` (a module global: see :func:`_plain_kernel`).
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
    _fogged = _fog_function()  # a module global, not a closure variable: see _plain_kernel

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


#: The lighting equation's compiled per-point function, set by :func:`_plain_kernel`.
_point_terms: object = None
_plain_row: object = None
_map_row: object = None


@functools.lru_cache(maxsize=1)
def _row_kernels() -> None:
    """Compile-on-demand dispatchers of the fused frame kernel's rows, set as module globals:
    ``_plain_row`` (a row's shading, resolve and writes) and ``_map_row`` (a row's shadow-map
    look-ups, compiled only when a frame has shadow maps)."""
    import hashlib
    import math

    import numba

    from blinn_phong.frame import lighting

    global _point_terms, _fogged
    _kernel()  # sets _winner_point: the depth-test winners' depth and barycentrics, shared with finish
    _fogged = _fog_function()  # the colour stage's fog (a module global, as _point_terms)
    # The lighting equation: the same compiled function as lighting.shade's kernel. A module
    # global, not a closure variable (numba's disk-cache key hashes closure variables, and a
    # compiled function in one changes it in every process). numba does not track that this
    # kernel inlines code from lighting.py, so the hash of that file is a closure constant:
    # editing the equation invalidates the cached kernel.
    _point_terms = lighting.point_terms()
    # the shadow-map look-ups (shadow_kernels.nearest_run and stacked_visibility): their file is stamped too
    from blinn_phong.shadows import kernels as shadow_kernels

    global _stacked_visibility, _nearest_run
    _stacked_visibility = shadow_kernels.stacked_visibility
    _nearest_run = shadow_kernels.nearest_run
    digest = hashlib.sha256()
    for module in (lighting, shadow_kernels):
        with open(module.__file__, "rb") as source:
            digest.update(source.read())
    lighting_stamp = int(digest.hexdigest()[:15], 16)

    @numba.njit(inline="always", cache=True)
    def lerp(values, side, v0, v1, v2, b0, b1, b2, j):  # pragma: no cover - compiled
        return (b0 * values[side, v0, j] + b1 * values[side, v1, j]) + b2 * values[side, v2, j]

    global _lerp
    _lerp = lerp

    # numpy's error model (a division by zero gives inf or nan, as in numpy and in a parallel
    # loop's body, where numba uses it too): Python's would test every division and keep LLVM
    # from optimising the row's loops (measured: 2× the time per frame).
    def plain_row(
        row, width, from_winners, index, tri, bary, frag_depth, frag_front,
        source, sub_front, xe, ye, area, ea, eb, ec, z, w, weights, two_sided,
        geometry, materials, lights, flags, frequencies, fog, has_vis, vis, vis_mean, vis_index,
        maps, world, n_opaque, offsets, max_layers, max_list,
        o_rgba, o_amb, o_dif, o_spe, o_nrm, o_depth, o_shadow, group_of, group_base, o_groups,
        r_bary, r_vis,
    ):  # fmt: skip  # pragma: no cover - compiled
        # Per pixel, its visible fragments: ``index[pixel]`` is the z-buffer's winning
        # sub-triangle (from_winners: barycentrics and depth as ``finish`` computes them) or the
        # opaque fragment's index into (tri, bary, frag_depth, frag_front); −1 where none. Its row
        # of (vis, vis_mean) is ``o`` for fragments, ``vis_index[pixel]`` for winners. Each
        # fragment: surface_at_fragments_compiled's interpolation, the lighting kernel's
        # equation (point_terms), shading._shade_phong's colour (gl_clamp under gl_compat), the
        # colour stage's premultiplied (α·c, α) and per-fragment fog (_fogged) — _shade_fragment,
        # inlined. With transparent fragments (``offsets`` non-empty: the pixel's fragments
        # ``n_opaque + offsets[pixel] ...`` in draw order), resolve_frame_compiled's A-buffer:
        # sorted by depth (stable), the nearest ``max_layers`` composited front to back, over
        # the opaque colour; the passes, normal and depth of the nearest. Then resolve's float32
        # writes, with the same operations in the same order. One row per call: the parallel loop
        # of ``plain`` stays a few lines (numba's parallel transformation of a large loop body
        # is what made this kernel slow to compile: docs/compile.md).
        # Light groups (``o_groups`` (G, H, W, 3), G > 0): each fragment's colour per group, its
        # base ``group_base[mid, g]`` plus its lights' terms (point_terms with ``group_of``),
        # premultiplied, fogged towards black (the fog factor alone) and composited with the
        # same coverage as the frame's colour; Gouraud meshes are not split (the caller does
        # not ask for groups then).
        triangles, triangle_mesh, eye_pos, eye_n, world_n = geometry
        bases, a_cms, d_cms, s_cms, shininesses, opacity = materials
        pos, spot_dir, cos_cut, spot_exp, atten, l_amb, l_dif, l_spe = lights
        local_viewer, blinn, gl_compat, separate = flags
        mode_of, vertex_terms, winding, view_t = frequencies
        fog_mode, fog_radial, density, start, end, cr, cg, cb = fog
        m_first = maps[3]  # one entry per lit light with shadow maps (none: empty)
        # shadow maps (``r_bary``, ``r_vis``: the row's covered pixels' depth and barycentrics
        # and their visibility per light, found by map_row before this call)
        n_lit = m_first.shape[0]
        has_maps = n_lit > 0
        lists = offsets.shape[0] > 0
        row_stamp = np.zeros(0, np.int64)
        row_stamp[:0] = lighting_stamp  # (a reference that keeps the stamp in the cache key)
        order = np.empty(max(max_list, 1), np.int64)  # scratch of the row's thread
        r_vis3 = r_vis.reshape((r_vis.shape[0], r_vis.shape[1], 1))
        j_cov = 0  # the next covered pixel of the row (maps)
        n_groups = o_groups.shape[0]
        g_frag = np.zeros((n_groups, 3))  # a fragment's colour per group
        g_acc = np.zeros((n_groups, 3))  # the pixel's composited colour per group
        n_row = 0
        cy = row + 0.5
        for col in range(width):
            key = row * width + col
            o = index[key]
            count = 0
            first = 0
            if lists:
                first = n_opaque + offsets[key]
                count = offsets[key + 1] - offsets[key]
            if o < 0 and count == 0:
                for ch in range(4):
                    o_rgba[row, col, ch] = 0.0
                for ch in range(3):
                    o_amb[row, col, ch] = 0.0
                    o_dif[row, col, ch] = 0.0
                    o_spe[row, col, ch] = 0.0
                    o_nrm[row, col, ch] = 0.0
                o_depth[row, col] = np.float32(1.0)
                if has_vis:
                    o_shadow[row, col, 0] = 0.0
                for g in range(n_groups):
                    for ch in range(3):
                        o_groups[g, row, col, ch] = 0.0
                continue
            n_row += 1
            for g in range(n_groups):
                for ch in range(3):
                    g_acc[g, ch] = 0.0
            # The pixel's fragments, front to back: the nearest ``max_layers`` transparent ones
            # sorted by depth (stable in draw order), then the opaque one; each composited
            # under the ones before it (resolve's "B over A": acc = c·(1 − acc_α) + acc, and
            # the opaque one as src-over's acc + c·(1 − acc_α), the same sum). The first gives
            # the passes, normal and depth.
            for j in range(count):  # insertion sort by depth, stable in draw order
                f = first + j
                p = j
                while p > 0 and frag_depth[order[p - 1]] > frag_depth[f]:
                    order[p] = order[p - 1]
                    p -= 1
                order[p] = f
            layers = min(count, max_layers)
            acc0 = acc1 = acc2 = acc3 = 0.0
            n_a = n_ar = n_ag = n_ab = n_dr = n_dg = n_db = n_sr = n_sg = n_sb = 0.0
            n_wx = n_wy = n_wz = n_depth = 0.0
            n_v = 0
            for step in range(layers + (1 if o >= 0 else 0)):
                if step < layers:
                    f = order[step]
                    v = f
                    b0, b1, b2 = bary[f, 0], bary[f, 1], bary[f, 2]
                    depth = frag_depth[f]
                    src = tri[f]
                    front = frag_front[f]
                elif from_winners and has_maps:  # found above, with the row's visibilities
                    v = j_cov
                    depth, b0, b1, b2 = r_bary[v, 0], r_bary[v, 1], r_bary[v, 2], r_bary[v, 3]
                    j_cov += 1
                    src = source[o]
                    front = sub_front[o]
                elif from_winners:
                    v = vis_index[key] if has_vis else o
                    depth, b0, b1, b2 = _winner_point(
                        o, col + 0.5, cy, xe, ye, area, ea, eb, ec, z, w, weights
                    )
                    src = source[o]
                    front = sub_front[o]
                else:
                    v = o
                    b0, b1, b2 = bary[o, 0], bary[o, 1], bary[o, 2]
                    depth = frag_depth[o]
                    src = tri[o]
                    front = frag_front[o]
                back = 1 if two_sided and not front else 0
                v0, v1, v2 = triangles[src, 0], triangles[src, 1], triangles[src, 2]
                px = b0 * eye_pos[v0, 0] + b1 * eye_pos[v1, 0] + b2 * eye_pos[v2, 0]
                py = b0 * eye_pos[v0, 1] + b1 * eye_pos[v1, 1] + b2 * eye_pos[v2, 1]
                pz = b0 * eye_pos[v0, 2] + b1 * eye_pos[v1, 2] + b2 * eye_pos[v2, 2]
                mesh = triangle_mesh[src]
                mid = 2 * mesh + back
                mode = mode_of[mesh]
                # fog is a function of the fragment's own point; a flat face is lit at its centroid
                fx, fy, fz = px, py, pz
                nx = ny = nz = 0.0
                if mode == 1:  # flat: lit at the face's eye-space centroid with its face normal
                    px = ((eye_pos[v0, 0] + eye_pos[v1, 0]) + eye_pos[v2, 0]) / 3.0
                    py = ((eye_pos[v0, 1] + eye_pos[v1, 1]) + eye_pos[v2, 1]) / 3.0
                    pz = ((eye_pos[v0, 2] + eye_pos[v1, 2]) + eye_pos[v2, 2]) / 3.0
                    nx, ny, nz = _unit_face_normal(eye_pos, v0, v1, v2)
                    nx, ny, nz = nx * winding[mesh], ny * winding[mesh], nz * winding[mesh]
                    # the world normal: the view's normal matrix undone (n_world ∝ Vᵀ n_eye)
                    wx = view_t[0, 0] * nx + view_t[0, 1] * ny + view_t[0, 2] * nz
                    wy = view_t[1, 0] * nx + view_t[1, 1] * ny + view_t[1, 2] * nz
                    wz = view_t[2, 0] * nx + view_t[2, 1] * ny + view_t[2, 2] * nz
                    length = math.sqrt(wx * wx + wy * wy + wz * wz)
                    scale = 1.0 / length if length > 0 else 0.0
                    wx, wy, wz = wx * scale, wy * scale, wz * scale
                    if back:
                        nx, ny, nz = -nx, -ny, -nz
                else:
                    wx = b0 * world_n[v0, 0] + b1 * world_n[v1, 0] + b2 * world_n[v2, 0]
                    wy = b0 * world_n[v0, 1] + b1 * world_n[v1, 1] + b2 * world_n[v2, 1]
                    wz = b0 * world_n[v0, 2] + b1 * world_n[v1, 2] + b2 * world_n[v2, 2]
                    length = math.sqrt(wx * wx + wy * wy + wz * wz)
                    scale = 1.0 / length if length > 0 else 0.0
                    wx, wy, wz = wx * scale, wy * scale, wz * scale
                if mode == 0:  # phong: the interpolated eye-space normal, renormalised
                    nx = b0 * eye_n[v0, 0] + b1 * eye_n[v1, 0] + b2 * eye_n[v2, 0]
                    ny = b0 * eye_n[v0, 1] + b1 * eye_n[v1, 1] + b2 * eye_n[v2, 1]
                    nz = b0 * eye_n[v0, 2] + b1 * eye_n[v1, 2] + b2 * eye_n[v2, 2]
                    length = math.sqrt(nx * nx + ny * ny + nz * nz)
                    scale = (1.0 / length if length > 0 else 0.0) * (-1.0 if back else 1.0)
                    nx, ny, nz = nx * scale, ny * scale, nz * scale
                if mode == 2:  # gouraud: the vertices' terms interpolated (raster.interpolate's sums)
                    ar = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 0)
                    ag = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 1)
                    ab = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 2)
                    dr = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 3)
                    dg = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 4)
                    db = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 5)
                    sr = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 6)
                    sg = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 7)
                    sb = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 8)
                else:  # one call site of the (inlined) lighting equation for flat and phong
                    for g in range(n_groups):
                        for ch in range(3):
                            g_frag[g, ch] = group_base[mid, g, ch]
                    ar, ag, ab, dr, dg, db, sr, sg, sb = _point_terms(
                        v, px, py, pz, nx, ny, nz, mid, bases, a_cms, d_cms, s_cms, shininesses,
                        pos, spot_dir, cos_cut, spot_exp, atten, l_amb, l_dif, l_spe, local_viewer, blinn,
                        has_vis, r_vis3 if has_maps else vis, group_of, g_frag,
                    )  # fmt: skip
                r, g, b = ar + dr + sr, ag + dg + sg, ab + db + sb  # ShadingTerms.color
                if gl_compat:  # lighting.gl_clamp, then the colour sum clamped
                    if separate:
                        r = min(max(min(max(ar + dr, 0.0), 1.0) + min(max(sr, 0.0), 1.0), 0.0), 1.0)
                        g = min(max(min(max(ag + dg, 0.0), 1.0) + min(max(sg, 0.0), 1.0), 0.0), 1.0)
                        b = min(max(min(max(ab + db, 0.0), 1.0) + min(max(sb, 0.0), 1.0), 0.0), 1.0)
                    else:
                        r = min(max(min(max(r, 0.0), 1.0) + 0.0, 0.0), 1.0)
                        g = min(max(min(max(g, 0.0), 1.0) + 0.0, 0.0), 1.0)
                        b = min(max(min(max(b, 0.0), 1.0) + 0.0, 0.0), 1.0)
                a = opacity[mid]
                pr, pg, pb = a * r, a * g, a * b  # premultiplied (α·c, α): fragment_colours' order
                if fog_mode >= 0:
                    pr, pg, pb = _fogged(
                        fog_mode, fog_radial, density, start, end, cr, cg, cb, fx, fy, fz, pr, pg, pb, a
                    )
                cover = 1.0 - acc3
                if n_groups > 0:
                    f_fog = 1.0  # fog towards black: f·(α·c)
                    if fog_mode >= 0:
                        f_fog = _fogged(
                            fog_mode, fog_radial, density, start, end, 0.0, 0.0, 0.0, fx, fy, fz,
                            1.0, 1.0, 1.0, a,
                        )[0]  # fmt: skip
                    for g in range(n_groups):
                        for ch in range(3):
                            g_acc[g, ch] = (f_fog * (a * g_frag[g, ch])) * cover + g_acc[g, ch]
                acc0 = pr * cover + acc0
                acc1 = pg * cover + acc1
                acc2 = pb * cover + acc2
                acc3 = a * cover + acc3
                if step == 0:  # the nearest fragment: passes, normal, depth, shadow
                    n_a = a
                    n_ar, n_ag, n_ab, n_dr, n_dg, n_db, n_sr, n_sg, n_sb = (
                        ar,
                        ag,
                        ab,
                        dr,
                        dg,
                        db,
                        sr,
                        sg,
                        sb,
                    )
                    n_wx, n_wy, n_wz = wx, wy, wz
                    n_depth = depth
                    n_v = v
            pr, pg, pb, a_over, a = acc0, acc1, acc2, acc3, n_a
            ar, ag, ab, dr, dg, db, sr, sg, sb = n_ar, n_ag, n_ab, n_dr, n_dg, n_db, n_sr, n_sg, n_sb
            wx, wy, wz, depth, v = n_wx, n_wy, n_wz, n_depth, n_v
            # ``0.0 + x`` keeps numpy's sign of zero (a sum of one term), as resolve does.
            o_rgba[row, col, 0] = 0.0 + np.float32(pr)
            o_rgba[row, col, 1] = 0.0 + np.float32(pg)
            o_rgba[row, col, 2] = 0.0 + np.float32(pb)
            o_rgba[row, col, 3] = 0.0 + np.float32(a_over)
            o_amb[row, col, 0] = 0.0 + np.float32(ar * a)
            o_amb[row, col, 1] = 0.0 + np.float32(ag * a)
            o_amb[row, col, 2] = 0.0 + np.float32(ab * a)
            o_dif[row, col, 0] = 0.0 + np.float32(dr * a)
            o_dif[row, col, 1] = 0.0 + np.float32(dg * a)
            o_dif[row, col, 2] = 0.0 + np.float32(db * a)
            o_spe[row, col, 0] = 0.0 + np.float32(sr * a)
            o_spe[row, col, 1] = 0.0 + np.float32(sg * a)
            o_spe[row, col, 2] = 0.0 + np.float32(sb * a)
            o_nrm[row, col, 0] = 0.0 + np.float32(wx)
            o_nrm[row, col, 1] = 0.0 + np.float32(wy)
            o_nrm[row, col, 2] = 0.0 + np.float32(wz)
            o_depth[row, col] = min(np.float32(1.0), np.float32(depth))
            if has_maps:  # resolve.shadow_pass_values: summed in light order, then divided
                mean = r_vis[v, 0]
                for i_light in range(1, n_lit):
                    mean += r_vis[v, i_light]
                mean /= n_lit
                o_shadow[row, col, 0] = 0.0 + np.float32(mean * a)
            elif has_vis:
                o_shadow[row, col, 0] = 0.0 + np.float32(vis_mean[v] * a)
            for g in range(n_groups):
                for ch in range(3):
                    o_groups[g, row, col, ch] = 0.0 + np.float32(g_acc[g, ch])
        return n_row

    plain_row = numba.njit(cache=True, error_model="numpy")(plain_row)
    # module globals, not closure variables (as _point_terms: the disk cache's key)
    global _plain_row, _map_row
    _plain_row = plain_row

    @numba.njit(cache=True, error_model="numpy")
    def map_row(
        row, width, index, xe, ye, area, ea, eb, ec, z, w, weights, source, triangles, world, maps,
        r_bary, r_pts, r_vis, s_qx, s_qy, s_qz, s_cw, s_face,
    ):  # fmt: skip  # pragma: no cover - compiled
        # The row's covered pixels first: each winner's depth and barycentrics (read back by
        # plain_row), its world point (as winner_surface) and its visibility per light
        # (shadow_kernels.visibility_at, opaque winners only, no normal offset), in runs over the
        # row (shadow_kernels.nearest_run: tight loops of divisions), or per point
        # (stacked_visibility: the PCF kernels). Compiled only for frames with shadow maps.
        m_depth, m_vp, m_vz, m_first, m_faces, m_pos, m_kernel, m_rects, m_miss = maps
        n_lit = m_first.shape[0]
        no_faces = np.zeros(0, np.int8)
        n_cov = 0
        for col in range(width):
            o = index[row * width + col]
            if o < 0:
                continue
            depth, b0, b1, b2 = _winner_point(
                o, col + 0.5, row + 0.5, xe, ye, area, ea, eb, ec, z, w, weights
            )
            r_bary[n_cov, 0], r_bary[n_cov, 1], r_bary[n_cov, 2], r_bary[n_cov, 3] = depth, b0, b1, b2
            src = source[o]
            v0, v1, v2 = triangles[src, 0], triangles[src, 1], triangles[src, 2]
            for k in range(3):
                r_pts[n_cov, k] = _interpolated(world, v0, v1, v2, b0, b1, b2, k)  # as winner_surface
            n_cov += 1
        for i_light in range(n_lit):
            f0 = m_first[i_light]
            if f0 < 0:
                for j in range(n_cov):
                    r_vis[j, i_light] = 1.0
                continue
            cube = 1 if m_faces[i_light] == 6 else 0
            if m_kernel[i_light] == 0:
                _nearest_run(
                    r_pts, 0, n_cov, m_depth, m_vp, f0, cube, m_pos[i_light], no_faces, False,
                    r_vis, i_light, 0, s_qx, s_qy, s_qz, s_cw, s_face, m_rects, m_miss,
                )  # fmt: skip
                continue
            for j in range(n_cov):
                r_vis[j, i_light] = _stacked_visibility(
                    r_pts[j, 0], r_pts[j, 1], r_pts[j, 2], 0.0, 0.0, 0.0,
                    m_depth, m_vp, m_vz, f0, cube, m_pos[i_light], 0.0, m_kernel[i_light],
                    m_rects, m_miss,
                )  # fmt: skip

    _map_row = map_row


@functools.lru_cache(maxsize=2)
def _plain_kernel(with_maps: bool = False) -> object:  # a numba dispatcher
    """The fused frame kernel; ``with_maps``: the variant that looks shadow maps up itself.

    Two variants of the short loop over a share of rows, so that a frame without shadow maps
    does not compile the shadow-map look-ups (``map_row``, ``shadow_kernels.nearest_run`` and
    ``stacked_visibility``, about 5 s of compilation): the branch on the constant ``with_maps``
    is removed before numba types the function, and the variants are cached apart (their names
    and closure values differ). Both call the same row function (compiled once)."""
    import numba

    _row_kernels()

    def plain(
        width, height, row_order, from_winners, index, tri, bary, frag_depth, frag_front,
        source, sub_front, xe, ye, area, ea, eb, ec, z, w, weights, two_sided,
        geometry, materials, lights, flags, frequencies, fog, has_vis, vis, vis_mean, vis_index,
        maps, world, n_opaque, offsets, max_layers, max_list,
        o_rgba, o_amb, o_dif, o_spe, o_nrm, o_depth, o_shadow, group_of, group_base, o_groups,
    ):  # fmt: skip  # pragma: no cover - compiled
        # The rows ``row_order`` (a share of the frame's: compositing._threads runs the shares on
        # threads, the GIL released); each row is written by one call of plain_row, so there are
        # no write races. Returns the number of covered pixels. ``with_maps`` (a constant: the
        # branch is removed before typing) — the variant that looks the shadow maps up first.
        n_lit = maps[3].shape[0]
        scratch = width if with_maps and n_lit > 0 else 0
        r_bary = np.empty((scratch, 4))  # the row's winners (depth, b0, b1, b2) ...
        r_pts = np.empty((scratch, 3))  # ... world points and visibilities
        r_vis = np.empty((scratch, max(n_lit, 1)))
        s_qx = np.empty(scratch)
        s_qy = np.empty(scratch)
        s_qz = np.empty(scratch)
        s_cw = np.empty(scratch)
        s_face = np.zeros(scratch, np.int64)
        covered = 0
        for i_row in range(row_order.shape[0]):
            row = row_order[i_row]
            if with_maps:
                if n_lit > 0:
                    _map_row(
                        row, width, index, xe, ye, area, ea, eb, ec, z, w, weights, source,
                        geometry[0], world, maps, r_bary, r_pts, r_vis, s_qx, s_qy, s_qz, s_cw, s_face,
                    )  # fmt: skip
            covered += _plain_row(
                row, width, from_winners, index, tri, bary, frag_depth, frag_front,
                source, sub_front, xe, ye, area, ea, eb, ec, z, w, weights, two_sided,
                geometry, materials, lights, flags, frequencies, fog, has_vis, vis, vis_mean, vis_index,
                maps, world, n_opaque, offsets, max_layers, max_list,
                o_rgba, o_amb, o_dif, o_spe, o_nrm, o_depth, o_shadow, group_of, group_base, o_groups,
                r_bary, r_vis,
            )  # fmt: skip
        return covered

    variant = "maps" if with_maps else "plain"
    plain.__qualname__ += f".{variant}"
    return numba.njit(cache=True, nogil=True)(plain)


def _run_plain(*args: object, with_maps: bool = False) -> int:
    """Run the fused kernel: the frame's rows in shares on threads
    (:func:`compositing._threads.run_shares`; the kernel releases the GIL).

    Its first compilation (once per machine: the kernel is disk-cached) makes numba's own
    pedantic SSA check warn about variables of the inlined lighting helpers that it expects in
    scope (``NumbaIRAssumptionWarning``, "please report"); the compiled code is unaffected (the
    fused frame equals the numpy engine's, tested), so that warning is not passed on to the user.
    """
    from numba.core.errors import NumbaIRAssumptionWarning

    from compositing._threads import run_shares

    kernel = _plain_kernel(with_maps)
    width, height, row_order, *rest = args
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaIRAssumptionWarning)
        # compiled (or loaded) on this thread first: the shares' threads then only run it
        kernel(width, height, row_order[:0], *rest)  # type: ignore[operator]
        shares = run_shares(lambda rows: kernel(width, height, rows, *rest), row_order)  # type: ignore[operator]
    return int(sum(shares))


_NO_SETUP = (
    np.zeros(0, np.int64), np.zeros(0, np.bool_), *(np.zeros((0, 3)) for _ in range(2)), np.zeros(0),
    *(np.zeros((0, 3)) for _ in range(5)), np.zeros((0, 3, 3)),
)  # fmt: skip
_NO_FRAGMENTS = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.bool_))
_NO_INDEX = np.zeros(0, np.int64)
#: No shadow maps for the fused kernel (the fields of blinn_phong.shadows.frame_maps.MapStack), no world
#: vertices.
_NO_MAPS = (
    np.zeros((0, 1, 1)), np.zeros((0, 4, 4)), np.zeros((0, 3)), np.zeros(0, np.int64),
    np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 4), np.int64),
    np.zeros(1, np.int64),
)  # fmt: skip
_NO_WORLD = np.zeros((0, 3))
_NO_WORLD.flags.writeable = False  # one signature: the kernel reads world vertices as read-only views
#: No light groups for the fused kernel: ``(group_of, group_base, out)``.
_NO_GROUPS = (np.zeros(0, np.int64), np.zeros((0, 0, 3)), np.zeros((0, 0, 0, 3), np.float32))


def _group_args(
    groups: tuple[np.ndarray, np.ndarray, np.ndarray] | None, n_lights: int, height: int, width: int,
    n_materials: int,
) -> tuple[np.ndarray, ...]:  # fmt: skip
    """The fused kernel's ``(group_of, group_base, o_groups)`` of ``groups`` (see
    :func:`shade_plain_fragments_compiled`), checked, or :data:`_NO_GROUPS`."""
    if groups is None:
        return _NO_GROUPS
    group_of, base, out = groups
    group_of = np.ascontiguousarray(group_of, dtype=np.int64)
    base = np.ascontiguousarray(base, dtype=np.float64)
    n = out.shape[0] if out.ndim == 4 else -1
    if group_of.shape != (n_lights,) or (group_of >= n).any() or base.shape != (n_materials, n, 3):
        raise ValueError(
            f"groups: expected group_of ({n_lights},) < G and base ({n_materials}, G, 3) for out "
            f"(G, H, W, 3), got {group_of.shape}, {base.shape} and {out.shape}"
        )
    if n < 1 or out.shape[1:] != (height, width, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(
            f"groups: expected out a C-contiguous float32 (G ≥ 1, {height}, {width}, 3) array, "
            f"got {out.dtype} {out.shape}"
        )
    return group_of, base, out


def _row_order(height: int) -> np.ndarray:
    """Rows grouped by their residue modulo 16: a parallel loop's contiguous share of iterations
    then covers rows spread over the whole image (an image's busy rows are often together)."""
    return np.argsort(np.arange(height) % 16, kind="stable").astype(np.int64)


#: What the fused plain kernels read of a prepared scene: ``(two_sided, geometry, materials,
#: lights, flags, frequencies)`` with geometry ``(triangles, triangle_mesh, eye_position, eye_normal,
#: world_normal)``, materials and lights as :func:`blinn_phong.frame.lighting.material_tables` and
#: :func:`blinn_phong.frame.lighting.light_tables` give them, flags ``(local_viewer, blinn,
#: gl_compat, separate_specular)``, frequencies ``(mode, vertex_terms, winding, view_t)`` as
#: :func:`blinn_phong.frame.shading.plain_tables` gives them (per mesh: 0 phong, 1 flat, 2 gouraud).
_Arrays = tuple[np.ndarray, ...]
PlainTables = tuple[bool, _Arrays, _Arrays, _Arrays, tuple, _Arrays]


def shade_plain_fragments_compiled(
    width: int,
    height: int,
    opaque_of: np.ndarray,
    triangle: np.ndarray,
    bary: np.ndarray,
    depth: np.ndarray,
    front_facing: np.ndarray,
    tables: PlainTables,
    visibility: np.ndarray | None,
    vis_mean: np.ndarray | None,
    out: tuple[np.ndarray, ...],
    fog: FogArgs = None,
    transparent: tuple[int, np.ndarray, int] | None = None,
    groups: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> None:
    """The frame's shading and resolve fused: each pixel's fragments shaded, resolved and written.

    For one sample per pixel, no transparency resolve, per-pixel (phong) shading and
    partial-occlusion colours ``(α·c, α)``: per pixel, the fragment ``opaque_of[pixel]`` (−1:
    empty) is interpolated (as :func:`surface_at_fragments_compiled`), lit by
    :func:`blinn_phong.frame.lighting.point_terms` with ``visibility`` (N, L, K) (K = 1 or 3), fogged
    when ``fog`` is given (``(mode, radial, (density, start, end), colour)`` as for
    :func:`fragment_colours_compiled`, by the same compiled function: OpenGL 2.1 §3.10 on the
    premultiplied colour; the light passes are not fogged) and written into the float32
    ``out = (rgba, ambient, diffuse, specular, normal, depth, shadow)`` buffers as
    :func:`resolve_plain_compiled` writes them: the same images as the separate shading,
    colour and resolve stages, without their (N, 3) float64 arrays.

    ``transparent``: ``(n_opaque, offsets, max_layers)`` of a frame with transparent fragments
    (:class:`blinn_phong.frame.visibility.FrameFragments`: the fragments ``n_opaque + offsets[p] …
    n_opaque + offsets[p + 1]`` of pixel ``p``, in draw order, in front of its opaque one),
    resolved as the A-buffer (``max_layers`` ≥ the longest list) or depth peeling
    (``max_layers`` = the layers) of :func:`resolve_frame_compiled`: sorted by depth, the
    nearest ``max_layers`` composited front to back over the opaque colour; passes, normal and
    depth of the nearest fragment.

    ``groups``: None, or light groups' passes (:mod:`blinn_phong.frame.light_groups`) made in the same
    pass: ``(group_of, base, out)`` with ``group_of`` (L,) int64 the group of each light of the
    tables (−1: none), ``base`` (2·M, G, 3) float64 each material side's terms that do not depend
    on a light of the tables, per group (emission, ``a_cm``·global ambient, ``a_cm``·ambient
    lights), and ``out`` (G, H, W, 3) float32, written like ``rgba``'s colour: each fragment's
    colour from group g's emitters alone, premultiplied, fogged towards black (the fog factor
    applied), composited with the frame's coverages. Not for Gouraud-shaded meshes (their
    vertex terms are not split by group).
    """
    two_sided, geometry, materials, lights, flags, frequencies = tables
    fragments = (
        np.ascontiguousarray(triangle, dtype=np.int64), np.ascontiguousarray(bary),
        np.ascontiguousarray(depth), np.ascontiguousarray(front_facing, dtype=np.bool_),
    )  # fmt: skip
    lists: tuple[int, np.ndarray, int, int] = (0, _NO_INDEX, 0, 0)
    if transparent is not None:
        n_opaque, offsets, max_layers = transparent
        offsets = np.ascontiguousarray(offsets, dtype=np.int64)
        longest = int(np.diff(offsets).max(initial=0))
        if max_layers < 1:
            raise ValueError(f"transparent: max_layers must be >= 1, got {max_layers}")
        lists = (int(n_opaque), offsets, int(max_layers), longest)
    _run_plain(
        width, height, _row_order(height), False, opaque_of, *fragments, *_NO_SETUP, two_sided,
        geometry, materials, lights, flags, frequencies, _fog_scalars(fog), visibility is not None,
        np.zeros((0, 0, 1)) if visibility is None else np.ascontiguousarray(visibility, dtype=np.float64),
        np.zeros(0) if vis_mean is None else np.ascontiguousarray(vis_mean, dtype=np.float64),
        _NO_INDEX, _NO_MAPS, _NO_WORLD, *lists, *out,
        *_group_args(groups, len(lights[0]), height, width, len(materials[0])),
    )  # fmt: skip


def nearest_winners_compiled(setup: _TriangleSetup) -> np.ndarray:
    """(fine height · fine width,) int64: the sub-triangle of ``setup`` nearest at each fine sample
    (−1 where none), by the compiled z-buffer (``GL_LESS`` in draw order)."""
    fine_w, fine_h = setup.width * setup.k, setup.height * setup.k
    zbuffer = _kernel()[0]
    winner, _ = zbuffer(
        _bands(fine_h), fine_w, fine_h, setup.selected.astype(np.int64), setup.x0, setup.x1, setup.y0,
        setup.y1, setup.a, setup.b, setup.c, setup.top_left, setup.x_exact, setup.y_exact, setup.area,
        setup.z, setup.source,
    )  # fmt: skip
    return winner


def shade_plain_winners_compiled(
    setup: _TriangleSetup,
    winner: np.ndarray,
    tables: PlainTables,
    out: tuple[np.ndarray, ...],
    fog: FogArgs = None,
    visibility: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    maps: tuple[tuple[np.ndarray, ...], np.ndarray] | None = None,
    groups: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> int:
    """:func:`shade_plain_fragments_compiled` straight from the z-buffer's winners (one sample per
    pixel, ``fog`` as there): barycentrics and depth as :func:`frame_fragments_compiled` computes
    them, in the same pass.

    ``visibility``: None, or ``(vis, vis_mean, rank)`` for shadowed frames: ``vis`` (N, L, K)
    and ``vis_mean`` (N,) of the covered pixels in row-major order, ``rank`` (H·W,) each pixel's
    row in them (−1 where empty), as :func:`winner_surfaces_compiled` numbers them.

    ``maps``: None, or ``(stack, world_vertices)`` for a frame whose every shadowed light is
    shadow-mapped (``visibility`` None): a :class:`blinn_phong.shadows.frame_maps.MapStack` of the maps
    of every non-ambient light and the (V, 3) float64 world positions of the prepared scene's
    vertices. Each pixel's world point (as :func:`winner_surfaces_compiled` computes it) is
    looked up in the maps as it is shaded (:func:`blinn_phong.shadows.kernels.stacked_visibility`),
    and the shadow pass is the mean of its visibilities
    (:func:`blinn_phong.frame.resolve.shadow_pass_values`).

    ``groups``: light groups' passes made in the same pass, as for
    :func:`shade_plain_fragments_compiled`.

    Returns the number of covered pixels (fragments shaded)."""
    if setup.k != 1:
        raise ValueError(f"setup: expected one sample per pixel, got {setup.k * setup.k}")
    two_sided, geometry, materials, lights, flags, frequencies = tables
    sub = (
        setup.source, setup.front, setup.x_exact, setup.y_exact, setup.area, setup.a, setup.b, setup.c,
        setup.z, setup.w, np.ascontiguousarray(setup.weights),
    )  # fmt: skip
    if visibility is not None and maps is not None:
        raise ValueError("visibility and maps: expected at most one of them")
    if visibility is None:
        vis, vis_mean, rank = np.zeros((0, 0, 1)), np.zeros(0), _NO_INDEX
    else:
        vis, vis_mean, rank = (np.ascontiguousarray(a) for a in visibility)
        vis = vis.astype(np.float64, copy=False)
        vis_mean = vis_mean.astype(np.float64, copy=False)
    stack, world = _NO_MAPS, _NO_WORLD
    if maps is not None:
        stack, world = tuple(maps[0]), np.ascontiguousarray(maps[1], dtype=np.float64).view()
        world.flags.writeable = False  # typed as _NO_WORLD is: one compiled specialisation
        if len(stack[3]) != len(lights[0]):
            raise ValueError(
                f"maps: expected one entry per non-ambient light ({len(lights[0])}), got {len(stack[3])}"
            )
    return int(
        _run_plain(
            setup.width, setup.height, _row_order(setup.height), True, winner, *_NO_FRAGMENTS, *sub,
            two_sided, geometry, materials, lights, flags, frequencies, _fog_scalars(fog),
            visibility is not None or maps is not None, vis, vis_mean, rank, stack, world, 0, _NO_INDEX, 0, 0,
            *out, *_group_args(groups, len(lights[0]), setup.height, setup.width, len(materials[0])),
            with_maps=maps is not None,
        )
    )  # fmt: skip


@functools.lru_cache(maxsize=1)
def _winner_surface_kernel() -> object:  # a numba dispatcher

    import numba

    _kernel()  # sets _winner_point (a module global, as in _plain_kernel)

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def winner_surface(
        share,
        width, height, row_order, winner, rank, xe, ye, area, a, b, c, z, w, weights, source, triangles,
        world, face_normal, triangle_mesh, out_points, out_normals, out_mesh,
    ):  # fmt: skip  # pragma: no cover - compiled
        # Per covered pixel (its row ``rank[pixel]``): the winner's perspective-correct
        # barycentrics (_winner_point, as ``finish``), the world point interpolated as
        # raster.interpolate sums it (k = 0, 1, 2), its triangle's unit face normal and mesh.
        for i_row in share:
            row = row_order[i_row]  # rows interleaved over the threads (balanced work)
            cy = row + 0.5
            for col in range(width):
                key = row * width + col
                t = winner[key]
                if t < 0:
                    continue
                i = rank[key]
                _, b0, b1, b2 = _winner_point(t, col + 0.5, cy, xe, ye, area, a, b, c, z, w, weights)
                src = source[t]
                out_mesh[i] = triangle_mesh[src]
                v0, v1, v2 = triangles[src, 0], triangles[src, 1], triangles[src, 2]
                for k in range(3):
                    out_points[i, k] = _interpolated(world, v0, v1, v2, b0, b1, b2, k)
                nx, ny, nz = face_normal[src, 0], face_normal[src, 1], face_normal[src, 2]
                out_normals[i, 0], out_normals[i, 1], out_normals[i, 2] = nx, ny, nz

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def face_normals(share, triangles, world, out):  # pragma: no cover - compiled
        # normals.face_normals over the world corners (_unit_face_normal)
        for f in share:
            nx, ny, nz = _unit_face_normal(world, triangles[f, 0], triangles[f, 1], triangles[f, 2])
            out[f, 0], out[f, 1], out[f, 2] = nx, ny, nz

    @numba.njit(cache=True)
    def ranks(winner, rank):  # pragma: no cover - compiled
        # each covered key's rank among the covered keys in increasing order (−1 where empty),
        # as compact numbers them; returns their number
        n = 0
        for key in range(winner.shape[0]):
            if winner[key] >= 0:
                rank[key] = n
                n += 1
            else:
                rank[key] = -1
        return n

    return winner_surface, face_normals, ranks


def face_normals_compiled(triangles: np.ndarray, world_vertices: np.ndarray) -> np.ndarray:
    """(T, 3) float64 unit world face normals of the triangles (zero for a zero-area triangle):
    :func:`blinn_phong.geometry.normals.face_normals` of each triangle's world corners, in parallel.

    Args:
        triangles: (T, 3) int64 vertex indices into ``world_vertices``.
        world_vertices: (V, 3) float64 world-space positions.
    """
    tris = np.ascontiguousarray(triangles, dtype=np.int64)
    out = np.empty((len(tris), 3))
    _shares(
        _winner_surface_kernel()[1],
        len(tris),
        tris,
        np.ascontiguousarray(world_vertices, dtype=np.float64),
        out,
    )
    return out


def winner_surfaces_compiled(
    setup: _TriangleSetup,
    winner: np.ndarray,
    triangles: np.ndarray,
    world_vertices: np.ndarray,
    triangle_mesh: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """World points and face normals of the z-buffer's winners, one row per covered pixel.

    Args:
        setup: the frame's triangle set-up (one sample per pixel).
        winner: (H·W,) int64 from :func:`nearest_winners_compiled`.
        triangles: (T, 3) int64 vertex indices into ``world_vertices`` (the prepared scene's).
        world_vertices: (V, 3) float64 world-space positions of every mesh's vertices.
        triangle_mesh: (T,) int64 the mesh of each triangle.

    Returns:
        ``(points (N, 3), normals (N, 3), rank (H·W,), mesh (N,))`` float64, float64, int64,
        int64: the covered
        pixels in row-major order, their perspective-correct world points, their unit world face
        normals (zero for a zero-area triangle; the orientation of the world corners, which
        shadow methods do not use: they face each normal towards the light), and each
        pixel's row (−1 where empty), and each covered pixel's mesh.
    """
    if setup.k != 1:
        raise ValueError(f"setup: expected one sample per pixel, got {setup.k * setup.k}")
    rank = np.empty(setup.width * setup.height, np.int64)
    covered = _winner_surface_kernel()[2](winner, rank)
    points = np.empty((covered, 3))
    normals = np.empty((covered, 3))
    mesh = np.empty(covered, np.int64)
    winner_surface = _winner_surface_kernel()[0]
    tris = np.ascontiguousarray(triangles, dtype=np.int64)
    verts = np.ascontiguousarray(world_vertices, dtype=np.float64)
    faces = face_normals_compiled(tris, verts)
    _shares(
        winner_surface, setup.height,
        setup.width, setup.height, _row_order(setup.height), winner, rank, setup.x_exact, setup.y_exact,
        setup.area, setup.a,
        setup.b, setup.c, setup.z, setup.w, np.ascontiguousarray(setup.weights), setup.source,
        tris, verts, faces, np.ascontiguousarray(triangle_mesh, dtype=np.int64), points, normals, mesh,
    )  # fmt: skip
    return points, normals, rank, mesh


@functools.lru_cache(maxsize=1)
def _setup_kernels() -> object:  # numba dispatchers

    import numba

    @numba.njit(cache=True)
    def classify(clip, tri, n_in):  # pragma: no cover - compiled
        # Vertices inside the near plane (z + w >= 0) per triangle, as raster._clip_near counts them
        # (serial: a few operations per triangle, not worth a parallel region's start-up).
        for t in range(tri.shape[0]):
            n = 0
            for j in range(3):
                v = tri[t, j]
                if clip[v, 2] + clip[v, 3] >= 0:
                    n += 1
            n_in[t] = n

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def setup(
        share,
        clip, tri, whole, extra, fine_w, fine_h, cull, w_out, xe_out, ye_out, z_out, area_out, front_out,
        keep_out, ok_out, x0_out, x1_out, y0_out, y1_out, a_out, b_out, c_out, tl_out, scale,
    ):  # fmt: skip  # pragma: no cover - compiled
        # raster._setup_triangles per sub-triangle, the same operations in the same order: the
        # whole triangles ``tri[whole]`` first, then the near-clipped sub-triangles ``extra``.
        n_whole = whole.shape[0]
        half_w = 0.5 * fine_w
        half_h = 0.5 * fine_h
        for s in share:
            ok = True
            x = (0.0, 0.0, 0.0)
            y = (0.0, 0.0, 0.0)
            for j in range(3):
                if s < n_whole:
                    v = tri[whole[s], j]
                    cx, cy, cz, cw = clip[v, 0], clip[v, 1], clip[v, 2], clip[v, 3]
                else:
                    e = s - n_whole
                    cx, cy, cz, cw = extra[e, j, 0], extra[e, j, 1], extra[e, j, 2], extra[e, j, 3]
                ok = ok and cw > 0
                w_out[s, j] = cw
                xe = (cx / cw + 1.0) * half_w
                ye = fine_h - (cy / cw + 1.0) * half_h
                xe_out[s, j] = xe
                ye_out[s, j] = ye
                z_out[s, j] = (cz / cw + 1.0) * 0.5
                xs = np.rint(xe * scale) / scale  # snapped to the sub-pixel grid: coverage only
                ys = fine_h - np.rint((fine_h - ye) * scale) / scale
                if j == 0:
                    x = (xs, x[1], x[2])
                    y = (ys, y[1], y[2])
                elif j == 1:
                    x = (x[0], xs, x[2])
                    y = (y[0], ys, y[2])
                else:
                    x = (x[0], x[1], xs)
                    y = (y[0], y[1], ys)
            ok_out[s] = ok
            area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
            area_out[s] = area
            front = area < 0
            front_out[s] = front
            keep = area != 0
            if cull:
                keep = keep and front
            x0 = min(max(np.ceil(min(x[0], x[1], x[2]) - 0.5), 0.0), float(fine_w))
            x1 = min(max(np.floor(max(x[0], x[1], x[2]) - 0.5), -1.0), float(fine_w - 1))
            y0 = min(max(np.ceil(min(y[0], y[1], y[2]) - 0.5), 0.0), float(fine_h))
            y1 = min(max(np.floor(max(y[0], y[1], y[2]) - 0.5), -1.0), float(fine_h - 1))
            x0_out[s], x1_out[s], y0_out[s], y1_out[s] = int(x0), int(x1), int(y0), int(y1)
            keep_out[s] = keep and x0 <= x1 and y0 <= y1
            sign = -1.0 if area < 0 else 1.0
            for i in range(3):
                j = (i + 1) % 3
                k = (i + 2) % 3
                xj, yj, xk, yk = x[j], y[j], x[k], y[k]
                a = -(yk - yj) * sign
                b = (xk - xj) * sign
                a_out[s, i] = a
                b_out[s, i] = b
                c_out[s, i] = ((yk - yj) * xj - (xk - xj) * yj) * sign
                tl_out[s, i] = a > 0 or (a == 0 and b < 0)

    return classify, setup


def setup_triangles_compiled(
    clip_xyzw: np.ndarray, triangles: np.ndarray, width: int, height: int, samples: int, cull_backfaces: bool
) -> _TriangleSetup:
    """Compiled twin of :func:`blinn_phong.geometry.raster._setup_triangles`: the same arrays, bit for bit.

    The same validation; triangles crossing the near plane are clipped by the reference
    :func:`blinn_phong.geometry.raster._clip_near` (on those triangles only), and every sub-triangle's
    window positions, snapping, bounding box and edge functions are computed in one parallel
    loop with the reference's operations in the reference's order (IEEE arithmetic, no
    fast-math: the same bits; tests/blinn_phong/test_engines_agree.py checks every array).
    """
    from blinn_phong._checks import float_array
    from blinn_phong.geometry.raster import (
        SUBPIXEL_BITS,
        _check_size,
        _check_triangles,
        _clip_near,
        _grid_side,
    )

    clip = np.ascontiguousarray(float_array(clip_xyzw, "clip_xyzw", (None, 4)))
    tri = np.ascontiguousarray(_check_triangles(triangles, len(clip)))
    width = _check_size(width, "width")
    height = _check_size(height, "height")
    k = _grid_side(samples)
    fine_w, fine_h = width * k, height * k
    classify, setup = _setup_kernels()
    n_in = np.empty(len(tri), np.int64)
    classify(clip, tri, n_in)
    whole = np.flatnonzero(n_in == 3)
    partial = np.flatnonzero((n_in == 1) | (n_in == 2))
    if len(partial):
        extra, extra_weights, extra_source = _clip_near(clip[tri[partial]])
        extra_source = partial[extra_source]
    else:
        extra, extra_weights, extra_source = np.zeros((0, 3, 4)), np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    n = len(whole) + len(extra)
    f64 = np.float64
    w, xe, ye, z = (np.empty((n, 3), f64) for _ in range(4))
    area = np.empty(n, f64)
    front, keep, ok = (np.empty(n, np.bool_) for _ in range(3))
    x0, x1, y0, y1 = (np.empty(n, np.int64) for _ in range(4))
    a, b, c = (np.empty((n, 3), f64) for _ in range(3))
    top_left = np.empty((n, 3), np.bool_)
    _shares(
        setup, n,
        clip, tri, whole, np.ascontiguousarray(extra, dtype=f64), fine_w, fine_h, bool(cull_backfaces),
        w, xe, ye, z, area, front, keep, ok, x0, x1, y0, y1, a, b, c, top_left, float(1 << SUBPIXEL_BITS),
    )  # fmt: skip
    source = np.concatenate([whole, extra_source]).astype(np.int64, copy=False)
    weights = np.empty((n, 3, 3))
    weights[: len(whole)] = np.eye(3)
    weights[len(whole) :] = extra_weights
    if not ok.all():  # a non-standard projection left w <= 0 after near clipping: dropped
        arrays = [source, weights, w, xe, ye, z, area, front, keep, x0, x1, y0, y1, a, b, c, top_left]
        source, weights, w, xe, ye, z, area, front, keep, x0, x1, y0, y1, a, b, c, top_left = (
            v[ok] for v in arrays
        )
    return _TriangleSetup(
        width, height, k, source, weights, w, xe, ye, z, area, front, np.flatnonzero(keep),
        x0, x1, y0, y1, a, b, c, top_left,
    )  # fmt: skip
