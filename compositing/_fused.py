"""Optional numba engine: one fused, multi-threaded pass per operator.

The kernel source is generated from the factor expression trees of
:mod:`compositing.factors` (no formula is written here), compiled once per
(operator, dtype) on first use. Per pixel it reads the eight inputs once,
evaluates Fa and Fb in the image dtype with the same operations in the same
order as the numpy engine (constants typed to the dtype, no fast-math, no fused
multiply-add), and writes the four outputs. The results are therefore bitwise
equal to :func:`compositing.operators.composite` with ``engine="numpy"``; the
tests check that.

Each call splits the pixels into a few ranges per core; the calling thread and a
small pool of helper threads take ranges until none is left (the compiled loop
releases the GIL), so a thread slowed down by another process does not hold up
the rest. The same pass flags suspicious input or output (non-finite values,
alpha outside [0, 1] or NaN) so the caller need not read the images again; the
exact checks of :mod:`compositing.validate` then run only when the flag is raised.
"""

from __future__ import annotations

import functools
import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from ._kernel_cache import compile_kernel
from .factors import Expr, OperatorSpec

__all__ = ["composite_fused", "factor_source", "kernel_source", "run_ranges"]

#: Threads working on one call, the calling thread included (the kernel releases the GIL).
THREADS = max(1, min(8, os.cpu_count() or 1))

#: Below this many pixels a call runs on the calling thread only; no range is smaller.
MIN_PIXELS_PER_THREAD = 1 << 15

#: Ranges per thread: more ranges than threads let an idle thread take over the work of one
#: slowed down by another process (dynamic load balancing).
RANGES_PER_THREAD = 8


def _const_name(value: float) -> str:
    return "K_" + repr(float(value)).replace(".", "_").replace("-", "m")


def factor_source(expr: Expr, consts: set[float]) -> str:
    """Python/numba source of one factor expression over the scalars ``sa``, ``da``.

    Constants are emitted as names bound to dtype-typed values (collected in
    ``consts``) so float32 arithmetic stays float32, as in numpy.
    """
    if expr.op == "const":
        consts.add(float(expr.value))  # type: ignore[arg-type]
        return _const_name(float(expr.value))  # type: ignore[arg-type]
    if expr.op == "var":
        return str(expr.value)
    a, b = (factor_source(x, consts) for x in expr.args)
    consts.update((0.0, 1.0))
    infix = {"add": "+", "sub": "-", "mul": "*"}
    if expr.op in infix:
        return f"({a} {infix[expr.op]} {b})"
    if expr.op == "min":
        return f"min({a}, {b})"
    if expr.op == "max":
        return f"max({a}, {b})"
    if expr.op == "lt":
        return f"({_const_name(1.0)} if {a} < {b} else {_const_name(0.0)})"
    if expr.op == "gt":
        return f"({_const_name(1.0)} if {a} > {b} else {_const_name(0.0)})"
    if expr.op == "safe_div":
        return f"(({a}) / ({b}) if ({b}) != {_const_name(0.0)} else {_const_name(0.0)})"
    raise ValueError(f"unknown factor operation {expr.op!r}")


def _term(channel: str, factor: Expr, code: str) -> str | None:
    if factor.is_const and float(factor.value) == 0.0:  # type: ignore[arg-type]
        return None
    if factor.is_const and float(factor.value) == 1.0:  # type: ignore[arg-type]
        return channel
    return f"{channel} * {code}"


def _is_zero(factor: Expr) -> bool:
    return factor.is_const and float(factor.value) == 0.0  # type: ignore[arg-type]


