"""The OpenGL blend stage on numpy arrays: every blend factor and equation, float or RGBA8 target.

OpenGL combines the fragment colour ``s`` (the source) with the colour already in the
framebuffer ``d`` (the destination) as (OpenGL 4.6 core profile §17.3.6, "Blending";
refpages ``glBlendFuncSeparate`` and ``glBlendEquationSeparate``)::

    FUNC_ADD               r = s·S + d·D
    FUNC_SUBTRACT          r = s·S − d·D
    FUNC_REVERSE_SUBTRACT  r = d·D − s·S
    MIN                    r = min(s, d)      (factors ignored)
    MAX                    r = max(s, d)      (factors ignored)

per component, where the source and destination factors ``S`` and ``D`` are chosen by
name from table 17.2 (:data:`GL_BLEND_FACTORS`). The RGB components use the RGB part of
the factor and the RGB equation; alpha uses the alpha part of the (possibly different)
alpha factor and the alpha equation (``glBlendFuncSeparate``, ``glBlendEquationSeparate``).

Two framebuffer formats are modelled:

* ``target="float32"``, a floating-point colour buffer (RGBA32F): "If the color buffer is
  floating-point, no clamping occurs" (§17.3.6). The arithmetic runs in the input dtype.
* ``target="unorm8"``, a fixed-point RGBA8 buffer: the source, destination and constant
  colours are clamped to [0, 1] and held as 8-bit values ``round(255·x)/255`` (round to
  nearest), the blend is evaluated exactly on those values and the result is clamped to
  [0, 1] and rounded to the nearest 8-bit value. The GL spec clamps the source,
  destination and factors of a fixed-point buffer to [0, 1] (§17.3.6) and lets the
  implementation quantise and round; Mesa's llvmpipe quantises the fragment and constant
  colours to 8 bits and rounds each product separately, so it can differ from this model
  by one step of 1/255 (measured in ``tests/compositing/test_gl_blend_mesa.py``). When
  every factor is ``ZERO`` or ``ONE`` (or the equation is MIN/MAX) there is nothing to round
  and the two agree bit for bit.

With ``target="unorm8"`` the colours may also be ``uint8`` arrays, the codes of an RGBA8
image (value = code/255); two ``uint8`` inputs give a ``uint8`` result computed on the codes,
with no float round trip (the dtype rule is written once, in docs/gl_blend.md, "Dtypes").

Factors and equations are held once, as expression trees (:data:`GL_FACTOR_EXPRS`,
:data:`GL_EQUATION_EXPRS`). The numpy reference (``engine="numpy"``) evaluates them on
arrays; the compiled blend stage (``engine="numba"``, :mod:`compositing._gl_fused`) is
generated from them and gives the same values (identical floats, identical 8-bit codes).

Names are the GL enumerants without the ``GL_`` prefix (a leading ``GL_`` is tolerated),
case-insensitive. Dual-source factors (``SRC1_*``) are not modelled: they need a second
fragment colour.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Final

import numpy as np

from ._engine import ENGINES, use_compiled
from ._gl_exprs import GL_EQUATION_EXPRS, GL_FACTOR_EXPRS, exact_factor, uses_factors
from .factors import ALL_OPERATORS, evaluate_in
from .operators import resolve_operator
from .validate import as_rgba, broadcast_shapes, check_finite

__all__ = [
    "GL_BLEND_ENGINES",
    "GL_BLEND_EQUATIONS",
    "GL_BLEND_FACTORS",
    "GL_BLEND_TARGETS",
    "GL_EQUATION_EXPRS",
    "GL_FACTOR_EXPRS",
    "gl_blend",
    "gl_factors",
]

#: The 15 blend factors of OpenGL 4.6 §17.3.6.1, table 17.2 (dual-source ones excluded), with
#: their value as (R, G, B, A) in terms of the source s, destination d and constant colour c.
GL_BLEND_FACTORS: Final[Mapping[str, str]] = {
    "ZERO": "(0, 0, 0, 0)",
    "ONE": "(1, 1, 1, 1)",
    "SRC_COLOR": "(Rs, Gs, Bs, As)",
    "ONE_MINUS_SRC_COLOR": "(1, 1, 1, 1) − (Rs, Gs, Bs, As)",
    "DST_COLOR": "(Rd, Gd, Bd, Ad)",
    "ONE_MINUS_DST_COLOR": "(1, 1, 1, 1) − (Rd, Gd, Bd, Ad)",
    "SRC_ALPHA": "(As, As, As, As)",
    "ONE_MINUS_SRC_ALPHA": "(1, 1, 1, 1) − (As, As, As, As)",
    "DST_ALPHA": "(Ad, Ad, Ad, Ad)",
    "ONE_MINUS_DST_ALPHA": "(1, 1, 1, 1) − (Ad, Ad, Ad, Ad)",
    "CONSTANT_COLOR": "(Rc, Gc, Bc, Ac)",
    "ONE_MINUS_CONSTANT_COLOR": "(1, 1, 1, 1) − (Rc, Gc, Bc, Ac)",
    "CONSTANT_ALPHA": "(Ac, Ac, Ac, Ac)",
    "ONE_MINUS_CONSTANT_ALPHA": "(1, 1, 1, 1) − (Ac, Ac, Ac, Ac)",
    "SRC_ALPHA_SATURATE": "(f, f, f, 1), f = min(As, 1 − Ad)",
}

#: The 5 blend equations of OpenGL 4.6 §17.3.6.2, table 17.1, per component.
GL_BLEND_EQUATIONS: Final[Mapping[str, str]] = {
    "FUNC_ADD": "s·S + d·D",
    "FUNC_SUBTRACT": "s·S − d·D",
    "FUNC_REVERSE_SUBTRACT": "d·D − s·S",
    "MIN": "min(s, d)",
    "MAX": "max(s, d)",
}

#: Framebuffer formats :func:`gl_blend` models.
GL_BLEND_TARGETS: Final[tuple[str, ...]] = ("float32", "unorm8")

#: Engines :func:`gl_blend` accepts: the compiled blend stage (``"numba"``, generated from the
#: table below) and the numpy reference; ``"auto"`` takes the compiled one when numba is installed.
GL_BLEND_ENGINES: Final[tuple[str, ...]] = ENGINES

#: ``engine="auto"`` evaluates fewer pixels than this with numpy: a few colours are not worth
#: the compilation of the generic kernel (1–2 s once per process); both engines agree.
AUTO_COMPILED_MIN_PIXELS: Final = 64

_UNORM8_MAX: Final = 255.0


def _gl_name(name: object, argument: str, table: Mapping[str, str], kind: str) -> str:
    """Normalise a GL enumerant name (case-insensitive, optional ``GL_`` prefix) or raise."""
    if not isinstance(name, str):
        raise TypeError(f"{argument} must be a {kind} name (str), got {type(name).__name__} {name!r}")
    key = name.strip().upper()
    if key.startswith("GL_"):
        key = key[3:]
    if key not in table:
        raise ValueError(f"{argument}: unknown {kind} {name!r}; valid names are {', '.join(table)}")
    return key


def _as_constant(constant: object) -> np.ndarray:
    """Validate the blend colour (glBlendColor): four finite numbers."""
    if not isinstance(constant, np.ndarray):
        # Keep full precision here; the caller casts to the dtype of src/dst.
        try:
            constant = np.asarray(constant, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"constant: expected four numbers (R, G, B, A), got {constant!r}") from exc
    arr = as_rgba(constant, "constant")
    if arr.shape != (4,):
        raise ValueError(f"constant: expected one colour, four numbers (R, G, B, A); got shape {arr.shape}")
    return arr


def _quantise_unorm8(x: np.ndarray) -> np.ndarray:
    """Clamp to [0, 1] and round to the nearest multiple of 1/255 (a UNORM8 store), same dtype."""
    q = np.clip(x, 0.0, 1.0)  # a new array, so the rest can work in place
    q *= _UNORM8_MAX
    np.rint(q, out=q)
    q /= _UNORM8_MAX
    return q


def _blend_part(
    env: dict[str, np.ndarray | float], sf: str, df: str, eq: str, part: int
) -> np.ndarray | float:
    """One channel group (RGB: ``part`` 0, alpha: 1) of the blend, evaluated from the table."""
    if uses_factors(eq):
        for key, colour, name in (("sw", "s", sf), ("dw", "d", df)):
            exact = exact_factor(name, part)
            if exact == 0.0:
                env[key] = 0.0
            elif exact == 1.0:
                env[key] = env[colour]
            else:
                env[key] = env[colour] * evaluate_in(GL_FACTOR_EXPRS[name][part], env)
    return evaluate_in(GL_EQUATION_EXPRS[eq], env)


def blend_reference(
    s: np.ndarray,
    d: np.ndarray,
    c: np.ndarray,
    rgb_state: tuple[str, str, str],
    alpha_state: tuple[str, str, str],
    shape: tuple[int, ...],
) -> np.ndarray:
    """The numpy reference: the table evaluated on validated arrays of one float dtype, no rounding."""
    rgb = {"s": s[..., :3], "d": d[..., :3], "c": c[:3], "sa": s[..., 3:], "da": d[..., 3:], "ca": c[3:]}
    alpha = {"s": s[..., 3:], "d": d[..., 3:], "c": c[3:], "sa": s[..., 3:], "da": d[..., 3:], "ca": c[3:]}
    out = np.empty(shape, dtype=s.dtype)
    out[..., :3] = _blend_part(rgb, *rgb_state, part=0)
    out[..., 3:] = _blend_part(alpha, *alpha_state, part=1)
    return out


def gl_blend(
    src: np.ndarray,
    dst: np.ndarray,
    src_factor: str,
    dst_factor: str,
    equation: str = "FUNC_ADD",
    *,
    src_factor_alpha: str | None = None,
    dst_factor_alpha: str | None = None,
    equation_alpha: str | None = None,
    constant: Sequence[float] | np.ndarray = (0, 0, 0, 0),
    target: str = "float32",
    engine: str = "auto",
) -> np.ndarray:
    """Blend ``src`` onto ``dst`` exactly as OpenGL's blend stage does (OpenGL 4.6 §17.3.6).

    Args:
        src: The fragment colour, RGBA in the last axis, shape ``(..., 4)``: float32 or float64,
            or, with ``target="unorm8"``, ``uint8`` codes of an RGBA8 image (value = code/255).
            The blend stage is colour-space agnostic; with this package's convention it is linear,
            premultiplied, row 0 at the top.
        dst: The framebuffer colour, same conventions; broadcasts against ``src``.
        src_factor: Source factor for RGB (and alpha, unless ``src_factor_alpha`` is given), one of
            :data:`GL_BLEND_FACTORS` (``glBlendFunc`` sfactor), case-insensitive.
        dst_factor: Destination factor, as ``src_factor`` (``glBlendFunc`` dfactor).
        equation: One of :data:`GL_BLEND_EQUATIONS` (``glBlendEquation``); MIN and MAX ignore the factors.
        src_factor_alpha: Source factor for alpha (``glBlendFuncSeparate`` srcAlpha); default ``src_factor``.
        dst_factor_alpha: Destination factor for alpha (``dstAlpha``); default ``dst_factor``.
        equation_alpha: Equation for alpha (``glBlendEquationSeparate`` modeAlpha); default ``equation``.
        constant: The blend colour (``glBlendColor``) used by the ``CONSTANT_*`` factors, four numbers.
        target: ``"float32"`` for a floating-point colour buffer (no clamping anywhere) or ``"unorm8"``
            for a fixed-point RGBA8 buffer (source, destination, constant and result clamped to
            [0, 1] and rounded to the nearest multiple of 1/255, see the module docstring).
        engine: ``"auto"`` (the compiled blend stage when numba is installed, except for fewer
            than :data:`AUTO_COMPILED_MIN_PIXELS` pixels), ``"numba"`` or ``"numpy"`` (the
            reference evaluation of the table). Both give the same values.

    Returns:
        The blended RGBA, shape ``broadcast(src, dst)``. dtype (docs/gl_blend.md, "Dtypes"):
        ``uint8`` when both inputs are ``uint8`` (the codes an RGBA8 framebuffer would hold);
        otherwise ``result_type`` of the float inputs (a ``uint8`` operand then reads as
        code/255). For ``"unorm8"`` with float output every value is ``k/255`` with integer
        ``k`` in [0, 255]; ``np.rint(255·out)`` gives the bytes.

    Raises:
        TypeError: a colour is not a float array (or a ``uint8`` array with ``target="unorm8"``),
            or a name is not a string.
        ValueError: the last axis is not 4, the shapes do not broadcast, a value is NaN/Inf,
            a factor/equation/target/engine name is unknown (the message lists the valid ones), the
            constant is not four numbers, or a float32/float64 result overflows.
    """
    names = {
        "src_factor": src_factor,
        "dst_factor": dst_factor,
        "src_factor_alpha": src_factor if src_factor_alpha is None else src_factor_alpha,
        "dst_factor_alpha": dst_factor if dst_factor_alpha is None else dst_factor_alpha,
    }
    sf, df, sfa, dfa = (_gl_name(v, k, GL_BLEND_FACTORS, "blend factor") for k, v in names.items())
    eq = _gl_name(equation, "equation", GL_BLEND_EQUATIONS, "blend equation")
    eqa = _gl_name(
        equation if equation_alpha is None else equation_alpha,
        "equation_alpha",
        GL_BLEND_EQUATIONS,
        "blend equation",
    )
    if not isinstance(target, str) or target.lower() not in GL_BLEND_TARGETS:
        raise ValueError(f"target must be one of {', '.join(GL_BLEND_TARGETS)}, got {target!r}")
    compiled = use_compiled(engine)
    unorm8 = target.lower() == "unorm8"

    # Any finite value is allowed, alpha included: a float framebuffer holds whatever it is given.
    s = _as_colour(src, "src", unorm8)
    d = _as_colour(dst, "dst", unorm8)
    shape = broadcast_shapes(src=s, dst=d)
    codes = s.dtype == np.uint8 and d.dtype == np.uint8
    if codes:
        dtype = np.dtype(np.float32)  # the reference reads codes as float32 k/255
    else:
        dtype = np.result_type(*(x for x in (s, d) if x.dtype != np.uint8))
    constant_arr = _as_constant(constant)
    rgb_state, alpha_state = (sf, df, eq), (sfa, dfa, eqa)

    pixels = int(np.prod(shape[:-1]))
    use_fused = compiled and (engine == "numba" or pixels >= AUTO_COMPILED_MIN_PIXELS)
    if use_fused:
        return _gl_blend_fused(s, d, constant_arr, rgb_state, alpha_state, shape, dtype, unorm8, codes)

    s, d = (_codes_to_float(x, dtype) if x.dtype == np.uint8 else x.astype(dtype, copy=False) for x in (s, d))
    check_finite(s, "src")
    check_finite(d, "dst")
    c = constant_arr.astype(dtype)
    if unorm8:
        s, d, c = _quantise_unorm8(s), _quantise_unorm8(d), _quantise_unorm8(c)
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported below, not warned
        out = blend_reference(s, d, c, rgb_state, alpha_state, shape)
    if unorm8:
        out = _quantise_unorm8(out)
        return np.rint(out * _UNORM8_MAX).astype(np.uint8) if codes else out
    _check_overflow(out)
    return out


def _as_colour(x: object, name: str, unorm8: bool) -> np.ndarray:
    """``src``/``dst``: a float RGBA array, or uint8 codes when the target is RGBA8."""
    if isinstance(x, np.ndarray) and x.dtype == np.uint8:
        if not unorm8:
            raise TypeError(
                f"{name}: uint8 arrays are RGBA8 codes and need target='unorm8'; got dtype uint8 with "
                "target='float32' (pass float values k/255 for a float framebuffer)"
            )
        if x.ndim == 0 or x.shape[-1] != 4:
            raise ValueError(f"{name}: expected RGBA in the last axis, shape (..., 4); got shape {x.shape}")
        return x
    return as_rgba(x, name, check_values=False)


def _codes_to_float(x: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """uint8 codes as the float values k/255 they stand for (exactly rounded in ``dtype``)."""
    out = x.astype(dtype)
    out /= _UNORM8_MAX
    return out


def _as_kind(x: np.ndarray, kind: np.dtype) -> np.ndarray:
    """``x`` in dtype ``kind`` (uint8 codes read as k/255 when ``kind`` is a float dtype)."""
    if x.dtype == kind:
        return x
    return _codes_to_float(x, kind) if x.dtype == np.uint8 else x.astype(kind)


def _unorm8_codes(x: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Float values as 8-bit codes, quantised in ``dtype`` exactly as :func:`_quantise_unorm8`."""
    q = np.clip(x.astype(dtype), 0.0, 1.0)
    q *= _UNORM8_MAX
    return np.rint(q).astype(np.int32)


