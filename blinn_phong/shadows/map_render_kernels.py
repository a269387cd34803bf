"""Compiled (numba) shadow-map rendering: the depth maps of
:func:`blinn_phong.shadows.maps.render_shadow_map`, without an array of all fragments.

:func:`blinn_phong.shadows.maps.render_shadow_map` (numpy) is the reference; this module
runs the same formulas in compiled loops:

* :func:`depth_map_compiled` / :func:`cube_maps_compiled` — per (map, chunk of triangles)
  in shares on threads: near-plane clipping (``z_c ≥ −w_c``, new vertices interpolated in clip
  space, §2.12 of OpenGL 2.1), the viewport transform, snapping to 1/256 texel, edge functions
  and the top-left fill rule of :mod:`blinn_phong.geometry.raster`, and for a triangle that
  draws something its depth slope ``m = max(|∂z/∂x|, |∂z/∂y|)`` in texel units (the unclipped
  triangle, §3.5.5), each drawn triangle one float64 record; then per (map, band of rows),
  every thread taking every other band of every map, the scan conversion (each row only over
  the span its three edge functions allow, plus a texel of margin; every texel still takes
  the exact edge tests) keeps the smallest biased depth ``z + constant + slope·m`` per texel
  (``glPolygonOffset(slope, ·)``). The result is a minimum, so it does not depend on the order
  in which triangles are drawn, nor on which other texels are rendered (:func:`_render_maps`
  renders a rectangle of each map: :mod:`blinn_phong.shadows.map_receiver_kernels`).
* :func:`corner_bounds` — the casters' per-axis extent, which the light's frustum is fitted to.

Agreement with the numpy reference: the per-texel arithmetic is the same sequence of IEEE
double operations, except that the reference transforms vertices with a BLAS matrix product
(whose summation order and fused multiply-adds vary between machines) where the kernels use
``((m0·x + m1·y) + m2·z) + m3``. Depths therefore agree to a few units in the last place
(tests/effects/test_shadow_kernels.py asserts ≤ 1e-12 where both cover a texel).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from blinn_phong._scratch import ScratchPool, carve, carved_bytes
from compositing._threads import in_shares

__all__ = ["corner_bounds", "cube_maps_compiled", "depth_map_compiled"]


#: Columns of a set-up triangle's record (one float64 row per drawn triangle): window x, y and
#: depth of its corners (unsnapped), the edge functions' a (3) and the snapped signed area, b,
#: c, the slope bias, the top-left flags (1.0 / 0.0) and the unsnapped signed area.
_SX, _SY, _SZ, _EA, _AREA, _EB, _EC, _BIAS, _ETL, _EXAREA, _NREC = 0, 3, 6, 9, 12, 13, 16, 19, 20, 23, 24


@numba.njit(cache=True)  # a call, not inlined: two call sites in _setup_range
def _snap_ndc(nx0, ny0, nz0, nx1, ny1, nz1, nx2, ny2, nz2, res, rec, box, s):  # pragma: no cover - compiled
    # normalised device corners (w > 0) of one (sub-)triangle; fills slot s; False when it draws nothing
    scale = 256.0
    half = 0.5 * res
    r = rec[s]
    xe0 = (nx0 + 1.0) * half
    xe1 = (nx1 + 1.0) * half
    xe2 = (nx2 + 1.0) * half
    ye0 = res - (ny0 + 1.0) * half
    ye1 = res - (ny1 + 1.0) * half
    ye2 = res - (ny2 + 1.0) * half
    r[_SX], r[_SX + 1], r[_SX + 2] = xe0, xe1, xe2
    r[_SY], r[_SY + 1], r[_SY + 2] = ye0, ye1, ye2
    r[_SZ] = (nz0 + 1.0) * 0.5
    r[_SZ + 1] = (nz1 + 1.0) * 0.5
    r[_SZ + 2] = (nz2 + 1.0) * 0.5
    x_0 = np.rint(xe0 * scale) / scale
    x_1 = np.rint(xe1 * scale) / scale
    x_2 = np.rint(xe2 * scale) / scale
    y_0 = res - np.rint((res - ye0) * scale) / scale
    y_1 = res - np.rint((res - ye1) * scale) / scale
    y_2 = res - np.rint((res - ye2) * scale) / scale
    area = (x_1 - x_0) * (y_2 - y_0) - (x_2 - x_0) * (y_1 - y_0)
    if area == 0:
        return False
    bx0 = max(np.ceil(min(x_0, x_1, x_2) - 0.5), 0.0)
    bx1 = min(np.floor(max(x_0, x_1, x_2) - 0.5), res - 1.0)
    by0 = max(np.ceil(min(y_0, y_1, y_2) - 0.5), 0.0)
    by1 = min(np.floor(max(y_0, y_1, y_2) - 0.5), res - 1.0)
    if not (bx0 <= bx1 and by0 <= by1):  # NaN-safe: no box, no integer cast
        return False
    box[s, 0] = int(bx0)
    box[s, 1] = int(bx1)
    box[s, 2] = int(by0)
    box[s, 3] = int(by1)
    sign = -1.0 if area < 0 else 1.0
    r[_AREA] = area
    # edge i runs from corner j = i + 1 to corner k = i + 2
    for i in range(3):
        if i == 0:
            xj, yj, xk, yk = x_1, y_1, x_2, y_2
        elif i == 1:
            xj, yj, xk, yk = x_2, y_2, x_0, y_0
        else:
            xj, yj, xk, yk = x_0, y_0, x_1, y_1
        a = -(yk - yj) * sign
        b = (xk - xj) * sign
        r[_EA + i] = a
        r[_EB + i] = b
        r[_EC + i] = ((yk - yj) * xj - (xk - xj) * yj) * sign
        r[_ETL + i] = 1.0 if (a > 0) or (a == 0 and b < 0) else 0.0
    r[_EXAREA] = (xe1 - xe0) * (ye2 - ye0) - (xe2 - xe0) * (ye1 - ye0)
    return True


@numba.njit(cache=True, inline="always")
def _overlaps(box, s, rect):  # pragma: no cover - compiled
    # the triangle's texel box meets the rectangle (r0, r1, c0, c1) of texels to render
    return box[s, 2] <= rect[1] and box[s, 3] >= rect[0] and box[s, 0] <= rect[3] and box[s, 1] >= rect[2]


@numba.njit(cache=True, inline="always")
def _clip_row(vp, ch, x, y, z):  # pragma: no cover - compiled
    return ((vp[ch, 0] * x + vp[ch, 1] * y) + vp[ch, 2] * z) + vp[ch, 3]


@numba.njit(cache=True)
def _setup_range(world, t0, t1, vp, res, slope_bias, rect, rec, box, base):  # pragma: no cover - compiled
    # triangles t0..t1-1 into slots base, base+1, ... (at most two a triangle: near clipping);
    # only triangles whose texel box meets ``rect`` are kept. Returns the number of slots filled.
    c = np.empty((3, 4))
    cv = np.empty((3, 4))
    w = np.zeros((5, 3))
    k = base
    for t in range(t0, t1):
        v = world[t]
        x0c = _clip_row(vp, 0, v[0, 0], v[0, 1], v[0, 2])
        x1c = _clip_row(vp, 0, v[1, 0], v[1, 1], v[1, 2])
        x2c = _clip_row(vp, 0, v[2, 0], v[2, 1], v[2, 2])
        w0c = _clip_row(vp, 3, v[0, 0], v[0, 1], v[0, 2])
        w1c = _clip_row(vp, 3, v[1, 0], v[1, 1], v[1, 2])
        w2c = _clip_row(vp, 3, v[2, 0], v[2, 1], v[2, 2])
        # trivially outside one side of the light's frustum: nothing to draw
        if (x0c > w0c and x1c > w1c and x2c > w2c) or (x0c < -w0c and x1c < -w1c and x2c < -w2c):
            continue
        y0c = _clip_row(vp, 1, v[0, 0], v[0, 1], v[0, 2])
        y1c = _clip_row(vp, 1, v[1, 0], v[1, 1], v[1, 2])
        y2c = _clip_row(vp, 1, v[2, 0], v[2, 1], v[2, 2])
        if (y0c > w0c and y1c > w1c and y2c > w2c) or (y0c < -w0c and y1c < -w1c and y2c < -w2c):
            continue
        z0c = _clip_row(vp, 2, v[0, 0], v[0, 1], v[0, 2])
        z1c = _clip_row(vp, 2, v[1, 0], v[1, 1], v[1, 2])
        z2c = _clip_row(vp, 2, v[2, 0], v[2, 1], v[2, 2])
        # near clipping, as raster._clip_near; the depth slope is computed below, only for a
        # triangle that draws something in the rectangle
        d0 = z0c + w0c
        d1 = z1c + w1c
        d2 = z2c + w2c
        inside0, inside1, inside2 = d0 >= 0, d1 >= 0, d2 >= 0
        n_in = int(inside0) + int(inside1) + int(inside2)
        first = k
        # the corners' normalised device coordinates, shared by the set-up and the depth slope
        all_w = w0c > 0 and w1c > 0 and w2c > 0
        nx0 = ny0 = nz0 = nx1 = ny1 = nz1 = nx2 = ny2 = nz2 = 0.0
        if all_w:
            nx0, ny0, nz0 = x0c / w0c, y0c / w0c, z0c / w0c
            nx1, ny1, nz1 = x1c / w1c, y1c / w1c, z1c / w1c
            nx2, ny2, nz2 = x2c / w2c, y2c / w2c, z2c / w2c
        if n_in == 3:
            if all_w and _snap_ndc(nx0, ny0, nz0, nx1, ny1, nz1, nx2, ny2, nz2, res, rec, box, k):
                if _overlaps(box, k, rect):
                    k += 1
        elif n_in > 0:
            c[0, 0], c[0, 1], c[0, 2], c[0, 3] = x0c, y0c, z0c, w0c
            c[1, 0], c[1, 1], c[1, 2], c[1, 3] = x1c, y1c, z1c, w1c
            c[2, 0], c[2, 1], c[2, 2], c[2, 3] = x2c, y2c, z2c, w2c
            lone_inside = n_in == 1
            ins = (inside0, inside1, inside2)
            odd = 0
            for j in range(3):
                if ins[j] == lone_inside:
                    odd = j
                    break
            ia, ib, ic = odd, (odd + 1) % 3, (odd + 2) % 3
            dd = (d0, d1, d2)
            t_ab = dd[ia] / (dd[ia] - dd[ib])
            t_ac = dd[ia] / (dd[ia] - dd[ic])
            # weights of the sub-triangles' corners on the source corners (rows), as _clip_near
            w[:] = 0.0  # rows: a, b, c, ab, ac
            w[0, ia] = 1.0
            w[1, ib] = 1.0
            w[2, ic] = 1.0
            for m in range(3):
                w[3, m] = w[0, m] + t_ab * (w[1, m] - w[0, m])
                w[4, m] = w[0, m] + t_ac * (w[2, m] - w[0, m])
            if lone_inside:
                corners = ((0, 3, 4), (0, 3, 4))
                count = 1
            else:
                corners = ((3, 1, 2), (3, 2, 4))
                count = 2
            for q in range(count):
                for j in range(3):
                    r = corners[q][j]
                    for ch in range(4):
                        cv[j, ch] = w[r, 0] * c[0, ch] + w[r, 1] * c[1, ch] + w[r, 2] * c[2, ch]
                w0, w1, w2 = cv[0, 3], cv[1, 3], cv[2, 3]
                if not (w0 > 0 and w1 > 0 and w2 > 0):
                    continue
                drawn = _snap_ndc(
                    cv[0, 0] / w0, cv[0, 1] / w0, cv[0, 2] / w0, cv[1, 0] / w1, cv[1, 1] / w1, cv[1, 2] / w1,
                    cv[2, 0] / w2, cv[2, 1] / w2, cv[2, 2] / w2, res, rec, box, k,
                )  # fmt: skip
                if drawn and _overlaps(box, k, rect):
                    k += 1
        if k == first:
            continue
        # depth slope of the unclipped triangle in window units (GL 2.1 §3.5.5)
        slope = 0.0
        if all_w:
            xw0 = (nx0 + 1) * 0.5 * res
            yw0 = (ny0 + 1) * 0.5 * res
            zw0 = (nz0 + 1) * 0.5
            xw1 = (nx1 + 1) * 0.5 * res
            yw1 = (ny1 + 1) * 0.5 * res
            zw1 = (nz1 + 1) * 0.5
            xw2 = (nx2 + 1) * 0.5 * res
            yw2 = (ny2 + 1) * 0.5 * res
            zw2 = (nz2 + 1) * 0.5
            e1x, e1y, e1z = xw1 - xw0, yw1 - yw0, zw1 - zw0
            e2x, e2y, e2z = xw2 - xw0, yw2 - yw0, zw2 - zw0
            det = e1x * e2y - e2x * e1y
            if det != 0:
                slope = max(abs((e1z * e2y - e2z * e1y) / det), abs((e1x * e2z - e2x * e1z) / det))
        b = slope_bias * slope
        for s in range(first, k):
            rec[s, _BIAS] = b
    return k - base


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _setup_tasks(
    share, world, vps, rects, res, slope_bias, n_chunks, workers, rec, box, filled
):  # pragma: no cover
    # every (face, chunk of triangles) is one task; chunk c of n fills the slots from 2·t0 on (a
    # triangle takes at most two), so the tasks write disjoint rows. Faces whose rectangle is
    # empty (r0 > r1) are skipped. Fills the records ``rec`` (F, 2n, _NREC) and the texel boxes
    # ``box`` (F, 2n, 4), and ``filled[f, chunk]`` the slots each task drew. The arrays come
    # from numpy, whose large allocations get transparent huge pages: a fresh 20 MB of 4 KiB
    # pages costs milliseconds of page faults.
    n_faces = vps.shape[0]
    n = world.shape[0]
    # worker w (of W = workers, the threads; ``share``: the workers of this call) takes the tasks
    # w, w + W, w + 2W, ... of face-major order: every W-th chunk of every face, so that each
    # thread gets a share of every part of the mesh list
    for w in share:
        for task in range(w, n_faces * n_chunks, workers):
            f = task // n_chunks
            ch = task % n_chunks
            if rects[f, 0] > rects[f, 1] or rects[f, 2] > rects[f, 3]:
                continue
            t0 = ch * n // n_chunks
            t1 = (ch + 1) * n // n_chunks
            filled[f, ch] = _setup_range(
                world, t0, t1, vps[f], res, slope_bias, rects[f], rec[f], box[f], 2 * t0
            )


def _slots(filled: np.ndarray, n: int, slots: np.ndarray) -> np.ndarray:
    """The slots drawn per face into ``slots`` (F, 2n; the first count[f] of row f), in chunk
    order: chunk ``ch`` of ``C`` filled ``filled[f, ch]`` slots from ``2·(ch·n // C)`` on.
    Returns count (F,)."""
    n_faces, n_chunks = filled.shape
    bases = 2 * (np.arange(n_chunks, dtype=np.int64) * n // n_chunks)
    count = filled.sum(axis=1)
    for f in range(n_faces):
        lengths = filled[f]
        # slot k of the face's list lies in chunk ch: bases[ch] + (k − the slots of chunks before ch)
        before = np.cumsum(lengths) - lengths
        slots[f, : count[f]] = np.repeat(bases - before, lengths) + np.arange(count[f])
    return count


def _setup(
    world: np.ndarray, vps: np.ndarray, rects: np.ndarray, res: float, slope_bias: float, n_chunks: int,
    workers: int, rec: np.ndarray, box: np.ndarray, slots: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """The triangles' records and texel boxes per face (:func:`_setup_tasks`, the workers on
    threads), then the slots each face draws (:func:`_slots`); returns count (F,)."""
    filled = np.zeros((vps.shape[0], n_chunks), np.int64)
    in_shares(_setup_tasks, workers, world, vps, rects, res, slope_bias, n_chunks, workers, rec, box, filled)
    return _slots(filled, world.shape[0], slots)


@numba.njit(cache=True)
def _scan_rows(depth, r0, r1, c0, c1, slots, constant_bias, rec, box):  # pragma: no cover - compiled
    # texels (r0..r1, c0..c1) (inclusive) of one map: fill with 1, then keep the smallest biased
    # depth; every texel's value is the one a scan of the whole map gives it (a minimum over the
    # same triangles, whatever the order)
    depth[r0 : r1 + 1, c0 : c1 + 1] = 1.0
    for q in range(slots.shape[0]):
        s = slots[q]
        lo = max(box[s, 2], r0)
        hi = min(box[s, 3], r1)
        if lo > hi:
            continue
        r = rec[s]
        sx0, sx1, sx2 = r[_SX], r[_SX + 1], r[_SX + 2]
        sy0, sy1, sy2 = r[_SY], r[_SY + 1], r[_SY + 2]
        sz0, sz1, sz2 = r[_SZ], r[_SZ + 1], r[_SZ + 2]
        a0, a1, a2 = r[_EA], r[_EA + 1], r[_EA + 2]
        b0, b1, b2 = r[_EB], r[_EB + 1], r[_EB + 2]
        k0, k1, k2 = r[_EC], r[_EC + 1], r[_EC + 2]
        tl0, tl1, tl2 = r[_ETL] != 0.0, r[_ETL + 1] != 0.0, r[_ETL + 2] != 0.0
        area = r[_AREA]
        ex_area = r[_EXAREA]
        exact = ex_area * area > 0 and abs(ex_area) > 1e-12
        abs_area = abs(area)
        b = r[_BIAS]
        bx0 = float(max(box[s, 0], c0))
        bx1 = float(min(box[s, 1], c1))
        # reciprocals of the edges' a (|a| ≥ 1/256 or 0: snapped coordinates): the row spans
        # below multiply instead of dividing, a few ulp off, well inside their texel of margin
        i0 = 1.0 / a0 if a0 != 0 else 0.0
        i1 = 1.0 / a1 if a1 != 0 else 0.0
        i2 = 1.0 / a2 if a2 != 0 else 0.0
        for py in range(lo, hi + 1):
            cy = py + 0.5
            # the row's span: each edge function is linear in x, so its sign changes once; the
            # span is widened by a texel on each side and every texel in it still takes the
            # exact tests below, so the covered texels are those of the whole bounding box
            x_lo, x_hi = bx0, bx1
            empty = False
            for i in range(3):
                if i == 0:
                    a, inv, k, tl = a0, i0, b0 * cy + k0, tl0
                elif i == 1:
                    a, inv, k, tl = a1, i1, b1 * cy + k1, tl1
                else:
                    a, inv, k, tl = a2, i2, b2 * cy + k2, tl2
                if a > 0:
                    x_lo = max(x_lo, math.ceil(-k * inv - 0.5) - 1.0)
                elif a < 0:
                    x_hi = min(x_hi, math.floor(-k * inv - 0.5) + 1.0)
                elif k < 0 or (k == 0 and not tl):
                    empty = True
            if empty or not x_lo <= x_hi:
                continue
            row0 = b0 * cy + k0
            row1 = b1 * cy + k1
            row2 = b2 * cy + k2
            for px in range(int(x_lo), int(x_hi) + 1):
                cx = px + 0.5
                e0 = a0 * cx + row0
                if e0 < 0 or (e0 == 0 and not tl0):
                    continue
                e1 = a1 * cx + row1
                if e1 < 0 or (e1 == 0 and not tl1):
                    continue
                e2 = a2 * cx + row2
                if e2 < 0 or (e2 == 0 and not tl2):
                    continue
                if exact:
                    l0 = ((sx2 - sx1) * (cy - sy1) - (sy2 - sy1) * (cx - sx1)) / ex_area
                    l1 = ((sx0 - sx2) * (cy - sy2) - (sy0 - sy2) * (cx - sx2)) / ex_area
                    l2 = ((sx1 - sx0) * (cy - sy0) - (sy1 - sy0) * (cx - sx0)) / ex_area
                else:
                    l0 = e0 / abs_area
                    l1 = e1 / abs_area
                    l2 = e2 / abs_area
                z = l0 * sz0 + l1 * sz1 + l2 * sz2
                if z > 1.0:
                    continue
                z = max(z, 0.0)
                biased = z + constant_bias + b
                if biased < depth[py, px]:
                    depth[py, px] = biased


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _scan_tasks(
    share, out, rects, n_bands, workers, slots, count, constant_bias, rec, box
):  # pragma: no cover
    # every (face, band of the face's rows) is one task; worker w takes the tasks w, w + W, ...
    # of face-major order, i.e. every W-th band of every face: the work of a map is far from
    # uniform over its rows (a sphere in a few bands), and neighbouring bands hold similar
    # work. Faces with an empty rectangle are left unwritten.
    n_faces = out.shape[0]
    for w in share:
        for task in range(w, n_faces * n_bands, workers):
            f = task // n_bands
            band = task % n_bands
            r_lo, r_hi, c0, c1 = rects[f, 0], rects[f, 1], rects[f, 2], rects[f, 3]
            if r_lo > r_hi or c0 > c1:
                continue
            band_h = (r_hi - r_lo + n_bands) // n_bands
            r0 = r_lo + band * band_h
            r1 = min(r_hi, r0 + band_h - 1)
            if r0 <= r1:
                _scan_rows(out[f], r0, r1, c0, c1, slots[f, : count[f]], constant_bias, rec[f], box[f])


def _render_maps(
    world: np.ndarray,
    vps: np.ndarray,
    rects: np.ndarray,
    constant_bias: float,
    slope_bias: float,
    out: np.ndarray,
) -> np.ndarray:
    """Depth maps of the casters seen by F cameras, each only over its rectangle of texels.

    ``world``: (n, 3, 3) contiguous float64; ``vps``: (F, 4, 4); ``rects``: (F, 4) int64 texel
    rectangles ``(r0, r1, c0, c1)`` (inclusive; r0 > r1 or c0 > c1: the face is not rendered);
    ``out``: (F, R, R) float64. Texels outside a face's rectangle are left as they were.
    """
    res = out.shape[1]
    threads = numba.get_num_threads()
    n_chunks = max(1, min(len(world), 4 * threads))
    shape = (len(vps), 2 * len(world))
    parts = (((*shape, _NREC), np.float64), ((*shape, 4), np.int32), (shape, np.int64))
    # the records of a slot per (face, triangle) are mostly never written: kept between frames
    with _SETUP_SCRATCH.bytes(carved_bytes(*parts)) as buf:
        rec, box, slots = carve(buf, *parts)
        count = _setup(world, vps, rects, float(res), float(slope_bias), n_chunks, threads, rec, box, slots)
        n_bands = max(1, min(res, 4 * threads))
        in_shares(
            _scan_tasks, threads, out, rects, n_bands, threads, slots, count, float(constant_bias), rec, box
        )
    return out


#: Scratch of :func:`_render_maps`' set-up (records, texel boxes, slots), reused by the next
#: maps: up to 1 GiB (a cube of 2.6M casters) is kept.
_SETUP_SCRATCH = ScratchPool(1 << 30)


def cube_maps_compiled(
    world_triangles: np.ndarray,
    view_projections: np.ndarray,
    constant_bias: float,
    slope_bias: float,
    out: np.ndarray,
) -> np.ndarray:
    """:func:`depth_map_compiled` for several cameras at once (a cube's six faces).

    The triangle set-up runs in parallel over (face, chunk of triangles) tasks; then every
    (face, band of rows) pair is one task of a parallel scan, so that a face holding most of
    the work is shared by every thread.

    Args:
        world_triangles: (n, 3, 3) float64 world-space casters.
        view_projections: (F, 4, 4) world → clip matrices.
        constant_bias: window-depth units added to every fragment.
        slope_bias: multiple of the triangle's depth slope per texel added.
        out: C-contiguous (F, R, R) float64 array, written and returned.

    Returns:
        ``out``, each face as :func:`depth_map_compiled` makes it.
    """
    world = np.ascontiguousarray(world_triangles, dtype=np.float64).reshape(-1, 3, 3)
    if len(world) == 0:
        out[:] = 1.0
        return out
    vps = np.ascontiguousarray(view_projections, dtype=np.float64)
    return _render_maps(world, vps, _full_rects(len(vps), out.shape[1]), constant_bias, slope_bias, out)


def _full_rects(n_faces: int, res: int) -> np.ndarray:
    """(F, 4) rectangles ``(0, R − 1, 0, R − 1)``: every texel of every face."""
    rects = np.empty((n_faces, 4), np.int64)
    rects[:, 0::2] = 0
    rects[:, 1::2] = res - 1
    return rects


def depth_map_compiled(
    world_triangles: np.ndarray,
    view_projection: np.ndarray,
    resolution: int,
    constant_bias: float,
    slope_bias: float,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Biased nearest window depth per texel of world-space triangles seen by a light camera.

    Args:
        world_triangles: (n, 3, 3) float64 world-space casters.
        view_projection: 4×4 world → clip matrix of the light camera (``P·V``).
        resolution: texels per side of the square map.
        constant_bias: window-depth units added to every fragment.
        slope_bias: multiple of the triangle's depth slope per texel added.
        out: optional C-contiguous (resolution, resolution) float64 array to write into.

    Returns:
        (resolution, resolution) float64 map, row 0 at the top, 1 where nothing was drawn —
        :func:`blinn_phong.shadows.maps.render_shadow_map`'s ``depth`` (same conventions).
    """
    res = int(resolution)
    world = np.ascontiguousarray(world_triangles, dtype=np.float64).reshape(-1, 3, 3)
    depth = np.empty((res, res)) if out is None else out
    if len(world) == 0:
        depth[:] = 1.0
        return depth
    vp = np.ascontiguousarray(view_projection, dtype=np.float64).reshape(1, 4, 4)
    _render_maps(world, vp, _full_rects(1, res), constant_bias, slope_bias, depth.reshape(1, res, res))
    return depth


@numba.njit(cache=True)
def corner_bounds(world_triangles):  # pragma: no cover - compiled
    """(lo, hi): per-axis minimum and maximum of the (n, 3, 3) corners (exact, as ``min``/``max``)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for t in range(world_triangles.shape[0]):
        for j in range(3):
            for ch in range(3):
                v = world_triangles[t, j, ch]
                if v < lo[ch]:
                    lo[ch] = v
                if v > hi[ch]:
                    hi[ch] = v
    return lo, hi
