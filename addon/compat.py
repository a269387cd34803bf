"""Every difference between the Blender 4.2 LTS, 4.5 LTS and 5.0 compositor APIs, in one place.

The rest of the add-on calls these functions and never tests a version itself.
Differences are detected by feature (an attribute or socket that exists), not by
version number, so an intermediate release behaves like the release it resembles.

=========================  ==================================  ==========================================
topic                      4.2 / 4.5                           5.0
=========================  ==================================  ==========================================
scene compositor tree      ``scene.use_nodes``,                ``scene.compositing_node_group`` (a
                           ``scene.node_tree`` (embedded)      ``CompositorNodeTree`` data-block)
Math node                  ``CompositorNodeMath``              ``ShaderNodeMath``
Alpha Over inputs          ``Fac``, ``Image``, ``Image_001``   ``Background``, ``Foreground``, ``Fac``
Alpha Over straight alpha  ``use_premultiply`` (4.2);          ``Straight Alpha`` input
                           ``Straight Alpha`` input (4.5)
Alpha Over modes           Over only                           ``Type``: Over, Disjoint Over, Conjoint Over
Alpha Convert direction    ``mapping`` property                ``Type`` menu input
File Output                ``base_path``, ``layer_slots``      ``directory``, ``file_name``,
                                                               ``file_output_items``, ``save_as_render``
=========================  ==================================  ==========================================

Light linking (``Object.light_linking``, ``CollectionObject.light_linking``) exists from 4.0, so in
every supported release; :func:`light_linking_collections` reads it by feature all the same (a
build without it links nothing), as :func:`object_holdout` reads the view layer's holdout flags.

Sources: Blender 5.0 Python API change log (https://docs.blender.org/api/5.0/change_log.html),
``source/blender/nodes/composite/nodes/node_composite_alpha_over.cc`` and the PyPI ``bpy``
wheels 4.2.23 and 5.0.1, where each row was checked. Blender 5.2 LTS (``bpy`` 5.2.3, Python 3.13,
numpy 2) behaves like 5.0 in every row: the Blender tests pass on it unchanged
(``make test-blender52``), so no 5.1/5.2 entry is needed here.
"""

from __future__ import annotations

import bpy

__all__ = [
    "ALPHA_OVER_MODES",
    "add_file_output",
    "add_render_output",
    "alpha_over_modes",
    "collection_link_states",
    "compositor_tree",
    "configure_alpha_convert",
    "configure_alpha_over",
    "light_emission",
    "light_linking_collections",
    "link_alpha_over",
    "math_node_type",
    "new_group_tree",
    "object_holdout",
    "set_full_precision",
    "set_image_format",
    "world_uses_nodes",
]

#: Alpha Over modes by the name of the operator they realise.
ALPHA_OVER_MODES: dict[str, str] = {
    "src_over": "Over",
    "disjoint_over": "Disjoint Over",
    "conjoint_over": "Conjoint Over",
}

_GROUP_TREE_TYPE = "CompositorNodeTree"


def compositor_tree(scene: bpy.types.Scene) -> bpy.types.NodeTree:
    """Give ``scene`` an empty compositor tree, with compositing enabled, and return it.

    5.0 uses a ``CompositorNodeTree`` data-block in ``scene.compositing_node_group``;
    4.x uses the embedded ``scene.node_tree`` (its default nodes are removed).
    """
    scene.render.use_compositing = True
    if hasattr(scene, "compositing_node_group"):
        tree = bpy.data.node_groups.new(f"{scene.name} Compositing", _GROUP_TREE_TYPE)
        scene.compositing_node_group = tree
        return tree
    scene.use_nodes = True
    tree = scene.node_tree
    tree.nodes.clear()
    return tree


def new_group_tree(name: str) -> bpy.types.NodeTree:
    """A new, empty compositor node group."""
    return bpy.data.node_groups.new(name, _GROUP_TREE_TYPE)


def math_node_type() -> str:
    """The node type of the Math node in compositor trees."""
    return "CompositorNodeMath" if hasattr(bpy.types, "CompositorNodeMath") else "ShaderNodeMath"


def alpha_over_modes() -> tuple[str, ...]:
    """The Alpha Over modes this Blender has, as operator names (keys of ``ALPHA_OVER_MODES``)."""
    tree = new_group_tree("_probe_alpha_over")
    try:
        node = tree.nodes.new("CompositorNodeAlphaOver")
        if "Type" in node.inputs:
            return tuple(ALPHA_OVER_MODES)
        return ("src_over",)
    finally:
        bpy.data.node_groups.remove(tree)


