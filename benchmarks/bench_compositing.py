"""``compositing.composite`` against OpenImageIO's ``ImageBufAlgo.over``, measured in the same run.

For 1920×1080 and 3840×2160 float32 premultiplied frames this times, interleaved round
by round (:func:`benchmarks._util.time_interleaved`):

* OpenImageIO ``ImageBufAlgo.over(A, B)`` on ImageBufs made beforehand (the peer; it
  allocates its result, as ``composite`` does);
* ``composite(a, b, op)`` for every operator with the default engine (the fused numba
  pass when numba is installed; compiled in the warm-up call, not timed);
* the numpy reference engine for a few operators;
* ``gl_blend(..., target="unorm8")`` with ``(ONE, ONE_MINUS_SRC_ALPHA)`` against Pillow's
  ``Image.alpha_composite`` on 8-bit frames (1920×1080 only).

Each ratio is ``median time / median time of the peer`` (< 1: faster than the peer); the
ratio of the best times is recorded too. Both
sides use the machine's cores (OIIO's thread pool, the fused engine's threads), so run it
on an otherwise idle machine: the JSON records the load average before and after.
Targets of issue 2: ``src_over`` ≤ 1.5, every other operator ≤ 2. Usage::

    .venv/bin/python -m benchmarks.bench_compositing [--out benchmarks/results] [--repeat 7] [--quick]

Writes ``compositing.json`` to ``--out`` and prints a markdown table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813

from benchmarks._util import machine_info, markdown_table, time_interleaved, write_json
from compositing import ALL_OPERATORS, composite
from compositing.operators import _fused_available

__all__ = ["main", "run"]

SIZES = {"1920x1080": (1080, 1920), "3840x2160": (2160, 3840)}
NUMPY_ENGINE_OPS = ("src_over", "xor", "disjoint_over")


def _frames(shape: tuple[int, int], seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        alpha = rng.random((*shape, 1), dtype=np.float32)
        rgb = rng.random((*shape, 3), dtype=np.float32) * alpha
        out.append(np.ascontiguousarray(np.concatenate([rgb, alpha], axis=-1)))
    return out[0], out[1]


def _target(op: str) -> float:
    return 1.5 if op == "src_over" else 2.0


def _rows(size: str, timings: dict[str, dict[str, float]], group: str) -> list[dict]:
    peer = timings["oiio_over"]
    rows = []
    for name, t in timings.items():
        if name == "oiio_over" and group != "fused":
            continue  # reported once, from the main group
        row = {
            "size": size,
            "group": group,
            "name": name,
            "median_ms": round(t["median_s"] * 1e3, 3),
            "min_ms": round(t["min_s"] * 1e3, 3),
            "ratio_to_oiio_over": round(t["median_s"] / peer["median_s"], 3),
            "ratio_to_oiio_over_min": round(t["min_s"] / peer["min_s"], 3),
        }
        if name in ALL_OPERATORS:
            row["target_ratio"] = _target(name)
            row["meets_target"] = row["ratio_to_oiio_over"] <= row["target_ratio"]
        rows.append(row)
    return rows


def _bench_float(size: str, repeat: int) -> list[dict]:
    a, b = _frames(SIZES[size], seed=1)
    buf_a, buf_b = oiio.ImageBuf(a), oiio.ImageBuf(b)

    def peer():
        return oiio.ImageBufAlgo.over(buf_a, buf_b)

    # Two groups, each with the peer: the numpy engine's large temporaries disturb the
    # allocator for whatever runs next, so it is not interleaved with the default engine.
    fused = {"oiio_over": peer, **{op: (lambda op=op: composite(a, b, op)) for op in ALL_OPERATORS}}
    reference = {
        "oiio_over": peer,
        **{
            f"{op} (numpy engine)": (lambda op=op: composite(a, b, op, engine="numpy"))
            for op in NUMPY_ENGINE_OPS
        },
    }
    return _rows(size, time_interleaved(fused, repeat=repeat), "fused") + _rows(
        size, time_interleaved(reference, repeat=max(3, repeat // 2)), "numpy"
    )


def _bench_unorm8(repeat: int) -> list[dict]:
    try:
        from PIL import Image

        from compositing.gl_blend import gl_blend
    except ImportError as exc:  # pragma: no cover - both are in the lock file
        return [{"skipped": str(exc)}]
    a, b = _frames(SIZES["1920x1080"], seed=2)
    # Pillow takes straight 8-bit RGBA; give it the same pixels, unpremultiplied and quantised.
    straight = [np.where(x[..., 3:] > 0, x / np.maximum(x[..., 3:], 1e-12), 0) for x in (a, b)]
    for s, x in zip(straight, (a, b), strict=True):
        s[..., 3] = x[..., 3]
    img_a, img_b = (
        Image.fromarray(np.rint(np.clip(s, 0, 1) * 255).astype(np.uint8), "RGBA") for s in straight
    )
    timings = time_interleaved(
        {
            "pillow_alpha_composite": lambda: Image.alpha_composite(img_b, img_a),
            "gl_blend unorm8 (ONE, ONE_MINUS_SRC_ALPHA)": lambda: gl_blend(
                a, b, "ONE", "ONE_MINUS_SRC_ALPHA", target="unorm8"
            ),
        },
        repeat=repeat,
    )
    peer = timings["pillow_alpha_composite"]["median_s"]
    return [
        {
            "size": "1920x1080",
            "name": name,
            "median_ms": round(t["median_s"] * 1e3, 3),
            "min_ms": round(t["min_s"] * 1e3, 3),
            "ratio_to_pillow_alpha_composite": round(t["median_s"] / peer, 3),
        }
        for name, t in timings.items()
    ]


def run(repeat: int = 7, quick: bool = False) -> dict:
    """Run the benchmark and return the results (what ``main`` writes as JSON)."""
    sizes = ["1920x1080"] if quick else list(SIZES)
    machine = machine_info()
    float_rows = [row for size in sizes for row in _bench_float(size, repeat)]
    unorm8_rows = _bench_unorm8(repeat)
    machine["load_average_1min_after"] = machine_info().get("load_average_1min")
    return {
        "benchmark": "compositing.composite vs OpenImageIO ImageBufAlgo.over (float32 RGBA)",
        "engine": "numba fused" if _fused_available() else "numpy",
        "repeat": repeat,
        "oiio_version": oiio.VERSION_STRING,
        "numpy_version": np.__version__,
        "machine": machine,
        "float32": float_rows,
        "unorm8": unorm8_rows,
    }


def main(argv: list[str] | None = None) -> None:
    """Command-line entry; see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--quick", action="store_true", help="1920x1080 only")
    args = parser.parse_args(argv)
    results = run(args.repeat, args.quick)
    write_json(args.out / "compositing.json", results)
    header = ["size", "operation", "median ms", "× OIIO over (median)", "× OIIO over (best)", "target", "ok"]
    rows = [
        [
            r["size"],
            r["name"],
            f"{r['median_ms']:.2f}",
            f"{r['ratio_to_oiio_over']:.2f}",
            f"{r['ratio_to_oiio_over_min']:.2f}",
            r.get("target_ratio", ""),
            {True: "yes", False: "NO"}.get(r.get("meets_target"), ""),
        ]
        for r in results["float32"]
    ]
    print(markdown_table(header, rows))
    print()
    unorm8 = [r for r in results["unorm8"] if "name" in r]
    if unorm8:
        print(
            markdown_table(
                ["size", "operation", "median ms", "× Pillow alpha_composite"],
                [
                    [
                        r["size"],
                        r["name"],
                        f"{r['median_ms']:.2f}",
                        f"{r['ratio_to_pillow_alpha_composite']:.2f}",
                    ]
                    for r in unorm8
                ],
            )
        )
    print(f"\nwrote {args.out / 'compositing.json'}")


if __name__ == "__main__":
    main()
