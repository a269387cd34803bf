"""Compiled per-pixel kernels of :mod:`compositing.deep` (numba, cached on disk).

The rules are those of OpenEXR's "Interpreting OpenEXR Deep Pixels" (Kainz & Hillman,
openexr.com/en/latest/InterpretingDeepPixels.html), written in the closed form that its
companion "Theory of Deep Samples" (Hillman) derives them from: a sample of opacity
``a`` has optical depth ``u = -log1p(-a)``; a piece of relative length ``x`` of a volume
sample has optical depth ``x·u``, hence alpha ``-expm1(-x·u)`` (the document's
``1 - (1 - a)^x``) and colour ``c·alpha'/a`` (``c·x`` when ``a = 0``); coincident samples add
their optical depths, so their merge has alpha ``-expm1(-Σu)`` and colour
``(Σ c·u/a)·alpha/Σu`` (``c·u/a`` read as ``c`` for ``a = 0``), the document's two-sample rule
extended to any number. A sample of alpha 1 has infinite optical depth: a piece of it keeps
alpha 1 and its colour, and coincident opaque samples win, their colours averaged (the
document's rule for two opaque samples, the mean for more, so that the merge does not depend
on the order of its inputs).

All arithmetic is float64; results are stored as float32. A sample that is alone in its
place keeps its stored values exactly. Every kernel works on a range ``[lo, hi)`` of pixels
and releases the GIL, so :mod:`compositing.deep` runs ranges on several threads.

Sample layout: pixel ``p`` owns samples ``offsets[p]:offsets[p + 1]`` of the flat arrays
``z``, ``zback`` (float32, ``(N,)``) and ``rgba`` (float32, ``(N, 4)``, premultiplied).
"""

from __future__ import annotations

import numba
import numpy as np

_OPTS = {"cache": True, "nogil": True, "error_model": "numpy"}

#: Pixels with at most this many samples are sorted by insertion (stable); larger ones by mergesort.
_INSERTION_MAX = 48


@numba.njit(inline="always", **_OPTS)
def _sort_by_z(sz, order, n):
    """``order[:n]`` = the stable argsort of ``sz[:n]``."""
    if n <= _INSERTION_MAX:
        for i in range(n):
            order[i] = i
        for i in range(1, n):
            j = order[i]
            key = sz[j]
            k = i - 1
            while k >= 0 and sz[order[k]] > key:
                order[k + 1] = order[k]
                k -= 1
            order[k + 1] = j
    else:
        order[:n] = np.argsort(sz[:n], kind="mergesort")


@numba.njit(inline="always", **_OPTS)
def _sort_unique(b, nb):
    """Sort ``b[:nb]`` in place and drop repeated values; returns the new length."""
    if nb <= _INSERTION_MAX:
        for i in range(1, nb):
            key = b[i]
            k = i - 1
            while k >= 0 and b[k] > key:
                b[k + 1] = b[k]
                k -= 1
            b[k + 1] = key
    else:
        b[:nb] = np.sort(b[:nb])
    m = 0
    for i in range(nb):
        if m == 0 or b[i] != b[m - 1]:
            b[m] = b[i]
            m += 1
    return m


@numba.njit(inline="always", **_OPTS)
def _group(grp, gx, g, sc, out):
    """Merge ``g`` coincident pieces into ``out`` (r, g, b, a); returns the count of opaque pieces.

    Piece ``q`` is the fraction ``gx[q]`` (relative length, 1 for a whole sample) of sample
    ``grp[q]`` whose stored premultiplied colour is ``sc[grp[q]]``.
    """
    if g == 1 and gx[0] == 1.0:
        j = grp[0]
        for c in range(4):
            out[c] = sc[j, c]
        return 1 if sc[j, 3] >= 1.0 else 0
    n_opaque = 0
    o0 = 0.0
    o1 = 0.0
    o2 = 0.0
    big_u = 0.0
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for q in range(g):
        j = grp[q]
        a = sc[j, 3]
        if a >= 1.0:
            n_opaque += 1
            o0 += sc[j, 0]
            o1 += sc[j, 1]
            o2 += sc[j, 2]
            continue
        x = gx[q]
        if a > 0.0:
            u = -np.log1p(-a)
            xv = x * (u / a)
            big_u += x * u
        else:
            xv = x
        s0 += xv * sc[j, 0]
        s1 += xv * sc[j, 1]
        s2 += xv * sc[j, 2]
    if n_opaque > 0:
        out[0] = o0 / n_opaque
        out[1] = o1 / n_opaque
        out[2] = o2 / n_opaque
        out[3] = 1.0
        return n_opaque
    alpha = -np.expm1(-big_u)
    w = alpha / big_u if big_u > 0.0 else 1.0
    out[0] = s0 * w
    out[1] = s1 * w
    out[2] = s2 * w
    out[3] = alpha
    return 0


