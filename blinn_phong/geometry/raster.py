"""Triangle rasterization with OpenGL conventions, returning every fragment.

:func:`rasterize` turns clip-space triangles into *all* the fragments they cover
(not only the nearest), so the same call serves a z-buffer
(:func:`resolve_nearest`), an A-buffer, depth peeling, order-independent
transparency and shadow maps (depth seen from a light's camera).

Conventions (OpenGL 2.1 spec §2.11–2.12 and §3.5; the fill rule is Direct3D's
top-left rule):

* Clipping: triangles are clipped against the near plane ``z_c >= -w_c`` (new
  vertices interpolated linearly in clip space, §2.12); fragments with window
  depth > 1 (beyond the far plane) are dropped. x/y clipping is done by the
  screen bounds.
* Viewport: ``x_w = (x_ndc + 1)·width/2``, ``y_w = (y_ndc + 1)·height/2``,
  ``depth = (z_ndc + 1)/2`` (``glViewport(0, 0, w, h)``, ``glDepthRange(0, 1)``).
  Vertex window positions are snapped to 1/256 pixel (8 sub-pixel bits, as
  llvmpipe's fixed-point setup) so edge tests are exact.
* Sampling: pixel centres at +0.5. ``samples = k²`` places an ordered k×k grid of
  sample points in each pixel (centres of the k×k sub-pixels).
* Fill rule: the top-left rule in OpenGL window coordinates read in memory order
  (window y = 0 first), which is how Mesa llvmpipe applies it to framebuffer
  objects: a sample exactly on an edge belongs to the triangle if the edge is a
  *left* edge, or a horizontal edge with the interior at larger window y — in the
  returned top-row-first image, a *bottom* edge. Two triangles sharing an edge
  never both cover, and never both miss, a sample.
* Returned arrays use row 0 at the TOP: ``pixel = row·width + column``.
* Barycentrics are perspective-correct (§3.5.1 eq. 3.9): attributes linear in
  clip space interpolate exactly with them. Window depth is interpolated linearly
  in screen space (eq. 3.10).
* Facing: a triangle is front-facing when counter-clockwise in OpenGL window
  coordinates (``GL_CCW``), i.e. positive signed area with y up (§3.5.1 eq. 3.6).
  Zero-area triangles produce no fragments.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from blinn_phong._checks import float_array

__all__ = [
    "SUBPIXEL_BITS",
    "Fragments",
    "interpolate",
    "rasterize",
    "resolve_nearest",
    "sample_offsets",
]

#: Vertex window coordinates are snapped to 1/2**SUBPIXEL_BITS pixel.
SUBPIXEL_BITS = 8
_MAX_TILE = 64  # triangles with a larger bounding box are split into tiles of this size
_BATCH_ELEMENTS = 1 << 20  # pixels evaluated per vectorized batch (B·S·S)


@dataclass(frozen=True, eq=False)
class Fragments:
    """All fragments produced by :func:`rasterize` (one row per covered sample per triangle).

    Attributes:
        width, height: image size in pixels.
        samples: samples per pixel (k² for a k×k grid).
        pixel: (N,) int64 flat pixel index ``row·width + column``, row 0 at the top.
        sample: (N,) int64 sample index in [0, samples), row-major in the k×k grid
            (row 0 at the top).
        depth: (N,) float64 window depth in [0, 1] (0 = near plane).
        triangle: (N,) int64 index into the ``triangles`` array given to :func:`rasterize`.
        bary: (N, 3) float64 perspective-correct barycentrics on that triangle's three
            vertices (sum 1); use :func:`interpolate` to interpolate vertex attributes.
        front_facing: (N,) bool, True where the triangle is counter-clockwise in window space.
    """

    width: int
    height: int
    samples: int
    pixel: np.ndarray
    sample: np.ndarray
    depth: np.ndarray
    triangle: np.ndarray
    bary: np.ndarray
    front_facing: np.ndarray

    def __len__(self) -> int:
        return len(self.pixel)

    @property
    def sample_key(self) -> np.ndarray:
        """(N,) int64 ``pixel·samples + sample``: a flat index into a (height, width, samples) buffer."""
        return self.pixel * self.samples + self.sample

    def subset(self, index: np.ndarray) -> Fragments:
        """The fragments selected by a boolean mask or an integer index array."""
        return Fragments(
            self.width,
            self.height,
            self.samples,
            self.pixel[index],
            self.sample[index],
            self.depth[index],
            self.triangle[index],
            self.bary[index],
            self.front_facing[index],
        )


def sample_offsets(samples: int) -> np.ndarray:
    """(samples, 2) sample positions (x right, y down) inside a pixel, in [0, 1), for ``samples = k²``.

    The ordered k×k grid of sub-pixel centres ``((i + 0.5)/k, (j + 0.5)/k)``,
    row-major from the top; ``samples = 1`` gives the pixel centre (0.5, 0.5).
    """
    k = _grid_side(samples)
    j, i = np.mgrid[0:k, 0:k]
    return np.stack([(i.ravel() + 0.5) / k, (j.ravel() + 0.5) / k], axis=1)


def _grid_side(samples: object) -> int:
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or samples < 1:
        raise ValueError(f"samples: expected a positive perfect square (1, 4, 9, 16, ...), got {samples!r}")
    k = math.isqrt(int(samples))
    if k * k != samples:
        raise ValueError(
            f"samples: expected a perfect square (1, 4, 9, 16, ...) for a k×k grid, got {samples}"
        )
    return k


def _check_size(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name}: expected a positive integer number of pixels, got {value!r}")
    return int(value)


def _check_triangles(triangles: object, n_vertices: int) -> np.ndarray:
    tri = np.asarray(triangles)
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"triangles: expected shape (T, 3), got shape {tri.shape}")
    if tri.size and tri.dtype.kind not in "iu":
        raise TypeError(f"triangles: expected integer vertex indices, got dtype {tri.dtype}")
    tri = tri.astype(np.int64, copy=False)
    if tri.size and (tri.min() < 0 or tri.max() >= n_vertices):
        raise ValueError(
            f"triangles: indices must lie in [0, {n_vertices - 1}] for {n_vertices} vertices; "
            f"got range [{int(tri.min())}, {int(tri.max())}]"
        )
    return tri


# --------------------------------------------------------------------------- clipping


def _clip_near(clip_tri: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clip (T, 3, 4) clip-space triangles against ``z + w >= 0``.

    Returns (sub-triangle vertices (S, 3, 4), their weights on the source triangle's
    vertices (S, 3, 3), source triangle index (S,)). Vertex order (and so winding) is kept.
    """
    t_count = len(clip_tri)
    dist = clip_tri[:, :, 2] + clip_tri[:, :, 3]
    inside = dist >= 0
    n_in = inside.sum(axis=1)
    eye3 = np.eye(3)

    whole = np.flatnonzero(n_in == 3)
    verts = [clip_tri[whole]]
    weights = [np.broadcast_to(eye3, (len(whole), 3, 3))]
    source = [whole]

    for lone_inside, count in ((True, 1), (False, 2)):
        idx = np.flatnonzero(n_in == count)
        if len(idx) == 0:
            continue
        # Roll each triangle so the odd vertex (the lone inside one, or the lone outside one) comes first.
        odd = np.argmax(inside[idx] == lone_inside, axis=1)
        order = (odd[:, None] + np.arange(3)[None, :]) % 3
        d = np.take_along_axis(dist[idx], order, axis=1)
        w_a, w_b, w_c = (eye3[order[:, j]] for j in range(3))  # (n, 3) weights of rolled vertices a, b, c
        t_ab = (d[:, 0] / (d[:, 0] - d[:, 1]))[:, None]
        t_ac = (d[:, 0] / (d[:, 0] - d[:, 2]))[:, None]
        w_ab = w_a + t_ab * (w_b - w_a)
        w_ac = w_a + t_ac * (w_c - w_a)
        if lone_inside:  # a inside: triangle (a, ab, ac)
            subs = [np.stack([w_a, w_ab, w_ac], axis=1)]
        else:  # a outside: quad (ab, b, c, ca) -> (ab, b, c) and (ab, c, ca)
            subs = [np.stack([w_ab, w_b, w_c], axis=1), np.stack([w_ab, w_c, w_ac], axis=1)]
        for wsub in subs:
            weights.append(wsub)
            verts.append(np.einsum("sjm,smc->sjc", wsub, clip_tri[idx]))
            source.append(idx)
    if t_count == 0:
        return np.zeros((0, 3, 4)), np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    return np.concatenate(verts), np.concatenate(weights), np.concatenate(source)


