"""Compiled layer stacks: the whole stack in one pass per tile of pixels.

The image is cut into tiles of :data:`TILE` pixels. For each tile the accumulator lives in a
small buffer that stays in the first-level cache while every layer's pixels of that tile
stream through it; only the final tile is written out. Tiles are shared between the calling
thread and the helper pool of :mod:`compositing._fused`.

* Back to front: ``acc ← L[k] over acc`` for k = 1 … n−1.
* Front to back: ``acc ← L[k] dst_over acc`` (the next layer goes under) for k = n−2 … 0; a
  tile stops as soon as every one of its pixels has α ≥ the threshold, so the layers behind
  are not read for that tile.
* 8-bit straight alpha, back to front, as an RGBA8 straight-alpha buffer holds it: each layer
  and the stored value are premultiplied, composited with ``over``, unpremultiplied (α = 0
  keeps the colour) and stored back rounded to the nearest 8-bit value, in float32.

The per-pixel ``over``/``dst_over`` update is generated from the operators' (Fa, Fb)
expressions in :mod:`compositing.factors` with the code generator of
:mod:`compositing._fused`, so it performs the same float operations in the same order as
``composite`` and the stacks are bitwise equal to the layer-by-layer loop.

Layers are passed as an array of their data addresses (no copy of the stack); the caller
keeps the arrays alive during the call.
"""

from __future__ import annotations

import functools

import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from ._fused import _const_name, _term, factor_source, run_ranges
from ._kernel_cache import compile_kernel
from .factors import ALL_OPERATORS

__all__ = ["TILE", "stack_fused", "update_source"]

#: Pixels per tile: the accumulator (128 KB in float32) stays in the core's second-level cache while
#: each layer is read in 128 KB runs.
TILE = 8192

_NUMBA_TYPES = {"float32": types.float32, "float64": types.float64, "uint8": types.uint8}


def _pointer_intrinsic(nbtype: types.Type):
    """An intrinsic turning an integer address into a typed pointer (for ``numba.carray``)."""

    @intrinsic
    def as_pointer(typingctx, address):
        sig = types.CPointer(nbtype)(types.int64)

        def codegen(context, builder, signature, args):
            return builder.inttoptr(args[0], context.get_value_type(types.CPointer(nbtype)))

        return sig, codegen

    return as_pointer


def update_source(op: str, consts: set[float]) -> list[str]:
    """Lines computing ``m0..m3`` from the layer ``s0..s3`` (src) and accumulator ``d0..d3`` (dst)."""
    spec = ALL_OPERATORS[op]
    lines = [
        "sa = s3",
        "da = d3",
        f"fa = {factor_source(spec.fa_expr, consts)}",
        f"fb = {factor_source(spec.fb_expr, consts)}",
    ]
    for c in range(4):
        terms = [t for t in (_term(f"s{c}", spec.fa_expr, "fa"), _term(f"d{c}", spec.fb_expr, "fb")) if t]
        lines.append(f"m{c} = " + (" + ".join(f"({t})" for t in terms) if terms else _const_name(0.0)))
    return lines


def _check_layer(indent: str) -> list[str]:
    """Flag an alpha outside [0, 1] of the layer pixel s0..s3.

    A NaN or Inf needs no test here: ``over`` and ``dst_over`` carry it into every later
    value of that pixel (x·0 is NaN for x = ±Inf or NaN), so the finite check of the finished
    tile sees it.
    """
    return [f"{indent}bad |= np.int32((s3 < K_0_0) | (s3 > K_1_0))"]


def _opaque_scan(full: str) -> list[str]:
    """Lines finding ``start``: the frontmost layer opaque on every pixel of the tile (0 if none).

    Over such a layer ``over`` gives the layer itself whatever lies behind (its ``1 − α`` is
    an exact 0), so back to front starts there and the layers behind are not read. The scan
    of a layer stops at its first pixel that is not opaque: for most layers one cache line.
    """
    return [
        "start = 0",
        "for k in range(nl - 1, 0, -1):",
        "    layer = numba.carray(as_pointer(addrs[k]), (npix * 4,))",
        "    covered = True",
        "    for p in range(np.uint64(0), m):",
        f"        if layer[U4 * (p0 + p) + U3] != {full}:",
        "            covered = False",
        "            break",
        "    if covered:",
        "        start = k",
        "        break",
    ]


