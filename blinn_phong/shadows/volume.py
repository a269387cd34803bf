"""Shadow volumes: exact hard shadows by counting volume faces per sample (stencil counting).

Crow ("Shadow Algorithms for Computer Graphics", SIGGRAPH '77) bounds the region a caster
hides from a light by a closed *shadow volume*: the caster's faces that face the light (the
*light cap*), quads swept from its *silhouette edges* away from the light (the *sides*), and the
faces that face away, pushed to infinity (the *dark cap*). A point is in shadow when it lies
inside a volume. Heidmann (1991) counted this per pixel with the stencil buffer; Everitt &
Kilgard ("Practical and Robust Stenciled Shadow Volumes for Hardware-Accelerated Rendering",
NVIDIA 2002) made it robust.

Per receiver point ``p`` (a visible sample), with the camera's view and projection:

* **z-pass** (Heidmann): count the volume faces drawn *in front of* ``p`` along the camera ray
  through ``p`` — +1 for a face seen from its front (entering a volume), −1 from its back. The
  sum is the number of volumes ``p`` lies in **if the camera is outside every volume and no
  volume is cut by the near plane**; otherwise the faces the camera is already behind are
  missing from the count (tests/failures/test_shadow_volume_failures.py measures it).
* **z-fail** ("Carmack's reverse", Everitt & Kilgard §3): count the faces *behind* ``p`` — +1
  for back faces, −1 for front faces — out to infinity. Counting from infinity (where every
  count is 0) instead of from the eye makes it independent of where the camera is; it needs
  the volumes closed at both ends (light and dark caps) and nothing lost behind a far plane:
  here nothing is clipped but the near plane, which is what ``GL_DEPTH_CLAMP`` (or Everitt &
  Kilgard's infinite projection) gives the stencil buffer.

``p`` is lit when its count is 0 (the stencil test ``GL_EQUAL 0``). Whatever the method,
``zfail − zpass = w(q_p)``, the number of volumes containing the point ``q_p`` where the camera
ray through ``p`` crosses the near plane: every face is counted by exactly one of the two.

z-pass here draws the **light caps** (Heidmann drew the sides only): a receiver hidden behind
a caster — a layer the A-buffer shades, a surface behind a transparent caster, the far side
of a two-sided object — has the caster's lit faces between it and the eye, and without them
its count is off by the cap's own count (the planner's random scenes found it: a closed box
under two-sided lighting, an open pane inside a closed slab under spot lights, 119 of 1966
samples wrong; tests/failures/test_shadow_volume_failures.py). The dark cap at infinity is
never in front of a finite point (its window depth ``(f+n)/(f−n)`` exceeds every finite
point's), so z-pass still skips it — and z-pass skips nothing else z-fail draws.
``stencil="auto"`` (:func:`choose_stencil`) picks z-pass where it is provably exact — every
receiver inside the near rectangle and :func:`zpass_is_safe` (no volume reaches it), so
``w(q_p) = 0`` — and z-fail elsewhere.

Geometry
--------
* **Welding and adjacency.** The input is a world-space triangle soup; vertices with
  bit-identical coordinates are merged (a mesh's shared vertices transform to identical
  floats). Triangles that share an edge are neighbours; edge-connected sets are components.
* **Closed 2-manifold components** (every directed edge ``a→b`` used once and its twin
  ``b→a`` once) use silhouette extrusion: silhouette edges are the edges between a triangle
  facing the light and one facing away (facing: sign of the plane equation at the light,
  ``n·(L − v₀)``, or ``−n·d`` for a directional light). A component enclosing negative volume
  (inside-out) is flipped so every volume is outward: counts of different volumes then add
  and never cancel.
* **Open or non-manifold components** (a ground quad, a mesh with a hole, an edge shared by
  three faces) fall back to *extruding every triangle*: each triangle, oriented to face the
  light, is treated as the closed two-sided sliver ``{T, reversed T}`` with its own light cap,
  three sides and dark cap. The count at a point is then the number of such triangles between
  it and the light — exact for any triangle soup (what a shadow ray sees), at three side quads
  per triangle instead of per silhouette edge. Silhouette extrusion of an open mesh would
  leak: its boundary edges are not silhouettes, so the volume has holes
  (tests/failures/test_shadow_volume_failures.py). :func:`analyse_topology` reports which
  components fell back and why.
* **Extrusion to infinity** in homogeneous coordinates (Everitt & Kilgard §4): a vertex ``v``
  goes to ``(v − L, 0)`` for a point or spot light at ``L`` and to ``(d, 0)`` for a directional
  light travelling along ``d`` (then every dark-cap vertex is the same point and the dark cap
  vanishes; sides are triangles). With a perspective camera these project to finite window
  positions; with an orthographic one (whose ``w`` would be 0 there) the volume is instead
  extruded to a finite distance beyond every receiver and caster, which gives the same counts
  for every receiver point.
* Spot lights cast the shadows of a point light at their position (the cone limits the light,
  not the occluders), as :mod:`blinn_phong.shadows.raytrace` does.

Counting
--------
Volume triangles are transformed to clip space and clipped against the near plane
``z_c ≥ −w_c`` (as OpenGL clips) and no far plane (as ``GL_DEPTH_CLAMP`` leaves it), plus a
guard band ``|x_c|, |y_c| ≤ G·w_c`` wider than every receiver, which only keeps window positions
finite where vertices at infinity graze the eye plane. Each receiver is projected with the same
matrices. A volume triangle counts at a receiver whose normalised-device ``(x, y)`` lies inside it — edge
functions evaluated from each edge's canonical (lexicographically first) endpoint, so two
triangles sharing an edge give exactly opposite values and, with a fixed tie-break
(perturbation towards +x, then +y), a point on a shared edge belongs to exactly one of them —
and whose depth, interpolated linearly in screen space (OpenGL 4.6 §14.6.1), is nearer than the
receiver's (z-pass; ``GL_LESS`` passes) or not nearer (z-fail; the depth test fails). Facing is
the sign of the window-space area (``GL_CCW`` front). Receivers are binned on a screen grid. With
numba every step is compiled (receiver projection, a counting sort into tiles, each tile's depth
range and depth plane, volume-triangle set-up, counting, written back in input order); the
counting kernel gives each thread interleaved rows of tiles, each row owning its receivers (no
write races), and jobs under ``_PARALLEL_RECEIVERS`` run on one thread. The numpy engine is the
readable reference: it tests every receiver a triangle's tiles hold. The compiled kernel skips
only what provably cannot count, so it reaches the same per-receiver decisions: a tile the
triangle misses, or whose receivers all lie behind it (z-pass) or in front of it (z-fail) —
judged from the tile's receiver depth range, or, when the ranges overlap, from a least-squares
depth plane of the tile's receivers with their measured residuals (the triangle's depth plane
minus the receivers' is affine, so its corners bound it over the tile; every bound is widened
past the rounding of the per-receiver expressions). That settles a ground under its own light
cap (receivers 1e-4 above the cap, on one plane) without a test per receiver. Whole tiles
inside a triangle and wholly on one side of it are counted at once. Counts are integers and
both engines evaluate the same floating-point expressions in the same order (written out, no
fused multiply-add), so they agree exactly. Topologies, volumes and near-plane proofs are cached
by a digest of the casters and the light (a frame's lights share one topology; the next frame
reuses the volumes). The next light of a frame (the same point and normal arrays, the same
camera) projects its receivers — moved towards that light — straight into the previous
light's tile order instead of sorting them again; each tile is then widened by the farthest
any receiver now lies outside it, so the order only affects speed, never a count.

Self-shadowing without depth invariance: a real stencil pass relies on a surface and its own
light cap giving bit-identical depths (the cap then fails ``GL_LESS`` and lies "behind"). Here
receivers are world points, so each is first moved ``offset`` along its normal towards the
light's side (as the ray tracer's origins are, :func:`blinn_phong.shadows.raytrace.point_light_visibility`):
a face lit by the light moves out of its own volume, a face turned away moves into it.
"""

from __future__ import annotations

import functools
import hashlib
import math
import weakref
from dataclasses import dataclass

import numpy as np

from blinn_phong._checks import choice_error
from blinn_phong._numba import use_compiled
from blinn_phong._scratch import carve, carved_bytes
from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Camera
from blinn_phong.shadows.method import ShadowFrame, ShadowMethod

