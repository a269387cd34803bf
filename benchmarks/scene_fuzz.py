"""The long sweep of random everyday scenes at real sizes (:mod:`blinn_phong.scene_fuzz`).

``python -m benchmarks.scene_fuzz [N] [--start S] [--max-samples M] [--out FILE]`` renders seeds
``S … S+N−1`` (default 0 … 999), each at its drawn size and sample count (capped at ``M``
samples per frame when given), checks every pixel and compares the engines on a downscaled
copy (:func:`blinn_phong.scene_fuzz.check_case`). It prints one line per frame and writes
``benchmarks/results/scene_fuzz.json``: how many frames rendered, how many failed and how
(the error, the case), the time per frame by size class, and the largest engine difference.
It exits 1 when any frame failed.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
import traceback
from pathlib import Path

from benchmarks._util import machine_info, write_json
from blinn_phong.scene_fuzz import check_case, fuzz_case

__all__ = ["main", "sweep"]


def _size_class(width: int, height: int, samples: int) -> str:
    total = width * height * samples
    for limit, name in ((1 << 12, "tiny"), (1 << 18, "small"), (1 << 21, "medium"), (1 << 23, "large")):
        if total <= limit:
            return name
    return "huge"


def sweep(seeds: range, max_samples: int | None = None, echo: bool = True) -> dict[str, object]:
    """Render every seed of ``seeds``; the JSON-ready summary (see the module docstring)."""
    failures: list[dict[str, object]] = []
    seconds: dict[str, list[float]] = collections.defaultdict(list)
    worst = 0.0
    started = time.perf_counter()
    for seed in seeds:
        case = fuzz_case(seed, max_samples=max_samples)
        t = time.perf_counter()
        try:
            report = check_case(case)
        except Exception as exc:  # every failure is recorded, the sweep goes on
            where = traceback.extract_tb(exc.__traceback__)[-1]
            failures.append(
                {
                    "seed": seed,
                    "case": case.describe(),
                    "error": f"{type(exc).__name__}: {exc}",
                    "where": f"{Path(where.filename).name}:{where.lineno}",
                }
            )
            if echo:
                print(f"FAIL {case.describe()}\n     {type(exc).__name__}: {exc}", flush=True)
            continue
        elapsed = time.perf_counter() - t
        seconds[_size_class(case.width, case.height, case.samples)].append(elapsed)
        worst = max(worst, report.engine_difference)
        if echo:
            print(f"ok   seed {seed}: {case.width}×{case.height}×{case.samples} {elapsed:.2f} s", flush=True)
    return {
        "frames": len(seeds),
        "rendered": len(seeds) - len(failures),
        "failed": len(failures),
        "failures": failures,
        "seconds_total": time.perf_counter() - started,
        "seconds_by_size": {
            name: {"frames": len(ts), "median_s": sorted(ts)[len(ts) // 2], "max_s": max(ts)}
            for name, ts in sorted(seconds.items())
        },
        "largest_engine_difference": worst,
        "seeds": [seeds.start, seeds.stop],
        "max_samples": max_samples,
    }


def main(argv: list[str] | None = None) -> int:
    """The command line (see the module docstring)."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.scene_fuzz", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("frames", nargs="?", type=int, default=1000, help="frames to render (default 1000)")
    parser.add_argument("--start", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--max-samples", type=int, default=None, help="cap on width × height × samples")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/scene_fuzz.json"))
    args = parser.parse_args(argv)
    if args.frames < 1 or args.start < 0:
        parser.error(f"frames must be >= 1 and --start >= 0, got {args.frames} and {args.start}")
    result = sweep(range(args.start, args.start + args.frames), args.max_samples)
    result["machine"] = machine_info()
    write_json(args.out, result)
    print(
        f"{result['rendered']} of {result['frames']} frames rendered, {result['failed']} failed, "
        f"in {result['seconds_total']:.0f} s; wrote {args.out}"
    )
    return 1 if result["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
