"""Measured error and cost models of the approximate methods, for choosing one by a tolerance.

``calibration.json`` (next to this module) holds models fitted by
:mod:`benchmarks.error_models` to the measurements of ``python -m benchmarks`` (each
approximate method against its exact reference, times as ratios to the exact method
measured in the same run). This module reads them and predicts, for one setting, its error
in **8-bit steps** (1/255 of the unit range) and its time relative to the exact method;
the ``choose_*`` functions return the cheapest setting predicted within a tolerance. The
planner (:func:`blinn_phong.planning.planner.plan`) uses them; nothing here renders.

Models (each states the error metric it predicts):

* ``depth_peeling`` — max error after peeling ``k`` layers. What lies behind them is at
  most ``(1 − α_min)^k`` of the brightest straight radiance ``B`` (every further layer's
  contribution is scaled by the transmittance of the first ``k``), so the error is at most
  ``255·c·B·(1 − α_min)^k`` steps; ``c`` is the largest measured/bound ratio over the
  calibration cases (≤ 1 when the bound holds); predictions use ``max(c, 1)``, the bound
  itself, since other scenes reach it. Cost: the frame fit's ratio (``frame_cost`` below;
  without it ``t₀ + t₁·k`` times the A-buffer's, the resolver alone).
* ``shadow_map`` — mean error of light visibility over the visible points facing the light
  (misclassified share × 255), nearest-texel lookup with bias ``1e-4 + 2·slope``. A
  shadow's edge band is one texel (``D/R`` for a map of resolution ``R`` covering a span
  ``D``) and its area/perimeter ratio about ``f/4`` for a caster whose smallest extent seen
  from the light is ``f``, so the error is ``255·c·s·D/(f·R)`` with ``s`` the shadowed share
  of the points; ``c`` fitted (largest ratio). Its *maximum* is the whole light on a
  misplaced edge, so under the per-pixel tolerance a map is chosen only where the light's
  whole shadowed contribution fits; the mean model picks no resolution, it is reported.
  Calibrated with a directional light. Cost relative to Embree ray tracing for ``N``
  receiver points and ``T`` triangles: ``(m₀ + m₂·R² + m_N·N + m_T·T)/(b₀ + b_N·N + b_T·T)``
  (:func:`shadow_map_cost`).
* ``shading`` — max error on interior pixels of a curved mesh against per-pixel shading of
  the exact surface, per method, as a power law ``a·θ^b`` of the angle ``θ`` between the
  vertex normals at the ends of an edge (``2π/segments`` for a UV sphere), the upper
  envelope of a log-space least-squares fit, times a safety ``margin``. Calibrated at
  shininess 40: valid for shininess ≤ ``shininess_calibrated``. Cost: ``ratio_to_phong``.
* ``frame_cost`` — the frame-aware costs: process CPU seconds of a whole ``render()`` frame
  per transparency method (:func:`transparency_seconds`), per shading method and with fog
  (:func:`frame_seconds`), ``x₀ + x_S·S + x_T·T`` (depth peeling ``+ x_k·k·S``) for ``S``
  samples and ``T`` triangles, fitted to ``render()`` timings: depth peeling, shading and fog
  costs are their ratios (:func:`depth_peeling_cost`, :func:`shading_cost`, :func:`fog_cost`).
* ``shadow_volume`` — exact (no error model). Cost, in seconds, of shadow volumes and of Embree
  ray tracing for ``T`` triangles and ``N`` receiver samples: ``v₀ + v_T·T + v_N·N`` and
  ``r₀ + r_T·T + r_N·N`` (:func:`shadow_volume_cost`), fitted to both methods timed in the
  same run (``benchmarks/results/shadow_volume.json``, ``crossover``): volumes pay a larger
  set-up (building and clipping the volume) and less per sample.
"""

from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from blinn_phong.geometry.normals import max_normal_angle

__all__ = [
    "CALIBRATION_PATH",
    "brightest_radiance",
    "choose_depth_peeling",
    "choose_shading",
    "choose_shadow_map",
    "depth_peeling_cost",
    "depth_peeling_factor",
    "fog_cost",
    "frame_seconds",
    "load",
    "max_normal_angle",
    "predict_depth_peeling",
    "predict_shading",
    "predict_shadow_map",
    "scene_extent",
    "shading_cost",
    "shadow_map_cost",
    "shadow_stage_seconds",
    "shadow_volume_cost",
    "shipped_models",
    "transparency_seconds",
]

