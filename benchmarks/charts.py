"""Pareto charts of the speed/accuracy measurements (matplotlib PNGs).

Each tradeoff chart has three panels sharing the x axis — the time of a method as a ratio
to a peer measured in the same run (the peer's median time is in the axis label) — and one
error metric each: max absolute error and mean absolute error in 8-bit steps (log scale,
lower is better) and PSNR in dB (higher is better). Points of one method are joined in
order of its parameter (tessellation, resolution, samples, layers) and labelled with it.
The grey dashed line is the Pareto front on the mean error: no method is both faster
and more accurate than a point on it. Zero errors (exact results) are drawn at
:data:`EXACT_FLOOR` steps and PSNR of exact results is left out (it is unbounded).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from benchmarks._util import save_figure

__all__ = ["EXACT_FLOOR", "draw_all", "frame_scaling_chart", "pareto_front", "tradeoff_chart"]

#: Where an error of exactly 0 is drawn on the log-scale error axes (8-bit steps).
EXACT_FLOOR = 1e-3
DPI = 72
MARKERS = "osD^v<>ph*X"


def pareto_front(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The non-dominated points (cost, error), sorted by cost: each is cheaper or better than all others."""
    front: list[tuple[float, float]] = []
    for x, y in sorted(points):
        if not front or y < front[-1][1]:
            front.append((x, y))
    return front


def tradeoff_chart(
    cases: list[dict],
    *,
    series: Callable[[dict], str],
    x_key: str,
    x_label: str,
    point_label: Callable[[dict], str],
    order: Callable[[dict], float],
    title: str,
    path: Path,
    metrics_of: Callable[[dict], dict] = lambda c: c,
) -> Path:
    """Draw one three-panel Pareto chart (max, mean error in 8-bit steps; PSNR) and save it as PNG.

    Args:
        cases: measurement rows (see :mod:`benchmarks.tradeoffs`).
        series: row → name of the line it belongs to (one per method).
        x_key: row key of the cost (a time ratio to the peer).
        x_label: x-axis label, naming the peer and its median time.
        point_label: row → the short text written next to the point (its parameter).
        order: row → the value that orders the points of a line.
        title: figure title (scene and reference).
        path: output PNG path.
        metrics_of: row → the dict holding ``max_steps``, ``mean_steps``, ``psnr_db``.

    Returns:
        ``path``.
    """
    groups: dict[str, list[dict]] = {}
    for case in cases:
        groups.setdefault(series(case), []).append(case)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    colours = plt.get_cmap("tab20").colors
    panels = (
        ("max_steps", "max |error| (8-bit steps)", True),
        ("mean_steps", "mean |error| (8-bit steps)", True),
        ("psnr_db", "PSNR (dB, peak 1)", False),
    )
    for ax, (key, label, log) in zip(axes, panels, strict=True):
        for i, (name, rows) in enumerate(groups.items()):
            rows = sorted(rows, key=order)
            xs, ys, texts = [], [], []
            for row in rows:
                value = metrics_of(row)[key]
                if value is None:
                    continue
                xs.append(row[x_key])
                ys.append(max(value, EXACT_FLOOR) if log else value)
                texts.append(point_label(row))
            if not xs:
                continue
            ax.plot(
                xs,
                ys,
                marker=MARKERS[i % len(MARKERS)],
                ms=4,
                lw=1,
                label=name,
                color=colours[i % len(colours)],
            )
            for x, y, t in zip(xs, ys, texts, strict=True):
                ax.annotate(t, (x, y), fontsize=6, xytext=(2, 2), textcoords="offset points")
        if key == "mean_steps":
            pts = [(c[x_key], max(metrics_of(c)[key], EXACT_FLOOR)) for c in cases]
            front = pareto_front(pts)
            ax.plot([p[0] for p in front], [p[1] for p in front], "--", color="grey", lw=1.5, zorder=0)
        ax.set_xscale("log")
        if log:
            ax.set_yscale("log")
            ax.axhline(1.0, color="k", lw=0.6, ls=":")
        ax.set_xlabel(x_label, fontsize=8)
        ax.set_ylabel(label, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="both", alpha=0.25)
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=DPI)
    plt.close(fig)
    return path


def _peer_time(cases: list[dict], x_key: str, method: str) -> str:
    peers = [c["median_s"] / c[x_key] for c in cases if c.get(x_key)]
    if not peers:
        return method
    peers.sort()
    return f"{method}, median {1e3 * peers[len(peers) // 2]:.3g} ms"


