"""Ray casting with Intel Embree (through ``embreex``): hard and soft shadows.

A :class:`RayScene` holds a bounding-volume hierarchy that Embree builds over world-space
triangles. Shadow rays are occlusion queries (``rtcOccluded``: "is there any hit between
``t_near`` and ``t_far``?", Embree API manual, "Ray Queries"); nearest-hit queries
(``rtcIntersect``) serve refraction (:mod:`blinn_phong.effects.refraction`).

* Hard shadows: one ray per point towards the light; the reference answer for shadow maps.
* Soft shadows from a rectangular area light: ``n × n`` stratified (jittered) samples over
  the rectangle, visibility = fraction of unoccluded rays (Cook, Porter & Carpenter,
  "Distributed Ray Tracing", SIGGRAPH '84; stratification: Mitchell 1996). Points that see
  none of the light are in the umbra, points that see part of it in the penumbra.

Self-intersection is avoided by moving each ray origin along the surface normal towards the
light side, and by ending point-light rays as far short of the light. Embree works in float32,
whose spacing grows with the magnitude of the coordinates, so two things keep a scene far
from the origin behaving as it does at the origin:

* the BVH is built around the centre of the triangles' bounding box (subtracted in float64
  before the conversion to float32, and subtracted from every ray origin alike), so a
  compact scene at a real-world coordinate keeps the float32 precision of one at the origin;
* the offset actually used is ``max(offset, OFFSET_ULPS · 2⁻²³ · ‖p − centre‖∞)``: at
  least :data:`OFFSET_ULPS` float32 spacings of the recentred point, the size of the
  rounding error of a float32 ray–triangle intersection at that magnitude (Wächter &
  Binder, "A Fast and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems,
  2019, ch. 6, offset in units of the floating-point spacing of the hit point).

Ray set-up (origins, unit directions, ``t_max`` in float32) for a whole batch is one
compiled pass (numba) when numba imports, numpy otherwise (the same formulas), followed by
one Embree call per light over every point.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import hashlib
import os
from collections import OrderedDict
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from embreex import mesh_construction, rtcore_scene

from blinn_phong._numba import use_compiled

__all__ = [
    "OFFSET_ULPS",
    "Hits",
    "RayScene",
    "area_light_visibility",
    "cached_ray_scene",
    "directional_light_visibility",
    "point_light_visibility",
    "transmitted_light",
    "world_triangles",
]

#: Embree reports "no hit" with a very large t; anything beyond this counts as a miss.
_MISS_T = 1e30
#: Smallest ray-origin offset in float32 spacings of the (recentred) point's largest coordinate.
OFFSET_ULPS = 64.0
#: Default smallest ray-origin offset of hard shadow rays (world units).
HARD_SHADOW_OFFSET = 1e-4
_EPS32 = float(np.finfo(np.float32).eps)  # 2**-23


def offset_scale() -> float:
    """The origin offset's growth with ``‖p − centre‖∞``: :data:`OFFSET_ULPS` float32 spacings
    (read at each call, so the constant can be changed)."""
    return OFFSET_ULPS * _EPS32


def _points(name: str, value: np.ndarray) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiu":
        raise TypeError(f"{name} must be a real numeric array, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got NaN or Inf")
    return arr.astype(np.float64, copy=False)


def _vector(name: str, value: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return v


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


@dataclass(frozen=True)
class Hits:
    """Nearest hits of a batch of rays.

    ``t``: (n,) distance along the unit direction, ``inf`` where the ray missed.
    ``triangle``: (n,) index into the scene's triangles, −1 on a miss.
    ``normal``: (n, 3) unit geometric normal of the hit triangle (winding order
    ``(v1 − v0) × (v2 − v0)``), zero on a miss.
    """

    t: np.ndarray
    triangle: np.ndarray
    normal: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        """(n,) bool, True where the ray hit a triangle."""
        return self.triangle >= 0


class RayScene:
    """An Embree BVH over world-space triangles.

    Args:
        triangles: (n, 3, 3) world-space triangle corners, any unit; Embree works in float32.
    """

    def __init__(self, triangles: np.ndarray) -> None:
        tris = np.asarray(triangles)
        if tris.dtype.kind not in "fiu":
            raise TypeError(f"triangles must be a real numeric array, got dtype {tris.dtype}")
        if tris.ndim != 3 or tris.shape[1:] != (3, 3) or tris.shape[0] == 0:
            raise ValueError(f"triangles must have shape (n >= 1, 3, 3), got {tris.shape}")
        if not np.all(np.isfinite(tris)):
            raise ValueError("triangles must be finite, got NaN or Inf")
        self.triangles = np.asarray(tris, dtype=np.float64)
        flat = self.triangles.reshape(-1, 3)
        #: world-space point that Embree's float32 coordinates are relative to
        self.centre = (flat.min(axis=0) + flat.max(axis=0)) / 2
        self._scene = rtcore_scene.EmbreeScene()
        self._mesh = mesh_construction.TriangleMesh(
            self._scene, (self.triangles - self.centre).astype(np.float32)
        )
        self._normals: np.ndarray | None = None

    @property
    def normals(self) -> np.ndarray:
        """(n, 3) unit geometric normals ``(v1 − v0) × (v2 − v0)`` (computed on first use)."""
        if self._normals is None:
            t = self.triangles
            self._normals = _normalize(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
        return self._normals

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> Hits:
        """Nearest hit of each ray (``rtcIntersect``).

        Args:
            origins: (n, 3) ray origins, world space.
            directions: (n, 3) ray directions (normalised here).

        Returns:
            :class:`Hits` with ``t`` in world units along the unit direction.
        """
        o = _points("origins", origins)
        d = _normalize(_points("directions", directions))
        if o.shape != d.shape:
            raise ValueError(f"origins and directions must match, got {o.shape} and {d.shape}")
        if len(o) == 0:
            return Hits(np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
        out = self._scene.run((o - self.centre).astype(np.float32), d.astype(np.float32), output=1)
        tri = out["primID"].astype(np.int64)
        t = np.where(tri >= 0, out["tfar"].astype(np.float64), np.inf)
        t = np.where(t > _MISS_T, np.inf, t)
        normal = np.where((tri >= 0)[:, None], self.normals[np.maximum(tri, 0)], 0.0)
        return Hits(t, tri, normal)

    def occluded(self, origins: np.ndarray, directions: np.ndarray, t_max: np.ndarray | float) -> np.ndarray:
        """True where a ray hits any triangle with ``0 < t < t_max`` (``rtcOccluded``).

        Args:
            origins: (n, 3) ray origins, world space.
            directions: (n, 3) ray directions (normalised here, so ``t`` is a world distance).
            t_max: scalar or (n,) largest distance that counts (``inf`` for directional lights).

        Returns:
            (n,) bool.
        """
        o = _points("origins", origins)
        d = _normalize(_points("directions", directions))
        if o.shape != d.shape:
            raise ValueError(f"origins and directions must match, got {o.shape} and {d.shape}")
        if len(o) == 0:
            return np.zeros(0, dtype=bool)
        tm = np.broadcast_to(np.asarray(t_max, dtype=np.float64), (len(o),))
        tm = np.minimum(tm, 1e37).astype(np.float32)
        return self._occluded32(
            (o - self.centre).astype(np.float32), d.astype(np.float32), np.ascontiguousarray(tm)
        )

    def _occluded32(self, origins: np.ndarray, directions: np.ndarray, t_max: np.ndarray) -> np.ndarray:
        """``rtcOccluded`` over float32 recentred origins, unit directions and t_max (modified).

        A large batch is cut into contiguous chunks queried on :func:`_pool`'s threads (the
        binding releases the GIL while Embree traverses); each ray's answer does not depend on
        the chunk it is in.
        """
        n = len(origins)
        if n == 0:
            return np.zeros(0, dtype=bool)
        chunks = min(_threads(), n // _MIN_CHUNK)
        if chunks < 2:
            return np.asarray(self._scene.run(origins, directions, dists=t_max, query="OCCLUDED")) >= 0
        out = np.empty(n, dtype=bool)
        bounds = np.linspace(0, n, 2 * chunks + 1).astype(np.int64)

        def run(k: int) -> None:
            a, b = int(bounds[k]), int(bounds[k + 1])
            res = self._scene.run(origins[a:b], directions[a:b], dists=t_max[a:b], query="OCCLUDED")
            out[a:b] = np.asarray(res) >= 0

        list(_pool().map(run, range(len(bounds) - 1)))
        return out


#: Fewest rays per chunk of a threaded occlusion batch (smaller batches run on the calling thread).
_MIN_CHUNK = 1 << 15


def _threads() -> int:
    """Threads for Embree batches: ``NUMBA_NUM_THREADS`` when set (the renderer's budget), else the CPUs."""
    return max(1, int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1)))


