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

Names are the GL enumerants without the ``GL_`` prefix (a leading ``GL_`` is tolerated),
case-insensitive. Dual-source factors (``SRC1_*``) are not modelled: they need a second
fragment colour.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Final

import numpy as np

from .factors import ALL_OPERATORS
from .operators import resolve_operator
from .validate import as_rgba, broadcast_shapes

__all__ = ["GL_BLEND_EQUATIONS", "GL_BLEND_FACTORS", "GL_BLEND_TARGETS", "gl_blend", "gl_factors"]

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


def _factor(name: str, src: np.ndarray, dst: np.ndarray, constant: np.ndarray) -> np.ndarray | float:
    """The RGBA value of one blend factor (table 17.2): an array broadcasting to (..., 4), or 0.0/1.0."""
    if name == "ZERO":
        return 0.0
    if name == "ONE":
        return 1.0
    if name == "SRC_COLOR":
        return src
    if name == "ONE_MINUS_SRC_COLOR":
        return 1.0 - src
    if name == "DST_COLOR":
        return dst
    if name == "ONE_MINUS_DST_COLOR":
        return 1.0 - dst
    if name == "SRC_ALPHA":
        return src[..., 3:]
    if name == "ONE_MINUS_SRC_ALPHA":
        return 1.0 - src[..., 3:]
    if name == "DST_ALPHA":
        return dst[..., 3:]
    if name == "ONE_MINUS_DST_ALPHA":
        return 1.0 - dst[..., 3:]
    if name == "CONSTANT_COLOR":
        return constant
    if name == "ONE_MINUS_CONSTANT_COLOR":
        return 1.0 - constant
    if name == "CONSTANT_ALPHA":
        return constant[3:]
    if name == "ONE_MINUS_CONSTANT_ALPHA":
        return 1.0 - constant[3:]
    if name == "SRC_ALPHA_SATURATE":
        f = np.minimum(src[..., 3:], 1.0 - dst[..., 3:])
        return np.concatenate([np.broadcast_to(f, (*f.shape[:-1], 3)), np.ones_like(f)], axis=-1)
    raise AssertionError(f"unhandled blend factor {name}")  # names are validated before


def _weighted(colour: np.ndarray, factor: np.ndarray | float) -> np.ndarray | float:
    """colour·factor, skipping the multiply for the exact factors 0 and 1 (GL guarantees both are exact)."""
    if isinstance(factor, float):
        return colour if factor == 1.0 else 0.0
    return colour * factor


def _equation(
    name: str, s: np.ndarray, d: np.ndarray, s_factor: np.ndarray | float, d_factor: np.ndarray | float
) -> np.ndarray:
    """One blend equation (table 17.1), component-wise on arrays of matching channels."""
    if name == "MIN":
        return np.minimum(s, d)
    if name == "MAX":
        return np.maximum(s, d)
    sw = _weighted(s, s_factor)
    dw = _weighted(d, d_factor)
    shape = np.broadcast_shapes(s.shape, d.shape)
    # Write into a product we own when it already has the full shape (saves one allocation).
    if name == "FUNC_ADD":
        own = next((w for w in (sw, dw) if _is_scratch(w, shape, s, d)), None)
        out = sw + dw if own is None else np.add(sw, dw, out=own)
    elif name == "FUNC_SUBTRACT":
        out = np.subtract(sw, dw, out=sw) if _is_scratch(sw, shape, s, d) else sw - dw
    else:  # FUNC_REVERSE_SUBTRACT
        out = np.subtract(dw, sw, out=dw) if _is_scratch(dw, shape, s, d) else dw - sw
    return out if np.shape(out) == shape else np.broadcast_to(out, shape)


