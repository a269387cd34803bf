"""Shadow maps for directional, spot and point lights; planar projected ("fake") shadows.

Shadow mapping (Williams, "Casting curved shadows on curved surfaces", SIGGRAPH '78):
render the scene's depth from the light with :func:`blinn_phong.geometry.raster.rasterize`, then a
surface point is lit when its own light-space depth is not behind the stored depth.

* Lights: a directional light uses an orthographic light camera fitted around the scene
  bounds; a spot light a perspective one with a field of view of twice its cut-off; a point
  light a cube of six 90° perspective faces, the face chosen by the major axis of the
  light-to-point vector (the cube-map face rule of OpenGL 4.6 §8.13 table 8.19).
* Bias, as ``glPolygonOffset(factor, units)`` applies it while the map is rendered (OpenGL
  2.1 §3.5.5): each caster fragment is pushed back by ``constant + slope·m`` window-depth
  units, ``m = max(|∂z/∂x|, |∂z/∂y|)`` the triangle's depth slope per texel. Too little
  bias leaves self-shadowing stripes ("acne"); too much detaches shadows from their
  casters ("peter-panning").
* Normal offset (Holbert, "Normal Offset Shadows", GDC 2011): the receiver is moved along
  its surface normal by ``normal_offset`` world units before it is projected.
* Percentage-closer filtering (Reeves, Salesin & Cook, SIGGRAPH '87): the depth comparison
  is made at several texels and the results (not the depths) are averaged. Kernels:
  ``nearest`` (1 tap), ``bilinear`` (the 2×2 taps around the point weighted bilinearly, as
  hardware PCF does), ``box3``/``box5``/``box7`` (k×k taps, equal weights). A tap h texels
  away in x and y meets the receiver's own depth up to ``2·h·m`` away, so wider kernels need
  ``slope_bias ≳ 1 + 2h`` (h = 1 for bilinear, (k − 1)/2 for box k) to stay free of acne.

Planar projected shadows (Blinn, "Me and my (fake) shadow", IEEE CG&A 8(1) 1988): the
matrix ``M = (π·l) I − l πᵀ`` flattens geometry onto the plane ``π = (a, b, c, d)`` from
the homogeneous light ``l`` (w = 0 directional, w = 1 positional). Cheap, exact on that
one plane, and only there: no shadows on other receivers, and casters on the far side of
the plane or behind the light still cast.

Engines: every shadow-map function takes ``engine``: ``numpy`` runs the code in this module
(the readable reference), ``numba`` the compiled twins of :mod:`blinn_phong.shadows.kernels`
(same formulas; depths within 1e-12, visibilities within 1e-9), ``auto`` (the default) the
compiled ones when numba imports. :func:`light_visibility` also accepts per-triangle RGB
transmittances, for coloured shadows of transparent casters (ray traced).

Image conventions: shadow maps are (height, width) arrays of window depth in [0, 1],
row 0 at the top (as :func:`~blinn_phong.geometry.raster.rasterize` returns them), 1 where no
caster was drawn.
"""

from __future__ import annotations

import contextlib
import contextvars
import weakref
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from blinn_phong._numba import ENGINES, numba_available, use_compiled
from blinn_phong.geometry.raster import rasterize
from blinn_phong.model.scene import (
    DirectionalLight,
    PointLight,
    SpotLight,
    look_at,
    orthographic_matrix,
    perspective_matrix,
)

__all__ = [
    "ENGINES",
    "PCF_KERNELS",
    "SHADOW_METHODS",
    "ShadowLookup",
    "ShadowMap",
    "caster_transmittance",
    "light_cameras",
    "light_shadow_maps",
    "light_visibility",
    "map_matrices",
    "mesh_shadow_transmittance",
    "planar_shadow_mask",
    "planar_shadow_matrix",
    "render_shadow_map",
    "shadow_lookup",
    "shadow_map_visibility",
    "shadow_transmittance",
    "shadow_visibility",
    "trusted_arrays",
]

#: The percentage-closer filtering kernels :func:`shadow_visibility` accepts.
PCF_KERNELS: tuple[str, ...] = ("nearest", "bilinear", "box3", "box5", "box7")
@dataclass(frozen=True, eq=False)
class ShadowMap:
    """Depth seen from a light.

    ``depth``: (height, width) window depth in [0, 1], row 0 at the top, biased as rendered.
    ``view``/``projection``: the light camera's 4×4 matrices (world → eye → clip).
    """

    depth: np.ndarray
    view: np.ndarray
    projection: np.ndarray

    @property
    def resolution(self) -> tuple[int, int]:
        """(height, width) in texels."""
        return self.depth.shape  # type: ignore[return-value]


#: ids of float64 arrays already checked by the light_visibility call running in this context
_CHECKED: contextvars.ContextVar[frozenset[int]] = contextvars.ContextVar("checked", default=frozenset())


@contextlib.contextmanager
def trusted_arrays(*arrays: np.ndarray) -> Iterator[None]:
    """Inside the block the shadow functions skip the shape and finiteness checks of these arrays.

    For a caller that made them itself (the frame pipeline's world points, face normals and
    caster triangles, finite float64 arrays of the right shapes): a 1.3 M-point frame then checks
    its points once, not once per light. Arrays not listed are checked as usual.
    """
    token = _CHECKED.set(_CHECKED.get() | frozenset(id(a) for a in arrays))
    try:
        yield
    finally:
        _CHECKED.reset(token)


