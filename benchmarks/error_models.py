"""Fitting the error and cost models of ``blinn_phong/planning/calibration.json`` to the tradeoff
measurements.

:func:`fit` reads the measurements of :mod:`benchmarks.tradeoffs` and returns small JSON
models; :func:`save` writes them to ``blinn_phong/planning/calibration.json``, shipped with the
package, where :mod:`blinn_phong.planning.calibration` reads them (the predictions and the
``choose_*`` functions live there, one definition used by the planner, the tests and this
module). Each model and the error metric it predicts, in 8-bit steps:

* ``depth_peeling`` — max error after peeling ``k`` layers, ``255·c·B·(1 − α_min)^k``;
  ``c`` is the largest measured/bound ratio over the calibration cases, ``B`` the
  brightest straight radiance of the transparent fragments. Cost ``t₀ + t₁·k`` relative
  to the A-buffer, least squares.
* ``shadow_map`` — mean visibility error over the visible lit-side points,
  ``255·c·s·D/(f·R)`` (``s`` shadowed share, ``D`` the map's span, ``f`` the thinnest caster
  seen from the light, both as the planner computes them, ``R`` resolution); ``c`` the
  largest ratio on the calibration scene. Cost relative to ray tracing: ``t₀ + t₂·R²`` at
  the calibration scene's receiver count, and the frame-aware
  ``(m₀ + m₂·R² + m_N·N + m_T·T)/(b₀ + b_N·N + b_T·T)`` fitted (non-negative least squares,
  in seconds, fastest rounds) to the times measured at several receiver counts ``N`` and two
  triangle counts ``T`` (rasterizing the map; building the ray tracer's BVH).
* ``shading`` — interior max error of flat/Gouraud/Phong against per-pixel shading of the
  exact surface, a power law ``a·θ^b`` of the largest angle between adjacent vertex
  normals fitted in log space; ``a`` is the upper envelope (the fit times its largest
  residual factor) and :data:`SHADING_MARGIN` is stored with it. Calibrated at shininess 40.
* ``frame_cost`` — the frame-aware costs from whole ``render()`` timings (the ``frame_costs``
  family): process CPU seconds of a frame per transparency method, per shading method and
  with fog, ``x₀ + x_S·S + x_T·T`` (depth peeling ``+ x_k·k·S``; ``S`` samples
  ``width·height·samples``, ``T`` triangles); non-negative least squares on unit-norm columns.
* ``shadow_volume`` — no error model (exact, like ray tracing); its cost against Embree ray
  tracing, both in seconds, ``v₀ + v_T·T + v_N·N`` and ``r₀ + r_T·T + r_N·N`` for ``T``
  triangles and ``N`` receiver samples, least squares (unit-norm columns, non-negative) on the
  ``crossover`` rows of ``benchmarks/results/shadow_volume.json``
  (:mod:`benchmarks.bench_shadow_volume`: both methods timed in the same run). Where the rows
  have cold timings (``*_cold_s``: the volumes' per-mesh caches cleared and Embree's BVH built
  in the timed call) those are fitted, since a frame of a new scene pays both, as the other
  shadow cost models assume.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from blinn_phong.planning.calibration import CALIBRATION_PATH, brightest_radiance, load
from blinn_phong.planning.planner import MapGeometry
from compositing._atomic import write_json_atomic

__all__ = [
    "CALIBRATION_PATH",
    "SHADING_MARGIN",
    "fit",
    "fit_results",
    "frame_cost_designs",
    "load",
    "main",
    "save",
    "shadow_stage_designs",
    "shadow_volume_cost_design",
]

#: Safety factor on the shading envelope for scenes other than the calibration sphere (other
#: lights, views, shininess ≤ 40): the fit has one light and one view, so its largest
#: residual under-covers new ones; 1.5 is half an octave of slack on a power law.
SHADING_MARGIN = 1.5


# --------------------------------------------------------------------------- fitting


def _fit_depth_peeling(data: dict) -> dict:
    from testbeds.tradeoff_scenes import layered_scene, transparent_fragments

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


def frame_cost_design(rows: list[dict]) -> np.ndarray:
    """Design matrix of the frame-aware shadow cost fit: ``[1, N, T]`` for ray tracing rows,
    ``[1, R², N, T]`` for shadow-map rows (``N`` receivers, ``R`` resolution, ``T`` triangles)."""
    n = [r["receivers"] for r in rows]
    t = [r["triangles"] for r in rows]
    if rows and rows[0]["method"] == "ray_traced":
        return np.c_[np.ones(len(rows)), n, t].astype(float)
    return np.c_[np.ones(len(rows)), [r["resolution"] ** 2 for r in rows], n, t].astype(float)


def _scaled_lstsq(design: np.ndarray, y: list[float]) -> np.ndarray:
    """Least squares with unit-norm columns (as ``np.polyfit`` scales), then unscaled: the scaled
    matrix is well conditioned (checked in ``tests/failures/test_calibrated_models.py``)."""
    scale = np.sqrt((design * design).sum(axis=0))
    coef = np.linalg.lstsq(design / scale, np.asarray(y, float), rcond=None)[0]
    return coef / scale


def _fit_shadow_map(data: dict, geometry: MapGeometry) -> dict:
    span, feature = geometry.span, geometry.feature
    ratios, res, cost = [], [], []
    shadowed = data["shadowed_share"]
    for case in data["cases"]:
        if (
            case["method"] != "shadow_map"
            or case["kernel"] != "nearest"
            or case["bias"] != "bias 1e-4 + 2·slope"
        ):
            continue
        bound = 255.0 * shadowed * span / (feature * case["resolution"])
        ratios.append(case["mean_steps"] / bound)
        res.append(case["resolution"])
        cost.append(case["ratio_to_ray_traced"])
    x = np.asarray(res, float) ** 2
    t2, t0 = np.polyfit(x, cost, 1)
    model = {
        "error": "mean_steps <= 255 * c * shadowed_share * span / (caster_size * resolution)",
        "kernel": "nearest",
        "constant_bias": 1e-4,
        "slope_bias": 2.0,
        "c": max(ratios),
        "cases": len(ratios),
        "cost": "ratio_to_ray_traced ~= t0 + t2 * resolution**2",
        "t0": float(t0),
        "t2": float(t2),
    }
    rows = data.get("frame_cost")
    if rows and "triangles" in rows[0]:
        # seconds (fastest round): ray tracing b0 + bn·N + bt·T, a map m0 + m2·R² + mn·N + mt·T
        rt = [r for r in rows if r["method"] == "ray_traced"]
        sm = [r for r in rows if r["method"] == "shadow_map"]
        b = _nonnegative_lstsq(frame_cost_design(rt), [r["min_s"] for r in rt])
        m = _nonnegative_lstsq(frame_cost_design(sm), [r["min_s"] for r in sm])
        model.update(
            {
                "cost": "ratio ~= (m0 + m2 * R**2 + mn * N + mt * T) / (b0 + bn * N + bt * T)",
                "m0": float(m[0]),
                "m2": float(m[1]),
                "mn": float(m[2]),
                "mt": float(m[3]),
                "b0": float(b[0]),
                "bn": float(b[1]),
                "bt": float(b[2]),
                "receivers": int(data["points"]),
                "triangles": geometry.triangles,
            }
        )
    return model


def _fit_frame_shadows(rows: list[dict]) -> dict:
    """The frame's shadow passes per receiver, relative to one Embree ray
    (:func:`benchmarks.tradeoffs.shadow_frame_constants`): the medians of ``surface_ratio`` and
    ``cull_ratio`` (reported), and the largest traced share beyond the receivers on meshes the
    culling never answers (``rim``, the constant of :func:`blinn_phong.planning.planner.traced_share`)."""
    return {
        "cost": "in a frame, per receiver: surface (every method) + cull + traced share, × one ray's cost",
        "surface": float(np.median([r["surface_ratio"] for r in rows])),
        "cull": float(np.median([r["cull_ratio"] for r in rows])),
        "rim": float(max(max(r["traced_share"] - r["general_share"], 0.0) for r in rows)),
        "cases": len(rows),
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


def shadow_volume_cost_design(rows: list[dict]) -> np.ndarray:
    """Design matrix of the exact shadow methods' cost fit: ``[1, T, N]`` per crossover row
    (``T`` triangles, ``N`` receiver samples)."""
    return np.c_[np.ones(len(rows)), [r["triangles"] for r in rows], [r["samples"] for r in rows]].astype(
        float
    )


def _fit_shadow_volume(data: dict) -> dict:
    rows = data["crossover"]
    design = shadow_volume_cost_design(rows)
    cold = all("shadow_volume_cold_s" in r and "ray_traced_cold_s" in r for r in rows)
    suffix = "_cold_s" if cold else "_s"
    v = np.maximum(_scaled_lstsq(design, [r["shadow_volume" + suffix] for r in rows]), 0.0)
    r = np.maximum(_scaled_lstsq(design, [r["ray_traced" + suffix] for r in rows]), 0.0)
    return {
        "error": "exact (hard shadows, like ray tracing)",
        "cost": "seconds ~= v0 + vt * T + vn * N (volumes), r0 + rt * T + rn * N (Embree), "
        "T triangles, N receiver samples" + (" (cold: caches and BVH built in the frame)" if cold else ""),
        "v0": float(v[0]),
        "vt": float(v[1]),
        "vn": float(v[2]),
        "r0": float(r[0]),
        "rt": float(r[1]),
        "rn": float(r[2]),
        "cases": len(rows),
    }


def _nonnegative_lstsq(design: np.ndarray, y: list[float]) -> np.ndarray:
    """Non-negative least squares (Lawson–Hanson, ``scipy.optimize.nnls``) on unit-norm columns,
    then unscaled: a cost is a sum of non-negative terms."""
    from scipy.optimize import nnls

    scale = np.sqrt((design * design).sum(axis=0))
    scale = np.where(scale > 0, scale, 1.0)
    coef, _ = nnls(design / scale, np.asarray(y, float))
    return coef / scale


def frame_cost_designs(rows: list[dict]) -> dict[str, np.ndarray]:
    """Design matrices of the frame-aware cost fits (``frame_costs`` rows), by model key:
    ``transparency/<method>`` and ``frame/<variant>`` ``[1, S, T]`` (``depth_peeling``:
    ``[1, S, T, k·S]``; ``S`` samples, ``T`` triangles, ``k`` peeled layers)."""
    out: dict[str, np.ndarray] = {}
    groups = [("transparency", m) for m in ("a_buffer", "draw_last", "sort_objects", "depth_peeling")]
    groups += [("frame", v) for v in ("phong", "gouraud", "flat", "fog")]
    for kind, name in groups:
        sel = [r for r in rows if r["kind"] == kind and r["method"] == name]
        cols = [np.ones(len(sel)), [r["samples"] for r in sel], [r["triangles"] for r in sel]]
        if name == "depth_peeling":
            cols.append([r["layers"] * r["samples"] for r in sel])
        out[f"{kind}/{name}"] = np.c_[tuple(cols)].astype(float)
    return out


def _fit_frame_cost(data: dict) -> dict:
    rows = data["rows"]
    model: dict[str, object] = {
        "cost": "process CPU seconds of a whole render() frame ~= x0 + xs * S + xt * T (+ xk * k * S for "
        "depth peeling), per transparency method and per shading method / fog; S samples, T triangles",
        "transparency": {},
        "frame": {},
        "samples_median": int(np.median([r["samples"] for r in rows])),
        "cases": len(rows),
    }
    for key, design in frame_cost_designs(rows).items():
        kind, name = key.split("/")
        y = [r["cpu_s"] for r in rows if r["kind"] == kind and r["method"] == name]
        model[kind][name] = [float(v) for v in _nonnegative_lstsq(design, y)]  # type: ignore[index]
    stage = [r for r in rows if r["kind"] == "shadows"]
    if stage:
        model["shadows"] = {
            "cost": "shadows-stage wall seconds of one light in a render() frame, BVH and volumes built: "
            "ray_traced x0 + xs*S + xt*T + xf*f*S (f the planner's traced share), shadow_volume "
            "x0 + xs*S + xt*T, shadow_map x0 + xs*S + xt*T + xr*R^2",
        }
        for name, design in shadow_stage_designs(stage).items():
            y = [r["shadows_s"] for r in stage if r["method"] == name]
            model["shadows"][name] = [float(v) for v in _nonnegative_lstsq(design, y)]
    return model


def shadow_stage_designs(rows: list[dict]) -> dict[str, np.ndarray]:
    """Design matrices of the frame-stage shadow cost fit (``kind == "shadows"`` rows of
    ``frame_costs``): ``[1, S, T]`` per method, plus ``f·S`` for ``ray_traced`` and ``R²`` for
    ``shadow_map`` (``S`` samples, ``T`` triangles, ``f`` traced share, ``R`` resolution)."""
    out: dict[str, np.ndarray] = {}
    for name in ("ray_traced", "shadow_volume", "shadow_map"):
        sel = [r for r in rows if r["method"] == name]
        cols = [np.ones(len(sel)), [r["samples"] for r in sel], [r["triangles"] for r in sel]]
        if name == "ray_traced":
            cols.append([(r["traced_share"] or 1.0) * r["samples"] for r in sel])
        if name == "shadow_map":
            cols.append([r["resolution"] ** 2 for r in sel])
        out[name] = np.c_[tuple(cols)].astype(float)
    return out


def fit(tradeoffs: dict, volumes: dict | None = None) -> dict:
    """Fit every model to a ``tradeoffs.json`` document (``{"families": {...}}``) and, when given,
    the shadow-volume cost model to a ``shadow_volume.json`` document (``{"crossover": [...]}``)."""
    from blinn_phong.planning.planner import shadow_map_geometry
    from testbeds.tradeoff_scenes import shadow_scene

    families = tradeoffs["families"]
    models: dict[str, object] = {
        "units": "8-bit steps (1/255 of the unit range)",
        "source": "python -m benchmarks",
    }
    if "transparency" in families:
        models["depth_peeling"] = _fit_depth_peeling(families["transparency"])
    if "shadows" in families:
        # the planner's own inputs: the map's span and the thinnest caster seen from the light
        models["shadow_map"] = _fit_shadow_map(families["shadows"], shadow_map_geometry(shadow_scene(), 0))
        if families["shadows"].get("frame_constants"):
            models["frame_shadows"] = _fit_frame_shadows(families["shadows"]["frame_constants"])
    if "shading" in families:
        models["shading"] = _fit_shading(families["shading"])
    if "frame_costs" in families:
        models["frame_cost"] = _fit_frame_cost(families["frame_costs"])
    if volumes is not None and volumes.get("crossover"):
        models["shadow_volume"] = _fit_shadow_volume(volumes)
    return models


def save(models: dict, path: Path = CALIBRATION_PATH) -> Path:
    """Write the models as JSON (default: ``blinn_phong/planning/calibration.json``, shipped with the
    package)."""
    write_json_atomic(path, models, indent=1)
    return path


def fit_results(results: Path, families: dict | None = None) -> dict:
    """Fit every model to the measurements in the directory ``results``: ``tradeoffs.json`` (or the
    given ``families``) and, when present, ``shadow_volume.json`` (the exact shadow methods' costs,
    measured by :mod:`benchmarks.bench_shadow_volume`)."""
    volumes_path = Path(results) / "shadow_volume.json"
    volumes = json.loads(volumes_path.read_text()) if volumes_path.exists() else None
    if families is None:
        families = json.loads((Path(results) / "tradeoffs.json").read_text())["families"]
    return fit({"families": families}, volumes)


def main() -> None:
    """Fit the models to ``benchmarks/results/tradeoffs.json`` and ``shadow_volume.json`` and write
    ``blinn_phong/planning/calibration.json``."""
    path = save(fit_results(Path(__file__).resolve().parent / "results"))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
