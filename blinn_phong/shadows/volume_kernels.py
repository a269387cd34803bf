"""Shadow volumes' compiled (numba) kernels: receiver projection and tile binning, each tile's
receiver depths, volume-triangle set-up, the stencil count, and a frame's pixel tiles.

Every expression is written out in the same order as its numpy twin in
:mod:`blinn_phong.shadows.volume_setup` (:func:`~blinn_phong.shadows.volume_setup._project_numpy`,
:func:`~blinn_phong.shadows.volume_setup._transform`, :func:`~blinn_phong.shadows.volume_setup._setup`),
without fused multiply-adds, so both engines produce bit-identical set-ups and therefore identical
counts. The kernels' helpers are module-level functions of
:mod:`blinn_phong.shadows._volume_helpers` (so that numba's disk cache serves the callers).

Each kernel is one serial build (compiling numba's parallel loops cost several times as much)
that loops over the items it is given — bands of tile rows, rows, faces, chunks of receivers —
and releases the GIL: :mod:`blinn_phong.shadows.volume_counting` runs shares of the items on
threads (:func:`compositing._threads.in_shares`), or all of them on the calling thread for a
small job. Each item writes its own outputs, so results do not depend on the threads.
"""

from __future__ import annotations

import functools

import numpy as np


def _njit() -> object:
    """``numba.njit`` for a share kernel: a serial loop over the indices it is given that releases
    the GIL (:func:`compositing._threads.in_shares` runs shares of them on threads) under numpy's
    error model (a division is not tested for zero, so LLVM optimises the loops as it does a
    parallel loop's body). Every index writes its own outputs: no write races, and the results do
    not depend on the number of threads or shares."""
    import numba

    return numba.njit(cache=True, nogil=True, error_model="numpy")


