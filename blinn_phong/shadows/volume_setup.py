"""Shadow volumes' counting, the readable numpy engine: clipping, per-triangle set-up, the screen
grid of receivers and the stencil count (:mod:`blinn_phong.shadows.volume` describes the method).

The compiled engine (:mod:`blinn_phong.shadows.volume_kernels`) evaluates the same expressions in
the same order, without fused multiply-adds, so both give bit-identical set-ups and identical
counts; it also uses :func:`_clip` and :func:`_transform` for the few volume triangles that cross
the near plane or the guard band.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_TILE_POINTS = 32  # receivers per screen tile, on average (16–128 measured: 32 is fastest)


def _plane_distance(clip: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """``plane · v`` for (..., 4) clip coordinates, summed in a fixed order (as compiled: no fused
    multiply-add, so both engines clip the same faces at the same points)."""
    return ((clip[..., 0] * plane[0] + clip[..., 1] * plane[1]) + clip[..., 2] * plane[2]) + clip[
        ..., 3
    ] * plane[3]


def _clip_plane(clip: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Clip (S, 3, 4) clip-space triangles to ``plane · v ≥ 0``, keeping winding. New vertices are
    interpolated from the lexicographically first endpoint, so an edge shared by two triangles is
    cut at bit-identical points."""
    dist = _plane_distance(clip, plane)
    inside = dist >= 0
    n_in = inside.sum(axis=1)
    out = [clip[n_in == 3]]

    def cut(p: np.ndarray, q: np.ndarray, dp: np.ndarray, dq: np.ndarray) -> np.ndarray:
        swap = np.zeros(len(p), bool)
        undecided = np.ones(len(p), bool)
        for c in range(4):
            lt, gt = q[:, c] < p[:, c], q[:, c] > p[:, c]
            swap |= undecided & lt
            undecided &= ~(lt | gt)
        p2, q2 = np.where(swap[:, None], q, p), np.where(swap[:, None], p, q)
        d2p, d2q = np.where(swap, dq, dp), np.where(swap, dp, dq)
        t = (d2p / (d2p - d2q))[:, None]
        return p2 + t * (q2 - p2)

    for lone_inside, count in ((True, 1), (False, 2)):
        sel = np.flatnonzero(n_in == count)
        if len(sel) == 0:
            continue
        odd = np.argmax(inside[sel] == lone_inside, axis=1)
        order = (odd[:, None] + np.arange(3)[None, :]) % 3
        v = np.take_along_axis(clip[sel], order[:, :, None], axis=1)
        d = np.take_along_axis(dist[sel], order, axis=1)
        ab = cut(v[:, 0], v[:, 1], d[:, 0], d[:, 1])
        ac = cut(v[:, 0], v[:, 2], d[:, 0], d[:, 2])
        if lone_inside:
            out.append(np.stack([v[:, 0], ab, ac], axis=1))
        else:
            out.append(np.stack([ab, v[:, 1], v[:, 2]], axis=1))
            out.append(np.stack([ab, v[:, 2], ac], axis=1))
    return np.concatenate(out)


def _clip(clip: np.ndarray, guard: float) -> np.ndarray:
    """Clip to the near plane ``z ≥ −w`` (as OpenGL does) and to a guard band ``|x|, |y| ≤ guard·w``
    lying beyond every receiver (it only keeps window positions finite: vertices at infinity that
    graze the eye plane would otherwise land at infinity on the screen)."""
    planes = np.array(
        [(0, 0, 1, 1), (-1, 0, 0, guard), (1, 0, 0, guard), (0, -1, 0, guard), (0, 1, 0, guard)], np.float64
    )
    inside = np.ones(len(clip), bool)  # most faces need no clipping at all
    for plane in planes:
        inside &= (_plane_distance(clip, plane) >= 0).all(axis=1)
    cut = clip[~inside]
    for plane in planes:
        cut = _clip_plane(cut, plane)
    return np.concatenate([clip[inside], cut])