# --------------------------------------------------------------------------- rasterization


def rasterize(
    clip_xyzw: np.ndarray,
    triangles: np.ndarray,
    width: int,
    height: int,
    *,
    samples: int = 1,
    cull_backfaces: bool = False,
    progress: Callable[[float], None] | None = None,
) -> Fragments:
    """Rasterize clip-space triangles and return every covered sample (see the module docstring).

    Args:
        clip_xyzw: (V, 4) clip-space vertex positions (``P @ V @ M @ p``), finite.
        triangles: (T, 3) integer vertex indices; counter-clockwise in window space = front.
        width: image width in pixels (> 0).
        height: image height in pixels (> 0).
        samples: samples per pixel, a perfect square k² (ordered k×k grid).
        cull_backfaces: drop triangles that are clockwise in window space (``GL_CULL_FACE``, ``GL_BACK``).
        progress: optional ``callback(fraction)`` called after each batch with the share of
            the triangle work done (for long renders).

    Returns:
        :class:`Fragments`, in no particular order.

    Raises:
        ValueError/TypeError: wrong shapes, non-finite positions, indices out of range,
            non-positive size, samples not a perfect square.
    """
    setup = _setup_triangles(clip_xyzw, triangles, width, height, samples, cull_backfaces)
    jobs = _tile_jobs(setup.selected, setup.x0, setup.x1, setup.y0, setup.y1)
    pieces: list[tuple[np.ndarray, ...]] = []
    total = sum(len(j[0]) * size * size for size, j in jobs.items())
    done = 0
    for size, (job_tri, job_x, job_y) in jobs.items():
        batch = max(1, _BATCH_ELEMENTS // (size * size))
        for start in range(0, len(job_tri), batch):
            stop = start + batch
            pieces.append(_cover(job_tri[start:stop], job_x[start:stop], job_y[start:stop], size, setup))
            done += len(job_tri[start:stop]) * size * size
            if progress is not None:
                progress(done / total)
    if pieces:
        frag_sub = np.concatenate([p[0] for p in pieces])
        fx = np.concatenate([p[1] for p in pieces])
        fy = np.concatenate([p[2] for p in pieces])
    else:
        frag_sub = np.zeros(0, np.int64)
        fx = fy = np.zeros(0, np.int64)
    return _fragments_from_hits(setup, frag_sub, fx, fy)


@dataclass(frozen=True, eq=False)
class _TriangleSetup:
    """Per (near-clipped) sub-triangle data shared by the numpy and compiled rasterizers."""

    width: int
    height: int
    k: int  # samples = k²; the fine grid is (k·width, k·height)
    source: np.ndarray  # (S,) input triangle index
    weights: np.ndarray  # (S, 3, 3) sub-vertex weights on the source triangle's vertices
    w: np.ndarray  # (S, 3) clip w
    x_exact: np.ndarray  # (S, 3) fine-grid window x (unsnapped)
    y_exact: np.ndarray  # (S, 3) fine-grid rows from the top (unsnapped)
    z: np.ndarray  # (S, 3) window depth
    area: np.ndarray  # (S,) signed area of the snapped triangle, y-down frame
    front: np.ndarray  # (S,) bool
    selected: np.ndarray  # indices of sub-triangles to rasterize, in draw order
    x0: np.ndarray  # (S,) bounding box in fine pixels (inclusive)
    x1: np.ndarray
    y0: np.ndarray
    y1: np.ndarray
    a: np.ndarray  # (S, 3) edge functions E_i = a·x + b·y + c (snapped, interior positive)
    b: np.ndarray
    c: np.ndarray
    top_left: np.ndarray  # (S, 3) bool, edge owns samples exactly on it


def _setup_triangles(
    clip_xyzw: np.ndarray, triangles: np.ndarray, width: int, height: int, samples: int, cull_backfaces: bool
) -> _TriangleSetup:
    """Validate, clip against the near plane, map to the (fine) window grid, build edge functions."""
    clip = float_array(clip_xyzw, "clip_xyzw", (None, 4))
    tri = _check_triangles(triangles, len(clip))
    width = _check_size(width, "width")
    height = _check_size(height, "height")
    k = _grid_side(samples)
    fine_w, fine_h = width * k, height * k

    sub_clip, sub_weights, sub_source = _clip_near(clip[tri])
    # Drop anything a non-standard projection leaves at w <= 0 after near clipping.
    ok = (sub_clip[:, :, 3] > 0).all(axis=1)
    sub_clip, sub_weights, sub_source = sub_clip[ok], sub_weights[ok], sub_source[ok]

    w = sub_clip[:, :, 3]
    ndc = sub_clip[:, :, :3] / w[:, :, None]
    scale = float(1 << SUBPIXEL_BITS)
    x_exact = (ndc[:, :, 0] + 1.0) * (0.5 * fine_w)
    y_exact = fine_h - (ndc[:, :, 1] + 1.0) * (0.5 * fine_h)  # rows counted from the top
    x = np.round(x_exact * scale) / scale  # snapped: coverage only
    y = fine_h - np.round((fine_h - y_exact) * scale) / scale
    z = (ndc[:, :, 2] + 1.0) * 0.5

    # Signed area in the y-down frame: negative <=> counter-clockwise with y up (front).
    area = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    front = area < 0
    keep = area != 0
    if cull_backfaces:
        keep &= front
    # Screen bounding boxes in (fine) pixel indices: first/last pixel whose centre lies inside.
    # Clipped to [-1, size] before the integer cast: window coordinates far outside the image
    # (vertices near 1e30, say) give an empty box instead of an overflowing cast.
    x0 = np.clip(np.ceil(x.min(axis=1) - 0.5), 0, fine_w).astype(np.int64)
    x1 = np.clip(np.floor(x.max(axis=1) - 0.5), -1, fine_w - 1).astype(np.int64)
    y0 = np.clip(np.ceil(y.min(axis=1) - 0.5), 0, fine_h).astype(np.int64)
    y1 = np.clip(np.floor(y.max(axis=1) - 0.5), -1, fine_h - 1).astype(np.int64)
    keep &= (x0 <= x1) & (y0 <= y1)

    # Edge functions E_i(p) = a_i·px + b_i·py + c_i for the edge opposite vertex i, signed so the
    # interior is positive. With positions on the 1/256 grid every value is exact in float64.
    sign = np.where(area < 0, -1.0, 1.0)
    a = np.empty((len(area), 3))
    b = np.empty((len(area), 3))
    c = np.empty((len(area), 3))
    for i, (j, kk) in enumerate(((1, 2), (2, 0), (0, 1))):
        xj, yj, xk, yk = x[:, j], y[:, j], x[:, kk], y[:, kk]
        a[:, i] = -(yk - yj) * sign
        b[:, i] = (xk - xj) * sign
        c[:, i] = ((yk - yj) * xj - (xk - xj) * yj) * sign
    # Top-left rule applied in OpenGL window coordinates taken in memory order (y_w = 0 first, as
    # llvmpipe does for framebuffer objects): the inward normal (a, b) of a left edge points right
    # (a > 0); a horizontal edge counts when the interior has larger y_w, i.e. lies above it in
    # the returned top-row-first image (inward normal points up in rows: a == 0, b < 0).
    top_left = (a > 0) | ((a == 0) & (b < 0))
    return _TriangleSetup(
        width,
        height,
        k,
        sub_source,
        sub_weights,
        w,
        x_exact,
        y_exact,
        z,
        area,
        front,
        np.flatnonzero(keep),
        x0,
        x1,
        y0,
        y1,
        a,
        b,
        c,
        top_left,
    )


def _fragments_from_hits(
    setup: _TriangleSetup, frag_sub: np.ndarray, fx: np.ndarray, fy: np.ndarray
) -> Fragments:
    """Barycentrics, depth and pixel/sample indices of covered fine-grid samples (fx, fy) of sub-triangles."""
    px, py = fx + 0.5, fy + 0.5
    edge = (
        setup.a[frag_sub] * px[:, None] + setup.b[frag_sub] * py[:, None] + setup.c[frag_sub]
        if len(frag_sub)
        else np.zeros((0, 3))
    )
    lam = _exact_barycentrics(setup.x_exact, setup.y_exact, frag_sub, px, py, setup.area, edge)
    depth = np.einsum("ni,ni->n", lam, setup.z[frag_sub])
    in_range = depth <= 1.0  # beyond the far plane: clipped
    if not in_range.all():
        frag_sub, fx, fy, lam, depth = (
            frag_sub[in_range],
            fx[in_range],
            fy[in_range],
            lam[in_range],
            depth[in_range],
        )
    depth = np.maximum(depth, 0.0)  # the near plane itself, up to rounding of the clipped vertices
    q = lam / setup.w[frag_sub]
    persp = q / q.sum(axis=1, keepdims=True)
    bary = np.einsum("nj,njm->nm", persp, setup.weights[frag_sub])
    k = setup.k
    return Fragments(
        width=setup.width,
        height=setup.height,
        samples=k * k,
        pixel=((fy // k) * setup.width + fx // k).astype(np.int64),
        sample=((fy % k) * k + fx % k).astype(np.int64),
        depth=depth,
        triangle=setup.source[frag_sub],
        bary=bary,
        front_facing=setup.front[frag_sub],
    )


def _exact_barycentrics(
    x: np.ndarray,
    y: np.ndarray,
    sub: np.ndarray,
    px: np.ndarray,
    py: np.ndarray,
    snapped_area: np.ndarray,
    snapped_edges: np.ndarray,
) -> np.ndarray:
    """Screen-space barycentrics of sample points from the unsnapped window positions.

    Snapping decides coverage only; interpolation uses the exact vertex positions so
    attributes are not shifted by up to 1/512 pixel. Where snapping changed the
    orientation or the exact area vanishes, the snapped values are kept.
    """
    xs, ys = x[sub], y[sub]  # (n, 3)
    area = (xs[:, 1] - xs[:, 0]) * (ys[:, 2] - ys[:, 0]) - (xs[:, 2] - xs[:, 0]) * (ys[:, 1] - ys[:, 0])
    lam = np.empty((len(sub), 3))
    for i, (j, k) in enumerate(((1, 2), (2, 0), (0, 1))):
        lam[:, i] = (xs[:, k] - xs[:, j]) * (py - ys[:, j]) - (ys[:, k] - ys[:, j]) * (px - xs[:, j])
    ok = (area * snapped_area[sub] > 0) & (np.abs(area) > 1e-12)
    safe = np.where(ok, area, 1.0)
    return np.where(ok[:, None], lam / safe[:, None], snapped_edges / np.abs(snapped_area[sub])[:, None])


def _tile_jobs(
    sel: np.ndarray, x0: np.ndarray, x1: np.ndarray, y0: np.ndarray, y1: np.ndarray
) -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Group triangles (or 64×64 tiles of large ones) by power-of-two bounding-box size."""
    bw = (x1[sel] - x0[sel] + 1).astype(np.int64)
    bh = (y1[sel] - y0[sel] + 1).astype(np.int64)
    extent = np.maximum(bw, bh)
    size = np.where(extent <= 1, 1, 1 << np.ceil(np.log2(np.maximum(extent, 1))).astype(np.int64))
    jobs: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    small = size <= _MAX_TILE
    for s in np.unique(size[small]):
        m = small & (size == s)
        jobs[int(s)] = (sel[m], x0[sel][m].astype(np.int64), y0[sel][m].astype(np.int64))
    big = np.flatnonzero(~small)
    if len(big):
        tx = (bw[big] + _MAX_TILE - 1) // _MAX_TILE
        ty = (bh[big] + _MAX_TILE - 1) // _MAX_TILE
        counts = tx * ty
        owner = np.repeat(big, counts)
        local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        tile_x = local % np.repeat(tx, counts)
        tile_y = local // np.repeat(tx, counts)
        t_ids = sel[owner]
        jx = x0[t_ids].astype(np.int64) + tile_x * _MAX_TILE
        jy = y0[t_ids].astype(np.int64) + tile_y * _MAX_TILE
        if _MAX_TILE in jobs:
            prev = jobs[_MAX_TILE]
            jobs[_MAX_TILE] = (
                np.concatenate([prev[0], t_ids]),
                np.concatenate([prev[1], jx]),
                np.concatenate([prev[2], jy]),
            )
        else:
            jobs[_MAX_TILE] = (t_ids, jx, jy)
    return jobs


def _cover(
    tri: np.ndarray, px0: np.ndarray, py0: np.ndarray, size: int, setup: _TriangleSetup
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Evaluate the edge functions of a batch of triangles on size×size pixel blocks.

    Returns (sub-triangle, x, y) of the covered (fine) pixels.
    """
    d = np.arange(size)
    px = px0[:, None] + d[None, :]  # (B, S)
    py = py0[:, None] + d[None, :]
    cx = px + 0.5
    cy = py + 0.5
    mask = (px <= setup.x1[tri][:, None])[:, None, :] & (py <= setup.y1[tri][:, None])[:, :, None]
    for i in range(3):
        a = setup.a[tri, i][:, None]
        b = setup.b[tri, i][:, None]
        c = setup.c[tri, i][:, None]
        e = (a * cx)[:, None, :] + (b * cy + c)[:, :, None]
        mask &= (e > 0) | ((e == 0) & setup.top_left[tri, i][:, None, None])
    bi, yi, xi = np.nonzero(mask)
    return tri[bi], px[bi, xi], py[bi, yi]


# --------------------------------------------------------------------------- resolve and interpolation


def resolve_nearest(fragments: Fragments) -> np.ndarray:
    """The depth test: for each sample, the index of its nearest fragment, or -1 if none.

    ``GL_LESS`` semantics with draw order = triangle index: the smallest depth wins
    and among equal depths the lowest triangle index (drawn first) wins.

    Returns:
        (height·width·samples,) int64 indices into the fragment arrays, ordered by
        :attr:`Fragments.sample_key` (reshape to (height, width, samples)).
    """
    n_keys = fragments.width * fragments.height * fragments.samples
    winner = np.full(n_keys, -1, np.int64)
    if len(fragments) == 0:
        return winner
    key = fragments.sample_key
    zbuf = np.full(n_keys, np.inf)
    np.minimum.at(zbuf, key, fragments.depth)
    nearest = np.flatnonzero(fragments.depth == zbuf[key])
    first_tri = np.full(n_keys, np.iinfo(np.int64).max, np.int64)
    np.minimum.at(first_tri, key[nearest], fragments.triangle[nearest])
    chosen = nearest[fragments.triangle[nearest] == first_tri[key[nearest]]]
    winner[key[chosen]] = chosen
    return winner


def interpolate(fragments: Fragments, triangles: np.ndarray, attribute: np.ndarray) -> np.ndarray:
    """Perspective-correct interpolation of a per-vertex attribute at each fragment.

    Args:
        fragments: from :func:`rasterize` with the same ``triangles``.
        triangles: (T, 3) vertex indices given to :func:`rasterize`.
        attribute: (V, C) or (V,) per-vertex values (any units; interpolated linearly in clip space).

    Returns:
        (N, C) or (N,) values ``Σ_i bary_i · attribute[triangles[t, i]]``.
    """
    tri = np.asarray(triangles)[fragments.triangle]  # (N, 3)
    att = np.asarray(attribute)
    values = att[tri]  # (N, 3) or (N, 3, C)
    if att.ndim == 1:
        return np.einsum("ni,ni->n", fragments.bary, values)
    return np.einsum("ni,nic->nc", fragments.bary, values)
