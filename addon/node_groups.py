"""Porter-Duff compositor node groups, generated from the factor table.

Each group computes ``lerp(Destination, Source·Fa + Destination·Fb, Factor)`` on
premultiplied RGBA with Blender's built-in Separate Color, Math and Combine Color
nodes. The graph comes from :func:`addon.factor_graph.plan_operator`, which walks
the (Fa, Fb) expressions of :mod:`compositing.factors`: no operator is written out
here, so the groups and the numpy kernels share one definition.

Group interface: inputs ``Source`` (colour), ``Destination`` (colour), ``Factor``
(float in [0, 1], default 1); output ``Image``. A group already in the file with the
same name is reused as long as it carries this module's version stamp, and rebuilt
otherwise.
"""

from __future__ import annotations

import bpy

from compositing.factors import ALL_OPERATORS, OPERATORS, OperatorSpec

from . import compat
from .factor_graph import CHANNELS, Operand, plan_operator

__all__ = ["ALPHA_OVER_MODE_OPERATORS", "ARTIST_OPERATORS", "GENERATOR_VERSION", "ensure_group", "group_name"]

#: The operators offered in the Add menu: the twelve Porter-Duff operators and ``plus``.
ARTIST_OPERATORS: tuple[str, ...] = (*OPERATORS, "plus")

#: Blender 5.0's Alpha Over modes as groups, offered too: Blender 4.2 and 4.5 lack them.
ALPHA_OVER_MODE_OPERATORS: tuple[str, ...] = ("disjoint_over", "conjoint_over")

#: Bumped whenever the generated graph changes, so stale groups in old files are rebuilt.
GENERATOR_VERSION = 1
_STAMP = "porter_duff_generator"
_OPERATOR_KEY = "porter_duff_operator"

_COLUMN = 200.0
_ROW = 170.0
_HIDDEN_ROW = 45.0


def group_name(operator: str) -> str:
    """The node group name of an operator, e.g. ``"Porter-Duff · A atop B"``."""
    return f"Porter-Duff · {_spec(operator).title}"


def _spec(operator: str) -> OperatorSpec:
    if operator not in ALL_OPERATORS:
        raise ValueError(f"operator: expected one of {sorted(ALL_OPERATORS)}, got {operator!r}")
    return ALL_OPERATORS[operator]


def ensure_group(operator: str) -> bpy.types.NodeTree:
    """Return the node group of ``operator`` in the current file, creating it if needed.

    Args:
        operator: a name from :data:`compositing.factors.ALL_OPERATORS` (e.g. ``"src_atop"``).
    """
    name = group_name(operator)
    group = bpy.data.node_groups.get(name)
    if group is not None and group.get(_STAMP) == GENERATOR_VERSION and group.get(_OPERATOR_KEY) == operator:
        return group
    if group is None:
        group = compat.new_group_tree(name)
    else:
        group.nodes.clear()
        group.interface.clear()
    _build(group, _spec(operator))
    group[_STAMP] = GENERATOR_VERSION
    group[_OPERATOR_KEY] = operator
    return group


def _build(group: bpy.types.NodeTree, spec: OperatorSpec) -> None:
    group.description = (
        f"{spec.title}: Source·Fa + Destination·Fb, Fa = {spec.fa}, Fb = {spec.fb} ({spec.source})"
    )
    iface = group.interface
    src_socket = iface.new_socket("Source", in_out="INPUT", socket_type="NodeSocketColor")
    dst_socket = iface.new_socket("Destination", in_out="INPUT", socket_type="NodeSocketColor")
    factor_socket = iface.new_socket("Factor", in_out="INPUT", socket_type="NodeSocketFloat")
    iface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    src_socket.default_value = (0.0, 0.0, 0.0, 0.0)
    dst_socket.default_value = (0.0, 0.0, 0.0, 0.0)
    factor_socket.default_value = 1.0
    factor_socket.min_value = 0.0
    factor_socket.max_value = 1.0
    if hasattr(factor_socket, "subtype"):
        factor_socket.subtype = "FACTOR"

    nodes, links = group.nodes, group.links
    group_in = nodes.new("NodeGroupInput")
    group_in.location = (0.0, 0.0)
    inputs: dict[str, bpy.types.NodeSocket] = {"factor": group_in.outputs["Factor"]}
    for row, (prefix, socket_name) in enumerate((("src", "Source"), ("dst", "Destination"))):
        separate = nodes.new("CompositorNodeSeparateColor")
        separate.label = f"{socket_name} channels"
        separate.location = (_COLUMN, -row * _ROW)
        links.new(group_in.outputs[socket_name], separate.inputs[0])
        for channel in CHANNELS:
            inputs[f"{prefix}.{channel}"] = separate.outputs[channel]

    plan = plan_operator(spec)
    depth: list[int] = []
    outputs: list[bpy.types.NodeSocket] = []

    def resolve(operand: Operand) -> tuple[bpy.types.NodeSocket | None, int]:
        kind, value = operand
        if kind == "step":
            return outputs[int(value)], depth[int(value)]
        if kind == "input":
            return inputs[str(value)], 1
        return None, 0

    rows: dict[int, int] = {}
    math_type = compat.math_node_type()
    for step in plan.steps:
        node = nodes.new(math_type)
        node.operation = step.operation
        node.use_clamp = False
        node.label = step.label
        level = 1
        for slot, operand in enumerate(step.operands):
            socket, operand_depth = resolve(operand)
            level = max(level, operand_depth)
            if socket is None:
                node.inputs[slot].default_value = float(operand[1])
            else:
                links.new(socket, node.inputs[slot])
        level += 1
        node.location = (level * _COLUMN, -rows.get(level, 0) * _HIDDEN_ROW)
        rows[level] = rows.get(level, 0) + 1
        node.hide = True
        depth.append(level)
        outputs.append(node.outputs[0])

    last = max(depth, default=1) + 1
    combine = nodes.new("CompositorNodeCombineColor")
    combine.location = (last * _COLUMN, 0.0)
    for channel in CHANNELS:
        socket, _ = resolve(plan.outputs[channel])
        links.new(socket, combine.inputs[channel])
    group_out = nodes.new("NodeGroupOutput")
    group_out.location = ((last + 1) * _COLUMN, 0.0)
    links.new(combine.outputs[0], group_out.inputs["Image"])
