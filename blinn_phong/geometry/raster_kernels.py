"""The compiled (numba) twins of :mod:`blinn_phong.geometry.raster`: triangle set-up, scan
conversion and the depth test.

* :func:`setup_triangles_compiled`: the same triangle set-up as the reference
  (:func:`blinn_phong.geometry.raster._setup_triangles`), computed to the same bits: the same
  clipping, snapping, edge functions and fill rule.
* :func:`visible_fragments_compiled` keeps only the nearest fragment per sample;
  :func:`frame_fragments_compiled` also builds, per sample, the list of transparent fragments in
  front of the opaque depth (a counting pass, a prefix sum, a filling pass), so no array of all
  fragments is ever built. Barycentrics and depths of the kept fragments come from a compiled
  twin of :func:`blinn_phong.geometry.raster._fragments_from_hits`.
* :func:`nearest_winners_compiled`, :func:`winner_surfaces_compiled`: the z-buffer's winners and
  their world points and face normals, for frames shaded straight from the winners.

The depth test is ``GL_LESS`` in draw order, as :func:`blinn_phong.geometry.raster.resolve_nearest`:
smaller depth wins, equal depths go to the lower triangle index. Rasterization splits the image
into horizontal bands processed in parallel (numba ``prange``: as serial shares on threads these
loops ran 2–5× slower); the other kernels are serial loops that release the GIL and run on shares
of their rows on threads (:mod:`compositing._threads`). Each band or row owns its outputs, so
there are no write races and the results do not depend on the thread count
(tests/blinn_phong/test_engines_agree.py checks every kernel against the reference).
"""

from __future__ import annotations

import functools
import os

import numpy as np

from blinn_phong.geometry.raster import Fragments, _TriangleSetup

#: The z-buffer kernels' inlined helpers, set by :func:`_kernel` (module globals: the fused frame
#: kernel of :mod:`blinn_phong.frame.fused` inlines them too).
_triangle_setup: object = None
_sample_depth: object = None
_winner_point: object = None
_unit_face_normal: object = None
_interpolated: object = None


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
        zbuf = np.empty(n_keys)  # each band clears its own rows: the pages are touched in parallel
        winner = np.empty(n_keys, np.int64)
        band_h = (fine_h + n_bands - 1) // n_bands
        for band in numba.prange(n_bands):
            r0 = band * band_h
            r1 = min(fine_h, r0 + band_h) - 1
            for key in range(r0 * fine_w, (r1 + 1) * fine_w):
                zbuf[key] = np.inf
                winner[key] = -1
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



def _row_order(height: int) -> np.ndarray:
    """Rows grouped by their residue modulo 16: a parallel loop's contiguous share of iterations
    then covers rows spread over the whole image (an image's busy rows are often together)."""
    return np.argsort(np.arange(height) % 16, kind="stable").astype(np.int64)


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


@functools.lru_cache(maxsize=1)
def _winner_surface_kernel() -> object:  # a numba dispatcher

    import numba

    _kernel()  # sets _winner_point (a module global: numba's disk-cache key hashes closure variables)

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