@numba.njit(inline="always", **_OPTS)
def _already_tidy(sz, szb, n):
    """True if samples ``0..n-1`` are sorted by (Z, ZBack) and pairwise non-overlapping.

    ``szb`` is already normalised (``ZBack = Z`` for point samples). For a sorted list it is
    enough to test neighbours: each sample ends where or before the next begins, and two
    samples share a front only as a point sample followed by a volume sample.
    """
    for i in range(n - 1):
        z0 = sz[i]
        z1 = sz[i + 1]
        if z0 < z1:
            if szb[i] > z1:
                return False
        elif z0 == z1:
            if not (szb[i] == z0 and szb[i + 1] > z1):
                return False
        else:
            return False
    return True


@numba.njit(**_OPTS)
def tidy_pixel(sz, szb, sc, n, order, bounds, act, grp, gx, tmp4, oz, ozb, oc):
    """Make the ``n`` samples in the scratch arrays tidy; write them to ``oz, ozb, oc``; return the count.

    Scratch: ``sz, szb`` (float64, ≥ n), ``sc`` (float64, ≥ n × 4) hold the samples
    (``szb`` is normalised in place); ``order, act, grp`` (int64, ≥ n), ``bounds`` (float64,
    ≥ 2n), ``gx`` (float64, ≥ n), ``tmp4`` (float64, 4). Output capacity ≥ 3n - 1.

    Steps (the document's "Making an Image Tidy", done as one front-to-back sweep): every
    depth where a sample begins or a volume sample ends is a boundary; at each boundary the
    point samples there merge into one point sample, then the volume samples spanning the
    interval to the next boundary contribute one piece each, merged into one volume sample.
    """
    for i in range(n):
        if szb[i] < sz[i]:  # Z >= ZBack: a point sample at Z
            szb[i] = sz[i]
    if _already_tidy(sz, szb, n):
        for i in range(n):
            oz[i] = sz[i]
            ozb[i] = szb[i]
            for c in range(4):
                oc[i, c] = sc[i, c]
        return n
    _sort_by_z(sz, order, n)
    nb = 0
    for i in range(n):
        bounds[nb] = sz[i]
        nb += 1
        if szb[i] > sz[i]:
            bounds[nb] = szb[i]
            nb += 1
    nb = _sort_unique(bounds, nb)
    m = 0
    na = 0
    i = 0
    for k in range(nb):
        d = bounds[k]
        kept = 0
        for q in range(na):  # volumes ending at d leave the active set
            if szb[act[q]] > d:
                act[kept] = act[q]
                kept += 1
        na = kept
        g = 0
        while i < n and sz[order[i]] == d:
            j = order[i]
            if szb[j] > sz[j]:
                act[na] = j
                na += 1
            else:
                grp[g] = j
                gx[g] = 1.0
                g += 1
            i += 1
        if g > 0:
            _group(grp, gx, g, sc, tmp4)
            oz[m] = d
            ozb[m] = d
            for c in range(4):
                oc[m, c] = tmp4[c]
            m += 1
        if na > 0 and k + 1 < nb:
            e = bounds[k + 1]
            for q in range(na):
                j = act[q]
                grp[q] = j
                gx[q] = 1.0 if (d == sz[j] and e == szb[j]) else (e - d) / (szb[j] - sz[j])
            _group(grp, gx, na, sc, tmp4)
            oz[m] = d
            ozb[m] = e
            for c in range(4):
                oc[m, c] = tmp4[c]
            m += 1
    return m


@numba.njit(inline="always", **_OPTS)
def _gather(offsets, z, zb, rgba, p, sz, szb, sc, start):
    """Copy pixel ``p``'s samples into the scratch arrays from index ``start``; returns the new end."""
    s = start
    for t in range(offsets[p], offsets[p + 1]):
        sz[s] = z[t]
        szb[s] = zb[t]
        for c in range(4):
            sc[s, c] = rgba[t, c]
        s += 1
    return s