@functools.lru_cache(maxsize=1)
def _pool() -> ThreadPoolExecutor:
    """The process's thread pool for Embree batches (created on first use)."""
    return ThreadPoolExecutor(max_workers=_threads(), thread_name_prefix="embree")


#: A few recently built scenes, keyed by the triangles' bytes (a BVH per frame, not per light).
_SCENE_CACHE: OrderedDict[tuple[tuple[int, ...], str], RayScene] = OrderedDict()
_SCENE_CACHE_SIZE = 2


#: Cache keys of arrays their owner promised not to modify inside a :func:`frame_triangles` block.
_FRAME_KEYS: contextvars.ContextVar[dict[int, tuple[tuple[int, ...], str]] | None] = contextvars.ContextVar(
    "frame_keys", default=None
)


@contextlib.contextmanager
def frame_triangles(triangles: np.ndarray, key: object = None) -> Iterator[None]:
    """Inside the block, :func:`cached_ray_scene` of this very array hashes it once, not per call.

    For a caller that made ``triangles`` itself and does not modify it inside the block (the
    frame pipeline's caster triangles, queried once per light): the SHA-1 of 260 k triangles
    costs about 5 ms per call. ``key``: the array's :func:`_key`, when the caller kept it (a
    read-only array it hashed before).
    """
    token = _FRAME_KEYS.set({**(_FRAME_KEYS.get() or {}), id(triangles): key or _key(triangles)})
    try:
        yield
    finally:
        _FRAME_KEYS.reset(token)