def _check_overflow(out: np.ndarray) -> None:
    overflow = np.count_nonzero(~np.isfinite(out))
    if overflow:
        raise ValueError(
            f"the blend overflowed {out.dtype} in {overflow} value(s); src/dst/constant are too large"
        )


def _gl_blend_fused(
    s: np.ndarray,
    d: np.ndarray,
    constant: np.ndarray,
    rgb_state: tuple[str, str, str],
    alpha_state: tuple[str, str, str],
    shape: tuple[int, ...],
    dtype: np.dtype,
    unorm8: bool,
    codes: bool,
) -> np.ndarray:
    """The compiled blend stage on same-shape, same-dtype, C-contiguous copies of the inputs."""
    from ._gl_fused import gl_blend_fused

    kind = np.dtype(np.uint8) if codes else dtype
    s0, d0 = s, d
    s, d = (np.ascontiguousarray(np.broadcast_to(_as_kind(x, kind), shape)) for x in (s, d))
    if unorm8:
        c = _unorm8_codes(constant, dtype)
        mode = "codes" if codes else "quantise"
    else:
        c = constant.astype(dtype)
        mode = "float"
    out, flagged = gl_blend_fused(s, d, c, rgb_state, alpha_state, mode)
    if flagged:  # the pass flags a non-finite value; the exact checks name it
        check_finite(s0, "src")
        check_finite(d0, "dst")
        if not unorm8:
            _check_overflow(out)
    return out


