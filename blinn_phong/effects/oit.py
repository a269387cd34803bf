"""Resolving transparent fragments: A-buffer, sorted drawing, depth peeling, weighted blended OIT.

Every function takes *fragments*: parallel arrays with one row per covered pixel (or
sample) per primitive — ``pixel`` (flat index ``row·width + column``, or a sample index),
a depth or drawing-order key, and premultiplied linear RGBA — and returns an image
``(n_pixels, 4)`` of premultiplied RGBA. Fragments are sorted once by (pixel, key) with
``np.lexsort``; the k-th fragment of every pixel is then composited for all pixels at
once, so the only Python loop runs over layer ranks (the depth complexity), never
over pixels. Every blend is :func:`compositing.composite`.

* :func:`resolve_a_buffer` — Carpenter, "The A-buffer, an antialiased hidden surface
  method", SIGGRAPH '84: all fragments of a pixel kept, sorted by depth, composited front
  to back (``acc = fragment under acc``, Porter–Duff *B over A*), then over the
  background. Exact for any submission order and for interpenetrating surfaces, since
  the order is decided per fragment. The reference answer.
* :func:`resolve_in_draw_order` with :func:`object_draw_order` /
  :func:`triangle_draw_order` — the classic "opaque first, then transparent primitives
  sorted back to front with ``src over``" (painter's order per object or per triangle).
  Equal to the A-buffer when the primitive order agrees with the per-pixel depth order;
  wrong where surfaces interpenetrate or cyclically overlap.
* :func:`resolve_depth_peeling` — Everitt, "Interactive Order-Independent Transparency",
  NVIDIA 2001: pass k peels the k-th nearest layer; with ``layers`` passes the nearest
  ``layers`` fragments of each pixel are composited front to back and the rest is lost.
  Exact once ``layers`` ≥ the depth complexity.
* :func:`resolve_weighted_blended` with :func:`wboit_weights` — McGuire & Bavoil,
  "Weighted Blended Order-Independent Transparency", JCGT 2(2) 2013:
  ``accum = Σ (c·w, α·w)`` (premultiplied ``c``), ``revealage = Π (1 − α)``,
  ``result = (accum.rgb / max(accum.a, 1e-5))·(1 − revealage)`` as a colour of alpha
  ``1 − revealage``, composited over the background. The paper's floor ``1e-5`` (its
  listing's ``max(accum.a, 1e-5)``) is kept: for one layer, or layers of equal colour,
  the result is exact where ``accum.a = Σ w·α ≥ 1e-5`` and its colour is scaled by
  ``accum.a / 1e-5`` below it (faint, distant fragments come out darker: α = 0.01 at window
  depth 0.99 with eq. 10 has ``w·α = 1e-6``, a tenth of its colour). Otherwise an
  approximation whose error the benchmark measures.

:func:`depth_test` discards transparent fragments behind the opaque depth buffer (GL_LESS),
the "depth-tested but not written" rule for transparent geometry.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from blinn_phong.geometry.raster import Fragments, resolve_nearest
from compositing import composite

__all__ = [
    "TRANSPARENCY_METHODS",
    "WBOIT_EQUATIONS",
    "depth_complexity",
    "depth_test",
    "draw_order",
    "object_draw_order",
    "resolve_a_buffer",
    "resolve_depth_peeling",
    "resolve_in_draw_order",
    "resolve_transparency",
    "resolve_weighted_blended",
    "transparency_pass",
    "triangle_draw_order",
    "wboit_weights",
]

#: Weight functions of McGuire & Bavoil 2013 (equations 7–10) and the constant weight.
WBOIT_EQUATIONS: tuple[str, ...] = ("constant", "eq7", "eq8", "eq9", "eq10")


def _check_fragments(
    pixel: np.ndarray, key: np.ndarray, rgba: np.ndarray, n_pixels: int, key_name: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if not isinstance(n_pixels, int | np.integer) or n_pixels < 0:
        raise ValueError(f"n_pixels must be an integer >= 0, got {n_pixels!r}")
    pix = np.asarray(pixel)
    if pix.ndim != 1 or pix.dtype.kind not in "iu":
        raise TypeError(f"pixel must be a 1-D integer array, got dtype {pix.dtype} shape {pix.shape}")
    if len(pix) and (pix.min() < 0 or pix.max() >= n_pixels):
        raise ValueError(f"pixel indices must lie in [0, {n_pixels}), got range [{pix.min()}, {pix.max()}]")
    k = np.asarray(key)
    if k.shape != pix.shape or k.dtype.kind not in "fiu":
        raise ValueError(f"{key_name} must be a real array of shape {pix.shape}, got {k.dtype} {k.shape}")
    if not np.all(np.isfinite(k)):
        raise ValueError(f"{key_name} must be finite, got NaN or Inf")
    c = np.asarray(rgba)
    if c.shape != (len(pix), 4):
        raise ValueError(
            f"rgba must have shape ({len(pix)}, 4) (one premultiplied RGBA per fragment), got {c.shape}"
        )
    if c.dtype not in (np.float32, np.float64):
        raise TypeError(f"rgba must be float32 or float64, got {c.dtype}")
    return pix.astype(np.int64, copy=False), k, c


def _background(background: np.ndarray | None, n_pixels: int, dtype: np.dtype) -> np.ndarray:
    if background is None:
        return np.zeros((n_pixels, 4), dtype=dtype)
    bg = np.asarray(background)
    if bg.shape not in ((n_pixels, 4), (4,)):
        raise ValueError(f"background must have shape ({n_pixels}, 4) or (4,), got {bg.shape}")
    return np.array(np.broadcast_to(bg, (n_pixels, 4)), dtype=dtype)


def _sorted_layers(pixel: np.ndarray, key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fragment order sorted by (pixel, key, input position) and each fragment's rank in its pixel."""
    order = np.lexsort((np.arange(len(pixel)), key, pixel))
    p = pixel[order]
    if len(p) == 0:
        return order, np.zeros(0, dtype=np.int64)
    start = np.r_[0, np.flatnonzero(p[1:] != p[:-1]) + 1]
    first_of_run = np.zeros(len(p), dtype=np.int64)
    first_of_run[start] = start
    first_of_run = np.maximum.accumulate(first_of_run)
    return order, np.arange(len(p)) - first_of_run


