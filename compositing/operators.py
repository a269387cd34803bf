"""Porter-Duff compositing on premultiplied RGBA, driven by the factor table.

``composite(src, dst, op)`` computes ``src·Fa + dst·Fb`` on all four channels with
the (Fa, Fb) of :mod:`compositing.factors` (Porter & Duff 1984, table 1; W3C
Compositing Level 1 §9.1), then mixes with the destination:
``result = dst·(1 − factor) + op(src, dst)·factor``, as Blender's Alpha Over
(``interpolate(bg, m, Factor)``) and Nuke's Merge ``mix`` do.

Two engines compute the same thing:

* ``"numpy"``: the reference. It evaluates Fa and Fb on the alpha planes with
  :func:`compositing.factors.evaluate` and skips products with constant 0 or 1.
* ``"numba"``: one fused, multi-threaded pass per pixel generated from the same
  expression trees (:mod:`compositing._fused`). Tests show it is bitwise equal to
  the numpy engine. ``"auto"`` picks it for large contiguous same-shape inputs with
  a scalar factor when numba is installed.
"""

from __future__ import annotations

import difflib

import numpy as np

from ._engine import ENGINES, use_compiled
from .factors import ALL_OPERATORS, OperatorSpec, evaluate
from .validate import as_rgba, broadcast_shapes, check_alpha_range, check_factor, check_finite

__all__ = ["ENGINES", "composite", "resolve_operator"]

#: Below this many pixels ``engine="auto"`` stays with numpy (no compilation for small inputs).
FUSED_MIN_PIXELS = 1 << 16


def resolve_operator(op: str | OperatorSpec) -> OperatorSpec:
    """The :class:`OperatorSpec` for an operator name (case-insensitive, ``-`` read as ``_``).

    Raises:
        ValueError: unknown name; the message lists the valid names and the closest match.
        TypeError: ``op`` is not a string.
    """
    if isinstance(op, OperatorSpec):
        return op
    if not isinstance(op, str):
        raise TypeError(f"op: expected an operator name (str), got {type(op).__name__}")
    key = op.strip().lower().replace("-", "_")
    if key in ALL_OPERATORS:
        return ALL_OPERATORS[key]
    close = difflib.get_close_matches(key, ALL_OPERATORS, n=1, cutoff=0.5)
    hint = f" Did you mean {close[0]!r}?" if close else ""
    raise ValueError(f"op: unknown operator {op!r}.{hint} Valid operators: {', '.join(ALL_OPERATORS)}")


def _weighted(x: np.ndarray, weight: np.ndarray | float) -> np.ndarray | None:
    """``x·weight`` with the weight broadcast over RGBA; None for a constant 0, ``x`` itself for 1."""
    if isinstance(weight, float):
        if weight == 0.0:
            return None
        if weight == 1.0:
            return x
        return x * x.dtype.type(weight)
    return x * weight[..., None]


def _composite_numpy(
    spec: OperatorSpec, src: np.ndarray, dst: np.ndarray, factor: float | np.ndarray, shape: tuple[int, ...]
) -> np.ndarray:
    """Reference engine: the factor trees evaluated on the alpha planes, then one multiply-add."""
    sa, da = src[..., 3], dst[..., 3]
    terms = [_weighted(src, evaluate(spec.fa_expr, sa, da)), _weighted(dst, evaluate(spec.fb_expr, sa, da))]
    terms = [t for t in terms if t is not None]
    if not terms:
        mixed = np.zeros(shape, dtype=src.dtype)
    elif len(terms) == 1:
        mixed = terms[0]
    else:
        mixed = terms[0] + terms[1]
    if isinstance(factor, float):
        if factor != 1.0:
            t = src.dtype.type
            mixed = dst * t(1.0 - factor) + mixed * t(factor)
    else:
        f = factor.astype(src.dtype, copy=False)[..., None]
        mixed = dst * (1 - f) + mixed * f
    if mixed is src or mixed is dst or mixed.shape != shape:
        # Never hand back an input (``src``/``dst`` operators) or a broadcast view.
        mixed = np.array(np.broadcast_to(mixed, shape), order="C")
    return mixed