def _float_source(front_to_back: bool, consts: set[float]) -> str:
    """Float stacks: two layers per sweep over the tile (the accumulator stays in registers
    between them); front to back checks the tile's alpha before each pair."""
    update = update_source("dst_over" if front_to_back else "src_over", consts)
    first = "nl - 1" if front_to_back else "start"
    load = "s0 = {L}[j]; s1 = {L}[j + U1]; s2 = {L}[j + U2]; s3 = {L}[j + U3]"
    lines = [
        "def kernel(addrs, nl, npix, out, threshold, used, lo, hi):",
        "    bad = np.int32(0)",
        "    acc = np.empty(TILE * 4, dtype=out.dtype)",
        "    for t in range(lo, hi):",
        "        p0 = np.uint64(t) * U_TILE",
        "        m = np.uint64(min(TILE, npix - t * TILE))",
        *([] if front_to_back else [f"        {x}" for x in _opaque_scan("K_1_0")]),
        f"        layer = numba.carray(as_pointer(addrs[{first}]), (npix * 4,))",
        "        opaque = np.int32(1)",
        "        for p in range(np.uint64(0), m):",
        "            i = U4 * p",
        "            j = U4 * (p0 + p)",
        "            " + load.format(L="layer"),
        "            acc[i] = s0; acc[i + U1] = s1; acc[i + U2] = s2; acc[i + U3] = s3",
        *(["            opaque &= np.int32(s3 >= threshold)"] if front_to_back else []),
        *_check_layer("            "),
        "        read = 1",
    ]
    sweep_head = [
        "for p in range(np.uint64(0), m):",
        "    i = U4 * p",
        "    j = U4 * (p0 + p)",
        "    d0 = acc[i]; d1 = acc[i + U1]; d2 = acc[i + U2]; d3 = acc[i + U3]",
    ]
    sweep_tail = ["    acc[i] = m0; acc[i + U1] = m1; acc[i + U2] = m2; acc[i + U3] = m3"]

    def apply(name: str) -> list[str]:
        return ["    " + load.format(L=name), *(f"    {x}" for x in update), *_check_layer("    ")]

    if front_to_back:
        pair = [*apply("la"), "    d0 = m0; d1 = m1; d2 = m2; d3 = m3", *apply("lb")]
        track = ["    opaque &= np.int32(m3 >= threshold)"]
        body = [
            "k = nl - 2",
            "while k >= 0:",
            "    if opaque != 0:",
            "        break",
            "    opaque = np.int32(1)",
            "    la = numba.carray(as_pointer(addrs[k]), (npix * 4,))",
            "    if k >= 1:",
            "        lb = numba.carray(as_pointer(addrs[k - 1]), (npix * 4,))",
            *(f"        {x}" for x in [*sweep_head, *pair, *track, *sweep_tail]),
            "        read += 2",
            "        k -= 2",
            "    else:",
            *(f"        {x}" for x in [*sweep_head, *apply("la"), *track, *sweep_tail]),
            "        read += 1",
            "        k -= 1",
        ]
    else:
        pair = [*apply("la"), "    d0 = m0; d1 = m1; d2 = m2; d3 = m3", *apply("lb")]
        body = [
            "for k in range(start + 1, nl - 1, 2):",
            "    la = numba.carray(as_pointer(addrs[k]), (npix * 4,))",
            "    lb = numba.carray(as_pointer(addrs[k + 1]), (npix * 4,))",
            *(f"    {x}" for x in sweep_head + pair + sweep_tail),
            "    read += 2",
            "if (nl - 1 - start) % 2 == 1:",
            "    la = numba.carray(as_pointer(addrs[nl - 1]), (npix * 4,))",
            *(f"    {x}" for x in sweep_head + apply("la") + sweep_tail),
            "    read += 1",
        ]
    lines += [f"        {x}" for x in body]
    lines += [
        "        used[t] = read",
        "        for p in range(np.uint64(0), m):",
        "            i = U4 * p",
        "            j = U4 * (p0 + p)",
        "            out[j] = acc[i]; out[j + U1] = acc[i + U1]",
        "            out[j + U2] = acc[i + U2]; out[j + U3] = acc[i + U3]",
        "            z = (acc[i] + acc[i + U1]) + (acc[i + U2] + acc[i + U3])",
        "            bad |= np.int32(z - z != K_0_0)",
        "    return bad != 0",
    ]
    return "\n".join(lines) + "\n"