def _front_to_back(
    pixel: np.ndarray,
    key: np.ndarray,
    rgba: np.ndarray,
    n_pixels: int,
    background: np.ndarray | None,
    max_layers: int | None,
) -> np.ndarray:
    """Composite each pixel's fragments in increasing ``key`` (front first), then over the background."""
    dtype = rgba.dtype
    order, rank = _sorted_layers(pixel, key)
    acc = np.zeros((n_pixels, 4), dtype=dtype)
    n_layers = int(rank.max()) + 1 if len(rank) else 0
    if max_layers is not None:
        n_layers = min(n_layers, max_layers)
    p_sorted = pixel[order]
    c_sorted = rgba[order]
    for k in range(n_layers):
        sel = rank == k
        pix = p_sorted[sel]
        # the new, farther fragment goes under what is already accumulated: B over A
        acc[pix] = composite(c_sorted[sel], acc[pix], "dst_over", engine="numpy")
    return composite(acc, _background(background, n_pixels, dtype), "src_over", engine="numpy")


def depth_complexity(pixel: np.ndarray, n_pixels: int) -> np.ndarray:
    """Number of fragments per pixel, (n_pixels,) int64 (the layers an exact method must handle).

    Args:
        pixel: (n,) flat pixel (or sample) index of each fragment.
        n_pixels: number of pixels (or samples) in the image.
    """
    pix, _, _ = _check_fragments(
        pixel, np.zeros(len(np.asarray(pixel))), np.zeros((len(pixel), 4)), n_pixels, "key"
    )
    return np.bincount(pix, minlength=n_pixels)


def depth_test(pixel: np.ndarray, depth: np.ndarray, opaque_depth: np.ndarray) -> np.ndarray:
    """Mask of transparent fragments in front of the opaque depth buffer (``GL_LESS``).

    Args:
        pixel: (n,) flat pixel index of each transparent fragment.
        depth: (n,) window depth in [0, 1] of each fragment.
        opaque_depth: (n_pixels,) depth buffer after the opaque pass (1 = nothing drawn).

    Returns:
        (n,) bool, True for fragments that survive and must be composited.
    """
    od = np.asarray(opaque_depth)
    if od.ndim != 1:
        raise ValueError(f"opaque_depth must be a flat (n_pixels,) array, got shape {od.shape}")
    pix, d, _ = _check_fragments(pixel, depth, np.zeros((len(np.asarray(pixel)), 4)), len(od), "depth")
    return d < od[pix]


