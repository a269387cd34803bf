"""Shadow volumes' geometry: welding, edge pairing, closed and open components, silhouettes and
the volumes themselves (:mod:`blinn_phong.shadows.volume` describes the method).

A world-space triangle soup is welded (bit-identical vertices merged), its directed edges paired
with their twins, and its edge-connected components classified as closed 2-manifolds (silhouette
extrusion, turned outward) or open and non-manifold (every triangle extruded on its own):
:func:`analyse_topology`. :func:`shadow_volume_triangles` builds one light's volumes from that
topology as homogeneous triangles (extruded to infinity, or to a finite distance). Topologies are
cached by a content digest of the triangles. The input checks shared by the shadow-volume modules
live here too.
"""

from __future__ import annotations

import functools
import hashlib
import weakref
from dataclasses import dataclass

import numpy as np

from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight

__all__ = ["Topology", "analyse_topology", "shadow_volume_triangles", "silhouette_edges"]


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


#: Casters of fewer triangles are welded, paired and split into components by the numpy
#: reference (a few milliseconds, once per caster geometry; the same topology, tested), so that
#: a scene of small meshes compiles none of those kernels (about 0.8 s of compilation in the
#: first process on a machine, ``docs/compile.md``); larger casters use the compiled kernels.
_NUMPY_BELOW = 5_000


def _compiled(n_triangles: int) -> bool:
    """Whether the topology of ``n_triangles`` casters is built by the compiled kernels."""
    from blinn_phong._numba import numba_available

    return n_triangles >= _NUMPY_BELOW and numba_available()


def _digest(tris: np.ndarray) -> bytes:
    """A 128-bit content digest of a float64 array (the cache key of its topology): BLAKE2b, or
    with numba four interleaved splitmix64 lanes per 64-bit half, seeded differently (a cache
    key against accidental collisions, not an adversary; it is several times faster, and taken
    at every call on an array that may change)."""
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

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def pair_by_vertex(
        edges, a, b, start, end, index, own, twin_count, twin_first
    ):  # pragma: no cover - compiled
        """``pair``'s results for the directed edges ``a[e] → b[e]`` of ``edges`` (a share of
        them: each writes its own entries), from the edges grouped by start vertex (a stable
        sort, so a group lists its edges in input order: vertex ``v``'s ends are
        ``end[start[v]:start[v + 1]]``, their edges ``index[...]``): an edge's own count is how
        often its end appears in its start's group, its twin's the same with the ends swapped,
        the twin's first index the first such edge."""
        for i in range(edges.shape[0]):
            e = edges[i]
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
        return 0

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
        from compositing._threads import in_shares

        m = len(a)
        index = np.argsort(a, kind="stable")  # the edges grouped by start vertex, in input order
        start = np.zeros(nv + 1, np.int64)
        np.cumsum(np.bincount(a, minlength=nv), out=start[1:])
        own, twin_count, twin_first = np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m, np.int64)
        in_shares(_pair_kernel(), m, a, b, start, b[index], index, own, twin_count, twin_first)  # type: ignore[arg-type]
        return own, twin_count, twin_first
    return _hash_kernels()[1](a * nv + b, b * nv + a)


def _components(n: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Connected components of n nodes joined by edges (rows[i], cols[i]): each node's label is
    the smallest node index of its component (the same on both engines)."""
    if _compiled(n):
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
    if _compiled(len(flat) // 3):
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
    if _compiled(n):
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
