"""The compiled OpenGL blend stage: one fused, multi-threaded pass per call, generated from the table.

The kernel source is generated from the factor and equation expression trees of
:mod:`compositing._gl_exprs` (``GL_FACTOR_EXPRS``, ``GL_EQUATION_EXPRS``); no formula is
written here. Two kinds of kernel are generated:

* a *specialised* kernel per blend state (the six names), in which the factor and equation
  expressions are inlined: compiled on first use, for large images;
* a *generic* kernel per (mode, dtype) taking the state as integers at run time (an
  ``if`` chain over the same table, one branch per name): compiled once, used for small
  images so that a program trying many states does not compile one kernel per state.

Three modes:

* ``"float"`` (``target="float32"``): the table evaluated in the image dtype with the same
  operations in the same order as the numpy reference (constants typed to the dtype, no
  fast-math, no fused multiply-add, products with an exact 0 or 1 skipped as the reference
  skips them), so the results are bitwise equal to it.
* ``"codes"`` (``target="unorm8"`` on ``uint8`` arrays): the table on the 8-bit codes in
  integer arithmetic. A factor is a code (its constants 0 and 1 become 0 and 255), a
  weighted colour ``s·S`` is the product of two codes (value·255²), and the result
  ``N = s·S ± d·D`` is clamped to [0, 255²] and rounded to ``round(N/255)`` as
  ``((N + 128)·257) >> 16``, exact for every N in that range. This is the rounding model of
  the reference (quantise, blend exactly, round once): the exact value ``N/255`` is never
  halfway between two codes, and the reference's float evaluation is far closer to it than
  the 1/510 step that would be needed to round differently. MIN/MAX take the codes as they are.
* ``"quantise"`` (``target="unorm8"`` on float arrays): the inputs are quantised in the
  kernel exactly as the reference quantises them (clamp, ·255, round half to even, in the
  dtype), blended as in ``"codes"`` and stored as ``k/255`` in the dtype.

Each pass also flags a non-finite input or (float mode) output so that the caller runs
the exact checks only when needed.
"""

from __future__ import annotations

import functools

import numpy as np

from ._fused import MIN_PIXELS_PER_THREAD, run_ranges
from ._gl_exprs import GL_EQUATION_EXPRS, GL_FACTOR_EXPRS, exact_factor, uses_factors
from ._kernel_cache import compile_kernel
from .factors import Expr

__all__ = ["SPECIALISE_MIN_PIXELS", "generic_source", "gl_blend_fused", "kernel_source"]

#: From this many pixels on a blend state gets its own compiled kernel (about 0.3 s once);
#: smaller calls use the generic kernel, compiled once per mode and dtype.
SPECIALISE_MIN_PIXELS = 1 << 16

FACTOR_NAMES = tuple(GL_FACTOR_EXPRS)
EQUATION_NAMES = tuple(GL_EQUATION_EXPRS)
MODES = ("float", "codes", "quantise")

# Names the generated source uses for typed constants.
_FLOAT_CONSTS = {0.0: "K0", 1.0: "K1"}


def _emit(expr: Expr, names: dict[str, str], integer: bool) -> str:
    """Source of one expression of the table over scalar names (``s``, ``d``, ``c``, ``sa``, ...)."""
    if expr.op == "const":
        value = float(expr.value)  # type: ignore[arg-type]
        if integer:
            code = value * 255.0
            if code != int(code):
                raise AssertionError(f"constant {value} has no 8-bit code")
            return f"np.int32({int(code)})"
        return _FLOAT_CONSTS[value]
    if expr.op == "var":
        return names[str(expr.value)]
    a, b = (_emit(x, names, integer) for x in expr.args)
    infix = {"add": "+", "sub": "-", "mul": "*"}
    if expr.op in infix:
        return f"({a} {infix[expr.op]} {b})"
    if expr.op == "min":  # numpy's minimum/maximum on non-NaN values
        return f"({a} if {a} < {b} else {b})"
    if expr.op == "max":
        return f"({a} if {a} > {b} else {b})"
    raise AssertionError(f"operation {expr.op!r} is not used by the GL table")


def _names(channel: int) -> dict[str, str]:
    """Scalar names for one component: the colour's own component and the three alphas."""
    return {
        "s": f"s{channel}",
        "d": f"d{channel}",
        "c": f"c{channel}",
        "sa": "s3",
        "da": "d3",
        "ca": "c3",
    }


def _round_codes(n: str) -> str:
    """round(N / 255) for N clamped to [0, 255²] (exact: verified for every N by the tests)."""
    return (
        f"(((min(max({n}, np.int64(0)), np.int64(65025)) + np.int64(128)) * np.int64(257)) >> np.int64(16))"
    )