__all__ = [
    "STENCIL_METHODS",
    "Topology",
    "analyse_topology",
    "choose_stencil",
    "pixel_binning",
    "shadow_volume_triangles",
    "shadow_volume_visibility",
    "silhouette_edges",
    "stencil_counts",
    "zpass_is_safe",
]

#: Counting methods: ``zpass`` (Heidmann 1991) and ``zfail`` (Everitt & Kilgard 2002).
STENCIL_METHODS: tuple[str, ...] = ("zfail", "zpass")
_TILE_POINTS = 32  # receivers per screen tile, on average (16–128 measured: 32 is fastest)
_PARALLEL_RECEIVERS = 10_000  # fewer receivers are counted on one thread (parallel pays from about 10k)
_PARALLEL_FACES = 10_000  # fewer volume triangles are set up on one thread


# --------------------------------------------------------------------------- input checks


def _triangles(name: str, value: object) -> np.ndarray:
    tris = np.asarray(value)
    if tris.dtype.kind not in "fiu" or tris.ndim != 3 or tris.shape[1:] != (3, 3):
        raise ValueError(f"{name}: expected a real array of shape (n, 3, 3), got {tris.dtype} {tris.shape}")
    if not np.all(np.isfinite(tris)):
        raise ValueError(f"{name}: expected finite coordinates, got NaN or Inf")
    return tris.astype(np.float64, copy=False)


def _points(name: str, value: object, check_finite: bool = True) -> np.ndarray:
    """(n, 3) float64; ``check_finite=False`` leaves the NaN/Inf check to :func:`_projected`."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiu" or arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name}: expected a real array of shape (n, 3), got {arr.dtype} {arr.shape}")
    if check_finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected finite coordinates, got NaN or Inf")
    return arr.astype(np.float64, copy=False)


def _light(light: object) -> tuple[np.ndarray, bool]:
    """(position or direction of travel, is_directional)."""
    if getattr(light, "casts_shadows", False):
        h = light.homogeneous()  # type: ignore[attr-defined]  # (−direction, 0) or (position, 1)
        if h[3] == 0:
            return -h[:3] / np.linalg.norm(h[:3]), True
        return h[:3], False
    raise TypeError(
        f"light: expected a DirectionalLight, PointLight or SpotLight, got {type(light).__name__}"
    )


# --------------------------------------------------------------------------- topology


@dataclass(frozen=True, eq=False)
class Topology:
    """Welded connectivity of a triangle soup and which parts are closed 2-manifolds.

    Attributes:
        vertices: (V, 3) float64 welded world positions (bit-identical coordinates merged).
        triangles: (T, 3) int64 vertex indices, one row per input triangle (in input order);
            triangle orientation is flipped where its component was inside-out.
        valid: (T,) bool, False for triangles with a repeated vertex (zero area, never drawn).
        component: (T,) int64 edge-connected component of each triangle (-1 when not valid).
        closed: (T,) bool, True when the triangle's component is a closed 2-manifold.
        reasons: one line per open or non-manifold component: why it is extruded per triangle.
        neighbour: (T, 3) int64, the triangle across edge ``(v_i, v_(i+1))`` of each triangle
            (its twin's owner), −1 where the edge has no unique twin.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    valid: np.ndarray
    component: np.ndarray
    closed: np.ndarray
    reasons: tuple[str, ...]
    neighbour: np.ndarray

    @functools.cached_property
    def planes(self) -> tuple[np.ndarray, np.ndarray]:
        """(T, 3) each triangle's unnormalised normal ``(v₁ − v₀) × (v₂ − v₀)`` and (T, 3) its
        first vertex ``v₀``: what every light's facing test reads (computed once per topology;
        a topology is cached and shared, so its arrays are never written in place)."""
        v = self.vertices[self.triangles]
        return np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), np.ascontiguousarray(v[:, 0])


def analyse_topology(world_triangles: np.ndarray) -> Topology:
    """Weld a triangle soup, build edge adjacency and classify components as closed 2-manifolds.

    A component is closed when each of its directed edges ``a→b`` occurs exactly once and its
    twin ``b→a`` exactly once (every edge shared by two consistently oriented faces). Closed
    components with negative signed volume ``Σ v₀·(v₁×v₂)/6`` are flipped to face outwards.

    Args:
        world_triangles: (n, 3, 3) world-space triangles, counter-clockwise = front.

    Returns:
        :class:`Topology`.
    """
    tris = _triangles("world_triangles", world_triangles)
    n = len(tris)
    if n == 0:
        e = np.zeros(0, np.int64)
        return Topology(
            np.zeros((0, 3)),
            np.zeros((0, 3), np.int64),
            e.astype(bool),
            e,
            e.astype(bool),
            (),
            np.zeros((0, 3), np.int64),
        )
    return _topology_with_key(tris)[0]


def _digest(tris: np.ndarray) -> bytes:
    """A 128-bit content digest of a float64 array (the cache key of its topology): BLAKE2b, or
    with numba four interleaved splitmix64 lanes per 64-bit half, seeded differently (a cache
    key against accidental collisions, not an adversary; it is several times faster)."""
    flat = np.ascontiguousarray(tris).reshape(-1)
    from blinn_phong._numba import numba_available

    if not numba_available():
        return hashlib.blake2b(flat.data, digest_size=16).digest()
    lanes = _hash_kernels()[3](flat.view(np.uint64))
    return b"%d:" % len(flat) + lanes.tobytes()


#: The last digests of read-only triangle arrays, by identity: (weak reference, digest). A
#: frame's lights share one read-only array of casters (the pipeline's cached world geometry).
_DIGESTS: list[tuple[object, bytes]] = []


def _topology_with_key(tris: np.ndarray) -> tuple[Topology, bytes]:
    """The (cached) topology of checked float64 triangles and the digest it is cached by (a
    read-only array's digest is remembered while it lives: it is not written in place)."""
    key = next((k for ref, k in _DIGESTS if ref() is tris), None)  # type: ignore[operator]
    if key is None:
        key = _digest(tris)
        if not tris.flags.writeable:
            try:
                _DIGESTS[:] = [(weakref.ref(tris), key), *_DIGESTS[:3]]
            except TypeError:  # an array that takes no weak reference: not kept
                pass
    if key in _TOPOLOGY_CACHE:
        return _TOPOLOGY_CACHE[key], key
    if len(tris) == 0:
        e = np.zeros(0, np.int64)
        empty = (
            np.zeros((0, 3)),
            np.zeros((0, 3), np.int64),
            e.astype(bool),
            e,
            e.astype(bool),
            (),
            np.zeros((0, 3), np.int64),
        )
        return Topology(*empty), key
    topology = _analyse(tris)
    if len(_TOPOLOGY_CACHE) >= 2:
        _TOPOLOGY_CACHE.pop(next(iter(_TOPOLOGY_CACHE)))
    _TOPOLOGY_CACHE[key] = topology
    return topology, key


#: The last topologies analysed, by a digest of the triangles (a frame asks once per light).
_TOPOLOGY_CACHE: dict[bytes, Topology] = {}


