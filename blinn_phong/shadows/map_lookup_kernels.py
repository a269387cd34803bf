"""Compiled (numba) shadow-map look-ups: the twins of
:func:`blinn_phong.shadows.maps.shadow_visibility`.

* :func:`lookup_compiled` — per receiver point: normal offset (Holbert 2011), projection into
  the light's clip space, the cube face of the major axis for point lights (OpenGL 4.6 §8.13,
  table 8.19), and the percentage-closer filter (Reeves, Salesin & Cook 1987) of
  :data:`blinn_phong.shadows.maps.PCF_KERNELS`. The per-point body is
  :func:`visibility_at`, an ``njit`` function a compiled shading kernel can call directly
  (the nearest tap without normal offset runs the same operations in blocks of points:
  :func:`nearest_run`).
* :func:`stacked_visibility` and :func:`nearest_run` — the same look-ups of one light among
  the maps of several stacked together, called by the fused frame pass
  (:mod:`blinn_phong.frame.fused`, which inlines this module's code and stamps its source
  into its cache key).

Agreement with the numpy reference: the same sequence of IEEE double operations, except that
the reference transforms points with a BLAS matrix product where the kernels use
``((m0·x + m1·y) + m2·z) + m3``; a visibility can differ only where a receiver's depth lies
within a few units in the last place of a stored depth.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np

from compositing._threads import in_shares

__all__ = ["KERNEL_CODES", "lookup_compiled", "nearest_run", "stacked_visibility", "visibility_at"]

#: PCF kernel codes shared with :mod:`blinn_phong.shadows.maps` (index into its PCF_KERNELS).
KERNEL_CODES = {"nearest": 0, "bilinear": 1, "box3": 3, "box5": 5, "box7": 7}


def _threads() -> int:
    return max(1, int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1)))


@numba.njit(cache=True)  # a call, not inlined: six call sites in _filtered
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
    the formulas of :func:`blinn_phong.shadows.maps.shadow_visibility`.
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
def _lookup(
    points, normals, depth, vp, view_z, face_mode, light_pos, normal_offset, kernel, out
):  # pragma: no cover - compiled
    # out[i] = visibility_at of every point. A numba-parallel loop, not shares on threads: numba
    # compiles a parallel loop's body knowing its arrays do not alias, and this body runs 2–3.5×
    # faster so (the percentage-closer taps); it costs about 2 s of compilation, paid only by
    # look-ups with a normal offset or a filter outside the fused frame pass.
    with_normals = normal_offset != 0.0
    for i in numba.prange(points.shape[0]):
        nx = normals[i, 0] if with_normals else 0.0
        ny = normals[i, 1] if with_normals else 0.0
        nz = normals[i, 2] if with_normals else 0.0
        out[i] = visibility_at(
            points[i, 0], points[i, 1], points[i, 2], nx, ny, nz,
            depth, vp, view_z, face_mode, light_pos, normal_offset, kernel,
        )  # fmt: skip


#: Points per block of :func:`_lookup_nearest_share`.
_BLOCK = 512


@numba.njit(cache=True, error_model="numpy")  # a call, not inlined: nearest_run calls it twice
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _lookup_nearest_share(
    share, points, depth, vp, face_mode, light_pos, out, n_chunks, known
):  # pragma: no cover - compiled
    # visibility_at with the nearest kernel and no normal offset, per block of points
    # (nearest_run), for the chunks of points in ``share`` (of n_chunks); ``out``: (n, 1);
    # ``known``: the points' cube faces when the receiver pre-pass found them (int8, −1:
    # none), else empty.
    n = points.shape[0]
    reuse = known.shape[0] == n
    every = np.zeros((0, 4), np.int64)  # every texel a look-up reads is rendered
    miss = np.zeros(1, np.int64)
    # nearest_run's integers as int64 variables, not literals: a literal argument (0) would
    # compile a specialisation of nearest_run apart from the fused frame pass's (map_row)
    zero = np.int64(0)
    qx = np.empty(_BLOCK)
    qy = np.empty(_BLOCK)
    qz = np.empty(_BLOCK)
    cws = np.empty(_BLOCK)
    faces = np.zeros(_BLOCK, np.int64)
    for ch in share:
        hi = (ch + 1) * n // n_chunks
        for b0 in range(ch * n // n_chunks, hi, _BLOCK):
            b1 = min(b0 + _BLOCK, hi)
            nearest_run(
                points, b0, b1, depth, vp, zero, face_mode, light_pos, known, reuse, out, zero, zero,
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
            :data:`blinn_phong.model.lights.CUBE_FACES`).
        view_projection: (F, 4, 4) world → clip matrices of the maps.
        view: (F, 4, 4) world → light-eye matrices (row 2 orients the normal offset).
        points: (n, 3) float64 world-space receivers.
        normals: (n, 3) float64 normals, or None when ``normal_offset`` is 0.
        light_position: the point light's position for a cube (F = 6), else None.
        normal_offset: world units along the light-facing unit normal.
        kernel: one of :data:`blinn_phong.shadows.maps.PCF_KERNELS`.

    Returns:
        (n,) float64 visibility in [0, 1], :func:`blinn_phong.shadows.maps.shadow_map_visibility`'s.
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

    ``faces``: the points' cube faces from
    :func:`blinn_phong.shadows.map_receiver_kernels._receiver_rects`, or None.
    """
    if normal_offset == 0.0 and code == 0:
        n_chunks = max(1, min(len(points) // _BLOCK + 1, 8 * _threads()))
        known = np.zeros(0, np.int8) if faces is None else faces
        args = (points, depth, vps, face_mode, light_position, out.reshape(-1, 1), n_chunks, known)
        in_shares(_lookup_nearest_share, n_chunks, *args)
    else:
        _lookup(points, normals, depth, vps, view_z, face_mode, light_position, normal_offset, code, out)
