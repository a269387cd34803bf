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

Modules
-------
:mod:`.volume_mesh` (welding, components, silhouettes, the volumes), :mod:`.volume_setup` (the
numpy engine's clipping, set-up and counting), :mod:`.volume_kernels` (the compiled kernels),
:mod:`.volume_counting` (stencil counts of projected receivers on either engine, receiver tiles)
and this module (the visibility of receivers, and the choice between z-pass and z-fail).
"""

from __future__ import annotations

import math

import numpy as np

from blinn_phong._checks import choice_error
from blinn_phong._numba import use_compiled
from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Camera
from blinn_phong.shadows.method import ShadowFrame, ShadowMethod
from blinn_phong.shadows.volume_counting import STENCIL_METHODS, _count, _projected
from blinn_phong.shadows.volume_mesh import (
    _light,
    _points,
    _topology_with_key,
    _triangles,
    shadow_volume_triangles,
)
from blinn_phong.shadows.volume_setup import _offset_numpy, _project_numpy

__all__ = ["choose_stencil", "shadow_volume_visibility", "zpass_is_safe"]


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