def _channel_lines(channel: int, state: tuple[str, str, str], part: int, integer: bool) -> list[str]:
    """Lines computing ``r<channel>`` for one component with an inlined state."""
    sf, df, eq = state
    names = _names(channel)
    lines = []
    if uses_factors(eq):
        for key, colour, factor in (("sw", "s", sf), ("dw", "d", df)):
            var = f"{key}{channel}"
            exact = exact_factor(factor, part)
            x = names[colour]
            if integer:
                f = _emit(GL_FACTOR_EXPRS[factor][part], names, integer=True)
                lines.append(f"{var} = np.int64({x}) * np.int64({f})")
            elif exact == 0.0:
                lines.append(f"{var} = K0")
            elif exact == 1.0:
                lines.append(f"{var} = {x}")
            else:
                lines.append(f"{var} = {x} * {_emit(GL_FACTOR_EXPRS[factor][part], names, integer=False)}")
        names = {**names, "sw": f"sw{channel}", "dw": f"dw{channel}"}
    value = _emit(GL_EQUATION_EXPRS[eq], names, integer)
    if integer and uses_factors(eq):
        value = _round_codes(value)
    lines.append(f"r{channel} = {value}")
    return lines


def _load_store(mode: str) -> tuple[list[str], list[str], str]:
    """Lines loading s0..s3, d0..d3; lines storing r0..r3; the flag expression."""
    load = []
    for x in "sd":
        for k in range(4):
            index = "i" if k == 0 else f"i + U{k}"
            if mode == "float":
                load.append(f"{x}{k} = {x}[{index}]")
            elif mode == "codes":
                load.append(f"{x}{k} = np.int32({x}[{index}])")
            else:  # quantise as the reference: clip to [0, 1], times 255, round half to even
                load.append(f"{x}{k}f = {x}[{index}]")
                load.append(f"{x}{k} = np.int32(np.rint(min(max({x}{k}f, K0), K1) * K255))")
    store = []
    for k in range(4):
        index = "i" if k == 0 else f"i + U{k}"
        if mode == "float":
            store.append(f"o[{index}] = r{k}")
        elif mode == "codes":
            store.append(f"o[{index}] = np.uint8(r{k})")
        else:
            store.append(f"o[{index}] = T(r{k}) / K255")
    if mode == "float":
        flag = "(s0 + s1) + (s2 + s3) + (d0 + d1) + (d2 + d3) + (r0 + r1) + (r2 + r3)"
    elif mode == "quantise":
        flag = "(s0f + s1f) + (s2f + s3f) + (d0f + d1f) + (d2f + d3f)"
    else:
        flag = ""
    return load, store, flag


def _kernel(params: str, prologue: list[str], body: list[str], mode: str) -> str:
    load, store, flag = _load_store(mode)
    inner = load + body + store
    if flag:
        inner += [f"z = {flag}", "bad |= np.int32(z - z != K0)"]  # NaN or Inf somewhere (or a sum overflow)
    lines = [
        f"def kernel(s, d, o, c0, c1, c2, c3, {params}lo, hi):",
        *(f"    {x}" for x in prologue),
        "    bad = np.int32(0)",
        "    # Unsigned indices: no negative-index wrap-around code, so LLVM can vectorise the loop.",
        "    for p in range(np.uint64(lo), np.uint64(hi)):",
        "        i = U4 * p",
        *(f"        {x}" for x in inner),
        "    return bad != 0",
    ]
    return "\n".join(lines) + "\n"


def kernel_source(rgb_state: tuple[str, str, str], alpha_state: tuple[str, str, str], mode: str) -> str:
    """Source of the specialised kernel for one blend state (six names) and mode."""
    integer = mode != "float"
    body = []
    for channel in range(3):
        body += _channel_lines(channel, rgb_state, 0, integer)
    body += _channel_lines(3, alpha_state, 1, integer)
    return _kernel("", [], body, mode)