def link_alpha_over(
    tree: bpy.types.NodeTree,
    node: bpy.types.Node,
    background: bpy.types.NodeSocket,
    foreground: bpy.types.NodeSocket,
) -> None:
    """Link the background (destination) and foreground (source) images of an Alpha Over node."""
    if "Background" in node.inputs:
        tree.links.new(background, node.inputs["Background"])
        tree.links.new(foreground, node.inputs["Foreground"])
    else:  # 4.x: Fac, Image (background), Image_001 (foreground)
        tree.links.new(background, node.inputs[1])
        tree.links.new(foreground, node.inputs[2])


def configure_alpha_over(node: bpy.types.Node, operator: str, *, straight_alpha: bool, factor: float) -> None:
    """Set mode, straight-alpha handling and factor of an Alpha Over node.

    Args:
        node: a ``CompositorNodeAlphaOver``.
        operator: ``"src_over"``, ``"disjoint_over"`` or ``"conjoint_over"``.
        straight_alpha: treat the foreground as straight (unassociated) alpha.
        factor: the Factor input, in [0, 1].

    Raises:
        ValueError: the mode does not exist in this Blender (Disjoint and Conjoint
            Over need 5.0) or ``operator`` is not an Alpha Over mode.
    """
    if operator not in ALPHA_OVER_MODES:
        raise ValueError(f"operator: expected one of {sorted(ALPHA_OVER_MODES)}, got {operator!r}")
    if "Type" in node.inputs:
        node.inputs["Type"].default_value = ALPHA_OVER_MODES[operator]
    elif operator != "src_over":
        raise ValueError(
            f"operator: Alpha Over has no {ALPHA_OVER_MODES[operator]!r} mode before Blender 5.0 "
            f"(this is {bpy.app.version_string}); use the Porter-Duff node group instead"
        )
    if "Straight Alpha" in node.inputs:
        node.inputs["Straight Alpha"].default_value = straight_alpha
    else:
        node.use_premultiply = straight_alpha
    node.inputs[0 if "Background" not in node.inputs else "Factor"].default_value = factor


def configure_alpha_convert(node: bpy.types.Node, *, to_premultiplied: bool) -> None:
    """Set the direction of an Alpha Convert (``CompositorNodePremulKey``) node."""
    if "Type" in node.inputs:
        node.inputs["Type"].default_value = "To Premultiplied" if to_premultiplied else "To Straight"
    else:
        node.mapping = "STRAIGHT_TO_PREMUL" if to_premultiplied else "PREMUL_TO_STRAIGHT"


def add_file_output(
    tree: bpy.types.NodeTree, directory: str, file_name: str, layers: list[str]
) -> dict[str, bpy.types.NodeSocket]:
    """Add a File Output node writing one 32-bit float multilayer EXR with an RGBA layer per name.

    Pixels are written as computed: no view transform, lossless ZIP compression.
    Blender 4.x appends the frame number to ``file_name`` (``name0001.exr``), 5.0 does
    not; readers should look for ``file_name*.exr``. Returns the input socket per layer.
    """
    node = tree.nodes.new("CompositorNodeOutputFile")
    node.format.file_format = "OPEN_EXR_MULTILAYER"
    node.format.color_depth = "32"
    node.format.exr_codec = "ZIP"
    if hasattr(node, "save_as_render"):
        node.save_as_render = False
    if hasattr(node, "file_output_items"):
        node.directory = directory
        node.file_name = file_name
        node.file_output_items.clear()
        for layer in layers:
            node.file_output_items.new("RGBA", layer)
    else:
        node.base_path = f"{directory}/{file_name}"
        node.layer_slots.clear()
        for layer in layers:
            node.layer_slots.new(layer)
    return {layer: node.inputs[layer] for layer in layers}


def add_render_output(tree: bpy.types.NodeTree) -> bpy.types.NodeSocket:
    """Add the node that receives the final composite (the render result) and return its image input.

    5.0 has no Composite node: the tree's Group Output with an ``Image`` socket takes its place.
    """
    if hasattr(bpy.types, "CompositorNodeComposite"):
        node = tree.nodes.new("CompositorNodeComposite")
        if hasattr(node, "use_alpha"):
            node.use_alpha = True
        return node.inputs["Image"]
    if "Image" not in [item.name for item in tree.interface.items_tree if item.item_type == "SOCKET"]:
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    node = tree.nodes.new("NodeGroupOutput")
    return node.inputs["Image"]


def set_image_format(
    settings: bpy.types.ImageFormatSettings, file_format: str, color_depth: str | None
) -> None:
    """Set an output format by its 4.x identifier (``OPEN_EXR_MULTILAYER`` included) and, if given, depth.

    5.0 moved multilayer EXR behind ``media_type = "MULTI_LAYER_IMAGE"``; 4.x has no ``media_type``.
    """
    if hasattr(settings, "media_type"):
        settings.media_type = "MULTI_LAYER_IMAGE" if file_format == "OPEN_EXR_MULTILAYER" else "IMAGE"
    settings.file_format = file_format
    if color_depth:
        settings.color_depth = color_depth