def resolve_a_buffer(
    pixel: np.ndarray,
    depth: np.ndarray,
    rgba: np.ndarray,
    n_pixels: int,
    background: np.ndarray | None = None,
) -> np.ndarray:
    """Exact order-independent transparency: per-pixel sort by depth (Carpenter 1984).

    Args:
        pixel: (n,) flat pixel (or sample) index of each fragment, in [0, n_pixels).
        depth: (n,) fragment depth, smaller = nearer (window depth or eye distance);
            equal depths keep submission order.
        rgba: (n, 4) premultiplied linear RGBA of each fragment, float32/float64.
        n_pixels: number of pixels (or samples).
        background: (n_pixels, 4) or (4,) premultiplied RGBA behind all fragments
            (the opaque image); transparent black when omitted.

    Returns:
        (n_pixels, 4) premultiplied RGBA in the dtype of ``rgba``.
    """
    pix, d, c = _check_fragments(pixel, depth, rgba, n_pixels, "depth")
    return _front_to_back(pix, d, c, n_pixels, background, None)


def resolve_depth_peeling(
    pixel: np.ndarray,
    depth: np.ndarray,
    rgba: np.ndarray,
    n_pixels: int,
    layers: int,
    background: np.ndarray | None = None,
) -> np.ndarray:
    """Depth peeling with ``layers`` passes (Everitt 2001): the nearest ``layers`` fragments per pixel.

    Fragments beyond the ``layers``-th nearest are dropped, as the passes never reach them.

    Args:
        pixel: (n,) flat pixel (or sample) index of each fragment.
        depth: (n,) fragment depth, smaller = nearer.
        rgba: (n, 4) premultiplied linear RGBA of each fragment.
        n_pixels: number of pixels (or samples).
        layers: number of peeling passes, ≥ 1 (the cost knob).
        background: premultiplied RGBA behind all fragments, see :func:`resolve_a_buffer`.

    Returns:
        (n_pixels, 4) premultiplied RGBA in the dtype of ``rgba``.
    """
    if not isinstance(layers, int | np.integer) or layers < 1:
        raise ValueError(f"layers must be an integer >= 1, got {layers!r}")
    pix, d, c = _check_fragments(pixel, depth, rgba, n_pixels, "depth")
    return _front_to_back(pix, d, c, n_pixels, background, int(layers))


def resolve_in_draw_order(
    pixel: np.ndarray,
    draw_order: np.ndarray,
    rgba: np.ndarray,
    n_pixels: int,
    background: np.ndarray | None = None,
) -> np.ndarray:
    """Blend fragments with ``src over`` in drawing order, as a GPU does without OIT.

    A fragment drawn later lands over those drawn earlier in its pixel, whatever their
    depths (transparent geometry does not write depth).

    Args:
        pixel: (n,) flat pixel (or sample) index of each fragment.
        draw_order: (n,) position of each fragment's primitive in the drawing sequence
            (0 = drawn first); see :func:`object_draw_order`, :func:`triangle_draw_order`.
        rgba: (n, 4) premultiplied linear RGBA of each fragment.
        n_pixels: number of pixels (or samples).
        background: premultiplied RGBA already in the framebuffer (the opaque pass).

    Returns:
        (n_pixels, 4) premultiplied RGBA in the dtype of ``rgba``.
    """
    pix, k, c = _check_fragments(pixel, draw_order, rgba, n_pixels, "draw_order")
    # last drawn = front: composite front to back in decreasing draw order
    return _front_to_back(pix, -np.asarray(k, dtype=np.float64), c, n_pixels, background, None)


def triangle_draw_order(triangle: np.ndarray, triangle_depth: np.ndarray) -> np.ndarray:
    """Per-fragment draw order for triangles sorted back to front.

    Args:
        triangle: (n,) triangle index of each fragment.
        triangle_depth: (n_triangles,) sort depth of each triangle, larger = farther
            (e.g. the eye distance or window depth of its centroid).

    Returns:
        (n,) int64 drawing position of each fragment's triangle (farthest drawn first;
        ties by triangle index).
    """
    tri = np.asarray(triangle)
    td = np.asarray(triangle_depth, dtype=np.float64)
    if tri.dtype.kind not in "iu" or td.ndim != 1:
        raise TypeError("triangle must be an integer array and triangle_depth a 1-D array")
    if len(tri) and (tri.min() < 0 or tri.max() >= len(td)):
        raise ValueError(f"triangle indices must lie in [0, {len(td)}), got [{tri.min()}, {tri.max()}]")
    rank = np.empty(len(td), dtype=np.int64)
    rank[np.lexsort((np.arange(len(td)), -td))] = np.arange(len(td))
    return rank[tri]