@functools.lru_cache(maxsize=1)
def _hash_kernels() -> tuple[object, object, object, object]:
    """Compiled hash-table welding (:func:`blinn_phong._hashing.weld_rows`), edge pairing (linear
    probing) and union-find (same results as the numpy sorts and pointer jumping), and the
    content digest of :func:`_digest`."""
    import numba

    from blinn_phong import _hashing as hx  # module-level helpers: numba caches the callers

    @numba.njit(cache=True)
    def pair(key, twin):  # pragma: no cover - compiled
        """Per directed edge: how often it occurs, how often its twin occurs, the twin's first index."""
        m = key.shape[0]
        size = 1
        while size < 2 * m:
            size *= 2
        table = np.full(size, -1, np.int64)
        count = np.zeros(m, np.int64)  # indexed by the first occurrence
        first_of = np.empty(m, np.int64)
        for e in range(m):
            slot = np.int64(hx.mix(np.uint64(key[e])) & np.uint64(size - 1))
            while True:
                f = table[slot]
                if f < 0:
                    table[slot] = e
                    first_of[e] = e
                    count[e] = 1
                    break
                if key[f] == key[e]:
                    first_of[e] = f
                    count[f] += 1
                    break
                slot = (slot + 1) & (size - 1)
        own = np.empty(m, np.int64)
        twin_count = np.zeros(m, np.int64)
        twin_first = np.full(m, -1, np.int64)
        for e in range(m):
            own[e] = count[first_of[e]]
            slot = np.int64(hx.mix(np.uint64(twin[e])) & np.uint64(size - 1))
            while True:
                f = table[slot]
                if f < 0:
                    break
                if key[f] == twin[e]:
                    twin_count[e] = count[f]
                    twin_first[e] = f
                    break
                slot = (slot + 1) & (size - 1)
        return own, twin_count, twin_first

    @numba.njit(cache=True)
    def union_find(n, rows, cols):  # pragma: no cover - compiled
        parent = np.arange(n)
        for e in range(rows.shape[0]):
            a = rows[e]
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            b = cols[e]
            while parent[b] != b:
                parent[b] = parent[parent[b]]
                b = parent[b]
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b
        for i in range(n):  # roots are the smallest index of their set; parents point lower
            parent[i] = parent[parent[i]]
        return parent

    @numba.njit(cache=True)
    def digest(bits):  # pragma: no cover - compiled
        out = np.empty(8, np.uint64)
        for lane in range(8):
            out[lane] = hx.mix(np.uint64(lane + 1) * np.uint64(0x9E3779B97F4A7C15))
        m = bits.shape[0]
        full = m - m % 4
        for i in range(0, full, 4):
            for lane in range(4):
                v = bits[i + lane]
                out[lane] = hx.mix(out[lane] ^ v)
                out[lane + 4] = hx.mix((out[lane + 4] + v) * np.uint64(0xD6E8FEB86659FD93))
        for i in range(full, m):
            out[0] = hx.mix(out[0] ^ bits[i])
            out[4] = hx.mix((out[4] + bits[i]) * np.uint64(0xD6E8FEB86659FD93))
        return out

    return hx.weld_rows, pair, union_find, digest


@functools.lru_cache(maxsize=1)
def _pair_kernel() -> object:  # a numba dispatcher
    import numba

    @numba.njit(parallel=True, cache=True)
    def pair_by_vertex(a, b, nv):  # pragma: no cover - compiled
        """``pair``'s results for directed edges ``a[e] → b[e]`` from the edges grouped by start
        vertex (a stable counting sort, so a group lists its edges in input order): an edge's
        own count is how often its end appears in its start's group, its twin's the same with
        the ends swapped, the twin's first index the first such edge."""
        m = a.shape[0]
        start = np.zeros(nv + 1, np.int64)
        for e in range(m):
            start[a[e] + 1] += 1
        for v in range(nv):
            start[v + 1] += start[v]
        fill = start[:nv].copy()
        end = np.empty(m, np.int64)
        index = np.empty(m, np.int64)
        for e in range(m):
            k = fill[a[e]]
            fill[a[e]] = k + 1
            end[k] = b[e]
            index[k] = e
        own = np.empty(m, np.int64)
        twin_count = np.empty(m, np.int64)
        twin_first = np.empty(m, np.int64)
        for e in numba.prange(m):
            u = a[e]
            v = b[e]
            c = 0
            for k in range(start[u], start[u + 1]):
                if end[k] == v:
                    c += 1
            own[e] = c
            c = 0
            f = -1
            for k in range(start[v], start[v + 1]):
                if end[k] == u:
                    if f < 0:
                        f = index[k]
                    c += 1
            twin_count[e] = c
            twin_first[e] = f
        return own, twin_count, twin_first

    return pair_by_vertex


#: Edges grouped by start vertex scan each group once per edge of it (and of its twins' group):
#: ``Σ degree²`` steps. Up to this many steps per edge the groups are used, beyond it (a vertex
#: shared by thousands of faces) the hash table, whose cost does not depend on degrees.
_GROUP_STEPS_PER_EDGE = 32