@functools.lru_cache(maxsize=1)
def _kernel() -> object:  # a numba dispatcher
    from blinn_phong.shadows import _volume_helpers as vh  # module-level helpers: numba caches the callers

    @_njit()
    def count(
        bands,
        n_bands,
        ny,
        nx,
        xmin,
        ymin,
        cw,
        ch,
        cx0,
        cx1,
        cy0,
        cy1,
        ex,
        ey,
        edx,
        edy,
        esign,
        etie,
        z0,
        x0,
        y0,
        gx,
        gy,
        front,
        bx0,
        bx1,
        by0,
        by1,
        px,
        py,
        pz,
        cell_start,
        zlo,
        zhi,
        fit,
        order,
        zfail,
        visibility,
        slack_x,
        slack_y,
        counts,
        out_counts,
        out_vis,
    ):  # pragma: no cover - compiled
        # Counts the receivers of the bands ``bands`` (of ``n_bands``: band b owns the tile rows b,
        # b + n_bands, ...). Receivers arrive sorted by tile: px[cell_start[c]:cell_start[c + 1]]
        # lie in tile c;
        # zlo/zhi: each tile's receiver depth range; fit: its receivers' depth plane and their
        # residuals from it (see ``tile_depths``). Returns (counts, visibility) in the receivers'
        # input order (``order`` maps sorted → input): with ``visibility`` an empty count array
        # and 1.0 where the count is 0, else 0.0; without it the counts and an empty array.
        # slack_x/slack_y: how far a receiver may lie outside its tile (0 when binned from these
        # very positions; see ``project_binned``): every tile is widened by as much, plus 1e-9
        # of its size for rounding of the binning. counts (m,) int64: scratch, zeroed here by the
        # band that owns each receiver; out_counts (m,) or out_vis (m,): the result, every entry
        # written (the caller allocates them: numpy's memory is reused between frames, without
        # the page faults of fresh memory).
        n_cells = nx * ny
        whole = np.zeros(n_cells, np.int64)  # counts added to every receiver of a tile at once
        wx = 1e-9 * cw + slack_x
        wy = 1e-9 * ch + slack_y
        # band b owns the tile rows b, b + n_bands, b + 2·n_bands, ...: interleaved, so every band
        # gets a share of the busy rows
        for i_band in range(bands.shape[0]):
            band = bands[i_band]
            for row in range(band, ny, n_bands):
                for k in range(cell_start[row * nx], cell_start[(row + 1) * nx]):
                    counts[k] = 0
            for t in range(front.shape[0]):
                if cx0[t] > cx1[t] or cy0[t] > cy1[t]:
                    continue
                # the face's fields as scalars (the same values: the same arithmetic below)
                ex0, ex1, ex2 = ex[t, 0], ex[t, 1], ex[t, 2]
                ey0, ey1, ey2 = ey[t, 0], ey[t, 1], ey[t, 2]
                dx0, dx1, dx2 = edx[t, 0], edx[t, 1], edx[t, 2]
                dy0, dy1, dy2 = edy[t, 0], edy[t, 1], edy[t, 2]
                es0, es1, es2 = esign[t, 0], esign[t, 1], esign[t, 2]
                et0, et1, et2 = etie[t, 0], etie[t, 1], etie[t, 2]
                zt, xt, yt, gxt, gyt = z0[t], x0[t], y0[t], gx[t], gy[t]
                lx, hx, ly, hy = bx0[t], bx1[t], by0[t], by1[t]
                ft = front[t]
                step = -ft if zfail else ft
                # a small face (within 2 × 2 tiles): its rows need no clipping to their strips, and
                # it is not worth testing against each tile's corners (it seldom covers a tile)
                single = cx1[t] - cx0[t] <= 1 and cy1[t] - cy0[t] <= 1
                if n_bands == 1:
                    lo = cy0[t]
                else:  # the first row >= cy0 of this band
                    d = band - cy0[t] % n_bands
                    lo = cy0[t] + (d + n_bands if d < 0 else d)
                for row in range(lo, cy1[t] + 1, n_bands):
                    c_lo = cx0[t]
                    c_hi = cx1[t]
                    if not single:
                        # the face's x-extent inside this row of tiles: its edges clipped to the strip
                        sy0 = ymin + row * ch - wy
                        sy1 = ymin + (row + 1) * ch + wy
                        span_lo, span_hi = vh.edge_span(ex0, ey0, dx0, dy0, sy0, sy1, np.inf, -np.inf)
                        span_lo, span_hi = vh.edge_span(ex1, ey1, dx1, dy1, sy0, sy1, span_lo, span_hi)
                        span_lo, span_hi = vh.edge_span(ex2, ey2, dx2, dy2, sy0, sy1, span_lo, span_hi)
                        if span_lo > span_hi:
                            continue
                        pad = wx + 1e-12 * (abs(span_lo) + abs(span_hi))
                        c_lo = max(c_lo, int(np.floor((span_lo - pad - xmin) / cw)))
                        c_hi = min(c_hi, int(np.floor((span_hi + pad - xmin) / cw)))
                    for col in range(c_lo, c_hi + 1):
                        cell = row * nx + col
                        s0 = cell_start[cell]
                        s1 = cell_start[cell + 1]
                        if s0 == s1:
                            continue
                        # the tile's rectangle, widened to hold every receiver binned into it
                        ax = xmin + col * cw - wx
                        bx = xmin + (col + 1) * cw + wx
                        ay = ymin + row * ch - wy
                        by = ymin + (row + 1) * ch + wy
                        # the face's depth over the part of the tile inside its bounding box (no
                        # receiver outside that box is counted) against the receivers' depths:
                        # their range, then (when the ranges overlap) their plane and residuals
                        rx0 = max(ax, lx)
                        rx1 = min(bx, hx)
                        ry0 = max(ay, ly)
                        ry1 = min(by, hy)
                        lo_z, hi_z = vh.depth_range(zt, xt, yt, gxt, gyt, rx0, rx1, ry0, ry1)
                        all_nearer = hi_z < zlo[cell]
                        none_nearer = lo_z > zhi[cell]
                        if not (all_nearer or none_nearer):
                            lo_g, hi_g = vh.plane_gap(
                                zt, xt, yt, gxt, gyt, fit[cell, 0], fit[cell, 1], fit[cell, 2],
                                xmin + (col + 0.5) * cw, ymin + (row + 0.5) * ch, rx0, rx1, ry0, ry1,
                            )  # fmt: skip
                            all_nearer = hi_g < fit[cell, 3]
                            none_nearer = lo_g > fit[cell, 4]
                        # a face behind every receiver (z-pass) or in front of all (z-fail) counts
                        # at none of them, whatever it covers
                        if all_nearer if zfail else none_nearer:
                            continue
                        inside_all = False
                        if not single:  # tile against the face: outside one edge, or inside all three
                            out0, in0 = vh.edge_box(ex0, ey0, dx0, dy0, es0, ax, bx, ay, by)
                            out1, in1 = vh.edge_box(ex1, ey1, dx1, dy1, es1, ax, bx, ay, by)
                            out2, in2 = vh.edge_box(ex2, ey2, dx2, dy2, es2, ax, bx, ay, by)
                            if out0 or out1 or out2:
                                continue
                            inside_all = in0 and in1 and in2
                        if inside_all and (none_nearer if zfail else all_nearer):
                            whole[cell] += -ft if zfail else ft
                            continue
                        # the tile's receivers one by one (views of the tile: indices from 0
                        # compile to plain loads)
                        xs = px[s0:s1]
                        ys = py[s0:s1]
                        zs = pz[s0:s1]
                        cs = counts[s0:s1]
                        for j in range(xs.shape[0]):
                            x = xs[j]
                            y = ys[j]
                            if x < lx or x > hx or y < ly or y > hy:
                                continue
                            e = dx0 * (y - ey0) - dy0 * (x - ex0)
                            if not (es0 * e > 0 or (e == 0 and et0)):
                                continue
                            e = dx1 * (y - ey1) - dy1 * (x - ex1)
                            if not (es1 * e > 0 or (e == 0 and et1)):
                                continue
                            e = dx2 * (y - ey2) - dy2 * (x - ex2)
                            if not (es2 * e > 0 or (e == 0 and et2)):
                                continue
                            depth = zt + (gxt * (x - xt) + gyt * (y - yt))
                            # z-fail counts −front where the face is not nearer, z-pass +front where
                            # it is: one update (the loop compiles to masked vector code)
                            if (depth < zs[j]) != zfail:
                                cs[j] += step
            for row in range(band, ny, n_bands):
                for cell in range(row * nx, (row + 1) * nx):
                    for k in range(cell_start[cell], cell_start[cell + 1]):
                        c = counts[k] + whole[cell]
                        if visibility:
                            out_vis[order[k]] = 1.0 if c == 0 else 0.0
                        else:
                            out_counts[order[k]] = c
        return 0

    return count