def _key(triangles: np.ndarray) -> tuple[tuple[int, ...], str]:
    tris = np.ascontiguousarray(triangles, dtype=np.float64)
    return tris.shape, hashlib.sha1(memoryview(tris.reshape(-1))).hexdigest()


def cached_ray_scene(triangles: np.ndarray) -> RayScene:
    """A :class:`RayScene` over ``triangles``, reused while the same triangles come back.

    The key is the SHA-1 of the float64 triangle data, so an array changed in place gets a
    new BVH (inside :func:`frame_triangles` the key of that block's array is computed once).
    Keeps the last two scenes (e.g. the shadows and the refraction of one frame).

    Args:
        triangles: (n, 3, 3) world-space triangles.

    Returns:
        The cached or newly built scene.
    """
    tris = np.ascontiguousarray(triangles, dtype=np.float64)
    key = (_FRAME_KEYS.get() or {}).get(id(triangles)) or _key(tris)
    scene = _SCENE_CACHE.get(key)
    if scene is None:
        scene = RayScene(tris)
        _SCENE_CACHE[key] = scene
        while len(_SCENE_CACHE) > _SCENE_CACHE_SIZE:
            _SCENE_CACHE.popitem(last=False)
    else:
        _SCENE_CACHE.move_to_end(key)
    return scene


