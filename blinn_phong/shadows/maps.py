"""Shadow maps for directional, spot and point lights (the ``shadow_map`` method).

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

Engines: every shadow-map function takes ``engine``: ``numpy`` runs the code in this module
(the readable reference), ``numba`` the compiled twins of
:mod:`blinn_phong.shadows.map_render_kernels` and :mod:`blinn_phong.shadows.map_lookup_kernels`
(same formulas; depths within 1e-12, visibilities within 1e-9), ``auto`` (the default) the
compiled ones when numba imports. :func:`blinn_phong.shadows.methods.light_visibility` also accepts
per-triangle RGB transmittances, for coloured shadows of transparent casters (ray traced).

Image conventions: shadow maps are (height, width) arrays of window depth in [0, 1],
row 0 at the top (as :func:`~blinn_phong.geometry.raster.rasterize` returns them), 1 where no
caster was drawn.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from blinn_phong._numba import numba_available, use_compiled
from blinn_phong.geometry.raster import rasterize
from blinn_phong.model.lights import CUBE_FACES, DirectionalLight, PointLight, SpotLight
from blinn_phong.shadows._inputs import checked_points, checked_triangles, homogeneous
from blinn_phong.shadows.method import ShadowMethod

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
    n = checked_points("normals", normals)
    if n.shape != p.shape:
        raise ValueError(f"normals must have the shape of points {p.shape}, got {n.shape}")
    return n


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
            scatter-min), ``numba`` (:func:`blinn_phong.shadows.map_render_kernels.depth_map_compiled`,
            same formulas, depths within 1e-12) or ``auto`` (numba when it imports).

    Returns:
        :class:`ShadowMap` with the biased nearest depth per texel (1 where empty).
    """
    tris = checked_triangles("world_triangles", world_triangles)
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
    clip = homogeneous(tris.reshape(-1, 3)) @ vp.T
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
            (:func:`blinn_phong.shadows.map_lookup_kernels.lookup_compiled`) or ``auto``.

    Returns:
        (n,) float64 visibility in [0, 1].
    """
    p = checked_points("points", points)
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
    clip = homogeneous(p) @ (shadow_map.projection @ shadow_map.view).T
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
    tris = checked_triangles("world_triangles", world_triangles)
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
    ``CUBE_FACES`` (+x, −x, +y, −y, +z, −z; OpenGL 4.6 §8.13 table 8.19). Perspective
    cameras span ``near = 10⁻³·far`` to ``far`` = distance to the farthest bounding-sphere point.

    Args:
        light: a light of the scene model.
        world_triangles: (n, 3, 3) world-space casters.

    Returns:
        One (view, projection) pair, or six for a cube.
    """
    tris = checked_triangles("world_triangles", world_triangles)
    centre, radius = _bounds(tris)
    if not getattr(light, "casts_shadows", False):
        raise TypeError(
            f"light must be a DirectionalLight, PointLight or SpotLight, got {type(light).__name__}"
        )
    return light.shadow_cameras(centre, radius)  # type: ignore[union-attr]


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
    p = checked_points("points", points)
    if len(maps) == 1:
        return shadow_visibility(
            maps[0], p, normals, normal_offset=normal_offset, kernel=kernel, engine=engine
        )
    if len(maps) != 6 or not light.positional:
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
    for face, (ax, sg, _) in enumerate(CUBE_FACES):
        sel = (axis == ax) & (sign == sg)
        if np.any(sel):
            nrm = None if normals is None else np.asarray(normals)[sel]
            vis[sel] = shadow_visibility(
                maps[face], p[sel], nrm, normal_offset=normal_offset, kernel=kernel, engine="numpy"
            )
    return vis


@dataclass(frozen=True, eq=False)
class ShadowLookup:
    """The arrays :func:`blinn_phong.shadows.map_lookup_kernels.visibility_at` reads, for one light's maps.

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
    if len(maps) not in (1, 6) or (len(maps) == 6 and not light.positional):
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
    (:func:`blinn_phong.shadows.map_receiver_kernels.receiver_visibility_compiled`)."""
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


def map_visibility(
    light: DirectionalLight | PointLight | SpotLight,
    tris: np.ndarray,
    p: np.ndarray,
    normals: np.ndarray | None,
    *,
    resolution: int = 1024,
    constant_bias: float = 1e-4,
    slope_bias: float = 2.0,
    kernel: str = "nearest",
    normal_offset: float = 0.0,
    engine: str = "auto",
) -> np.ndarray:
    """(m,) visibility of the (m, 3) points ``p`` by ``light``'s shadow map(s) of the (n, 3, 3)
    casters ``tris`` (both checked by the caller): :func:`light_shadow_maps` then
    :func:`shadow_map_visibility` (numpy), or with the compiled engine only the texels the
    look-ups read (:func:`_receiver_visibility`, bit-identical)."""
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


def _choice_params(options: Any, planned: Any) -> tuple[dict, str]:
    params: dict[str, object] = {"resolution": options.resolution or planned.params.get("resolution", 1024)}
    for name in ("constant_bias", "slope_bias", "kernel"):
        if getattr(options, name) is not None:
            params[name] = getattr(options, name)
    return params, ""


METHOD = ShadowMethod(
    name="shadow_map",
    title="a shadow map",
    summary="the scene's depth from the light, looked up per point (Williams 1978), with bias and PCF",
    exact=False,
    coloured=False,
    uses_rays=False,
    without_embree=None,
    cost_model="shadow_map",
    parameters=("resolution", "constant_bias", "slope_bias", "kernel", "normal_offset", "engine"),
    visibility=map_visibility,
    choice_params=_choice_params,
)