def set_full_precision(scene: bpy.types.Scene) -> None:
    """Ask the compositor for 32-bit float buffers where Blender offers a choice."""
    if hasattr(scene.render, "compositor_precision"):
        scene.render.compositor_precision = "FULL"
    if hasattr(scene.render, "compositor_device"):
        scene.render.compositor_device = "CPU"


def world_uses_nodes(world: bpy.types.World) -> bool:
    """True when Blender renders ``world`` from its node tree rather than ``world.color``.

    5.0 always uses the node tree (``World.use_nodes`` is deprecated, reads True and ignores
    assignments); 4.2/4.5 honour ``use_nodes`` and new worlds start without a tree.
    """
    if world.node_tree is None:
        return False
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        use_nodes = bool(world.use_nodes)
    if any(issubclass(w.category, DeprecationWarning) for w in caught):
        return True
    return use_nodes


def light_emission(light: bpy.types.Light) -> tuple[float, tuple[float, float, float]]:
    """A light's effective power (W, or W/m² for a sun) and linear RGB colour.

    5.0 adds ``exposure`` (power × 2^exposure) and a blackbody colour (``use_temperature``: the
    colour is multiplied by ``temperature_color``); 4.2/4.5 have neither, so power and colour are
    ``energy`` and ``color``.
    """
    energy = float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))
    colour = [float(c) for c in light.color]
    if getattr(light, "use_temperature", False):
        colour = [c * float(t) for c, t in zip(colour, light.temperature_color, strict=True)]
    return energy, (colour[0], colour[1], colour[2])


def light_linking_collections(obj: bpy.types.Object) -> tuple[object, object]:
    """``(receiver_collection, blocker_collection)`` of an emitter's light linking (None for unset;
    both None where the build has no ``Object.light_linking``)."""
    linking = getattr(obj, "light_linking", None)
    if linking is None:
        return None, None
    return getattr(linking, "receiver_collection", None), getattr(linking, "blocker_collection", None)


def collection_link_states(collection: bpy.types.Collection) -> list[tuple[bpy.types.Object, str]]:
    """``(object, "INCLUDE" | "EXCLUDE")`` for every object a light-linking collection holds, as
    Blender's depsgraph reads it (``depsgraph_light_linking.cc``): a direct member with its own
    state, a member of a child collection (at any depth) with that child's state; children first,
    then the direct members, so a later entry for the same object wins. Without light-linking
    data on collections every member is included."""

    def state(item: object) -> str:
        linking = getattr(item, "light_linking", None)
        return str(getattr(linking, "link_state", "INCLUDE"))

    def objects_of(child: bpy.types.Collection) -> list[bpy.types.Object]:
        return list(child.all_objects)

    # collection_children / collection_objects run over the same lists as children / objects
    out: list[tuple[bpy.types.Object, str]] = []
    settings = getattr(collection, "collection_children", None)
    for i, child in enumerate(collection.children):
        link = "INCLUDE" if settings is None else state(settings[i])
        out.extend((obj, link) for obj in objects_of(child))
    settings = getattr(collection, "collection_objects", None)
    for i, obj in enumerate(collection.objects):
        out.append((obj, "INCLUDE" if settings is None else state(settings[i])))
    return out


def object_holdout(obj: bpy.types.Object, view_layer: object) -> bool:
    """Whether ``obj`` is held out: ``Object.is_holdout`` or a collection of it marked *Holdout* in
    ``view_layer`` (``Object.holdout_get``; objects not based in the view layer, e.g. instances
    of a collection, read only their own flag)."""
    original = getattr(obj, "original", obj)
    if getattr(original, "is_holdout", False):
        return True
    getter = getattr(original, "holdout_get", None)
    if getter is None or view_layer is None:
        return False
    try:
        return bool(getter(view_layer=view_layer))
    except (RuntimeError, TypeError):
        return False


def float_pixels_associated(image: bpy.types.Image) -> bool:
    """Whether Cycles uses a float image's ``pixels`` as they are, alpha associated (4.2–5.0), or
    associates them itself as it does a byte image's when the image's alpha mode is Straight
    (5.2: a float texel (0.4, 0.2, 0.1, α 0.5) gives a Color output of 0.2, 0.1, 0.05 with the
    Alpha output unlinked, where 5.0.1 gives 0.4, 0.2, 0.1; measured with Cycles 5.0.1 and
    5.2.3, ``tests/blinn_phong/test_texture_vs_cycles.py``)."""
    if bpy.app.version >= (5, 2, 0):
        return str(getattr(image, "alpha_mode", "STRAIGHT")) != "STRAIGHT"
    return True

