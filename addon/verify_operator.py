""" "Verify against Blender": the last render over a background, by our operator and by Alpha Over.

Inside a running Blender (no second process): the Render Result is saved to a 32-bit EXR and read
with OpenImageIO (which Blender bundles); the background image is read from its file (EXR as
stored, other formats decoded by ``compositing.io``). Ours is
``compositing.composite(render, background, operator)``. Blender's is a throw-away scene whose
compositor holds two Image nodes (the same arrays written as EXR, loaded ``Non-Color``/``Channel
Packed`` so Blender converts nothing) and an Alpha Over node, rendered once. The operator reports
the largest difference and shows ``|ours − Blender|`` as the image "Blinn-Phong Verify Difference"
in an Image Editor.
"""

import tempfile
import time
from pathlib import Path

import bpy
import numpy as np

from . import compat

__all__ = [
    "LAST_VERIFY",
    "BLINN_PHONG_OT_verify_composite",
    "BLINN_PHONG_PT_verify",
    "blender_alpha_over",
    "classes",
    "register",
    "unregister",
]

LAST_VERIFY: dict = {}
"""Outcome of the last verification: ``max_abs_error``, ``mean_abs_error``, ``operator``, ``seconds``,
``files`` (render, background, ours, Blender's, difference as EXR)."""

DIFFERENCE_IMAGE = "Blinn-Phong Verify Difference"


def read_rgba_exr(path: Path | str) -> np.ndarray:
    """An RGBA EXR as (H, W, 4) float32, row 0 at the top, values as stored (OpenImageIO)."""
    import OpenImageIO as oiio  # noqa: N813 (the library's documented alias)

    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise OSError(f"path: cannot open {path}: {oiio.geterror()}")
    try:
        spec = image.spec()
        names = list(spec.channelnames)
        pixels = image.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    finally:
        image.close()
    picked = [
        next(i for i, n in enumerate(names) if n.split(".")[-1] == c)
        for c in "RGBA"
        if any(n.split(".")[-1] == c for n in names)
    ]
    if len(picked) != 4:
        raise ValueError(f"path: {path} has channels {names}, expected R, G, B and A")
    return np.ascontiguousarray(pixels[..., picked], dtype=np.float32)


def _read_background(path: str) -> np.ndarray:
    """A background file in the project convention: EXR as stored; other formats via ``compositing.io``."""
    if Path(path).suffix.lower() == ".exr":
        return read_rgba_exr(path)
    from compositing.io import read_image  # decodes sRGB (needs colour-science)

    return read_image(path)


def _load_exact(path: Path) -> bpy.types.Image:
    image = bpy.data.images.load(str(path), check_existing=False)
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "CHANNEL_PACKED"
    return image


def blender_alpha_over(src: np.ndarray, dst: np.ndarray, operator: str, workdir: Path) -> np.ndarray:
    """Composite premultiplied ``src`` over ``dst`` with Blender's Alpha Over node, in this Blender.

    Args:
        src: foreground, (H, W, 4) float32 premultiplied linear RGBA, row 0 at the top.
        dst: background, same shape.
        operator: ``src_over``, ``disjoint_over`` or ``conjoint_over`` (the last two need 5.0).
        workdir: directory for the temporary EXR files.

    Returns:
        Blender's result, (H, W, 4) float32, row 0 at the top.
    """
    from .verify import write_exr

    if src.shape != dst.shape or src.ndim != 3 or src.shape[2] != 4:
        raise ValueError(
            f"src, dst: expected two (H, W, 4) images of one shape, got {src.shape} and {dst.shape}"
        )
    write_exr(workdir / "src.exr", src)
    write_exr(workdir / "dst.exr", dst)
    scene = bpy.data.scenes.new("Blinn-Phong Verify")
    images = [_load_exact(workdir / "src.exr"), _load_exact(workdir / "dst.exr")]
    camera = bpy.data.objects.new(
        "Blinn-Phong Verify Camera", bpy.data.cameras.new("Blinn-Phong Verify Camera")
    )
    try:
        scene.collection.objects.link(camera)
        scene.camera = camera
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.resolution_x, scene.render.resolution_y = src.shape[1], src.shape[0]
        scene.render.resolution_percentage = 100
        scene.view_settings.view_transform = "Standard"
        settings = scene.render.image_settings
        settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
        compat.set_full_precision(scene)
        tree = compat.compositor_tree(scene)
        sockets = []
        for image in images:
            node = tree.nodes.new("CompositorNodeImage")
            node.image = image
            sockets.append(node.outputs["Image"])
        over = tree.nodes.new("CompositorNodeAlphaOver")
        compat.link_alpha_over(tree, over, background=sockets[1], foreground=sockets[0])
        compat.configure_alpha_over(over, operator, straight_alpha=False, factor=1.0)
        tree.links.new(over.outputs["Image"], compat.add_render_output(tree))
        scene.render.filepath = str(workdir / "blender.exr")
        bpy.ops.render.render(write_still=True, scene=scene.name)
        return read_rgba_exr(workdir / "blender.exr")
    finally:
        tree_group = getattr(scene, "compositing_node_group", None)
        bpy.data.scenes.remove(scene)
        if tree_group is not None:
            bpy.data.node_groups.remove(tree_group)
        for image in images:
            bpy.data.images.remove(image)
        camera_data = camera.data
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(camera_data)