def world_triangles(scene: object) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle of a :class:`blinn_phong.model.scene.Scene` in world space.

    Args:
        scene: the scene (meshes with ``positions``, ``triangles`` and a model ``transform``).

    Returns:
        ``(triangles (T, 3, 3), mesh_index (T,))`` in scene order, the order of
        :func:`blinn_phong.frame.render.prepare_scene`.
    """
    meshes = getattr(scene, "meshes", None)
    if meshes is None:
        raise TypeError(f"scene must be a blinn_phong.Scene, got {type(scene).__name__}")
    tris, owner = [], []
    for i, mesh in enumerate(meshes):
        world = (np.c_[mesh.positions, np.ones(len(mesh.positions))] @ mesh.transform.T)[:, :3]
        tris.append(world[mesh.triangles])
        owner.append(np.full(len(mesh.triangles), i, dtype=np.int64))
    if not tris:
        return np.zeros((0, 3, 3)), np.zeros(0, dtype=np.int64)
    return np.concatenate(tris), np.concatenate(owner)


def _effective_offset(points: np.ndarray, centre: np.ndarray, offset: float) -> np.ndarray:
    """(n,) ``max(offset, OFFSET_ULPS · 2⁻²³ · ‖p − centre‖∞)``: see the module docstring."""
    return np.maximum(offset, offset_scale() * np.abs(points - centre).max(axis=1, initial=0.0))


def _offset_origins(
    points: np.ndarray, normals: np.ndarray, to_light: np.ndarray, offset: np.ndarray | float
) -> np.ndarray:
    n = _normalize(normals)
    side = np.sign(np.einsum("ij,ij->i", n, to_light))
    side = np.where(side == 0, 1.0, side)
    return points + n * (side * offset)[:, None]


def _hard_rays_numpy(
    points: np.ndarray,
    normals: np.ndarray,
    light: np.ndarray,
    positional: bool,
    centre: np.ndarray,
    offset: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Float32 recentred origins, unit directions and t_max of one shadow ray per point (reference)."""
    eff = _effective_offset(points, centre, offset)
    if positional:
        o = _offset_origins(points, normals, light - points, eff)
        to_light = light - o
        dist = np.linalg.norm(to_light, axis=1)
        d = to_light / np.where(dist > 0, dist, 1.0)[:, None]
        t_max = np.maximum(dist - eff, 0.0)
    else:
        d = np.broadcast_to(light, points.shape)
        o = _offset_origins(points, normals, d, eff)
        t_max = np.full(len(points), 1e37)
    return (
        (o - centre).astype(np.float32),
        np.ascontiguousarray(d, dtype=np.float32),
        t_max.astype(np.float32),
    )


@functools.lru_cache(maxsize=1)
def _hard_rays_kernel() -> object | None:
    """The compiled ray set-up (:func:`.ray_setup_kernels.hard_shadow_rays`); None without numba."""
    try:
        from blinn_phong.shadows.ray_setup_kernels import hard_shadow_rays
    except Exception:
        return None
    return hard_shadow_rays