#: Real scalars accepted wherever a number is: Python and numpy numbers.
_REAL = (int, float, np.integer, np.floating)

#: The models shipped with the package (written by ``benchmarks/error_models.py``).
CALIBRATION_PATH = Path(__file__).resolve().with_name("calibration.json")

#: Shadow-map resolutions the chooser considers (powers of two).
SHADOW_MAP_RESOLUTIONS = (64, 128, 256, 512, 1024, 2048, 4096)


def load(path: Path | str = CALIBRATION_PATH) -> dict:
    """Read models written by ``benchmarks.error_models.save`` (JSON) from ``path``."""
    return json.loads(Path(path).read_text())


@lru_cache(maxsize=1)
def _shipped() -> str:
    return CALIBRATION_PATH.read_text()


def shipped_models() -> dict:
    """The shipped models (``calibration.json`` next to this module), a fresh copy on each call."""
    return json.loads(_shipped())


def _check_tolerance(tolerance: float) -> float:
    if isinstance(tolerance, bool) or not (
        isinstance(tolerance, _REAL) and math.isfinite(tolerance) and tolerance > 0
    ):
        raise ValueError(f"tolerance: expected a finite number of 8-bit steps > 0, got {tolerance!r}")
    return float(tolerance)


def _check_positive(value: float, name: str) -> float:
    if isinstance(value, bool) or not (isinstance(value, _REAL) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: expected a finite number > 0, got {value!r}")
    return float(value)


# --------------------------------------------------------------------------- scene features


def scene_extent(world_triangles: np.ndarray) -> float:
    """Diameter ``D`` (world units) of the axis-aligned box around world-space triangles ``(n, 3, 3)``."""
    pts = np.asarray(world_triangles, dtype=np.float64).reshape(-1, 3)
    if pts.size == 0 or not np.isfinite(pts).all():
        raise ValueError(f"world_triangles: expected finite (n, 3, 3) triangles, got shape {pts.shape}")
    return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))


def brightest_radiance(fragments_rgba: np.ndarray) -> float:
    """Largest straight colour channel (``rgb/α`` where α > 0) of premultiplied fragments ``(n, 4)``."""
    rgba = np.asarray(fragments_rgba, dtype=np.float64)
    if rgba.ndim != 2 or rgba.shape[1] != 4:
        raise ValueError(f"fragments_rgba: expected shape (n, 4), got {rgba.shape}")
    a = rgba[:, 3:4]
    straight = rgba[:, :3] / np.where(a > 0, a, 1.0)
    return float(straight[a[:, 0] > 0].max(initial=0.0))


# --------------------------------------------------------------------------- depth peeling


def predict_depth_peeling(models: dict, k: int, alpha_min: float, brightest: float) -> float:
    """Predicted max error (8-bit steps) of peeling ``k`` layers: ``255·max(c, 1)·B·(1 − α_min)^k``.

    ``alpha_min`` is the smallest opacity in [0, 1]; ``brightest`` (``B``) bounds the straight
    radiance of what lies behind the peeled layers (≥ 1 when alpha counts: coverage is 1).
    The measured ``c`` (the largest measured/bound ratio, 0.52 on the calibration scenes)
    is the slack those scenes leave; an opaque surface of radiance ``B`` right behind the
    peeled layers reaches the bound itself (``c = 1``, e.g. 0.72 measured in
    ``tests/planning/test_planner.py``), so the prediction never uses less than 1.
    """
    return 255.0 * depth_peeling_factor(models) * brightest * (1.0 - alpha_min) ** k


def depth_peeling_factor(models: dict) -> float:
    """The factor :func:`predict_depth_peeling` applies to the bound: ``max(c, 1)``, ``c`` measured."""
    return max(float(models["depth_peeling"]["c"]), 1.0)