def composite(
    src: np.ndarray,
    dst: np.ndarray,
    op: str = "src_over",
    *,
    factor: float | np.ndarray = 1.0,
    engine: str = "auto",
) -> np.ndarray:
    """Composite premultiplied ``src`` (A) with ``dst`` (B) by a named operator.

    ``result = dst·(1 − factor) + (src·Fa + dst·Fb)·factor`` on all four channels,
    with (Fa, Fb) from :data:`compositing.factors.ALL_OPERATORS` (Porter & Duff
    1984, table 1; Blender 5.0 Alpha Over for disjoint/conjoint over; pixman for
    the rest of that family). Results are not clamped: HDR colour stays HDR.

    Args:
        src: the source / foreground A, linear premultiplied RGBA ``(..., 4)``,
            float32 or float64 (a single colour ``(4,)`` broadcasts). Alpha in [0, 1].
        dst: the destination / background B, same conventions.
        op: operator name: one of :data:`compositing.OPERATORS` (the 12
            Porter-Duff operators), ``plus``, ``disjoint_over``, ``conjoint_over``
            or the pixman ``disjoint_*``/``conjoint_*`` family.
        factor: mix amount in [0, 1]: a number, or a float array broadcastable to
            the pixel shape (the image shape without the RGBA axis).
        engine: ``"auto"``, ``"numpy"`` (the reference) or ``"numba"`` (fused
            single pass; needs equal shapes, equal dtypes and a scalar factor).

    Returns:
        A new array of the broadcast shape, in the common dtype of
        ``src`` and ``dst`` (float64 if either is float64).

    Raises:
        ValueError: unknown operator or engine, last axis not 4, shapes that do not
            broadcast, NaN/Inf, alpha or factor outside [0, 1].
        TypeError: integer or other non-float arrays.
    """
    spec = resolve_operator(op)
    compiled = use_compiled(engine)
    src = as_rgba(src, "src", check_values=False)
    dst = as_rgba(dst, "dst", check_values=False)
    shape = broadcast_shapes(src=src, dst=dst)
    mix = check_factor(factor, "factor", shape[:-1])
    dtype = np.result_type(src, dst)
    src = src.astype(dtype, copy=False)
    dst = dst.astype(dtype, copy=False)

    fusable = (
        src.shape == dst.shape
        and isinstance(mix, float)
        and src.flags.c_contiguous
        and dst.flags.c_contiguous
        and src.ndim >= 2
    )
    use_fused = compiled and (engine == "numba" or (fusable and src.size // 4 >= FUSED_MIN_PIXELS))
    if use_fused:
        if not fusable:
            raise ValueError(
                f"engine: 'numba' {_unfusable_reason(src, dst, mix)}; use engine='numpy' or 'auto'"
            )
        from ._fused import composite_fused

        out, suspicious = composite_fused(spec, src, dst, mix)
        if suspicious:  # the fused pass flags; the exact checks below name the problem
            for arr, name in ((src, "src"), (dst, "dst")):
                check_finite(arr, name)
                check_alpha_range(arr, name)
            _check_overflow(out)
        return out

    for arr, name in ((src, "src"), (dst, "dst")):
        check_finite(arr, name)
        check_alpha_range(arr, name)
    with np.errstate(over="ignore", invalid="ignore"):  # reported below, not warned
        out = _composite_numpy(spec, src, dst, mix, shape)
    _check_overflow(out)
    return out


def _unfusable_reason(src: np.ndarray, dst: np.ndarray, mix: np.ndarray | float) -> str:
    """Which requirement of the fused engine ``src``, ``dst`` and the factor fail (the first one)."""
    if src.shape != dst.shape:
        return f"needs src and dst of the same shape, got {src.shape} and {dst.shape}"
    if src.ndim < 2:
        return f"needs images (at least one pixel axis before RGBA), got shape {src.shape}"
    if not isinstance(mix, float):
        return f"needs a scalar factor, got a factor array of shape {np.shape(mix)}"
    name = "src" if not src.flags.c_contiguous else "dst"
    return f"needs C-contiguous arrays, {name} is not (use np.ascontiguousarray)"


def _check_overflow(out: np.ndarray) -> None:
    """Finite inputs can still overflow (HDR values near the dtype's maximum): raise, never return Inf."""
    if not np.isfinite(out).all():
        n = int(np.count_nonzero(~np.isfinite(out)))
        raise ValueError(
            f"the result overflowed {out.dtype} in {n} values; src/dst colours are too large for this dtype"
        )