def object_draw_order(
    obj: np.ndarray,
    triangle: np.ndarray,
    object_depth: np.ndarray,
    front_facing: np.ndarray | None = None,
) -> np.ndarray:
    """Per-fragment draw order for objects sorted back to front.

    Inside an object, back-facing triangles are drawn before front-facing ones when
    ``front_facing`` is given (two passes, culling front then back faces), then in mesh
    order. For a convex closed object every back face lies behind every front face on
    any ray, so this order is exact; for a planar one any order is.

    Args:
        obj: (n,) object index of each fragment.
        triangle: (n,) triangle index of each fragment (the order within an object).
        object_depth: (n_objects,) sort depth of each object, larger = farther
            (e.g. the eye distance of its centre).
        front_facing: optional (n,) bool, True for fragments of front-facing triangles.

    Returns:
        (n,) int64 drawing position (comparable between fragments).
    """
    ob = np.asarray(obj)
    tri = np.asarray(triangle)
    od = np.asarray(object_depth, dtype=np.float64)
    if ob.dtype.kind not in "iu" or tri.dtype.kind not in "iu" or od.ndim != 1 or ob.shape != tri.shape:
        raise TypeError("obj and triangle must be integer arrays of one shape, object_depth a 1-D array")
    if len(ob) and (ob.min() < 0 or ob.max() >= len(od)):
        raise ValueError(f"object indices must lie in [0, {len(od)}), got [{ob.min()}, {ob.max()}]")
    facing = np.zeros(len(ob), dtype=np.int64)
    if front_facing is not None:
        ff = np.asarray(front_facing)
        if ff.shape != ob.shape or ff.dtype != bool:
            raise ValueError(
                f"front_facing must be a bool array of shape {ob.shape}, got {ff.dtype} {ff.shape}"
            )
        facing = ff.astype(np.int64)
    rank = np.empty(len(od), dtype=np.int64)
    rank[np.lexsort((np.arange(len(od)), -od))] = np.arange(len(od))
    n_tri = int(tri.max()) + 1 if len(tri) else 1
    return (rank[ob] * 2 + facing) * n_tri + tri


def wboit_weights(
    alpha: np.ndarray,
    equation: str = "eq7",
    *,
    view_distance: np.ndarray | None = None,
    window_depth: np.ndarray | None = None,
) -> np.ndarray:
    """Weights ``w(z, α)`` of weighted blended OIT (McGuire & Bavoil 2013, eqs. 7–10).

    * ``eq7``: ``α·clamp(10 / (1e-5 + (|z|/5)² + (|z|/200)⁶), 1e-2, 3e3)``
    * ``eq8``: ``α·clamp(10 / (1e-5 + (|z|/10)³ + (|z|/200)⁶), 1e-2, 3e3)``
    * ``eq9``: ``α·clamp(0.03 / (1e-5 + (|z|/200)⁴), 1e-2, 3e3)``
    * ``eq10``: ``α·max(1e-2, 3e3·(1 − d)³)`` with window depth ``d``
    * ``constant``: ``α`` (the α factor alone, no depth term)

    Args:
        alpha: (n,) fragment alphas in [0, 1].
        equation: one of :data:`WBOIT_EQUATIONS`.
        view_distance: (n,) eye-space distance |z| (eqs. 7–9), in the paper's units
            (tuned for roughly 0.1–500).
        window_depth: (n,) window depth in [0, 1] (eq. 10).

    Returns:
        (n,) float64 weights ≥ 0.
    """
    a = np.asarray(alpha, dtype=np.float64)
    if equation == "constant":
        return a.copy()
    if equation in ("eq7", "eq8", "eq9"):
        if view_distance is None:
            raise ValueError(f"equation {equation!r} needs view_distance (|z_eye| per fragment)")
        z = np.abs(np.asarray(view_distance, dtype=np.float64))
        if z.shape != a.shape:
            raise ValueError(f"view_distance must have shape {a.shape}, got {z.shape}")
        if equation == "eq7":
            w = 10.0 / (1e-5 + (z / 5.0) ** 2 + (z / 200.0) ** 6)
        elif equation == "eq8":
            w = 10.0 / (1e-5 + (z / 10.0) ** 3 + (z / 200.0) ** 6)
        else:
            w = 0.03 / (1e-5 + (z / 200.0) ** 4)
        return a * np.clip(w, 1e-2, 3e3)
    if equation == "eq10":
        if window_depth is None:
            raise ValueError("equation 'eq10' needs window_depth (in [0, 1] per fragment)")
        d = np.asarray(window_depth, dtype=np.float64)
        if d.shape != a.shape:
            raise ValueError(f"window_depth must have shape {a.shape}, got {d.shape}")
        return a * np.maximum(1e-2, 3e3 * (1.0 - d) ** 3)
    raise ValueError(f"equation must be one of {WBOIT_EQUATIONS}, got {equation!r}")