def kernel_source(spec: OperatorSpec, lerp: bool) -> tuple[str, set[float]]:
    """Source of the fused kernel for one operator, and the constants it needs.

    ``lerp`` selects the variant that mixes with the destination (factor < 1); two
    variants keep the per-pixel loop free of a branch.
    """
    consts: set[float] = {0.0, 1.0}
    fa_code = factor_source(spec.fa_expr, consts)
    fb_code = factor_source(spec.fb_expr, consts)
    lines = []
    for c in range(4):
        terms = [t for t in (_term(f"s{c}", spec.fa_expr, "fa"), _term(f"d{c}", spec.fb_expr, "fb")) if t]
        value = " + ".join(f"({t})" for t in terms) if terms else _const_name(0.0)
        lines.append(f"        m{c} = {value}")
    if lerp:
        lines += [f"        m{c} = d{c} * keep + m{c} * mix" for c in range(4)]
    body = "\n".join(lines)
    # The flag: a NaN or Inf in an input reaches the outputs (x·0 is NaN for x = ±Inf or
    # NaN) unless the input is skipped by a constant-zero factor; add those inputs as well.
    checked = ["(m0 + m1)", "(m2 + m3)"]
    if _is_zero(spec.fa_expr):
        checked += ["(s0 + s1)", "(s2 + s3)"]
    if _is_zero(spec.fb_expr) and not lerp:
        checked += ["(d0 + d1)", "(d2 + d3)"]
    k0, k1 = _const_name(0.0), _const_name(1.0)
    src = f"""
def kernel(s, d, o, keep, mix, lo, hi):
    bad = np.int32(0)
    # Unsigned indices: no negative-index wrap-around code, so LLVM vectorises the loop.
    for p in range(np.uint64(lo), np.uint64(hi)):
        i = np.uint64(4) * p
        s0 = s[i]; s1 = s[i + U1]; s2 = s[i + U2]; s3 = s[i + U3]
        d0 = d[i]; d1 = d[i + U1]; d2 = d[i + U2]; d3 = d[i + U3]
        sa = s3
        da = d3
        fa = {fa_code}
        fb = {fb_code}
{body}
        o[i] = m0; o[i + U1] = m1; o[i + U2] = m2; o[i + U3] = m3
        # Flag without a branch: z is non-finite iff some value is (or the sum overflows,
        # a false alarm the exact checks clear); alpha outside [0, 1] or NaN.
        z = {" + ".join(checked)}
        bad |= np.int32((z - z != {k0}) | (min(sa, da) < {k0}) | (max(sa, da) > {k1}))
    return bad != 0
"""
    return src, consts


@functools.cache
def _compiled(name: str, spec: OperatorSpec, dtype_name: str, lerp: bool):
    src, consts = kernel_source(spec, lerp)
    t = np.dtype(dtype_name).type
    namespace = {
        "np": np,
        "numba": numba,
        "U1": np.uint64(1),
        "U2": np.uint64(2),
        "U3": np.uint64(3),
        **{_const_name(v): t(v) for v in consts},
    }
    return compile_kernel(src, namespace, f"fused {name} {dtype_name} lerp={lerp}")


@functools.cache
def _pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=max(1, THREADS - 1), thread_name_prefix="compositing")


if hasattr(os, "register_at_fork"):  # a forked child has none of the parent's threads: start afresh
    os.register_at_fork(after_in_child=_pool.cache_clear)


def composite_fused(
    spec: OperatorSpec, src: np.ndarray, dst: np.ndarray, factor: float
) -> tuple[np.ndarray, bool]:
    """``composite`` in one fused pass; returns ``(result, suspicious)``.

    ``src`` and ``dst`` must be C-contiguous float32/float64 arrays of equal shape
    and dtype; ``factor`` a float in [0, 1]. ``suspicious`` is True when some value
    may be non-finite or some alpha may lie outside [0, 1]; the caller then runs
    the exact checks.
    """
    kernel = _compiled(spec.name, spec, src.dtype.name, factor != 1.0)
    out = np.empty_like(src)
    t = src.dtype.type
    args = (src.reshape(-1), dst.reshape(-1), out.reshape(-1), t(1.0 - factor), t(factor))
    return out, run_ranges(kernel, args, src.size // 4)


def run_ranges(kernel, args: tuple, n: int, min_per_range: int = MIN_PIXELS_PER_THREAD) -> bool:
    """Run ``kernel(*args, lo, hi)`` over ``[0, n)`` split into ranges; True if any call returned True.

    The ranges go to the calling thread and the helper pool, each thread taking the next
    range until none is left (the kernels release the GIL). Ranges hold at least
    ``min_per_range`` items; a small ``n`` runs on the calling thread alone.
    """
    parts = max(1, min(THREADS * RANGES_PER_THREAD, n // max(1, min_per_range)))
    if parts == 1:
        return bool(kernel(*args, 0, n))
    bounds = np.linspace(0, n, parts + 1).astype(np.int64).tolist()
    ranges = iter(itertools.pairwise(bounds))
    lock = threading.Lock()

    def work() -> bool:
        """Take ranges until none is left (the calling thread works too)."""
        flagged = False
        while True:
            with lock:
                pixel_range = next(ranges, None)
            if pixel_range is None:
                return flagged
            flagged |= bool(kernel(*args, *pixel_range))

    helpers = [_pool().submit(work) for _ in range(min(THREADS, parts) - 1)]
    flagged = work()
    return any([flagged] + [f.result() for f in helpers])
