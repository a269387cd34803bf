"""Compiled helpers of the shadow-volume kernels (:mod:`blinn_phong.shadows.volume_kernels`), at module level.

numba keys a cached kernel on the values it closes over; a kernel closing over another compiled
function (a dispatcher, pickled with a per-process identity) misses the disk cache and is
compiled again in every new process. The kernels reach these helpers through this module
instead (``vh.edge_box``), so they load from the cache. Imported only where numba is installed.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "clip_vertex",
    "depth_range",
    "edge_box",
    "edge_span",
    "finite_input",
    "matrix_entries",
    "plane_gap",
    "project_point",
    "tile_fit",
]


@numba.njit(inline="always", cache=True)
def matrix_entries(vp):  # pragma: no cover - compiled
    """The 16 entries of a 4×4 matrix, row by row, as a tuple (held in registers by a loop)."""
    return (
        vp[0, 0], vp[0, 1], vp[0, 2], vp[0, 3],
        vp[1, 0], vp[1, 1], vp[1, 2], vp[1, 3],
        vp[2, 0], vp[2, 1], vp[2, 2], vp[2, 3],
        vp[3, 0], vp[3, 1], vp[3, 2], vp[3, 3],
    )  # fmt: skip


@numba.njit(inline="always", cache=True)
def project_point(
    q0, q1, q2, n0, n1, n2, light_vec, directional, offset, moved, m
):  # pragma: no cover - compiled
    """A receiver at (q0, q1, q2) with normal (n0, n1, n2) moved ``offset`` along its normal
    towards the light's side (when ``moved``), as normalised-device (x, y, z) and clip w (the
    numpy engine's expressions, in their order). ``light_vec``: the light's (x, y, z) as a tuple;
    ``m``: :func:`matrix_entries` of the view-projection matrix. Scalars, not the arrays: an
    array passed to an inlined helper is reference-counted at every call."""
    if moved:
        if directional:
            t0 = -light_vec[0]
            t1 = -light_vec[1]
            t2 = -light_vec[2]
        else:
            t0 = light_vec[0] - q0
            t1 = light_vec[1] - q1
            t2 = light_vec[2] - q2
        dot = (n0 * t0 + n1 * t1) + n2 * t2
        side = 1.0 if dot >= 0 else -1.0
        length = np.sqrt((n0 * n0 + n1 * n1) + n2 * n2)
        k = side * offset / max(length, 1e-300)
        q0 = q0 + n0 * k
        q1 = q1 + n1 * k
        q2 = q2 + n2 * k
    c0 = ((q0 * m[0] + q1 * m[1]) + q2 * m[2]) + m[3]
    c1 = ((q0 * m[4] + q1 * m[5]) + q2 * m[6]) + m[7]
    c2 = ((q0 * m[8] + q1 * m[9]) + q2 * m[10]) + m[11]
    c3 = ((q0 * m[12] + q1 * m[13]) + q2 * m[14]) + m[15]
    return c0 / c3, c1 / c3, c2 / c3, c3


@numba.njit(inline="always", cache=True)
def finite_input(q0, q1, q2, n0, n1, n2, moved):  # pragma: no cover - compiled
    """False when a receiver (q0, q1, q2) (or, when ``moved``, its normal (n0, n1, n2)) has a NaN
    or infinite coordinate."""
    if not (np.isfinite(q0) and np.isfinite(q1) and np.isfinite(q2)):
        return False
    return not moved or (np.isfinite(n0) and np.isfinite(n1) and np.isfinite(n2))


@numba.njit(inline="always", cache=True)
def clip_vertex(x, y, z, w, m, transform):  # pragma: no cover - compiled
    """A vertex (x, y, z, w) in clip coordinates: with ``transform``, the homogeneous world vertex
    moved by the view-projection matrix (``m``: :func:`matrix_entries`; each row summed in
    :func:`blinn_phong.shadows.volume_setup._transform`'s order), else as given."""
    if not transform:
        return x, y, z, w
    return (
        ((x * m[0] + y * m[1]) + z * m[2]) + w * m[3],
        ((x * m[4] + y * m[5]) + z * m[6]) + w * m[7],
        ((x * m[8] + y * m[9]) + z * m[10]) + w * m[11],
        ((x * m[12] + y * m[13]) + z * m[14]) + w * m[15],
    )


@numba.njit(inline="always", cache=True)
def depth_range(z0, x0, y0, gx, gy, ax, bx, ay, by):  # pragma: no cover - compiled
    """The range of the depth plane ``z0 + (gx·(x − x0) + gy·(y − y0))`` over the rectangle
    [ax, bx] × [ay, by] (its corners), widened past the rounding of evaluating it at a point."""
    lo = np.inf
    hi = -np.inf
    mag = 0.0
    for corner in range(4):
        xc = ax if corner % 2 == 0 else bx
        yc = ay if corner < 2 else by
        u = gx * (xc - x0)
        v = gy * (yc - y0)
        d = z0 + (u + v)
        lo = min(lo, d)
        hi = max(hi, d)
        mag = max(mag, abs(z0) + abs(u) + abs(v))
    margin = 1e-12 * mag + 1e-300
    return lo - margin, hi + margin


@numba.njit(inline="always", cache=True)
def plane_gap(z0, x0, y0, gx, gy, a, b, c, xc, yc, ax, bx, ay, by):  # pragma: no cover - compiled
    """The range of ``(z0 + (gx·(x − x0) + gy·(y − y0))) − (a + (b·(x − xc) + c·(y − yc)))`` (a
    face's depth plane minus a tile's receiver plane) over [ax, bx] × [ay, by] (its corners: the
    difference is affine), widened past the rounding of evaluating either plane at a point."""
    lo = np.inf
    hi = -np.inf
    mag = 0.0
    for corner in range(4):
        xc_ = ax if corner % 2 == 0 else bx
        yc_ = ay if corner < 2 else by
        u = gx * (xc_ - x0)
        v = gy * (yc_ - y0)
        s = b * (xc_ - xc)
        t = c * (yc_ - yc)
        g = (z0 + (u + v)) - (a + (s + t))
        lo = min(lo, g)
        hi = max(hi, g)
        mag = max(mag, abs(z0) + abs(u) + abs(v) + abs(a) + abs(s) + abs(t))
    margin = 1e-12 * mag + 1e-300
    return lo - margin, hi + margin


@numba.njit(cache=True)
def edge_span(ex, ey, dx, dy, sy0, sy1, lo, hi):  # pragma: no cover - compiled
    """(lo, hi) widened by the x-extent of the edge from (ex, ey) along (dx, dy) clipped to the
    strip sy0 ≤ y ≤ sy1 (unchanged when the edge misses the strip)."""
    if dy == 0.0:
        if sy0 <= ey <= sy1:
            lo = min(lo, ex)
            hi = max(hi, ex + dx)
        return lo, hi
    ta = (sy0 - ey) / dy
    tb = (sy1 - ey) / dy
    t_lo = max(min(ta, tb), 0.0)
    t_hi = min(max(ta, tb), 1.0)
    if t_lo > t_hi:
        return lo, hi
    xa = ex + t_lo * dx
    xb = ex + t_hi * dx
    return min(lo, xa, xb), max(hi, xa, xb)


@numba.njit(cache=True)
def edge_box(ex, ey, dx, dy, es, ax, bx, ay, by):  # pragma: no cover - compiled
    """The rectangle [ax, bx] × [ay, by] against the inside of one edge (``es·E > 0``, E the edge
    function from (ex, ey) along (dx, dy)), past rounding: (wholly outside, wholly inside)."""
    lo = np.inf
    hi = -np.inf
    mag = 0.0
    for corner in range(4):
        xc = ax if corner % 2 == 0 else bx
        yc = ay if corner < 2 else by
        u = dx * (yc - ey)
        v = dy * (xc - ex)
        e = es * (u - v)
        lo = min(lo, e)
        hi = max(hi, e)
        mag = max(mag, abs(u) + abs(v))
    margin = 1e-12 * mag + 1e-300
    return hi < -margin, lo > margin


@numba.njit(inline="always", cache=True)
def tile_fit(xs, ys, zs, xc, yc):  # pragma: no cover - compiled
    """One tile's receivers (views ``xs``, ``ys``, ``zs``, at least one): their depth range, and a
    least-squares depth plane ``a + (b·(x − xc) + c·(y − yc))`` about (xc, yc) with the lowest
    and highest residual ``z − plane``, widened past rounding: (zlo, zhi, a, b, c, r_lo, r_hi).
    Any plane would do (the residuals are measured); a good one lets the counting kernel settle
    a tile whose receivers lie on one surface without testing each receiver."""
    n = xs.shape[0]
    zref = zs[0]
    su = 0.0
    sv = 0.0
    sw = 0.0
    suu = 0.0
    suv = 0.0
    svv = 0.0
    suw = 0.0
    svw = 0.0
    lo = np.inf
    hi = -np.inf
    for k in range(n):
        u = xs[k] - xc
        v = ys[k] - yc
        w = zs[k] - zref
        lo = min(lo, zs[k])
        hi = max(hi, zs[k])
        su += u
        sv += v
        sw += w
        suu += u * u
        suv += u * v
        svv += v * v
        suw += u * w
        svw += v * w
    mu = su / n
    mv = sv / n
    mw = sw / n
    cuu = suu / n - mu * mu
    cuv = suv / n - mu * mv
    cvv = svv / n - mv * mv
    cuw = suw / n - mu * mw
    cvw = svw / n - mv * mw
    det = cuu * cvv - cuv * cuv
    b = 0.0
    c = 0.0
    if n >= 3 and det > 1e-6 * cuu * cvv:
        b = (cuw * cvv - cvw * cuv) / det
        c = (cvw * cuu - cuw * cuv) / det
    a = zref + (mw - (b * mu + c * mv))
    r_lo = np.inf
    r_hi = -np.inf
    mag = 0.0
    for k in range(n):
        u = b * (xs[k] - xc)
        v = c * (ys[k] - yc)
        r = zs[k] - (a + (u + v))
        r_lo = min(r_lo, r)
        r_hi = max(r_hi, r)
        mag = max(mag, abs(zs[k]) + abs(a) + abs(u) + abs(v))
    margin = 1e-12 * mag + 1e-300
    return lo, hi, a, b, c, r_lo - margin, r_hi + margin