def _shading(data: dict, out: Path) -> list[Path]:
    cases = data["cases"]
    x_key = "ratio_to_mesa_glsl" if all("ratio_to_mesa_glsl" in c for c in cases) else "ratio_to_phong"
    peer = "Mesa GLSL per-pixel" if x_key == "ratio_to_mesa_glsl" else "our phong"
    return [
        tradeoff_chart(
            cases,
            series=lambda c: c["method"],
            x_key=x_key,
            x_label=f"time ÷ time of {peer}, same tessellation ({_peer_time(cases, x_key, peer)})",
            point_label=lambda c: str(c["segments"]),
            order=lambda c: c["segments"],
            metrics_of=lambda c: c["interior"],
            title=f"Shading frequency × tessellation (labels: segments), interior pixels; reference: "
            f"{data['reference']}; {data['size'][0]}² px",
            path=out / "shading_tessellation.png",
        )
    ]


def _antialiasing(data: dict, out: Path) -> list[Path]:
    cases = data["cases"]
    return [
        tradeoff_chart(
            cases,
            series=lambda c: "ordered-grid supersampling",
            x_key="ratio_to_1x1",
            x_label=f"time / time at 1 sample ({_peer_time(cases, 'ratio_to_1x1', '1 sample')})",
            point_label=lambda c: c["method"],
            order=lambda c: c["samples_per_pixel"],
            title=f"Antialiasing — against {data['reference']}; {data['scene']}, {data['size'][0]}² px",
            path=out / "antialiasing.png",
        )
    ]


def _shadows(data: dict, out: Path) -> list[Path]:
    cases = [c for c in data["cases"] if c["method"] == "shadow_map"]
    all_cases = data["cases"]
    return [
        tradeoff_chart(
            cases,
            series=lambda c: f"{c['kernel']}, {c['bias']}",
            x_key="ratio_to_ray_traced",
            x_label=f"time / time of Embree ray tracing "
            f"({_peer_time(all_cases, 'ratio_to_ray_traced', 'Embree')})",
            point_label=lambda c: str(c["resolution"]),
            order=lambda c: c["resolution"],
            title=f"Shadow maps: resolution (labels) × PCF kernel × bias — visibility error ×255 against "
            f"ray-traced shadows, {data['points']} points",
            path=out / "shadows.png",
        )
    ]


