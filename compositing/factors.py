"""The Porter-Duff factor table: the single source of truth for every operator.

Every operator in this package is ``result = src·Fa + dst·Fb`` on premultiplied RGBA,
applied identically to all four channels (Porter & Duff, "Compositing Digital
Images", SIGGRAPH '84, table 1; W3C Compositing and Blending Level 1, §9.1).
``Fa`` and ``Fb`` depend only on the source alpha ``sa`` and destination alpha ``da``.

Each factor is a small expression tree (:class:`Expr`) over ``sa``, ``da`` and
constants, built from a handful of operations that every back end has:

* the numpy kernels evaluate it (:func:`evaluate`),
* the Blender node groups turn each operation into one Math node,
* :func:`compositing.gl_factors` reads the GL name of the standard factors,
* the documentation prints it (:func:`describe`).

So an operator is defined once, here, and nowhere else.

Operations (``safe_div`` follows Blender's compositor: x / 0 = 0):

=============  ===============================  ==========================
op             value                            Blender Math node
=============  ===============================  ==========================
``add``        a + b                            ADD
``sub``        a − b                            SUBTRACT
``mul``        a · b                            MULTIPLY
``safe_div``   a / b, 0 where b = 0             DIVIDE (safe in Blender)
``min``        min(a, b)                        MINIMUM
``max``        max(a, b)                        MAXIMUM
``lt``         1 if a < b else 0                LESS_THAN
``gt``         1 if a > b else 0                GREATER_THAN
=============  ===============================  ==========================

Zero denominators: ``safe_div`` tests ``b == 0`` exactly, as Blender's ``safe_divide``
(``b != 0 ? a / b : 0``) does, and the node groups are verified against Blender. Recent
pixman (``get_factor`` in ``pixman-combine-float.c`` with ``FLOAT_IS_ZERO`` of
``pixman-private.h``: ``-FLT_MIN < x < FLT_MIN``) also applies its zero-denominator
default when ``|x| < FLT_MIN`` (1.18e-38), i.e. for subnormal float32 alphas; older pixman
tests ``== 0.0f``. So the disjoint/conjoint operators can differ from current pixman only
where an alpha is a nonzero subnormal: there we divide (and clamp as pixman does) while
pixman takes its default factor.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ALL_OPERATORS",
    "EXTRA_OPERATORS",
    "FACTORS",
    "OPERATORS",
    "PORTER_DUFF",
    "Expr",
    "OperatorSpec",
    "describe",
    "evaluate",
]

#: Binary operations an expression may use, with the Blender Math node operation that realises each.
BLENDER_MATH_OPS: Mapping[str, str] = {
    "add": "ADD",
    "sub": "SUBTRACT",
    "mul": "MULTIPLY",
    "safe_div": "DIVIDE",
    "min": "MINIMUM",
    "max": "MAXIMUM",
    "lt": "LESS_THAN",
    "gt": "GREATER_THAN",
}


@dataclass(frozen=True)
class Expr:
    """A node of a factor expression.

    ``op`` is ``"const"`` (``value`` holds the number), ``"var"`` (``value`` is
    ``"sa"`` or ``"da"``), or one of the binary operations in ``BLENDER_MATH_OPS``
    with two ``args``.
    """

    op: str
    args: tuple[Expr, ...] = ()
    value: float | str | None = None

    # Small operator overloads keep the table below readable.
    def __add__(self, other: Expr | float) -> Expr:
        return Expr("add", (self, _wrap(other)))

    def __radd__(self, other: float) -> Expr:
        return Expr("add", (_wrap(other), self))

    def __sub__(self, other: Expr | float) -> Expr:
        return Expr("sub", (self, _wrap(other)))

    def __rsub__(self, other: float) -> Expr:
        return Expr("sub", (_wrap(other), self))

    def __mul__(self, other: Expr | float) -> Expr:
        return Expr("mul", (self, _wrap(other)))

    def __rmul__(self, other: float) -> Expr:
        return Expr("mul", (_wrap(other), self))

    @property
    def is_const(self) -> bool:
        """True for a constant leaf."""
        return self.op == "const"


def _wrap(x: Expr | float) -> Expr:
    return x if isinstance(x, Expr) else Expr("const", value=float(x))


def _op(name: str, a: Expr | float, b: Expr | float) -> Expr:
    return Expr(name, (_wrap(a), _wrap(b)))


def safe_div(a: Expr | float, b: Expr | float) -> Expr:
    """a / b, defined as 0 where b == 0 (Blender's ``safe_divide``)."""
    return _op("safe_div", a, b)


def minimum(a: Expr | float, b: Expr | float) -> Expr:
    """Element-wise minimum."""
    return _op("min", a, b)


def maximum(a: Expr | float, b: Expr | float) -> Expr:
    """Element-wise maximum."""
    return _op("max", a, b)


def less_than(a: Expr | float, b: Expr | float) -> Expr:
    """1 where a < b, else 0."""
    return _op("lt", a, b)


def greater_than(a: Expr | float, b: Expr | float) -> Expr:
    """1 where a > b, else 0."""
    return _op("gt", a, b)


SA = Expr("var", value="sa")
DA = Expr("var", value="da")
ZERO = Expr("const", value=0.0)
ONE = Expr("const", value=1.0)

#: Named factors. The first six carry the OpenGL blend-factor name that realises them
#: exactly on premultiplied data (glBlendFunc, OpenGL 4.6 core §17.3.6.1, table 17.2).
FACTORS: dict[str, Expr] = {
    "ZERO": ZERO,
    "ONE": ONE,
    "SRC_ALPHA": SA,
    "ONE_MINUS_SRC_ALPHA": 1.0 - SA,
    "DST_ALPHA": DA,
    "ONE_MINUS_DST_ALPHA": 1.0 - DA,
    # Blender 5.0 Alpha Over, Disjoint Over (node_composite_alpha_over.cc):
    #   sa + da < 1 -> src + dst; else src + safe_divide(dst, da)·(1 − sa).
    # As a factor on dst: 1 where sa + da < 1, else min(1, (1 − sa)/da) with x/0 = 0.
    "DISJOINT_OVER_DST": maximum(less_than(SA + DA, 1.0), minimum(1.0, safe_div(1.0 - SA, DA))),
    # Blender 5.0 Alpha Over, Conjoint Over: sa > da -> src; else src + dst·(1 − safe_divide(sa, da)).
    # (Nuke's manual prints A + B(1 − a)/b here; that formula is wrong, as Blender's GLSL notes.)
    "CONJOINT_OVER_DST": (1.0 - greater_than(SA, DA)) * (1.0 - safe_div(SA, DA)),
    # pixman's float combiners (pixman-combine-float.c) for the rest of the disjoint/conjoint family;
    # factors clamped to [0, 1], a zero denominator gives pixman's documented default.
    "INV_DA_OVER_SA": minimum(1.0, maximum(0.0, safe_div(1.0 - DA, SA)))
    + (1.0 - greater_than(SA, 0.0)),  # (1-da)/sa, default 1
    "INV_SA_OVER_DA": minimum(1.0, maximum(0.0, safe_div(1.0 - SA, DA)))
    + (1.0 - greater_than(DA, 0.0)),  # (1-sa)/da, default 1
    "DA_OVER_SA": minimum(1.0, safe_div(DA, SA)) + (1.0 - greater_than(SA, 0.0)),  # da/sa, default 1
    "SA_OVER_DA": minimum(1.0, safe_div(SA, DA)) + (1.0 - greater_than(DA, 0.0)),  # sa/da, default 1
    "ONE_MINUS_DA_OVER_SA": maximum(0.0, 1.0 - safe_div(DA, SA)) * greater_than(SA, 0.0),  # default 0
    "ONE_MINUS_SA_OVER_DA": maximum(0.0, 1.0 - safe_div(SA, DA)) * greater_than(DA, 0.0),  # default 0
    "ONE_MINUS_INV_DA_OVER_SA": maximum(0.0, 1.0 - safe_div(1.0 - DA, SA)) * greater_than(SA, 0.0),
    "ONE_MINUS_INV_SA_OVER_DA": maximum(0.0, 1.0 - safe_div(1.0 - SA, DA)) * greater_than(DA, 0.0),
}

#: The factors OpenGL's blend stage has a name for (used by ``gl_factors``).
GL_FACTOR_NAMES = ("ZERO", "ONE", "SRC_ALPHA", "ONE_MINUS_SRC_ALPHA", "DST_ALPHA", "ONE_MINUS_DST_ALPHA")


@dataclass(frozen=True)
class OperatorSpec:
    """One compositing operator: ``src·Fa + dst·Fb`` with named factors.

    ``title`` is the artist-facing name ("A atop B"), ``source`` cites where the
    factors come from.
    """

    name: str
    fa: str
    fb: str
    title: str
    source: str

    @property
    def fa_expr(self) -> Expr:
        """The expression tree of Fa."""
        return FACTORS[self.fa]

    @property
    def fb_expr(self) -> Expr:
        """The expression tree of Fb."""
        return FACTORS[self.fb]

    @property
    def gl_realisable(self) -> bool:
        """True when an OpenGL (sfactor, dfactor) pair with FUNC_ADD realises the operator exactly."""
        return self.fa in GL_FACTOR_NAMES and self.fb in GL_FACTOR_NAMES


_PD = "Porter & Duff 1984, table 1; W3C Compositing Level 1 §9.1"
_PIXMAN = "pixman, pixman-combine-float.c (X Render disjoint/conjoint family)"

#: The 12 Porter-Duff operators, named as Skia and the W3C do, in the paper's order.
PORTER_DUFF: dict[str, OperatorSpec] = {
    spec.name: spec
    for spec in (
        OperatorSpec("clear", "ZERO", "ZERO", "clear", _PD),
        OperatorSpec("src", "ONE", "ZERO", "A", _PD),
        OperatorSpec("dst", "ZERO", "ONE", "B", _PD),
        OperatorSpec("src_over", "ONE", "ONE_MINUS_SRC_ALPHA", "A over B", _PD),
        OperatorSpec("dst_over", "ONE_MINUS_DST_ALPHA", "ONE", "B over A", _PD),
        OperatorSpec("src_in", "DST_ALPHA", "ZERO", "A in B", _PD),
        OperatorSpec("dst_in", "ZERO", "SRC_ALPHA", "B in A", _PD),
        OperatorSpec("src_out", "ONE_MINUS_DST_ALPHA", "ZERO", "A out B", _PD),
        OperatorSpec("dst_out", "ZERO", "ONE_MINUS_SRC_ALPHA", "B out A", _PD),
        OperatorSpec("src_atop", "DST_ALPHA", "ONE_MINUS_SRC_ALPHA", "A atop B", _PD),
        OperatorSpec("dst_atop", "ONE_MINUS_DST_ALPHA", "SRC_ALPHA", "B atop A", _PD),
        OperatorSpec("xor", "ONE_MINUS_DST_ALPHA", "ONE_MINUS_SRC_ALPHA", "A xor B", _PD),
    )
}

#: Operators beyond the twelve: ``plus`` (Porter & Duff's "plus"), Blender 5.0's Disjoint and
#: Conjoint Over, and the rest of pixman's disjoint/conjoint family.
EXTRA_OPERATORS: dict[str, OperatorSpec] = {
    spec.name: spec
    for spec in (
        OperatorSpec("plus", "ONE", "ONE", "A plus B", _PD),
        OperatorSpec(
            "disjoint_over",
            "ONE",
            "DISJOINT_OVER_DST",
            "A disjoint-over B",
            "Blender 5.0 Alpha Over node, Disjoint Over (node_composite_alpha_over.cc)",
        ),
        OperatorSpec(
            "conjoint_over",
            "ONE",
            "CONJOINT_OVER_DST",
            "A conjoint-over B",
            "Blender 5.0 Alpha Over node, Conjoint Over (node_composite_alpha_over.cc)",
        ),
        OperatorSpec("disjoint_dst_over", "INV_DA_OVER_SA", "ONE", "B disjoint-over A", _PIXMAN),
        OperatorSpec("disjoint_src_in", "ONE_MINUS_INV_DA_OVER_SA", "ZERO", "A disjoint-in B", _PIXMAN),
        OperatorSpec("disjoint_dst_in", "ZERO", "ONE_MINUS_INV_SA_OVER_DA", "B disjoint-in A", _PIXMAN),
        OperatorSpec("disjoint_src_out", "INV_DA_OVER_SA", "ZERO", "A disjoint-out B", _PIXMAN),
        OperatorSpec("disjoint_dst_out", "ZERO", "INV_SA_OVER_DA", "B disjoint-out A", _PIXMAN),
        OperatorSpec(
            "disjoint_src_atop", "ONE_MINUS_INV_DA_OVER_SA", "INV_SA_OVER_DA", "A disjoint-atop B", _PIXMAN
        ),
        OperatorSpec(
            "disjoint_dst_atop", "INV_DA_OVER_SA", "ONE_MINUS_INV_SA_OVER_DA", "B disjoint-atop A", _PIXMAN
        ),
        OperatorSpec("disjoint_xor", "INV_DA_OVER_SA", "INV_SA_OVER_DA", "A disjoint-xor B", _PIXMAN),
        OperatorSpec("conjoint_dst_over", "ONE_MINUS_DA_OVER_SA", "ONE", "B conjoint-over A", _PIXMAN),
        OperatorSpec("conjoint_src_in", "DA_OVER_SA", "ZERO", "A conjoint-in B", _PIXMAN),
        OperatorSpec("conjoint_dst_in", "ZERO", "SA_OVER_DA", "B conjoint-in A", _PIXMAN),
        OperatorSpec("conjoint_src_out", "ONE_MINUS_DA_OVER_SA", "ZERO", "A conjoint-out B", _PIXMAN),
        OperatorSpec("conjoint_dst_out", "ZERO", "ONE_MINUS_SA_OVER_DA", "B conjoint-out A", _PIXMAN),
        OperatorSpec("conjoint_src_atop", "DA_OVER_SA", "ONE_MINUS_SA_OVER_DA", "A conjoint-atop B", _PIXMAN),
        OperatorSpec("conjoint_dst_atop", "ONE_MINUS_DA_OVER_SA", "SA_OVER_DA", "B conjoint-atop A", _PIXMAN),
        OperatorSpec(
            "conjoint_xor", "ONE_MINUS_DA_OVER_SA", "ONE_MINUS_SA_OVER_DA", "A conjoint-xor B", _PIXMAN
        ),
    )
}

#: The 12 Porter-Duff operator names (the public ``compositing.OPERATORS``).
OPERATORS: tuple[str, ...] = tuple(PORTER_DUFF)

#: Every operator ``composite`` accepts, by name.
ALL_OPERATORS: dict[str, OperatorSpec] = {**PORTER_DUFF, **EXTRA_OPERATORS}


def evaluate(expr: Expr, sa: np.ndarray, da: np.ndarray) -> np.ndarray | float:
    """Evaluate a factor expression on alpha arrays.

    ``sa`` and ``da`` are source and destination alpha (any broadcastable shapes,
    values in [0, 1]). Constants stay Python floats so callers can skip a multiply
    by 1 or 0. The dtype of the result follows ``sa``/``da``.
    """
    return evaluate_in(expr, {"sa": sa, "da": da}, np.result_type(sa, da))


def evaluate_in(
    expr: Expr, env: Mapping[str, np.ndarray | float], dtype: np.dtype | None = None
) -> np.ndarray | float:
    """Evaluate an expression with its variables looked up by name in ``env`` (numpy broadcasting).

    The one interpreter of the expression trees: the Porter-Duff (Fa, Fb) table
    (:func:`evaluate`, variables ``sa``/``da``) and the OpenGL blend tables of
    :mod:`compositing.gl_blend` (variables ``s``, ``d``, ``sa``, ``da``, ``c``, …) both
    run through it. Constants stay Python floats so callers can skip a multiply by 1 or 0.
    ``dtype`` is the result type of the comparisons and the safe division (default: the
    result type of ``env``'s values).
    """
    if expr.op == "const":
        return float(expr.value)  # type: ignore[arg-type]
    if expr.op == "var":
        return env[str(expr.value)]
    a, b = (evaluate_in(x, env, dtype) for x in expr.args)
    if expr.op == "add":
        return a + b
    if expr.op == "sub":
        return a - b
    if expr.op == "mul":
        return a * b
    if expr.op == "min":
        return np.minimum(a, b)
    if expr.op == "max":
        return np.maximum(a, b)
    kind = np.result_type(*env.values()) if dtype is None else dtype
    if expr.op == "lt":
        return np.less(a, b).astype(kind)
    if expr.op == "gt":
        return np.greater(a, b).astype(kind)
    if expr.op == "safe_div":
        b_arr = np.asarray(b)
        a_arr = np.asarray(a, dtype=kind)
        zero = b_arr == 0
        out = np.divide(a_arr, np.where(zero, 1, b_arr))
        return np.where(zero, 0, out).astype(kind)
    raise ValueError(f"unknown factor operation {expr.op!r}")


def describe(expr: Expr) -> str:
    """A human-readable formula for a factor expression (used by the docs and the CLI)."""
    if expr.op == "const":
        v = float(expr.value)  # type: ignore[arg-type]
        return str(int(v)) if v.is_integer() else repr(v)
    if expr.op == "var":
        return str(expr.value)
    a, b = (describe(x) for x in expr.args)
    infix = {"add": "+", "sub": "−", "mul": "·"}
    if expr.op in infix:
        return f"({a} {infix[expr.op]} {b})"
    if expr.op == "safe_div":
        return f"({a} / {b}, 0 if {b} = 0)"
    if expr.op == "lt":
        return f"[{a} < {b}]"
    if expr.op == "gt":
        return f"[{a} > {b}]"
    return f"{expr.op}({a}, {b})"