def depth_peeling_cost(models: dict, k: int, samples: int | None = None, triangles: int = 0) -> float:
    """Predicted time of peeling ``k`` layers relative to the A-buffer's.

    With the frame fit (``frame_cost`` in the models): the whole frame's, by
    :func:`transparency_seconds` for ``samples`` (``width·height·samples``; None: the fit's
    median frame) and ``triangles``. Without it, ``t₀ + t₁·k`` (the resolver alone on the
    calibration fragments).
    """
    if "frame_cost" in models:
        peel = transparency_seconds(models, "depth_peeling", samples, triangles, k)
        return peel / transparency_seconds(models, "a_buffer", samples, triangles)
    m = models["depth_peeling"]
    return m["t0"] + m["t1"] * k


def _samples_or_default(models: dict, samples: int | None) -> int:
    if samples is None:
        return int(models["frame_cost"]["samples_median"])
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or samples < 0:
        raise ValueError(f"samples: expected an integer >= 0, got {samples!r}")
    return int(samples)


def _linear(
    models: dict, kind: str, name: str, samples: int | None, triangles: int, layers: int = 0
) -> float:
    table = models["frame_cost"][kind]
    if name not in table:
        raise ValueError(f"method: expected one of {sorted(table)}, got {name!r}")
    if isinstance(triangles, bool) or not isinstance(triangles, int | np.integer) or triangles < 0:
        raise ValueError(f"triangles: expected an integer >= 0, got {triangles!r}")
    s = _samples_or_default(models, samples)
    c = table[name]
    return c[0] + c[1] * s + c[2] * int(triangles) + (c[3] * layers * s if len(c) > 3 else 0.0)


def transparency_seconds(
    models: dict, method: str, samples: int | None = None, triangles: int = 0, layers: int = 1
) -> float:
    """Predicted process CPU seconds of a ``render()`` frame resolving transparency by ``method``.

    ``x₀ + x_S·S + x_T·T`` per method (``a_buffer``, ``draw_last``, ``sort_objects``), plus
    ``x_k·layers·S`` for ``depth_peeling``; ``S`` samples (``width·height·samples``), ``T``
    triangles. Fitted by :mod:`benchmarks.error_models` to the ``frame_costs`` family
    (``render()`` of the transparency calibration scenes and the frame benchmark's scene at two
    sizes each, every method timed in the same run): the ratios, not the seconds, carry over to
    other machines.
    """
    return _linear(models, "transparency", method, samples, triangles, layers)


def frame_seconds(models: dict, variant: str, samples: int | None = None, triangles: int = 0) -> float:
    """Predicted process CPU seconds of a whole ``render()`` frame without shadows: ``x₀ + x_S·S + x_T·T``.

    ``variant``: ``phong``, ``gouraud``, ``flat`` (the shading of every mesh) or ``fog``
    (Phong with exp fog); ``S`` samples (``width·height·samples``), ``T`` triangles. Fitted to
    the ``frame_costs`` family (see :func:`transparency_seconds`).
    """
    return _linear(models, "frame", variant, samples, triangles)


def fog_cost(models: dict, samples: int | None = None, triangles: int = 0) -> float | None:
    """Predicted time of a frame with fog relative to the same frame without (:func:`frame_seconds`);
    None without the frame fit."""
    if "frame_cost" not in models:
        return None
    return frame_seconds(models, "fog", samples, triangles) / frame_seconds(
        models, "phong", samples, triangles
    )


def shading_cost(models: dict, method: str, samples: int | None = None, triangles: int = 0) -> float:
    """Predicted time of a frame shaded by ``method`` relative to Phong's (:func:`frame_seconds`
    when the frame fit exists, else the calibration sphere's measured ``ratio_to_phong``)."""
    if "frame_cost" in models:
        return frame_seconds(models, method, samples, triangles) / frame_seconds(
            models, "phong", samples, triangles
        )
    return float(models["shading"]["methods"][method]["ratio_to_phong"])


