"""The fused frame pass: the plain frame shaded, fogged and written in one compiled pass.

:func:`shade_plain_winners_compiled` and :func:`shade_plain_fragments_compiled`: one sample per
pixel, no transparency resolve, per-pixel shading. Each pixel's nearest fragment is interpolated,
lit by :func:`blinn_phong.frame.lighting.point_terms` (the lighting kernel's own compiled
equation), fogged by the colour stage's compiled fog
(:func:`blinn_phong.frame.resolve_kernels._fog_function`) and written into the float32 frame
buffers in one pass over the rows, with the operations of the separate stages in their order (the
same images, no (N, 3) arrays). Frames whose shadowed lights are all shadow-mapped look the maps
up in the same pass (``map_row``, :mod:`blinn_phong.shadows.map_lookup_kernels`).

The row function (``plain_row``) is serial; the short loop over a share of rows releases the GIL
and the shares run on threads (:mod:`compositing._threads`): numba's parallel transformation of
the long row body cost minutes of compilation. Each row is written by one call, so there are no
write races.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np

from blinn_phong.frame.resolve_kernels import FogArgs, _fog_function, _fog_scalars
from blinn_phong.geometry import raster_kernels
from blinn_phong.geometry.raster import _TriangleSetup
from blinn_phong.geometry.raster_kernels import _kernel, _row_order

#: The fused kernel's interpolation of per-vertex terms, set by :func:`_row_kernels`.
_lerp: object = None
#: The z-buffer's helpers the rows inline (:mod:`blinn_phong.geometry.raster_kernels`), set by
#: :func:`_row_kernels`.
_winner_point: object = None
_unit_face_normal: object = None
_interpolated: object = None
#: The colour stage's fog (:func:`blinn_phong.frame.resolve_kernels._fog_function`), set by
#: :func:`_row_kernels`.
_fogged: object = None
#: The shadow-map look-ups (map_lookup_kernels.stacked_visibility per point, nearest_run per run of
#: points), set by :func:`_row_kernels`.
_stacked_visibility: object = None
_nearest_run: object = None
#: The lighting equation's compiled per-point function, set by :func:`_plain_kernel`.
_point_terms: object = None
_plain_row: object = None
_map_row_nearest: object = None
_map_row_filtered: object = None


@functools.lru_cache(maxsize=1)
def _row_kernels() -> None:
    """Compile-on-demand dispatchers of the fused frame kernel's rows, set as module globals:
    ``_plain_row`` (a row's shading, resolve and writes) and ``_map_row_nearest`` /
    ``_map_row_filtered`` (a row's shadow-map look-ups, nearest texel only or with the filters too,
    compiled only when a frame has shadow maps)."""
    import hashlib
    import math

    import numba

    from blinn_phong.frame import lighting

    global _point_terms, _fogged, _winner_point, _unit_face_normal, _interpolated
    _kernel()  # the z-buffer's helpers, shared with the rows: the winners' depth and barycentrics
    _winner_point = raster_kernels._winner_point
    _unit_face_normal = raster_kernels._unit_face_normal
    _interpolated = raster_kernels._interpolated
    _fogged = _fog_function()  # the colour stage's fog (a module global, as _point_terms)
    # The lighting equation: the same compiled function as lighting.shade's kernel. A module
    # global, not a closure variable (numba's disk-cache key hashes closure variables, and a
    # compiled function in one changes it in every process). numba does not track that this
    # kernel inlines code from lighting.py, so the hash of that file is a closure constant:
    # editing the equation invalidates the cached kernel.
    _point_terms = lighting.point_terms()
    # the shadow-map look-ups (map_lookup_kernels.nearest_run and stacked_visibility, with the
    # helpers they inline, all in that module): their file is stamped too
    from blinn_phong.shadows import map_lookup_kernels

    global _stacked_visibility, _nearest_run
    _stacked_visibility = map_lookup_kernels.stacked_visibility
    _nearest_run = map_lookup_kernels.nearest_run
    digest = hashlib.sha256()
    for module in (lighting, map_lookup_kernels):
        with open(module.__file__, "rb") as source:
            digest.update(source.read())
    lighting_stamp = int(digest.hexdigest()[:15], 16)

    @numba.njit(inline="always", cache=True)
    def lerp(values, side, v0, v1, v2, b0, b1, b2, j):  # pragma: no cover - compiled
        return (b0 * values[side, v0, j] + b1 * values[side, v1, j]) + b2 * values[side, v2, j]

    global _lerp
    _lerp = lerp

    # numpy's error model (a division by zero gives inf or nan, as in numpy and in a parallel
    # loop's body, where numba uses it too): Python's would test every division and keep LLVM
    # from optimising the row's loops (measured: 2× the time per frame).
    def plain_row(
        row, width, from_winners, index, tri, bary, frag_depth, frag_front,
        source, sub_front, xe, ye, area, ea, eb, ec, z, w, weights, two_sided,
        geometry, materials, lights, flags, frequencies, fog, has_vis, vis, vis_mean, vis_index,
        maps, world, n_opaque, offsets, max_layers, max_list,
        o_rgba, o_amb, o_dif, o_spe, o_nrm, o_depth, o_shadow, group_of, group_base, o_groups,
        r_bary, r_vis,
    ):  # fmt: skip  # pragma: no cover - compiled
        # Per pixel, its visible fragments: ``index[pixel]`` is the z-buffer's winning
        # sub-triangle (from_winners: barycentrics and depth as ``finish`` computes them) or the
        # opaque fragment's index into (tri, bary, frag_depth, frag_front); −1 where none. Its row
        # of (vis, vis_mean) is ``o`` for fragments, ``vis_index[pixel]`` for winners. Each
        # fragment: surface_at_fragments_compiled's interpolation, the lighting kernel's
        # equation (point_terms), shading._shade_phong's colour (gl_clamp under gl_compat), the
        # colour stage's premultiplied (α·c, α) and per-fragment fog (_fogged) — _shade_fragment,
        # inlined. With transparent fragments (``offsets`` non-empty: the pixel's fragments
        # ``n_opaque + offsets[pixel] ...`` in draw order), resolve_frame_compiled's A-buffer:
        # sorted by depth (stable), the nearest ``max_layers`` composited front to back, over
        # the opaque colour; the passes, normal and depth of the nearest. Then resolve's float32
        # writes, with the same operations in the same order. One row per call: the parallel loop
        # of ``plain`` stays a few lines (numba's parallel transformation of a large loop body
        # is what made this kernel slow to compile: docs/compile.md).
        # Light groups (``o_groups`` (G, H, W, 3), G > 0): each fragment's colour per group, its
        # base ``group_base[mid, g]`` plus its lights' terms (point_terms with ``group_of``),
        # premultiplied, fogged towards black (the fog factor alone) and composited with the
        # same coverage as the frame's colour; Gouraud meshes are not split (the caller does
        # not ask for groups then).
        triangles, triangle_mesh, eye_pos, eye_n, world_n = geometry
        bases, a_cms, d_cms, s_cms, shininesses, opacity = materials
        pos, spot_dir, cos_cut, spot_exp, atten, l_amb, l_dif, l_spe = lights
        local_viewer, blinn, gl_compat, separate = flags
        mode_of, vertex_terms, winding, view_t = frequencies
        fog_mode, fog_radial, density, start, end, cr, cg, cb = fog
        m_first = maps[3]  # one entry per lit light with shadow maps (none: empty)
        # shadow maps (``r_bary``, ``r_vis``: the row's covered pixels' depth and barycentrics
        # and their visibility per light, found by map_row before this call)
        n_lit = m_first.shape[0]
        has_maps = n_lit > 0
        lists = offsets.shape[0] > 0
        row_stamp = np.zeros(0, np.int64)
        row_stamp[:0] = lighting_stamp  # (a reference that keeps the stamp in the cache key)
        order = np.empty(max(max_list, 1), np.int64)  # scratch of the row's thread
        r_vis3 = r_vis.reshape((r_vis.shape[0], r_vis.shape[1], 1))
        j_cov = 0  # the next covered pixel of the row (maps)
        n_groups = o_groups.shape[0]
        g_frag = np.zeros((n_groups, 3))  # a fragment's colour per group
        g_acc = np.zeros((n_groups, 3))  # the pixel's composited colour per group
        n_row = 0
        cy = row + 0.5
        for col in range(width):
            key = row * width + col
            o = index[key]
            count = 0
            first = 0
            if lists:
                first = n_opaque + offsets[key]
                count = offsets[key + 1] - offsets[key]
            if o < 0 and count == 0:
                for ch in range(4):
                    o_rgba[row, col, ch] = 0.0
                for ch in range(3):
                    o_amb[row, col, ch] = 0.0
                    o_dif[row, col, ch] = 0.0
                    o_spe[row, col, ch] = 0.0
                    o_nrm[row, col, ch] = 0.0
                o_depth[row, col] = np.float32(1.0)
                if has_vis:
                    o_shadow[row, col, 0] = 0.0
                for g in range(n_groups):
                    for ch in range(3):
                        o_groups[g, row, col, ch] = 0.0
                continue
            n_row += 1
            for g in range(n_groups):
                for ch in range(3):
                    g_acc[g, ch] = 0.0
            # The pixel's fragments, front to back: the nearest ``max_layers`` transparent ones
            # sorted by depth (stable in draw order), then the opaque one; each composited
            # under the ones before it (resolve's "B over A": acc = c·(1 − acc_α) + acc, and
            # the opaque one as src-over's acc + c·(1 − acc_α), the same sum). The first gives
            # the passes, normal and depth.
            for j in range(count):  # insertion sort by depth, stable in draw order
                f = first + j
                p = j
                while p > 0 and frag_depth[order[p - 1]] > frag_depth[f]:
                    order[p] = order[p - 1]
                    p -= 1
                order[p] = f
            layers = min(count, max_layers)
            acc0 = acc1 = acc2 = acc3 = 0.0
            n_a = n_ar = n_ag = n_ab = n_dr = n_dg = n_db = n_sr = n_sg = n_sb = 0.0
            n_wx = n_wy = n_wz = n_depth = 0.0
            n_v = 0
            for step in range(layers + (1 if o >= 0 else 0)):
                if step < layers:
                    f = order[step]
                    v = f
                    b0, b1, b2 = bary[f, 0], bary[f, 1], bary[f, 2]
                    depth = frag_depth[f]
                    src = tri[f]
                    front = frag_front[f]
                elif from_winners and has_maps:  # found above, with the row's visibilities
                    v = j_cov
                    depth, b0, b1, b2 = r_bary[v, 0], r_bary[v, 1], r_bary[v, 2], r_bary[v, 3]
                    j_cov += 1
                    src = source[o]
                    front = sub_front[o]
                elif from_winners:
                    v = vis_index[key] if has_vis else o
                    depth, b0, b1, b2 = _winner_point(
                        o, col + 0.5, cy, xe, ye, area, ea, eb, ec, z, w, weights
                    )
                    src = source[o]
                    front = sub_front[o]
                else:
                    v = o
                    b0, b1, b2 = bary[o, 0], bary[o, 1], bary[o, 2]
                    depth = frag_depth[o]
                    src = tri[o]
                    front = frag_front[o]
                back = 1 if two_sided and not front else 0
                v0, v1, v2 = triangles[src, 0], triangles[src, 1], triangles[src, 2]
                px = b0 * eye_pos[v0, 0] + b1 * eye_pos[v1, 0] + b2 * eye_pos[v2, 0]
                py = b0 * eye_pos[v0, 1] + b1 * eye_pos[v1, 1] + b2 * eye_pos[v2, 1]
                pz = b0 * eye_pos[v0, 2] + b1 * eye_pos[v1, 2] + b2 * eye_pos[v2, 2]
                mesh = triangle_mesh[src]
                mid = 2 * mesh + back
                mode = mode_of[mesh]
                # fog is a function of the fragment's own point; a flat face is lit at its centroid
                fx, fy, fz = px, py, pz
                nx = ny = nz = 0.0
                if mode == 1:  # flat: lit at the face's eye-space centroid with its face normal
                    px = ((eye_pos[v0, 0] + eye_pos[v1, 0]) + eye_pos[v2, 0]) / 3.0
                    py = ((eye_pos[v0, 1] + eye_pos[v1, 1]) + eye_pos[v2, 1]) / 3.0
                    pz = ((eye_pos[v0, 2] + eye_pos[v1, 2]) + eye_pos[v2, 2]) / 3.0
                    nx, ny, nz = _unit_face_normal(eye_pos, v0, v1, v2)
                    nx, ny, nz = nx * winding[mesh], ny * winding[mesh], nz * winding[mesh]
                    # the world normal: the view's normal matrix undone (n_world ∝ Vᵀ n_eye)
                    wx = view_t[0, 0] * nx + view_t[0, 1] * ny + view_t[0, 2] * nz
                    wy = view_t[1, 0] * nx + view_t[1, 1] * ny + view_t[1, 2] * nz
                    wz = view_t[2, 0] * nx + view_t[2, 1] * ny + view_t[2, 2] * nz
                    length = math.sqrt(wx * wx + wy * wy + wz * wz)
                    scale = 1.0 / length if length > 0 else 0.0
                    wx, wy, wz = wx * scale, wy * scale, wz * scale
                    if back:
                        nx, ny, nz = -nx, -ny, -nz
                else:
                    wx = b0 * world_n[v0, 0] + b1 * world_n[v1, 0] + b2 * world_n[v2, 0]
                    wy = b0 * world_n[v0, 1] + b1 * world_n[v1, 1] + b2 * world_n[v2, 1]
                    wz = b0 * world_n[v0, 2] + b1 * world_n[v1, 2] + b2 * world_n[v2, 2]
                    length = math.sqrt(wx * wx + wy * wy + wz * wz)
                    scale = 1.0 / length if length > 0 else 0.0
                    wx, wy, wz = wx * scale, wy * scale, wz * scale
                if mode == 0:  # phong: the interpolated eye-space normal, renormalised
                    nx = b0 * eye_n[v0, 0] + b1 * eye_n[v1, 0] + b2 * eye_n[v2, 0]
                    ny = b0 * eye_n[v0, 1] + b1 * eye_n[v1, 1] + b2 * eye_n[v2, 1]
                    nz = b0 * eye_n[v0, 2] + b1 * eye_n[v1, 2] + b2 * eye_n[v2, 2]
                    length = math.sqrt(nx * nx + ny * ny + nz * nz)
                    scale = (1.0 / length if length > 0 else 0.0) * (-1.0 if back else 1.0)
                    nx, ny, nz = nx * scale, ny * scale, nz * scale
                if mode == 2:  # gouraud: the vertices' terms interpolated (raster.interpolate's sums)
                    ar = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 0)
                    ag = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 1)
                    ab = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 2)
                    dr = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 3)
                    dg = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 4)
                    db = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 5)
                    sr = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 6)
                    sg = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 7)
                    sb = _lerp(vertex_terms, back, v0, v1, v2, b0, b1, b2, 8)
                else:  # one call site of the (inlined) lighting equation for flat and phong
                    for g in range(n_groups):
                        for ch in range(3):
                            g_frag[g, ch] = group_base[mid, g, ch]
                    ar, ag, ab, dr, dg, db, sr, sg, sb = _point_terms(
                        v, px, py, pz, nx, ny, nz, mid, bases, a_cms, d_cms, s_cms, shininesses,
                        pos, spot_dir, cos_cut, spot_exp, atten, l_amb, l_dif, l_spe, local_viewer, blinn,
                        has_vis, r_vis3 if has_maps else vis, group_of, g_frag,
                    )  # fmt: skip
                r, g, b = ar + dr + sr, ag + dg + sg, ab + db + sb  # ShadingTerms.color
                if gl_compat:  # lighting.gl_clamp, then the colour sum clamped
                    if separate:
                        r = min(max(min(max(ar + dr, 0.0), 1.0) + min(max(sr, 0.0), 1.0), 0.0), 1.0)
                        g = min(max(min(max(ag + dg, 0.0), 1.0) + min(max(sg, 0.0), 1.0), 0.0), 1.0)
                        b = min(max(min(max(ab + db, 0.0), 1.0) + min(max(sb, 0.0), 1.0), 0.0), 1.0)
                    else:
                        r = min(max(min(max(r, 0.0), 1.0) + 0.0, 0.0), 1.0)
                        g = min(max(min(max(g, 0.0), 1.0) + 0.0, 0.0), 1.0)
                        b = min(max(min(max(b, 0.0), 1.0) + 0.0, 0.0), 1.0)
                a = opacity[mid]
                pr, pg, pb = a * r, a * g, a * b  # premultiplied (α·c, α): fragment_colours' order
                if fog_mode >= 0:
                    pr, pg, pb = _fogged(
                        fog_mode, fog_radial, density, start, end, cr, cg, cb, fx, fy, fz, pr, pg, pb, a
                    )
                cover = 1.0 - acc3
                if n_groups > 0:
                    f_fog = 1.0  # fog towards black: f·(α·c)
                    if fog_mode >= 0:
                        f_fog = _fogged(
                            fog_mode, fog_radial, density, start, end, 0.0, 0.0, 0.0, fx, fy, fz,
                            1.0, 1.0, 1.0, a,
                        )[0]  # fmt: skip
                    for g in range(n_groups):
                        for ch in range(3):
                            g_acc[g, ch] = (f_fog * (a * g_frag[g, ch])) * cover + g_acc[g, ch]
                acc0 = pr * cover + acc0
                acc1 = pg * cover + acc1
                acc2 = pb * cover + acc2
                acc3 = a * cover + acc3
                if step == 0:  # the nearest fragment: passes, normal, depth, shadow
                    n_a = a
                    n_ar, n_ag, n_ab, n_dr, n_dg, n_db, n_sr, n_sg, n_sb = (
                        ar,
                        ag,
                        ab,
                        dr,
                        dg,
                        db,
                        sr,
                        sg,
                        sb,
                    )
                    n_wx, n_wy, n_wz = wx, wy, wz
                    n_depth = depth
                    n_v = v
            pr, pg, pb, a_over, a = acc0, acc1, acc2, acc3, n_a
            ar, ag, ab, dr, dg, db, sr, sg, sb = n_ar, n_ag, n_ab, n_dr, n_dg, n_db, n_sr, n_sg, n_sb
            wx, wy, wz, depth, v = n_wx, n_wy, n_wz, n_depth, n_v
            # ``0.0 + x`` keeps numpy's sign of zero (a sum of one term), as resolve does.
            o_rgba[row, col, 0] = 0.0 + np.float32(pr)
            o_rgba[row, col, 1] = 0.0 + np.float32(pg)
            o_rgba[row, col, 2] = 0.0 + np.float32(pb)
            o_rgba[row, col, 3] = 0.0 + np.float32(a_over)
            o_amb[row, col, 0] = 0.0 + np.float32(ar * a)
            o_amb[row, col, 1] = 0.0 + np.float32(ag * a)
            o_amb[row, col, 2] = 0.0 + np.float32(ab * a)
            o_dif[row, col, 0] = 0.0 + np.float32(dr * a)
            o_dif[row, col, 1] = 0.0 + np.float32(dg * a)
            o_dif[row, col, 2] = 0.0 + np.float32(db * a)
            o_spe[row, col, 0] = 0.0 + np.float32(sr * a)
            o_spe[row, col, 1] = 0.0 + np.float32(sg * a)
            o_spe[row, col, 2] = 0.0 + np.float32(sb * a)
            o_nrm[row, col, 0] = 0.0 + np.float32(wx)
            o_nrm[row, col, 1] = 0.0 + np.float32(wy)
            o_nrm[row, col, 2] = 0.0 + np.float32(wz)
            o_depth[row, col] = min(np.float32(1.0), np.float32(depth))
            if has_maps:  # resolve.shadow_pass_values: summed in light order, then divided
                mean = r_vis[v, 0]
                for i_light in range(1, n_lit):
                    mean += r_vis[v, i_light]
                mean /= n_lit
                o_shadow[row, col, 0] = 0.0 + np.float32(mean * a)
            elif has_vis:
                o_shadow[row, col, 0] = 0.0 + np.float32(vis_mean[v] * a)
            for g in range(n_groups):
                for ch in range(3):
                    o_groups[g, row, col, ch] = 0.0 + np.float32(g_acc[g, ch])
        return n_row

    plain_row = numba.njit(cache=True, error_model="numpy")(plain_row)
    # module globals, not closure variables (as _point_terms: the disk cache's key)
    global _plain_row, _map_row_nearest, _map_row_filtered
    _plain_row = plain_row

    def make_map_row(filtered: bool) -> object:
        def map_row(
            row, width, index, xe, ye, area, ea, eb, ec, z, w, weights, source, triangles, world, maps,
            r_bary, r_pts, r_vis, s_qx, s_qy, s_qz, s_cw, s_face,
        ):  # fmt: skip  # pragma: no cover - compiled
            # The row's covered pixels first: each winner's depth and barycentrics (read back by
            # plain_row), its world point (as winner_surface) and its visibility per light
            # (map_lookup_kernels.visibility_at, opaque winners only, no normal offset), in runs over the
            # row (map_lookup_kernels.nearest_run: tight loops of divisions), or per point
            # (stacked_visibility: the PCF kernels). Compiled only for frames with shadow maps.
            m_depth, m_vp, m_vz, m_first, m_faces, m_pos, m_kernel, m_rects, m_miss = maps
            n_lit = m_first.shape[0]
            no_faces = np.zeros(0, np.int8)
            # nearest_run's integers and flag as int64 / bool variables, never literals: a literal
            # (0, False) is a type of its own, and would compile specialisations of nearest_run
            # apart from the one the general path's look-up (_lookup_nearest_share) compiles
            zero = np.int64(0)
            no_reuse = no_faces.shape[0] != 0
            n_cov = zero
            for col in range(width):
                o = index[row * width + col]
                if o < 0:
                    continue
                depth, b0, b1, b2 = _winner_point(
                    o, col + 0.5, row + 0.5, xe, ye, area, ea, eb, ec, z, w, weights
                )
                r_bary[n_cov, 0], r_bary[n_cov, 1], r_bary[n_cov, 2], r_bary[n_cov, 3] = depth, b0, b1, b2
                src = source[o]
                v0, v1, v2 = triangles[src, 0], triangles[src, 1], triangles[src, 2]
                for k in range(3):
                    r_pts[n_cov, k] = _interpolated(world, v0, v1, v2, b0, b1, b2, k)  # as winner_surface
                n_cov += 1
            for i_light in range(n_lit):
                f0 = m_first[i_light]
                if f0 < 0:
                    for j in range(n_cov):
                        r_vis[j, i_light] = 1.0
                    continue
                cube = 1 if m_faces[i_light] == 6 else 0
                if m_kernel[i_light] == 0:
                    _nearest_run(
                        r_pts, zero, n_cov, m_depth, m_vp, f0, cube, m_pos[i_light], no_faces, no_reuse,
                        r_vis, i_light, zero, s_qx, s_qy, s_qz, s_cw, s_face, m_rects, m_miss,
                    )  # fmt: skip
                    continue
                if filtered:  # a constant: the nearest-only variant never compiles stacked_visibility
                    for j in range(n_cov):
                        r_vis[j, i_light] = _stacked_visibility(
                            r_pts[j, 0], r_pts[j, 1], r_pts[j, 2], 0.0, 0.0, 0.0,
                            m_depth, m_vp, m_vz, f0, cube, m_pos[i_light], 0.0, m_kernel[i_light],
                            m_rects, m_miss,
                        )  # fmt: skip

        return map_row

    # Two variants, cached apart by name: frames whose maps are all looked up at the nearest
    # texel (the default) do not compile the percentage-closer filters (stacked_visibility).
    for filtered in (False, True):
        variant = make_map_row(filtered)
        variant.__qualname__ += ".filtered" if filtered else ".nearest"  # type: ignore[attr-defined]
        compiled = numba.njit(cache=True, error_model="numpy")(variant)
        if filtered:
            _map_row_filtered = compiled
        else:
            _map_row_nearest = compiled


@functools.lru_cache(maxsize=3)
def _plain_kernel(with_maps: bool = False, filtered: bool = False) -> object:  # a numba dispatcher
    """The fused frame kernel; ``with_maps``: the variant that looks shadow maps up itself, at the
    nearest texel only, or with percentage-closer filters too (``filtered``).

    Variants of the short loop over a share of rows, so that a frame without shadow maps does
    not compile the shadow-map look-ups (``map_row``, ``map_lookup_kernels.nearest_run``, about
    3 s of compilation), and one with nearest look-ups only not the filters
    (``stacked_visibility``, about 1 s): the branches on the constants are removed before numba
    types the function, and the variants are cached apart (their names and closure values
    differ). All call the same row function (compiled once)."""
    import numba

    _row_kernels()

    def plain(
        width, height, row_order, from_winners, index, tri, bary, frag_depth, frag_front,
        source, sub_front, xe, ye, area, ea, eb, ec, z, w, weights, two_sided,
        geometry, materials, lights, flags, frequencies, fog, has_vis, vis, vis_mean, vis_index,
        maps, world, n_opaque, offsets, max_layers, max_list,
        o_rgba, o_amb, o_dif, o_spe, o_nrm, o_depth, o_shadow, group_of, group_base, o_groups,
    ):  # fmt: skip  # pragma: no cover - compiled
        # The rows ``row_order`` (a share of the frame's: compositing._threads runs the shares on
        # threads, the GIL released); each row is written by one call of plain_row, so there are
        # no write races. Returns the number of covered pixels. ``with_maps`` (a constant: the
        # branch is removed before typing) — the variant that looks the shadow maps up first.
        n_lit = maps[3].shape[0]
        scratch = width if with_maps and n_lit > 0 else 0
        r_bary = np.empty((scratch, 4))  # the row's winners (depth, b0, b1, b2) ...
        r_pts = np.empty((scratch, 3))  # ... world points and visibilities
        r_vis = np.empty((scratch, max(n_lit, 1)))
        s_qx = np.empty(scratch)
        s_qy = np.empty(scratch)
        s_qz = np.empty(scratch)
        s_cw = np.empty(scratch)
        s_face = np.zeros(scratch, np.int64)
        covered = 0
        for i_row in range(row_order.shape[0]):
            row = row_order[i_row]
            if with_maps:
                if n_lit > 0:
                    if filtered:
                        _map_row_filtered(
                            row, width, index, xe, ye, area, ea, eb, ec, z, w, weights, source,
                            geometry[0], world, maps, r_bary, r_pts, r_vis, s_qx, s_qy, s_qz, s_cw, s_face,
                        )  # fmt: skip
                    else:
                        _map_row_nearest(
                            row, width, index, xe, ye, area, ea, eb, ec, z, w, weights, source,
                            geometry[0], world, maps, r_bary, r_pts, r_vis, s_qx, s_qy, s_qz, s_cw, s_face,
                        )  # fmt: skip
            covered += _plain_row(
                row, width, from_winners, index, tri, bary, frag_depth, frag_front,
                source, sub_front, xe, ye, area, ea, eb, ec, z, w, weights, two_sided,
                geometry, materials, lights, flags, frequencies, fog, has_vis, vis, vis_mean, vis_index,
                maps, world, n_opaque, offsets, max_layers, max_list,
                o_rgba, o_amb, o_dif, o_spe, o_nrm, o_depth, o_shadow, group_of, group_base, o_groups,
                r_bary, r_vis,
            )  # fmt: skip
        return covered

    variant = ("maps_filtered" if filtered else "maps") if with_maps else "plain"
    plain.__qualname__ += f".{variant}"
    return numba.njit(cache=True, nogil=True)(plain)


def _run_plain(*args: object, with_maps: bool = False, filtered: bool = False) -> int:
    """Run the fused kernel: the frame's rows in shares on threads
    (:func:`compositing._threads.run_shares`; the kernel releases the GIL).

    Its first compilation (once per machine: the kernel is disk-cached) makes numba's own
    pedantic SSA check warn about variables of the inlined lighting helpers that it expects in
    scope (``NumbaIRAssumptionWarning``, "please report"); the compiled code is unaffected (the
    fused frame equals the numpy engine's, tested), so that warning is not passed on to the user.
    """
    from numba.core.errors import NumbaIRAssumptionWarning

    from compositing._threads import run_shares

    kernel = _plain_kernel(with_maps, with_maps and filtered)
    width, height, row_order, *rest = args
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaIRAssumptionWarning)
        # compiled (or loaded) on this thread first: the shares' threads then only run it
        kernel(width, height, row_order[:0], *rest)  # type: ignore[operator]
        shares = run_shares(lambda rows: kernel(width, height, rows, *rest), row_order)  # type: ignore[operator]
    return int(sum(shares))


_NO_SETUP = (
    np.zeros(0, np.int64), np.zeros(0, np.bool_), *(np.zeros((0, 3)) for _ in range(2)), np.zeros(0),
    *(np.zeros((0, 3)) for _ in range(5)), np.zeros((0, 3, 3)),
)  # fmt: skip
_NO_FRAGMENTS = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.bool_))
_NO_INDEX = np.zeros(0, np.int64)
#: No shadow maps for the fused kernel (the fields of blinn_phong.shadows.frame_maps.MapStack), no world
#: vertices.
_NO_MAPS = (
    np.zeros((0, 1, 1)), np.zeros((0, 4, 4)), np.zeros((0, 3)), np.zeros(0, np.int64),
    np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 4), np.int64),
    np.zeros(1, np.int64),
)  # fmt: skip
_NO_WORLD = np.zeros((0, 3))
_NO_WORLD.flags.writeable = False  # one signature: the kernel reads world vertices as read-only views
#: No light groups for the fused kernel: ``(group_of, group_base, out)``.
_NO_GROUPS = (np.zeros(0, np.int64), np.zeros((0, 0, 3)), np.zeros((0, 0, 0, 3), np.float32))


def _group_args(
    groups: tuple[np.ndarray, np.ndarray, np.ndarray] | None, n_lights: int, height: int, width: int,
    n_materials: int,
) -> tuple[np.ndarray, ...]:  # fmt: skip
    """The fused kernel's ``(group_of, group_base, o_groups)`` of ``groups`` (see
    :func:`shade_plain_fragments_compiled`), checked, or :data:`_NO_GROUPS`."""
    if groups is None:
        return _NO_GROUPS
    group_of, base, out = groups
    group_of = np.ascontiguousarray(group_of, dtype=np.int64)
    base = np.ascontiguousarray(base, dtype=np.float64)
    n = out.shape[0] if out.ndim == 4 else -1
    if group_of.shape != (n_lights,) or (group_of >= n).any() or base.shape != (n_materials, n, 3):
        raise ValueError(
            f"groups: expected group_of ({n_lights},) < G and base ({n_materials}, G, 3) for out "
            f"(G, H, W, 3), got {group_of.shape}, {base.shape} and {out.shape}"
        )
    if n < 1 or out.shape[1:] != (height, width, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(
            f"groups: expected out a C-contiguous float32 (G ≥ 1, {height}, {width}, 3) array, "
            f"got {out.dtype} {out.shape}"
        )
    return group_of, base, out


#: What the fused plain kernels read of a prepared scene: ``(two_sided, geometry, materials,
#: lights, flags, frequencies)`` with geometry ``(triangles, triangle_mesh, eye_position, eye_normal,
#: world_normal)``, materials and lights as :func:`blinn_phong.frame.lighting.material_tables` and
#: :func:`blinn_phong.frame.lighting.light_tables` give them, flags ``(local_viewer, blinn,
#: gl_compat, separate_specular)``, frequencies ``(mode, vertex_terms, winding, view_t)`` as
#: :func:`blinn_phong.frame.shading.plain_tables` gives them (per mesh: 0 phong, 1 flat, 2 gouraud).
_Arrays = tuple[np.ndarray, ...]
PlainTables = tuple[bool, _Arrays, _Arrays, _Arrays, tuple, _Arrays]


def shade_plain_fragments_compiled(
    width: int,
    height: int,
    opaque_of: np.ndarray,
    triangle: np.ndarray,
    bary: np.ndarray,
    depth: np.ndarray,
    front_facing: np.ndarray,
    tables: PlainTables,
    visibility: np.ndarray | None,
    vis_mean: np.ndarray | None,
    out: tuple[np.ndarray, ...],
    fog: FogArgs = None,
    transparent: tuple[int, np.ndarray, int] | None = None,
    groups: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> None:
    """The frame's shading and resolve fused: each pixel's fragments shaded, resolved and written.

    For one sample per pixel, no transparency resolve, per-pixel (phong) shading and
    partial-occlusion colours ``(α·c, α)``: per pixel, the fragment ``opaque_of[pixel]`` (−1:
    empty) is interpolated (as :func:`surface_at_fragments_compiled`), lit by
    :func:`blinn_phong.frame.lighting.point_terms` with ``visibility`` (N, L, K) (K = 1 or 3), fogged
    when ``fog`` is given (``(mode, radial, (density, start, end), colour)`` as for
    :func:`fragment_colours_compiled`, by the same compiled function: OpenGL 2.1 §3.10 on the
    premultiplied colour; the light passes are not fogged) and written into the float32
    ``out = (rgba, ambient, diffuse, specular, normal, depth, shadow)`` buffers as
    :func:`resolve_plain_compiled` writes them: the same images as the separate shading,
    colour and resolve stages, without their (N, 3) float64 arrays.

    ``transparent``: ``(n_opaque, offsets, max_layers)`` of a frame with transparent fragments
    (:class:`blinn_phong.frame.visibility.FrameFragments`: the fragments ``n_opaque + offsets[p] …
    n_opaque + offsets[p + 1]`` of pixel ``p``, in draw order, in front of its opaque one),
    resolved as the A-buffer (``max_layers`` ≥ the longest list) or depth peeling
    (``max_layers`` = the layers) of :func:`resolve_frame_compiled`: sorted by depth, the
    nearest ``max_layers`` composited front to back over the opaque colour; passes, normal and
    depth of the nearest fragment.

    ``groups``: None, or light groups' passes (:mod:`blinn_phong.frame.light_groups`) made in the same
    pass: ``(group_of, base, out)`` with ``group_of`` (L,) int64 the group of each light of the
    tables (−1: none), ``base`` (2·M, G, 3) float64 each material side's terms that do not depend
    on a light of the tables, per group (emission, ``a_cm``·global ambient, ``a_cm``·ambient
    lights), and ``out`` (G, H, W, 3) float32, written like ``rgba``'s colour: each fragment's
    colour from group g's emitters alone, premultiplied, fogged towards black (the fog factor
    applied), composited with the frame's coverages. Not for Gouraud-shaded meshes (their
    vertex terms are not split by group).
    """
    two_sided, geometry, materials, lights, flags, frequencies = tables
    fragments = (
        np.ascontiguousarray(triangle, dtype=np.int64), np.ascontiguousarray(bary),
        np.ascontiguousarray(depth), np.ascontiguousarray(front_facing, dtype=np.bool_),
    )  # fmt: skip
    lists: tuple[int, np.ndarray, int, int] = (0, _NO_INDEX, 0, 0)
    if transparent is not None:
        n_opaque, offsets, max_layers = transparent
        offsets = np.ascontiguousarray(offsets, dtype=np.int64)
        longest = int(np.diff(offsets).max(initial=0))
        if max_layers < 1:
            raise ValueError(f"transparent: max_layers must be >= 1, got {max_layers}")
        lists = (int(n_opaque), offsets, int(max_layers), longest)
    _run_plain(
        width, height, _row_order(height), False, opaque_of, *fragments, *_NO_SETUP, two_sided,
        geometry, materials, lights, flags, frequencies, _fog_scalars(fog), visibility is not None,
        np.zeros((0, 0, 1)) if visibility is None else np.ascontiguousarray(visibility, dtype=np.float64),
        np.zeros(0) if vis_mean is None else np.ascontiguousarray(vis_mean, dtype=np.float64),
        _NO_INDEX, _NO_MAPS, _NO_WORLD, *lists, *out,
        *_group_args(groups, len(lights[0]), height, width, len(materials[0])),
    )  # fmt: skip


def shade_plain_winners_compiled(
    setup: _TriangleSetup,
    winner: np.ndarray,
    tables: PlainTables,
    out: tuple[np.ndarray, ...],
    fog: FogArgs = None,
    visibility: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    maps: tuple[tuple[np.ndarray, ...], np.ndarray] | None = None,
    groups: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> int:
    """:func:`shade_plain_fragments_compiled` straight from the z-buffer's winners (one sample per
    pixel, ``fog`` as there): barycentrics and depth as :func:`frame_fragments_compiled` computes
    them, in the same pass.

    ``visibility``: None, or ``(vis, vis_mean, rank)`` for shadowed frames: ``vis`` (N, L, K)
    and ``vis_mean`` (N,) of the covered pixels in row-major order, ``rank`` (H·W,) each pixel's
    row in them (−1 where empty), as :func:`winner_surfaces_compiled` numbers them.

    ``maps``: None, or ``(stack, world_vertices)`` for a frame whose every shadowed light is
    shadow-mapped (``visibility`` None): a :class:`blinn_phong.shadows.frame_maps.MapStack` of the maps
    of every non-ambient light and the (V, 3) float64 world positions of the prepared scene's
    vertices. Each pixel's world point (as :func:`winner_surfaces_compiled` computes it) is
    looked up in the maps as it is shaded (:func:`blinn_phong.shadows.map_lookup_kernels.stacked_visibility`),
    and the shadow pass is the mean of its visibilities
    (:func:`blinn_phong.frame.resolve.shadow_pass_values`).

    ``groups``: light groups' passes made in the same pass, as for
    :func:`shade_plain_fragments_compiled`.

    Returns the number of covered pixels (fragments shaded)."""
    if setup.k != 1:
        raise ValueError(f"setup: expected one sample per pixel, got {setup.k * setup.k}")
    two_sided, geometry, materials, lights, flags, frequencies = tables
    sub = (
        setup.source, setup.front, setup.x_exact, setup.y_exact, setup.area, setup.a, setup.b, setup.c,
        setup.z, setup.w, np.ascontiguousarray(setup.weights),
    )  # fmt: skip
    if visibility is not None and maps is not None:
        raise ValueError("visibility and maps: expected at most one of them")
    if visibility is None:
        vis, vis_mean, rank = np.zeros((0, 0, 1)), np.zeros(0), _NO_INDEX
    else:
        vis, vis_mean, rank = (np.ascontiguousarray(a) for a in visibility)
        vis = vis.astype(np.float64, copy=False)
        vis_mean = vis_mean.astype(np.float64, copy=False)
    stack, world = _NO_MAPS, _NO_WORLD
    if maps is not None:
        stack, world = tuple(maps[0]), np.ascontiguousarray(maps[1], dtype=np.float64).view()
        world.flags.writeable = False  # typed as _NO_WORLD is: one compiled specialisation
        if len(stack[3]) != len(lights[0]):
            raise ValueError(
                f"maps: expected one entry per non-ambient light ({len(lights[0])}), got {len(stack[3])}"
            )
    return int(
        _run_plain(
            setup.width, setup.height, _row_order(setup.height), True, winner, *_NO_FRAGMENTS, *sub,
            two_sided, geometry, materials, lights, flags, frequencies, _fog_scalars(fog),
            visibility is not None or maps is not None, vis, vis_mean, rank, stack, world, 0, _NO_INDEX, 0, 0,
            *out, *_group_args(groups, len(lights[0]), setup.height, setup.width, len(materials[0])),
            with_maps=maps is not None,
            filtered=maps is not None and bool(np.any(np.asarray(stack[6]) != 0)),  # a PCF kernel
        )
    )  # fmt: skip