def _is_scratch(x: np.ndarray | float, shape: tuple[int, ...], *inputs: np.ndarray) -> bool:
    """True for a temporary array of the full shape that is none of the inputs (safe to overwrite)."""
    return (
        isinstance(x, np.ndarray) and x.shape == shape and x.base is None and all(x is not i for i in inputs)
    )


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
) -> np.ndarray:
    """Blend ``src`` onto ``dst`` exactly as OpenGL's blend stage does (OpenGL 4.6 §17.3.6).

    Args:
        src: The fragment colour, RGBA in the last axis, shape ``(..., 4)``, float32 or float64.
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

    Returns:
        The blended RGBA, shape ``broadcast(src, dst)``, dtype ``result_type(src, dst)``. For
        ``"unorm8"`` every value is ``k/255`` with integer ``k`` in [0, 255]; ``np.rint(255·out)``
        gives the bytes a GL RGBA8 framebuffer would hold.

    Raises:
        TypeError: a colour is not a float array, or a name is not a string.
        ValueError: the last axis is not 4, the shapes do not broadcast, a value is NaN/Inf,
            a factor/equation/target name is unknown (the message lists the valid ones), the
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
    unorm8 = target.lower() == "unorm8"

    # Any finite value is allowed, alpha included: a float framebuffer holds whatever it is given.
    s = as_rgba(src, "src")
    d = as_rgba(dst, "dst")
    shape = broadcast_shapes(src=s, dst=d)
    dtype = np.result_type(s, d)
    s, d = s.astype(dtype, copy=False), d.astype(dtype, copy=False)
    c = _as_constant(constant).astype(dtype)
    if unorm8:
        s, d, c = _quantise_unorm8(s), _quantise_unorm8(d), _quantise_unorm8(c)

    with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported below, not warned
        out = _blend(s, d, c, (sf, df, eq), (sfa, dfa, eqa))
    if not (_is_scratch(out, shape, s, d) and out.dtype == dtype):
        out = np.array(np.broadcast_to(out, shape), dtype=dtype)  # own, writable, right dtype
    if unorm8:
        return _quantise_unorm8(out)
    overflow = np.count_nonzero(~np.isfinite(out))
    if overflow:
        raise ValueError(
            f"the blend overflowed {dtype} in {overflow} value(s); src/dst/constant are too large"
        )
    return out


def _blend(
    s: np.ndarray,
    d: np.ndarray,
    c: np.ndarray,
    rgb_state: tuple[str, str, str],
    alpha_state: tuple[str, str, str],
) -> np.ndarray:
    """The blend on validated arrays.

    With separate state the RGB and alpha parts of each factor are merged into one RGBA factor
    first, so the products run over whole contiguous pixels; only a different alpha equation
    needs a second (alpha-only) pass.
    """
    sf, df, eq = rgb_state
    sfa, dfa, eqa = alpha_state
    s_factor = _factor(sf, s, d, c)
    if sfa != sf:
        s_factor = _merge(s_factor, _factor(sfa, s, d, c), s.dtype)
    d_factor = _factor(df, s, d, c)
    if dfa != df:
        d_factor = _merge(d_factor, _factor(dfa, s, d, c), s.dtype)
    out = _equation(eq, s, d, s_factor, d_factor)
    if eqa != eq:
        shape = np.broadcast_shapes(s.shape, d.shape)
        if not _is_scratch(out, shape, s, d):
            out = np.array(np.broadcast_to(out, shape))
        alpha = slice(3, 4)
        out[..., alpha] = _equation(
            eqa, s[..., alpha], d[..., alpha], _part(s_factor, alpha), _part(d_factor, alpha)
        )
    return out


def _part(factor: np.ndarray | float, channels: slice) -> np.ndarray | float:
    """The RGB or alpha part of a factor; scalars and single-channel (replicated) factors as they are."""
    if isinstance(factor, float) or factor.shape[-1] == 1:
        return factor
    return factor[..., channels]


def _merge(rgb: np.ndarray | float, alpha: np.ndarray | float, dtype: np.dtype) -> np.ndarray | float:
    """One RGBA factor from the RGB part of ``rgb`` and the alpha part of ``alpha``."""
    if isinstance(rgb, float) and isinstance(alpha, float):
        return rgb if rgb == alpha else np.array([rgb, rgb, rgb, alpha], dtype=dtype)
    pixels = np.broadcast_shapes(*(np.shape(f)[:-1] for f in (rgb, alpha) if not isinstance(f, float)))
    merged = np.empty((*pixels, 4), dtype=dtype)
    merged[..., :3] = _part(rgb, slice(0, 3))
    merged[..., 3:] = _part(alpha, slice(3, 4))
    return merged


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
