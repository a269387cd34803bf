"""Compiled (numba) shadow kernels: the twins of :mod:`blinn_phong.shadows.visibility` and of the ray set-up
of :mod:`blinn_phong.shadows.raytrace`.

:func:`blinn_phong.shadows.visibility.render_shadow_map` and
:func:`blinn_phong.shadows.visibility.shadow_visibility`
written with numpy are the reference; this module runs the same formulas in compiled loops
that never build an array of all fragments:

* :func:`depth_map_compiled` / :func:`cube_maps_compiled` — per (map, chunk of triangles)
  in parallel: near-plane clipping (``z_c ≥ −w_c``, new vertices interpolated in clip space,
  §2.12 of OpenGL 2.1), the viewport transform, snapping to 1/256 texel, edge functions and
  the top-left fill rule of :mod:`blinn_phong.geometry.raster`, and for a triangle that draws
  something its depth slope ``m = max(|∂z/∂x|, |∂z/∂y|)`` in texel units (the unclipped
  triangle, §3.5.5), each drawn triangle one float64 record; then per (map, band of rows) in
  parallel, every thread taking every other band of every map, the scan conversion (each row
  only over the span its three edge functions allow, plus a texel of margin; every texel
  still takes the exact edge tests) keeps the smallest biased depth ``z + constant + slope·m``
  per texel (``glPolygonOffset(slope, ·)``). The result is a minimum, so it does not depend
  on the order in which triangles are drawn, nor on which other texels are rendered.
* :func:`lookup_compiled` — per receiver point (in parallel): normal offset (Holbert 2011),
  projection into the light's clip space, the cube face of the major axis for point
  lights (OpenGL 4.6 §8.13, table 8.19), and the percentage-closer filter (Reeves, Salesin
  & Cook 1987) of :data:`blinn_phong.shadows.visibility.PCF_KERNELS`. The per-point body is
  :func:`visibility_at`, an ``njit`` function a compiled shading kernel can call directly
  (the nearest tap without normal offset runs the same operations in blocks of points).
* :func:`receiver_visibility_compiled` — the maps and the look-up of one light in one call,
  for the frame pipeline: a cube face no receiver uses is not rendered, the others only over
  a rectangle holding every texel the receivers' taps read; the visibilities are those of
  the complete maps, bit for bit.
* :func:`fragment_surface` — per visible fragment (in parallel): its world-space point (the
  perspective-correct barycentrics of the rasterizer applied to the world-space corners,
  ``Σ_k b_k·v_k`` — an affine map commutes with the barycentric sum, so this is the eye-space
  point mapped back to world space) and its triangle's world face normal, written into
  preallocated contiguous arrays, so the look-ups and the ray set-up read them without copies.
* :func:`hard_shadow_rays` — per receiver point (in parallel): the float32 origin, unit
  direction and ``t_max`` of its shadow ray, as ``raytrace._hard_rays_numpy`` computes them
  (offset scaled with the point's distance from the scene centre), so that Embree gets
  one batch per light and no numpy temporaries are built around it.

Agreement with the numpy reference: the per-texel arithmetic is the same sequence of IEEE
double operations, except that the reference transforms vertices and points with a BLAS
matrix product (whose summation order and fused multiply-adds vary between machines) where
the kernels use ``((m0·x + m1·y) + m2·z) + m3``. Depths therefore agree to a few units in
the last place (tests/effects/test_shadow_kernels.py asserts ≤ 1e-12 where both cover a
texel), and a visibility can differ only where a receiver's depth lies within that of a
stored depth, or a snapped vertex sits on a rounding boundary.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np

from blinn_phong._scratch import ScratchPool, carve, carved_bytes
from compositing._threads import in_shares

__all__ = [
    "area_light_rays",
    "corner_bounds",
    "cube_maps_compiled",
    "depth_map_compiled",
    "fragment_surface",
    "hard_shadow_rays",
    "lookup_compiled",
    "receiver_visibility_compiled",
    "visibility_at",
]

#: PCF kernel codes shared with :mod:`blinn_phong.shadows.visibility` (index into its PCF_KERNELS).
KERNEL_CODES = {"nearest": 0, "bilinear": 1, "box3": 3, "box5": 5, "box7": 7}


def _threads() -> int:
    return max(1, int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1)))


#: Columns of a set-up triangle's record (one float64 row per drawn triangle): window x, y and
#: depth of its corners (unsnapped), the edge functions' a (3) and the snapped signed area, b,
#: c, the slope bias, the top-left flags (1.0 / 0.0) and the unsnapped signed area.
_SX, _SY, _SZ, _EA, _AREA, _EB, _EC, _BIAS, _ETL, _EXAREA, _NREC = 0, 3, 6, 9, 12, 13, 16, 19, 20, 23, 24


@numba.njit(cache=True, inline="always")
def _snap_setup(
    x0c, y0c, z0c, w0c, x1c, y1c, z1c, w1c, x2c, y2c, z2c, w2c, res, rec, box, s
):  # pragma: no cover - compiled
    # clip corners of one (sub-)triangle (scalars); fills slot s; False when it draws nothing
    if not (w0c > 0 and w1c > 0 and w2c > 0):
        return False
    return _snap_ndc(
        x0c / w0c, y0c / w0c, z0c / w0c, x1c / w1c, y1c / w1c, z1c / w1c,
        x2c / w2c, y2c / w2c, z2c / w2c, res, rec, box, s,
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
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
                drawn = _snap_setup(
                    cv[0, 0], cv[0, 1], cv[0, 2], cv[0, 3], cv[1, 0], cv[1, 1], cv[1, 2], cv[1, 3],
                    cv[2, 0], cv[2, 1], cv[2, 2], cv[2, 3], res, rec, box, k,
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


@numba.njit(cache=True)
def _slots(filled, n, slots):  # pragma: no cover - compiled
    # the slots drawn per face ``slots`` (F, 2n; the first count[f] of row f), in chunk order;
    # returns count (F,)
    n_faces, n_chunks = filled.shape
    count = np.zeros(n_faces, np.int64)
    for f in range(n_faces):
        k = 0
        for ch in range(n_chunks):
            base = 2 * (ch * n // n_chunks)
            for s in range(base, base + filled[f, ch]):
                slots[f, k] = s
                k += 1
        count[f] = k
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
        :func:`blinn_phong.shadows.visibility.render_shadow_map`'s ``depth`` (same conventions).
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


@numba.njit(cache=True, inline="always")
def _lit(depth, f, col, row, z, res_x, res_y):  # pragma: no cover - compiled
    c = min(max(col, 0.0), res_x - 1.0)
    r = min(max(row, 0.0), res_y - 1.0)
    return 1.0 if z <= depth[f, int(r), int(c)] else 0.0


@numba.njit(cache=True, inline="always")
def _cube_face(px, py, pz, light_pos):  # pragma: no cover - compiled
    # cube face of the major axis of p − light (ties to the lower axis, as np.argmax); −1 at the light
    rx, ry, rz = px - light_pos[0], py - light_pos[1], pz - light_pos[2]
    ax, best, val = 0, abs(rx), rx
    if abs(ry) > best:
        ax, best, val = 1, abs(ry), ry
    if abs(rz) > best:
        ax, best, val = 2, abs(rz), rz
    if val == 0:
        return -1
    return 2 * ax + (0 if val > 0 else 1)


@numba.njit(cache=True, inline="always")
def _window(nxd, nyd, nzd, res_x, res_y):  # pragma: no cover - compiled
    # (x, y, z, found) from normalised device coordinates (w > 0): texel coordinates (x right,
    # y down from the top) and window depth; found is False outside the map (lit)
    z = (nzd + 1) * 0.5
    if not (nxd >= -1 and nxd <= 1 and nyd >= -1 and nyd <= 1 and z <= 1):  # outside (or NaN): lit
        return 0.0, 0.0, 0.0, False
    x = (nxd + 1) * 0.5 * res_x
    y = res_y - (nyd + 1) * 0.5 * res_y
    return x, y, z, True


@numba.njit(cache=True, inline="always")
def _locate(
    px, py, pz, nx, ny, nz, vp, view_z, face_mode, light_pos, normal_offset, res_x, res_y, base=0
):  # pragma: no cover - compiled
    # (face, x, y, z, found): the texel coordinates (x right, y down from the top) and window
    # depth of a receiver in its map; found is False where the map is not read (lit). The
    # light's maps are base, base + 1, … of the stack (vp, view_z, and the returned face).
    f = base
    if face_mode == 1:  # cube: face of the major axis
        f = _cube_face(px, py, pz, light_pos)
        if f < 0:
            return 0, 0.0, 0.0, 0.0, False
        f += base
    if normal_offset != 0.0:
        length = max(math.sqrt(nx * nx + ny * ny + nz * nz), 1e-300)
        nx, ny, nz = nx / length, ny / length, nz / length
        if nx * view_z[f, 0] + ny * view_z[f, 1] + nz * view_z[f, 2] < 0:
            nx, ny, nz = -nx, -ny, -nz
        px, py, pz = px + normal_offset * nx, py + normal_offset * ny, pz + normal_offset * nz
    m = vp[f]
    cx = ((m[0, 0] * px + m[0, 1] * py) + m[0, 2] * pz) + m[0, 3]
    cy = ((m[1, 0] * px + m[1, 1] * py) + m[1, 2] * pz) + m[1, 3]
    cz = ((m[2, 0] * px + m[2, 1] * py) + m[2, 2] * pz) + m[2, 3]
    cw = ((m[3, 0] * px + m[3, 1] * py) + m[3, 2] * pz) + m[3, 3]
    if not cw > 0:
        return f, 0.0, 0.0, 0.0, False
    x, y, z, found = _window(cx / cw, cy / cw, cz / cw, res_x, res_y)
    return f, x, y, z, found


@numba.njit(cache=True, inline="always")
def _filtered(depth, f, x, y, z, kernel, res_x, res_y):  # pragma: no cover - compiled
    # the percentage-closer filter of ``kernel`` at texel coordinates (x, y), receiver depth z
    if kernel == 0:
        return _lit(depth, f, math.floor(x), math.floor(y), z, res_x, res_y)
    if kernel == 1:
        fx, fy = x - 0.5, y - 0.5
        x0, y0 = math.floor(fx), math.floor(fy)
        tx, ty = fx - x0, fy - y0
        l00 = _lit(depth, f, x0, y0, z, res_x, res_y)
        l10 = _lit(depth, f, x0 + 1, y0, z, res_x, res_y)
        l01 = _lit(depth, f, x0, y0 + 1, z, res_x, res_y)
        l11 = _lit(depth, f, x0 + 1, y0 + 1, z, res_x, res_y)
        top = l00 + tx * (l10 - l00)
        bottom = l01 + tx * (l11 - l01)
        return top + ty * (bottom - top)
    h = (kernel - 1) // 2
    col, row = math.floor(x), math.floor(y)
    total = 0.0
    for oy in range(-h, h + 1):
        for ox in range(-h, h + 1):
            total += _lit(depth, f, col + ox, row + oy, z, res_x, res_y)
    return total / (kernel * kernel)


@numba.njit(cache=True, inline="always")  # inlined: a call per point costs more than its body
def visibility_at(
    px, py, pz, nx, ny, nz, depth, vp, view_z, face_mode, light_pos, normal_offset, kernel
):  # pragma: no cover - compiled
    """Shadow-map visibility of one world point (compiled; callable from other numba kernels).

    ``(px, py, pz)``: world point; ``(nx, ny, nz)``: its normal (read only when
    ``normal_offset`` ≠ 0); ``depth``: (F, H, W) maps; ``vp``: (F, 4, 4) world → clip;
    ``view_z``: (F, 3) row 2 of each view matrix (towards-the-light test of the normal
    offset); ``face_mode``: 1 for a cube (F = 6, face of the major axis of ``p − light_pos``),
    else 0; ``kernel``: 0 nearest, 1 bilinear, k for a k×k box. Returns a float in [0, 1]:
    the formulas of :func:`blinn_phong.shadows.visibility.shadow_visibility`.
    """
    res_y = float(depth.shape[1])
    res_x = float(depth.shape[2])
    f, x, y, z, found = _locate(
        px, py, pz, nx, ny, nz, vp, view_z, face_mode, light_pos, normal_offset, res_x, res_y
    )
    if not found:
        return 1.0
    return _filtered(depth, f, x, y, z, kernel, res_x, res_y)


@numba.njit(cache=True)  # a call, not inlined: keeps the fused shading kernel's compilation short
def stacked_visibility(
    px, py, pz, nx, ny, nz, depth, vp, view_z, base, face_mode, light_pos, normal_offset, kernel, rects, miss
):  # pragma: no cover - compiled
    """:func:`visibility_at` of one light whose maps are ``base, base + 1, …`` (1, or 6 cube
    faces) of a stack of several lights' maps (``depth`` (F, H, W), ``vp`` (F, 4, 4),
    ``view_z`` (F, 3)): the same operations on the same operands, so the same value.
    ``rects`` (F, 4): each map's rendered texels ``(r0, r1, c0, c1)``; a look-up whose taps
    leave them sets ``miss[0] = 1`` (its value is then not to be used)."""
    res_y = float(depth.shape[1])
    res_x = float(depth.shape[2])
    f, x, y, z, found = _locate(
        px, py, pz, nx, ny, nz, vp, view_z, face_mode, light_pos, normal_offset, res_x, res_y, base
    )
    if not found:
        return 1.0
    if not _taps_inside(rects, f, x, y, kernel, res_x, res_y):
        miss[0] = 1
    return _filtered(depth, f, x, y, z, kernel, res_x, res_y)


@numba.njit(cache=True, inline="always")
def _taps_inside(rects, f, x, y, kernel, res_x, res_y):  # pragma: no cover - compiled
    # whether every texel the taps of ``kernel`` at (x, y) read (clamped to the map, as _lit
    # clamps) lies in rects[f] = (r0, r1, c0, c1)
    if kernel == 1:
        c_lo, r_lo = math.floor(x - 0.5), math.floor(y - 0.5)
        c_hi, r_hi = c_lo + 1, r_lo + 1
    else:
        h = 0 if kernel == 0 else (kernel - 1) // 2
        c_lo, r_lo = math.floor(x) - h, math.floor(y) - h
        c_hi, r_hi = math.floor(x) + h, math.floor(y) + h
    c_lo = min(max(c_lo, 0.0), res_x - 1.0)
    c_hi = min(max(c_hi, 0.0), res_x - 1.0)
    r_lo = min(max(r_lo, 0.0), res_y - 1.0)
    r_hi = min(max(r_hi, 0.0), res_y - 1.0)
    return rects[f, 0] <= r_lo and r_hi <= rects[f, 1] and rects[f, 2] <= c_lo and c_hi <= rects[f, 3]


@numba.njit(parallel=True, cache=True)
def _receiver_rects(
    points, normals, n_faces, res, vp, view_z, face_mode, light_pos, normal_offset, kernel, n_chunks, faces
):  # pragma: no cover - compiled
    # per face, a rectangle (r0, r1, c0, c1) holding every texel the look-ups of the points read
    # (r0 > r1: none). The face and the normal offset are chosen as visibility_at chooses them
    # (exactly: a point must be counted in its own face); the projection is then bounded from
    # outside: one reciprocal instead of three divisions (a few ulp off), no depth test, the
    # frustum test widened by 1e-9, and two texels of margin beyond the taps' reach, so the
    # rectangle can only be larger than the exact one. Per chunk of points in parallel: the
    # extreme normalised coordinates per face, merged and turned into texels at the end. Each
    # point's cube face (−1: none) is written to ``faces`` (int8) for the look-up.
    n = points.shape[0]
    with_normals = normal_offset != 0.0
    part = np.empty((n_chunks, n_faces, 4))  # min x, max x, min y, max y (normalised device)
    lim = 1.0 + 1e-9
    for ch in numba.prange(n_chunks):
        for f in range(n_faces):
            part[ch, f, 0] = np.inf
            part[ch, f, 1] = -np.inf
            part[ch, f, 2] = np.inf
            part[ch, f, 3] = -np.inf
        # the current face's extremes and matrix rows in registers; points come in runs of one
        # face, so they are stored and reloaded only where the face changes
        cur = 0
        x_lo, x_hi, y_lo, y_hi = np.inf, -np.inf, np.inf, -np.inf
        m00, m01, m02, m03 = vp[0, 0, 0], vp[0, 0, 1], vp[0, 0, 2], vp[0, 0, 3]
        m10, m11, m12, m13 = vp[0, 1, 0], vp[0, 1, 1], vp[0, 1, 2], vp[0, 1, 3]
        m30, m31, m32, m33 = vp[0, 3, 0], vp[0, 3, 1], vp[0, 3, 2], vp[0, 3, 3]
        for i in range(ch * n // n_chunks, (ch + 1) * n // n_chunks):
            px, py, pz = points[i, 0], points[i, 1], points[i, 2]
            f = 0
            if face_mode == 1:  # as _locate
                f = _cube_face(px, py, pz, light_pos)
                faces[i] = f
                if f < 0:
                    continue
            if f != cur:
                part[ch, cur, 0], part[ch, cur, 1] = x_lo, x_hi
                part[ch, cur, 2], part[ch, cur, 3] = y_lo, y_hi
                cur = f
                x_lo, x_hi, y_lo, y_hi = part[ch, f, 0], part[ch, f, 1], part[ch, f, 2], part[ch, f, 3]
                m00, m01, m02, m03 = vp[f, 0, 0], vp[f, 0, 1], vp[f, 0, 2], vp[f, 0, 3]
                m10, m11, m12, m13 = vp[f, 1, 0], vp[f, 1, 1], vp[f, 1, 2], vp[f, 1, 3]
                m30, m31, m32, m33 = vp[f, 3, 0], vp[f, 3, 1], vp[f, 3, 2], vp[f, 3, 3]
            if with_normals:  # as _locate
                nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
                length = max(math.sqrt(nx * nx + ny * ny + nz * nz), 1e-300)
                nx, ny, nz = nx / length, ny / length, nz / length
                if nx * view_z[f, 0] + ny * view_z[f, 1] + nz * view_z[f, 2] < 0:
                    nx, ny, nz = -nx, -ny, -nz
                px, py, pz = px + normal_offset * nx, py + normal_offset * ny, pz + normal_offset * nz
            cw = ((m30 * px + m31 * py) + m32 * pz) + m33
            if not cw > 0:
                continue
            inv = 1.0 / cw
            nxd = (((m00 * px + m01 * py) + m02 * pz) + m03) * inv
            nyd = (((m10 * px + m11 * py) + m12 * pz) + m13) * inv
            if not (nxd >= -lim and nxd <= lim and nyd >= -lim and nyd <= lim):
                continue
            x_lo = min(x_lo, nxd)
            x_hi = max(x_hi, nxd)
            y_lo = min(y_lo, nyd)
            y_hi = max(y_hi, nyd)
        part[ch, cur, 0], part[ch, cur, 1] = x_lo, x_hi
        part[ch, cur, 2], part[ch, cur, 3] = y_lo, y_hi
    return _rects_from_extremes(part, res, kernel)


@numba.njit(cache=True)
def _rects_from_extremes(part, res, kernel):  # pragma: no cover - compiled
    # (F, 4) texel rectangles (r0, r1, c0, c1) from per-chunk extremes part[ch, f] = (min x,
    # max x, min y, max y) of normalised device coordinates, merged over the chunks, clamped to
    # the map and widened by two texels beyond the taps' reach (r0 > r1: the face is not read)
    n_chunks, n_faces = part.shape[0], part.shape[1]
    reach = 2 + (0 if kernel <= 1 else (kernel - 1) // 2)  # texels beyond floor(x) a tap may read
    rects = np.empty((n_faces, 4), np.int64)
    for f in range(n_faces):  # merged over the chunks
        ax_lo, ax_hi, ay_lo, ay_hi = np.inf, -np.inf, np.inf, -np.inf
        for ch in range(n_chunks):
            ax_lo = min(ax_lo, part[ch, f, 0])
            ax_hi = max(ax_hi, part[ch, f, 1])
            ay_lo = min(ay_lo, part[ch, f, 2])
            ay_hi = max(ay_hi, part[ch, f, 3])
        if not ax_lo <= ax_hi:
            rects[f, 0], rects[f, 1], rects[f, 2], rects[f, 3] = res, -1, res, -1
            continue
        ax_lo, ax_hi = max(ax_lo, -1.0), min(ax_hi, 1.0)
        ay_lo, ay_hi = max(ay_lo, -1.0), min(ay_hi, 1.0)
        # columns from x = (nx + 1)·R/2, rows from y = R − (ny + 1)·R/2 (rows grow as ny falls)
        c0 = math.floor((ax_lo + 1) * 0.5 * res) - reach
        c1 = math.floor((ax_hi + 1) * 0.5 * res) + reach
        r0 = math.floor(res - (ay_hi + 1) * 0.5 * res) - reach
        r1 = math.floor(res - (ay_lo + 1) * 0.5 * res) + reach
        rects[f, 0] = max(r0, 0)
        rects[f, 1] = min(r1, res - 1)
        rects[f, 2] = max(c0, 0)
        rects[f, 3] = min(c1, res - 1)
    return rects


@numba.njit(cache=True, inline="always")
def _extend(part, f, vp, x, y, z, floor_w):  # pragma: no cover - compiled
    # widen face f's extremes by the projection of world point (x, y, z); False where its clip
    # w is below floor_w (too near the light's plane for a bounded projection)
    cw = ((vp[f, 3, 0] * x + vp[f, 3, 1] * y) + vp[f, 3, 2] * z) + vp[f, 3, 3]
    if not cw > floor_w:
        return False
    nxd = (((vp[f, 0, 0] * x + vp[f, 0, 1] * y) + vp[f, 0, 2] * z) + vp[f, 0, 3]) / cw
    nyd = (((vp[f, 1, 0] * x + vp[f, 1, 1] * y) + vp[f, 1, 2] * z) + vp[f, 1, 3]) / cw
    part[0, f, 0] = min(part[0, f, 0], nxd)
    part[0, f, 1] = max(part[0, f, 1], nxd)
    part[0, f, 2] = min(part[0, f, 2], nyd)
    part[0, f, 3] = max(part[0, f, 3], nyd)
    return True


@numba.njit(cache=True)
def _triangle_rects(corners, vp, light_pos, res, kernel):  # pragma: no cover - compiled
    # Per cube face, a texel rectangle holding every texel a nearest or PCF look-up (no normal
    # offset) of any point of the (n, 3, 3) world triangles ``corners`` reads. Face f's cone
    # {d = p − light: s·d_a ≥ |d_b|, s·d_a ≥ |d_c|} (axis a, sign s) is convex, and a point
    # is looked up in face f only inside it (_cube_face). A triangle whose corners lie inside
    # one cone with a margin is wholly inside it; its points project (w > 0: a perspective map
    # keeps convexity) inside the triangle of its projected corners. Any other triangle is
    # clipped against each cone loosened by the margin (Sutherland–Hodgman) and the vertices
    # of what is left are projected. The margin (1e-9 of the triangle's extent from the
    # light) exceeds the rounding of a point interpolated on the triangle, so every point a
    # look-up assigns to face f is inside what was projected; a vertex with clip w at most
    # 1e-6 of that extent makes the face whole. The projected extremes go through
    # _rects_from_extremes (two texels of margin beyond the taps' reach).
    part = np.empty((1, 6, 4))
    for f in range(6):
        part[0, f, 0] = np.inf
        part[0, f, 1] = -np.inf
        part[0, f, 2] = np.inf
        part[0, f, 3] = -np.inf
    whole = np.zeros(6, np.bool_)
    lx, ly, lz = light_pos[0], light_pos[1], light_pos[2]
    poly = np.empty((16, 3))
    nxt = np.empty((16, 3))
    d = np.empty((3, 3))
    for t in range(corners.shape[0]):
        scale = 0.0
        for j in range(3):
            d[j, 0] = corners[t, j, 0] - lx
            d[j, 1] = corners[t, j, 1] - ly
            d[j, 2] = corners[t, j, 2] - lz
            scale = max(scale, abs(d[j, 0]), abs(d[j, 1]), abs(d[j, 2]))
        if not scale > 0:  # a degenerate triangle at the light: read nowhere (_cube_face: −1)
            continue
        eps = 1e-9 * scale
        floor_w = 1e-6 * scale
        # the face holding every corner with the margin, if one does
        inside = -1
        for f in range(6):
            a = f // 2
            sgn = 1.0 if f % 2 == 0 else -1.0
            b, c = (a + 1) % 3, (a + 2) % 3
            ok = True
            for j in range(3):
                major = sgn * d[j, a]
                if not (major - abs(d[j, b]) > eps and major - abs(d[j, c]) > eps):
                    ok = False
                    break
            if ok:
                inside = f
                break
        if inside >= 0:
            for j in range(3):
                if not _extend(
                    part, inside, vp, corners[t, j, 0], corners[t, j, 1], corners[t, j, 2], floor_w
                ):
                    whole[inside] = True
            continue
        for f in range(6):
            if whole[f]:
                continue
            a = f // 2
            sgn = 1.0 if f % 2 == 0 else -1.0
            b, c = (a + 1) % 3, (a + 2) % 3
            n = 3
            for j in range(3):
                poly[j, 0], poly[j, 1], poly[j, 2] = d[j, 0], d[j, 1], d[j, 2]
            for plane in range(4):  # s·d_a − σ·d_o + eps ≥ 0, o ∈ {b, c}, σ = ±1
                o = b if plane < 2 else c
                sig = 1.0 if plane % 2 == 0 else -1.0
                m = 0
                for j in range(n):
                    k = (j + 1) % n
                    dj = sgn * poly[j, a] - sig * poly[j, o] + eps
                    dk = sgn * poly[k, a] - sig * poly[k, o] + eps
                    if dj >= 0:
                        nxt[m, 0], nxt[m, 1], nxt[m, 2] = poly[j, 0], poly[j, 1], poly[j, 2]
                        m += 1
                    if (dj >= 0) != (dk >= 0):
                        u = dj / (dj - dk)
                        for ch in range(3):
                            nxt[m, ch] = poly[j, ch] + u * (poly[k, ch] - poly[j, ch])
                        m += 1
                n = m
                for j in range(n):
                    poly[j, 0], poly[j, 1], poly[j, 2] = nxt[j, 0], nxt[j, 1], nxt[j, 2]
                if n == 0:
                    break
            for j in range(n):
                if not _extend(part, f, vp, poly[j, 0] + lx, poly[j, 1] + ly, poly[j, 2] + lz, floor_w):
                    whole[f] = True
                    break
    rects = _rects_from_extremes(part, res, kernel)
    for f in range(6):
        if whole[f]:
            rects[f, 0], rects[f, 1], rects[f, 2], rects[f, 3] = 0, res - 1, 0, res - 1
    return rects


def receiver_triangle_rects(
    corners: np.ndarray, view_projection: np.ndarray, light_position: np.ndarray, resolution: int, kernel: str
) -> np.ndarray:
    """Per cube face, the texels that look-ups of any point on the receiver triangles may read.

    A bound from the receivers' triangles rather than their points (the pre-pass of
    :func:`receiver_visibility_compiled` needs the points): each triangle's part inside a
    face's cone (the points :func:`visibility_at` looks up in that face), projected, with a
    margin past rounding and two texels beyond the taps' reach. For look-ups without a normal
    offset.

    Args:
        corners: (n, 3, 3) float64 world-space receiver triangles.
        view_projection: (6, 4, 4) world → clip matrices of the faces
            (:data:`blinn_phong.shadows.visibility._CUBE_FACES` order).
        light_position: (3,) the point light's world position.
        resolution: texels per face side.
        kernel: one of :data:`blinn_phong.shadows.visibility.PCF_KERNELS`.

    Returns:
        (6, 4) int64 inclusive rectangles ``(r0, r1, c0, c1)``; r0 > r1: the face is not read.
    """
    return _triangle_rects(
        np.ascontiguousarray(corners, dtype=np.float64).reshape(-1, 3, 3),
        np.ascontiguousarray(view_projection, dtype=np.float64),
        np.asarray(light_position, dtype=np.float64),
        int(resolution),
        KERNEL_CODES[kernel],
    )


@numba.njit(parallel=True, cache=True)
def _lookup(
    points, normals, depth, vp, view_z, face_mode, light_pos, normal_offset, kernel, out
):  # pragma: no cover
    with_normals = normal_offset != 0.0
    for i in numba.prange(points.shape[0]):
        nx = normals[i, 0] if with_normals else 0.0
        ny = normals[i, 1] if with_normals else 0.0
        nz = normals[i, 2] if with_normals else 0.0
        out[i] = visibility_at(
            points[i, 0], points[i, 1], points[i, 2], nx, ny, nz,
            depth, vp, view_z, face_mode, light_pos, normal_offset, kernel,
        )  # fmt: skip


#: Points per block of :func:`_lookup_nearest`.
_BLOCK = 512


@numba.njit(cache=True, inline="always")
def _project_run(points, lo, hi, vp, f, qx, qy, qz, cws, base):  # pragma: no cover - compiled
    # clip coordinates of points lo..hi-1 by face f's matrix and their quotients by w, into the
    # block's scratch rows (i − base); a tight loop of independent divisions, no branches
    m00, m01, m02, m03 = vp[f, 0, 0], vp[f, 0, 1], vp[f, 0, 2], vp[f, 0, 3]
    m10, m11, m12, m13 = vp[f, 1, 0], vp[f, 1, 1], vp[f, 1, 2], vp[f, 1, 3]
    m20, m21, m22, m23 = vp[f, 2, 0], vp[f, 2, 1], vp[f, 2, 2], vp[f, 2, 3]
    m30, m31, m32, m33 = vp[f, 3, 0], vp[f, 3, 1], vp[f, 3, 2], vp[f, 3, 3]
    for i in range(lo, hi):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        cx = ((m00 * px + m01 * py) + m02 * pz) + m03
        cy = ((m10 * px + m11 * py) + m12 * pz) + m13
        cz = ((m20 * px + m21 * py) + m22 * pz) + m23
        cw = ((m30 * px + m31 * py) + m32 * pz) + m33
        j = i - base
        qx[j] = cx / cw
        qy[j] = cy / cw
        qz[j] = cz / cw
        cws[j] = cw


@numba.njit(cache=True, error_model="numpy")  # a call, not inlined: a per-run body
def nearest_run(
    points,
    b0,
    b1,
    depth,
    vp,
    base,
    face_mode,
    light_pos,
    known,
    reuse,
    out,
    col,
    shift,
    qx,
    qy,
    qz,
    cws,
    faces,
    rects,
    miss,
):  # pragma: no cover - compiled
    """``out[i + shift, col]`` = :func:`visibility_at` (nearest tap, no normal offset) of points
    ``b0 … b1 − 1`` of one light whose maps are ``base, base + 1, …`` of the stack ``depth``
    (F, H, W) / ``vp`` (F, 4, 4) (compiled; callable from other numba kernels).

    In two passes: the projection (cube faces first, then runs of one face as tight loops of
    divisions), then the tests and the tap — the operations of _locate / _window / _lit on the
    same operands, written out (a call of the tuple-returning helpers per point costs a third
    more). The quotient of a point behind the light (w ≤ 0) is never read (numpy error model:
    no exception at 0). ``qx, qy, qz, cws`` (float64) and ``faces`` (int64): scratch of at
    least ``b1 − b0`` rows. ``known[i + shift]``: point i's cube face when ``reuse`` (int8,
    −1: none). ``rects`` (F, 4): each map's rendered texels, or (0, 4) when every texel is; a
    tap outside them sets ``miss[0] = 1`` (its value is then not to be used).
    """
    res_y = float(depth.shape[1])
    res_x = float(depth.shape[2])
    check = rects.shape[0] > 0
    if face_mode == 1:
        if reuse:
            for i in range(b0, b1):
                faces[i - b0] = known[i + shift]
        else:
            for i in range(b0, b1):
                faces[i - b0] = _cube_face(points[i, 0], points[i, 1], points[i, 2], light_pos)
        j0 = b0
        while j0 < b1:
            f = faces[j0 - b0]
            j1 = j0 + 1
            while j1 < b1 and faces[j1 - b0] == f:
                j1 += 1
            if f >= 0:
                _project_run(points, j0, j1, vp, base + f, qx, qy, qz, cws, b0)
            j0 = j1
    else:
        for i in range(b0, b1):
            faces[i - b0] = 0
        _project_run(points, b0, b1, vp, base, qx, qy, qz, cws, b0)
    for i in range(b0, b1):
        j = i - b0
        f = faces[j]
        if f < 0 or not cws[j] > 0:
            out[i + shift, col] = 1.0
            continue
        nxd, nyd, nzd = qx[j], qy[j], qz[j]
        z = (nzd + 1) * 0.5
        if not (nxd >= -1 and nxd <= 1 and nyd >= -1 and nyd <= 1 and z <= 1):
            out[i + shift, col] = 1.0
            continue
        x = (nxd + 1) * 0.5 * res_x
        y = res_y - (nyd + 1) * 0.5 * res_y
        if check and not _taps_inside(rects, base + f, x, y, 0, res_x, res_y):
            miss[0] = 1
        out[i + shift, col] = _lit(depth, base + f, math.floor(x), math.floor(y), z, res_x, res_y)


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _lookup_nearest(points, depth, vp, face_mode, light_pos, out, n_chunks, known):  # pragma: no cover
    # visibility_at with the nearest kernel and no normal offset, per block of points
    # (nearest_run); ``out``: (n, 1); ``known``: the points' cube faces when the receiver
    # pre-pass found them (int8, −1: none), else empty.
    n = points.shape[0]
    reuse = known.shape[0] == n
    every = np.zeros((0, 4), np.int64)  # every texel a look-up reads is rendered
    miss = np.zeros(1, np.int64)
    for ch in numba.prange(n_chunks):
        qx = np.empty(_BLOCK)
        qy = np.empty(_BLOCK)
        qz = np.empty(_BLOCK)
        cws = np.empty(_BLOCK)
        faces = np.zeros(_BLOCK, np.int64)
        hi = (ch + 1) * n // n_chunks
        for b0 in range(ch * n // n_chunks, hi, _BLOCK):
            b1 = min(b0 + _BLOCK, hi)
            nearest_run(
                points, b0, b1, depth, vp, 0, face_mode, light_pos, known, reuse, out, 0, 0,
                qx, qy, qz, cws, faces, every, miss,
            )  # fmt: skip


def lookup_compiled(
    depth: np.ndarray,
    view_projection: np.ndarray,
    view: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray | None,
    *,
    light_position: np.ndarray | None,
    normal_offset: float,
    kernel: str,
) -> np.ndarray:
    """Percentage-closer visibility of points from one map or a cube of six.

    Args:
        depth: (F, H, W) stacked maps (F = 1, or 6 cube faces in the order of
            :data:`blinn_phong.shadows.visibility._CUBE_FACES`).
        view_projection: (F, 4, 4) world → clip matrices of the maps.
        view: (F, 4, 4) world → light-eye matrices (row 2 orients the normal offset).
        points: (n, 3) float64 world-space receivers.
        normals: (n, 3) float64 normals, or None when ``normal_offset`` is 0.
        light_position: the point light's position for a cube (F = 6), else None.
        normal_offset: world units along the light-facing unit normal.
        kernel: one of :data:`blinn_phong.shadows.visibility.PCF_KERNELS`.

    Returns:
        (n,) float64 visibility in [0, 1], :func:`blinn_phong.shadows.visibility.shadow_map_visibility`'s.
    """
    out = np.empty(len(points))
    if len(points) == 0:
        return out
    nrm = np.zeros((1, 3)) if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
    cube = depth.shape[0] == 6
    lp = np.zeros(3) if light_position is None else np.asarray(light_position, dtype=np.float64)
    _look_up(
        np.ascontiguousarray(points, dtype=np.float64),
        nrm,
        np.ascontiguousarray(depth, dtype=np.float64),
        np.ascontiguousarray(view_projection, dtype=np.float64),
        np.ascontiguousarray(np.asarray(view, dtype=np.float64)[:, 2, :3]),
        1 if cube else 0,
        lp,
        float(normal_offset),
        KERNEL_CODES[kernel],
        out,
    )
    return out


def _look_up(
    points: np.ndarray,
    normals: np.ndarray,
    depth: np.ndarray,
    vps: np.ndarray,
    view_z: np.ndarray,
    face_mode: int,
    light_position: np.ndarray,
    normal_offset: float,
    code: int,
    out: np.ndarray,
    faces: np.ndarray | None = None,
) -> None:
    """``out[i]`` = :func:`visibility_at` of every point (blocked: the nearest tap, no normal offset).

    ``faces``: the points' cube faces from :func:`_receiver_rects`, or None.
    """
    if normal_offset == 0.0 and code == 0:
        n_chunks = max(1, min(len(points) // _BLOCK + 1, 8 * _threads()))
        known = np.zeros(0, np.int8) if faces is None else faces
        _lookup_nearest(points, depth, vps, face_mode, light_position, out.reshape(-1, 1), n_chunks, known)
    else:
        _lookup(points, normals, depth, vps, view_z, face_mode, light_position, normal_offset, code, out)


def receiver_visibility_compiled(
    world_triangles: np.ndarray,
    view_projection: np.ndarray,
    view: np.ndarray,
    resolution: int,
    points: np.ndarray,
    normals: np.ndarray | None,
    *,
    constant_bias: float,
    slope_bias: float,
    light_position: np.ndarray | None,
    normal_offset: float,
    kernel: str,
) -> np.ndarray:
    """Shadow-map visibility of points, a cube's faces rendered only where their look-ups read.

    The value of :func:`lookup_compiled` on the maps of :func:`depth_map_compiled` /
    :func:`cube_maps_compiled`, bit for bit. For a cube (F = 6) a first parallel pass over the
    points finds, per face, a rectangle holding every texel their percentage-closer taps read
    (the look-up's face choice, and its projection bounded from outside); a face no point
    reads is not rendered at all, the others only over their rectangle, and only with the
    triangles whose texel box meets it. A texel's depth is a minimum over the triangles that
    cover it, so it is the same whether or not the texels around it are rendered. A single
    map is rendered whole.

    Args:
        world_triangles: (n, 3, 3) float64 world-space casters.
        view_projection: (F, 4, 4) world → clip matrices (F = 1, or 6 cube faces in the
            order of :data:`blinn_phong.shadows.visibility._CUBE_FACES`).
        view: (F, 4, 4) world → light-eye matrices (row 2 orients the normal offset).
        resolution: texels per map side.
        points: (m, 3) float64 world-space receivers.
        normals: (m, 3) float64 normals, or None when ``normal_offset`` is 0.
        constant_bias: window-depth units added to every caster fragment.
        slope_bias: multiple of the triangle's depth slope per texel added.
        light_position: the point light's position for a cube (F = 6), else None.
        normal_offset: world units along the light-facing unit normal.
        kernel: one of :data:`blinn_phong.shadows.visibility.PCF_KERNELS`.

    Returns:
        (m,) float64 visibility in [0, 1].
    """
    out = np.empty(len(points))
    if len(points) == 0:
        return out
    res = int(resolution)
    world = np.ascontiguousarray(world_triangles, dtype=np.float64).reshape(-1, 3, 3)
    vps = np.ascontiguousarray(view_projection, dtype=np.float64)
    view_z = np.ascontiguousarray(np.asarray(view, dtype=np.float64)[:, 2, :3])
    p = np.ascontiguousarray(points, dtype=np.float64)
    nrm = np.zeros((1, 3)) if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
    cube = len(vps) == 6
    lp = np.zeros(3) if light_position is None else np.asarray(light_position, dtype=np.float64)
    code = KERNEL_CODES[kernel]
    if cube:
        # which faces the receivers use, and where: most points of a frame fall in two or three
        # faces, each over part of its rows
        n_chunks = max(1, min(len(p), 4 * _threads()))
        faces = np.empty(len(p), np.int8)
        rects = _receiver_rects(
            p, nrm, 6, res, vps, view_z, 1, lp, float(normal_offset), code, n_chunks, faces
        )
    else:
        # one map fitted to the casters: the receivers cover most of it, and the pre-pass would
        # cost more than the texels it saves
        rects = _full_rects(len(vps), res)
        faces = None
    depth = np.empty((len(vps), res, res))  # texels outside the rectangles are never read
    if len(world) == 0:
        depth[:] = 1.0
    else:
        _render_maps(world, vps, rects, constant_bias, slope_bias, depth)
    _look_up(p, nrm, depth, vps, view_z, 1 if cube else 0, lp, float(normal_offset), code, out, faces)
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _hard_shadow_rays_share(
    share, points, normals, light, positional, centre, offset, ulps, o32, d32, t32
):  # pragma: no cover
    """Shadow rays of points for one light, written into float32 arrays (compiled).

    ``points``/``normals``: (n, 3) float64 world space; ``light``: unit direction towards a
    directional light, or the position of a point light (``positional``); ``centre``: the
    :class:`~blinn_phong.shadows.raytrace.RayScene` centre subtracted from the origins; ``offset``:
    smallest origin offset (world units), raised to ``ulps·‖p − centre‖∞``. Outputs: ``o32``
    (n, 3) recentred origins, ``d32`` (n, 3) unit directions, ``t32`` (n,) ``t_max``.
    Returns the number of rows with a non-finite point or normal (left unwritten).
    """
    bad = 0
    for i in share:
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        if not (math.isfinite(px + py + pz) and math.isfinite(nx + ny + nz)):
            bad += 1
            continue
        mag = max(abs(px - centre[0]), abs(py - centre[1]), abs(pz - centre[2]))
        eff = max(offset, ulps * mag)
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        if length > 0:
            nx, ny, nz = nx / length, ny / length, nz / length
        if positional:
            lx, ly, lz = light[0] - px, light[1] - py, light[2] - pz
        else:
            lx, ly, lz = light[0], light[1], light[2]
        side = -eff if nx * lx + ny * ly + nz * lz < 0 else eff
        ox, oy, oz = px + nx * side, py + ny * side, pz + nz * side
        if positional:
            dx, dy, dz = light[0] - ox, light[1] - oy, light[2] - oz
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dist > 0:
                dx, dy, dz = dx / dist, dy / dist, dz / dist
            t32[i] = max(dist - eff, 0.0)
        else:
            dx, dy, dz = lx, ly, lz
            t32[i] = 1e37
        o32[i, 0], o32[i, 1], o32[i, 2] = ox - centre[0], oy - centre[1], oz - centre[2]
        d32[i, 0], d32[i, 1], d32[i, 2] = dx, dy, dz
    return bad


def hard_shadow_rays(points: np.ndarray, *args: object) -> int:
    """The compiled :func:`_hard_shadow_rays_share` (same arguments, without ``share``) over every row, in
    shares on threads (:func:`compositing._threads.in_shares`); returns the sum of the shares'
    counts."""
    return int(sum(in_shares(_hard_shadow_rays_share, points.shape[0], points, *args)))


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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _area_light_rays_share(
    share, origins, s, t, corner, edge_u, edge_v, offset, d32, t32
):  # pragma: no cover - compiled
    """Shadow rays towards one jittered sample ``corner + s·edge_u + t·edge_v`` per point (compiled).

    ``origins``: (n, 3) float64 offset ray origins (world); ``s``, ``t``: (n,) sample
    coordinates in [0, 1]; ``offset``: (n,) gap left before the light. Writes ``d32`` (n, 3)
    unit directions and ``t32`` (n,) ``max(distance − offset, 0)``, as
    :func:`blinn_phong.shadows.raytrace.area_light_visibility` computes them with numpy.
    """
    for i in share:
        dx = (corner[0] + s[i] * edge_u[0] + t[i] * edge_v[0]) - origins[i, 0]
        dy = (corner[1] + s[i] * edge_u[1] + t[i] * edge_v[1]) - origins[i, 1]
        dz = (corner[2] + s[i] * edge_u[2] + t[i] * edge_v[2]) - origins[i, 2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        scale = 1.0 / dist if dist > 0 else 1.0
        d32[i, 0], d32[i, 1], d32[i, 2] = dx * scale, dy * scale, dz * scale
        t32[i] = max(dist - offset[i], 0.0)


def area_light_rays(origins: np.ndarray, *args: object) -> None:
    """The compiled :func:`_area_light_rays_share` (same arguments, without ``share``) over every row, in
    shares on threads (:func:`compositing._threads.in_shares`)."""
    in_shares(_area_light_rays_share, origins.shape[0], origins, *args)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _fragment_surface_share(
    share, triangle, bary, triangles, world_vertices, face_normals, out_points, out_normals
):  # pragma: no cover - compiled
    """World-space point and face normal of each fragment, in one compiled pass.

    ``triangle``: (n,) int64 triangle of each fragment; ``bary``: (n, 3) float64 its
    perspective-correct barycentrics; ``triangles``: (T, 3) int64 vertex indices;
    ``world_vertices``: (V, 3) float64 world positions; ``face_normals``: (T, 3) float64 unit
    world face normals. Writes ``out_points[i] = Σ_k bary[i, k]·world_vertices[triangles[t, k]]``
    (the formula of :func:`blinn_phong.geometry.raster.interpolate`, summed in the order k = 0, 1, 2) and
    ``out_normals[i] = face_normals[t]``, ``t = triangle[i]``.
    """
    for i in share:
        t = triangle[i]
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        w0, w1, w2 = bary[i, 0], bary[i, 1], bary[i, 2]
        for k in range(3):
            va, vb, vc = world_vertices[a, k], world_vertices[b, k], world_vertices[c, k]
            out_points[i, k] = (w0 * va + w1 * vb) + w2 * vc
            out_normals[i, k] = face_normals[t, k]


def fragment_surface(triangle: np.ndarray, *args: object) -> None:
    """The compiled :func:`_fragment_surface_share` (same arguments, without ``share``) over every row, in
    shares on threads (:func:`compositing._threads.in_shares`)."""
    in_shares(_fragment_surface_share, triangle.shape[0], triangle, *args)
