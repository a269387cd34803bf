""" "Verify against Blender": the last render over a background, by our operator and by Alpha Over.

Inside a running Blender (no second process), and every image goes through Blender's own image
API, so the operator needs nothing beyond Blender and the add-on: no OpenImageIO (the bpy 4.2
module has none; 4.5 and later carry it outside ``sys.path``) and no colour-science.

* The Render Result is saved with ``Image.save_render`` as a 32-bit float RGBA EXR (lossless ZIP;
  a float format gets no view transform) and loaded back.
* The background: an EXR file is read as stored (the project convention: premultiplied linear
  RGBA), any other image (PNG, JPEG, TIFF, packed or generated) is decoded by Blender with the
  image's own colour space and alpha mode (``save_render`` to a float EXR converts it to scene-linear
  premultiplied RGBA).
* Arrays become Blender images with ``bpy.data.images.new(float_buffer=True)`` and
  ``Image.pixels.foreach_set``, and EXR files are read with ``bpy.data.images.load`` and
  ``Image.pixels.foreach_get``, as ``Non-Color``/``Channel Packed`` so Blender converts nothing
  (bit-exact both ways; tests/addon/test_addon_verify_operator.py checks the files with
  OpenImageIO).

Ours is ``compositing.composite(render, background, operator)``. Blender's is a throw-away scene
whose compositor holds two Image nodes (the same arrays) and an Alpha Over node, rendered once. The
operator reports the largest difference and shows ``|ours − Blender|`` as the image "Blinn-Phong
Verify Difference" in an Image Editor.
"""

import contextlib
import tempfile
import time
from collections.abc import Iterator
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
    "image_to_array",
    "read_background",
    "read_exr",
    "register",
    "unregister",
    "write_exr",
]

LAST_VERIFY: dict = {}
"""Outcome of the last verification: ``max_abs_error``, ``mean_abs_error``, ``operator``, ``seconds``,
``files`` (render, background, ours, Blender's, difference as EXR)."""

DIFFERENCE_IMAGE = "Blinn-Phong Verify Difference"


@contextlib.contextmanager
def _float_exr_output(scene: bpy.types.Scene) -> Iterator[None]:
    """Make ``scene``'s output a lossless 32-bit float RGBA EXR for the ``with`` block, then restore it.

    ``Image.save_render`` writes in the scene's output format; a user's scene may hold PNG, half
    floats or a lossy EXR codec (DWAA, B44). Linear float formats get no view transform.
    """
    settings = scene.render.image_settings
    names = ("media_type", "file_format", "color_depth", "color_mode", "exr_codec", "color_management")
    saved = {name: getattr(settings, name) for name in names if hasattr(settings, name)}
    try:
        compat.set_image_format(settings, "OPEN_EXR", "32")
        settings.color_mode = "RGBA"
        settings.exr_codec = "ZIP"
        if "color_management" in saved:
            settings.color_management = "FOLLOW_SCENE"
        yield
    finally:
        for name in names:  # media_type first: it decides which file formats are valid (5.0)
            if name in saved:
                setattr(settings, name, saved[name])


def image_to_array(image: bpy.types.Image) -> np.ndarray:
    """The pixels of a Blender image as (H, W, 4) float32, row 0 at the top.

    ``Image.pixels`` holds the bottom row first; an RGB image gets alpha 1. Values are Blender's
    buffer as it is (for an EXR loaded ``Non-Color``/``Channel Packed``: the file's values).
    """
    width, height = image.size
    channels = image.channels
    if width == 0 or height == 0 or channels not in (3, 4):
        raise ValueError(
            f"image: {image.name!r} has {width}×{height} pixels and {channels} channels; expected an "
            "RGB or RGBA image with pixels"
        )
    flat = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(flat)
    pixels = flat.reshape(height, width, channels)[::-1]
    if channels == 3:
        pixels = np.concatenate([pixels, np.ones((height, width, 1), np.float32)], axis=-1)
    return np.ascontiguousarray(pixels)


def _new_image(name: str, rgba: np.ndarray) -> bpy.types.Image:
    """A float Blender image holding ``rgba`` ((H, W, 4), row 0 at the top) unconverted."""
    rgba = np.asarray(rgba, dtype=np.float32)
    if rgba.ndim != 3 or rgba.shape[2] != 4:
        raise ValueError(f"rgba: expected shape (height, width, 4), got {rgba.shape}")
    height, width = rgba.shape[:2]
    image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=True)
    # Colour space and alpha mode first: changing them regenerates a generated image's buffer.
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "CHANNEL_PACKED"
    image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())
    image.update()
    return image