def resolve_weighted_blended(
    pixel: np.ndarray,
    weight: np.ndarray,
    rgba: np.ndarray,
    n_pixels: int,
    background: np.ndarray | None = None,
) -> np.ndarray:
    """Weighted blended order-independent transparency (McGuire & Bavoil 2013).

    ``accum = Σ w·(rgb, α)`` (premultiplied rgb; the paper's ``(C·α·w, α·w)``),
    ``revealage = Π (1 − α)``; the transparent layer is the colour
    ``accum.rgb / max(accum.a, 1e-5)`` with coverage ``1 − revealage``, composited
    ``src over`` the background. No sorting, one pass, the result does not depend on order.

    The floor ``1e-5`` is the paper's (it avoids dividing by zero where nothing was
    accumulated). It bounds the error of a single layer (or of layers of equal colour):
    exact when ``accum.a ≥ 1e-5``, otherwise the layer's colour is multiplied by
    ``accum.a / 1e-5 < 1`` (its coverage is exact). Weights that include ``α`` (all of
    :func:`wboit_weights`) make ``accum.a`` quadratic in ``α``, so faint fragments are the
    ones affected.

    Args:
        pixel: (n,) flat pixel (or sample) index of each fragment.
        weight: (n,) weights from :func:`wboit_weights` (≥ 0).
        rgba: (n, 4) premultiplied linear RGBA of each fragment.
        n_pixels: number of pixels (or samples).
        background: premultiplied RGBA behind all fragments, see :func:`resolve_a_buffer`.

    Returns:
        (n_pixels, 4) premultiplied RGBA in the dtype of ``rgba``.
    """
    pix, w, c = _check_fragments(pixel, weight, rgba, n_pixels, "weight")
    if np.any(w < 0):
        raise ValueError(f"weight must be >= 0, got minimum {w.min()}")
    dtype = c.dtype
    w64 = np.asarray(w, dtype=np.float64)
    accum = np.zeros((n_pixels, 4))
    for ch in range(4):  # ONE, ONE blending of (rgb·w, α·w): an order-free sum per pixel
        accum[:, ch] = np.bincount(pix, weights=c[:, ch] * w64, minlength=n_pixels)
    revealage = np.ones(n_pixels)
    np.multiply.at(revealage, pix, 1.0 - c[:, 3].astype(np.float64))
    coverage = 1.0 - revealage
    safe = np.maximum(accum[:, 3], 1e-5)
    layer = np.zeros((n_pixels, 4))
    layer[:, :3] = accum[:, :3] / safe[:, None] * coverage[:, None]
    layer[:, 3] = coverage
    return composite(
        layer.astype(dtype), _background(background, n_pixels, dtype), "src_over", engine="numpy"
    )


#: Methods :func:`resolve_transparency` dispatches (the planner's transparency choices).
TRANSPARENCY_METHODS: tuple[str, ...] = (
    "a_buffer",
    "draw_last",
    "sort_objects",
    "sort_triangles",
    "depth_peeling",
    "weighted_blended",
)


