"""``gl_blend`` against Mesa's llvmpipe blending the same 1920×1080 frame, measured in the same run.

For a few blend states (the Porter-Duff ``src_over`` pair, a separate-alpha state, a
constant-colour state, ``SRC_ALPHA_SATURATE``) and both targets (RGBA32F / ``"float32"`` and
RGBA8 / ``"unorm8"``) this times

* ``compositing.gl_blend`` on the numpy frame (for RGBA8, on the frame's 8-bit codes as
  ``uint8`` arrays, in and out, as an RGBA8 framebuffer holds them), and
* :func:`oracles.gl_blend.mesa_blend` on the same pixels: texture upload, one draw, readback
  (the shader for the state is compiled in a warm-up call first, so compilation is not timed).

Each is the best of ``--repeat`` runs (the least disturbed by other processes), the two
alternating so that both see the same machine load. The ratio is ``gl_blend time / Mesa
time`` (< 1: numpy is faster). The JSON also records the agreement of
the two on that frame: max abs difference (float32) and the share of values one step apart
(unorm8). Usage::

    .venv/bin/python -m benchmarks.bench_gl_blend [--out benchmarks/results] [--repeat 5]

Writes ``gl_blend.json`` to ``--out``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchmarks._util import write_json
from compositing.gl_blend import gl_blend, gl_factors
from oracles.egl import gl_context
from oracles.gl_blend import BlendState, mesa_blend

__all__ = ["main", "run"]

WIDTH, HEIGHT = 1920, 1080

STATES = {
    "src_over": BlendState(*gl_factors("src_over")),
    "separate_alpha": BlendState(
        "SRC_ALPHA", "ONE_MINUS_SRC_ALPHA", "FUNC_ADD", "ONE", "ONE_MINUS_SRC_ALPHA", "FUNC_ADD"
    ),
    "constant_colour": BlendState(
        "CONSTANT_COLOR", "ONE_MINUS_CONSTANT_COLOR", constant=(0.25, 0.5, 0.75, 0.5)
    ),
    "src_alpha_saturate": BlendState("SRC_ALPHA_SATURATE", "ONE"),
}


def _paired_best_times(
    first: Callable[[], object], second: Callable[[], object], repeat: int
) -> tuple[float, float]:
    """Best wall-clock time of each, the two run alternately so both see the same machine load."""
    first(), second()  # warm-up: caches, shader compilation
    times: tuple[list[float], list[float]] = ([], [])
    for _ in range(repeat):
        for fn, log in zip((first, second), times, strict=True):
            start = time.perf_counter()
            fn()
            log.append(time.perf_counter() - start)
    return min(times[0]), min(times[1])


def _frame(rng: np.random.Generator) -> np.ndarray:
    """A premultiplied float32 frame with alpha in [0, 1]."""
    alpha = rng.uniform(0, 1, (HEIGHT, WIDTH, 1)).astype(np.float32)
    return np.concatenate([rng.uniform(0, 1, (HEIGHT, WIDTH, 3)).astype(np.float32) * alpha, alpha], axis=-1)


def _ours(src: np.ndarray, dst: np.ndarray, state: BlendState, target: str) -> np.ndarray:
    return gl_blend(
        src,
        dst,
        state.src_factor,
        state.dst_factor,
        state.equation,
        src_factor_alpha=state.src_factor_alpha,
        dst_factor_alpha=state.dst_factor_alpha,
        equation_alpha=state.equation_alpha,
        constant=state.constant,
        target=target,
    )


def run(out_dir: str | os.PathLike, *, repeat: int = 5) -> dict:
    """Run the benchmark, write ``gl_blend.json`` into ``out_dir`` and return its content."""
    info = gl_context()
    rng = np.random.default_rng(1)
    src, dst = _frame(rng), _frame(rng)
    src_list, dst_list = src.reshape(1, -1, 4), dst.reshape(1, -1, 4)
    dst_bytes = np.rint(dst_list * 255).astype(np.uint8)
    # llvmpipe quantises the float fragment colour to 8 bits; gl_blend takes those codes.
    src_bytes = np.rint(np.clip(src, 0, 1) * 255).astype(np.uint8)
    dst_codes = dst_bytes.reshape(dst.shape)

    cases = []
    for name, state in STATES.items():
        for target in ("float32", "unorm8"):
            mesa_dst = dst_list if target == "float32" else dst_bytes
            ours_src, ours_dst = (src, dst) if target == "float32" else (src_bytes, dst_codes)
            t_ours, t_mesa = _paired_best_times(
                lambda s=state, t=target, a=ours_src, d=ours_dst: _ours(a, d, s, t),
                lambda s=state, t=target, d=mesa_dst: mesa_blend(src_list, d, [s], t),
                repeat,
            )
            model = _ours(ours_src, ours_dst, state, target).reshape(1, -1, 4)
            got = mesa_blend(src_list, mesa_dst, [state], target)
            if target == "float32":
                agreement = {"max_abs_difference": float(np.abs(model - got).max())}
            else:
                steps = np.abs(model.astype(np.int64) - got)
                agreement = {"max_steps": int(steps.max()), "share_one_step_apart": float(np.mean(steps > 0))}
            cases.append(
                {
                    "state": name,
                    "target": target,
                    "gl_blend_s": t_ours,
                    "mesa_s": t_mesa,
                    "ratio_gl_blend_over_mesa": t_ours / t_mesa,
                    **agreement,
                }
            )
            print(
                f"{name:20s} {target:8s} gl_blend {t_ours * 1e3:7.1f} ms  Mesa {t_mesa * 1e3:7.1f} ms  "
                f"ratio {t_ours / t_mesa:5.2f}  {agreement}"
            )
    result = {
        "benchmark": "gl_blend",
        "frame": [WIDTH, HEIGHT],
        "repeat": repeat,
        "timing": "best of repeat, wall clock; Mesa includes texture upload, one draw and readback",
        "mesa": {"renderer": info.renderer, "version": info.version},
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor(),
            "cpus": os.cpu_count(),
        },
        "numpy": np.__version__,
        "cases": cases,
    }
    write_json(Path(out_dir) / "gl_blend.json", result)
    return result


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="benchmarks/results", help="directory for gl_blend.json")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per case (best is kept)")
    args = parser.parse_args(argv)
    run(args.out, repeat=args.repeat)


if __name__ == "__main__":
    main()
