"""Pure maths that maps Blender's scene values onto the Blinn-Phong / OpenGL lighting model.

No bpy here: every function takes plain numbers and returns numbers or numpy arrays, so it is
tested without Blender. ``addon/convert.py`` reads the values out of the depsgraph and calls these.

Conventions: lengths in Blender units (metres), angles in radians unless a name says ``_degrees``,
colours linear-light RGB. Matrices are 4×4 float64 acting on column vectors (OpenGL convention, as
in ``blinn_phong.model.scene``). Pixel rectangles are ``(x0, y0, x1, y1)`` half-open, with y counted from the
TOP row (the image convention of this project), unlike Blender, which counts from the bottom.

Radiometry: Blender's lights are in watts (point, spot, area) or W/m² (sun), its diffuse BSDF is
``albedo/π``. The Blinn-Phong equation has ``kd · I · (n·l)`` with a unit-less light "intensity" ``I``;
choosing ``I`` = irradiance/π makes ``kd = albedo`` render the same radiance as Blender's Lambertian
surface. Hence a sun of strength ``S`` has ``I = S/π`` and a point light of power ``P`` (radiant
intensity ``P/(4π)`` W/sr in Cycles, ``intern/cycles/scene/light.cpp`` divides the strength by 4π)
has ``I = P/(4π²)`` with inverse-square attenuation.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from blinn_phong.model.transforms import orthographic_matrix

__all__ = [
    "BLENDER_EMPTY_DEPTH",
    "MAX_SHININESS",
    "area_light_intensity",
    "blinn_phong_from_principled",
    "border_rectangle",
    "camera_projection",
    "crop_projection",
    "frustum_matrix",
    "point_light_attenuation",
    "point_light_intensity",
    "render_size",
    "roughness_to_shininess",
    "spot_cutoff_degrees",
    "spot_exponent",
    "spot_mean_blender",
    "spot_mean_gl",
    "sun_light_intensity",
    "view3d_zoom_factor",
    "viewport_projection",
    "viewport_size",
    "window_depth_to_distance",
]

MAX_SHININESS = 10_000.0
"""Upper end of :func:`roughness_to_shininess` (reached at roughness ≈ 0.119); a mirror has no
finite Blinn-Phong exponent, so smaller roughness values map to this one (documented, not silent)."""

SensorFit = Literal["AUTO", "HORIZONTAL", "VERTICAL"]


def _finite(
    value: float, name: str, *, low: float | None = None, high: float | None = None, low_open: bool = False
) -> float:
    """Check one scalar argument; raise ValueError/TypeError naming it."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{name}: expected a finite number, got {x!r}")
    if low is not None and (x < low or (low_open and x == low)):
        raise ValueError(f"{name}: expected a value {'>' if low_open else '>='} {low}, got {x!r}")
    if high is not None and x > high:
        raise ValueError(f"{name}: expected a value <= {high}, got {x!r}")
    return x


# --------------------------------------------------------------------------- image size, border


def render_size(resolution_x: int, resolution_y: int, percentage: int) -> tuple[int, int]:
    """Pixel size of the rendered frame: ``floor(resolution · percentage / 100)`` per axis.

    Source: Blender ``BKE_render_resolution`` (``source/blender/blenkernel/intern/scene.cc``):
    ``r_width = (r->xsch * r->size) / 100`` in integer arithmetic.

    Args:
        resolution_x: ``RenderSettings.resolution_x`` (pixels, >= 1).
        resolution_y: ``RenderSettings.resolution_y`` (pixels, >= 1).
        percentage: ``RenderSettings.resolution_percentage`` (1..32767).
    """
    for name, v in (
        ("resolution_x", resolution_x),
        ("resolution_y", resolution_y),
        ("percentage", percentage),
    ):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
            raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
    return int(resolution_x) * int(percentage) // 100, int(resolution_y) * int(percentage) // 100