def resolve_transparency(
    method: str,
    pixel: np.ndarray,
    depth: np.ndarray,
    rgba: np.ndarray,
    n_pixels: int,
    *,
    triangle: np.ndarray,
    triangle_mesh: np.ndarray,
    triangle_eye_distance: np.ndarray,
    background: np.ndarray | None = None,
    layers: int | None = None,
    weights: np.ndarray | None = None,
    front_facing: np.ndarray | None = None,
) -> np.ndarray:
    """Resolve transparent fragments with a named method (a planner choice).

    Args:
        method: one of :data:`TRANSPARENCY_METHODS`. ``draw_last`` and ``sort_objects`` draw
            meshes back to front by the mean eye distance of their triangles' centroids,
            inside a mesh back faces before front faces (with ``front_facing``), then in
            mesh order (:func:`object_draw_order`); ``sort_triangles`` sorts triangles by
            their centroids' eye distance.
        pixel: (n,) flat pixel (or sample) index of each transparent fragment (already
            depth-tested against the opaque pass, see :func:`depth_test`).
        depth: (n,) window depth of each fragment.
        rgba: (n, 4) premultiplied linear RGBA of each fragment.
        n_pixels: number of pixels (or samples).
        triangle: (n,) triangle index of each fragment.
        triangle_mesh: (T,) mesh index of every triangle.
        triangle_eye_distance: (T,) eye distance of every triangle's centroid.
        background: the opaque image, (n_pixels, 4) premultiplied RGBA.
        layers: passes for ``depth_peeling``.
        weights: (n,) weights for ``weighted_blended`` (:func:`wboit_weights`).
        front_facing: (n,) bool per fragment, for ``draw_last`` and ``sort_objects``.

    Returns:
        (n_pixels, 4) premultiplied RGBA in the dtype of ``rgba``.
    """
    tri = np.asarray(triangle)
    if method == "a_buffer":
        return resolve_a_buffer(pixel, depth, rgba, n_pixels, background)
    if method == "depth_peeling":
        if layers is None:
            raise ValueError("depth_peeling needs layers (an integer >= 1)")
        return resolve_depth_peeling(pixel, depth, rgba, n_pixels, layers, background)
    if method == "weighted_blended":
        if weights is None:
            raise ValueError("weighted_blended needs weights (see wboit_weights)")
        return resolve_weighted_blended(pixel, weights, rgba, n_pixels, background)
    if method in ("draw_last", "sort_objects", "sort_triangles"):
        order = draw_order(
            method,
            tri,
            triangle_mesh=triangle_mesh,
            triangle_eye_distance=triangle_eye_distance,
            front_facing=front_facing,
        )
        return resolve_in_draw_order(pixel, order, rgba, n_pixels, background)
    raise ValueError(f"method must be one of {TRANSPARENCY_METHODS}, got {method!r}")


def draw_order(
    method: str,
    triangle: np.ndarray,
    *,
    triangle_mesh: np.ndarray,
    triangle_eye_distance: np.ndarray,
    front_facing: np.ndarray | None = None,
) -> np.ndarray:
    """Per-fragment drawing position of a sorted-drawing method (0 = drawn first).

    ``draw_last`` and ``sort_objects``: meshes back to front by the mean eye distance of their
    triangles' centroids, inside a mesh back faces first (with ``front_facing``), then mesh
    order (:func:`object_draw_order`); ``sort_triangles``: triangles back to front by their
    centroid's eye distance (:func:`triangle_draw_order`).

    Args:
        method: ``draw_last``, ``sort_objects`` or ``sort_triangles``.
        triangle: (n,) triangle index of each fragment.
        triangle_mesh: (T,) mesh index of every triangle.
        triangle_eye_distance: (T,) eye distance of every triangle's centroid (world units).
        front_facing: optional (n,) bool per fragment.

    Returns:
        (n,) int64 drawing positions (comparable between fragments).
    """
    tri = np.asarray(triangle)
    dist = np.asarray(triangle_eye_distance, dtype=np.float64)
    if method in ("draw_last", "sort_objects"):
        owner = np.asarray(triangle_mesh)
        n_mesh = int(owner.max()) + 1 if len(owner) else 0
        mesh_dist = np.bincount(owner, weights=dist, minlength=n_mesh) / np.maximum(
            np.bincount(owner, minlength=n_mesh), 1
        )
        return object_draw_order(owner[tri], tri, mesh_dist, front_facing)
    if method == "sort_triangles":
        return triangle_draw_order(tri, dist)
    raise ValueError(f"method: expected 'draw_last', 'sort_objects' or 'sort_triangles', got {method!r}")