def _hard_shadow(
    scene: RayScene,
    points: object,
    normals: object,
    light: np.ndarray,
    positional: bool,
    offset: float,
    engine: str,
) -> np.ndarray:
    """Visibility (1 lit, 0 shadowed) of points for one hard light: one batched occlusion query."""
    kernel = _hard_rays_kernel() if use_compiled(engine) else None
    if engine == "numba" and kernel is None:
        raise ValueError(
            "engine: 'numba' requested but blinn_phong.shadows.ray_setup_kernels cannot be imported"
        )
    if offset < 0 or not np.isfinite(offset):
        raise ValueError(f"offset must be a finite number >= 0, got {offset!r}")
    if kernel is None:
        p = _points("points", points)
        n = _points("normals", normals)
        if n.shape != p.shape:
            raise ValueError(f"normals must have the shape of points {p.shape}, got {n.shape}")
        o32, d32, t32 = _hard_rays_numpy(p, n, light, positional, scene.centre, offset)
    else:
        p = np.asarray(points)
        n = np.asarray(normals)
        for name, arr in (("points", p), ("normals", n)):
            if arr.dtype.kind not in "fiu":
                raise TypeError(f"{name} must be a real numeric array, got dtype {arr.dtype}")
            if arr.ndim != 2 or arr.shape[1] != 3:
                raise ValueError(f"{name} must have shape (n, 3), got {arr.shape}")
        if n.shape != p.shape:
            raise ValueError(f"normals must have the shape of points {p.shape}, got {n.shape}")
        o32 = np.empty((len(p), 3), np.float32)
        d32 = np.empty((len(p), 3), np.float32)
        t32 = np.empty(len(p), np.float32)
        bad = kernel(
            np.ascontiguousarray(p, dtype=np.float64),
            np.ascontiguousarray(n, dtype=np.float64),
            light,
            positional,
            scene.centre,
            float(offset),
            offset_scale(),
            o32,
            d32,
            t32,
        )
        if bad:
            raise ValueError(f"points and normals must be finite, got NaN or Inf in {bad} rows")
    return 1.0 - scene._occluded32(o32, d32, t32).astype(np.float64)


def directional_light_visibility(
    scene: RayScene,
    points: np.ndarray,
    normals: np.ndarray,
    direction_to_light: np.ndarray | tuple[float, float, float],
    *,
    offset: float = HARD_SHADOW_OFFSET,
    engine: str = "auto",
) -> np.ndarray:
    """Ray-traced hard shadows from a directional light: 1 = lit, 0 = shadowed.

    One occlusion ray per point, all in one Embree batch.

    Args:
        scene: the occluders.
        points: (n, 3) world-space surface points.
        normals: (n, 3) their normals (for the origin offset; need not be unit).
        direction_to_light: world-space vector pointing towards the light (normalised here).
        offset: smallest origin offset along the normal, world units (raised to
            :data:`OFFSET_ULPS` float32 spacings of the point far from the scene's centre).
        engine: ray set-up by ``numpy`` (the reference), ``numba`` or ``auto``.

    Returns:
        (n,) float64 visibility in {0, 1}.
    """
    lv = _normalize(_vector("direction_to_light", direction_to_light))
    return _hard_shadow(scene, points, normals, lv, False, offset, engine)


def point_light_visibility(
    scene: RayScene,
    points: np.ndarray,
    normals: np.ndarray,
    light_position: np.ndarray | tuple[float, float, float],
    *,
    offset: float = HARD_SHADOW_OFFSET,
    engine: str = "auto",
) -> np.ndarray:
    """Ray-traced hard shadows from a point (or spot) light: 1 = lit, 0 = shadowed.

    One occlusion ray per point, all in one Embree batch.

    Args:
        scene: the occluders.
        points: (n, 3) world-space surface points.
        normals: (n, 3) their normals (for the origin offset).
        light_position: world-space light position.
        offset: smallest origin offset along the normal and gap left before the light, world
            units (raised as for :func:`directional_light_visibility`).
        engine: ray set-up by ``numpy`` (the reference), ``numba`` or ``auto``.

    Returns:
        (n,) float64 visibility in {0, 1}.
    """
    lp = _vector("light_position", light_position)
    return _hard_shadow(scene, points, normals, lp, True, offset, engine)


