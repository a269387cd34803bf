"""Compiled (numba) shadow maps rendered only where receivers read them.

* :func:`receiver_visibility_compiled` — the maps and the look-up of one light in one call,
  for the frame pipeline: a cube face no receiver uses is not rendered, the others only over
  a rectangle holding every texel the receivers' taps read (:func:`_receiver_rects`, from the
  points); the visibilities are those of the complete maps, bit for bit.
* :func:`receiver_triangle_rects` — the same rectangles bounded from the receivers' triangles
  (for :mod:`blinn_phong.shadows.frame_maps`, whose look-ups run inside the fused frame pass).

Renders with :mod:`blinn_phong.shadows.map_render_kernels` and looks up with
:mod:`blinn_phong.shadows.map_lookup_kernels`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from blinn_phong.shadows.map_lookup_kernels import KERNEL_CODES, _cube_face, _look_up, _threads
from blinn_phong.shadows.map_render_kernels import _full_rects, _render_maps
from compositing._threads import in_shares

__all__ = ["receiver_triangle_rects", "receiver_visibility_compiled"]


def _receiver_rects(
    points: np.ndarray, normals: np.ndarray, n_faces: int, res: int, vp: np.ndarray,
    view_z: np.ndarray, face_mode: int, light_pos: np.ndarray, normal_offset: float, kernel: int,
    n_chunks: int, faces: np.ndarray,
) -> np.ndarray:  # fmt: skip
    # per face, a rectangle (r0, r1, c0, c1) holding every texel the look-ups of the points read
    # (r0 > r1: none). The face and the normal offset are chosen as visibility_at chooses them
    # (exactly: a point must be counted in its own face); the projection is then bounded from
    # outside: one reciprocal instead of three divisions (a few ulp off), no depth test, the
    # frustum test widened by 1e-9, and two texels of margin beyond the taps' reach, so the
    # rectangle can only be larger than the exact one. Per chunk of points (shares on threads): the
    # extreme normalised coordinates per face, merged and turned into texels at the end. Each
    # point's cube face (−1: none) is written to ``faces`` (int8) for the look-up.
    part = np.empty((n_chunks, n_faces, 4))  # min x, max x, min y, max y (normalised device)
    args = (points, normals, n_faces, vp, view_z, face_mode, light_pos, normal_offset, n_chunks, faces, part)
    in_shares(_receiver_extremes_share, n_chunks, *args)
    return _rects_from_extremes(part, res, kernel)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _receiver_extremes_share(
    share, points, normals, n_faces, vp, view_z, face_mode, light_pos, normal_offset, n_chunks, faces, part
):  # pragma: no cover - compiled
    # part[ch] for the chunks ch of ``share`` (of n_chunks): the extreme normalised device
    # coordinates per face of the chunk's points (_receiver_rects)
    n = points.shape[0]
    with_normals = normal_offset != 0.0
    lim = 1.0 + 1e-9
    for ch in share:
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


@numba.njit(cache=True)  # a call, not inlined: _triangle_rects calls it twice
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
    face's cone (the points :func:`.map_lookup_kernels.visibility_at` looks up in that face),
    projected, with a margin past rounding and two texels beyond the taps' reach. For look-ups
    without a normal offset.

    Args:
        corners: (n, 3, 3) float64 world-space receiver triangles.
        view_projection: (6, 4, 4) world → clip matrices of the faces
            (:data:`blinn_phong.model.lights.CUBE_FACES` order).
        light_position: (3,) the point light's world position.
        resolution: texels per face side.
        kernel: one of :data:`blinn_phong.shadows.maps.PCF_KERNELS`.

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

    The value of :func:`.map_lookup_kernels.lookup_compiled` on the maps of
    :func:`.map_render_kernels.depth_map_compiled` / :func:`.map_render_kernels.cube_maps_compiled`,
    bit for bit. For a cube (F = 6) a first pass over the points (shares on threads) finds,
    per face, a rectangle holding every texel their percentage-closer taps read (the
    look-up's face choice, and its projection bounded from outside); a face no point reads
    is not rendered at all, the others only over their rectangle, and only with the
    triangles whose texel box meets it. A texel's depth is a minimum over the triangles that
    cover it, so it is the same whether or not the texels around it are rendered. A single
    map is rendered whole.

    Args:
        world_triangles: (n, 3, 3) float64 world-space casters.
        view_projection: (F, 4, 4) world → clip matrices (F = 1, or 6 cube faces in the
            order of :data:`blinn_phong.model.lights.CUBE_FACES`).
        view: (F, 4, 4) world → light-eye matrices (row 2 orients the normal offset).
        resolution: texels per map side.
        points: (m, 3) float64 world-space receivers.
        normals: (m, 3) float64 normals, or None when ``normal_offset`` is 0.
        constant_bias: window-depth units added to every caster fragment.
        slope_bias: multiple of the triangle's depth slope per texel added.
        light_position: the point light's position for a cube (F = 6), else None.
        normal_offset: world units along the light-facing unit normal.
        kernel: one of :data:`blinn_phong.shadows.maps.PCF_KERNELS`.

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