def border_rectangle(
    min_x: float, max_x: float, min_y: float, max_y: float, width: int, height: int
) -> tuple[int, int, int, int]:
    """Pixel rectangle of Blender's render border, as ``(x0, y0, x1, y1)`` with y from the TOP row.

    Blender rounds each edge to the nearest pixel, ``round_fl_to_int(border.xmin * winx)`` etc.
    (``render_init_from_main`` in ``source/blender/render/intern/pipeline.cc``), with y measured from
    the bottom; this returns the same pixels with y flipped to the top-down convention.

    Args:
        min_x: ``RenderSettings.border_min_x`` in [0, 1] (fraction of the width from the left).
        max_x: ``border_max_x`` in [0, 1], >= ``min_x``.
        min_y: ``border_min_y`` in [0, 1] (fraction of the height from the BOTTOM).
        max_y: ``border_max_y`` in [0, 1], >= ``min_y``.
        width: full frame width in pixels (after the resolution percentage).
        height: full frame height in pixels.
    """
    fx0, fx1, fy0, fy1 = (
        _finite(v, n, low=0.0, high=1.0)
        for v, n in ((min_x, "min_x"), (max_x, "max_x"), (min_y, "min_y"), (max_y, "max_y"))
    )
    if fx1 < fx0 or fy1 < fy0:
        raise ValueError(f"border: expected min <= max, got x {fx0}..{fx1}, y {fy0}..{fy1}")
    x0, x1 = math.floor(fx0 * width + 0.5), math.floor(fx1 * width + 0.5)
    yb0, yb1 = math.floor(fy0 * height + 0.5), math.floor(fy1 * height + 0.5)
    return x0, height - yb1, x1, height - yb0


# --------------------------------------------------------------------------- camera


def frustum_matrix(
    left: float, right: float, bottom: float, top: float, near: float, far: float
) -> np.ndarray:
    """``glFrustum(left, right, bottom, top, near, far)`` (eye → clip), OpenGL 2.1 spec §2.11.1.

    Rows ``(2n/(r-l), 0, (r+l)/(r-l), 0)``, ``(0, 2n/(t-b), (t+b)/(t-b), 0)``,
    ``(0, 0, -(f+n)/(f-n), -2fn/(f-n))``, ``(0, 0, -1, 0)``.
    """
    l, r, b, t = (
        _finite(v, n) for v, n in ((left, "left"), (right, "right"), (bottom, "bottom"), (top, "top"))
    )
    n = _finite(near, "near", low=0.0, low_open=True)
    f = _finite(far, "far", low=n, low_open=True)
    if l == r or b == t:
        raise ValueError(f"frustum: need left != right and bottom != top, got {l}, {r}, {b}, {t}")
    m = np.zeros((4, 4))
    m[0, 0], m[0, 2] = 2 * n / (r - l), (r + l) / (r - l)
    m[1, 1], m[1, 2] = 2 * n / (t - b), (t + b) / (t - b)
    m[2, 2], m[2, 3] = -(f + n) / (f - n), -2 * f * n / (f - n)
    m[3, 2] = -1.0
    return m


