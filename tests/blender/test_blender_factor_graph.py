"""The Math-node plan of each operator, evaluated in plain numpy, against Porter & Duff's table.

No Blender here: the plan (``addon.factor_graph``) is interpreted step by step with the
semantics of Blender's Math node operations, and the result is compared with the
closed forms of Porter & Duff (1984), table 1, written out below independently of the
factor table, and, for the operators beyond the paper, with ``compositing.composite``.
"""

import numpy as np
import pytest

from addon.factor_graph import CHANNELS, plan_operator
from compositing import composite
from compositing.factors import ALL_OPERATORS, EXTRA_OPERATORS, OPERATORS
from tests.porter_duff_paper import PAPER

# Blender Math node operations (source/blender/nodes/shader/node_shader_math.cc, safe DIVIDE).
MATH = {
    "ADD": np.add,
    "SUBTRACT": np.subtract,
    "MULTIPLY": np.multiply,
    "DIVIDE": lambda a, b: np.divide(a, np.where(b == 0, 1, b)) * (b != 0),
    "MINIMUM": np.minimum,
    "MAXIMUM": np.maximum,
    "LESS_THAN": lambda a, b: (a < b).astype(np.float64),
    "GREATER_THAN": lambda a, b: (a > b).astype(np.float64),
}


RNG = np.random.default_rng(7)
SRC = RNG.uniform(-0.5, 3.0, (64, 4))
DST = RNG.uniform(-0.5, 3.0, (64, 4))
SRC[:, 3] = np.tile([0.0, 0.25, 0.5, 1.0], 16)
DST[:, 3] = np.repeat([0.0, 0.25, 0.75, 1.0], 16)


def run_plan(name: str, src: np.ndarray, dst: np.ndarray, factor: float) -> np.ndarray:
    plan = plan_operator(ALL_OPERATORS[name])
    inputs = {"factor": np.full(src.shape[0], factor)}
    for i, channel in enumerate(CHANNELS):
        inputs[f"src.{channel}"] = src[:, i]
        inputs[f"dst.{channel}"] = dst[:, i]
    values: list[np.ndarray] = []

    def value(operand):
        kind, v = operand
        return {"const": lambda: np.float64(v), "input": lambda: inputs[v], "step": lambda: values[v]}[kind]()

    for step in plan.steps:
        values.append(MATH[step.operation](*(value(o) for o in step.operands)))
    return np.stack([np.broadcast_to(value(plan.outputs[c]), src.shape[:1]) for c in CHANNELS], axis=-1)


@pytest.mark.parametrize("factor", [1.0, 0.3, 0.0])
@pytest.mark.parametrize("name", [*OPERATORS, "plus"])
def test_plan_matches_porter_duff_closed_form(name: str, factor: float) -> None:
    fa, fb = (f(SRC[:, 3:], DST[:, 3:]) for f in PAPER[name])
    want = DST * (1 - factor) + (SRC * fa + DST * fb) * factor
    np.testing.assert_allclose(run_plan(name, SRC, DST, factor), want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", list(EXTRA_OPERATORS))
def test_plan_matches_composite_for_the_extended_family(name: str) -> None:
    want = composite(SRC, DST, name, factor=0.6, engine="numpy")
    np.testing.assert_allclose(run_plan(name, SRC, DST, 0.6), want, rtol=0, atol=1e-12)


def test_shared_subexpressions_become_one_step() -> None:
    # Conjoint Over's Fb = (1 − [sa > da])·(1 − sa/da): every sub-expression once, each step distinct.
    for name in ALL_OPERATORS:
        plan = plan_operator(ALL_OPERATORS[name])
        keys = [(s.operation, s.operands) for s in plan.steps]
        assert len(keys) == len(set(keys)), name
    plan = plan_operator(ALL_OPERATORS["src_over"])
    # 1 − sa, 1 − factor, then per channel dst·Fb, sum, dst·(1 − f), m·f, result: 2 + 4·5 steps.
    assert len(plan.steps) == 22


def test_plan_rejects_a_non_operator() -> None:
    with pytest.raises(TypeError, match=r"spec: expected a compositing\.factors\.OperatorSpec"):
        plan_operator("src_over")  # type: ignore[arg-type]