@dataclass(frozen=True, eq=False)
class _Setup:
    """Per volume triangle (after near clipping): canonical edges, depth plane, facing, bounding box."""

    ex: np.ndarray  # (S, 3) canonical edge start x
    ey: np.ndarray
    edx: np.ndarray  # (S, 3) canonical edge vector
    edy: np.ndarray
    esign: np.ndarray  # (S, 3) +1/-1: interior where esign·E > 0
    etie: np.ndarray  # (S, 3) bool: a point with E == 0 is inside (perturbation rule)
    z0: np.ndarray  # (S,) depth plane z = z0 + gx·(x − x0) + gy·(y − y0)
    x0: np.ndarray
    y0: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    front: np.ndarray  # (S,) int64 +1 counter-clockwise (front), −1 clockwise
    cx0: np.ndarray  # (S,) grid cell bounding box (inclusive), empty when cx0 > cx1
    cx1: np.ndarray
    cy0: np.ndarray
    cy1: np.ndarray
    bx0: np.ndarray  # (S,) window bounding box, slightly widened
    bx1: np.ndarray
    by0: np.ndarray
    by1: np.ndarray


def _setup(clip: np.ndarray, grid: tuple[float, float, float, float, int, int], guard: float) -> _Setup:
    xmin, ymin, cw, ch, nx, ny = grid
    sub = _clip(clip, guard)
    w = sub[:, :, 3]
    ok = (w > 0).all(axis=1)
    sub = sub[ok]
    w = sub[:, :, 3]
    x = sub[:, :, 0] / w
    y = sub[:, :, 1] / w
    z = sub[:, :, 2] / w
    area = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    keep = (area != 0) & np.isfinite(area)
    x, y, z, area = x[keep], y[keep], z[keep], area[keep]
    s = len(area)
    ex, ey, edx, edy, esign = (np.empty((s, 3)) for _ in range(5))
    for i, (p, q) in enumerate(((0, 1), (1, 2), (2, 0))):
        canonical = (x[:, p] < x[:, q]) | ((x[:, p] == x[:, q]) & (y[:, p] < y[:, q]))
        sx = np.where(canonical, x[:, p], x[:, q])
        sy = np.where(canonical, y[:, p], y[:, q])
        tx = np.where(canonical, x[:, q], x[:, p])
        ty = np.where(canonical, y[:, q], y[:, p])
        ex[:, i], ey[:, i], edx[:, i], edy[:, i] = sx, sy, tx - sx, ty - sy
        # counter-clockwise triangle (area > 0): interior left of p→q, where E_pq > 0
        esign[:, i] = np.sign(area) * np.where(canonical, 1.0, -1.0)
    # tie-break: treat a point on an edge as moved by (ε, ε²): inside when d/dx (then d/dy) of esign·E > 0
    ddx = -edy * esign
    ddy = edx * esign
    etie = (ddx > 0) | ((ddx == 0) & (ddy > 0))
    det = area
    gx = ((z[:, 1] - z[:, 0]) * (y[:, 2] - y[:, 0]) - (z[:, 2] - z[:, 0]) * (y[:, 1] - y[:, 0])) / det
    gy = ((x[:, 1] - x[:, 0]) * (z[:, 2] - z[:, 0]) - (x[:, 2] - x[:, 0]) * (z[:, 1] - z[:, 0])) / det
    with np.errstate(invalid="ignore", over="ignore"):
        cx0 = np.floor((x.min(axis=1) - xmin) / cw)
        cx1 = np.floor((x.max(axis=1) - xmin) / cw)
        cy0 = np.floor((y.min(axis=1) - ymin) / ch)
        cy1 = np.floor((y.max(axis=1) - ymin) / ch)
    cx0 = np.clip(cx0, 0, nx).astype(np.int64)
    cx1 = np.clip(cx1, -1, nx - 1).astype(np.int64)
    cy0 = np.clip(cy0, 0, ny).astype(np.int64)
    cy1 = np.clip(cy1, -1, ny - 1).astype(np.int64)
    front = np.where(area > 0, 1, -1).astype(np.int64)
    # bounding boxes widened past rounding (a pre-test only: the edge functions decide)
    pad_x = 1e-9 * (np.abs(x).max(axis=1) + 1.0)
    pad_y = 1e-9 * (np.abs(y).max(axis=1) + 1.0)
    return _Setup(
        ex,
        ey,
        edx,
        edy,
        esign,
        etie,
        z[:, 0].copy(),
        x[:, 0].copy(),
        y[:, 0].copy(),
        gx,
        gy,
        front,
        cx0,
        cx1,
        cy0,
        cy1,
        x.min(axis=1) - pad_x,
        x.max(axis=1) + pad_x,
        y.min(axis=1) - pad_y,
        y.max(axis=1) + pad_y,
    )


