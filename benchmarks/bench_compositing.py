"""``compositing.composite`` against OpenImageIO's ``ImageBufAlgo.over``, measured in the same run.

For 1920×1080 and 3840×2160 float32 premultiplied frames this times, interleaved round
by round (:func:`benchmarks._util.time_interleaved`):

* OpenImageIO ``ImageBufAlgo.over(A, B)`` on ImageBufs made beforehand (the peer; it
  allocates its result, as ``composite`` does);
* ``composite(a, b, op)`` for every operator with the default engine (the fused numba
  pass when numba is installed; compiled in the warm-up call, not timed);
* the numpy reference engine for a few operators;
* ``gl_blend`` on uint8 frames (``target="unorm8"``) in several blend states against Pillow's
  ``Image.alpha_composite`` on the same 8-bit frames, and ``gl_blend`` on the float32 frames
  against ``composite(a, b, "src_over")`` (1920×1080 only);
* ``composite_stack`` of a 128-layer stack (256×256, the stack of the compositing tradeoff
  study) against a chain of OpenImageIO ``over`` (float32) and of Pillow ``alpha_composite``
  (8-bit straight alpha).

Each ratio is ``median time / median time of the peer`` (< 1: faster than the peer); the
ratio of the best times is recorded too. Both
sides use the machine's cores (OIIO's thread pool, the fused engine's threads), so run it
on an otherwise idle machine: the JSON records the load average before and after.
Targets: ``src_over`` ≤ 1.5, every other operator ≤ 2; gl_blend on uint8 ≤ 1.0× Pillow for the
``src_over`` pair and ≤ 1.5× for other states; gl_blend float32 ≤ 1.5× ``composite``; stacks
≤ 1.0× the OIIO chain and ≤ 1.5× the Pillow chain. Usage::

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
from compositing._engine import numba_available

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


#: Blend states timed on 8-bit and float32 frames: (label, positional args, keyword args).
GL_STATES = {
    "src_over (ONE, ONE_MINUS_SRC_ALPHA)": (("ONE", "ONE_MINUS_SRC_ALPHA"), {}),
    "SRC_ALPHA, ONE_MINUS_SRC_ALPHA": (("SRC_ALPHA", "ONE_MINUS_SRC_ALPHA"), {}),
    "separate alpha (…, ONE, ONE_MINUS_SRC_ALPHA)": (
        ("SRC_ALPHA", "ONE_MINUS_SRC_ALPHA"),
        {"src_factor_alpha": "ONE", "dst_factor_alpha": "ONE_MINUS_SRC_ALPHA"},
    ),
    "constant colour": (
        ("CONSTANT_COLOR", "ONE_MINUS_CONSTANT_COLOR"),
        {"constant": (0.25, 0.5, 0.75, 0.5)},
    ),
    "SRC_ALPHA_SATURATE, ONE": (("SRC_ALPHA_SATURATE", "ONE"), {}),
    "ONE_MINUS_DST_COLOR, SRC_COLOR, REVERSE_SUBTRACT, MAX alpha": (
        ("ONE_MINUS_DST_COLOR", "SRC_COLOR", "FUNC_REVERSE_SUBTRACT"),
        {"equation_alpha": "MAX"},
    ),
}


def _straight_bytes(x: np.ndarray) -> np.ndarray:
    """Premultiplied float RGBA as straight 8-bit RGBA (what Pillow takes)."""
    straight = np.where(x[..., 3:] > 0, x / np.maximum(x[..., 3:], 1e-12), 0)
    straight[..., 3] = x[..., 3]
    return np.rint(np.clip(straight, 0, 1) * 255).astype(np.uint8)


def _bench_gl_blend(repeat: int) -> tuple[list[dict], list[dict]]:
    """gl_blend on uint8 frames against Pillow ``alpha_composite``; on float32 against ``composite``.

    Pillow blends straight 8-bit RGBA (src over dst); gl_blend takes the same frames' 8-bit
    premultiplied codes. Targets: the ``src_over`` pair ≤ 1.0× Pillow, every other state ≤ 1.5×;
    float32, every state ≤ 1.5× ``composite(a, b, "src_over")``.
    """
    from PIL import Image

    from compositing.gl_blend import gl_blend

    a, b = _frames(SIZES["1920x1080"], seed=2)
    img_a, img_b = (Image.fromarray(_straight_bytes(x), "RGBA") for x in (a, b))
    a8, b8 = (np.rint(x * 255).astype(np.uint8) for x in (a, b))
    u8 = {
        name: (lambda args=args, kw=kw: gl_blend(a8, b8, *args, target="unorm8", **kw))
        for name, (args, kw) in GL_STATES.items()
    }
    f32 = {
        name: (lambda args=args, kw=kw: gl_blend(a, b, *args, **kw)) for name, (args, kw) in GL_STATES.items()
    }
    timings = time_interleaved(
        {"pillow_alpha_composite": lambda: Image.alpha_composite(img_b, img_a), **u8}, repeat
    )
    peer = timings["pillow_alpha_composite"]
    unorm8_rows = []
    for name, t in timings.items():
        row = {
            "size": "1920x1080",
            "name": name if name.startswith("pillow") else f"gl_blend uint8 {name}",
            "median_ms": round(t["median_s"] * 1e3, 3),
            "min_ms": round(t["min_s"] * 1e3, 3),
            "ratio_to_pillow_alpha_composite": round(t["median_s"] / peer["median_s"], 3),
        }
        if name in GL_STATES:
            row["target_ratio"] = 1.0 if name.startswith("src_over") else 1.5
            row["meets_target"] = row["ratio_to_pillow_alpha_composite"] <= row["target_ratio"]
        unorm8_rows.append(row)
    timings = time_interleaved({"composite src_over": lambda: composite(a, b, "src_over"), **f32}, repeat)
    peer = timings["composite src_over"]
    float_rows = []
    for name, t in timings.items():
        row = {
            "size": "1920x1080",
            "name": name,
            "median_ms": round(t["median_s"] * 1e3, 3),
            "min_ms": round(t["min_s"] * 1e3, 3),
            "ratio_to_composite_src_over": round(t["median_s"] / peer["median_s"], 3),
        }
        if name in GL_STATES:
            row["name"] = f"gl_blend float32 {name}"
            row["target_ratio"] = 1.5
            row["meets_target"] = row["ratio_to_composite_src_over"] <= 1.5
        float_rows.append(row)
    return unorm8_rows, float_rows


def _bench_stacks(repeat: int, layers: int = 128, shape: tuple[int, int] = (256, 256)) -> list[dict]:
    """``composite_stack`` of the project's layer stack against the OpenImageIO and Pillow chains.

    The stack of :func:`benchmarks.tradeoffs.layer_stack` (α in [0.02, 0.3] over an opaque
    background): float32 premultiplied against a chain of ``ImageBufAlgo.over`` (with its read
    back), 8-bit straight against a chain of Pillow ``alpha_composite``. Targets: ≤ 1.0× OIIO,
    ≤ 1.5× Pillow.
    """
    from benchmarks.tradeoffs import compositing_peers, layer_stack
    from compositing import composite_stack, premultiply

    straight, background = layer_stack(layers, shape)
    premult = [premultiply(background).astype(np.float32)] + [
        premultiply(x).astype(np.float32) for x in straight
    ]
    codes = [np.rint(background * 255).astype(np.uint8)] + [
        np.rint(x * 255).astype(np.uint8) for x in straight
    ]
    peers = compositing_peers(straight, background)
    timings = time_interleaved(
        {
            "oiio_over_chain": peers["OpenImageIO over (float32)"],
            "pillow_alpha_composite_chain": peers["Pillow alpha_composite (straight unorm8)"],
            "composite_stack float32": lambda: composite_stack(premult),
            "composite_stack float32 front_to_back": lambda: composite_stack(premult, "front_to_back"),
            "composite_stack uint8 straight": lambda: composite_stack(codes),
        },
        repeat,
    )
    oiio, pillow = timings["oiio_over_chain"]["median_s"], timings["pillow_alpha_composite_chain"]["median_s"]
    rows = []
    for name, t in timings.items():
        row = {
            "size": f"{shape[1]}x{shape[0]}",
            "layers": layers,
            "name": name,
            "median_ms": round(t["median_s"] * 1e3, 3),
            "min_ms": round(t["min_s"] * 1e3, 3),
        }
        if "float32" in name:
            row.update(peer="oiio_over_chain", ratio=round(t["median_s"] / oiio, 3), target_ratio=1.0)
        elif "uint8" in name:
            row.update(
                peer="pillow_alpha_composite_chain", ratio=round(t["median_s"] / pillow, 3), target_ratio=1.5
            )
        if "ratio" in row:
            row["meets_target"] = row["ratio"] <= row["target_ratio"]
        rows.append(row)
    return rows


def run(repeat: int = 7, quick: bool = False) -> dict:
    """Run the benchmark and return the results (what ``main`` writes as JSON)."""
    sizes = ["1920x1080"] if quick else list(SIZES)
    machine = machine_info()
    float_rows = [row for size in sizes for row in _bench_float(size, repeat)]
    unorm8_rows, gl_float_rows = _bench_gl_blend(repeat)
    stack_rows = _bench_stacks(max(3, repeat // 2))
    machine["load_average_1min_after"] = machine_info().get("load_average_1min")
    return {
        "benchmark": "compositing.composite vs OpenImageIO ImageBufAlgo.over (float32 RGBA)",
        "engine": "numba fused" if numba_available() else "numpy",
        "repeat": repeat,
        "oiio_version": oiio.VERSION_STRING,
        "numpy_version": np.__version__,
        "machine": machine,
        "float32": float_rows,
        "unorm8": unorm8_rows,
        "gl_blend_float32": gl_float_rows,
        "stacks": stack_rows,
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
    for key, ratio, peer in (
        ("unorm8", "ratio_to_pillow_alpha_composite", "× Pillow alpha_composite"),
        ("gl_blend_float32", "ratio_to_composite_src_over", "× composite src_over"),
        ("stacks", "ratio", "× peer chain (OIIO float32 / Pillow uint8)"),
    ):
        print(
            markdown_table(
                ["size", "operation", "median ms", peer, "target", "ok"],
                [
                    [
                        r["size"],
                        r["name"],
                        f"{r['median_ms']:.2f}",
                        f"{r[ratio]:.2f}" if ratio in r else "",
                        r.get("target_ratio", ""),
                        {True: "yes", False: "NO"}.get(r.get("meets_target"), ""),
                    ]
                    for r in results[key]
                ],
            )
        )
        print()
    print(f"\nwrote {args.out / 'compositing.json'}")


if __name__ == "__main__":
    main()
