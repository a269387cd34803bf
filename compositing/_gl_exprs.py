"""The OpenGL blend factors and equations as expression trees (OpenGL 4.6 §17.3.6, tables 17.1–17.2).

The single source of truth that the numpy reference (:mod:`compositing.gl_blend`) evaluates and
the compiled kernels (:mod:`compositing._gl_fused`) are generated from; both import it, it
imports neither. :mod:`compositing.gl_blend` re-exports :data:`GL_FACTOR_EXPRS` and
:data:`GL_EQUATION_EXPRS`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

from .factors import ONE, ZERO, Expr, maximum, minimum

__all__ = ["GL_EQUATION_EXPRS", "GL_FACTOR_EXPRS", "exact_factor", "uses_factors"]

# Variables: ``s``, ``d``, ``c`` the component being blended of the source, destination and
# constant colour; ``sa``, ``da``, ``ca`` their alphas. For the alpha component ``s`` is ``sa``
# and so on.

_S, _D, _C = (Expr("var", value=v) for v in ("s", "d", "c"))
_SA, _DA, _CA = (Expr("var", value=v) for v in ("sa", "da", "ca"))

#: Table 17.2 as ``name -> (RGB part, alpha part)``, each an expression over s, d, c, sa, da, ca.
GL_FACTOR_EXPRS: Final[Mapping[str, tuple[Expr, Expr]]] = {
    "ZERO": (ZERO, ZERO),
    "ONE": (ONE, ONE),
    "SRC_COLOR": (_S, _S),
    "ONE_MINUS_SRC_COLOR": (1.0 - _S, 1.0 - _S),
    "DST_COLOR": (_D, _D),
    "ONE_MINUS_DST_COLOR": (1.0 - _D, 1.0 - _D),
    "SRC_ALPHA": (_SA, _SA),
    "ONE_MINUS_SRC_ALPHA": (1.0 - _SA, 1.0 - _SA),
    "DST_ALPHA": (_DA, _DA),
    "ONE_MINUS_DST_ALPHA": (1.0 - _DA, 1.0 - _DA),
    "CONSTANT_COLOR": (_C, _C),
    "ONE_MINUS_CONSTANT_COLOR": (1.0 - _C, 1.0 - _C),
    "CONSTANT_ALPHA": (_CA, _CA),
    "ONE_MINUS_CONSTANT_ALPHA": (1.0 - _CA, 1.0 - _CA),
    "SRC_ALPHA_SATURATE": (minimum(_SA, 1.0 - _DA), ONE),
}

_SW, _DW = Expr("var", value="sw"), Expr("var", value="dw")

#: Table 17.1 as expressions over ``sw = s·S``, ``dw = d·D`` (the weighted colours) and ``s``, ``d``.
GL_EQUATION_EXPRS: Final[Mapping[str, Expr]] = {
    "FUNC_ADD": _SW + _DW,
    "FUNC_SUBTRACT": _SW - _DW,
    "FUNC_REVERSE_SUBTRACT": _DW - _SW,
    "MIN": minimum(_S, _D),
    "MAX": maximum(_S, _D),
}


def uses_factors(equation: str) -> bool:
    """True when the equation reads the weighted colours (FUNC_*), False for MIN/MAX."""
    return _uses(GL_EQUATION_EXPRS[equation], ("sw", "dw"))


def _uses(expr: Expr, names: tuple[str, ...]) -> bool:
    if expr.op == "var":
        return expr.value in names
    return any(_uses(a, names) for a in expr.args)


def exact_factor(name: str, part: int) -> float | None:
    """0.0 or 1.0 when the factor's RGB (``part`` 0) or alpha (1) part is that constant, else None.

    A product with an exact 0 or 1 is not computed (GL guarantees both are exact): ``x·1`` is
    ``x`` and ``x·0`` is the constant 0, in every back end.
    """
    expr = GL_FACTOR_EXPRS[name][part]
    return float(expr.value) if expr.is_const and float(expr.value) in (0.0, 1.0) else None  # type: ignore[arg-type]