def _triangles(name: str, value: np.ndarray) -> np.ndarray:
    tris = np.asarray(value)
    if id(tris) in _CHECKED.get():
        return tris
    if tris.dtype.kind not in "fiu" or tris.ndim != 3 or tris.shape[1:] != (3, 3):
        raise ValueError(f"{name} must be a real array of shape (n, 3, 3), got {tris.dtype} {tris.shape}")
    if not np.all(np.isfinite(tris)):
        raise ValueError(f"{name} must be finite, got NaN or Inf")
    return tris.astype(np.float64, copy=False)


def _points(name: str, value: np.ndarray) -> np.ndarray:
    arr = np.asarray(value)
    if id(arr) in _CHECKED.get():
        return arr
    if arr.dtype.kind not in "fiu" or arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must be a real array of shape (n, 3), got {arr.dtype} {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got NaN or Inf")
    return arr.astype(np.float64, copy=False)


def _lookup_normals(
    p: np.ndarray, normals: np.ndarray | None, normal_offset: float, kernel: str
) -> np.ndarray | None:
    """Check a shadow-map look-up's kernel and normals; the (n, 3) normals when ``normal_offset`` is used."""
    if kernel not in PCF_KERNELS:
        raise ValueError(f"kernel must be one of {PCF_KERNELS}, got {kernel!r}")
    if normal_offset == 0.0:
        return None
    if normals is None:
        raise ValueError("normals are required when normal_offset != 0")
    n = _points("normals", normals)
    if n.shape != p.shape:
        raise ValueError(f"normals must have the shape of points {p.shape}, got {n.shape}")
    return n


def _homogeneous(points: np.ndarray) -> np.ndarray:
    return np.concatenate([points, np.ones((len(points), 1))], axis=1)


def render_shadow_map(
    world_triangles: np.ndarray,
    view: np.ndarray,
    projection: np.ndarray,
    resolution: int,
    *,
    constant_bias: float = 0.0,
    slope_bias: float = 0.0,
    engine: str = "auto",
) -> ShadowMap:
    """Render a light-space depth map of world-space triangles (both faces, nearest depth).

    Args:
        world_triangles: (n, 3, 3) world-space caster triangles.
        view: 4×4 world → light-eye matrix.
        projection: 4×4 light-eye → clip matrix.
        resolution: map size in texels (square), ≥ 1.
        constant_bias: window-depth units added to every caster fragment (≥ 0).
        slope_bias: multiple of the triangle's depth slope per texel added (≥ 0).
        engine: ``numpy`` (the reference: :func:`~blinn_phong.geometry.raster.rasterize` and a
            scatter-min), ``numba`` (:func:`blinn_phong.shadows.kernels.depth_map_compiled`,
            same formulas, depths within 1e-12) or ``auto`` (numba when it imports).

    Returns:
        :class:`ShadowMap` with the biased nearest depth per texel (1 where empty).
    """
    tris = _triangles("world_triangles", world_triangles)
    if not isinstance(resolution, int | np.integer) or resolution < 1:
        raise ValueError(f"resolution must be an integer >= 1, got {resolution!r}")
    if constant_bias < 0 or slope_bias < 0:
        raise ValueError(f"biases must be >= 0, got constant_bias={constant_bias}, slope_bias={slope_bias}")
    res = int(resolution)
    vp = np.asarray(projection, dtype=np.float64) @ np.asarray(view, dtype=np.float64)
    if use_compiled(engine):
        from blinn_phong.shadows.map_render_kernels import depth_map_compiled

        depth_map = depth_map_compiled(tris, vp, res, float(constant_bias), float(slope_bias))
        return ShadowMap(depth_map, np.asarray(view, float), np.asarray(projection, float))
    clip = _homogeneous(tris.reshape(-1, 3)) @ vp.T
    index = np.arange(len(clip)).reshape(-1, 3)
    frags = rasterize(clip, index, res, res)
    depth = np.ones(res * res)
    if len(frags):
        # depth slope of each triangle in window coordinates (texel units), GL 2.1 §3.5.5
        cw = clip.reshape(-1, 3, 4)
        w = cw[:, :, 3]
        ok = np.all(w > 0, axis=1)
        ndc = cw[:, :, :3] / np.where(ok[:, None], w, 1.0)[:, :, None]
        xw = (ndc[:, :, 0] + 1) * 0.5 * res
        yw = (ndc[:, :, 1] + 1) * 0.5 * res
        zw = (ndc[:, :, 2] + 1) * 0.5
        e1x, e1y, e1z = xw[:, 1] - xw[:, 0], yw[:, 1] - yw[:, 0], zw[:, 1] - zw[:, 0]
        e2x, e2y, e2z = xw[:, 2] - xw[:, 0], yw[:, 2] - yw[:, 0], zw[:, 2] - zw[:, 0]
        det = e1x * e2y - e2x * e1y
        safe = np.where(det != 0, det, 1.0)
        dzdx = (e1z * e2y - e2z * e1y) / safe
        dzdy = (e1x * e2z - e2x * e1z) / safe
        slope = np.where(ok & (det != 0), np.maximum(np.abs(dzdx), np.abs(dzdy)), 0.0)
        biased = frags.depth + constant_bias + slope_bias * slope[frags.triangle]
        np.minimum.at(depth, frags.pixel, biased)
    return ShadowMap(depth.reshape(res, res), np.asarray(view, float), np.asarray(projection, float))


def _tap_offsets(kernel: str) -> np.ndarray:
    k = int(kernel[3:])
    r = np.arange(k) - (k - 1) / 2
    oy, ox = np.meshgrid(r, r, indexing="ij")
    return np.stack([ox.ravel(), oy.ravel()], axis=1)


def shadow_visibility(
    shadow_map: ShadowMap,
    points: np.ndarray,
    normals: np.ndarray | None = None,
    *,
    normal_offset: float = 0.0,
    kernel: str = "nearest",
    engine: str = "auto",
) -> np.ndarray:
    """Fraction of the depth comparisons that find each point lit (1 = lit, 0 = shadowed).

    Points outside the light's frustum are lit (the map says nothing about them).

    Args:
        shadow_map: from :func:`render_shadow_map`.
        points: (n, 3) world-space receiver points.
        normals: (n, 3) their normals (needed when ``normal_offset`` ≠ 0).
        normal_offset: world units each point moves along its unit normal (towards the
            side facing the light) before projection.
        kernel: one of :data:`PCF_KERNELS`.
        engine: ``numpy`` (this function's reference code), ``numba``
            (:func:`blinn_phong.shadows.kernels.lookup_compiled`) or ``auto``.

    Returns:
        (n,) float64 visibility in [0, 1].
    """
    p = _points("points", points)
    n = _lookup_normals(p, normals, normal_offset, kernel)
    if use_compiled(engine):
        from blinn_phong.shadows.map_lookup_kernels import lookup_compiled

        vp = shadow_map.projection @ shadow_map.view
        return lookup_compiled(
            shadow_map.depth[None],
            vp[None],
            shadow_map.view[None],
            p,
            n,
            light_position=None,
            normal_offset=float(normal_offset),
            kernel=kernel,
        )
    if n is not None:
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        # face the normal towards the light: the side whose light-eye z is larger (nearer the light)
        towards = (n @ shadow_map.view[:3, :3].T)[:, 2]
        n = np.where((towards < 0)[:, None], -n, n)
        p = p + normal_offset * n
    res_y, res_x = shadow_map.depth.shape
    clip = _homogeneous(p) @ (shadow_map.projection @ shadow_map.view).T
    w = clip[:, 3]
    front = w > 0
    ndc = clip[:, :3] / np.where(front, w, 1.0)[:, None]
    x = (ndc[:, 0] + 1) * 0.5 * res_x
    y = res_y - (ndc[:, 1] + 1) * 0.5 * res_y  # rows from the top
    z = (ndc[:, 2] + 1) * 0.5
    inside = front & (ndc[:, 0] >= -1) & (ndc[:, 0] <= 1) & (ndc[:, 1] >= -1) & (ndc[:, 1] <= 1) & (z <= 1)
    flat = shadow_map.depth.ravel()

    def lit_at(col: np.ndarray, row: np.ndarray) -> np.ndarray:
        c = np.clip(col, 0, res_x - 1).astype(np.int64)
        r = np.clip(row, 0, res_y - 1).astype(np.int64)
        return (z <= flat[r * res_x + c]).astype(np.float64)

    if kernel == "nearest":
        vis = lit_at(np.floor(x), np.floor(y))
    elif kernel == "bilinear":
        fx, fy = x - 0.5, y - 0.5
        x0, y0 = np.floor(fx), np.floor(fy)
        tx, ty = fx - x0, fy - y0
        top = lit_at(x0, y0) + tx * (lit_at(x0 + 1, y0) - lit_at(x0, y0))
        bottom = lit_at(x0, y0 + 1) + tx * (lit_at(x0 + 1, y0 + 1) - lit_at(x0, y0 + 1))
        vis = top + ty * (bottom - top)  # lerp form: exactly 1 when all taps are lit
    else:
        offsets = _tap_offsets(kernel)
        col, row = np.floor(x), np.floor(y)
        vis = np.mean([lit_at(col + ox, row + oy) for ox, oy in offsets], axis=0)
    return np.where(inside, vis, 1.0)


def _bounds(world_triangles: np.ndarray) -> tuple[np.ndarray, float]:
    if numba_available() and world_triangles.flags.c_contiguous and len(world_triangles):
        # the same minimum and maximum, in one pass
        from blinn_phong.shadows.map_render_kernels import corner_bounds

        lo, hi = corner_bounds(world_triangles)
    else:
        pts = world_triangles.reshape(-1, 3)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-9)
    return centre, radius