@numba.njit(**_OPTS)
def merge_range(off_a, z_a, zb_a, c_a, off_b, z_b, zb_b, c_b, max_n, lo, hi):
    """Tidy the union of two images' samples for pixels ``[lo, hi)`` (``off_b`` may be all zeros).

    Returns ``(counts, z, zback, rgba)`` of the range, the samples of pixel ``lo`` first.
    """
    cap_n = max(max_n, 1)
    sz = np.empty(cap_n)
    szb = np.empty(cap_n)
    sc = np.empty((cap_n, 4))
    order = np.empty(cap_n, np.int64)
    act = np.empty(cap_n, np.int64)
    grp = np.empty(cap_n, np.int64)
    gx = np.empty(cap_n)
    bounds = np.empty(2 * cap_n)
    tmp4 = np.empty(4)
    oz = np.empty(3 * cap_n)
    ozb = np.empty(3 * cap_n)
    oc = np.empty((3 * cap_n, 4))
    counts = np.zeros(hi - lo, np.uint32)
    total_in = (off_a[hi] - off_a[lo]) + (off_b[hi] - off_b[lo])
    cap = max(16, total_in + total_in // 4)
    rz = np.empty(cap, np.float32)
    rzb = np.empty(cap, np.float32)
    rc = np.empty((cap, 4), np.float32)
    pos = 0
    for p in range(lo, hi):
        n = _gather(off_a, z_a, zb_a, c_a, p, sz, szb, sc, 0)
        n = _gather(off_b, z_b, zb_b, c_b, p, sz, szb, sc, n)
        if n == 0:
            continue
        m = tidy_pixel(sz, szb, sc, n, order, bounds, act, grp, gx, tmp4, oz, ozb, oc)
        if pos + m > cap:
            new_cap = max(2 * cap, pos + m)
            nz = np.empty(new_cap, np.float32)
            nzb = np.empty(new_cap, np.float32)
            nc = np.empty((new_cap, 4), np.float32)
            nz[:pos] = rz[:pos]
            nzb[:pos] = rzb[:pos]
            nc[:pos] = rc[:pos]
            rz, rzb, rc, cap = nz, nzb, nc, new_cap
        for k in range(m):
            rz[pos + k] = oz[k]
            rzb[pos + k] = ozb[k]
            for c in range(4):
                rc[pos + k, c] = oc[k, c]
        pos += m
        counts[p - lo] = m
    return counts, rz[:pos].copy(), rzb[:pos].copy(), rc[:pos].copy()


@numba.njit(inline="always", **_OPTS)
def _over_into(oc, m, out, p):
    """Front-to-back ``over`` of ``m`` tidy samples into ``out[p]`` (the document's flatten, step 2)."""
    acc_a = 0.0
    acc0 = 0.0
    acc1 = 0.0
    acc2 = 0.0
    for k in range(m):
        t = 1.0 - acc_a
        acc0 += t * oc[k, 0]
        acc1 += t * oc[k, 1]
        acc2 += t * oc[k, 2]
        acc_a += t * oc[k, 3]
        if acc_a >= 1.0:  # nothing behind shows: (1 - A) = 0
            break
    out[p, 0] = acc0
    out[p, 1] = acc1
    out[p, 2] = acc2
    out[p, 3] = acc_a


@numba.njit(**_OPTS)
def flatten_range(off, z, zb, rgba, known_tidy, max_n, out, lo, hi):
    """Flatten pixels ``[lo, hi)`` into ``out`` (float32, ``(n_pixels, 4)``): tidy, then front-to-back over.

    With ``known_tidy`` the stored samples are composited as they are. Returns False (the
    range runner's "suspicious" flag; input was checked when the image was made).
    """
    cap_n = max(max_n, 1)
    if known_tidy:
        for p in range(lo, hi):
            acc_a = 0.0
            acc0 = 0.0
            acc1 = 0.0
            acc2 = 0.0
            for t in range(off[p], off[p + 1]):
                tr = 1.0 - acc_a
                acc0 += tr * rgba[t, 0]
                acc1 += tr * rgba[t, 1]
                acc2 += tr * rgba[t, 2]
                acc_a += tr * rgba[t, 3]
                if acc_a >= 1.0:
                    break
            out[p, 0] = acc0
            out[p, 1] = acc1
            out[p, 2] = acc2
            out[p, 3] = acc_a
        return False
    sz = np.empty(cap_n)
    szb = np.empty(cap_n)
    sc = np.empty((cap_n, 4))
    order = np.empty(cap_n, np.int64)
    act = np.empty(cap_n, np.int64)
    grp = np.empty(cap_n, np.int64)
    gx = np.empty(cap_n)
    bounds = np.empty(2 * cap_n)
    tmp4 = np.empty(4)
    oz = np.empty(3 * cap_n)
    ozb = np.empty(3 * cap_n)
    oc = np.empty((3 * cap_n, 4))
    for p in range(lo, hi):
        n = _gather(off, z, zb, rgba, p, sz, szb, sc, 0)
        m = tidy_pixel(sz, szb, sc, n, order, bounds, act, grp, gx, tmp4, oz, ozb, oc) if n else 0
        _over_into(oc, m, out, p)
    return False


@numba.njit(inline="always", **_OPTS)
def _share(src4, n_op_s, msk4, n_op_m, has_m, share4):
    """Source's share of the merge of coincident merged samples ``src4`` and ``msk4``.

    The merged sample's colour (and alpha) is a sum of one term per input (document's
    merge rule: ``w·(c_s·v_s + c_m·v_m)``, or the opaque samples' mean); ``share4`` gets the
    source's term. Returns the merged alpha.
    """
    a_s = src4[3]
    if not has_m:
        for c in range(4):
            share4[c] = src4[c]
        return a_s
    a_m = msk4[3]
    a_merged = a_s + a_m - a_s * a_m
    if n_op_s + n_op_m > 0:
        f = n_op_s / (n_op_s + n_op_m)
        for c in range(3):
            share4[c] = src4[c] * f
        share4[3] = f
        return 1.0
    u_s = -np.log1p(-a_s) if a_s > 0.0 else 0.0
    u_m = -np.log1p(-a_m) if a_m > 0.0 else 0.0
    v_s = u_s / a_s if a_s > 0.0 else 1.0
    u = u_s + u_m
    w = a_merged / u if u > 0.0 else 1.0
    for c in range(3):
        share4[c] = src4[c] * v_s * w
    share4[3] = u_s * w
    return a_merged


@numba.njit(**_OPTS)
def holdout_range(off_s, z_s, zb_s, c_s, off_m, z_m, zb_m, c_m, max_n, lo, hi):
    """Hold out the source's samples by the mask's for pixels ``[lo, hi)``.

    Sweep front to back over the boundaries of both images (as :func:`tidy_pixel` does);
    at each place the source's and the mask's samples merge separately, and the source's
    share of their coincident merge, seen through everything in front (transmittance
    ``T`` of source and mask together), is what the source contributes to the flattened
    merge of both images. The output sample stores that contribution divided by the
    transmittance ``T_out`` of the output samples in front of it, so that flattening the
    output gives exactly the source's contributions (colour and alpha). Places where the
    source contributes nothing are dropped; the sweep stops where ``T`` reaches 0.
    Returns ``(counts, z, zback, rgba)`` of the range.
    """
    cap_n = max(max_n, 1)
    sz = np.empty(cap_n)
    szb = np.empty(cap_n)
    sc = np.empty((cap_n, 4))
    is_src = np.empty(cap_n, np.bool_)
    order = np.empty(cap_n, np.int64)
    act = np.empty(cap_n, np.int64)
    grp = np.empty(cap_n, np.int64)
    gx = np.empty(cap_n)
    grp_m = np.empty(cap_n, np.int64)
    gx_m = np.empty(cap_n)
    bounds = np.empty(2 * cap_n)
    src4 = np.empty(4)
    msk4 = np.empty(4)
    share4 = np.empty(4)
    counts = np.zeros(hi - lo, np.uint32)
    total_in = off_s[hi] - off_s[lo]
    cap = max(16, 2 * total_in)
    rz = np.empty(cap, np.float32)
    rzb = np.empty(cap, np.float32)
    rc = np.empty((cap, 4), np.float32)
    pos = 0
    for p in range(lo, hi):
        n_s = _gather(off_s, z_s, zb_s, c_s, p, sz, szb, sc, 0)
        if n_s == 0:
            continue
        n = _gather(off_m, z_m, zb_m, c_m, p, sz, szb, sc, n_s)
        for i in range(n):
            is_src[i] = i < n_s
            if szb[i] < sz[i]:
                szb[i] = sz[i]
        _sort_by_z(sz, order, n)
        nb = 0
        for i in range(n):
            bounds[nb] = sz[i]
            nb += 1
            if szb[i] > sz[i]:
                bounds[nb] = szb[i]
                nb += 1
        nb = _sort_unique(bounds, nb)
        if pos + 3 * n > cap:
            new_cap = max(2 * cap, pos + 3 * n)
            nz = np.empty(new_cap, np.float32)
            nzb = np.empty(new_cap, np.float32)
            nc = np.empty((new_cap, 4), np.float32)
            nz[:pos] = rz[:pos]
            nzb[:pos] = rzb[:pos]
            nc[:pos] = rc[:pos]
            rz, rzb, rc, cap = nz, nzb, nc, new_cap
        t_all = 1.0  # transmittance of source and mask in front
        t_out = 1.0  # transmittance of the output samples in front
        start = pos
        na = 0
        i = 0
        for k in range(nb):
            if t_all <= 0.0:
                break
            d = bounds[k]
            kept = 0
            for q in range(na):
                if szb[act[q]] > d:
                    act[kept] = act[q]
                    kept += 1
            na = kept
            g_s = 0
            g_m = 0
            while i < n and sz[order[i]] == d:
                j = order[i]
                if szb[j] > sz[j]:
                    act[na] = j
                    na += 1
                elif is_src[j]:
                    grp[g_s] = j
                    gx[g_s] = 1.0
                    g_s += 1
                else:
                    grp_m[g_m] = j
                    gx_m[g_m] = 1.0
                    g_m += 1
                i += 1
            for slot in range(2):  # 0: the point samples at d; 1: the interval [d, next boundary)
                if slot == 1:
                    if na == 0 or k + 1 == nb or t_all <= 0.0:
                        break
                    e = bounds[k + 1]
                    g_s = 0
                    g_m = 0
                    for q in range(na):
                        j = act[q]
                        x = 1.0 if (d == sz[j] and e == szb[j]) else (e - d) / (szb[j] - sz[j])
                        if is_src[j]:
                            grp[g_s] = j
                            gx[g_s] = x
                            g_s += 1
                        else:
                            grp_m[g_m] = j
                            gx_m[g_m] = x
                            g_m += 1
                else:
                    e = d
                if g_s == 0 and g_m == 0:
                    continue
                n_op_m = _group(grp_m, gx_m, g_m, sc, msk4) if g_m > 0 else 0
                if g_s == 0:
                    t_all *= 1.0 - msk4[3]
                    continue
                n_op_s = _group(grp, gx, g_s, sc, src4)
                a_merged = _share(src4, n_op_s, msk4, n_op_m, g_m > 0, share4)
                if t_out > 0.0:
                    r = 1.0 if t_all == t_out else t_all / t_out
                    nonzero = False
                    for c in range(4):
                        share4[c] *= r
                        nonzero |= share4[c] != 0.0
                    if nonzero:
                        rz[pos] = d
                        rzb[pos] = e
                        for c in range(4):
                            rc[pos, c] = share4[c]
                        pos += 1
                        t_out *= 1.0 - share4[3]
                t_all *= 1.0 - a_merged
        counts[p - lo] = pos - start
    return counts, rz[:pos].copy(), rzb[:pos].copy(), rc[:pos].copy()


@numba.njit(**_OPTS)
def tidy_flags(off, z, zb, lo, hi):
    """1 for each pixel of ``[lo, hi)`` that is tidy as stored (document's definition), else 0."""
    flags = np.zeros(hi - lo, np.uint8)
    for p in range(lo, hi):
        ok = True
        for t in range(off[p], off[p + 1] - 1):
            z0 = z[t]
            z1 = z[t + 1]
            b0 = max(z0, zb[t])
            b1 = max(z1, zb[t + 1])
            if z0 < z1:
                if b0 > z1:
                    ok = False
                    break
            elif z0 == z1:
                if not (b0 == z0 and b1 > z1):
                    ok = False
                    break
            else:
                ok = False
                break
        flags[p - lo] = 1 if ok else 0
    return flags