def _grid_params(
    m: int, bounds: tuple[float, float, float, float]
) -> tuple[float, float, float, float, int, int]:
    """A screen grid over ``m`` receivers within ``bounds`` = (xmin, xmax, ymin, ymax), about
    ``_TILE_POINTS`` per tile: (xmin, ymin, cw, ch, nx, ny)."""
    xmin, xmax, ymin, ymax = bounds
    spanx, spany = max(xmax - xmin, 1e-12), max(ymax - ymin, 1e-12)
    cells = max(1, m // _TILE_POINTS)
    nx = int(min(4096, max(1, round(math.sqrt(cells * spanx / spany)))))
    ny = int(min(4096, max(1, round(cells / nx))))
    cw, ch = spanx / nx * (1 + 1e-9), spany / ny * (1 + 1e-9)
    return xmin, ymin, cw, ch, nx, ny


def _bin_numpy(
    px: np.ndarray, py: np.ndarray, grid: tuple[float, float, float, float, int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Receivers sorted by tile (stable): (cell_start, order)."""
    xmin, ymin, cw, ch, nx, ny = grid
    cx = np.clip(((px - xmin) / cw).astype(np.int64), 0, nx - 1)
    cy = np.clip(((py - ymin) / ch).astype(np.int64), 0, ny - 1)
    cell = cy * nx + cx
    order = np.argsort(cell, kind="stable")
    cell_start = np.searchsorted(cell[order], np.arange(nx * ny + 1))
    return cell_start.astype(np.int64), order.astype(np.int64)


def _count_numpy(st: _Setup, px, py, pz, cell_start, order, nx: int, zfail: bool) -> np.ndarray:
    counts = np.zeros(len(px), np.int64)
    for t in range(len(st.front)):
        if st.cx0[t] > st.cx1[t] or st.cy0[t] > st.cy1[t]:
            continue
        rows = np.arange(st.cy0[t], st.cy1[t] + 1)
        starts = cell_start[rows * nx + st.cx0[t]]
        stops = cell_start[rows * nx + st.cx1[t] + 1]
        lengths = stops - starts
        if lengths.sum() == 0:
            continue
        cand = order[
            np.repeat(starts - np.cumsum(np.r_[0, lengths[:-1]]), lengths) + np.arange(lengths.sum())
        ]
        x, y = px[cand], py[cand]
        inside = np.ones(len(cand), bool)
        for i in range(3):
            e = st.edx[t, i] * (y - st.ey[t, i]) - st.edy[t, i] * (x - st.ex[t, i])
            se = st.esign[t, i] * e
            inside &= (se > 0) | ((e == 0) & st.etie[t, i])
        depth = st.z0[t] + (st.gx[t] * (x - st.x0[t]) + st.gy[t] * (y - st.y0[t]))
        nearer = depth < pz[cand]
        if zfail:
            hit = inside & ~nearer
            counts[cand[hit]] -= st.front[t]
        else:
            hit = inside & nearer
            counts[cand[hit]] += st.front[t]
    return counts


def _transform(vol: np.ndarray, vp: np.ndarray) -> np.ndarray:
    """(m, 3, 4) homogeneous world → clip coordinates, summed in a fixed order (as compiled)."""
    return (
        (vol[..., 0, None] * vp[:, 0] + vol[..., 1, None] * vp[:, 1]) + vol[..., 2, None] * vp[:, 2]
    ) + vol[..., 3, None] * vp[:, 3]


def _offset_numpy(
    p: np.ndarray, n: np.ndarray, light_vec: np.ndarray, directional: bool, offset: float
) -> np.ndarray:
    """Each receiver moved ``offset`` along its normal towards the light's side (as compiled)."""
    if directional:
        t0, t1, t2 = -light_vec[0], -light_vec[1], -light_vec[2]
    else:
        t0, t1, t2 = light_vec[0] - p[:, 0], light_vec[1] - p[:, 1], light_vec[2] - p[:, 2]
    dot = (n[:, 0] * t0 + n[:, 1] * t1) + n[:, 2] * t2
    side = np.where(dot >= 0, 1.0, -1.0)
    length = np.sqrt((n[:, 0] * n[:, 0] + n[:, 1] * n[:, 1]) + n[:, 2] * n[:, 2])
    k = side * offset / np.maximum(length, 1e-300)
    return p + n * k[:, None]


def _project_numpy(q: np.ndarray, vp: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Window (normalised-device) x, y, z and clip w of world points (as compiled)."""
    c = [((q[:, 0] * vp[r, 0] + q[:, 1] * vp[r, 1]) + q[:, 2] * vp[r, 2]) + vp[r, 3] for r in range(4)]
    return c[0] / c[3], c[1] / c[3], c[2] / c[3], c[3]