def _transparency(data: dict, out: Path) -> list[Path]:
    cases = [c for c in data["cases"] if c["label"] != "a_buffer"]
    opacities = sorted({c["opacity"] for c in cases})
    paths = [
        tradeoff_chart(
            cases,
            series=lambda c: f"{c['label']}, α={c['opacity']}",
            x_key="ratio_to_a_buffer",
            x_label="time / time of the A-buffer "
            f"({_peer_time(data['cases'], 'ratio_to_a_buffer', 'A-buffer')})",
            point_label=lambda c: f"{c['layers']}",
            order=lambda c: c["layers"],
            title="Transparency against the A-buffer (labels: number of interpenetrating layers)",
            path=out / "transparency.png",
        )
    ]
    # Growth: error against the number of layers, one panel per opacity.
    fig, axes = plt.subplots(1, len(opacities), figsize=(5 * len(opacities), 4.2), squeeze=False)
    for ax, alpha in zip(axes[0], opacities, strict=True):
        labels = sorted({c["label"] for c in cases if c["opacity"] == alpha})
        for i, label in enumerate(labels):
            rows = sorted(
                (c for c in cases if c["opacity"] == alpha and c["label"] == label), key=lambda c: c["layers"]
            )
            line = ax.plot(
                [r["layers"] for r in rows],
                [max(r["max_steps"], EXACT_FLOOR) for r in rows],
                marker=MARKERS[i % len(MARKERS)],
                ms=4,
                label=f"{label} (max)",
            )[0]
            ax.plot(
                [r["layers"] for r in rows],
                [max(r["mean_steps"], EXACT_FLOOR) for r in rows],
                ls=":",
                color=line.get_color(),
            )
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.axhline(1.0, color="k", lw=0.6, ls=":")
        ax.set_title(f"opacity α = {alpha}", fontsize=9)
        ax.set_xlabel("interpenetrating layers", fontsize=8)
        ax.set_ylabel("|error| in 8-bit steps (solid: max, dotted: mean)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="both", alpha=0.25)
    axes[0][0].legend(fontsize=6)
    fig.suptitle("Transparency error as layers and opacity grow (reference: A-buffer)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, out / "transparency_growth.png", dpi=DPI)
    plt.close(fig)
    paths.append(out / "transparency_growth.png")
    return paths


def _compositing(data: dict, out: Path) -> list[Path]:
    cases = [c for c in data["cases"] if c["method"] != "float64 premultiplied"]
    return [
        tradeoff_chart(
            cases,
            series=lambda c: c["method"],
            x_key="ratio_to_oiio",
            x_label=f"time / time of OpenImageIO over ({_peer_time(data['cases'], 'ratio_to_oiio', 'OIIO')})",
            point_label=lambda c: str(c["layers"]),
            order=lambda c: c["layers"],
            title=f"Compositing precision — N-layer over stack (labels: N) against float64 premultiplied, "
            f"{data['size'][0]}² px",
            path=out / "compositing_precision.png",
        )
    ]


def _scaling(data: dict, out: Path) -> list[Path]:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, key, rows, label in (
        (axes[0], "pixels", data["pixels"], "pixels (64-segment sphere)"),
        (axes[1], "triangles", data["triangles"], "triangles (256² px)"),
    ):
        x = [r[key] for r in rows]
        ax.plot(x, [r["ours_s"] for r in rows], "o-", label="blinn_phong.frame.render (phong)")
        if all("mesa_glsl_s" in r for r in rows):
            ax.plot(x, [r["mesa_glsl_s"] for r in rows], "s-", label="Mesa llvmpipe GLSL")
            for r in rows:
                ax.annotate(f"×{r['ratio_to_mesa_glsl']:.0f}", (r[key], r["ours_s"]), fontsize=7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(label, fontsize=8)
        ax.set_ylabel("median seconds per frame", fontsize=8)
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7)
    fig.suptitle("Scaling (labels: our time as a multiple of Mesa's, same run)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, out / "scaling.png", dpi=DPI)
    plt.close(fig)
    return [out / "scaling.png"]


def _peer_rows(results: dict[str, dict], results_dir: Path | None) -> list[tuple[str, float, str]]:
    """(label, our time ÷ peer time, accuracy note) from the tradeoffs and the per-module JSON files."""
    rows: list[tuple[str, float, str]] = []

    def load(name: str) -> dict | None:
        path = None if results_dir is None else Path(results_dir) / name
        if path is None or not path.exists():
            return None
        import json

        return json.loads(path.read_text())

    def steps(metrics: dict) -> str:
        return f"max {metrics['max_steps']:.3g} / mean {metrics['mean_steps']:.2g} steps"

    try:
        shading = results.get("shading", {}).get("cases", [])
        for c in shading:
            if c["method"] == "phong" and c["segments"] == 64 and "ratio_to_mesa_glsl" in c:
                mesa = next(
                    m for m in shading if m["method"] == "mesa_glsl_per_pixel" and m["segments"] == 64
                )
                rows.append(
                    (
                        "render, Phong (64-seg sphere) vs Mesa GLSL",
                        c["ratio_to_mesa_glsl"],
                        f"ours {steps(c['interior'])}, Mesa {steps(mesa['interior'])}",
                    )
                )
        for c in results.get("compositing", {}).get("cases", []):
            if c["layers"] == 128 and c["method"] == "float32 premultiplied":
                rows.append(("128-layer over, float32 vs OIIO over", c["ratio_to_oiio"], steps(c)))
            if c["layers"] == 128 and c["method"] == "unorm8 straight":
                pillow = next(
                    m
                    for m in results["compositing"]["cases"]
                    if m["layers"] == 128 and m["method"].startswith("Pillow")
                )
                rows.append(
                    (
                        "128-layer over, straight unorm8 vs Pillow",
                        c["median_s"] / pillow["median_s"],
                        steps(c),
                    )
                )
        for c in results.get("shadows", {}).get("cases", []):
            if (
                c.get("resolution") == 1024
                and c.get("kernel") == "nearest"
                and c.get("bias", "").startswith("bias 1e")
            ):
                rows.append(("shadow map 1024² vs Embree ray tracing", c["ratio_to_ray_traced"], steps(c)))
        comp = load("compositing.json")
        if comp:
            for r in comp.get("float32", []):
                if r.get("name") == "src_over":
                    rows.append((f"composite src_over {r['size']} vs OIIO over", r["ratio_to_oiio_over"], ""))
            for r in comp.get("unorm8", []):
                if "ratio_to_pillow_alpha_composite" in r and not r["name"].startswith("pillow"):
                    rows.append(
                        (f"{r['name']} {r['size']} vs Pillow", r["ratio_to_pillow_alpha_composite"], "")
                    )
        gl = load("gl_blend.json")
        if gl:
            for r in gl.get("cases", []):
                if r.get("state") == "src_over":
                    note = (
                        f"max {r['max_steps']} step"
                        if "max_steps" in r
                        else f"max diff {r.get('max_abs_difference')}"
                    )
                    rows.append(
                        (f"gl_blend src_over {r['target']} vs Mesa", r["ratio_gl_blend_over_mesa"], note)
                    )
        blender = load("blender_compositor.json")
        if blender:
            for r in blender.get("rows", []):
                if r.get("case") == "alpha_over/src_over" and r.get("ratio_blender_op_over_numba"):
                    rows.append(
                        (
                            "Alpha Over 1920×1080 vs Blender compositor",
                            1.0 / r["ratio_blender_op_over_numba"],
                            "",
                        )
                    )
    except (KeyError, StopIteration, TypeError, ZeroDivisionError) as exc:  # a peer's JSON changed shape
        print(f"peers chart: skipped a row ({exc!r})")
    return rows


def peers_chart(results: dict[str, dict], results_dir: Path | None, out_dir: Path) -> list[Path]:
    """One bar per peer comparison: our time as a multiple of the peer's (same run), with the accuracy."""
    rows = _peer_rows(results, results_dir)
    if not rows:
        return []
    fig, ax = plt.subplots(figsize=(11, 0.42 * len(rows) + 1.2))
    labels = [r[0] for r in rows]
    ratios = [r[1] for r in rows]
    colours = ["tab:green" if x <= 1 else "tab:red" for x in ratios]
    ax.barh(range(len(rows)), ratios, color=colours)
    for i, (_, ratio, note) in enumerate(rows):
        ax.annotate(
            f"×{ratio:.2g}  {note}", (ratio, i), fontsize=7, xytext=(3, -3), textcoords="offset points"
        )
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlim(min(min(ratios), 1.0) / 2, max(max(ratios), 1.0) * 40)
    ax.set_yticks(range(len(rows)), labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel(
        "our time ÷ the peer's, same run (medians; best-of-N where a module reports that); < 1: faster",
        fontsize=8,
    )
    ax.tick_params(labelsize=7)
    ax.grid(True, axis="x", which="both", alpha=0.25)
    fig.suptitle("Peers doing the same work: time ratio and our error (8-bit steps)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, out_dir / "peers.png", dpi=DPI)
    plt.close(fig)
    return [out_dir / "peers.png"]


#: Line style per scaling case: (colour, marker, dash).
_STYLE = {
    "plain": ("black", "o", "-"),
    "default": ("tab:gray", "x", "--"),
    "shadow_map": ("tab:blue", "s", "-"),
    "ray_traced": ("tab:orange", "^", "-"),
    "shadow_volume": ("tab:green", "v", "-"),
    "a_buffer": ("tab:red", "D", "-"),
    "draw_last": ("tab:purple", "<", ":"),
    "weighted_blended": ("tab:brown", ">", ":"),
    "fog": ("tab:cyan", "P", "--"),
}


def frame_scaling_chart(data: dict, out_dir: str | Path) -> list[Path]:
    """``frame_scaling.png`` from :mod:`benchmarks.bench_frame`'s ``frame.json``: time and peak RSS
    against pixels and against triangles, one line per effect, and the A-buffer's fragments
    (rasterized, kept) and bytes against pixels."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5))
    scaling = data["scaling"]
    cases = [c for c in _STYLE if any(p["case"] == c for p in scaling["pixels"] + scaling["triangles"])]
    cases += sorted({p["case"] for p in scaling["pixels"]} - set(cases))
    for col, key in enumerate(("pixels", "triangles")):
        for case in cases:
            mine = sorted((p for p in scaling[key] if p["case"] == case), key=lambda p: p[key])
            if not mine:
                continue
            colour, marker, dash = _STYLE.get(case, (None, ".", "-"))
            x = [p[key] for p in mine]
            style = {"color": colour, "marker": marker, "linestyle": dash, "label": case, "markersize": 4}
            axes[0, col].plot(x, [p["seconds"] for p in mine], **style)
            axes[1, col].plot(x, [p["peak_rss_bytes"] / 1e9 for p in mine], **style)
        sizes = sorted({(p["width"], p["height"]) for p in scaling[key]})
        fixed = (
            f"{max((p['triangles'] for p in scaling[key]), default=0):,} triangles"
            if key == "pixels"
            else "×".join(map(str, sizes[0]))
            if sizes
            else ""
        )
        for row, label in ((0, "seconds, one render (wall)"), (1, "peak RSS, GB (10⁹ bytes)")):
            ax = axes[row, col]
            ax.set_xscale("log")
            ax.set_xlabel(f"{key} ({fixed})", fontsize=8)
            ax.set_ylabel(label, fontsize=8)
            ax.grid(True, which="both", alpha=0.25)
            ax.tick_params(labelsize=7)
        axes[0, col].set_yscale("log")
        axes[1, col].axhline(2.0, color="red", linewidth=0.8, alpha=0.5)
    census = sorted(
        (p for p in scaling["pixels"] if p["case"] == "a_buffer" and "fragments" in p),
        key=lambda p: p["pixels"],
    )
    ax = axes[0, 2]
    if census:
        x = [p["pixels"] for p in census]
        for field, label, style in (
            ("rasterized", "rasterized, all meshes", "k-o"),
            ("rasterized_transparent", "rasterized, transparent sphere", "r--D"),
            ("kept_opaque", "kept: nearest opaque", "b-s"),
            ("kept_transparent", "kept: transparent in front", "r-D"),
        ):
            ax.plot(x, [p["fragments"][field] for p in census], style, label=label, markersize=4)
        ax.set_yscale("log")
    ax.set_title("A-buffer: fragments rasterized vs kept", fontsize=9)
    ax.set_ylabel("fragments", fontsize=8)
    ax = axes[1, 2]
    if census:
        ax.plot(
            x,
            [p["fragments"]["rasterized_bytes"] / 1e9 for p in census],
            "k-o",
            label="all rasterized fragments (not built)",
            markersize=4,
        )
        ax.plot(
            x,
            [p["fragments"]["kept_bytes"] / 1e9 for p in census],
            "r-D",
            label="kept fragments + per-sample lists",
            markersize=4,
        )
        plain = {p["pixels"]: p["peak_rss_bytes"] for p in scaling["pixels"] if p["case"] == "plain"}
        extra = [
            (p["pixels"], p["peak_rss_bytes"] - plain[p["pixels"]]) for p in census if p["pixels"] in plain
        ]
        ax.plot(
            [e[0] for e in extra],
            [e[1] / 1e9 for e in extra],
            "r:",
            label="peak RSS: A-buffer frame − plain frame",
        )
    ax.set_title("A-buffer: bytes", fontsize=9)
    ax.set_ylabel("GB", fontsize=8)
    for ax in axes[:, 2]:
        ax.set_xscale("log")
        ax.set_xlabel("pixels", fontsize=8)
        ax.grid(True, which="both", alpha=0.25)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    fig.suptitle(
        "Frame pipeline scaling per effect (two spheres over a plane, 2 lights; A-buffer/draw-last/weighted "
        "blended: one sphere at opacity 0.5); red line: 2 GB\n"
        "times: one render per point, each series in its own process on a shared machine — compare slopes, "
        "and ratios only within the interleaved table",
        fontsize=9,
    )
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    path = save_figure(fig, out / "frame_scaling.png", dpi=DPI)  # atomic: a failed save keeps the old chart
    plt.close(fig)
    return [path]


_DRAW: dict[str, Callable[[dict, Path], list[Path]]] = {
    "shading": _shading,
    "antialiasing": _antialiasing,
    "shadows": _shadows,
    "transparency": _transparency,
    "compositing": _compositing,
    "scaling": _scaling,
}


def draw_all(results: dict[str, dict], out_dir: Path, results_dir: Path | None = None) -> list[Path]:
    """Draw the charts of every family in ``results`` (``family → data``) and the peers chart.

    ``results_dir`` holds the per-module JSON files (``compositing.json``, ``gl_blend.json``,
    ``blender_compositor.json``) read for the peers chart, when present.
    """
    paths: list[Path] = []
    for family, data in results.items():
        if family in _DRAW:
            paths += _DRAW[family](data, Path(out_dir))
    paths += peers_chart(results, results_dir, Path(out_dir))
    frames = [Path(results_dir) / n for n in ("frame.json", "frame_quick.json")] if results_dir else []
    frames = [f for f in frames if f.exists()]
    if frames:  # benchmarks.bench_frame (the full measurement when there is one)
        import json

        paths += frame_scaling_chart(json.loads(frames[0].read_text()), Path(out_dir))
    return paths