def camera_projection(
    *,
    kind: Literal["PERSP", "ORTHO"],
    width: int,
    height: int,
    lens_mm: float = 50.0,
    sensor_width_mm: float = 36.0,
    sensor_height_mm: float = 24.0,
    sensor_fit: SensorFit = "AUTO",
    ortho_scale: float = 6.0,
    shift_x: float = 0.0,
    shift_y: float = 0.0,
    clip_start: float = 0.1,
    clip_end: float = 100.0,
    pixel_aspect_x: float = 1.0,
    pixel_aspect_y: float = 1.0,
    zoom: float = 1.0,
    offset_x: float = 0.0,
    offset_y: float = 0.0,
) -> np.ndarray:
    """Blender's camera projection matrix (eye → clip, OpenGL convention) for a ``width × height`` frame.

    Follows ``BKE_camera_params_compute_viewplane`` (``source/blender/blenkernel/intern/camera.cc``):
    the sensor fit picks the axis the sensor spans (AUTO: the longer side of the frame in aspect-
    corrected pixels, with the sensor *width* as its size); one pixel spans
    ``sensor · clip_start / lens / viewfac`` eye units (perspective) or ``ortho_scale / viewfac``
    (orthographic), where ``viewfac`` is the pixel count along the fitted axis; the shift moves the
    view plane by ``shift · viewfac`` pixels. The view plane bounds then go to ``glFrustum`` or
    ``glOrtho`` with ``clip_start``/``clip_end``.

    Args:
        kind: ``"PERSP"`` or ``"ORTHO"`` (``Camera.type``; panoramic cameras are not supported).
        width: frame width in pixels (after the resolution percentage).
        height: frame height in pixels.
        lens_mm: focal length (``Camera.lens``), mm, > 0.
        sensor_width_mm: ``Camera.sensor_width``, mm, > 0.
        sensor_height_mm: ``Camera.sensor_height``, mm, > 0 (used only with VERTICAL fit).
        sensor_fit: ``"AUTO"``, ``"HORIZONTAL"`` or ``"VERTICAL"``.
        ortho_scale: ``Camera.ortho_scale`` (view width along the fitted axis), > 0.
        shift_x: ``Camera.shift_x``, fraction of the fitted dimension.
        shift_y: ``Camera.shift_y``, fraction of the fitted dimension.
        clip_start: near clip distance, > 0.
        clip_end: far clip distance, > clip_start.
        pixel_aspect_x: ``RenderSettings.pixel_aspect_x``, > 0.
        pixel_aspect_y: ``RenderSettings.pixel_aspect_y``, > 0.
        zoom: ``CameraParams.zoom``: the view plane is scaled by it (1 for renders; the 3D view
            uses 2 outside camera view and ``1 / zoom factor`` in camera view), > 0.
        offset_x: ``CameraParams.offsetx``: the view plane moves by ``offset · width`` pixels
            (0 for renders; the 3D view's camera-view pan).
        offset_y: ``CameraParams.offsety``, by ``offset · height`` pixels.

    For ``ORTHO`` the clip range may start behind the eye (the 3D view's orthographic views clip
    at ``±clip_end/2``): only ``clip_start < clip_end`` is required.

    Returns:
        (4, 4) float64 projection matrix.
    """
    if kind not in ("PERSP", "ORTHO"):
        raise ValueError(
            f"kind: expected 'PERSP' or 'ORTHO' (panoramic cameras are not supported), got {kind!r}"
        )
    if sensor_fit not in ("AUTO", "HORIZONTAL", "VERTICAL"):
        raise ValueError(f"sensor_fit: expected 'AUTO', 'HORIZONTAL' or 'VERTICAL', got {sensor_fit!r}")
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
            raise ValueError(f"{name}: expected an integer >= 1 (pixels), got {v!r}")
    lens = _finite(lens_mm, "lens_mm", low=0.0, low_open=True)
    sensor_w = _finite(sensor_width_mm, "sensor_width_mm", low=0.0, low_open=True)
    sensor_h = _finite(sensor_height_mm, "sensor_height_mm", low=0.0, low_open=True)
    scale = _finite(ortho_scale, "ortho_scale", low=0.0, low_open=True)
    sx, sy = _finite(shift_x, "shift_x"), _finite(shift_y, "shift_y")
    near = _finite(clip_start, "clip_start", low=0.0 if kind == "PERSP" else None, low_open=True)
    far = _finite(clip_end, "clip_end", low=near, low_open=True)
    zoom = _finite(zoom, "zoom", low=0.0, low_open=True)
    ox, oy = _finite(offset_x, "offset_x"), _finite(offset_y, "offset_y")
    aspx = _finite(pixel_aspect_x, "pixel_aspect_x", low=0.0, low_open=True)
    aspy = _finite(pixel_aspect_y, "pixel_aspect_y", low=0.0, low_open=True)

    if sensor_fit == "AUTO":
        fit, sensor = ("HORIZONTAL" if aspx * width >= aspy * height else "VERTICAL"), sensor_w
    else:
        fit, sensor = sensor_fit, (sensor_w if sensor_fit == "HORIZONTAL" else sensor_h)
    ycor = aspy / aspx
    viewfac = float(width) if fit == "HORIZONTAL" else ycor * height
    pixsize = (sensor * near / lens if kind == "PERSP" else scale) / viewfac * zoom

    dx, dy = sx * viewfac + width * ox, sy * viewfac + height * oy
    xmin, xmax = (-0.5 * width + dx) * pixsize, (0.5 * width + dx) * pixsize
    ymin, ymax = (-0.5 * ycor * height + dy) * pixsize, (0.5 * ycor * height + dy) * pixsize
    if kind == "PERSP":
        return frustum_matrix(xmin, xmax, ymin, ymax, near, far)
    return orthographic_matrix(xmin, xmax, ymin, ymax, near, far)