def generic_source(mode: str) -> str:
    """Source of the generic kernel: the state as integers (indices into the table) at run time.

    Helper functions ``factor0`` (RGB part) and ``factor1`` (alpha part) choose a factor by
    index, ``weigh0``/``weigh1`` skip the exact products as the specialised kernels do, and
    ``equation`` chooses an equation; every branch is generated from the table.
    """
    integer = mode != "float"
    generic_names = {"s": "s", "d": "d", "c": "c", "sa": "sa", "da": "da", "ca": "ca"}
    helpers = []
    for part in (0, 1):
        lines = [f"def factor{part}(code, s, d, c, sa, da, ca):"]
        for k, name in enumerate(FACTOR_NAMES):
            expr = _emit(GL_FACTOR_EXPRS[name][part], generic_names, integer)
            lines.append(f"    if code == {k}:\n        return {expr}")
        lines.append("    return " + ("np.int32(0)" if integer else "K0"))
        helpers.append("\n".join(lines))
        lines = [f"def weigh{part}(code, x, f):"]
        if integer:
            lines.append("    return np.int64(x) * np.int64(f)")
        else:
            for k, name in enumerate(FACTOR_NAMES):
                exact = exact_factor(name, part)
                if exact is not None:
                    lines.append(f"    if code == {k}:\n        return {'K0' if exact == 0.0 else 'x'}")
            lines.append("    return x * f")
        helpers.append("\n".join(lines))
    lines = ["def equation(code, sw, dw, s, d):"]
    names = {"sw": "sw", "dw": "dw", "s": "s", "d": "d"}
    for k, name in enumerate(EQUATION_NAMES):
        value = _emit(GL_EQUATION_EXPRS[name], names, integer)
        if integer:
            value = _round_codes(value) if uses_factors(name) else f"np.int64({value})"
        lines.append(f"    if code == {k}:\n        return {value}")
    lines.append("    return " + ("np.int64(0)" if integer else "K0"))
    helpers.append("\n".join(lines))

    body = []
    for channel in range(4):
        part = 0 if channel < 3 else 1
        sf, df, eq = ("sf", "df", "eq") if part == 0 else ("sfa", "dfa", "eqa")
        n = _names(channel)
        args = f"{n['s']}, {n['d']}, {n['c']}, s3, d3, c3"
        body += [
            f"fs{channel} = factor{part}({sf}, {args})",
            f"fd{channel} = factor{part}({df}, {args})",
            f"r{channel} = equation({eq}, weigh{part}({sf}, {n['s']}, fs{channel}), "
            f"weigh{part}({df}, {n['d']}, fd{channel}), {n['s']}, {n['d']})",
        ]
    prologue = [
        "sf = state[0]; df = state[1]; eq = state[2]",
        "sfa = state[3]; dfa = state[4]; eqa = state[5]",
    ]
    return "\n\n".join(helpers) + "\n\n" + _kernel("state, ", prologue, body, mode)


def _namespace(dtype_name: str) -> dict:
    t = np.dtype(dtype_name).type if dtype_name != "uint8" else np.float32
    return {
        "np": np,
        "T": t,
        "U1": np.uint64(1),
        "U2": np.uint64(2),
        "U3": np.uint64(3),
        "U4": np.uint64(4),
        "K0": t(0.0),
        "K1": t(1.0),
        "K255": t(255.0),
    }


def _build(src: str, label: str, dtype_name: str, helper_names: tuple[str, ...] = ()):
    # helpers are compiled first so that the kernel calls compiled functions
    return compile_kernel(src, _namespace(dtype_name), f"gl blend {label} {dtype_name}", helpers=helper_names)


@functools.cache
def _specialised(
    rgb_state: tuple[str, str, str], alpha_state: tuple[str, str, str], mode: str, dtype_name: str
):
    src = kernel_source(rgb_state, alpha_state, mode)
    return _build(src, f"{rgb_state} {alpha_state} {mode}", dtype_name)


@functools.cache
def _generic(mode: str, dtype_name: str):
    helpers = ("factor0", "weigh0", "factor1", "weigh1", "equation")
    return _build(generic_source(mode), f"generic {mode}", dtype_name, helpers)


def gl_blend_fused(
    src: np.ndarray,
    dst: np.ndarray,
    constant: np.ndarray,
    rgb_state: tuple[str, str, str],
    alpha_state: tuple[str, str, str],
    mode: str,
) -> tuple[np.ndarray, bool]:
    """The blend in one pass; returns ``(result, suspicious)``.

    ``src`` and ``dst``: C-contiguous arrays of one shape ``(..., 4)`` and one dtype (float32
    or float64; uint8 for ``mode="codes"``). ``constant``: four values in that dtype, or four
    int codes for the unorm8 modes. ``suspicious`` is True when some input or output may be
    non-finite; the caller then runs the exact checks.
    """
    if mode not in MODES:
        raise ValueError(f"mode: expected one of {MODES}, got {mode!r}")
    n = src.size // 4
    dtype_name = src.dtype.name
    if n >= SPECIALISE_MIN_PIXELS:
        kernel = _specialised(tuple(rgb_state), tuple(alpha_state), mode, dtype_name)
        extra: tuple = ()
    else:
        kernel = _generic(mode, dtype_name)
        state = [FACTOR_NAMES.index(rgb_state[0]), FACTOR_NAMES.index(rgb_state[1])]
        state += [EQUATION_NAMES.index(rgb_state[2])]
        state += [FACTOR_NAMES.index(alpha_state[0]), FACTOR_NAMES.index(alpha_state[1])]
        state += [EQUATION_NAMES.index(alpha_state[2])]
        extra = (np.array(state, dtype=np.int64),)
    out = np.empty(src.shape, dtype=src.dtype)
    if mode == "float":
        c = [src.dtype.type(v) for v in constant]
    else:
        c = [np.int32(v) for v in constant]
    args = (src.reshape(-1), dst.reshape(-1), out.reshape(-1), *c, *extra)
    return out, run_ranges(kernel, args, n, MIN_PIXELS_PER_THREAD)