def transparency_pass(
    fragments: Fragments,
    opaque: np.ndarray,
    shade: Callable[[np.ndarray], np.ndarray],
    method: str,
    *,
    triangle_mesh: np.ndarray,
    triangle_eye_distance: np.ndarray,
    layers: int | None = None,
    wboit_equation: str = "eq10",
) -> tuple[np.ndarray, np.ndarray]:
    """Opaque fragments through a z-buffer, then transparent ones resolved by ``method``.

    The order of the issue: opaque geometry first with depth writes; transparent geometry
    after, depth-tested against the opaque depth but not writing it, then resolved by
    :func:`resolve_transparency` over the opaque image. Only the fragments that can be seen
    are shaded: the nearest opaque one per sample and the transparent ones in front of it.

    Args:
        fragments: :class:`blinn_phong.geometry.raster.Fragments` of every triangle.
        opaque: (N,) bool, True for fragments of opaque materials (opacity 1).
        shade: ``shade(index) -> (len(index), 4)`` premultiplied linear RGBA of the
            fragments ``index`` (e.g. from :func:`blinn_phong.frame.render.shade_fragments`).
        method: ``zbuffer`` or one of :data:`TRANSPARENCY_METHODS`.
        triangle_mesh: (T,) mesh of each triangle (``PreparedScene.triangle_mesh``).
        triangle_eye_distance: (T,) eye distance of each triangle's centroid
            (``-PreparedScene.face_eye_centroid[:, 2]``).
        layers: passes for ``depth_peeling``.
        wboit_equation: weight function for ``weighted_blended`` (window-depth ``eq10`` by
            default, since fragments carry window depth).

    Returns:
        ``(rgba, depth)``: (width·height·samples, 4) premultiplied RGBA per sample (index
        ``Fragments.sample_key``) in the dtype ``shade`` returns (the transparent fragments'
        when both are shaded; float64 when nothing is), and (width·height·samples,) float64
        opaque window depth (1 = empty). The opaque pass is
        :func:`blinn_phong.geometry.raster.resolve_nearest`
        on the opaque fragments.
    """
    n_keys = int(fragments.width * fragments.height * fragments.samples)
    key = np.asarray(fragments.sample_key)
    frag_depth = np.asarray(fragments.depth)
    frag_tri = np.asarray(fragments.triangle)
    op = np.asarray(opaque, dtype=bool)
    if op.shape != key.shape:
        raise ValueError(f"opaque: expected one flag per fragment, shape {key.shape}, got {op.shape}")
    if method != "zbuffer" and method not in TRANSPARENCY_METHODS:
        raise ValueError(f"method: expected 'zbuffer' or one of {TRANSPARENCY_METHODS}, got {method!r}")
    # opaque pass: the z-buffer (GL_LESS in draw order) over the opaque fragments only
    nearest = resolve_nearest(fragments.subset(np.flatnonzero(op)))
    covered = np.flatnonzero(nearest >= 0)
    winners = np.flatnonzero(op)[nearest[covered]]
    depth = np.ones(n_keys)
    depth[covered] = frag_depth[winners]
    opaque_rgba = np.asarray(shade(winners)) if len(winners) else None
    tr_idx = np.flatnonzero(~op) if method != "zbuffer" else np.empty(0, np.int64)
    tr_idx = tr_idx[frag_depth[tr_idx] < depth[key[tr_idx]]]
    rgba = np.asarray(shade(tr_idx)) if len(tr_idx) else None
    dtype = next((x.dtype for x in (opaque_rgba, rgba) if x is not None), np.dtype(np.float64))
    image = np.zeros((n_keys, 4), dtype)
    if opaque_rgba is not None:
        image[covered] = opaque_rgba
    if rgba is None:
        return image, depth
    weights = None
    if method == "weighted_blended":
        weights = wboit_weights(rgba[:, 3], wboit_equation, window_depth=frag_depth[tr_idx])
    out = resolve_transparency(
        method,
        key[tr_idx],
        frag_depth[tr_idx],
        rgba,
        n_keys,
        triangle=frag_tri[tr_idx],
        triangle_mesh=triangle_mesh,
        triangle_eye_distance=triangle_eye_distance,
        background=image.astype(rgba.dtype, copy=False),
        layers=layers,
        weights=weights,
        front_facing=np.asarray(fragments.front_facing)[tr_idx],
    )
    return out, depth