def _straight8_source(consts: set[float]) -> str:
    """Back to front on 8-bit straight layers, the accumulator stored as 8 bits after every layer."""
    update = update_source("src_over", consts)
    quantise = "rint(min(max({x}, K_0_0), K_1_0) * K255)"
    lines = [
        "def kernel(addrs, nl, npix, out, threshold, used, lo, hi):",
        "    acc = np.empty(TILE * 4, dtype=np.float32)",
        "    for t in range(lo, hi):",
        "        p0 = np.uint64(t) * U_TILE",
        "        m = np.uint64(min(TILE, npix - t * TILE))",
        *(f"        {x}" for x in _opaque_scan("np.uint8(255)")),
        "        layer = numba.carray(as_pointer(addrs[start]), (npix * 4,))",
        "        for q in range(np.uint64(0), U4 * m):",
        "            acc[q] = T(layer[U4 * p0 + q]) / K255",
        "        used[t] = nl - start",
        "        for k in range(start + 1, nl):",
        "            layer = numba.carray(as_pointer(addrs[k]), (npix * 4,))",
        "            for p in range(np.uint64(0), m):",
        "                i = U4 * p",
        "                j = U4 * (p0 + p)",
        "                # premultiply the layer and the stored value (straight k/255)",
        "                s3 = T(layer[j + U3]) / K255",
        "                s0 = T(layer[j]) / K255 * s3",
        "                s1 = T(layer[j + U1]) / K255 * s3",
        "                s2 = T(layer[j + U2]) / K255 * s3",
        "                d3 = acc[i + U3]",
        "                d0 = acc[i] * d3; d1 = acc[i + U1] * d3; d2 = acc[i + U2] * d3",
        *(f"                {x}" for x in update),
        "                # unpremultiply (alpha 0 keeps the colour) and store as 8 bits",
        "                w = m3 if m3 != K_0_0 else K_1_0",
        *(f"                acc[i + U{c}] = {quantise.format(x=f'(m{c} / w)')} / K255" for c in range(3)),
        f"                acc[i + U3] = {quantise.format(x='m3')} / K255",
        "        for q in range(np.uint64(0), U4 * m):",
        "            out[U4 * p0 + q] = np.uint8(rint(acc[q] * K255))",
        "    return False",
    ]
    return "\n".join(lines) + "\n"


@functools.cache
def _compiled(kind: str, dtype_name: str):
    consts: set[float] = {0.0, 1.0}
    if kind == "straight8":
        src = _straight8_source(consts)
        t = np.float32
    else:
        src = _float_source(kind == "front_to_back", consts)
        t = np.dtype(dtype_name).type
    namespace = {
        "np": np,
        "numba": numba,
        "rint": np.rint,
        "T": t,
        "K255": t(255.0),
        "TILE": TILE,
        "U_TILE": np.uint64(TILE),
        **{f"U{k}": np.uint64(k) for k in range(5)},
        "as_pointer": _pointer_intrinsic(_NUMBA_TYPES[dtype_name]),
        **{_const_name(v): t(v) for v in consts},
    }
    return compile_kernel(src, namespace, f"stack {kind} {dtype_name} tile={TILE}")


def stack_fused(layers: list[np.ndarray], kind: str, threshold: float = 1.0) -> tuple[np.ndarray, int, bool]:
    """The stack in one pass per tile; returns ``(image, layers_read, suspicious)``.

    ``layers``: C-contiguous arrays of one shape ``(..., 4)`` and one dtype (float32/float64
    premultiplied for ``kind`` ``"back_to_front"``/``"front_to_back"``, uint8 straight for
    ``"straight8"``), backmost first. ``layers_read`` is the most layers any tile read.
    ``suspicious``: some value read may be non-finite or an alpha outside [0, 1], or the
    result non-finite; the caller then runs the exact checks.
    """
    first = layers[0]
    dtype_name = first.dtype.name
    kernel = _compiled(kind, dtype_name)
    npix = first.size // 4
    out = np.empty(first.shape, dtype=first.dtype)
    addrs = np.array([layer.ctypes.data for layer in layers], dtype=np.int64)
    tiles = -(-npix // TILE)
    used = np.zeros(max(tiles, 1), dtype=np.int64)
    t = np.float32 if kind == "straight8" else first.dtype.type
    args = (addrs, len(layers), npix, out.reshape(-1), t(threshold), used)
    suspicious = run_ranges(kernel, args, tiles, min_per_range=2)
    if tiles:
        read = int(used.max())
    else:  # an empty image: what the numpy engine reports (its loop does not look at pixels)
        read = len(layers) if kind == "straight8" else 1
    return out, read, suspicious