def _pair_edges(a: np.ndarray, b: np.ndarray, nv: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per directed edge ``a[e] → b[e]`` (vertex indices below ``nv``): how often it occurs, how
    often its twin ``b → a`` occurs, and the twin's first index (−1: none). Compiled: edges grouped
    by start vertex, or a hash table where some vertex has a very high degree."""
    degree = np.bincount(a, minlength=nv).astype(np.float64)
    if float(degree @ degree) <= _GROUP_STEPS_PER_EDGE * max(len(a), 1):
        return _pair_kernel()(a, b, nv)
    return _hash_kernels()[1](a * nv + b, b * nv + a)


def _components(n: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Connected components of n nodes joined by edges (rows[i], cols[i]): each node's label is
    the smallest node index of its component (the same on both engines)."""
    from blinn_phong._numba import numba_available

    if numba_available():
        return _hash_kernels()[2](n, rows.astype(np.int64), cols.astype(np.int64))
    parent = np.arange(n)
    while True:  # hook larger roots under smaller ones, then jump pointers until flat
        pu, pv = parent[rows], parent[cols]
        lo, hi = np.minimum(pu, pv), np.maximum(pu, pv)
        moving = lo != hi
        if not moving.any():
            return parent
        np.minimum.at(parent, hi[moving], lo[moving])
        while True:
            grand = parent[parent]
            if np.array_equal(grand, parent):
                break
            parent = grand


def _weld(flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge bit-identical rows of (m, 3) float64: (unique rows, index of each input row)."""
    flat = np.ascontiguousarray(flat + 0.0)  # -0.0 and 0.0 weld together
    bits = flat.view(np.uint64).reshape(-1, 3)
    from blinn_phong._numba import numba_available

    if numba_available():
        representative, inverse = _hash_kernels()[0](bits)
        return flat[representative], inverse

    from blinn_phong._hashing import splitmix64 as mix

    digest = mix(mix(mix(bits[:, 0]) ^ bits[:, 1]) ^ bits[:, 2])
    order = np.argsort(digest, kind="stable")  # radix sort for integers
    ordered = digest[order]
    first = np.r_[True, ordered[1:] != ordered[:-1]]
    group = np.cumsum(first) - 1
    representative = order[first]
    if not np.array_equal(bits[order], bits[representative[group]]):  # a collision: sort exactly
        order = np.lexsort((bits[:, 2], bits[:, 1], bits[:, 0]))
        rows = bits[order]
        first = np.r_[True, np.any(rows[1:] != rows[:-1], axis=1)]
        group = np.cumsum(first) - 1
        representative = order[first]
    inverse = np.empty(len(flat), np.int64)
    inverse[order] = group
    return flat[representative], inverse


def _analyse(tris: np.ndarray) -> Topology:
    n = len(tris)
    vertices, inverse = _weld(tris.reshape(-1, 3))
    faces = inverse.reshape(n, 3).astype(np.int64)
    valid = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    idx = np.flatnonzero(valid)
    nv = len(vertices)
    # directed edges a→b of the valid triangles
    a = faces[idx][:, [0, 1, 2]].ravel()
    b = faces[idx][:, [1, 2, 0]].ravel()
    owner = np.repeat(idx, 3)
    from blinn_phong._numba import numba_available

    if numba_available():
        own_count, twin_count, twin_first = _pair_edges(a, b, nv)
        has_twin = twin_first >= 0
        twin_at = np.maximum(twin_first, 0)
    else:
        key = a * nv + b
        twin = b * nv + a
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        starts = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
        uniq = sorted_key[starts]
        counts = np.diff(np.r_[starts, len(sorted_key)])
        run = np.empty(len(key), np.int64)
        run[order] = np.cumsum(np.r_[True, sorted_key[1:] != sorted_key[:-1]]) - 1
        own_count = counts[run]
        tpos = np.clip(np.searchsorted(uniq, twin), 0, max(len(uniq) - 1, 0))
        has_twin = uniq[tpos] == twin
        twin_count = np.where(has_twin, counts[tpos], 0)
        twin_at = order[starts[tpos]]  # the first occurrence of the twin (where it exists)
    bad_edge = (own_count != 1) | (twin_count != 1)
    # components: triangles joined through an edge and its twin
    labels = _components(n, owner[has_twin], owner[twin_at[has_twin]])
    component = np.full(n, -1, np.int64)
    # relabel valid triangles' components densely
    present = np.zeros(n, bool)  # a label is its component's smallest triangle index: below n
    present[labels[idx]] = True
    dense = (np.cumsum(present) - 1)[labels[idx]]  # each label's rank among the labels (np.unique's)
    component[idx] = dense
    n_comp = int(dense.max()) + 1 if len(idx) else 0
    comp_bad = np.bincount(component[owner], weights=bad_edge, minlength=n_comp) > 0
    closed = np.zeros(n, bool)
    closed[idx] = ~comp_bad[component[idx]]
    reasons = []
    for c in np.flatnonzero(comp_bad):
        sel = component[owner] == c
        n_tri = int(np.count_nonzero(component == c))
        boundary = int(np.count_nonzero(sel & (twin_count == 0)))
        shared = int(np.count_nonzero(sel & ((own_count > 1) | (twin_count > 1))))
        what = []
        if boundary:
            what.append(f"{boundary} boundary edges (open)")
        if shared:
            what.append(f"{shared} edges shared by more than two faces or inconsistently oriented")
        reasons.append(
            f"component of {n_tri} triangles: {', '.join(what)}; every triangle extruded on its own"
        )
    # outward orientation of closed components
    v = vertices[faces]
    signed = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])) / 6.0
    comp_volume = np.bincount(component[idx], weights=signed[idx], minlength=n_comp)  # summed in order
    flip = np.zeros(n, bool)
    flip[idx] = closed[idx] & (comp_volume[component[idx]] < 0)
    faces = faces.copy()
    faces[flip] = faces[flip][:, ::-1]
    neighbour = np.full((n, 3), -1, np.int64)
    unique_twin = has_twin & (own_count == 1) & (twin_count == 1)
    twin_owner = np.where(unique_twin, owner[twin_at], -1)
    neighbour[idx] = twin_owner.reshape(-1, 3)
    # a reversed face (v2, v1, v0) has the edges of (v0, v1, v2) in the order 1, 0, 2
    neighbour[flip] = neighbour[flip][:, [1, 0, 2]]
    return Topology(vertices, faces, valid, component, closed, tuple(reasons), neighbour)


def _facing(topology: Topology, light_vec: np.ndarray, directional: bool) -> np.ndarray:
    """(T,) float64 plane-side value: > 0 when the triangle's front faces the light."""
    normal, first = topology.planes
    if directional:
        return -(normal @ light_vec)
    return np.einsum("ij,ij->i", normal, light_vec - first)


def silhouette_edges(topology: Topology, light: DirectionalLight | PointLight | SpotLight) -> np.ndarray:
    """Directed silhouette edges of the closed components for one light.

    An edge is a silhouette edge when one of its two faces faces the light (``n·(L − v₀) > 0``,
    or ``−n·d > 0`` for a directional light) and the other does not. It is returned as
    ``(a, b)`` in the order it has in the face that faces the light.

    Args:
        topology: from :func:`analyse_topology`.
        light: the light.

    Returns:
        (E, 2) int64 vertex indices into ``topology.vertices``.
    """
    light_vec, directional = _light(light)
    return _silhouette(topology, _facing(topology, light_vec, directional) > 0)


def _silhouette(topology: Topology, lit: np.ndarray) -> np.ndarray:
    sel = np.flatnonzero(topology.closed & lit)
    f = topology.triangles[sel]
    nb = topology.neighbour[sel]
    edges = []
    for i in range(3):
        other = nb[:, i]
        is_sil = (other >= 0) & ~lit[np.maximum(other, 0)]  # a boundary edge (no twin) is no silhouette
        edges.append(np.stack([f[is_sil, i], f[is_sil, (i + 1) % 3]], axis=1))
    return np.concatenate(edges)


def _to_infinity(
    points: np.ndarray, light_vec: np.ndarray, directional: bool, extent: float | None
) -> np.ndarray:
    """(n, 4) homogeneous images of points pushed away from the light (to infinity, or ``extent`` away)."""
    if directional:
        d = np.broadcast_to(light_vec, points.shape)
    else:
        d = points - light_vec
    if extent is None:
        return np.c_[d, np.zeros(len(points))]
    length = np.linalg.norm(d, axis=1, keepdims=True)
    return np.c_[points + d / np.maximum(length, 1e-300) * extent, np.ones(len(points))]


def shadow_volume_triangles(
    world_triangles: np.ndarray | Topology,
    light: DirectionalLight | PointLight | SpotLight,
    *,
    caps: bool | str = True,
    extent: float | None = None,
    force_silhouette: bool = False,
) -> np.ndarray:
    """The shadow volumes of every caster for one light, as outward-facing homogeneous triangles.

    Closed components: light cap (faces facing the light), a quad per silhouette edge, dark cap
    (the other faces, pushed away). Open/non-manifold components: every triangle extruded on its
    own (see the module docstring). Quads are split into two triangles.

    Args:
        world_triangles: (n, 3, 3) world-space triangles, or a :class:`Topology` of them.
        light: the light.
        caps: ``True`` — light and dark caps (z-fail needs both); ``"light"`` — the light caps
            only (z-pass: a light cap lies in front of every receiver hidden behind a caster's
            lit faces, while a dark cap at infinity is never in front of a finite point);
            ``False`` — no caps (Heidmann's z-pass, right only for receivers no caster hides).
        extent: None — extrude to infinity (w = 0); else the world distance of the far end.
        force_silhouette: treat open components as if closed too (silhouette extrusion only):
            wrong for open meshes, kept to measure their leak.

    Returns:
        (m, 3, 4) float64 homogeneous world-space triangles, counter-clockwise seen from
        outside the volume.
    """
    if caps not in (True, False, "light"):
        raise ValueError(f"caps: expected True, False or 'light', got {caps!r}")
    light_cap, dark_cap = (True, False) if isinstance(caps, str) else (bool(caps), bool(caps))
    topo = world_triangles if isinstance(world_triangles, Topology) else analyse_topology(world_triangles)
    if force_silhouette:
        topo = Topology(
            topo.vertices,
            topo.triangles,
            topo.valid,
            topo.component,
            topo.valid.copy(),
            topo.reasons,
            topo.neighbour,
        )
    light_vec, directional = _light(light)
    verts = topo.vertices
    facing = _facing(topo, light_vec, directional)
    lit = facing > 0
    hv = np.c_[verts, np.ones(len(verts))]
    far = _to_infinity(verts, light_vec, directional, extent)
    parts = []
    # closed components: silhouette extrusion
    closed = topo.closed
    sil = _silhouette(topo, lit) if closed.any() else np.zeros((0, 2), np.int64)
    a, b = sil[:, 0], sil[:, 1]
    # side quad (a, b, b∞, a∞): outward for an edge a→b of a face that faces the light
    parts.append(np.stack([hv[b], hv[a], far[a]], axis=1))
    parts.append(np.stack([hv[b], far[a], far[b]], axis=1))
    if light_cap:
        parts.append(hv[topo.triangles[closed & lit]])
    if dark_cap:
        parts.append(far[topo.triangles[closed & ~lit]])
    # open components: every triangle its own two-sided sliver, oriented to face the light
    single = topo.valid & ~closed & (facing != 0)
    f = topo.triangles[single]
    f = np.where((facing[single] > 0)[:, None], f, f[:, ::-1])
    for i, j in ((0, 1), (1, 2), (2, 0)):
        ea, eb = f[:, i], f[:, j]
        parts.append(np.stack([hv[eb], hv[ea], far[ea]], axis=1))
        parts.append(np.stack([hv[eb], far[ea], far[eb]], axis=1))
    if light_cap:
        parts.append(hv[f])
    if dark_cap:
        parts.append(far[f[:, ::-1]])
    return np.concatenate(parts).reshape(-1, 3, 4)


# --------------------------------------------------------------------------- counting


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


def _jit(parallel: bool, **options: object) -> object:
    """``numba.njit(parallel=parallel, cache=True, **options)`` for a kernel built both serial
    and parallel, each variant cached under its own name.

    numba's on-disk cache files a function under its qualified name and keys each entry by the
    function's bytecode and closure values, not by its compile options: the serial and parallel
    builds of one kernel would share an entry, and whichever was compiled first would be loaded
    for both (a parallel kernel then runs on one thread). The variant's name is therefore made
    part of the function's qualified name before it is compiled.
    """
    import numba

    def build(fn: object) -> object:
        fn.__qualname__ = f"{fn.__qualname__}.{'parallel' if parallel else 'serial'}"  # type: ignore[attr-defined]
        return numba.njit(parallel=parallel, cache=True, **options)(fn)

    return build


@functools.lru_cache(maxsize=2)
def _kernel(parallel: bool = True) -> object:  # a numba dispatcher
    import numba

    from blinn_phong.shadows import _volume_helpers as vh  # module-level helpers: numba caches the callers

    @_jit(parallel, fastmath=False)
    def count(
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
        # Receivers arrive sorted by tile: px[cell_start[c]:cell_start[c + 1]] lie in tile c;
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
        # gets a share of the busy rows whatever the threads' static split of the bands
        for band in numba.prange(n_bands):
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
        return out_counts, out_vis

    return count


# --------------------------------------------------------------------------- compiled set-up
#
# The numba engine runs the per-receiver and per-volume-triangle set-up compiled (one pass
# each, no large temporaries); every expression below is written out in the same order as its
# numpy twin (:func:`_project_numpy`, :func:`_transform`, :func:`_setup`), without fused
# multiply-adds, so both engines produce bit-identical set-ups and therefore identical counts.


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


@functools.lru_cache(maxsize=2)
def _fast_kernels(parallel: bool = True) -> tuple[object, ...]:
    """Compiled receiver projection, tile binning (counting sort), volume-triangle set-up, each
    tile's receiver depths, and the projection into an earlier binning's order."""
    import numba

    from blinn_phong.shadows import _volume_helpers as vh  # module-level helpers: numba caches the callers

    @_jit(parallel)
    def project(p, n, light_vec, directional, offset, moved, vp):  # pragma: no cover - compiled
        m = p.shape[0]
        px = np.empty(m)
        py = np.empty(m)
        pz = np.empty(m)
        n_chunks = 64
        mat = vh.matrix_entries(vp)
        lv = (light_vec[0], light_vec[1], light_vec[2])
        # per chunk: min/max of x and y, min of w, 1 if an input was not finite, (unused) 0, 0
        stats = np.zeros((n_chunks, 8))
        size = (m + n_chunks - 1) // n_chunks
        for chunk in numba.prange(n_chunks):
            xlo = np.inf
            xhi = -np.inf
            ylo = np.inf
            yhi = -np.inf
            wlo = np.inf
            bad = 0.0
            for i in range(chunk * size, min(m, (chunk + 1) * size)):
                if not vh.finite_input(p, n, moved, i):
                    bad = 1.0
                x, y, z, w = vh.project_point(p, n, lv, directional, offset, moved, mat, i)
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
        return px, py, pz, stats

    @_jit(parallel)
    def project_binned(
        p, n, light_vec, directional, offset, moved, vp, order, cell_start, xmin, ymin, cw, ch, nx, ny,
        sx, sy, sz,
    ):  # fmt: skip  # pragma: no cover - compiled
        """:func:`project` into an earlier binning's order (sorted by tile: receiver ``order[k]``
        at ``k``, written into ``sx``, ``sy``, ``sz``), with how far any receiver now lies outside
        its tile (a receiver moved for another light may cross a border: the kernel widens every
        tile by as much), and each tile's depths (``tile_depths``)."""
        mat = vh.matrix_entries(vp)
        lv = (light_vec[0], light_vec[1], light_vec[2])
        # per row of tiles: min/max of x and y, min of w, 1 if an input was not finite, and the
        # largest distance of a receiver outside its tile along x and along y
        stats = np.zeros((ny, 8))
        zlo = np.full(nx * ny, np.inf)
        zhi = np.full(nx * ny, -np.inf)
        fit = np.zeros((nx * ny, 5))
        spread = np.argsort(np.arange(ny) % 16, kind="mergesort")  # rows interleaved over the threads
        for i_row in numba.prange(ny):
            row = spread[i_row]
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
                    if not vh.finite_input(p, n, moved, i):
                        bad = 1.0
                    x, y, z, w = vh.project_point(p, n, lv, directional, offset, moved, mat, i)
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
        return sx, sy, sz, stats, zlo, zhi, fit

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

    @_jit(parallel)
    def tile_depths(px, py, pz, cell_start, xmin, ymin, cw, ch, nx, ny):  # pragma: no cover - compiled
        """Per tile its receivers' depth range (zlo, zhi), and a least-squares depth plane
        ``a + (b·(x − xc) + c·(y − yc))`` about the tile's centre (xc, yc) with the lowest and
        highest residual ``z − plane`` of its receivers, widened past rounding: (n_cells, 5) rows
        (a, b, c, r_lo, r_hi). Any plane would do (the residuals are measured); a good one lets
        the kernel settle a tile whose receivers lie on one surface (a ground under its own
        light cap) without testing each receiver."""
        n_cells = nx * ny
        zlo = np.full(n_cells, np.inf)
        zhi = np.full(n_cells, -np.inf)
        fit = np.zeros((n_cells, 5))
        spread = np.argsort(np.arange(ny) % 16, kind="mergesort")  # rows interleaved over the threads
        for i_row in numba.prange(ny):
            row = spread[i_row]
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
        return zlo, zhi, fit

    @_jit(parallel)
    def to_clip(src, vp, guard):  # pragma: no cover - compiled
        """Which homogeneous world triangles cross the near plane or the guard band once moved
        to clip space by ``vp`` (as ``setup`` transforms them): those are clipped first."""
        todo = np.zeros(src.shape[0], np.bool_)
        for t in numba.prange(src.shape[0]):
            for v in range(3):
                xc, yc, zc, wc = vh.clip_vertex(src, vp, True, t, v)
                gw = guard * wc
                if not (zc + wc >= 0 and gw - xc >= 0 and xc + gw >= 0 and gw - yc >= 0 and yc + gw >= 0):
                    todo[t] = True
        return todo

    @_jit(parallel)
    def setup(
        src, cut, todo, vp, xmin, ymin, cw, ch, nx, ny, slack_x, slack_y,
        ex, ey, edx, edy, esign, etie, z0, x0, y0, gx, gy, front, cx0, cx1, cy0, cy1, bx0, bx1, by0, by1,
    ):  # fmt: skip  # pragma: no cover - compiled
        """Per triangle the fields of :class:`_Setup` (see :func:`_setup`), written into the
        given arrays (``_setup_arrays``): first the homogeneous world triangles ``src``, moved to
        clip space by ``vp`` (those flagged in ``todo`` by ``to_clip`` are left empty), then the
        clip-space triangles ``cut`` (the flagged ones, clipped). Triangles with w ≤ 0 or zero or
        non-finite area are left empty too (an empty triangle: ``cx0 > cx1``, its edges unset). A
        triangle's tiles are those its bounding box meets once widened by the receivers' slack
        (see ``count``)."""
        n_src = src.shape[0]
        s = n_src + cut.shape[0]
        for t in numba.prange(s):
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
            if t < n_src and todo[t]:
                continue
            transform = t < n_src
            tri = src if transform else cut
            k = np.int64(t) if transform else np.int64(t) - n_src  # (a parallel loop's index is unsigned)
            c00, c01, c02, c03 = vh.clip_vertex(tri, vp, transform, k, 0)
            c10, c11, c12, c13 = vh.clip_vertex(tri, vp, transform, k, 1)
            c20, c21, c22, c23 = vh.clip_vertex(tri, vp, transform, k, 2)
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

    return project, bin_points, setup, tile_depths, project_binned, to_clip


def _threads() -> int:
    """Threads a compiled parallel loop runs on (numba's setting)."""
    import numba

    return max(1, int(numba.get_num_threads()))


def stencil_counts(
    volume_triangles: np.ndarray,
    view: np.ndarray,
    projection: np.ndarray,
    points: np.ndarray,
    *,
    stencil: str = "zfail",
    engine: str = "auto",
) -> np.ndarray:
    """Per receiver, the stencil count of the shadow-volume faces along its camera ray.

    Args:
        volume_triangles: (m, 3, 4) homogeneous world-space volume triangles, outward
            (counter-clockwise seen from outside), e.g. from :func:`shadow_volume_triangles`.
        view: 4×4 world → eye matrix of the camera.
        projection: 4×4 eye → clip matrix (OpenGL conventions); only the near plane clips.
        points: (n, 3) world-space receivers; each must lie in front of the camera (clip w > 0).
        stencil: ``"zfail"`` (faces behind the receiver: +1 back, −1 front) or ``"zpass"``
            (faces in front of it: +1 front, −1 back).
        engine: ``"numba"``, ``"numpy"`` (the reference) or ``"auto"``.

    Returns:
        (n,) int64 counts; 0 means outside every volume (lit) when the method is valid.
    """
    if stencil not in STENCIL_METHODS:
        raise choice_error("stencil", stencil, STENCIL_METHODS)
    vol = np.asarray(volume_triangles, dtype=np.float64)
    if vol.ndim != 3 or vol.shape[1:] != (3, 4) or not np.all(np.isfinite(vol)):
        raise ValueError(f"volume_triangles: expected finite (m, 3, 4), got shape {vol.shape}")
    p = _points("points", points)
    vp = np.asarray(projection, dtype=np.float64) @ np.asarray(view, dtype=np.float64)
    if vp.shape != (4, 4) or not np.all(np.isfinite(vp)):
        raise ValueError(f"view/projection: expected finite 4×4 matrices, got product shape {vp.shape}")
    numba_path = use_compiled(engine)
    if len(p) == 0:
        return np.zeros(0, np.int64)
    rec = _projected(p, p, np.zeros(3), False, 0.0, False, vp, numba_path)
    return _count(vol, vp, rec, stencil == "zfail")


@dataclass(frozen=True, eq=False)
class _Receivers:
    """Projected receivers: normalised-device (x, y, z) and their (xmin, xmax, ymin, ymax).

    The numpy engine keeps them in input order (``order`` None). The compiled engine keeps them
    sorted by the tiles of ``grid`` (receiver ``order[k]`` at ``k``, tile c holding
    ``cell_start[c]:cell_start[c + 1]``), with ``slack`` = (x, y): how far a receiver may lie
    outside its tile (0 when binned from these very positions).
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    bounds: tuple[float, float, float, float]
    grid: tuple[float, float, float, float, int, int] | None = None
    order: np.ndarray | None = None
    cell_start: np.ndarray | None = None
    slack: tuple[float, float] = (0.0, 0.0)
    depths: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # ``tile_depths``, if known


#: The last compiled binning of receivers: (weak references to the points and normals, the
#: view-projection bytes, grid, order, cell_start). The lights of a frame count the same
#: receivers, moved by ``offset`` towards each light: the next light projects straight into
#: this order instead of sorting again. Any permutation would count the same (every tile's
#: bounds, depths and slack are measured again); a good one only makes the tiles tight.
_BINNING: list[tuple] = []


def _projected(
    p: np.ndarray,
    n: np.ndarray,
    light_vec: np.ndarray,
    directional: bool,
    offset: float,
    moved: bool,
    vp: np.ndarray,
    numba_path: bool,
    reuse: bool = False,
    binning: tuple | None = None,
) -> _Receivers:
    """Receivers (moved ``offset`` towards the light's side when ``moved``) in normalised-device
    coordinates; the compiled engine also bins them into tiles (reusing the last binning of the
    same point and normal arrays under the same camera when ``reuse``, or projecting into
    ``binning`` = (grid, order, cell_start) when given, e.g. :func:`pixel_binning`). Raises if a
    receiver is behind the camera or a point or normal is not finite."""
    m = len(p)
    if numba_path:
        # small jobs run serially: a parallel region costs more than it saves on a busy machine
        parallel = m >= _PARALLEL_RECEIVERS
        kernels = _fast_kernels(parallel)
        key = vp.tobytes()
        cached = _BINNING[0] if reuse and _BINNING else None
        same = cached is not None and cached[0]() is p and cached[1]() is n and cached[2] == key
        if binning is not None and len(binning[1]) == m:
            cached = (None, None, key, *binning)
            same = True
        if same and len(cached[4]) == m:
            grid, order, cell_start = cached[3:]
            sx, sy, sz, stats, *depths = kernels[4](
                p, n, light_vec, directional, offset, moved, vp, order, cell_start, *grid,
                np.empty(m), np.empty(m), np.empty(m),
            )  # fmt: skip
        else:
            px, py, pz, stats = kernels[0](p, n, light_vec, directional, offset, moved, vp)
            cached = None
        bad = bool(stats[:, 5].any())
        w_ok = bool(stats[:, 4].min() > 0) if m else True
        lo, hi = stats.min(axis=0), stats.max(axis=0)
        bounds = (float(lo[0]), float(hi[1]), float(lo[2]), float(hi[3])) if m else (0.0,) * 4
    else:
        bad = not (np.all(np.isfinite(p)) and (not moved or np.all(np.isfinite(n))))
        q = _offset_numpy(p, n, light_vec, directional, offset) if moved else p
        px, py, pz, pw = _project_numpy(q, vp)
        w_ok = bool(np.all(pw > 0))
        bounds = (
            (float(px.min()), float(px.max()), float(py.min()), float(py.max())) if len(px) else (0.0,) * 4
        )
    if bad:
        raise ValueError("points/normals: expected finite coordinates, got NaN or Inf")
    if not w_ok:
        raise ValueError(f"points: some of the {len(p)} receivers lie behind the camera (clip w <= 0)")
    if not numba_path:
        return _Receivers(px, py, pz, bounds)
    if cached is not None:
        slack = (float(max(stats[:, 6].max(), 0.0)), float(max(stats[:, 7].max(), 0.0)))
        return _Receivers(sx, sy, sz, bounds, grid, order, cell_start, slack, tuple(depths))
    grid = _grid_params(m, bounds)
    order, cell_start, sx, sy, sz = kernels[1](px, py, pz, *grid)
    if reuse:
        try:
            _BINNING[:] = [(weakref.ref(p), weakref.ref(n), key, grid, order, cell_start)]
        except TypeError:  # an array that takes no weak reference: not kept
            _BINNING.clear()
    return _Receivers(sx, sy, sz, bounds, grid, order, cell_start)


@functools.lru_cache(maxsize=1)
def _pixel_binning_kernel() -> object:  # a numba dispatcher
    import numba

    @numba.njit(parallel=True, cache=True)
    def pixel_bins(rank, width, height, tile, nx, ny, order):  # pragma: no cover - compiled
        # counting sort of the covered pixels (rank ≥ 0) by tile: tile column col // tile, tile
        # row from the bottom (normalised y grows upwards, pixel rows downwards); each row of
        # tiles (its own cells) counted and filled in parallel, in row-major order within a tile,
        # into the first entries of ``order`` (width·height entries: room for every pixel)
        n_cells = nx * ny
        cell_start = np.zeros(n_cells + 1, np.int64)
        spread = np.argsort(np.arange(ny) % 16, kind="mergesort")  # tile rows interleaved over the threads
        for i_band in numba.prange(ny):
            band = spread[i_band]
            cy = ny - 1 - band
            for row in range(band * tile, min(height, (band + 1) * tile)):
                for col in range(width):
                    if rank[row * width + col] >= 0:
                        cell_start[cy * nx + col // tile + 1] += 1
        for c in range(n_cells):
            cell_start[c + 1] += cell_start[c]
        for i_band in numba.prange(ny):
            band = spread[i_band]
            cy = ny - 1 - band
            fill = cell_start[cy * nx : cy * nx + nx].copy()
            for row in range(band * tile, min(height, (band + 1) * tile)):
                for col in range(width):
                    r = rank[row * width + col]
                    if r >= 0:
                        c = col // tile
                        order[fill[c]] = r
                        fill[c] += 1
        return order[: cell_start[n_cells]], cell_start

    return pixel_bins


def pixel_binning(
    rank: np.ndarray, width: int, height: int, tile: int = 6
) -> tuple[tuple[float, float, float, float, int, int], np.ndarray, np.ndarray]:
    """Tiles of a frame's covered pixels for :func:`shadow_volume_visibility` (``binning=``).

    A frame's receivers are its pixels' surface points, which the camera projects onto the
    pixel centres (``x = 2(col + ½)/W − 1``, ``y = 1 − 2(row + ½)/H``; the offset towards
    the light moves them a little, measured as the tiles' slack): a grid of ``tile × tile``
    pixel blocks bins them with no projection and no sort.

    Args:
        rank: (H·W,) int64 each pixel's receiver row (−1: empty), row-major from the top.
        width: the frame's width in pixels.
        height: the frame's height in pixels.
        tile: pixels per tile side (``tile² ≈`` the 32 receivers per tile of the default grid).

    Returns:
        ``(grid, order, cell_start)``: grid ``(xmin, ymin, cw, ch, nx, ny)`` in normalised
        device coordinates, the receivers' rows in tile order, and each tile's first position.
    """
    if len(rank) != width * height:
        raise ValueError(f"rank: expected {width}×{height} = {width * height} entries, got {len(rank)}")
    nx, ny = -(-width // tile), -(-height // tile)
    cw, ch = 2.0 * tile / width, 2.0 * tile / height
    grid = (-1.0, 1.0 - ny * ch, cw, ch, nx, ny)
    # the order is written into numpy's memory (reused between frames without fresh page faults)
    order, cell_start = _pixel_binning_kernel()(
        np.ascontiguousarray(rank, dtype=np.int64), int(width), int(height), int(tile), nx, ny,
        np.empty(width * height, np.int64),
    )  # fmt: skip
    return grid, order, cell_start


_NO_CLIP = np.zeros((0, 3, 4))  # no clipped triangles (one array type for the set-up kernel)


def _setup_arrays(s: int) -> list[np.ndarray]:
    """Uninitialised arrays for the fields of :class:`_Setup` of ``s`` volume triangles, in its
    field order, carved from one numpy buffer (the set-up kernel initialises what it needs;
    numpy's memory is reused between frames without the page faults of fresh memory)."""
    f8, i8 = np.float64, np.int64
    parts = [((s, 3), f8)] * 5 + [((s, 3), np.bool_)] + [((s,), f8)] * 5 + [((s,), i8)] * 5 + [((s,), f8)] * 4
    return carve(np.empty(carved_bytes(*parts), np.uint8), *parts)


def _count(
    vol: np.ndarray, vp: np.ndarray, rec: _Receivers, zfail: bool, visibility: bool = False
) -> np.ndarray:
    """Stencil counts (or, with ``visibility``, 1.0 where the count is 0) of projected receivers,
    in their input order."""
    bounds = rec.bounds
    guard = 2.0 * max(*(abs(b) for b in bounds), 1.0) + 1.0
    if rec.order is None:  # the numpy engine
        grid = _grid_params(len(rec.x), bounds)
        st = _setup(_transform(vol, vp), grid, guard)
        cell_start, order = _bin_numpy(rec.x, rec.y, grid)
        counts = _count_numpy(st, rec.x, rec.y, rec.z, cell_start, order, grid[4], zfail)
        return (counts == 0).astype(np.float64) if visibility else counts
    grid = rec.grid
    xmin, ymin, cw, ch, nx, ny = grid
    slack_x, slack_y = rec.slack
    parallel = len(rec.x) >= _PARALLEL_RECEIVERS
    tile_depths = _fast_kernels(parallel)[3]
    # a small volume is set up on one thread (no parallel region to wait for)
    _, _, setup, _, _, to_clip = _fast_kernels(len(vol) >= _PARALLEL_FACES)
    todo = to_clip(vol, vp, guard)
    # the few faces crossing the near plane or the guard band: clipped, then set up after the rest
    cut = _clip(_transform(vol[todo], vp), guard) if todo.any() else _NO_CLIP
    fields = _setup_arrays(len(vol) + len(cut))
    setup(vol, cut, todo, vp, *grid, slack_x, slack_y, *fields)
    st = _Setup(*fields)
    depths = rec.depths
    zlo, zhi, fit = depths if depths is not None else tile_depths(rec.x, rec.y, rec.z, rec.cell_start, *grid)
    # small jobs run serially: a parallel region costs more than it saves on a busy machine
    n_bands = min(ny, _threads()) if parallel else 1
    m = len(rec.x)
    counts, lit = _kernel(parallel)(
        n_bands, ny, nx, xmin, ymin, cw, ch,
        st.cx0, st.cx1, st.cy0, st.cy1, st.ex, st.ey, st.edx, st.edy, st.esign, st.etie,
        st.z0, st.x0, st.y0, st.gx, st.gy, st.front, st.bx0, st.bx1, st.by0, st.by1,
        rec.x, rec.y, rec.z, rec.cell_start, zlo, zhi, fit, rec.order, zfail, visibility,
        slack_x, slack_y,
        np.empty(m, np.int64), np.empty(0 if visibility else m, np.int64), np.empty(m if visibility else 0),
    )  # fmt: skip
    return lit if visibility else counts


def zpass_is_safe(
    light: DirectionalLight | PointLight | SpotLight,
    world_triangles: np.ndarray,
    view: np.ndarray,
    projection: np.ndarray,
) -> bool:
    """True when no shadow volume can reach the camera's near plane, so z-pass counts exactly.

    A point q of the near-plane rectangle is in shadow only if the segment from q to the light
    (for a directional light: the ray towards it) meets a caster, i.e. only if a caster meets
    the convex hull of the rectangle and the light. z-pass is short by exactly the number of
    volumes containing q (see the module docstring), so it is exact when every caster lies
    wholly outside one of that hull's face planes. The test is conservative: a triangle not
    separated by a face plane counts as meeting the hull.

    Args:
        light: the light.
        world_triangles: (n, 3, 3) the casters, world space.
        view: 4×4 world → eye matrix.
        projection: 4×4 eye → clip matrix; must be a perspective (or orthographic) projection
            whose near plane is ``z_clip = −w_clip``.

    Returns:
        bool.
    """
    tris = _triangles("world_triangles", world_triangles)
    light_vec, directional = _light(light)
    inv = np.linalg.inv(np.asarray(projection, float) @ np.asarray(view, float))
    ndc = np.array([[-1, -1, -1, 1], [1, -1, -1, 1], [1, 1, -1, 1], [-1, 1, -1, 1]], float)
    corners = ndc @ inv.T
    if not np.all(np.abs(corners[:, 3]) > 1e-300):
        return False
    corners = corners[:, :3] / corners[:, 3:4]
    normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    planes = [(normal, float(normal @ corners[0]))]
    if directional:
        toward = -light_vec
        inside = corners.mean(axis=0) + toward  # a point inside the (infinite) prism
        if abs(float(normal @ toward)) < 1e-12 * np.linalg.norm(normal):
            return False
        for i in range(4):
            n = np.cross(corners[(i + 1) % 4] - corners[i], toward)
            planes.append((n, float(n @ corners[i])))
    else:
        apex = light_vec
        if abs(float(normal @ apex) - planes[0][1]) < 1e-9 * (
            np.linalg.norm(normal) * (1 + np.abs(apex).max())
        ):
            return False  # the light lies on the near plane
        inside = (corners.sum(axis=0) + apex) / 5.0
        for i in range(4):
            n = np.cross(corners[(i + 1) % 4] - corners[i], apex - corners[i])
            planes.append((n, float(n @ corners[i])))
    scale = 1.0 + float(np.abs(tris).max(initial=0.0))
    normals = np.empty((len(planes), 3))
    limits = np.empty(len(planes))
    for k, (n, d) in enumerate(planes):
        if n @ inside < d:  # orient every plane with the hull on its positive side
            n, d = -n, -d
        normals[k] = n
        limits[k] = d - 1e-9 * float(np.linalg.norm(n)) * scale
    # every plane at once, a block of triangles at a time (the first one not separated ends it)
    for start in range(0, len(tris), 1 << 16):
        block = tris[start : start + (1 << 16)]
        side = (normals @ block.reshape(-1, 3).T).reshape(len(planes), len(block), 3)
        farthest = np.maximum(np.maximum(side[:, :, 0], side[:, :, 1]), side[:, :, 2])  # per plane
        if not np.logical_or.reduce(farthest < limits[:, None], axis=0).all():
            return False
    return True


def _default_camera(points: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A perspective view that sees every receiver (for z-fail, whose count needs no particular eye)."""
    from blinn_phong.model.transforms import look_at, perspective_matrix

    pts = np.concatenate([points, tris.reshape(-1, 3)]) if len(tris) else points
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    direction = np.array([0.2672612419124244, 0.5345224838248488, 0.8017837257372732])  # (1, 2, 3)/√14
    eye = centre + direction * 4 * radius
    up = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    view = look_at(eye, centre, up)
    proj = perspective_matrix(2 * math.degrees(math.asin(0.5)) + 1, 1.0, radius, 10 * radius)
    return view, proj


def shadow_volume_visibility(
    light: DirectionalLight | PointLight | SpotLight,
    world_triangles: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    *,
    camera: Camera | None = None,
    stencil: str = "auto",
    offset: float = 1e-4,
    engine: str = "auto",
    binning: tuple | None = None,
) -> np.ndarray:
    """Hard-shadow visibility of receivers for one light by shadow volumes (1 = lit, 0 = shadowed).

    Same meaning and shape as :func:`blinn_phong.shadows.methods.light_visibility`.

    Args:
        light: the light (a spot light shadows as a point light at its position).
        world_triangles: (n, 3, 3) every caster (and receiver) triangle, world space.
        points: (m, 3) world-space receiver points (the visible samples).
        normals: (m, 3) their normals (need not be unit); each point moves ``offset`` along its
            normal towards the light's side before it is counted.
        camera: the camera whose samples the points are; None — a view that sees every point
            (fine for z-fail; z-pass is only valid for a camera outside every volume).
        stencil: ``"auto"`` (z-pass where :func:`choose_stencil` proves it exact, else
            z-fail), ``"zfail"`` (robust) or ``"zpass"`` (valid only while the camera is
            outside every volume and the near plane cuts none).
        offset: world units, ≥ 0.
        engine: ``"numba"``, ``"numpy"`` or ``"auto"``.
        binning: the compiled engine's tiles of the receivers, ``(grid, order, cell_start)``
            (:func:`pixel_binning` for a frame's pixels), or None: binned from their projections.
            Any binning counts the same (each tile's bounds and depths are measured from the
            projected receivers, which may lie outside their tile); a tight one is faster.

    Returns:
        (m,) float64 in {0, 1}.
    """
    p = _points("points", points, check_finite=False)  # checked while they are projected
    n = _points("normals", normals, check_finite=False)
    if n.shape != p.shape:
        raise ValueError(f"normals: expected the shape of points {p.shape}, got {n.shape}")
    if isinstance(offset, bool) or not (
        isinstance(offset, int | float | np.integer | np.floating) and math.isfinite(offset) and offset >= 0
    ):
        raise ValueError(f"offset: expected a finite number >= 0, got {offset!r}")
    if camera is not None and not isinstance(camera, Camera):
        raise TypeError(f"camera: expected a blinn_phong Camera or None, got {type(camera).__name__}")
    tris = _triangles("world_triangles", world_triangles)
    light_vec, directional = _light(light)
    if stencil not in (*STENCIL_METHODS, "auto"):
        raise choice_error("stencil", stencil, STENCIL_METHODS, also="'auto' or ")
    use_compiled(engine)  # checked here too: an empty scene must not accept a bad name
    if len(p) == 0 or len(tris) == 0:
        _points("points", p)
        _points("normals", n)
        return np.ones(len(p))
    numba_path = use_compiled(engine)
    q = None
    if camera is None:
        # the default camera is built from the points: refuse non-finite ones by their own name
        _points("points", p)
        _points("normals", n)
        q = _offset_numpy(p, n, light_vec, directional, float(offset))
        view, proj = _default_camera(q, tris)
    else:
        view, proj = camera.view, camera.projection
    orthographic = np.allclose(proj[3], [0.0, 0.0, 0.0, 1.0])
    extent = None
    if orthographic:  # w would be 0 at infinity: extrude past every receiver and caster instead
        q = _offset_numpy(p, n, light_vec, directional, float(offset)) if q is None else q
        pts = np.concatenate([q, tris.reshape(-1, 3)])
        span = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        reach = 0.0 if directional else float(np.linalg.norm(pts - light_vec, axis=1).max())
        extent = 4.0 * (span + reach) + 1.0
    vp = np.asarray(proj, dtype=np.float64) @ np.asarray(view, dtype=np.float64)
    # offset and projection in one compiled pass (the numpy engine: the same expressions)
    rec = _projected(
        p, n, light_vec, directional, float(offset), True, vp, numba_path, reuse=True, binning=binning
    )
    topo, key = _topology_with_key(tris)
    if stencil == "auto":
        stencil = _choose(light, tris, key, view, proj, rec.bounds)[0]
    # z-pass draws the light caps (receivers hidden behind a caster's lit faces need them) and,
    # when the volumes end at a finite distance (orthographic cameras), the dark caps too
    caps: bool | str = True if stencil == "zfail" or extent is not None else "light"
    light_key = (type(light).__name__, light_vec.tobytes(), caps, extent)
    volume = _cached(
        ("volume", key, light_key), lambda: shadow_volume_triangles(topo, light, caps=caps, extent=extent)
    )
    return _count(volume, vp, rec, stencil == "zfail", visibility=True)


#: Per-frame reuse: volumes and near-plane proofs by (topology digest, light, ...), a few entries.
_DERIVED_CACHE: dict[tuple, object] = {}


def _cached(key: tuple, make: object) -> object:
    if key in _DERIVED_CACHE:
        return _DERIVED_CACHE[key]
    value = make()  # type: ignore[operator]
    if len(_DERIVED_CACHE) >= 6:  # a frame of two lights needs four entries
        _DERIVED_CACHE.pop(next(iter(_DERIVED_CACHE)))
    _DERIVED_CACHE[key] = value
    return value


def _choose(
    light: DirectionalLight | PointLight | SpotLight,
    tris: np.ndarray,
    key: bytes,
    view: np.ndarray,
    projection: np.ndarray,
    bounds: tuple[float, ...],
) -> tuple[str, str]:
    """:func:`choose_stencil` for receivers whose normalised-device (xmin, xmax, ymin, ymax) are
    ``bounds`` (empty: no receivers)."""
    if bounds:
        reach = max(abs(b) for b in bounds)
        if not reach <= 1.0:
            return "zfail", f"a receiver projects outside the near rectangle (|ndc| up to {reach:.3g})"
    light_vec, _ = _light(light)
    safe = _cached(
        ("zpass_is_safe", key, type(light).__name__, light_vec.tobytes(), np.asarray(view, float).tobytes(),
         np.asarray(projection, float).tobytes()),
        lambda: zpass_is_safe(light, tris, view, projection),
    )  # fmt: skip
    if not safe:
        return (
            "zfail",
            "a caster meets the hull of the near rectangle and the light: the near plane may cut a volume",
        )
    return (
        "zpass",
        "no caster meets the hull of the near rectangle and the light: no volume reaches the near plane",
    )


def choose_stencil(
    light: DirectionalLight | PointLight | SpotLight,
    world_triangles: np.ndarray,
    view: np.ndarray,
    projection: np.ndarray,
    points: np.ndarray,
) -> tuple[str, str]:
    """The counting method ``stencil="auto"`` uses, and why: z-pass where it is provably exact.

    z-pass (with the light caps drawn) is short by exactly ``w(q_p)``, the number of volumes
    containing the point ``q_p`` where the camera ray of receiver p crosses the near plane
    (module docstring). It is therefore exact when (a) every receiver projects inside the
    near rectangle (``|x_ndc|, |y_ndc| ≤ 1``), so every ``q_p`` lies on that rectangle, and
    (b) :func:`zpass_is_safe` proves no caster meets the convex hull of the rectangle and the
    light, so no point of the rectangle lies in a volume. Elsewhere z-fail is used; it is exact
    for any camera.

    Args:
        light: the light.
        world_triangles: (n, 3, 3) the casters, world space.
        view: 4×4 world → eye matrix.
        projection: 4×4 eye → clip matrix (OpenGL conventions).
        points: (m, 3) world-space receivers (as they will be counted).

    Returns:
        ``("zpass" | "zfail", reason)``.
    """
    p = _points("points", points)
    tris = _triangles("world_triangles", world_triangles)
    vp = np.asarray(projection, dtype=np.float64) @ np.asarray(view, dtype=np.float64)
    px, py, _, pw = _project_numpy(p, vp)
    if not np.all(pw > 0):
        return "zfail", "a receiver lies behind the camera"
    bounds = (float(px.min()), float(px.max()), float(py.min()), float(py.max())) if len(px) else ()
    return _choose(light, tris, _topology_with_key(tris)[1], view, projection, bounds)


def _at_frame(frame: ShadowFrame, light: object, params: dict) -> np.ndarray:
    extra: dict[str, object] = {"camera": frame.scene.camera}
    if frame.binning is not None and "engine" not in params:
        extra["binning"] = frame.binning
    return shadow_volume_visibility(light, frame.tris, frame.world, frame.normal, **params, **extra)  # type: ignore[arg-type]


METHOD = ShadowMethod(
    name="shadow_volume",
    title="shadow volumes",
    summary="the casters' silhouettes extruded from the light, counted per point (Crow 1977): exact",
    exact=True,
    coloured=False,
    uses_rays=False,
    without_embree=None,
    cost_model="shadow_volume",
    parameters=("camera", "stencil", "offset", "engine", "binning"),
    visibility=shadow_volume_visibility,
    frame_visibility=_at_frame,
)