def _up_for(direction: np.ndarray) -> np.ndarray:
    return np.array([0.0, 1.0, 0.0]) if abs(direction[1]) < 0.9 else np.array([1.0, 0.0, 0.0])


#: Cube-map faces: (axis, sign) of the major axis, and the look-at up vector per face.
_CUBE_FACES = (
    (0, 1.0, (0.0, -1.0, 0.0)),
    (0, -1.0, (0.0, -1.0, 0.0)),
    (1, 1.0, (0.0, 0.0, 1.0)),
    (1, -1.0, (0.0, 0.0, -1.0)),
    (2, 1.0, (0.0, -1.0, 0.0)),
    (2, -1.0, (0.0, -1.0, 0.0)),
)


def light_shadow_maps(
    light: DirectionalLight | PointLight | SpotLight,
    world_triangles: np.ndarray,
    resolution: int,
    *,
    constant_bias: float = 0.0,
    slope_bias: float = 0.0,
    engine: str = "auto",
) -> list[ShadowMap]:
    """The shadow map(s) of one light over the given casters.

    Directional: one orthographic map fitted to the casters' bounding sphere. Spot: one
    perspective map, field of view ``2·cutoff`` (a cube when the cut-off exceeds 80°).
    Point: six cube faces.

    Args:
        light: a light of the scene model.
        world_triangles: (n, 3, 3) world-space casters (and receivers, for self-shadowing).
        resolution: texels per map side.
        constant_bias: see :func:`render_shadow_map`.
        slope_bias: see :func:`render_shadow_map`.
        engine: see :func:`render_shadow_map`.

    Returns:
        A list with one :class:`ShadowMap` (directional, spot) or six (point).
    """
    tris = _triangles("world_triangles", world_triangles)
    cameras = light_cameras(light, tris)
    if (
        len(cameras) == 6
        and use_compiled(engine)
        and isinstance(resolution, int | np.integer)
        and resolution >= 1
    ):
        if constant_bias < 0 or slope_bias < 0:
            raise ValueError(
                f"biases must be >= 0, got constant_bias={constant_bias}, slope_bias={slope_bias}"
            )
        from blinn_phong.shadows.map_render_kernels import cube_maps_compiled

        # the six faces in one (6, R, R) block, rendered one face per thread; the look-up
        # then reads the block without a copy
        res = int(resolution)
        cube = np.empty((6, res, res))
        vps = np.stack([proj @ view for view, proj in cameras])
        cube_maps_compiled(tris, vps, float(constant_bias), float(slope_bias), cube)
        return [ShadowMap(cube[face], view, proj) for face, (view, proj) in enumerate(cameras)]
    kw = {"constant_bias": constant_bias, "slope_bias": slope_bias, "engine": engine}
    return [render_shadow_map(tris, view, proj, resolution, **kw) for view, proj in cameras]