def transmitted_light(
    scene: RayScene,
    points: np.ndarray,
    normals: np.ndarray,
    light: np.ndarray | tuple[float, float, float],
    transmittance: np.ndarray,
    *,
    positional: bool = False,
    offset: float = 1e-4,
    max_layers: int = 16,
) -> np.ndarray:
    """Coloured hard shadows: the fraction of each RGB channel of a light that reaches each point.

    Each triangle is a thin filter with the per-channel transmittance ``transmittance[i]``
    (``1 − α`` for a partially covering surface, the absorption colour for a tinted one, 0 for
    an opaque one). Light crossing several filters keeps the product of their transmittances
    (Beer–Lambert for thin layers; the shadow counterpart of compositing a transparent
    surface ``over`` the light, Porter & Duff 1984). Computed by walking each shadow ray from
    hit to hit with ``rtcIntersect`` (each step restarts just past the surface found), all
    rays in one batch per step; a ray stops at the light, at the first opaque triangle, or
    after ``max_layers`` filters (then it counts as blocked: no light is invented).

    Args:
        scene: the casters; ``transmittance`` is indexed like ``scene.triangles``.
        points: (n, 3) world-space surface points.
        normals: (n, 3) their normals (for the origin offset).
        light: direction towards a directional light, or a point light's position (``positional``).
        transmittance: (T, 3) per-triangle RGB transmittance in [0, 1].
        positional: ``light`` is a position (point or spot light).
        offset: smallest origin offset (see :func:`directional_light_visibility`).
        max_layers: most filters a ray crosses.

    Returns:
        (n, 3) float64 transmitted fraction in [0, 1]; 0 in full shadow, 1 fully lit.
    """
    p = _points("points", points)
    n = _points("normals", normals)
    if n.shape != p.shape:
        raise ValueError(f"normals must have the shape of points {p.shape}, got {n.shape}")
    tr = np.asarray(transmittance, dtype=np.float64)
    if tr.shape != (len(scene.triangles), 3):
        raise ValueError(
            f"transmittance must have shape (n_triangles, 3) = ({len(scene.triangles)}, 3), got {tr.shape}"
        )
    if not np.all((tr >= 0) & (tr <= 1)):
        raise ValueError("transmittance must lie in [0, 1] (and be finite)")
    if not isinstance(max_layers, int | np.integer) or max_layers < 1:
        raise ValueError(f"max_layers must be an integer >= 1, got {max_layers!r}")
    lv = _vector("light", light)
    eff = _effective_offset(p, scene.centre, offset)
    if positional:
        o = _offset_origins(p, n, lv - p, eff)
        to_light = lv - o
        dist = np.linalg.norm(to_light, axis=1)
        d = to_light / np.where(dist > 0, dist, 1.0)[:, None]
        t_max = np.maximum(dist - eff, 0.0)
    else:
        d = np.broadcast_to(_normalize(lv), p.shape).copy()
        o = _offset_origins(p, n, d, eff)
        t_max = np.full(len(p), np.inf)
    out = np.ones((len(p), 3))
    active = np.arange(len(p))
    opaque = np.all(tr == 0, axis=1)
    for _ in range(int(max_layers)):
        if len(active) == 0:
            break
        tm = np.minimum(t_max[active], 1e37).astype(np.float32)
        res = scene._scene.run(
            (o[active] - scene.centre).astype(np.float32), d[active].astype(np.float32), dists=tm, output=1
        )
        tri = res["primID"].astype(np.int64)
        t = res["tfar"].astype(np.float64)
        hit = (tri >= 0) & (t < t_max[active])
        active, tri, t = active[hit], tri[hit], t[hit]
        out[active] *= tr[tri]
        keep = ~opaque[tri]
        active, t = active[keep], t[keep]
        step = t + eff[active]
        o[active] += d[active] * step[:, None]
        t_max[active] -= step
    if len(active):  # past max_layers filters: anything further on the way blocks
        tm = np.minimum(t_max[active], 1e37).astype(np.float32)
        more = scene._occluded32(
            (o[active] - scene.centre).astype(np.float32), d[active].astype(np.float32), tm
        )
        out[active[more]] = 0.0
    return out


