"""Small helpers shared by benchmarks: interleaved timing, machine facts, JSON output.

Timings on a shared machine drift; :func:`time_interleaved` runs the candidates in
turn, round after round, so a disturbance hits all of them alike, and reports the
median and the minimum of each. Ratios should be taken between medians measured in
the same call.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from compositing._atomic import atomic_path, write_json_atomic

__all__ = ["machine_info", "markdown_table", "save_figure", "time_interleaved", "write_json"]


def time_interleaved(
    candidates: Mapping[str, Callable[[], object]], repeat: int = 7, warmup: int = 1
) -> dict[str, dict[str, float]]:
    """Time each callable ``repeat`` times, interleaved round-robin, after ``warmup`` untimed calls.

    Returns ``{name: {"median_s", "min_s", "runs"}}``.
    """
    for fn in candidates.values():
        for _ in range(warmup):
            fn()
    samples: dict[str, list[float]] = {name: [] for name in candidates}
    for _ in range(repeat):
        for name, fn in candidates.items():
            start = time.perf_counter()
            fn()
            samples[name].append(time.perf_counter() - start)
    return {
        name: {"median_s": statistics.median(ts), "min_s": min(ts), "runs": len(ts)}
        for name, ts in samples.items()
    }


def machine_info() -> dict[str, object]:
    """Facts that make a timing interpretable: CPU count, platform, Python, load average."""
    info: dict[str, object] = {
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "processor": platform.processor() or platform.machine(),
    }
    if hasattr(os, "getloadavg"):
        info["load_average_1min"] = round(os.getloadavg()[0], 2)
    return info


def markdown_table(header: list[str], rows: list[list[object]]) -> str:
    """A GitHub-flavoured markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def write_json(path: Path, data: object) -> None:
    """Write ``data`` as indented JSON, creating the directory; atomic (a failed write keeps the old file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, data, indent=1)


def save_figure(fig: Any, path: str | os.PathLike, **savefig_kwargs: Any) -> Path:
    """``fig.savefig(path, **savefig_kwargs)`` atomically, creating the directory; returns the path.

    Matplotlib picks the format from the extension, which the temporary file keeps
    (see :func:`compositing._atomic.atomic_path`); a failed save leaves the old chart intact.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(target) as tmp:
        fig.savefig(tmp, **savefig_kwargs)
    return target


def ratio_main(run: Any, description: str, argv: list[str] | None = None) -> None:
    """The command line of a benchmark whose ``run(out, repeat=, quick=)`` reports rows with
    ``median_s`` and ``ratio_to_frame``: ``--out``, ``--repeat``, ``--quick``; prints each row."""
    import argparse

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    data = run(args.out, repeat=args.repeat, quick=args.quick)
    for name, row in data["rows"].items():
        print(f"{name:>14}: {row['median_s']:.3f} s  ({row['ratio_to_frame']:.2f}× the frame)")