@functools.lru_cache(maxsize=1)
def _fast_kernels() -> tuple[object, ...]:
    """Compiled receiver projection, tile binning (counting sort), volume-triangle set-up, each
    tile's receiver depths, and the projection into an earlier binning's order."""
    import numba

    from blinn_phong.shadows import _volume_helpers as vh  # module-level helpers: numba caches the callers

    @_njit()
    def project(
        chunks, p, n, light_vec, directional, offset, moved, vp, px, py, pz, stats
    ):  # pragma: no cover - compiled
        """The chunks ``chunks`` of the receivers (``stats.shape[0]`` chunks in all) projected into
        ``px``, ``py``, ``pz``; per chunk into ``stats`` (zeroed by the caller): min/max of x and
        y, min of w, 1 if an input was not finite, (unused) 0, 0."""
        m = p.shape[0]
        n_chunks = stats.shape[0]
        mat = vh.matrix_entries(vp)
        lv = (light_vec[0], light_vec[1], light_vec[2])
        size = (m + n_chunks - 1) // n_chunks
        for i_chunk in range(chunks.shape[0]):
            chunk = chunks[i_chunk]
            xlo = np.inf
            xhi = -np.inf
            ylo = np.inf
            yhi = -np.inf
            wlo = np.inf
            bad = 0.0
            for i_signed in range(chunk * size, min(m, (chunk + 1) * size)):
                i = np.uint64(i_signed)  # a valid row, taken unsigned (no negative-index handling)
                q0, q1, q2, n0, n1, n2 = p[i, 0], p[i, 1], p[i, 2], n[i, 0], n[i, 1], n[i, 2]
                if not vh.finite_input(q0, q1, q2, n0, n1, n2, moved):
                    bad = 1.0
                x, y, z, w = vh.project_point(q0, q1, q2, n0, n1, n2, lv, directional, offset, moved, mat)
                px[i] = x
                py[i] = y
                pz[i] = z
                xlo = min(xlo, x)
                xhi = max(xhi, x)
                ylo = min(ylo, y)
                yhi = max(yhi, y)
                wlo = min(wlo, w)
            stats[chunk, 0] = xlo
            stats[chunk, 1] = xhi
            stats[chunk, 2] = ylo
            stats[chunk, 3] = yhi
            stats[chunk, 4] = wlo
            stats[chunk, 5] = bad
        return 0

    @_njit()
    def project_binned(
        rows, spread, p, n, light_vec, directional, offset, moved, vp, order, cell_start, xmin, ymin, cw, ch,
        nx, ny, sx, sy, sz, stats, zlo, zhi, fit,
    ):  # fmt: skip  # pragma: no cover - compiled
        """:func:`project` into an earlier binning's order (sorted by tile: receiver ``order[k]``
        at ``k``, written into ``sx``, ``sy``, ``sz``), with how far any receiver now lies outside
        its tile (a receiver moved for another light may cross a border: the kernel widens every
        tile by as much), and each tile's depths (``tile_depths``), for the tile rows
        ``spread[rows]``. Per row of tiles into ``stats`` (zeroed by the caller): min/max of x and
        y, min of w, 1 if an input was not finite, and the largest distance of a receiver outside
        its tile along x and along y; ``zlo``, ``zhi`` (∞ and −∞) and ``fit`` as ``tile_depths``."""
        mat = vh.matrix_entries(vp)
        lv = (light_vec[0], light_vec[1], light_vec[2])
        for i_row in range(rows.shape[0]):
            row = spread[rows[i_row]]
            xlo = np.inf
            xhi = -np.inf
            ylo = np.inf
            yhi = -np.inf
            wlo = np.inf
            bad = 0.0
            out_x = 0.0
            out_y = 0.0
            ty0 = ymin + row * ch
            ty1 = ymin + (row + 1) * ch
            for cell in range(row * nx, (row + 1) * nx):
                tx0 = xmin + (cell - row * nx) * cw
                tx1 = xmin + (cell - row * nx + 1) * cw
                k0 = cell_start[cell]
                k1 = cell_start[cell + 1]
                if k0 == k1:
                    continue
                # views of the tile (indices from 0: plain loads and stores); an index from
                # ``order`` is a valid row, taken unsigned (no negative-index handling)
                ks = order[k0:k1]
                xs = sx[k0:k1]
                ys = sy[k0:k1]
                zs = sz[k0:k1]
                for k in range(k1 - k0):
                    i = np.uint64(ks[k])
                    q0, q1, q2, n0, n1, n2 = p[i, 0], p[i, 1], p[i, 2], n[i, 0], n[i, 1], n[i, 2]
                    if not vh.finite_input(q0, q1, q2, n0, n1, n2, moved):
                        bad = 1.0
                    x, y, z, w = vh.project_point(q0, q1, q2, n0, n1, n2, lv, directional, offset, moved, mat)
                    xs[k] = x
                    ys[k] = y
                    zs[k] = z
                    xlo = min(xlo, x)
                    xhi = max(xhi, x)
                    ylo = min(ylo, y)
                    yhi = max(yhi, y)
                    wlo = min(wlo, w)
                    out_x = max(out_x, tx0 - x, x - tx1)
                    out_y = max(out_y, ty0 - y, y - ty1)
                # the tile's depths while its receivers are at hand (as ``tile_depths``)
                zlo[cell], zhi[cell], fit[cell, 0], fit[cell, 1], fit[cell, 2], fit[cell, 3], fit[cell, 4] = (
                    vh.tile_fit(xs, ys, zs, xmin + (cell - row * nx + 0.5) * cw, ymin + (row + 0.5) * ch)
                )
            stats[row, 0] = xlo
            stats[row, 1] = xhi
            stats[row, 2] = ylo
            stats[row, 3] = yhi
            stats[row, 4] = wlo
            stats[row, 5] = bad
            stats[row, 6] = out_x
            stats[row, 7] = out_y
        return 0

    @numba.njit(cache=True)
    def bin_points(px, py, pz, xmin, ymin, cw, ch, nx, ny):  # pragma: no cover - compiled
        """Stable counting sort of the receivers by tile."""
        m = px.shape[0]
        n_cells = nx * ny
        cell = np.empty(m, np.int64)
        cell_start = np.zeros(n_cells + 1, np.int64)
        # a reciprocal instead of a division: a receiver on a tile border may land in either tile,
        # which the kernel's tile tests allow for (they widen each tile by 1e-9 of its size)
        icw = 1.0 / cw
        ich = 1.0 / ch
        for i in range(m):
            fx = (px[i] - xmin) * icw
            fy = (py[i] - ymin) * ich
            cx = np.int64(fx) if fx < nx else nx - 1
            cy = np.int64(fy) if fy < ny else ny - 1
            c = max(cy, 0) * nx + max(cx, 0)
            cell[i] = c
            cell_start[c + 1] += 1
        for c in range(n_cells):
            cell_start[c + 1] += cell_start[c]
        fill = cell_start[:n_cells].copy()
        order = np.empty(m, np.int64)
        sx = np.empty(m)
        sy = np.empty(m)
        sz = np.empty(m)
        for i in range(m):
            c = cell[i]
            k = fill[c]
            fill[c] = k + 1
            order[k] = i
            sx[k] = px[i]
            sy[k] = py[i]
            sz[k] = pz[i]
        return order, cell_start, sx, sy, sz

    @_njit()
    def tile_depths(
        rows, spread, px, py, pz, cell_start, xmin, ymin, cw, ch, nx, zlo, zhi, fit
    ):  # pragma: no cover - compiled
        """Per tile its receivers' depth range (zlo, zhi), and a least-squares depth plane
        ``a + (b·(x − xc) + c·(y − yc))`` about the tile's centre (xc, yc) with the lowest and
        highest residual ``z − plane`` of its receivers, widened past rounding: (n_cells, 5) rows
        (a, b, c, r_lo, r_hi). Any plane would do (the residuals are measured); a good one lets
        the kernel settle a tile whose receivers lie on one surface (a ground under its own
        light cap) without testing each receiver. For the tile rows ``spread[rows]``, into ``zlo``,
        ``zhi`` (∞ and −∞ where a tile is empty) and ``fit``."""
        for i_row in range(rows.shape[0]):
            row = spread[rows[i_row]]
            yc = ymin + (row + 0.5) * ch
            for cell in range(row * nx, (row + 1) * nx):
                k0 = cell_start[cell]
                k1 = cell_start[cell + 1]
                if k0 == k1:
                    continue
                xc = xmin + (cell - row * nx + 0.5) * cw
                zlo[cell], zhi[cell], fit[cell, 0], fit[cell, 1], fit[cell, 2], fit[cell, 3], fit[cell, 4] = (
                    vh.tile_fit(px[k0:k1], py[k0:k1], pz[k0:k1], xc, yc)
                )
        return 0

    @_njit()
    def to_clip(faces, src, vp, guard, todo):  # pragma: no cover - compiled
        """Which homogeneous world triangles (of ``faces``) cross the near plane or the guard band
        once moved to clip space by ``vp`` (as ``setup`` transforms them): those are clipped
        first (``todo``, written for each of ``faces``)."""
        m = vh.matrix_entries(vp)
        for i_face in range(faces.shape[0]):
            t = faces[i_face]
            todo[t] = False
            for v in range(3):
                xc, yc, zc, wc = vh.clip_vertex(
                    src[t, v, 0], src[t, v, 1], src[t, v, 2], src[t, v, 3], m, True
                )
                gw = guard * wc
                if not (zc + wc >= 0 and gw - xc >= 0 and xc + gw >= 0 and gw - yc >= 0 and yc + gw >= 0):
                    todo[t] = True
        return 0

    @_njit()
    def setup(
        faces, src, cut, todo, vp, xmin, ymin, cw, ch, nx, ny, slack_x, slack_y,
        ex, ey, edx, edy, esign, etie, z0, x0, y0, gx, gy, front, cx0, cx1, cy0, cy1, bx0, bx1, by0, by1,
    ):  # fmt: skip  # pragma: no cover - compiled
        """Per triangle the fields of :class:`_Setup` (see :func:`_setup`), written into the
        given arrays (``_setup_arrays``): first the homogeneous world triangles ``src``, moved to
        clip space by ``vp`` (those flagged in ``todo`` by ``to_clip`` are left empty), then the
        clip-space triangles ``cut`` (the flagged ones, clipped). Triangles with w ≤ 0 or zero or
        non-finite area are left empty too (an empty triangle: ``cx0 > cx1``, its edges unset). A
        triangle's tiles are those its bounding box meets once widened by the receivers' slack
        (see ``count``). Sets the triangles ``faces`` of ``src`` then ``cut``, numbered on."""
        n_src = src.shape[0]
        m = vh.matrix_entries(vp)
        for i_face in range(faces.shape[0]):
            t_signed = faces[i_face]
            t = np.uint64(t_signed)  # a valid index, taken unsigned (no negative-index handling)
            for i in range(3):
                etie[t, i] = False
            z0[t] = 0.0
            x0[t] = 0.0
            y0[t] = 0.0
            gx[t] = 0.0
            gy[t] = 0.0
            front[t] = 0
            cx0[t] = 1
            cx1[t] = 0
            cy0[t] = 1
            cy1[t] = 0
            bx0[t] = 0.0
            bx1[t] = 0.0
            by0[t] = 0.0
            by1[t] = 0.0
            if t_signed < n_src and todo[t]:
                continue
            transform = t_signed < n_src
            tri = src if transform else cut
            k = np.uint64(t_signed if transform else t_signed - n_src)
            c00, c01, c02, c03 = vh.clip_vertex(
                tri[k, 0, 0], tri[k, 0, 1], tri[k, 0, 2], tri[k, 0, 3], m, transform
            )
            c10, c11, c12, c13 = vh.clip_vertex(
                tri[k, 1, 0], tri[k, 1, 1], tri[k, 1, 2], tri[k, 1, 3], m, transform
            )
            c20, c21, c22, c23 = vh.clip_vertex(
                tri[k, 2, 0], tri[k, 2, 1], tri[k, 2, 2], tri[k, 2, 3], m, transform
            )
            if not (c03 > 0 and c13 > 0 and c23 > 0):
                continue
            xa = c00 / c03
            xb = c10 / c13
            xc_ = c20 / c23
            ya = c01 / c03
            yb = c11 / c13
            yc_ = c21 / c23
            za = c02 / c03
            zb = c12 / c13
            zc_ = c22 / c23
            area = (xb - xa) * (yc_ - ya) - (xc_ - xa) * (yb - ya)
            if area == 0 or not np.isfinite(area):
                continue
            sgn = 1.0 if area > 0 else -1.0
            for i in range(3):
                if i == 0:
                    xp, yp, xq, yq = xa, ya, xb, yb
                elif i == 1:
                    xp, yp, xq, yq = xb, yb, xc_, yc_
                else:
                    xp, yp, xq, yq = xc_, yc_, xa, ya
                canonical = (xp < xq) or (xp == xq and yp < yq)
                if canonical:
                    sx, sy, tx, ty = xp, yp, xq, yq
                else:
                    sx, sy, tx, ty = xq, yq, xp, yp
                ex[t, i] = sx
                ey[t, i] = sy
                edx[t, i] = tx - sx
                edy[t, i] = ty - sy
                es = sgn * (1.0 if canonical else -1.0)
                esign[t, i] = es
                ddx = -edy[t, i] * es
                ddy = edx[t, i] * es
                etie[t, i] = ddx > 0 or (ddx == 0 and ddy > 0)
            gx[t] = ((zb - za) * (yc_ - ya) - (zc_ - za) * (yb - ya)) / area
            gy[t] = ((xb - xa) * (zc_ - za) - (xc_ - xa) * (zb - za)) / area
            z0[t] = za
            x0[t] = xa
            y0[t] = ya
            front[t] = 1 if area > 0 else -1
            lo_x = min(xa, xb, xc_)
            hi_x = max(xa, xb, xc_)
            lo_y = min(ya, yb, yc_)
            hi_y = max(ya, yb, yc_)
            fx0 = np.floor((lo_x - slack_x - xmin) / cw)
            fx1 = np.floor((hi_x + slack_x - xmin) / cw)
            fy0 = np.floor((lo_y - slack_y - ymin) / ch)
            fy1 = np.floor((hi_y + slack_y - ymin) / ch)
            cx0[t] = np.int64(min(max(fx0, 0.0), float(nx)))
            cx1[t] = np.int64(min(max(fx1, -1.0), float(nx - 1)))
            cy0[t] = np.int64(min(max(fy0, 0.0), float(ny)))
            cy1[t] = np.int64(min(max(fy1, -1.0), float(ny - 1)))
            pad_x = 1e-9 * (max(abs(xa), abs(xb), abs(xc_)) + 1.0)
            pad_y = 1e-9 * (max(abs(ya), abs(yb), abs(yc_)) + 1.0)
            bx0[t] = lo_x - pad_x
            bx1[t] = hi_x + pad_x
            by0[t] = lo_y - pad_y
            by1[t] = hi_y + pad_y
        return 0

    return project, bin_points, setup, tile_depths, project_binned, to_clip


