"""Error and cost models fitted to the tradeoff measurements, for choosing methods by tolerance.

:func:`fit` reads the measurements of :mod:`benchmarks.tradeoffs` and returns small JSON
models; :func:`save` writes them to ``blinn_phong/calibration.json`` where the renderer's
planner can read them without importing the benchmarks. The ``choose_*`` functions take
a tolerance in **8-bit steps** and return the cheapest setting predicted to stay within it.

Models (each states the error metric it predicts, all in 8-bit steps):

* ``depth_peeling`` — max error after peeling ``k`` layers: what lies behind them is at
  most ``(1 − α_min)^k`` of the brightest transparent radiance ``B`` (the planner's bound),
  ``255·c·B·(1 − α_min)^k``; ``c`` is the largest measured/bound ratio over the
  calibration cases (≤ 1 if the bound holds). Cost: seconds ≈ ``t₀ + t₁·k`` relative to
  the A-buffer, least squares.
* ``shadow_map`` — mean error over the visible lit-side points (the share of points
  misclassified × 255): a shadow's edge band is one texel (``D/R`` for a map of
  resolution ``R`` over a scene of diameter ``D``) and its area/perimeter ratio about
  ``r/2`` for a caster of radius ``r``, so the error is ``255·c·s·D/(r·R)`` with ``s`` the
  shadowed share of the points; ``c`` fitted (largest ratio) on the calibration scene.
  Cost: seconds ≈ ``t₀ + t₂·R²`` relative to ray tracing.
* ``shading`` — max error on interior pixels of a curved mesh against per-pixel shading
  of the exact surface, per method, as a power law ``a·θ^b`` of the angle ``θ`` between
  adjacent vertex normals (``2π/segments`` for a UV sphere), fitted in log space; the
  prediction uses the upper envelope (the fit times its largest residual factor) times
  :data:`SHADING_MARGIN`. Calibrated on shininess 40 only: valid for shininess ≤ 40.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

__all__ = [
    "CALIBRATION_PATH",
    "brightest_radiance",
    "choose_depth_peeling",
    "choose_shading",
    "choose_shadow_map",
    "fit",
    "load",
    "max_normal_angle",
    "plan_within",
    "predict_depth_peeling",
    "predict_shading",
    "predict_shadow_map",
    "save",
    "scene_extent",
]

CALIBRATION_PATH = Path(__file__).resolve().parent.parent / "blinn_phong" / "calibration.json"

#: Safety factor on the shading envelope for scenes other than the calibration sphere (other
#: lights, views, shininess ≤ 40): the fit has one light and one view, so its largest
#: residual under-covers new ones; 1.5 is half an octave of slack on a power law.
SHADING_MARGIN = 1.5


def _check_tolerance(tolerance: float) -> float:
    if not (isinstance(tolerance, int | float) and math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance: expected a finite number of 8-bit steps > 0, got {tolerance!r}")
    return float(tolerance)


# --------------------------------------------------------------------------- scene features


def scene_extent(world_triangles: np.ndarray) -> float:
    """Diameter ``D`` of the axis-aligned box around world-space triangles ``(n, 3, 3)`` (world units)."""
    pts = np.asarray(world_triangles, dtype=np.float64).reshape(-1, 3)
    if pts.size == 0 or not np.isfinite(pts).all():
        raise ValueError(f"world_triangles: expected finite (n, 3, 3) triangles, got shape {pts.shape}")
    return float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))


def max_normal_angle(normals: np.ndarray, triangles: np.ndarray) -> float:
    """Largest angle (radians) between the vertex normals at the two ends of any triangle edge."""
    n = np.asarray(normals, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    if n.ndim != 2 or n.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(f"normals (V, 3) and triangles (T, 3) expected, got {n.shape} and {t.shape}")
    unit = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    worst = 0.0
    for a, b in ((0, 1), (1, 2), (2, 0)):
        cos = np.einsum("ij,ij->i", unit[t[:, a]], unit[t[:, b]])
        worst = max(worst, float(np.arccos(np.clip(cos, -1.0, 1.0)).max(initial=0.0)))
    return worst


# --------------------------------------------------------------------------- fitting


def brightest_radiance(fragments_rgba: np.ndarray) -> float:
    """Largest straight colour channel of premultiplied fragments ``(n, 4)`` (``rgb/α`` where α > 0)."""
    rgba = np.asarray(fragments_rgba, dtype=np.float64)
    a = rgba[:, 3:4]
    straight = rgba[:, :3] / np.where(a > 0, a, 1.0)
    return float(straight[a[:, 0] > 0].max(initial=0.0))


def _fit_depth_peeling(data: dict) -> dict:
    from benchmarks.tradeoffs import layered_scene, transparent_fragments

    size = data["size"][0]
    brightest: dict[tuple[int, float], float] = {}
    ratios, xs, ys = [], [], []
    for case in data["cases"]:
        if case["method"] != "depth_peeling":
            continue
        k, alpha = case["peel_layers"], case["opacity"]
        if k >= case["layers"]:
            continue  # exact: every layer peeled
        key = (case["layers"], alpha)
        if key not in brightest:
            brightest[key] = brightest_radiance(transparent_fragments(layered_scene(*key), size)["rgba"])
        bound = 255.0 * brightest[key] * (1.0 - alpha) ** k
        ratios.append(case["max_steps"] / bound)
        xs.append(k)
        ys.append(case["ratio_to_a_buffer"])
    t1, t0 = np.polyfit(xs, ys, 1)
    return {
        "error": "max_steps <= 255 * c * brightest * (1 - alpha_min) ** k",
        "c": max(ratios),
        "cases": len(ratios),
        "cost": "ratio_to_a_buffer ~= t0 + t1 * k",
        "t0": float(t0),
        "t1": float(t1),
    }


def _fit_shadow_map(data: dict, diameter: float, caster_radius: float) -> dict:
    ratios, res, cost = [], [], []
    shadowed = data["shadowed_share"]
    for case in data["cases"]:
        if (
            case["method"] != "shadow_map"
            or case["kernel"] != "nearest"
            or case["bias"] != "bias 1e-4 + 2·slope"
        ):
            continue
        bound = 255.0 * shadowed * diameter / (caster_radius * case["resolution"])
        ratios.append(case["mean_steps"] / bound)
        res.append(case["resolution"])
        cost.append(case["ratio_to_ray_traced"])
    x = np.asarray(res, float) ** 2
    t2, t0 = np.polyfit(x, cost, 1)
    return {
        "error": "mean_steps <= 255 * c * shadowed_share * diameter / (caster_radius * resolution)",
        "kernel": "nearest",
        "constant_bias": 1e-4,
        "slope_bias": 2.0,
        "c": max(ratios),
        "cases": len(ratios),
        "cost": "ratio_to_ray_traced ~= t0 + t2 * resolution**2",
        "t0": float(t0),
        "t2": float(t2),
    }


def _fit_shading(data: dict) -> dict:
    out: dict[str, dict] = {}
    for method in ("flat", "gouraud", "phong"):
        rows = [c for c in data["cases"] if c["method"] == method]
        theta = np.array([2 * math.pi / c["segments"] for c in rows])
        err = np.array([max(c["interior"]["max_steps"], 1e-3) for c in rows])
        b, log_a = np.polyfit(np.log(theta), np.log(err), 1)
        envelope = float(np.max(err / (math.exp(log_a) * theta**b)))
        out[method] = {
            "a": float(math.exp(log_a)) * envelope,
            "b": float(b),
            "ratio_to_phong": float(np.median([c["ratio_to_phong"] for c in rows])),
            "theta_range": [float(theta.min()), float(theta.max())],
        }
    return {
        "error": "interior max_steps <= margin * a * theta ** b, theta: max angle of adjacent vertex normals",
        "margin": SHADING_MARGIN,
        "shininess_calibrated": 40.0,
        "methods": out,
    }


def fit(tradeoffs: dict) -> dict:
    """Fit every model to a ``tradeoffs.json`` document (``{"families": {...}}``)."""
    from benchmarks.tradeoffs import shadow_scene
    from blinn_phong.raytrace import world_triangles

    families = tradeoffs["families"]
    models: dict[str, object] = {
        "units": "8-bit steps (1/255 of the unit range)",
        "source": "python -m benchmarks",
    }
    if "transparency" in families:
        models["depth_peeling"] = _fit_depth_peeling(families["transparency"])
    if "shadows" in families:
        tris, _ = world_triangles(shadow_scene())
        # the smallest caster: the sphere of radius 0.7 (the box's bounding radius is 0.73)
        models["shadow_map"] = _fit_shadow_map(families["shadows"], scene_extent(tris), 0.7)
    if "shading" in families:
        models["shading"] = _fit_shading(families["shading"])
    return models


def save(models: dict, path: Path = CALIBRATION_PATH) -> Path:
    """Write the models as JSON."""
    path.write_text(json.dumps(models, indent=1) + "\n")
    return path


def load(path: Path = CALIBRATION_PATH) -> dict:
    """Read the models written by :func:`save`."""
    return json.loads(Path(path).read_text())


# --------------------------------------------------------------------------- predictions and choices


def predict_depth_peeling(models: dict, k: int, alpha_min: float, brightest: float) -> float:
    """Predicted max error (8-bit steps) of peeling ``k`` layers; ``brightest`` is a straight radiance."""
    m = models["depth_peeling"]
    return 255.0 * m["c"] * brightest * (1.0 - alpha_min) ** k


def choose_depth_peeling(
    models: dict, tolerance: float, alpha_min: float, brightest: float, max_layers: int
) -> dict:
    """The fewest peeled layers predicted within ``tolerance`` steps, or the A-buffer when none is cheaper.

    Args:
        models: from :func:`load`.
        tolerance: acceptable max error in 8-bit steps (> 0).
        alpha_min: smallest opacity of the transparent surfaces, in (0, 1].
        brightest: largest straight radiance a transparent surface can reach (≥ 0).
        max_layers: an upper bound of the depth complexity (peeling that many is exact).

    Returns:
        ``{"method": "depth_peeling", "layers": k, "predicted_steps", "predicted_cost"}`` or
        ``{"method": "a_buffer", ...}``.
    """
    tol = _check_tolerance(tolerance)
    if not 0 < alpha_min <= 1:
        raise ValueError(f"alpha_min: expected a value in (0, 1], got {alpha_min!r}")
    m = models["depth_peeling"]
    for k in range(1, max_layers):
        err = predict_depth_peeling(models, k, alpha_min, brightest)
        cost = m["t0"] + m["t1"] * k
        if err <= tol and cost < 1.0:
            return {"method": "depth_peeling", "layers": k, "predicted_steps": err, "predicted_cost": cost}
        if cost >= 1.0:
            break
    return {"method": "a_buffer", "predicted_steps": 0.0, "predicted_cost": 1.0}


def predict_shadow_map(
    models: dict, resolution: int, diameter: float, caster_radius: float, shadowed_share: float = 0.5
) -> float:
    """Predicted mean error (8-bit steps) of a nearest-texel shadow map of ``resolution``."""
    m = models["shadow_map"]
    return 255.0 * m["c"] * shadowed_share * diameter / (caster_radius * resolution)


def choose_shadow_map(
    models: dict, tolerance: float, diameter: float, caster_radius: float, shadowed_share: float = 0.5
) -> dict:
    """The smallest power-of-two map (64–4096) predicted within ``tolerance`` mean steps, else ray tracing.

    ``shadowed_share`` (the share of visible points in shadow, ≤ 1) defaults to 0.5, which
    over-predicts for scenes that are mostly lit.
    """
    tol = _check_tolerance(tolerance)
    m = models["shadow_map"]
    for res in (64, 128, 256, 512, 1024, 2048, 4096):
        err = predict_shadow_map(models, res, diameter, caster_radius, shadowed_share)
        if err <= tol:
            cost = m["t0"] + m["t2"] * res**2
            if cost < 1.0:
                return {
                    "method": "shadow_map",
                    "resolution": res,
                    "predicted_steps": err,
                    "predicted_cost": cost,
                }
            break
    return {"method": "ray_traced", "predicted_steps": 0.0, "predicted_cost": 1.0}


def predict_shading(models: dict, method: str, theta: float) -> float:
    """Predicted interior max error (8-bit steps) of ``method``; ``theta`` is :func:`max_normal_angle`."""
    m = models["shading"]["methods"][method]
    return models["shading"].get("margin", 1.0) * m["a"] * theta ** m["b"]


def choose_shading(models: dict, tolerance: float, theta: float) -> dict:
    """The cheapest of flat/Gouraud predicted within ``tolerance`` steps, else Phong (the reference)."""
    tol = _check_tolerance(tolerance)
    methods = models["shading"]["methods"]
    for method in sorted(("flat", "gouraud"), key=lambda name: methods[name]["ratio_to_phong"]):
        err = predict_shading(models, method, theta)
        if err <= tol and methods[method]["ratio_to_phong"] < 1.0:
            return {
                "method": method,
                "predicted_steps": err,
                "predicted_cost": methods[method]["ratio_to_phong"],
            }
    return {
        "method": "phong",
        "predicted_steps": predict_shading(models, "phong", theta),
        "predicted_cost": 1.0,
    }


def plan_within(scene: object, tolerance_steps: float, models: dict | None = None) -> object:
    """A :class:`blinn_phong.planner.Plan` whose choices are the fastest predicted within ``tolerance_steps``.

    The planner's own tolerance is in linear radiance for transparency (what depth peeling
    leaves out) and in misclassified share of the shadowed area for shadow maps; the
    calibrated models convert a tolerance in 8-bit steps into each: depth peeling's measured
    max error is ``c·255`` times the planner's bound, so the planner gets ``T/(255·c)``; a
    shadow map's measured mean error is ``255·c·s/2`` times the planner's area share (its
    bound is ``2·D/(r·R)``, ours ``c·s·D/(r·R)`` with the shadowed share ``s`` ≤ 1), so it gets
    ``2·T/(255·c)``. The cost models then replace a choice by the exact method when that is
    predicted to be faster (depth peeling against the A-buffer, a shadow map against ray tracing).
    Shading: flat or Gouraud where predicted within the tolerance and cheaper, else the planner's.

    Args:
        scene: a :class:`blinn_phong.Scene`.
        tolerance_steps: acceptable error in 8-bit steps (> 0): the max error of the
            transparency resolve, the mean error of shadow visibility (a hard shadow edge is
            255 steps off at some point for any map), the max error of shading.
        models: from :func:`load` (default: ``blinn_phong/calibration.json``).

    Returns:
        The plan; every replaced choice says why in its reason.
    """
    from blinn_phong.normals import vertex_normals
    from blinn_phong.planner import Choice, Plan, plan

    tol = _check_tolerance(tolerance_steps)
    m = models if models is not None else load()
    peel, smap = m["depth_peeling"], m["shadow_map"]
    transparency = plan(scene, tolerance=tol / (255.0 * peel["c"])).transparency
    if transparency.method == "depth_peeling":
        k = int(transparency.params["layers"])
        cost = peel["t0"] + peel["t1"] * k
        if cost >= 1.0:
            transparency = Choice("a_buffer", f"{k} peeled layers would cost {cost:.2f}× the exact A-buffer")
        else:
            transparency = Choice(
                "depth_peeling",
                f"{transparency.reason}; calibrated: ≤ {tol:g} steps, about {cost:.2f}× the A-buffer's time",
                dict(transparency.params),
            )
    shadows = []
    for choice in plan(scene, tolerance=2.0 * tol / (255.0 * smap["c"])).shadows:
        if choice.method == "shadow_map":
            res = int(choice.params["resolution"])
            cost = smap["t0"] + smap["t2"] * res**2
            if cost >= 1.0:
                choice = Choice(
                    "ray_traced",
                    f"a {res}² map would be within {tol:g} mean steps but cost {cost:.2f}× ray tracing",
                )
        shadows.append(choice)
    base = plan(scene)
    shading = []
    for mesh, choice in zip(scene.meshes, base.shading, strict=True):  # type: ignore[attr-defined]
        if choice.method == "phong" and mesh.shading is None and len(mesh.triangles):
            normals = (
                mesh.normals if mesh.normals is not None else vertex_normals(mesh.positions, mesh.triangles)
            )
            pick = choose_shading(m, tol, max_normal_angle(normals, mesh.triangles))
            if pick["method"] != "phong":
                choice = Choice(
                    pick["method"],
                    f"calibrated: predicted {pick['predicted_steps']:.3g} ≤ {tol:g} steps at "
                    f"{pick['predicted_cost']:.2f}× Phong's time",
                )
        shading.append(choice)
    return Plan(transparency, tuple(shadows), tuple(shading), tol)


def main() -> None:
    """Fit the models to ``benchmarks/results/tradeoffs.json`` and write ``blinn_phong/calibration.json``."""
    source = Path(__file__).resolve().parent / "results" / "tradeoffs.json"
    path = save(fit(json.loads(source.read_text())))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