def gl_factors(op: str) -> tuple[str, str]:
    """The ``(sfactor, dfactor)`` pair that realises a compositing operator with ``FUNC_ADD``.

    Read from the operator's factor names in :data:`compositing.factors.ALL_OPERATORS` (the
    single factor table, Porter & Duff 1984 table 1): on premultiplied colours
    ``src·Fa + dst·Fb`` is exactly ``glBlendFunc(Fa, Fb)`` with ``glBlendEquation(FUNC_ADD)``
    whenever both factors are GL factors. That holds for the 12 Porter-Duff operators and
    ``plus``; the disjoint/conjoint operators need ratios of alphas that no GL factor gives,
    and raise ``ValueError``.

    Args:
        op: An operator name such as ``"src_over"``, read as :func:`compositing.composite` reads
            it (:func:`compositing.operators.resolve_operator`: case-insensitive, ``-`` as ``_``).

    Returns:
        ``(src_factor, dst_factor)``, GL names without the ``GL_`` prefix, usable with :func:`gl_blend`.
    """
    if not isinstance(op, str):
        raise TypeError(f"op: expected an operator name (str), got {type(op).__name__} {op!r}")
    spec = resolve_operator(op)
    if not spec.gl_realisable:
        realisable = [name for name, s in ALL_OPERATORS.items() if s.gl_realisable]
        raise ValueError(
            f"op: {spec.name!r} has factors ({spec.fa}, {spec.fb}) that no OpenGL blend factor pair "
            f"realises; operators with a GL pair are {', '.join(realisable)}"
        )
    for factor in (spec.fa, spec.fb):
        assert factor in GL_BLEND_FACTORS, f"factor table names {factor!r}, not a GL blend factor"
    return spec.fa, spec.fb