def read_exr(path: Path | str) -> np.ndarray:
    """An EXR file as (H, W, 4) float32, row 0 at the top, values as stored (Blender's image loader).

    Loaded ``Non-Color`` with alpha mode ``Channel Packed``: no colour-space conversion and no
    (un)premultiplication; the temporary image data-block is removed again.
    """
    image = bpy.data.images.load(str(path), check_existing=False)
    try:
        image.colorspace_settings.name = "Non-Color"
        image.alpha_mode = "CHANNEL_PACKED"
        return image_to_array(image)
    finally:
        bpy.data.images.remove(image)


def write_exr(path: Path | str, rgba: np.ndarray, scene: bpy.types.Scene) -> None:
    """Write (H, W, 4) float RGBA, row 0 at the top, as a lossless 32-bit float EXR (``Image.save_render``).

    ``scene`` lends its output settings (switched to EXR for the call, then restored).
    """
    image = _new_image("Blinn-Phong Verify Output", rgba)
    try:
        with _float_exr_output(scene):
            image.save_render(str(path), scene=scene)
    finally:
        bpy.data.images.remove(image)


def read_background(image: bpy.types.Image, workdir: Path, scene: bpy.types.Scene) -> np.ndarray:
    """A background image in the project convention: (H, W, 4) linear premultiplied float32, row 0 on top.

    An EXR file is read as stored (:func:`read_exr`; EXR holds premultiplied linear RGBA). Any other
    image is decoded by Blender with the data-block's own colour space and alpha mode: saved with
    ``save_render`` as a float EXR (scene-linear, premultiplied) and read back.
    """
    path = bpy.path.abspath(image.filepath, library=image.library) if image.filepath else ""
    if path.lower().endswith(".exr") and image.packed_file is None:
        if not Path(path).is_file():
            raise ValueError(f"background: image {image.name!r} reads {path}, which does not exist")
        return read_exr(path)
    decoded = workdir / "background_linear.exr"
    with _float_exr_output(scene):
        image.save_render(str(decoded), scene=scene)
    return read_exr(decoded)


def blender_alpha_over(src: np.ndarray, dst: np.ndarray, operator: str, workdir: Path) -> np.ndarray:
    """Composite premultiplied ``src`` over ``dst`` with Blender's Alpha Over node, in this Blender.

    Args:
        src: foreground, (H, W, 4) float32 premultiplied linear RGBA, row 0 at the top.
        dst: background, same shape.
        operator: ``src_over``, ``disjoint_over`` or ``conjoint_over`` (the last two need 5.0).
        workdir: directory receiving Blender's result, ``blender.exr``.

    Returns:
        Blender's result, (H, W, 4) float32, row 0 at the top.
    """
    if src.shape != dst.shape or src.ndim != 3 or src.shape[2] != 4:
        raise ValueError(
            f"src, dst: expected two (H, W, 4) images of one shape, got {src.shape} and {dst.shape}"
        )
    scene = bpy.data.scenes.new("Blinn-Phong Verify")
    images = [
        _new_image("Blinn-Phong Verify Foreground", src),
        _new_image("Blinn-Phong Verify Background", dst),
    ]
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
        compat.set_image_format(settings, "OPEN_EXR", "32")
        settings.color_mode, settings.exr_codec = "RGBA", "ZIP"
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
        return read_exr(workdir / "blender.exr")
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

    result = bpy.data.images.get("Render Result")
    if result is None:
        raise ValueError("Render Result: there is no render yet; render a frame first (F12)")
    scene = bpy.context.scene
    started = time.perf_counter()
    names = ("render", "background", "ours", "blender", "difference")
    files = {name: workdir / f"{name}.exr" for name in names}
    with _float_exr_output(scene):
        result.save_render(str(files["render"]), scene=scene)
    render = read_exr(files["render"])
    plate = read_background(background, workdir, scene)
    if plate.shape != render.shape:
        raise ValueError(
            f"background: {background.name!r} is {plate.shape[1]}×{plate.shape[0]}, "
            f"the render {render.shape[1]}×{render.shape[0]}; use an image of the render's size"
        )
    ours = composite(render, plate, operator)
    theirs = blender_alpha_over(render, plate, operator, workdir)
    difference = np.abs(ours.astype(np.float64) - theirs).astype(np.float32)
    for name, pixels in (("background", plate), ("ours", ours), ("difference", difference)):
        write_exr(files[name], pixels, scene)
    return {
        "operator": operator,
        "max_abs_error": float(difference.max()),
        "mean_abs_error": float(difference.mean()),
        "seconds": time.perf_counter() - started,
        "files": {k: str(v) for k, v in files.items()},
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
