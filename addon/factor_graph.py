"""Plan the Math-node graph of a Porter-Duff operator, without Blender.

The compositor node groups realise ``result = lerp(dst, src·Fa + dst·Fb, factor)`` on
premultiplied RGBA, channel by channel, with one Math node per operation of the
factor expressions in :mod:`compositing.factors`. This module turns an
:class:`~compositing.factors.OperatorSpec` into an ordered list of steps; the
Blender side (:mod:`addon.node_groups`) only creates one node per step and links it.
Keeping the plan free of ``bpy`` (as glTF-Blender-IO keeps its format logic out of
its Blender code) lets it be inspected and tested in plain Python.

Plan rules:

* every sub-expression of Fa and Fb becomes one step; equal sub-expressions
  (``Expr`` is a frozen dataclass, so equality is structural) share one step;
* constants become literal operands of the step that uses them, never steps;
* a factor that is the constant 1 passes the channel through, a factor that is the
  constant 0 drops its term (both exact in IEEE arithmetic); an operator whose two
  factors are both 0 (``clear``) multiplies the destination channel by 0 so that the
  result still has the size of the inputs;
* the factor stage is ``dst·(1 − factor) + m·factor``, the form Blender's own
  Alpha Over uses (``math::interpolate``), exact at factor 0 and 1.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from compositing.factors import BLENDER_MATH_OPS, Expr, OperatorSpec

__all__ = ["CHANNELS", "Operand", "Plan", "Step", "plan_operator"]

#: Channel names, in the order of Blender's Separate/Combine Color sockets.
CHANNELS: tuple[str, ...] = ("Red", "Green", "Blue", "Alpha")

#: An operand: ``("const", value)``, ``("input", name)`` or ``("step", index)``.
#: Input names are ``src.<Channel>``, ``dst.<Channel>`` and ``factor``.
Operand = tuple[str, float | str | int]


@dataclass(frozen=True)
class Step:
    """One Math node: ``operation`` is a Blender Math node operation (``"MULTIPLY"``, ...)."""

    operation: str
    operands: tuple[Operand, Operand]
    label: str


@dataclass
class Plan:
    """The steps of one operator, in dependency order, and where each output channel comes from."""

    steps: list[Step] = field(default_factory=list)
    outputs: dict[str, Operand] = field(default_factory=dict)
    _index: dict[tuple[str, Operand, Operand], int] = field(default_factory=dict, repr=False)

    def add(self, operation: str, a: Operand, b: Operand, label: str) -> Operand:
        """Append a step (or reuse an identical one) and return it as an operand."""
        key = (operation, a, b)
        if key not in self._index:
            self._index[key] = len(self.steps)
            self.steps.append(Step(operation, (a, b), label))
        return ("step", self._index[key])


def _alpha_input(var: str) -> Operand:
    if var == "sa":
        return ("input", "src.Alpha")
    if var == "da":
        return ("input", "dst.Alpha")
    raise ValueError(f"factor expression variable: expected 'sa' or 'da', got {var!r}")


def _expression(plan: Plan, expr: Expr) -> Operand:
    if expr.op == "const":
        return ("const", float(expr.value))  # type: ignore[arg-type]
    if expr.op == "var":
        return _alpha_input(str(expr.value))
    if expr.op not in BLENDER_MATH_OPS:
        raise ValueError(
            f"factor expression: operation {expr.op!r} has no Blender Math node; "
            f"expected one of {sorted(BLENDER_MATH_OPS)}"
        )
    a, b = (_expression(plan, arg) for arg in expr.args)
    return plan.add(BLENDER_MATH_OPS[expr.op], a, b, expr.op)


def _term(plan: Plan, channel: Operand, factor: Operand, label: str) -> Operand | None:
    """``channel·factor``, folding the exact cases factor = 1 and factor = 0."""
    if factor == ("const", 1.0):
        return channel
    if factor == ("const", 0.0):
        return None
    return plan.add("MULTIPLY", channel, factor, label)


def plan_operator(spec: OperatorSpec) -> Plan:
    """Plan ``lerp(dst, src·Fa + dst·Fb, factor)`` for one operator, channel by channel.

    Args:
        spec: the operator, from :data:`compositing.factors.ALL_OPERATORS`.

    Returns:
        A :class:`Plan` whose ``outputs`` maps each of :data:`CHANNELS` to an operand.
        Formula: Porter & Duff 1984, table 1 (``src·Fa + dst·Fb`` on premultiplied
        RGBA); the factor stage follows Blender's Alpha Over (``interpolate(bg, m, f)``).
    """
    if not isinstance(spec, OperatorSpec):
        raise TypeError(f"spec: expected a compositing.factors.OperatorSpec, got {type(spec).__name__}")
    plan = Plan()
    fa = _expression(plan, spec.fa_expr)
    fb = _expression(plan, spec.fb_expr)
    one_minus_factor = plan.add("SUBTRACT", ("const", 1.0), ("input", "factor"), "1 − factor")
    for channel in CHANNELS:
        src: Operand = ("input", f"src.{channel}")
        dst: Operand = ("input", f"dst.{channel}")
        terms = [
            t
            for t in (
                _term(plan, src, fa, f"src·Fa {channel}"),
                _term(plan, dst, fb, f"dst·Fb {channel}"),
            )
            if t is not None
        ]
        if not terms:
            mixed = plan.add("MULTIPLY", dst, ("const", 0.0), f"0 {channel}")
        elif len(terms) == 1:
            mixed = terms[0]
        else:
            mixed = plan.add("ADD", terms[0], terms[1], f"src·Fa + dst·Fb {channel}")
        kept = plan.add("MULTIPLY", dst, one_minus_factor, f"dst·(1 − factor) {channel}")
        blended = plan.add("MULTIPLY", mixed, ("input", "factor"), f"m·factor {channel}")
        plan.outputs[channel] = plan.add("ADD", kept, blended, f"result {channel}")
    return plan