def area_light_visibility(
    scene: RayScene,
    points: np.ndarray,
    normals: np.ndarray,
    corner: np.ndarray | tuple[float, float, float],
    edge_u: np.ndarray | tuple[float, float, float],
    edge_v: np.ndarray | tuple[float, float, float],
    *,
    samples_per_axis: int = 4,
    seed: int | None = 0,
    offset: float = 1e-4,
    engine: str = "auto",
) -> np.ndarray:
    """Fraction of a rectangular area light each point sees (soft shadows).

    The light is the parallelogram ``corner + s·edge_u + t·edge_v``, s, t ∈ [0, 1]. It is
    split into ``m × m`` strata (``m = samples_per_axis``) with one jittered sample in
    each (stratified sampling), and one occlusion ray is cast from each point to each
    sample. Visibility 0 is umbra, 1 fully lit, in between penumbra. For a straight
    occluder edge the exact visibility is linear across the penumbra and the estimate
    is within ``1/m`` of it.

    Args:
        scene: the occluders (the light itself must not be part of it).
        points: (n, 3) world-space surface points.
        normals: (n, 3) their normals (for the origin offset).
        corner: a corner of the light rectangle, world space.
        edge_u: first edge vector of the rectangle.
        edge_v: second edge vector of the rectangle.
        samples_per_axis: strata per edge (m ≥ 1), m² rays per point.
        seed: seed of the jitter (``None``: fresh randomness); the same seed gives the same image.
        offset: smallest origin offset along the normal and gap left before the light, world
            units (raised as for :func:`directional_light_visibility`).
        engine: per-sample ray set-up by ``numpy`` (the reference), ``numba`` (one compiled
            pass per sample, the same formulas) or ``auto``.

    Returns:
        (n,) float64 visibility in [0, 1], multiples of ``1/m²``.
    """
    compiled = use_compiled(engine)
    p = _points("points", points)
    n = _points("normals", normals)
    if n.shape != p.shape:
        raise ValueError(f"normals must have the shape of points {p.shape}, got {n.shape}")
    c0 = _vector("corner", corner)
    eu = _vector("edge_u", edge_u)
    ev = _vector("edge_v", edge_v)
    if not isinstance(samples_per_axis, int | np.integer) or samples_per_axis < 1:
        raise ValueError(f"samples_per_axis must be an integer >= 1, got {samples_per_axis!r}")
    m = int(samples_per_axis)
    rng = np.random.default_rng(seed)
    visible = np.zeros(len(p))
    centre = c0 + 0.5 * eu + 0.5 * ev
    eff = _effective_offset(p, scene.centre, offset)
    o = _offset_origins(p, n, centre - p, eff)
    kernel = _area_rays_kernel() if compiled else None
    if engine == "numba" and kernel is None:
        raise ValueError(
            "engine: 'numba' requested but blinn_phong.shadows.ray_setup_kernels cannot be imported"
        )
    o32 = (o - scene.centre).astype(np.float32)  # the same origins for every sample
    d32 = np.empty((len(p), 3), np.float32)
    t32 = np.empty(len(p), np.float32)
    for i in range(m):
        for j in range(m):
            s = (i + rng.random(len(p))) / m
            t = (j + rng.random(len(p))) / m
            if kernel is not None:  # one compiled pass, then one Embree batch per sample
                kernel(o, s, t, c0, eu, ev, eff, d32, t32)
                visible += ~scene._occluded32(o32, d32, t32)
                continue
            target = c0 + s[:, None] * eu + t[:, None] * ev
            d = target - o
            dist = np.linalg.norm(d, axis=1)
            visible += ~scene.occluded(o, d, np.maximum(dist - eff, 0.0))
    return visible / (m * m)


@functools.lru_cache(maxsize=1)
def _area_rays_kernel() -> object | None:
    """The compiled area-light ray set-up (``ray_setup_kernels.area_light_rays``); None without numba."""
    try:
        from blinn_phong.shadows.ray_setup_kernels import area_light_rays
    except Exception:
        return None
    return area_light_rays