# --------------------------------------------------------------------------- 3D viewport

VIEWPORT_SENSOR_MM = 36.0
"""Sensor width of the 3D view's own (non-camera) projection: ``DEFAULT_SENSOR_WIDTH``."""

VIEWPORT_ZOOM = 2.0
"""``CAMERA_PARAM_ZOOM_INIT_PERSP``: the 3D view's perspective and orthographic views see twice the
sensor (``BKE_camera_params_from_view3d``)."""


def view3d_zoom_factor(camera_zoom: float) -> float:
    """Scale of the camera frame in camera view: ``(√2 + camzoom/50)² / 4``
    (``BKE_screen_view3d_zoom_to_fac``; ``RegionView3D.view_camera_zoom``); 1 at
    ``camzoom = 50 (2 − √2) ≈ 29.29``, where the camera frame fills the region's fitted axis."""
    z = _finite(camera_zoom, "camera_zoom")
    return (math.sqrt(2.0) + z / 50.0) ** 2 / 4.0


def viewport_projection(
    *,
    view_perspective: Literal["PERSP", "ORTHO", "CAMERA"],
    region_width: int,
    region_height: int,
    lens_mm: float = 50.0,
    clip_start: float = 0.01,
    clip_end: float = 1000.0,
    view_distance: float = 10.0,
    camera: dict[str, object] | None = None,
    camera_zoom: float = 0.0,
    camera_offset: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, str]:
    """The projection matrix of a 3D view (``RegionView3D.window_matrix``) and the camera kind.

    Follows ``BKE_camera_params_from_view3d`` then ``BKE_camera_params_compute_viewplane`` with the
    region size and square pixels (``source/blender/blenkernel/intern/camera.cc``):

    * ``PERSP`` (a free perspective view): the view's ``lens`` on a 36 mm sensor, zoom 2, the
      view's clip range;
    * ``ORTHO``: ``ortho_scale = view_distance · 36 / lens``, zoom 2, clip range
      ``[−clip_end/2, clip_end/2]``;
    * ``CAMERA`` (looking through the scene camera): the camera's own parameters; with
      ``f = view3d_zoom_factor(camera_zoom)`` the shift is multiplied by ``f``, the view plane
      moves by ``offset = 2 · camera_offset · f`` and the zoom is ``1/f``.

    Args:
        view_perspective: ``RegionView3D.view_perspective``.
        region_width: the 3D view region's width in pixels (``Region.width``).
        region_height: its height.
        lens_mm: ``SpaceView3D.lens`` (PERSP, ORTHO).
        clip_start: ``SpaceView3D.clip_start`` (PERSP, ORTHO).
        clip_end: ``SpaceView3D.clip_end`` (PERSP, ORTHO).
        view_distance: ``RegionView3D.view_distance`` (ORTHO).
        camera: for CAMERA, the keyword arguments of :func:`camera_projection` that describe the
            camera (``kind``, ``lens_mm``, ``sensor_width_mm``, ``sensor_height_mm``, ``sensor_fit``,
            ``ortho_scale``, ``shift_x``, ``shift_y``, ``clip_start``, ``clip_end``).
        camera_zoom: ``RegionView3D.view_camera_zoom`` (CAMERA).
        camera_offset: ``RegionView3D.view_camera_offset`` (CAMERA).

    Returns:
        ``(projection, kind)``: the (4, 4) eye → clip matrix and ``"perspective"`` or
        ``"orthographic"`` (the ``blinn_phong.model.scene.Camera`` kind).
    """
    size = {"width": region_width, "height": region_height}
    if view_perspective == "PERSP":
        projection = camera_projection(
            kind="PERSP",
            **size,
            lens_mm=lens_mm,
            sensor_width_mm=VIEWPORT_SENSOR_MM,
            clip_start=clip_start,
            clip_end=clip_end,
            zoom=VIEWPORT_ZOOM,
        )
        return projection, "perspective"
    if view_perspective == "ORTHO":
        lens = _finite(lens_mm, "lens_mm", low=0.0, low_open=True)
        half = 0.5 * _finite(clip_end, "clip_end", low=0.0, low_open=True)
        distance = _finite(view_distance, "view_distance", low=0.0, low_open=True)
        projection = camera_projection(
            kind="ORTHO",
            **size,
            ortho_scale=distance * VIEWPORT_SENSOR_MM / lens,
            clip_start=-half,
            clip_end=half,
            zoom=VIEWPORT_ZOOM,
        )
        return projection, "orthographic"
    if view_perspective != "CAMERA":
        raise ValueError(f"view_perspective: expected 'PERSP', 'ORTHO' or 'CAMERA', got {view_perspective!r}")
    if camera is None:
        raise ValueError("camera: the CAMERA view needs the scene camera's parameters, got None")
    factor = view3d_zoom_factor(camera_zoom)
    params = dict(camera)
    params["shift_x"] = float(params.get("shift_x", 0.0)) * factor
    params["shift_y"] = float(params.get("shift_y", 0.0)) * factor
    ox, oy = (_finite(v, "camera_offset") for v in camera_offset)
    projection = camera_projection(
        **params, **size, zoom=1.0 / factor, offset_x=2.0 * ox * factor, offset_y=2.0 * oy * factor
    )
    return projection, "perspective" if params.get("kind", "PERSP") == "PERSP" else "orthographic"


