"""Compiled (numba) shadow kernels: the twins of :mod:`blinn_phong.shadows` and of the ray set-up
of :mod:`blinn_phong.raytrace`.

:func:`blinn_phong.shadows.render_shadow_map` and :func:`blinn_phong.shadows.shadow_visibility`
written with numpy are the reference; this module runs the same formulas in compiled loops
that never build an array of all fragments:

* :func:`depth_map_compiled` — per triangle (in parallel): the depth slope
  ``m = max(|∂z/∂x|, |∂z/∂y|)`` of the unclipped triangle in texel units (OpenGL 2.1
  §3.5.5), near-plane clipping (``z_c ≥ −w_c``, new vertices interpolated in clip space,
  §2.12), the viewport transform, snapping to 1/256 texel, edge functions and the top-left
  fill rule of :mod:`blinn_phong.raster`; then per band of rows (in parallel) the
  scan conversion (each row only over the span its three edge functions allow, plus a texel
  of margin; every texel still takes the exact edge tests) keeps the smallest biased depth
  ``z + constant + slope·m`` per texel (``glPolygonOffset(slope, ·)``). The result is a
  minimum, so it does not depend on the order in which triangles are drawn.
* :func:`lookup_compiled` — per receiver point (in parallel): normal offset (Holbert 2011),
  projection into the light's clip space, the cube face of the major axis for point
  lights (OpenGL 4.6 §8.13, table 8.19), and the percentage-closer filter (Reeves, Salesin
  & Cook 1987) of :data:`blinn_phong.shadows.PCF_KERNELS`. The per-point body is
  :func:`visibility_at`, an ``njit`` function a compiled shading kernel can call directly.
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

import functools
import math
import os
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

__all__ = [
    "area_light_rays",
    "corner_bounds",
    "cube_maps_compiled",
    "depth_map_compiled",
    "fragment_surface",
    "hard_shadow_rays",
    "lookup_compiled",
    "visibility_at",
]

#: PCF kernel codes shared with :mod:`blinn_phong.shadows` (index into its PCF_KERNELS).
KERNEL_CODES = {"nearest": 0, "bilinear": 1, "box3": 3, "box5": 5, "box7": 7}


def _threads() -> int:
    return max(1, int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1)))


@numba.njit(cache=True, inline="always")
def _snap_setup(cv, res, sx, sy, sz, qx, qy, ea, eb, ec, etl, box, s):  # pragma: no cover - compiled
    # cv: (3, 4) clip vertices of one (sub-)triangle; fills slot s; False when it draws nothing.
    for j in range(3):
        if not cv[j, 3] > 0:
            return False
    scale = 256.0
    for j in range(3):
        w = cv[j, 3]
        nx = cv[j, 0] / w
        ny = cv[j, 1] / w
        nz = cv[j, 2] / w
        xe = (nx + 1.0) * (0.5 * res)
        ye = res - (ny + 1.0) * (0.5 * res)
        sx[s, j] = xe
        sy[s, j] = ye
        sz[s, j] = (nz + 1.0) * 0.5
        qx[s, j] = np.rint(xe * scale) / scale
        qy[s, j] = res - np.rint((res - ye) * scale) / scale
    x_0, x_1, x_2 = qx[s, 0], qx[s, 1], qx[s, 2]
    y_0, y_1, y_2 = qy[s, 0], qy[s, 1], qy[s, 2]
    area = (x_1 - x_0) * (y_2 - y_0) - (x_2 - x_0) * (y_1 - y_0)
    if area == 0:
        return False
    x0 = max(np.ceil(min(x_0, x_1, x_2) - 0.5), 0.0)
    x1 = min(np.floor(max(x_0, x_1, x_2) - 0.5), res - 1.0)
    y0 = max(np.ceil(min(y_0, y_1, y_2) - 0.5), 0.0)
    y1 = min(np.floor(max(y_0, y_1, y_2) - 0.5), res - 1.0)
    if not (x0 <= x1 and y0 <= y1):  # NaN-safe: no box, no integer cast
        return False
    box[s, 0] = int(x0)
    box[s, 1] = int(x1)
    box[s, 2] = int(y0)
    box[s, 3] = int(y1)
    sign = -1.0 if area < 0 else 1.0
    ea[s, 3] = area
    for i in range(3):
        j = (i + 1) % 3
        k = (i + 2) % 3
        a = -(qy[s, k] - qy[s, j]) * sign
        b = (qx[s, k] - qx[s, j]) * sign
        ea[s, i] = a
        eb[s, i] = b
        ec[s, i] = ((qy[s, k] - qy[s, j]) * qx[s, j] - (qx[s, k] - qx[s, j]) * qy[s, j]) * sign
        etl[s, i] = (a > 0) or (a == 0 and b < 0)
    return True


@numba.njit(cache=True, nogil=True)  # serial: ~100 ns a triangle; nogil: a cube's faces set up on threads
def _setup(world, vp, res, slope_bias):  # pragma: no cover - compiled
    # slots are filled in order (k counts them), so only the rows of drawn triangles are touched
    n = world.shape[0]
    c = np.empty((3, 4))
    cv = np.empty((3, 4))
    w = np.zeros((5, 3))
    k = 0
    sx = np.empty((2 * n, 3))
    sy = np.empty((2 * n, 3))
    sz = np.empty((2 * n, 3))
    qx = np.empty((2 * n, 3))
    qy = np.empty((2 * n, 3))
    ea = np.empty((2 * n, 4))  # edge a (3) and the snapped signed area (column 3)
    eb = np.empty((2 * n, 3))
    ec = np.empty((2 * n, 3))
    etl = np.empty((2 * n, 3), np.bool_)
    box = np.empty((2 * n, 4), np.int64)
    valid = np.zeros(2 * n, np.bool_)
    bias = np.empty(2 * n)
    for t in range(n):
        for j in range(3):
            x, y, z = world[t, j, 0], world[t, j, 1], world[t, j, 2]
            for ch in range(4):
                c[j, ch] = ((vp[ch, 0] * x + vp[ch, 1] * y) + vp[ch, 2] * z) + vp[ch, 3]
        # trivially outside one side of the light's frustum: nothing to draw
        out = False
        for ch in range(2):
            if (c[0, ch] > c[0, 3] and c[1, ch] > c[1, 3] and c[2, ch] > c[2, 3]) or (
                c[0, ch] < -c[0, 3] and c[1, ch] < -c[1, 3] and c[2, ch] < -c[2, 3]
            ):
                out = True
        if out:
            continue
        # depth slope of the unclipped triangle in window units (GL 2.1 §3.5.5)
        slope = 0.0
        if c[0, 3] > 0 and c[1, 3] > 0 and c[2, 3] > 0:
            xw0 = (c[0, 0] / c[0, 3] + 1) * 0.5 * res
            yw0 = (c[0, 1] / c[0, 3] + 1) * 0.5 * res
            zw0 = (c[0, 2] / c[0, 3] + 1) * 0.5
            xw1 = (c[1, 0] / c[1, 3] + 1) * 0.5 * res
            yw1 = (c[1, 1] / c[1, 3] + 1) * 0.5 * res
            zw1 = (c[1, 2] / c[1, 3] + 1) * 0.5
            xw2 = (c[2, 0] / c[2, 3] + 1) * 0.5 * res
            yw2 = (c[2, 1] / c[2, 3] + 1) * 0.5 * res
            zw2 = (c[2, 2] / c[2, 3] + 1) * 0.5
            e1x, e1y, e1z = xw1 - xw0, yw1 - yw0, zw1 - zw0
            e2x, e2y, e2z = xw2 - xw0, yw2 - yw0, zw2 - zw0
            det = e1x * e2y - e2x * e1y
            if det != 0:
                slope = max(abs((e1z * e2y - e2z * e1y) / det), abs((e1x * e2z - e2x * e1z) / det))
        b = slope_bias * slope
        # near clipping, as raster._clip_near
        d0 = c[0, 2] + c[0, 3]
        d1 = c[1, 2] + c[1, 3]
        d2 = c[2, 2] + c[2, 3]
        inside0, inside1, inside2 = d0 >= 0, d1 >= 0, d2 >= 0
        n_in = int(inside0) + int(inside1) + int(inside2)
        if n_in == 3:
            if _snap_setup(c, res, sx, sy, sz, qx, qy, ea, eb, ec, etl, box, k):
                bias[k] = b
                valid[k] = True
                k += 1
        elif n_in > 0:
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
                if _snap_setup(cv, res, sx, sy, sz, qx, qy, ea, eb, ec, etl, box, k):
                    bias[k] = b
                    valid[k] = True
                    k += 1
    return valid, bias, sx, sy, sz, ea, eb, ec, etl, box


@numba.njit(cache=True)
def _scan_rows(
    depth, r0, r1, slots, bias, constant_bias, sx, sy, sz, ea, eb, ec, etl, box
):  # pragma: no cover
    # rows r0..r1 (inclusive) of one map: fill with 1, then keep the smallest biased depth
    depth[r0 : r1 + 1, :] = 1.0
    for q in range(slots.shape[0]):
        s = slots[q]
        lo = max(box[s, 2], r0)
        hi = min(box[s, 3], r1)
        if lo > hi:
            continue
        area = ea[s, 3]
        ex_area = (sx[s, 1] - sx[s, 0]) * (sy[s, 2] - sy[s, 0]) - (sx[s, 2] - sx[s, 0]) * (
            sy[s, 1] - sy[s, 0]
        )
        exact = ex_area * area > 0 and abs(ex_area) > 1e-12
        abs_area = abs(area)
        b = bias[s]
        bx0 = float(box[s, 0])
        bx1 = float(box[s, 1])
        for py in range(lo, hi + 1):
            cy = py + 0.5
            # the row's span: each edge function is linear in x, so its sign changes once; the
            # span is widened by a texel on each side and every texel in it still takes the
            # exact tests below, so the covered texels are those of the whole bounding box
            x_lo, x_hi = bx0, bx1
            empty = False
            for i in range(3):
                a = ea[s, i]
                k = eb[s, i] * cy + ec[s, i]
                if a > 0:
                    x_lo = max(x_lo, math.ceil(-k / a - 0.5) - 1.0)
                elif a < 0:
                    x_hi = min(x_hi, math.floor(-k / a - 0.5) + 1.0)
                elif k < 0 or (k == 0 and not etl[s, i]):
                    empty = True
            if empty or not x_lo <= x_hi:
                continue
            for px in range(int(x_lo), int(x_hi) + 1):
                cx = px + 0.5
                e0 = ea[s, 0] * cx + (eb[s, 0] * cy + ec[s, 0])
                if e0 < 0 or (e0 == 0 and not etl[s, 0]):
                    continue
                e1 = ea[s, 1] * cx + (eb[s, 1] * cy + ec[s, 1])
                if e1 < 0 or (e1 == 0 and not etl[s, 1]):
                    continue
                e2 = ea[s, 2] * cx + (eb[s, 2] * cy + ec[s, 2])
                if e2 < 0 or (e2 == 0 and not etl[s, 2]):
                    continue
                if exact:
                    l0 = (
                        (sx[s, 2] - sx[s, 1]) * (cy - sy[s, 1]) - (sy[s, 2] - sy[s, 1]) * (cx - sx[s, 1])
                    ) / ex_area
                    l1 = (
                        (sx[s, 0] - sx[s, 2]) * (cy - sy[s, 2]) - (sy[s, 0] - sy[s, 2]) * (cx - sx[s, 2])
                    ) / ex_area
                    l2 = (
                        (sx[s, 1] - sx[s, 0]) * (cy - sy[s, 0]) - (sy[s, 1] - sy[s, 0]) * (cx - sx[s, 0])
                    ) / ex_area
                else:
                    l0 = e0 / abs_area
                    l1 = e1 / abs_area
                    l2 = e2 / abs_area
                z = l0 * sz[s, 0] + l1 * sz[s, 1] + l2 * sz[s, 2]
                if z > 1.0:
                    continue
                z = max(z, 0.0)
                biased = z + constant_bias + b
                if biased < depth[py, px]:
                    depth[py, px] = biased


@numba.njit(parallel=True, cache=True)
def _scan(depth, n_bands, slots, bias, constant_bias, sx, sy, sz, ea, eb, ec, etl, box):  # pragma: no cover
    res = depth.shape[0]
    band_h = (res + n_bands - 1) // n_bands
    for band in numba.prange(n_bands):
        r0 = band * band_h
        r1 = min(res, r0 + band_h) - 1
        _scan_rows(depth, r0, r1, slots, bias, constant_bias, sx, sy, sz, ea, eb, ec, etl, box)


@numba.njit(parallel=True, cache=True)
def _scan_faces(
    out, n_bands, slots, bias, constant_bias, sx, sy, sz, ea, eb, ec, etl, box
):  # pragma: no cover - compiled
    # every (face, band of rows) is one task, faces interleaved so that each thread gets a share
    # of every face (one face may hold most of the work: the one looking at the ground); the
    # per-face arrays come as tuples, one entry per face, so nothing is copied into one block
    n_faces = out.shape[0]
    res = out.shape[1]
    band_h = (res + n_bands - 1) // n_bands
    for task in numba.prange(n_faces * n_bands):
        f = task % n_faces
        r0 = (task // n_faces) * band_h
        r1 = min(res, r0 + band_h) - 1
        if r0 <= r1:
            _scan_rows(
                out[f], r0, r1, slots[f], bias[f], constant_bias,
                sx[f], sy[f], sz[f], ea[f], eb[f], ec[f], etl[f], box[f],
            )  # fmt: skip


@functools.lru_cache(maxsize=1)
def _setup_pool() -> ThreadPoolExecutor:
    """Threads for the per-face set-up of a cube (``_setup`` releases the GIL)."""
    return ThreadPoolExecutor(max_workers=_threads(), thread_name_prefix="shadow-setup")


def cube_maps_compiled(
    world_triangles: np.ndarray,
    view_projections: np.ndarray,
    constant_bias: float,
    slope_bias: float,
    out: np.ndarray,
) -> np.ndarray:
    """:func:`depth_map_compiled` for several cameras at once (a cube's six faces).

    Each face's triangle set-up runs on a thread of its own (the compiled set-up releases the
    GIL); then every (face, band of rows) pair is one task of a parallel scan, so that a face
    holding most of the work is shared by every thread.

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
    res = float(out.shape[1])

    def setup(f: int) -> tuple[np.ndarray, ...]:
        valid, bias, sx, sy, sz, ea, eb, ec, etl, box = _setup(world, vps[f], res, float(slope_bias))
        k = int(np.count_nonzero(valid))  # slots are filled in order: the first k are the drawn ones
        return tuple(a[:k] for a in (bias, sx, sy, sz, ea, eb, ec, etl, box))

    faces = list(_setup_pool().map(setup, range(len(vps))))
    slots = tuple(np.arange(len(face[0]), dtype=np.int64) for face in faces)
    per_face = [tuple(face[j] for face in faces) for j in range(9)]
    n_bands = max(1, min(out.shape[1], 2 * _threads()))
    _scan_faces(out, n_bands, slots, per_face[0], float(constant_bias), *per_face[1:])
    return out


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
        :func:`blinn_phong.shadows.render_shadow_map`'s ``depth`` (same conventions).
    """
    res = int(resolution)
    world = np.ascontiguousarray(world_triangles, dtype=np.float64).reshape(-1, 3, 3)
    depth = np.empty((res, res)) if out is None else out
    if len(world) == 0:
        depth[:] = 1.0
        return depth
    vp = np.ascontiguousarray(view_projection, dtype=np.float64)
    valid, bias, sx, sy, sz, ea, eb, ec, etl, box = _setup(world, vp, float(res), float(slope_bias))
    slots = np.flatnonzero(valid).astype(np.int64)
    n_bands = max(1, min(res, 4 * _threads()))
    _scan(depth, n_bands, slots, bias, float(constant_bias), sx, sy, sz, ea, eb, ec, etl, box)
    return depth


@numba.njit(cache=True, inline="always")
def _lit(depth, f, col, row, z, res_x, res_y):  # pragma: no cover - compiled
    c = min(max(col, 0.0), res_x - 1.0)
    r = min(max(row, 0.0), res_y - 1.0)
    return 1.0 if z <= depth[f, int(r), int(c)] else 0.0


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
    the formulas of :func:`blinn_phong.shadows.shadow_visibility`.
    """
    res_y = float(depth.shape[1])
    res_x = float(depth.shape[2])
    f = 0
    if face_mode == 1:  # cube: face of the major axis, ties to the lower axis (np.argmax)
        rx, ry, rz = px - light_pos[0], py - light_pos[1], pz - light_pos[2]
        ax, best, val = 0, abs(rx), rx
        if abs(ry) > best:
            ax, best, val = 1, abs(ry), ry
        if abs(rz) > best:
            ax, best, val = 2, abs(rz), rz
        if val == 0:
            return 1.0
        f = 2 * ax + (0 if val > 0 else 1)
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
        return 1.0
    nxd, nyd, nzd = cx / cw, cy / cw, cz / cw
    z = (nzd + 1) * 0.5
    if not (nxd >= -1 and nxd <= 1 and nyd >= -1 and nyd <= 1 and z <= 1):  # outside (or NaN): lit
        return 1.0
    x = (nxd + 1) * 0.5 * res_x
    y = res_y - (nyd + 1) * 0.5 * res_y
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
            :data:`blinn_phong.shadows._CUBE_FACES`).
        view_projection: (F, 4, 4) world → clip matrices of the maps.
        view: (F, 4, 4) world → light-eye matrices (row 2 orients the normal offset).
        points: (n, 3) float64 world-space receivers.
        normals: (n, 3) float64 normals, or None when ``normal_offset`` is 0.
        light_position: the point light's position for a cube (F = 6), else None.
        normal_offset: world units along the light-facing unit normal.
        kernel: one of :data:`blinn_phong.shadows.PCF_KERNELS`.

    Returns:
        (n,) float64 visibility in [0, 1], :func:`blinn_phong.shadows.shadow_map_visibility`'s.
    """
    out = np.empty(len(points))
    if len(points) == 0:
        return out
    nrm = np.zeros((1, 3)) if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
    cube = depth.shape[0] == 6
    lp = np.zeros(3) if light_position is None else np.asarray(light_position, dtype=np.float64)
    _lookup(
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


@numba.njit(parallel=True, cache=True)
def hard_shadow_rays(
    points, normals, light, positional, centre, offset, ulps, o32, d32, t32
):  # pragma: no cover
    """Shadow rays of points for one light, written into float32 arrays (compiled).

    ``points``/``normals``: (n, 3) float64 world space; ``light``: unit direction towards a
    directional light, or the position of a point light (``positional``); ``centre``: the
    :class:`~blinn_phong.raytrace.RayScene` centre subtracted from the origins; ``offset``:
    smallest origin offset (world units), raised to ``ulps·‖p − centre‖∞``. Outputs: ``o32``
    (n, 3) recentred origins, ``d32`` (n, 3) unit directions, ``t32`` (n,) ``t_max``.
    Returns the number of rows with a non-finite point or normal (left unwritten).
    """
    bad = 0
    for i in numba.prange(points.shape[0]):
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


@numba.njit(parallel=True, cache=True)
def area_light_rays(origins, s, t, corner, edge_u, edge_v, offset, d32, t32):  # pragma: no cover - compiled
    """Shadow rays towards one jittered sample ``corner + s·edge_u + t·edge_v`` per point (compiled).

    ``origins``: (n, 3) float64 offset ray origins (world); ``s``, ``t``: (n,) sample
    coordinates in [0, 1]; ``offset``: (n,) gap left before the light. Writes ``d32`` (n, 3)
    unit directions and ``t32`` (n,) ``max(distance − offset, 0)``, as
    :func:`blinn_phong.raytrace.area_light_visibility` computes them with numpy.
    """
    for i in numba.prange(origins.shape[0]):
        dx = (corner[0] + s[i] * edge_u[0] + t[i] * edge_v[0]) - origins[i, 0]
        dy = (corner[1] + s[i] * edge_u[1] + t[i] * edge_v[1]) - origins[i, 1]
        dz = (corner[2] + s[i] * edge_u[2] + t[i] * edge_v[2]) - origins[i, 2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        scale = 1.0 / dist if dist > 0 else 1.0
        d32[i, 0], d32[i, 1], d32[i, 2] = dx * scale, dy * scale, dz * scale
        t32[i] = max(dist - offset[i], 0.0)


@numba.njit(parallel=True, cache=True)
def fragment_surface(
    triangle, bary, triangles, world_vertices, face_normals, out_points, out_normals
):  # pragma: no cover - compiled
    """World-space point and face normal of each fragment, in one compiled pass.

    ``triangle``: (n,) int64 triangle of each fragment; ``bary``: (n, 3) float64 its
    perspective-correct barycentrics; ``triangles``: (T, 3) int64 vertex indices;
    ``world_vertices``: (V, 3) float64 world positions; ``face_normals``: (T, 3) float64 unit
    world face normals. Writes ``out_points[i] = Σ_k bary[i, k]·world_vertices[triangles[t, k]]``
    (the formula of :func:`blinn_phong.raster.interpolate`, summed in the order k = 0, 1, 2) and
    ``out_normals[i] = face_normals[t]``, ``t = triangle[i]``.
    """
    for i in numba.prange(triangle.shape[0]):
        t = triangle[i]
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        w0, w1, w2 = bary[i, 0], bary[i, 1], bary[i, 2]
        for k in range(3):
            va, vb, vc = world_vertices[a, k], world_vertices[b, k], world_vertices[c, k]
            out_points[i, k] = (w0 * va + w1 * vb) + w2 * vc
            out_normals[i, k] = face_normals[t, k]