def choose_depth_peeling(
    models: dict,
    tolerance: float,
    alpha_min: float,
    brightest: float,
    max_layers: int,
    samples: int | None = None,
    triangles: int = 0,
) -> dict:
    """The fewest layers predicted within ``tolerance`` and faster than the A-buffer, else the A-buffer.

    Args:
        models: from :func:`load` or :func:`shipped_models`.
        tolerance: acceptable max error in 8-bit steps (> 0).
        alpha_min: smallest opacity of the transparent surfaces, in (0, 1].
        brightest: bound of the straight radiance behind the peeled layers (≥ 0).
        max_layers: an upper bound of the depth complexity (peeling that many is exact).
        samples: the frame's samples ``width·height·samples`` for the cost model (None: the
            fit's median frame).
        triangles: the scene's triangles, for the cost model.

    Returns:
        ``{"method": "depth_peeling", "layers": k, "predicted_steps", "predicted_cost"}`` or
        ``{"method": "a_buffer", "predicted_steps": 0.0, "predicted_cost": 1.0}``; costs are
        relative to the A-buffer.
    """
    tol = _check_tolerance(tolerance)
    if isinstance(alpha_min, bool) or not (isinstance(alpha_min, _REAL) and 0 < alpha_min <= 1):
        raise ValueError(f"alpha_min: expected a value in (0, 1], got {alpha_min!r}")
    if isinstance(brightest, bool) or not (
        isinstance(brightest, _REAL) and math.isfinite(brightest) and brightest >= 0
    ):
        raise ValueError(f"brightest: expected a finite radiance >= 0, got {brightest!r}")
    for k in range(1, max_layers):
        cost = depth_peeling_cost(models, k, samples, triangles)
        if cost >= 1.0:
            break
        err = predict_depth_peeling(models, k, alpha_min, brightest)
        if err <= tol:
            return {"method": "depth_peeling", "layers": k, "predicted_steps": err, "predicted_cost": cost}
    return {"method": "a_buffer", "predicted_steps": 0.0, "predicted_cost": 1.0}


# --------------------------------------------------------------------------- shadow maps


def predict_shadow_map(
    models: dict, resolution: int, span: float, caster_size: float, shadowed_share: float = 0.5
) -> float:
    """Predicted mean visibility error (8-bit steps) of a nearest-texel map: ``255·c·s·D/(f·R)``.

    ``span`` (``D``, the side of the square the map covers) and ``caster_size`` (``f``, the
    smallest extent of a caster seen from the light, see :func:`blinn_phong.planning.planner.plan`)
    in world units; ``shadowed_share`` (``s``) the share of lit-side points in shadow, in
    [0, 1]. A shadow's edge band is one texel ``D/R`` wide and its area/perimeter ratio is
    about ``f/4`` (``f/4`` for a disc of diameter ``f``, ``f/2`` for a long strip of width
    ``f``), so the misclassified share of the shadowed points is about ``c·D/(f·R)``.
    """
    return 255.0 * models["shadow_map"]["c"] * shadowed_share * span / (caster_size * resolution)


def shadow_stage_seconds(
    models: dict,
    method: str,
    samples: int,
    triangles: int,
    traced_share: float = 1.0,
    resolution: int = 0,
) -> float | None:
    """Predicted ``shadows``-stage seconds of one light in a compiled ``render()`` frame; None
    without the frame-stage fit.

    ``x₀ + x_S·S + x_T·T`` per method, plus ``x_f·f·S`` for ``ray_traced`` (``f`` the traced
    share, :func:`blinn_phong.planning.planner.traced_share`) and ``x_R·R²`` for ``shadow_map``; ``S``
    samples, ``T`` triangles. Fitted by :mod:`benchmarks.error_models` to the ``frame_costs``
    family's shadow rows (the BVH and the volumes built in every frame): ratios carry over to
    other machines, seconds do not.
    """
    if not (0.0 <= traced_share <= 1.0):
        raise ValueError(f"traced_share: expected a value in [0, 1], got {traced_share!r}")
    table = models.get("frame_cost", {}).get("shadows")
    if table is None or method not in table:
        return None
    c = table[method]
    value = c[0] + c[1] * samples + c[2] * triangles
    if method == "ray_traced":
        value += c[3] * traced_share * samples
    elif method == "shadow_map":
        value += c[3] * resolution**2
    return float(value)