@functools.lru_cache(maxsize=1)
def _pixel_binning_kernel() -> object:  # a numba dispatcher
    @_njit()
    def pixel_bins(
        bands, spread, fill, rank, width, height, tile, nx, ny, cell_start, order
    ):  # pragma: no cover - compiled
        # counting sort of the covered pixels (rank ≥ 0) by tile: tile column col // tile, tile
        # row from the bottom (normalised y grows upwards, pixel rows downwards). Each band of
        # pixel rows (``spread[bands]``) owns its row of tiles: without ``fill``, counted into
        # ``cell_start[c + 1]`` (zeroed by the caller, who then sums it up); with ``fill``, its
        # pixels' ranks written in row-major order within a tile from ``cell_start`` on, into
        # ``order`` (room for every pixel)
        for i_band in range(bands.shape[0]):
            band = spread[bands[i_band]]
            cy = ny - 1 - band
            if not fill:
                for row in range(band * tile, min(height, (band + 1) * tile)):
                    for col in range(width):
                        if rank[row * width + col] >= 0:
                            cell_start[cy * nx + col // tile + 1] += 1
                continue
            at = cell_start[cy * nx : cy * nx + nx].copy()
            for row in range(band * tile, min(height, (band + 1) * tile)):
                for col in range(width):
                    r = rank[row * width + col]
                    if r >= 0:
                        c = col // tile
                        order[at[c]] = r
                        at[c] += 1
        return 0

    return pixel_bins