def viewport_size(region_width: int, region_height: int, reduction: int = 1) -> tuple[int, int]:
    """Pixel size of a viewport frame rendered at ``1/reduction`` of the region (at least 1×1);
    the projection is the region's (the frame is stretched over it when drawn)."""
    if isinstance(reduction, bool) or not isinstance(reduction, int) or reduction < 1:
        raise ValueError(f"reduction: expected an integer >= 1, got {reduction!r}")
    for name, v in (("region_width", region_width), ("region_height", region_height)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
            raise ValueError(f"{name}: expected an integer >= 1 (pixels), got {v!r}")
    return max(1, int(region_width) // reduction), max(1, int(region_height) // reduction)


def crop_projection(
    projection: np.ndarray, width: int, height: int, region: tuple[int, int, int, int]
) -> np.ndarray:
    """Projection that renders only ``region`` of a ``width × height`` frame into its own image.

    Window coordinates of the cropped image are those of the full frame minus the region's corner
    (``x' = x − x0``; in OpenGL's bottom-up window y, ``y' = y − (height − y1)``), so every pixel
    centre and sample lands where it was: rendering the crop equals cropping the full render. With
    ``x_w = (x_ndc + 1)·W/2`` this is ``x_ndc' = x_ndc·W/w' + (W − 2·x0)/w' − 1`` (and likewise for y),
    applied in clip space by multiplying with ``w_c``.

    Args:
        projection: (4, 4) eye -> clip matrix of the full frame.
        width: full frame width in pixels.
        height: full frame height in pixels.
        region: ``(x0, y0, x1, y1)`` pixel rectangle, y from the top row (as :func:`border_rectangle`).
    """
    p = np.asarray(projection, dtype=np.float64)
    if p.shape != (4, 4) or not np.isfinite(p).all():
        raise ValueError(f"projection: expected a finite (4, 4) matrix, got shape {p.shape}")
    x0, y0, x1, y1 = (int(v) for v in region)
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise ValueError(
            f"region: expected 0 <= x0 < x1 <= {width} and 0 <= y0 < y1 <= {height}, got {region}"
        )
    w, h = x1 - x0, y1 - y0
    gl_y0 = height - y1
    crop = np.eye(4)
    crop[0, 0], crop[0, 3] = width / w, (width - 2 * x0) / w - 1.0
    crop[1, 1], crop[1, 3] = height / h, (height - 2 * gl_y0) / h - 1.0
    return crop @ p


# --------------------------------------------------------------------------- lights


def sun_light_intensity(strength: float) -> float:
    """Blinn-Phong intensity of a Blender sun of ``strength`` W/m²: ``strength / π``.

    A Lambertian surface of albedo ``ρ`` facing the sun reflects radiance ``ρ · S / π`` (BRDF ``ρ/π``
    times irradiance ``S``); with ``kd = ρ`` the Blinn-Phong term ``kd · I`` matches for ``I = S/π``.
    """
    return _finite(strength, "strength (W/m²)", low=0.0) / math.pi


def point_light_intensity(power: float) -> float:
    """Blinn-Phong intensity (at unit distance, inverse-square) of a point or spot light of ``power`` W.

    Cycles emits ``P/(4π)`` W/sr from a point light (spot lights too, before their cone mask), so the
    irradiance at distance ``d`` is ``P/(4π d²)`` and the reflected radiance ``ρ P/(4π² d²)``; the
    Blinn-Phong intensity with attenuation ``1/d²`` is therefore ``P / (4π²)``.
    """
    return _finite(power, "power (W)", low=0.0) / (4.0 * math.pi**2)


def area_light_intensity(power: float) -> float:
    """Blinn-Phong intensity along the normal of an area light of ``power`` W (far-field approximation).

    A one-sided Lambertian emitter of power ``P`` has radiant intensity ``(P/π) cos θ`` (the integral
    of ``cos θ`` over the hemisphere is π); reflected radiance at distance ``d`` along the normal is
    ``ρ P / (π² d²)``, so ``I = P/π²``. The converter models the ``cos θ`` lobe as a spot light with
    cutoff 90° and exponent 1 and inverse-square attenuation.
    """
    return _finite(power, "power (W)", low=0.0) / math.pi**2


def point_light_attenuation(radius: float) -> tuple[float, float, float]:
    """OpenGL attenuation ``(kc, kl, kq)`` for a Blender point/spot/area light of ``radius``.

    Inverse square, ``kq = 1``, with ``kc = radius²`` so a point at distance ``d`` receives
    ``1/(r² + d²)``: the irradiance on the axis of a Lambertian disc of radius ``r`` is proportional
    to ``1/(r² + d²)`` (the disc's form factor, e.g. Howell's catalogue, configuration B-16), which
    keeps a soft light finite at its centre instead of the singular ``1/d²``. ``kc`` is raised to
    ``1e-6`` for a zero radius because the attenuation must stay finite at ``d = 0``.

    Args:
        radius: ``Light.shadow_soft_size`` in Blender units, >= 0.
    """
    r = _finite(radius, "radius", low=0.0)
    return max(r * r, 1e-6), 0.0, 1.0


def spot_cutoff_degrees(spot_size: float) -> float:
    """OpenGL spot cutoff (half angle, degrees) of a Blender spot of full cone angle ``spot_size`` (rad)."""
    size = _finite(spot_size, "spot_size (radians)", low=0.0, high=math.pi, low_open=True)
    return math.degrees(size / 2.0)


def spot_mean_blender(spot_blend: float) -> float:
    """Mean of Blender's spot mask over the cone, uniformly in ``cos θ`` (i.e. per solid angle).

    Blender's mask is ``smoothstep(0, 1, (cos θ − c) / ((1 − c) · blend))`` with ``c = cos(size/2)``
    (Cycles ``spot_attenuation``, ``intern/cycles/kernel/light/spot.h``). The smoothstep ramp covers a
    fraction ``blend`` of the cone's ``cos θ`` range and averages 1/2 over it (``3t² − 2t³`` integrates
    to 1/2 on [0, 1]), so the mean is ``1 − blend/2``, independent of the cone size.
    """
    return 1.0 - _finite(spot_blend, "spot_blend", low=0.0, high=1.0) / 2.0


def spot_mean_gl(exponent: float, cos_cutoff: float) -> float:
    """Mean of OpenGL's spot factor ``cos(θ)^e`` over the cone, uniformly in ``cos θ`` ∈ [c, 1].

    ``∫_c^1 t^e dt / (1 − c) = (1 − c^(e+1)) / ((e + 1)(1 − c))``.
    """
    e = _finite(exponent, "exponent", low=0.0)
    c = _finite(cos_cutoff, "cos_cutoff", low=0.0, high=1.0)
    if c == 1.0:
        return 1.0
    if c == 0.0:
        return 1.0 / (e + 1.0)
    log_c = math.log(c)
    return -math.expm1((e + 1.0) * log_c) / ((e + 1.0) * -math.expm1(log_c))


def spot_exponent(spot_size: float, spot_blend: float) -> float:
    """OpenGL spot exponent for a Blender spot of cone angle ``spot_size`` (rad) and ``spot_blend``.

    Chosen so that the cone receives the same light: the mean of ``cos(θ)^e`` over the cone
    (:func:`spot_mean_gl`) equals the mean of Blender's smoothstep mask (:func:`spot_mean_blender`),
    solved by bisection to 1e-12. ``blend = 0`` (a hard edge) gives 0.
    """
    cos_c = math.cos(math.radians(spot_cutoff_degrees(spot_size)))
    target = spot_mean_blender(spot_blend)
    if target >= 1.0:
        return 0.0
    lo, hi = 0.0, 1.0
    while spot_mean_gl(hi, cos_c) > target:
        hi *= 2.0
        if hi > 1e12:
            raise ValueError(
                f"spot_size: cone of {spot_size!r} rad is too narrow to match blend {spot_blend!r}"
            )
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if spot_mean_gl(mid, cos_c) > target else (lo, mid)
        if hi - lo <= 1e-12 * max(1.0, hi):
            break
    return 0.5 * (lo + hi)


# --------------------------------------------------------------------------- materials


def roughness_to_shininess(roughness: float) -> float:
    """Blinn-Phong exponent equivalent to a Principled BSDF ``roughness``.

    Blender squares the artist roughness, ``α = roughness²`` (Principled BSDF, GGX/Beckmann width);
    a Blinn-Phong lobe of exponent ``s`` matches a Beckmann lobe of width ``α`` for
    ``s = 2/α² − 2`` (Walter et al. 2007, "Microfacet Models for Refraction", §5.2). Result capped
    at :data:`MAX_SHININESS` (roughness below ≈ 0.119).

    Args:
        roughness: Principled BSDF Roughness in [0, 1].
    """
    r = _finite(roughness, "roughness", low=0.0, high=1.0)
    alpha = r * r
    if alpha * alpha <= 2.0 / (MAX_SHININESS + 2.0):
        return MAX_SHININESS
    return 2.0 / (alpha * alpha) - 2.0


def blinn_phong_from_principled(
    *,
    base_color: tuple[float, float, float],
    metallic: float = 0.0,
    roughness: float = 0.5,
    ior: float = 1.5,
    specular_ior_level: float = 0.5,
    emission_color: tuple[float, float, float] = (0.0, 0.0, 0.0),
    emission_strength: float = 0.0,
    alpha: float = 1.0,
) -> dict[str, object]:
    """Blinn-Phong material values approximating a Principled BSDF (Blender 4.0+ socket set).

    * ``diffuse = ambient = base_color · (1 − metallic)`` (metals have no diffuse lobe);
    * ``F0 = mix(2 · specular_ior_level · ((ior − 1)/(ior + 1))², base_color, metallic)``: the Fresnel
      reflectance at normal incidence, where Specular IOR Level 0.5 leaves the IOR's value unchanged
      (Blender manual, Principled BSDF). ``ior`` is the relative index (inside / outside) and may be
      below 1 (an air bubble in water, 1/1.33 ≈ 0.75): normal-incidence reflectance is symmetric,
      ``F0(n) = F0(1/n)`` (Fresnel equations at θ = 0), so any ``ior > 0`` is accepted;
    * ``shininess`` = :func:`roughness_to_shininess`;
    * ``specular = F0 · (s + 8) / 8``: the energy-normalised Blinn-Phong lobe ``(s + 8)/(8π) · (n·h)^s``
      (Akenine-Möller et al., Real-Time Rendering 3rd ed., eq. 7.49) with the π absorbed by the light
      intensity convention of this module;
    * ``emission = emission_color · emission_strength``, ``opacity = alpha``.

    Returns:
        A dict with keys ``ambient``, ``diffuse``, ``specular``, ``emission`` (RGB tuples),
        ``shininess`` and ``opacity`` (floats), the field names of ``blinn_phong.model.scene.Material``.
    """
    base = np.asarray(base_color, dtype=np.float64)
    emit = np.asarray(emission_color, dtype=np.float64)
    for name, arr in (("base_color", base), ("emission_color", emit)):
        if arr.shape != (3,) or not np.isfinite(arr).all() or (arr < 0).any():
            raise ValueError(f"{name}: expected 3 finite non-negative linear RGB values, got {arr.tolist()}")
    m = _finite(metallic, "metallic", low=0.0, high=1.0)
    n = _finite(ior, "ior", low=0.0, low_open=True)
    level = _finite(specular_ior_level, "specular_ior_level", low=0.0)
    strength = _finite(emission_strength, "emission_strength", low=0.0)
    a = _finite(alpha, "alpha", low=0.0, high=1.0)
    shininess = roughness_to_shininess(roughness)
    f0_dielectric = 2.0 * level * ((n - 1.0) / (n + 1.0)) ** 2
    f0 = (1.0 - m) * f0_dielectric + m * base
    diffuse = base * (1.0 - m)

    def rgb(v: np.ndarray) -> tuple[float, float, float]:
        return (float(v[0]), float(v[1]), float(v[2]))

    return {
        "ambient": rgb(diffuse),
        "diffuse": rgb(diffuse),
        "specular": rgb(f0 * (shininess + 8.0) / 8.0),
        "emission": rgb(emit * strength),
        "shininess": shininess,
        "opacity": a,
    }


# --------------------------------------------------------------------------- depth

BLENDER_EMPTY_DEPTH = 1e10
"""Value of Blender's Depth (Z) pass where nothing was hit (Cycles and EEVEE write 1e10)."""


def window_depth_to_distance(depth: np.ndarray, projection: np.ndarray) -> np.ndarray:
    """Blender's Depth pass (distance along the view axis, positive) from OpenGL window depth.

    Window depth ``d`` in [0, 1] gives ``z_ndc = 2d − 1``; the projection's last two rows give
    ``z_ndc · (P₃₂ z_e + P₃₃) = P₂₂ z_e + P₂₃``, so ``z_e = (P₂₃ − z_ndc P₃₃) / (z_ndc P₃₂ − P₂₂)``
    for perspective and orthographic matrices alike (their third row has no x, y terms). The result
    is ``−z_e``; pixels at depth 1.0 (cleared, nothing drawn) get :data:`BLENDER_EMPTY_DEPTH`.

    Args:
        depth: window depths in [0, 1], any shape.
        projection: (4, 4) eye -> clip matrix the depths were rendered with.

    Returns:
        float32 array of the same shape, in scene units.
    """
    d = np.asarray(depth, dtype=np.float64)
    p = np.asarray(projection, dtype=np.float64)
    if p.shape != (4, 4):
        raise ValueError(f"projection: expected shape (4, 4), got {p.shape}")
    if d.size and (not np.isfinite(d).all() or d.min() < 0.0 or d.max() > 1.0):
        raise ValueError(f"depth: expected finite window depths in [0, 1], got range [{d.min()}, {d.max()}]")
    empty = d >= 1.0
    z_ndc = np.where(empty, 0.0, 2.0 * d - 1.0)
    z_eye = (p[2, 3] - z_ndc * p[3, 3]) / (z_ndc * p[3, 2] - p[2, 2])
    return np.where(empty, BLENDER_EMPTY_DEPTH, -z_eye).astype(np.float32)