def shadow_map_cost(
    models: dict,
    resolution: int,
    receivers: int | None = None,
    triangles: int | None = None,
    traced_share: float | None = None,
) -> float:
    """Predicted time of a ``resolution``² shadow map relative to Embree ray tracing.

    With the frame-aware fit in seconds over two triangle counts (``mt``, ``bt`` present):
    ``(m0 + m2·R² + mn·N + mt·T)/(b0 + bn·N + bt·T)`` for ``N = receivers`` points and
    ``T = triangles`` (rasterizing the map's triangles; building Embree's BVH, which ``render``
    reuses while the same triangles come back — the model charges it to every frame, as for
    a first frame or an animation). The former single-scene fit:
    ``(m0 + m2·R² + mn·N)/(b0·τ + bn·N)`` for ``N = receivers``
    points, with ``τ = triangles/triangles_calibrated`` (the ray tracer's scene build) —
    set-up, rasterization and one lookup per receiver against the scene build and one ray
    per receiver. Unknown arguments take the calibration scene's values. The rasterization
    term is the calibration scene's: scenes of many long thin triangles across the light's
    view rasterize slower (24 slats, 12k receivers: measured 2.6–3.9× ray tracing at 128² on a
    loaded machine, predicted 1.8×).
    Without that fit, ``t₀ + t₂·R²``.

    ``traced_share`` (a frame of the compiled engine, see :func:`shadow_volume_cost`): with the
    frame-stage fit, the ratio of the two stage predictions (:func:`shadow_stage_seconds`).
    """
    m = models["shadow_map"]
    if "m0" not in m:
        return m["t0"] + m["t2"] * resolution**2
    n = m["receivers"] if receivers is None else receivers
    if traced_share is not None and triangles is not None:
        stage_map = shadow_stage_seconds(models, "shadow_map", n, triangles, resolution=resolution)
        stage_ray = shadow_stage_seconds(models, "ray_traced", n, triangles, traced_share)
        if stage_map is not None and stage_ray is not None and stage_ray > 0:
            return stage_map / stage_ray
    if "mt" in m:
        t = m["triangles"] if triangles is None else triangles
        return (m["m0"] + m["m2"] * resolution**2 + m["mn"] * n + m["mt"] * t) / (
            m["b0"] + m["bn"] * n + m["bt"] * t
        )
    tau = 1.0 if triangles is None else triangles / m["triangles"]
    return (m["m0"] + m["m2"] * resolution**2 + m["mn"] * n) / (m["b0"] * tau + m["bn"] * n)


def choose_shadow_map(
    models: dict,
    tolerance: float,
    span: float,
    caster_size: float,
    shadowed_share: float = 1.0,
    weight: float = 1.0,
    *,
    receivers: int | None = None,
    triangles: int | None = None,
    traced_share: float | None = None,
) -> dict:
    """The cheapest power-of-two map (64–4096) that resolves every caster and is faster than ray tracing.

    A map is a candidate when its texel ``span/R`` is at most half of ``caster_size`` (no
    caster falls between texel centres) and, with the tolerance a per-pixel maximum, when the
    largest change a misplaced edge makes, ``255·weight`` (``weight`` ≥ 0: the largest change
    of a pixel, in the unit range, between lit and shadowed), is within ``tolerance``. The
    cheapest candidate predicted faster than ray tracing (:func:`shadow_map_cost` for
    ``receivers`` points and the scene's ``triangles``) is returned.

    Returns:
        ``{"method": "shadow_map", "resolution", "predicted_steps" (the per-pixel bound
        255·weight), "predicted_mean" (:func:`predict_shadow_map` × weight), "predicted_cost"}``
        or ``{"method": "ray_traced", "predicted_steps": 0.0, "predicted_cost": 1.0}``.
    """
    tol = _check_tolerance(tolerance)
    _check_positive(span, "span")
    _check_positive(caster_size, "caster_size")
    if not (0 <= shadowed_share <= 1):
        raise ValueError(f"shadowed_share: expected a value in [0, 1], got {shadowed_share!r}")
    if not (math.isfinite(weight) and weight >= 0):
        raise ValueError(f"weight: expected a finite number >= 0, got {weight!r}")
    exact = {"method": "ray_traced", "predicted_steps": 0.0, "predicted_cost": 1.0}
    if 255.0 * weight > tol:
        return exact
    for res in SHADOW_MAP_RESOLUTIONS:
        if span / res > caster_size / 2:
            continue
        cost = shadow_map_cost(models, res, receivers, triangles, traced_share)
        if cost >= 1.0:
            break
        mean = weight * predict_shadow_map(models, res, span, caster_size, shadowed_share)
        return {
            "method": "shadow_map",
            "resolution": res,
            "predicted_steps": 255.0 * weight,
            "predicted_mean": mean,
            "predicted_cost": cost,
        }
    return exact