def verify_last_render(background: bpy.types.Image, operator: str, workdir: Path) -> dict:
    """Compare ours and Blender's composite of the current Render Result over ``background``."""
    from compositing import composite

    from .verify import write_exr

    result = bpy.data.images.get("Render Result")
    if result is None:
        raise ValueError("Render Result: there is no render yet; render a frame first (F12)")
    if not background.filepath:
        raise ValueError(f"background: image {background.name!r} has no file to read")
    started = time.perf_counter()
    render_path = workdir / "render.exr"
    settings = bpy.context.scene.render.image_settings
    saved = (settings.file_format, settings.color_depth, settings.color_mode)
    try:  # save_render writes in the scene's output format: make it a 32-bit float RGBA EXR
        settings.file_format, settings.color_depth, settings.color_mode = "OPEN_EXR", "32", "RGBA"
        result.save_render(str(render_path), scene=bpy.context.scene)
    finally:
        settings.file_format, settings.color_depth, settings.color_mode = saved
    render = read_rgba_exr(render_path)
    plate = _read_background(bpy.path.abspath(background.filepath))
    if plate.shape != render.shape:
        raise ValueError(
            f"background: {background.name!r} is {plate.shape[1]}×{plate.shape[0]}, "
            f"the render {render.shape[1]}×{render.shape[0]}; use an image of the render's size"
        )
    ours = composite(render, plate, operator)
    theirs = blender_alpha_over(render, plate, operator, workdir)
    difference = np.abs(ours.astype(np.float64) - theirs).astype(np.float32)
    files = {"render": render_path, "ours": workdir / "ours.exr", "difference": workdir / "difference.exr"}
    write_exr(files["ours"], ours)
    write_exr(files["difference"], difference)
    return {
        "operator": operator,
        "max_abs_error": float(difference.max()),
        "mean_abs_error": float(difference.mean()),
        "seconds": time.perf_counter() - started,
        "files": {**{k: str(v) for k, v in files.items()}, "blender": str(workdir / "blender.exr")},
        "difference": difference,
    }


def _show_difference(context: bpy.types.Context, difference: np.ndarray) -> bpy.types.Image:
    """Put ``difference`` (row 0 at the top) into DIFFERENCE_IMAGE and show it in an Image Editor."""
    height, width = difference.shape[:2]
    image = bpy.data.images.get(DIFFERENCE_IMAGE)
    if image is None or tuple(image.size) != (width, height):
        if image is not None:
            bpy.data.images.remove(image)
        image = bpy.data.images.new(DIFFERENCE_IMAGE, width, height, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    shown = difference.copy()
    shown[..., 3] = 1.0  # show the colour differences opaque; the alpha difference is in the EXR
    image.pixels.foreach_set(np.ascontiguousarray(shown[::-1]).ravel())
    image.update()
    screen = getattr(context, "screen", None)
    for area in screen.areas if screen is not None else ():
        if area.type == "IMAGE_EDITOR":
            area.spaces.active.image = image
            break
    return image


class BLINN_PHONG_OT_verify_composite(bpy.types.Operator):  # noqa: N801 (Blender naming rule)
    """Composite the last render over the background with our operator and Blender's Alpha Over; compare"""

    bl_idname = "blinn_phong.verify_composite"
    bl_label = "Verify Against Blender"
    bl_options = {"REGISTER"}  # noqa: RUF012

    def execute(self, context: bpy.types.Context) -> set[str]:
        settings = context.scene.blinn_phong
        if settings.verify_background is None:
            self.report({"ERROR"}, "Choose a background image first")
            return {"CANCELLED"}
        from compositing._atomic import write_bytes_atomic

        LAST_VERIFY.clear()
        try:
            with tempfile.TemporaryDirectory(prefix="blinn-phong-verify-") as tmp:
                outcome = verify_last_render(settings.verify_background, settings.verify_operator, Path(tmp))
                keep = Path(bpy.app.tempdir or tempfile.gettempdir()) / "blinn_phong_verify"
                keep.mkdir(parents=True, exist_ok=True)
                for key, path in list(outcome["files"].items()):
                    target = keep / Path(path).name
                    write_bytes_atomic(target, Path(path).read_bytes())  # old copies survive a failure
                    outcome["files"][key] = str(target)
        except (ValueError, RuntimeError, OSError) as error:
            LAST_VERIFY.update({"error": str(error)})
            self.report({"ERROR"}, f"Verify against Blender failed: {error}")
            return {"CANCELLED"}
        _show_difference(context, outcome.pop("difference"))
        LAST_VERIFY.update(outcome)
        self.report(
            {"INFO"}, f"max |ours − Blender| = {outcome['max_abs_error']:.3g} ({outcome['operator']})"
        )
        return {"FINISHED"}


class BLINN_PHONG_PT_verify(bpy.types.Panel):  # noqa: N801
    """Compositor sidebar: compare our compositing with Blender's Alpha Over on the last render"""

    bl_space_type = "NODE_EDITOR"
    bl_region_type = "UI"
    bl_category = "Blinn-Phong"
    bl_label = "Verify Against Blender"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        space = context.space_data
        return getattr(space, "tree_type", None) == "CompositorNodeTree" and hasattr(
            context.scene, "blinn_phong"
        )

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        settings = context.scene.blinn_phong
        layout.template_ID(settings, "verify_background", open="image.open")
        layout.prop(settings, "verify_operator")
        layout.operator(BLINN_PHONG_OT_verify_composite.bl_idname, icon="CHECKMARK")
        if "max_abs_error" in LAST_VERIFY:
            layout.label(text=f"Max error {LAST_VERIFY['max_abs_error']:.3g} ({LAST_VERIFY['operator']})")
        elif "error" in LAST_VERIFY:
            layout.label(text=LAST_VERIFY["error"], icon="ERROR")


classes = (BLINN_PHONG_OT_verify_composite, BLINN_PHONG_PT_verify)


def register() -> None:
    """Register the operator and the compositor sidebar panel."""
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister() -> None:
    """Unregister in reverse order."""
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