def light_cameras(
    light: DirectionalLight | PointLight | SpotLight, world_triangles: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The light camera(s) of :func:`light_shadow_maps`: ``[(view, projection), ...]`` (4×4 each).

    Directional: an orthographic camera looking along the light over the casters' bounding
    sphere (centre ``c``, radius ``r``; eye at ``c − 2r·d``, depth range [0.5r, 3.5r]).
    Spot (cut-off ≤ 80°): a perspective camera at the light along its axis, field of view
    twice the cut-off. Point (or wider spot): six 90° cube faces in the order of
    ``_CUBE_FACES`` (+x, −x, +y, −y, +z, −z; OpenGL 4.6 §8.13 table 8.19). Perspective
    cameras span ``near = 10⁻³·far`` to ``far`` = distance to the farthest bounding-sphere point.

    Args:
        light: a light of the scene model.
        world_triangles: (n, 3, 3) world-space casters.

    Returns:
        One (view, projection) pair, or six for a cube.
    """
    tris = _triangles("world_triangles", world_triangles)
    centre, radius = _bounds(tris)
    if isinstance(light, DirectionalLight):
        d = np.asarray(light.direction, dtype=np.float64)
        eye = centre - d * 2 * radius
        view = look_at(eye, centre, _up_for(d))
        proj = orthographic_matrix(-radius, radius, -radius, radius, radius * 0.5, radius * 3.5)
        return [(view, proj)]
    if not isinstance(light, PointLight | SpotLight):
        raise TypeError(
            f"light must be a DirectionalLight, PointLight or SpotLight, got {type(light).__name__}"
        )
    pos = np.asarray(light.position, dtype=np.float64)
    far = float(np.linalg.norm(centre - pos)) + radius
    near = max(far * 1e-3, 1e-6)
    if isinstance(light, SpotLight) and light.cutoff <= 80.0:
        d = np.asarray(light.direction, dtype=np.float64)
        return [(look_at(pos, pos + d, _up_for(d)), perspective_matrix(2 * light.cutoff, 1.0, near, far))]
    proj = perspective_matrix(90.0, 1.0, near, far)
    cameras = []
    for axis, sign, up in _CUBE_FACES:
        d = np.zeros(3)
        d[axis] = sign
        cameras.append((look_at(pos, pos + d, up), proj))
    return cameras


def shadow_map_visibility(
    light: DirectionalLight | PointLight | SpotLight,
    maps: list[ShadowMap],
    points: np.ndarray,
    normals: np.ndarray | None = None,
    *,
    normal_offset: float = 0.0,
    kernel: str = "nearest",
    engine: str = "auto",
) -> np.ndarray:
    """Visibility of points for one light from its maps (:func:`light_shadow_maps`).

    For a cube (six maps) each point is looked up in the face of its major axis; PCF
    taps do not cross face edges (they clamp to the face).

    Args:
        light: the light the maps were made for.
        maps: its shadow maps.
        points: (n, 3) world-space receiver points.
        normals: (n, 3) normals, for ``normal_offset``.
        normal_offset: see :func:`shadow_visibility`.
        kernel: see :func:`shadow_visibility`.
        engine: see :func:`shadow_visibility`.

    Returns:
        (n,) float64 visibility in [0, 1].
    """
    p = _points("points", points)
    if len(maps) == 1:
        return shadow_visibility(
            maps[0], p, normals, normal_offset=normal_offset, kernel=kernel, engine=engine
        )
    if len(maps) != 6 or isinstance(light, DirectionalLight):
        raise ValueError(f"expected 1 map, or 6 cube faces for a point light, got {len(maps)}")
    if use_compiled(engine):
        n = _lookup_normals(p, normals, normal_offset, kernel)
        from blinn_phong.shadows.map_lookup_kernels import lookup_compiled

        base = maps[0].depth.base
        same_block = (
            isinstance(base, np.ndarray)
            and base.shape == (6, *maps[0].depth.shape)
            and all(m.depth.base is base and np.shares_memory(m.depth, base[f]) for f, m in enumerate(maps))
        )
        return lookup_compiled(
            base if same_block else np.stack([m.depth for m in maps]),
            np.stack([m.projection @ m.view for m in maps]),
            np.stack([m.view for m in maps]),
            p,
            n,
            light_position=np.asarray(light.position, dtype=np.float64),
            normal_offset=float(normal_offset),
            kernel=kernel,
        )
    rel = p - np.asarray(light.position, dtype=np.float64)
    axis = np.argmax(np.abs(rel), axis=1)
    sign = np.sign(rel[np.arange(len(p)), axis])
    vis = np.ones(len(p))
    for face, (ax, sg, _) in enumerate(_CUBE_FACES):
        sel = (axis == ax) & (sign == sg)
        if np.any(sel):
            nrm = None if normals is None else np.asarray(normals)[sel]
            vis[sel] = shadow_visibility(
                maps[face], p[sel], nrm, normal_offset=normal_offset, kernel=kernel, engine="numpy"
            )
    return vis


@dataclass(frozen=True, eq=False)
class ShadowLookup:
    """The arrays :func:`blinn_phong.shadows.kernels.visibility_at` reads, for one light's maps.

    A compiled shading kernel looks shadows up per fragment with
    ``visibility_at(px, py, pz, nx, ny, nz, *lookup.arguments())`` (world point, normal),
    getting exactly :func:`shadow_map_visibility`'s value.

    ``depth``: (F, R, R) maps; ``view_projection``: (F, 4, 4); ``view_z``: (F, 3) row 2 of
    each view matrix; ``face_mode``: 1 for a cube (F = 6) else 0; ``light_position``: (3,);
    ``normal_offset``: world units; ``kernel``: 0 nearest, 1 bilinear, k for a k×k box.
    """

    depth: np.ndarray
    view_projection: np.ndarray
    view_z: np.ndarray
    face_mode: int
    light_position: np.ndarray
    normal_offset: float
    kernel: int

    def arguments(self) -> tuple[object, ...]:
        """The trailing arguments of ``visibility_at``, in order."""
        return (
            self.depth, self.view_projection, self.view_z, self.face_mode, self.light_position,
            self.normal_offset, self.kernel,
        )  # fmt: skip


def shadow_lookup(
    light: DirectionalLight | PointLight | SpotLight,
    maps: list[ShadowMap],
    *,
    normal_offset: float = 0.0,
    kernel: str = "nearest",
) -> ShadowLookup:
    """Pack one light's maps (:func:`light_shadow_maps`) for look-ups inside a compiled kernel.

    Args:
        light: the light the maps were made for.
        maps: its one map, or six cube faces.
        normal_offset: see :func:`shadow_visibility`.
        kernel: one of :data:`PCF_KERNELS`.

    Returns:
        :class:`ShadowLookup` (contiguous float64 arrays; the cube's faces without a copy when
        :func:`light_shadow_maps` rendered them into one block).
    """
    if kernel not in PCF_KERNELS:
        raise ValueError(f"kernel must be one of {PCF_KERNELS}, got {kernel!r}")
    if len(maps) not in (1, 6) or (len(maps) == 6 and isinstance(light, DirectionalLight)):
        raise ValueError(f"expected 1 map, or 6 cube faces for a point light, got {len(maps)}")
    from blinn_phong.shadows.map_lookup_kernels import KERNEL_CODES

    base = maps[0].depth.base
    same_block = (
        len(maps) == 6
        and isinstance(base, np.ndarray)
        and base.shape == (6, *maps[0].depth.shape)
        and all(m.depth.base is base and np.shares_memory(m.depth, base[f]) for f, m in enumerate(maps))
    )
    depth = base if same_block else np.stack([m.depth for m in maps])
    position = getattr(light, "position", (0.0, 0.0, 0.0)) if len(maps) == 6 else (0.0, 0.0, 0.0)
    return ShadowLookup(
        np.ascontiguousarray(depth, dtype=np.float64),
        np.ascontiguousarray(np.stack([m.projection @ m.view for m in maps])),
        np.ascontiguousarray(np.stack([m.view[2, :3] for m in maps])),
        1 if len(maps) == 6 else 0,
        np.asarray(position, dtype=np.float64),
        float(normal_offset),
        KERNEL_CODES[kernel],
    )


def planar_shadow_matrix(
    plane: np.ndarray | tuple[float, ...], light: np.ndarray | tuple[float, ...]
) -> np.ndarray:
    """Blinn's projection onto a plane from a light: ``M = (π·l) I − l πᵀ``.

    Args:
        plane: ``(a, b, c, d)`` with the plane ``a·x + b·y + c·z + d = 0`` (world space).
        light: homogeneous light ``(x, y, z, w)``: w = 1 for a point light at (x, y, z),
            w = 0 for a directional light whose light lies towards (x, y, z).

    Returns:
        4×4 matrix acting on homogeneous column vectors; divide by w after applying it.
    """
    pl = np.asarray(plane, dtype=np.float64)
    lt = np.asarray(light, dtype=np.float64)
    if pl.shape != (4,) or lt.shape != (4,) or not (np.all(np.isfinite(pl)) and np.all(np.isfinite(lt))):
        raise ValueError(f"plane and light must each be 4 finite numbers, got {plane!r} and {light!r}")
    if np.linalg.norm(pl[:3]) == 0:
        raise ValueError(f"plane normal (a, b, c) must not be zero, got {plane!r}")
    dot = float(pl @ lt)
    if dot == 0:
        raise ValueError("the light lies in the plane (or is parallel to it): no projection exists")
    return dot * np.eye(4) - np.outer(lt, pl)


def planar_shadow_mask(
    occluder_triangles: np.ndarray,
    plane: np.ndarray | tuple[float, ...],
    light: np.ndarray | tuple[float, ...],
    points: np.ndarray,
) -> np.ndarray:
    """Fake shadows: which points of the plane fall inside the flattened occluders.

    Args:
        occluder_triangles: (n, 3, 3) world-space triangles of the shadow casters.
        plane: ``(a, b, c, d)``, see :func:`planar_shadow_matrix`.
        light: homogeneous light, see :func:`planar_shadow_matrix`.
        points: (m, 3) points on the plane.

    Returns:
        (m,) float64 visibility: 0 inside a projected occluder, 1 elsewhere.
    """
    tris = _triangles("occluder_triangles", occluder_triangles)
    p = _points("points", points)
    m = planar_shadow_matrix(plane, light)
    proj = _homogeneous(tris.reshape(-1, 3)) @ m.T
    w = proj[:, 3].reshape(-1, 3)
    # a vertex level with a point light projects to infinity: such triangles are dropped
    finite = np.all(
        np.abs(w) > 1e-12 * np.abs(proj[:, :3]).reshape(-1, 9).max(axis=1, initial=1.0)[:, None], axis=1
    )
    proj = proj.reshape(-1, 3, 4)[finite]
    flat = proj[:, :, :3] / proj[:, :, 3:4]
    # point-in-triangle for every point at once: a short ray across the plane through the
    # flattened triangles, answered by Embree's BVH (edge-on, zero-area triangles never hit)
    from blinn_phong.shadows.raytrace import RayScene

    nrm = np.asarray(plane, dtype=np.float64)[:3]
    nrm = nrm / np.linalg.norm(nrm)
    if len(flat) == 0 or len(p) == 0:
        return np.ones(len(p))
    scale = max(float(np.abs(np.concatenate([flat.reshape(-1, 3), p])).max()), 1.0)
    h = 1e-3 * scale
    shadowed = RayScene(flat).occluded(p + h * nrm, np.broadcast_to(-nrm, p.shape), 2 * h)
    return 1.0 - shadowed.astype(np.float64)


def shadow_transmittance(material: object) -> np.ndarray:
    """(3,) RGB fraction of light a surface of ``material`` lets through, for shadow rays.

    By the material's transparency model (docs/transparency_models.md): an opaque material
    (``not material.transparent``) 0; ``partial_occlusion`` — the surface covers the fraction α,
    so ``1 − α`` of the light passes (Porter & Duff's ``over`` for the light); ``absorption`` —
    the grey filter ``T = 1 − α`` the renderer gives it; ``emission`` — it only adds light and
    hides nothing: 1. A material whose opacity varies over the surface (a base-colour texture, an
    alpha clip, Kay–Greenberg) has no single transmittance: 0, a full shadow, as before coloured
    shadows existed. Specular wash-out depends on the viewer, not the light: the base opacity counts.

    Args:
        material: a :class:`blinn_phong.model.scene.Material`.

    Returns:
        (3,) float64 in [0, 1].
    """
    if not material.transparent or material.textured or material.kay_greenberg is not None:  # type: ignore[attr-defined]
        return np.zeros(3)
    if material.transparency_model == "emission":  # type: ignore[attr-defined]
        return np.ones(3)
    return np.full(3, 1.0 - float(material.opacity))  # type: ignore[attr-defined]


def mesh_shadow_transmittance(mesh: object, two_sided: bool) -> np.ndarray:
    """(3,) RGB transmittance of a mesh as a shadow caster: :func:`shadow_transmittance` of its material.

    Under two-sided lighting (``two_sided``) a mesh whose back material lets through other light
    than its front one casts a full shadow (0): a shadow ray may cross either side.
    """
    t = shadow_transmittance(mesh.material)  # type: ignore[attr-defined]
    back = mesh.back_material  # type: ignore[attr-defined]
    if two_sided and back is not None and not np.array_equal(t, shadow_transmittance(back)):
        return np.zeros(3)
    return t


def caster_transmittance(scene: object) -> np.ndarray | None:
    """(T, 3) per-triangle RGB transmittance of a scene's shadow casters, or None when every caster is opaque.

    Triangles of the meshes with ``casts_shadows``, in scene order (the order of the frame's
    caster triangles), each with :func:`mesh_shadow_transmittance` of its mesh.

    Args:
        scene: a :class:`blinn_phong.model.scene.Scene`.

    Returns:
        (T, 3) float64 in [0, 1], or None.
    """
    two_sided = scene.light_model.two_sided  # type: ignore[attr-defined]
    parts, any_light = [], False
    for mesh in scene.meshes:  # type: ignore[attr-defined]
        if not mesh.casts_shadows:
            continue
        t = mesh_shadow_transmittance(mesh, two_sided)
        any_light = any_light or bool(np.any(t > 0))
        parts.append(np.broadcast_to(t, (len(mesh.triangles), 3)))
    if not any_light:
        return None
    return np.ascontiguousarray(np.concatenate(parts))


#: Shadow methods :func:`light_visibility` dispatches (the planner's shadow choices).
SHADOW_METHODS: tuple[str, ...] = ("none", "planar", "shadow_map", "ray_traced", "shadow_volume")


def light_visibility(
    method: str,
    light: DirectionalLight | PointLight | SpotLight,
    world_triangles: np.ndarray,
    points: np.ndarray,
    normals: np.ndarray,
    *,
    resolution: int = 1024,
    constant_bias: float = 1e-4,
    slope_bias: float = 2.0,
    kernel: str = "nearest",
    plane: np.ndarray | tuple[float, ...] | None = None,
    caster_triangles: np.ndarray | None = None,
    normal_offset: float = 0.0,
    engine: str = "auto",
    transmittance: np.ndarray | None = None,
    **volume_options: object,
) -> np.ndarray:
    """Visibility of points for one light by a named method (a planner choice).

    Args:
        method: one of :data:`SHADOW_METHODS`.
        light: the light.
        world_triangles: (n, 3, 3) every triangle of the scene, world space.
        points: (m, 3) world-space receiver points.
        normals: (m, 3) their normals.
        resolution: shadow-map size for ``shadow_map``.
        constant_bias: see :func:`render_shadow_map`.
        slope_bias: see :func:`render_shadow_map`.
        kernel: PCF kernel for ``shadow_map``.
        plane: ``(a, b, c, d)`` receiving plane for ``planar``.
        caster_triangles: casters for ``planar`` (default: every triangle not in the plane).
        normal_offset: receiver offset along the normal for ``shadow_map`` (world units).
        engine: ``shadow_map`` maps and look-ups by the numpy reference (``numpy``), the
            compiled kernels (``numba``) or ``auto``; see :func:`render_shadow_map`.
        transmittance: optional (n, 3) per-triangle RGB transmittance in [0, 1] (1 − α for
            partial occlusion, the per-channel transmittance for absorption, 0 for opaque):
            transparent casters then cast coloured shadows
            (:func:`blinn_phong.shadows.raytrace.transmitted_light`) and the result is (m, 3).
            Only ``none`` and ``ray_traced`` accept it.
        volume_options: for ``shadow_volume``: the keyword arguments of
            :func:`blinn_phong.shadows.volume.shadow_volume_visibility` (``camera``, ``method``...).

    Returns:
        (m,) float64 visibility in [0, 1]; (m, 3) per channel when ``transmittance`` is given.
    """
    p = _points("points", points)
    if volume_options and method != "shadow_volume":
        raise TypeError(f"light_visibility: {sorted(volume_options)} are for shadow_volume, not {method}")
    if transmittance is not None:
        if method == "none":
            return np.ones((len(p), 3))
        if method != "ray_traced":
            raise ValueError(
                f"transmittance: coloured shadows are ray traced; method {method!r} casts full "
                "shadows only (use 'ray_traced' or pass transmittance=None)"
            )
        from blinn_phong.shadows.raytrace import cached_ray_scene, transmitted_light

        tris = _triangles("world_triangles", world_triangles)
        scene = cached_ray_scene(tris)
        if isinstance(light, DirectionalLight):
            return transmitted_light(scene, p, normals, -np.asarray(light.direction), transmittance)
        return transmitted_light(scene, p, normals, light.position, transmittance, positional=True)
    if method == "none":
        return np.ones(len(p))
    tris = _triangles("world_triangles", world_triangles)
    # p and tris are checked: the functions called below need not check them again
    token = _CHECKED.set(frozenset((id(p), id(tris))))
    try:
        return _light_visibility_checked(
            method, light, tris, p, normals, resolution, constant_bias, slope_bias, kernel, plane,
            caster_triangles, normal_offset, engine, volume_options,
        )  # fmt: skip
    finally:
        _CHECKED.reset(token)


#: The last :func:`_on_plane` answer: (weak reference to the points, plane bytes, result). The
#: lights of a frame test the same points against the same plane; the weak reference makes sure
#: the points are the very same array, still alive (an id alone could be reused).
_ON_PLANE: list[tuple[object, bytes, tuple[np.ndarray, np.ndarray, np.ndarray]]] = []


def _on_plane(p: np.ndarray, plane: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mask, points, normals): the points within ``1e-6·max|p|`` of the plane (the receivers of
    planar shadows), and the plane's normal for each, contiguous; reused for the frame's next light."""
    key = plane.tobytes()
    for ref, k, result in _ON_PLANE:
        if k == key and ref() is p:  # type: ignore[operator]
            return result
    scale = max(float(-p.min()), float(p.max()), 1.0) if len(p) else 1.0
    mask = np.abs(p @ plane[:3] + plane[3]) <= 1e-6 * scale
    q = p[mask]
    normals = np.empty_like(q)
    normals[:] = plane[:3]
    result = (mask, q, normals)
    try:
        _ON_PLANE[:] = [(weakref.ref(p), key, result)]
    except TypeError:  # an array that takes no weak reference: not kept
        _ON_PLANE.clear()
    return result


def _casters_between(height: np.ndarray, plane: np.ndarray, light: np.ndarray) -> bool:
    """True when every caster corner (signed ``height`` above ``plane``) lies on the light's side of
    the plane and, for a positional light, below the light's own height."""
    if len(height) == 0:
        return False
    side = float(plane @ light)  # > 0: the light is on the positive side (w = 0: its direction)
    if side == 0:
        return False
    h = height if side > 0 else -height
    if h.min() < 0:
        return False
    return bool(light[3] == 0 or h.max() < abs(side))


def _receiver_visibility(
    light: DirectionalLight | PointLight | SpotLight,
    tris: np.ndarray,
    p: np.ndarray,
    normals: np.ndarray | None,
    resolution: int,
    constant_bias: float,
    slope_bias: float,
    kernel: str,
    normal_offset: float,
) -> np.ndarray:
    """Compiled ``shadow_map`` visibility: :func:`light_shadow_maps` then :func:`shadow_map_visibility`,
    same checks and bit-identical values, with only the texels the look-ups read rendered
    (:func:`blinn_phong.shadows.kernels.receiver_visibility_compiled`)."""
    vps, views, light_position = map_matrices(light, tris, resolution, constant_bias, slope_bias)
    n = _lookup_normals(p, normals, normal_offset, kernel)
    from blinn_phong.shadows.map_receiver_kernels import receiver_visibility_compiled

    return receiver_visibility_compiled(
        tris,
        vps,
        views,
        int(resolution),
        p,
        n,
        constant_bias=float(constant_bias),
        slope_bias=float(slope_bias),
        light_position=light_position,
        normal_offset=float(normal_offset),
        kernel=kernel,
    )


def map_matrices(
    light: DirectionalLight | PointLight | SpotLight,
    tris: np.ndarray,
    resolution: int,
    constant_bias: float,
    slope_bias: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The checked matrices of a light's shadow map(s) (:func:`light_cameras`).

    Args:
        light: the light.
        tris: (n, 3, 3) float64 world-space casters (checked).
        resolution: texels per map side, an integer ≥ 1.
        constant_bias: window-depth units of :func:`render_shadow_map`, ≥ 0.
        slope_bias: multiple of the depth slope of :func:`render_shadow_map`, ≥ 0.

    Returns:
        ``(view_projection (F, 4, 4), view (F, 4, 4), light_position)``: F = 1, or 6 cube faces
        with the point light's (3,) world position (else None).
    """
    cameras = light_cameras(light, tris)  # the checks and their order of light_shadow_maps
    if not isinstance(resolution, int | np.integer) or resolution < 1:
        raise ValueError(f"resolution must be an integer >= 1, got {resolution!r}")
    if constant_bias < 0 or slope_bias < 0:
        raise ValueError(f"biases must be >= 0, got constant_bias={constant_bias}, slope_bias={slope_bias}")
    cube = len(cameras) == 6
    return (
        np.stack([proj @ view for view, proj in cameras]),
        np.stack([view for view, _ in cameras]),
        np.asarray(light.position, dtype=np.float64) if cube else None,  # type: ignore[union-attr]
    )


def _light_visibility_checked(
    method: str,
    light: DirectionalLight | PointLight | SpotLight,
    tris: np.ndarray,
    p: np.ndarray,
    normals: np.ndarray,
    resolution: int,
    constant_bias: float,
    slope_bias: float,
    kernel: str,
    plane: np.ndarray | tuple[float, ...] | None,
    caster_triangles: np.ndarray | None,
    normal_offset: float,
    engine: str,
    volume_options: dict[str, object],
) -> np.ndarray:
    if method == "ray_traced":
        from blinn_phong.shadows.raytrace import (
            cached_ray_scene,
            directional_light_visibility,
            point_light_visibility,
        )

        scene = cached_ray_scene(tris)  # one BVH for every light of a frame
        if isinstance(light, DirectionalLight):
            return directional_light_visibility(
                scene, p, normals, -np.asarray(light.direction), engine=engine
            )
        return point_light_visibility(scene, p, normals, light.position, engine=engine)
    if method == "shadow_volume":
        from blinn_phong.shadows.volume import shadow_volume_visibility

        return shadow_volume_visibility(light, tris, p, normals, **volume_options)  # type: ignore[arg-type]
    if method == "shadow_map":
        if use_compiled(engine):
            return _receiver_visibility(
                light, tris, p, normals, resolution, constant_bias, slope_bias, kernel, normal_offset
            )
        maps = light_shadow_maps(
            light, tris, resolution, constant_bias=constant_bias, slope_bias=slope_bias, engine=engine
        )
        return shadow_map_visibility(
            light, maps, p, normals, normal_offset=normal_offset, kernel=kernel, engine=engine
        )
    if method == "planar":
        if plane is None:
            raise ValueError("planar shadows need the receiving plane (a, b, c, d)")
        pl = np.asarray(plane, dtype=np.float64)
        if isinstance(light, DirectionalLight):
            homogeneous_light = np.r_[-np.asarray(light.direction), 0.0]
        else:
            homogeneous_light = np.r_[np.asarray(light.position), 1.0]
        on_plane, q, q_normals = _on_plane(p, pl)
        vis = np.ones(len(p))
        between = False
        if caster_triangles is None:
            height = tris @ pl[:3] + pl[3]  # (n, 3) signed heights (times |(a, b, c)|) of the corners
            off_plane = np.abs(height).max(axis=1) > 1e-9 * max(np.abs(tris).max(), 1.0)
            caster_triangles = tris[off_plane]
            between = _casters_between(height[off_plane], pl, homogeneous_light)
        if not (len(caster_triangles) and on_plane.any()):
            return vis
        if between:
            # every caster lies between the plane and the light: a point of the plane is inside a
            # flattened caster exactly when its segment (ray) to the light crosses that caster, so
            # the frame's one BVH answers it (cached_ray_scene, shared with every other light)
            # instead of a new BVH of flattened triangles per light
            from blinn_phong.shadows.raytrace import (
                cached_ray_scene,
                directional_light_visibility,
                point_light_visibility,
            )

            scene = cached_ray_scene(tris)
            towards = homogeneous_light[:3]
            if homogeneous_light[3] == 0:
                vis[on_plane] = directional_light_visibility(scene, q, q_normals, towards, engine=engine)
            else:
                vis[on_plane] = point_light_visibility(scene, q, q_normals, towards, engine=engine)
            return vis
        vis[on_plane] = planar_shadow_mask(caster_triangles, pl, homogeneous_light, q)
        return vis
    raise ValueError(f"method must be one of {SHADOW_METHODS}, got {method!r}")