# --------------------------------------------------------------------------- shadow volumes


def shadow_volume_cost(
    models: dict, triangles: int, receivers: int, traced_share: float | None = None
) -> dict | None:
    """Predicted times (seconds) of the two exact hard-shadow methods for one light.

    Args:
        models: from :func:`load` or :func:`shipped_models`.
        triangles: ``T``, triangles in the scene (≥ 0).
        receivers: ``N``, receiver samples of the frame (``width·height·samples``, ≥ 0).
        traced_share: in a frame of the compiled engine, the share ``f`` of the receivers whose
            shadow rays :mod:`blinn_phong.shadows.ray_culling` leaves to Embree (None: every ray traced).
            Given, and with the frame-stage fit, the two methods' ``shadows``-stage predictions
            (:func:`shadow_stage_seconds`) replace the per-call fit below.

    Returns:
        ``{"shadow_volume": v₀ + v_T·T + v_N·N, "ray_traced": r₀ + r_T·T + r_N·N,
        "ratio": volumes / ray tracing}``, or None when the models have no ``shadow_volume``
        entry. The fit is of one sphere over a plane under a point light on a loaded machine:
        the ratio, not the seconds, carries over to other machines.
    """
    m = models.get("shadow_volume")
    if m is None:
        return None
    for name, value in (("triangles", triangles), ("receivers", receivers)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
            raise ValueError(f"{name}: expected an integer >= 0, got {value!r}")
    if traced_share is not None:
        volume = shadow_stage_seconds(models, "shadow_volume", receivers, triangles)
        traced = shadow_stage_seconds(models, "ray_traced", receivers, triangles, traced_share)
        if volume is not None and traced is not None and traced > 0:
            return {"shadow_volume": volume, "ray_traced": traced, "ratio": volume / traced}
    volume = m["v0"] + m["vt"] * triangles + m["vn"] * receivers
    traced = m["r0"] + m["rt"] * triangles + m["rn"] * receivers
    return {"shadow_volume": volume, "ray_traced": traced, "ratio": volume / traced}


# --------------------------------------------------------------------------- shading frequency


def predict_shading(models: dict, method: str, theta: float) -> float:
    """Predicted interior max error (8-bit steps) of ``method`` against the exact surface: ``margin·a·θ^b``.

    ``theta`` is :func:`max_normal_angle` in radians.
    """
    shading = models["shading"]
    if method not in shading["methods"]:
        raise ValueError(f"method: expected one of {sorted(shading['methods'])}, got {method!r}")
    m = shading["methods"][method]
    return shading.get("margin", 1.0) * m["a"] * theta ** m["b"]


def choose_shading(
    models: dict, tolerance: float, theta: float, samples: int | None = None, triangles: int = 0
) -> dict:
    """The cheapest of flat/Gouraud predicted within ``tolerance`` steps and faster than Phong, else Phong.

    Costs by :func:`shading_cost` for the frame's ``samples`` (``width·height·samples``) and
    ``triangles``.

    Returns:
        ``{"method", "predicted_steps", "predicted_cost"}``, the cost relative to Phong's.
    """
    tol = _check_tolerance(tolerance)
    cost = {name: shading_cost(models, name, samples, triangles) for name in ("flat", "gouraud")}
    for method in sorted(("flat", "gouraud"), key=lambda name: cost[name]):
        err = predict_shading(models, method, theta)
        if err <= tol and cost[method] < 1.0:
            return {
                "method": method,
                "predicted_steps": err,
                "predicted_cost": cost[method],
            }
    return {
        "method": "phong",
        "predicted_steps": predict_shading(models, "phong", theta),
        "predicted_cost": 1.0,
    }
