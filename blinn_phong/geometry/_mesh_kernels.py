"""Compiled (numba) passes of :mod:`blinn_phong.geometry.mesh_facts`, cached on disk.

Imported only when numba is (:func:`blinn_phong.geometry.mesh_facts._kernels`). Each is the twin of
the numpy reference in :mod:`blinn_phong.geometry.mesh_facts`, with the same arithmetic operation for
operation: ``object_arrays`` (used vertices, triangles with an area, the coordinate tolerance,
planarity, flat normals), ``rows`` (out-neighbours per vertex by a counting sort of the
directed edges), ``paired`` (every directed edge once, its twin once), ``weld`` (a hash table
over integer cells, :func:`blinn_phong._hashing.weld_rows`), ``convex`` (tests (1)–(3) of
:func:`blinn_phong.geometry.mesh_facts._convex_surface`) and ``world_bounds``.

The functions live at module level, not in a closure: numba's disk cache keys a closure's
functions by the pickled cells, which differ from one process to the next for a cell holding
another compiled function, so those were compiled again in every new process.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from blinn_phong._hashing import weld_rows

__all__ = ["convex", "object_arrays", "paired", "rows", "weld", "world_bounds"]


@numba.njit(cache=True)
def object_arrays(pos, tri, normals, has_normals, eps32, eps64):  # pragma: no cover - compiled
    nv, nt = pos.shape[0], tri.shape[0]
    used = np.zeros(nv, np.bool_)
    for t in range(nt):
        for k in range(3):
            used[tri[t, k]] = True
    biggest = 0.0
    single = True
    any_used = False
    for v in range(nv):
        if used[v]:
            any_used = True
            for k in range(3):
                x = pos[v, k]
                if abs(x) > biggest:
                    biggest = abs(x)
                if single and np.float64(np.float32(x)) != x:
                    single = False
    tol = 0.0
    if any_used:
        tol = 64.0 * (eps32 if single else eps64) * max(biggest, 1e-300)
    good = np.zeros(nt, np.bool_)
    first = -1
    for t in range(nt):
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        ux, uy, uz = pos[b, 0] - pos[a, 0], pos[b, 1] - pos[a, 1], pos[b, 2] - pos[a, 2]
        vx, vy, vz = pos[c, 0] - pos[a, 0], pos[c, 1] - pos[a, 1], pos[c, 2] - pos[a, 2]
        fx, fy, fz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        if math.sqrt(fx * fx + fy * fy + fz * fz) > 0:
            good[t] = True
            if first < 0:
                first = t
    planar = False
    flat = not has_normals
    if first >= 0:
        a, b, c = tri[first, 0], tri[first, 1], tri[first, 2]
        ux, uy, uz = pos[b, 0] - pos[a, 0], pos[b, 1] - pos[a, 1], pos[b, 2] - pos[a, 2]
        vx, vy, vz = pos[c, 0] - pos[a, 0], pos[c, 1] - pos[a, 1], pos[c, 2] - pos[a, 2]
        fx, fy, fz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        ln = math.sqrt(fx * fx + fy * fy + fz * fz)
        nx, ny, nz = fx / ln, fy / ln, fz / ln
        planar = True
        for v in range(nv):
            if used[v]:
                d = (pos[v, 0] - pos[a, 0]) * nx + (pos[v, 1] - pos[a, 1]) * ny + (pos[v, 2] - pos[a, 2]) * nz
                if not abs(d) <= tol:
                    planar = False
                    break
        if has_normals:
            flat = True
            for t in range(nt):
                if not good[t]:
                    continue
                a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
                ux, uy, uz = pos[b, 0] - pos[a, 0], pos[b, 1] - pos[a, 1], pos[b, 2] - pos[a, 2]
                vx, vy, vz = pos[c, 0] - pos[a, 0], pos[c, 1] - pos[a, 1], pos[c, 2] - pos[a, 2]
                fx, fy, fz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
                ln = math.sqrt(fx * fx + fy * fy + fz * fz)
                fx, fy, fz = fx / ln, fy / ln, fz / ln
                for k in range(3):
                    w = tri[t, k]
                    mx, my, mz = normals[w, 0], normals[w, 1], normals[w, 2]
                    m = max(math.sqrt(mx * mx + my * my + mz * mz), 1e-300)
                    if not (mx / m) * fx + (my / m) * fy + (mz / m) * fz >= 1 - 1e-9:
                        flat = False
                        break
                if not flat:
                    break
    return used, good, tol, planar, flat


@numba.njit(cache=True)
def rows(tri, nv):  # pragma: no cover - compiled
    """Out-neighbours per vertex (a counting sort of the directed edges); False on a loop edge."""
    nt = tri.shape[0]
    start = np.zeros(nv + 1, np.int64)
    dst = np.empty(3 * nt, np.int64)
    simple = nt > 0
    for t in range(nt):
        for k in range(3):
            a, b = tri[t, k], tri[t, (k + 1) % 3]
            if a == b:
                simple = False
            start[a + 1] += 1
    for v in range(nv):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    for t in range(nt):
        for k in range(3):
            a = tri[t, k]
            dst[fill[a]] = tri[t, (k + 1) % 3]
            fill[a] += 1
    return simple, start, dst


@numba.njit(cache=True)
def paired(start, dst):  # pragma: no cover - compiled
    """Whether every directed edge (v, w) occurs once in v's row and its twin (w, v) once.

    A row holds about 6 entries: a short row is scanned; a row longer than 32 (a fan's
    centre) is sorted first and searched by bisection. Every row is checked to hold each
    neighbour once (so all directed edges are distinct); each edge (v, w) with v < w looks
    for its twin in w's row, counting the pairs found. The mesh is closed when the pairs
    cover every directed edge: 2·pairs = 3T (distinct edges, each in at most one pair)."""
    nv = start.shape[0] - 1
    for v in range(nv):
        if start[v + 1] - start[v] > 32:
            dst[start[v] : start[v + 1]] = np.sort(dst[start[v] : start[v + 1]])
    pairs = 0
    for v in range(nv):
        s, e = start[v], start[v + 1]
        for i in range(s, e):
            w = dst[i]
            if e - s > 32:
                if i > s and dst[i - 1] == w:
                    return False  # the directed edge (v, w) occurs twice
            else:
                for j in range(s, i):
                    if dst[j] == w:
                        return False
            if w < v:
                continue  # its pair, if any, is counted from w's row
            lo, hi = start[w], start[w + 1]
            found = False
            if hi - lo > 32:
                while lo < hi:
                    mid = (lo + hi) // 2
                    if dst[mid] < v:
                        lo = mid + 1
                    else:
                        hi = mid
                found = lo < start[w + 1] and dst[lo] == v
            else:
                for j in range(lo, hi):
                    if dst[j] == v:
                        found = True
                        break
            if not found:
                return False  # no twin (w, v)
            pairs += 1
    return 2 * pairs == dst.shape[0]


@numba.njit(cache=True)
def weld(cells, points):  # pragma: no cover - compiled
    first, label = weld_rows(cells)  # the hash table over the cells
    welded = np.zeros((first.shape[0], 3))
    for r in range(cells.shape[0]):  # the last vertex of a cell gives its position, as numpy's assignment
        for c in range(3):
            welded[label[r], c] = points[r, c]
    return label, welded


@numba.njit(inline="always", cache=True)
def triangle_test(points, tri, t, tol, cx, cy, cz, start, dst):  # pragma: no cover - compiled
    """Tests (2) and (1) for triangle t (status 1: passed, 0: no area, -1: failed) and its
    solid angle seen from the centroid (Van Oosterom & Strackee) for test (3)."""
    i0, i1, i2 = tri[t, 0], tri[t, 1], tri[t, 2]
    ux, uy, uz = (
        points[i1, 0] - points[i0, 0],
        points[i1, 1] - points[i0, 1],
        points[i1, 2] - points[i0, 2],
    )
    vx, vy, vz = (
        points[i2, 0] - points[i0, 0],
        points[i2, 1] - points[i0, 1],
        points[i2, 2] - points[i0, 2],
    )
    fx, fy, fz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    ln = math.sqrt(fx * fx + fy * fy + fz * fz)
    status = 0
    if ln > tol * math.sqrt(ux * ux + uy * uy + uz * uz):
        status = 1
        nx, ny, nz = fx / ln, fy / ln, fz / ln
        off = nx * points[i0, 0] + ny * points[i0, 1] + nz * points[i0, 2]
        if not (nx * cx + ny * cy + nz * cz) - off < -tol:
            return -1, 0.0  # (2) the centroid is not strictly below this plane
        for k in range(3):  # (1) the vertex stars
            v = tri[t, k]
            for e in range(start[v], start[v + 1]):
                w = dst[e]
                if w == i0 or w == i1 or w == i2:
                    continue  # a corner of t lies on t's plane
                h = (points[w, 0] * nx + points[w, 1] * ny + points[w, 2] * nz) - off
                if h > tol:
                    return -1, 0.0
    ax, ay, az = points[i0, 0] - cx, points[i0, 1] - cy, points[i0, 2] - cz
    bx, by, bz = points[i1, 0] - cx, points[i1, 1] - cy, points[i1, 2] - cz
    dx, dy, dz = points[i2, 0] - cx, points[i2, 1] - cy, points[i2, 2] - cz
    la = math.sqrt(ax * ax + ay * ay + az * az)
    lb = math.sqrt(bx * bx + by * by + bz * bz)
    ld = math.sqrt(dx * dx + dy * dy + dz * dz)
    num = ax * (by * dz - bz * dy) + ay * (bz * dx - bx * dz) + az * (bx * dy - by * dx)
    den = (
        la * lb * ld
        + (ax * bx + ay * by + az * bz) * ld
        + (ax * dx + ay * dy + az * dz) * lb
        + (bx * dx + by * dy + bz * dz) * la
    )
    return status, 2.0 * math.atan2(num, den)


@numba.njit(cache=True)
def convex(points, tri, used, tol, start, dst):  # pragma: no cover - compiled
    """Tests (1)–(3) of :func:`blinn_phong.geometry.mesh_facts._convex_surface` in one pass over the
    triangles (``used``: the vertices of the triangles), stopping at the first failure."""
    nv, nt = points.shape[0], tri.shape[0]
    cx = cy = cz = 0.0
    count = 0
    for v in range(nv):
        if used[v]:
            cx += points[v, 0]
            cy += points[v, 1]
            cz += points[v, 2]
            count += 1
    cx, cy, cz = cx / count, cy / count, cz / count
    good = False
    winding = 0.0
    for t in range(nt):
        status, omega = triangle_test(points, tri, t, tol, cx, cy, cz, start, dst)
        if status < 0:
            return False
        if status > 0:
            good = True
        winding += omega
    if not good:
        return False
    return abs(winding / (4.0 * math.pi) - 1.0) <= 0.25


@numba.njit(cache=True)
def world_bounds(pos, used, m):  # pragma: no cover - compiled
    nv = pos.shape[0]
    n = 0
    for v in range(nv):
        if used[v]:
            n += 1
    world = np.empty((n, 3))
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    j = 0
    for v in range(nv):
        if not used[v]:
            continue
        for r in range(3):
            x = (pos[v, 0] * m[r, 0] + pos[v, 1] * m[r, 1] + pos[v, 2] * m[r, 2]) + m[r, 3]
            world[j, r] = x
            lo[r] = min(lo[r], x)
            hi[r] = max(hi[r], x)
        j += 1
    centre = (lo + hi) / 2
    far = 0.0
    for j in range(n):
        dx, dy, dz = world[j, 0] - centre[0], world[j, 1] - centre[1], world[j, 2] - centre[2]
        far = max(far, dx * dx + dy * dy + dz * dz)
    return world, lo, hi, math.sqrt(far)


@numba.njit(cache=True)
def normal_angle(normals, tri, inverse):  # pragma: no cover - compiled
    """Largest angle between the world vertex normals (``n @ inverse``, normalised) at the two
    ends of any triangle edge: ``arccos`` of the smallest clipped cosine (arccos decreases)."""
    nv = normals.shape[0]
    unit = np.empty((nv, 3))
    for v in range(nv):
        x = normals[v, 0] * inverse[0, 0] + normals[v, 1] * inverse[1, 0] + normals[v, 2] * inverse[2, 0]
        y = normals[v, 0] * inverse[0, 1] + normals[v, 1] * inverse[1, 1] + normals[v, 2] * inverse[2, 1]
        z = normals[v, 0] * inverse[0, 2] + normals[v, 1] * inverse[1, 2] + normals[v, 2] * inverse[2, 2]
        length = max(math.sqrt(x * x + y * y + z * z), 1e-300)
        unit[v, 0], unit[v, 1], unit[v, 2] = x / length, y / length, z / length
    lowest = 1.0
    for t in range(tri.shape[0]):
        for k in range(3):
            a, b = tri[t, k], tri[t, (k + 1) % 3]
            c = unit[a, 0] * unit[b, 0] + unit[a, 1] * unit[b, 1] + unit[a, 2] * unit[b, 2]
            lowest = min(lowest, max(c, -1.0))
    return math.acos(lowest)


@numba.njit(cache=True)
def outside_polygon(flat, directions, margin):  # pragma: no cover - compiled
    """Mask of the points of ``flat`` (N, 2) not strictly inside the polygon of their extreme
    points along ``directions`` (K, 2, counter-clockwise by angle), by more than ``margin``
    in the edge functions. Every point when the polygon has fewer than 3 distinct corners."""
    n, m = flat.shape[0], directions.shape[0]
    best = np.full(m, -np.inf)
    at = np.zeros(m, np.int64)
    for i in range(n):
        for k in range(m):
            h = flat[i, 0] * directions[k, 0] + flat[i, 1] * directions[k, 1]
            if h > best[k]:
                best[k] = h
                at[k] = i
    corners = np.empty((m, 2))
    c = 0
    for k in range(m):
        x, y = flat[at[k], 0], flat[at[k], 1]
        if c == 0 or x != corners[c - 1, 0] or y != corners[c - 1, 1]:
            corners[c, 0], corners[c, 1] = x, y
            c += 1
    if c > 1 and corners[0, 0] == corners[c - 1, 0] and corners[0, 1] == corners[c - 1, 1]:
        c -= 1
    keep = np.ones(n, np.bool_)
    if c < 3:
        return keep
    for i in range(n):
        inside = True
        for k in range(c):
            ax, ay = corners[k, 0], corners[k, 1]
            bx, by = corners[(k + 1) % c, 0], corners[(k + 1) % c, 1]
            if not (bx - ax) * (flat[i, 1] - ay) - (by - ay) * (flat[i, 0] - ax) > margin:
                inside = False
                break
        keep[i] = not inside
    return keep
