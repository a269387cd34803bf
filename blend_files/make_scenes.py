"""Generate the sample .blend files (and the backplate image) for the Blinn-Phong engine.

Run with a Python that has ``bpy`` (the files are saved by Blender 4.2 LTS for the committed
copies, so that 4.2, 4.5 and 5.0 all open them)::

    .venv-blender42/bin/python blend_files/make_scenes.py [--out blend_files]

Writes:

* ``showcase.blend``: five spheres of increasing shininess (4 … 1024) under a world ambient, a
  sun, a point and a spot light; below them three coarse spheres shaded flat, Gouraud and
  Phong side by side;
* ``transparency.blend``: two interpenetrating glass boxes (red and blue, opacity 0.45) and a
  Kay-Greenberg glass sphere over an opaque floor ("Auto" transparency: the planner's A-buffer);
* ``shadows.blend``: a box, a sphere and a cone on a floor under a sun and a soft spot light
  ("Auto" shadows: the planner's choice per light);
* ``compositing.blend``: a torus rendered with a transparent background and composited over
  ``images/backplate.exr`` by Blender's Alpha Over node in the scene compositor;
* ``textures.blend``: an alpha-clipped fence card (an Image Texture node feeding the Principled
  BSDF's Base Color and Alpha; Closest interpolation, texel alpha 0 or 1) standing on a
  checker-textured floor beside an untextured box, under a sun casting shadows;
* ``passes.blend``: compositor passes: a crate, a ball and a cone on a floor under a sun; a red
  rim light linked to the ball alone (its receiver collection "Rim receivers"; the floor and
  the other shapes get none of its light); a card whose material is a Holdout node cutting a
  transparent hole through the cone and the floor; Cryptomatte (object) on the view layer. The
  compositor puts the render over ``images/backplate.exr`` (Alpha Over: the holdout's hole shows
  the backplate) and picks "Crate" with a Cryptomatte node shown in a Viewer node;
* ``images/backplate.exr``: a sky gradient over a checkered ground, linear premultiplied RGBA;
* ``images/fence.png``, ``images/floor_checker.png``: the two 32×32 textures of ``textures.blend``
  (sRGB PNGs generated here, referenced by the .blend with relative paths ``//images/…``).

Every scene is 320×180 pixels at 100 % and uses the engine ``BLINN_PHONG``; its frames go to
``//render/<scene>/####`` beside the .blend (e.g. ``render/showcase/0001.png``).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import bpy  # noqa: E402 - after the path set-up above
import numpy as np  # noqa: E402

from addon import compat, engine, properties  # noqa: E402

WIDTH, HEIGHT = 320, 180
SCENES = ("showcase", "transparency", "shadows", "compositing", "textures", "passes")
#: Texture size (texels) of the generated fence and floor images.
TEXTURE_SIZE = 32
#: Edge length (m) of the textured floor plane, centred at the origin (UV 0…1 across it).
FLOOR_SIZE = 8.0


def backplate(height: int = HEIGHT, width: int = WIDTH) -> np.ndarray:
    """The backplate: sky gradient above the horizon, grey checker ground below (linear, opaque)."""
    rows, cols = np.indices((height, width), dtype=np.float64)
    horizon = 0.55 * height
    sky_t = np.clip(rows / horizon, 0.0, 1.0)[..., None]
    sky = (1 - sky_t) * np.array([0.10, 0.25, 0.60]) + sky_t * np.array([0.60, 0.70, 0.85])
    checker = ((rows // 12 + cols // 12) % 2).astype(np.float64)[..., None]
    ground = 0.15 + 0.1 * checker * np.array([1.0, 1.0, 1.0])
    rgb = np.where((rows < horizon)[..., None], sky, ground)
    return np.concatenate([rgb, np.ones((height, width, 1))], axis=-1).astype(np.float32)


def _reset(name: str) -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.name = name
    scene.render.engine = engine.ENGINE_ID
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = (
        WIDTH,
        HEIGHT,
        100,
    )
    scene.render.film_transparent = True
    # Frames go next to the file, one folder per scene ("//render/showcase/0001.png"): two sample
    # files in one batch job never share an output, and nothing is written to Blender's /tmp/.
    scene.render.filepath = f"//render/{name.lower()}/####"
    scene.view_settings.view_transform = "Standard"
    scene.blinn_phong.samples_per_axis = 2
    world = bpy.data.worlds.new("World")
    scene.world = world
    _set_world_colour(world, (0.05, 0.05, 0.06))
    return scene


def _set_world_colour(world: bpy.types.World, rgb: tuple[float, float, float]) -> None:
    world.color = rgb
    if compat.world_uses_nodes(world):
        world.node_tree.nodes["Background"].inputs["Color"].default_value = (*rgb, 1.0)


def _camera(scene: bpy.types.Scene, location: tuple, target: tuple, lens: float = 40.0) -> bpy.types.Object:
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = location
    cam.data.lens = lens
    cam.data.clip_start, cam.data.clip_end = 0.5, 60.0
    scene.collection.objects.link(cam)
    direction = np.subtract(target, location)
    cam.rotation_euler = _look_rotation(direction)
    scene.camera = cam
    return cam


def _look_rotation(direction: np.ndarray) -> tuple[float, float, float]:
    """XYZ Euler angles that aim a camera or light (looking down its local -Z) along ``direction``, no roll.

    ``Rz(γ)·Rx(α)`` maps -Z to ``(−sin γ sin α, cos γ sin α, −cos α)``; solving for a unit
    direction ``(x, y, z)`` gives ``α = atan2(√(x² + y²), −z)``, ``γ = atan2(−x, y)``.
    """
    x, y, z = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    return (math.atan2(math.hypot(x, y), -z), 0.0, math.atan2(-x, y))


def _light(
    scene: bpy.types.Scene,
    kind: str,
    name: str,
    location: tuple,
    target: tuple,
    energy: float,
    **settings: object,
) -> bpy.types.Object:
    data = bpy.data.lights.new(name, kind)
    data.energy = energy
    for key, value in settings.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    obj.rotation_euler = _look_rotation(np.subtract(target, location))
    scene.collection.objects.link(obj)
    return obj


def _material(
    name: str,
    diffuse: tuple,
    *,
    specular: float = 0.5,
    shininess: float = 32.0,
    opacity: float = 1.0,
    shading: str = "SCENE",
) -> bpy.types.Material:
    mat = bpy.data.materials.new(name)
    mat.diffuse_color = (*diffuse, 1.0)
    bp = mat.blinn_phong
    bp.source = "CUSTOM"
    bp.ambient = bp.diffuse = diffuse
    bp.specular = (specular, specular, specular)
    bp.shininess = shininess
    bp.opacity = opacity
    bp.shading = shading
    return mat


def _add(
    obj_op: str, material: bpy.types.Material, *, smooth: bool = True, **kwargs: object
) -> bpy.types.Object:
    getattr(bpy.ops.mesh, obj_op)(**kwargs)
    obj = bpy.context.active_object
    if smooth:
        bpy.ops.object.shade_smooth()
    obj.data.materials.append(material)
    return obj


def make_showcase() -> bpy.types.Scene:
    """Shininess row, shading-frequency row, four kinds of light."""
    scene = _reset("Showcase")
    for i, shininess in enumerate((4.0, 16.0, 64.0, 256.0, 1024.0)):
        mat = _material(f"Shininess {shininess:g}", (0.55, 0.12, 0.08), specular=0.8, shininess=shininess)
        _add(
            "primitive_uv_sphere_add",
            mat,
            radius=0.55,
            segments=32,
            ring_count=16,
            location=(-3 + 1.5 * i, 0, 0.75),
        )
    for i, shading in enumerate(("FLAT", "GOURAUD", "PHONG")):
        mat = _material(
            f"{shading.title()} shading", (0.1, 0.3, 0.6), specular=0.6, shininess=48.0, shading=shading
        )
        _add(
            "primitive_uv_sphere_add",
            mat,
            radius=0.6,
            segments=12,
            ring_count=6,
            location=(-1.6 + 1.6 * i, 0, -0.8),
        )
    _light(scene, "SUN", "Sun", (0, -5, 6), (0, 0, 0), 1.5)
    _light(
        scene, "POINT", "Point", (-4, -3, 2), (0, 0, 0), 400.0, shadow_soft_size=0.2, color=(1.0, 0.85, 0.7)
    )
    _light(
        scene,
        "SPOT",
        "Spot",
        (4, -3, 3),
        (1.5, 0, 0.5),
        900.0,
        spot_size=math.radians(45),
        spot_blend=0.3,
        shadow_soft_size=0.1,
        color=(0.7, 0.85, 1.0),
    )
    _set_world_colour(scene.world, (0.08, 0.08, 0.1))
    _camera(scene, (0, -9, 1.2), (0, 0, 0))
    scene.blinn_phong.shadows = "NONE"
    return scene


def make_transparency() -> bpy.types.Scene:
    """Interpenetrating glass boxes and a Kay-Greenberg sphere over a floor."""
    scene = _reset("Transparency")
    _add(
        "primitive_plane_add",
        _material("Floor", (0.6, 0.6, 0.55), specular=0.1),
        smooth=False,
        size=10,
        location=(0, 0, -1),
    )
    red = _add(
        "primitive_cube_add",
        _material("Red glass", (0.9, 0.1, 0.1), opacity=0.45, shininess=80),
        smooth=False,
        size=1.4,
        location=(-0.9, 0, 0),
    )
    red.rotation_euler = (0.0, 0.0, math.radians(30))
    blue = _add(
        "primitive_cube_add",
        _material("Blue glass", (0.1, 0.2, 0.9), opacity=0.45, shininess=80),
        smooth=False,
        size=1.4,
        location=(-0.3, 0.3, 0.2),
    )
    blue.rotation_euler = (math.radians(20), 0.0, math.radians(-15))
    kay = _material("Kay glass", (0.8, 0.9, 1.0), specular=0.9, shininess=120)
    kay.blinn_phong.use_kay_greenberg = True
    kay.blinn_phong.kay_min_transmission, kay.blinn_phong.kay_max_transmission = 0.1, 0.85
    _add("primitive_uv_sphere_add", kay, radius=0.8, segments=32, ring_count=16, location=(1.6, 0, 0))
    _light(scene, "SUN", "Sun", (3, -4, 6), (0, 0, 0), 2.0)
    _light(scene, "POINT", "Point", (-3, -3, 3), (0, 0, 0), 300.0, shadow_soft_size=0.25)
    _camera(scene, (0, -7, 2.5), (0.2, 0, -0.2))
    scene.blinn_phong.shadows = "NONE"
    return scene


def make_shadows() -> bpy.types.Scene:
    """Three shapes on a floor under a sun and a spot light."""
    scene = _reset("Shadows")
    _add(
        "primitive_plane_add",
        _material("Floor", (0.7, 0.7, 0.7), specular=0.05),
        smooth=False,
        size=12,
        location=(0, 0, 0),
    )
    _add(
        "primitive_cube_add",
        _material("Box", (0.8, 0.5, 0.2)),
        smooth=False,
        size=1.0,
        location=(-1.8, 0, 0.5),
    )
    _add(
        "primitive_uv_sphere_add",
        _material("Ball", (0.2, 0.6, 0.3), shininess=60),
        radius=0.6,
        segments=32,
        ring_count=16,
        location=(0, 0.5, 0.6),
    )
    _add(
        "primitive_cone_add",
        _material("Cone", (0.3, 0.3, 0.8)),
        smooth=False,
        radius1=0.6,
        depth=1.4,
        location=(1.8, 0, 0.7),
    )
    _light(scene, "SUN", "Sun", (4, -2, 6), (0, 0, 0), 2.0)
    _light(
        scene,
        "SPOT",
        "Spot",
        (-2, -3, 4),
        (0, 0, 0),
        800.0,
        spot_size=math.radians(60),
        spot_blend=0.2,
        shadow_soft_size=0.3,
    )
    _camera(scene, (0, -7, 4), (0, 0, 0.3))
    scene.blinn_phong.shadows = "AUTO"
    return scene


def make_compositing(backplate_path: Path) -> bpy.types.Scene:
    """A torus composited over the backplate by Blender's Alpha Over node."""
    scene = _reset("Compositing")
    _add(
        "primitive_torus_add",
        _material("Gold", (0.8, 0.55, 0.15), specular=0.9, shininess=90),
        major_radius=1.0,
        minor_radius=0.35,
        location=(0, 0, 0.2),
        rotation=(math.radians(60), 0, 0),
    )
    _light(scene, "SUN", "Sun", (3, -4, 5), (0, 0, 0), 2.5)
    _camera(scene, (0, -6, 1.0), (0, 0, 0.2))
    scene.blinn_phong.shadows = "NONE"
    tree = compat.compositor_tree(scene)
    compat.set_full_precision(scene)
    layers = tree.nodes.new("CompositorNodeRLayers")
    image_node = tree.nodes.new("CompositorNodeImage")
    image = bpy.data.images.load(str(backplate_path))
    image.filepath = "//images/" + backplate_path.name
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "PREMUL"
    image_node.image = image
    over = tree.nodes.new("CompositorNodeAlphaOver")
    compat.link_alpha_over(tree, over, image_node.outputs["Image"], layers.outputs["Image"])
    compat.configure_alpha_over(over, "src_over", straight_alpha=False, factor=1.0)
    tree.links.new(over.outputs["Image"], compat.add_render_output(tree))
    return scene


def make_passes(backplate_path: Path) -> bpy.types.Scene:
    """Cryptomatte pick, holdout and a linked light, and the compositor nodes that use them."""
    scene = _reset("Passes")
    _add(
        "primitive_plane_add",
        _material("Floor", (0.6, 0.6, 0.6), specular=0.05),
        smooth=False,
        size=10,
        location=(0, 0, 0),
    )
    crate = _add(
        "primitive_cube_add",
        _material("Wood", (0.8, 0.5, 0.2)),
        smooth=False,
        size=1.0,
        location=(-1.7, 0, 0.5),
    )
    crate.name = "Crate"
    ball = _add(
        "primitive_uv_sphere_add",
        _material("Paint", (0.2, 0.4, 0.8), shininess=60),
        radius=0.6,
        segments=32,
        ring_count=16,
        location=(0, 0.3, 0.6),
    )
    ball.name = "Ball"
    cone = _add(
        "primitive_cone_add",
        _material("Leaf", (0.3, 0.7, 0.3)),
        smooth=False,
        radius1=0.6,
        depth=1.4,
        location=(1.7, 0, 0.7),
    )
    cone.name = "Cone"
    holdout = bpy.data.materials.new("Holdout")
    holdout.use_nodes = True
    nodes = holdout.node_tree.nodes
    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    holdout.node_tree.links.new(nodes.new("ShaderNodeHoldout").outputs[0], output.inputs["Surface"])
    card = _add(
        "primitive_plane_add",
        holdout,
        smooth=False,
        size=1.0,
        location=(1.3, -1.2, 0.6),
        rotation=(1.4, 0, 0.3),
    )
    card.name = "Holdout card"
    _light(scene, "SUN", "Key", (3, -4, 6), (0, 0, 0), 2.0)
    rim = _light(scene, "POINT", "Rim", (1.4, -0.9, 1.3), (0, 0.3, 0.6), 250.0, color=(1.0, 0.2, 0.1))
    receivers = bpy.data.collections.new("Rim receivers")
    receivers.objects.link(ball)
    rim.light_linking.receiver_collection = receivers
    _camera(scene, (0, -7, 3), (0, 0, 0.4))
    scene.blinn_phong.shadows = "AUTO"
    scene.view_layers[0].use_pass_cryptomatte_object = True

    tree = compat.compositor_tree(scene)
    compat.set_full_precision(scene)
    layers = tree.nodes.new("CompositorNodeRLayers")
    layers.location = (-400, 0)
    plate = tree.nodes.new("CompositorNodeImage")
    plate.location = (-400, 300)
    image = bpy.data.images.load(str(backplate_path))
    image.filepath = "//images/" + backplate_path.name
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "PREMUL"
    plate.image = image
    over = tree.nodes.new("CompositorNodeAlphaOver")
    compat.link_alpha_over(tree, over, plate.outputs["Image"], layers.outputs["Image"])
    compat.configure_alpha_over(over, "src_over", straight_alpha=False, factor=1.0)
    tree.links.new(over.outputs["Image"], compat.add_render_output(tree))
    pick = tree.nodes.new("CompositorNodeCryptomatteV2")
    pick.location = (0, -300)
    pick.source = "RENDER"
    pick.scene = scene
    pick.matte_id = "Crate"
    tree.links.new(layers.outputs["Image"], pick.inputs["Image"])
    viewer = tree.nodes.new("CompositorNodeViewer")
    viewer.location = (300, -300)
    tree.links.new(pick.outputs["Image"], viewer.inputs["Image"])
    return scene


def fence_texels(size: int = TEXTURE_SIZE) -> np.ndarray:
    """The fence card's sRGB bytes, (size, size, 4) uint8, row 0 at the top, straight alpha.

    Alpha is 255 on vertical pickets (texel columns ``i % 8 < 3``) and on two rails, 0 in the
    gaps; the gaps hold magenta so that a leak of a transparent texel's colour would show.
    """
    rows, cols = np.indices((size, size))
    bottom_rows = size - 1 - rows
    picket = cols % 8 < 3
    rail = ((bottom_rows >= 4) & (bottom_rows < 7)) | ((bottom_rows >= 24) & (bottom_rows < 27))
    solid = picket | rail
    texels = np.empty((size, size, 4), np.uint8)
    texels[...] = (255, 0, 255, 0)
    wood = np.stack([140 + 20 * (cols // 8), 95 + 2 * (bottom_rows % 5), 55 + 0 * cols], axis=-1)
    texels[solid, :3] = wood[solid]
    texels[solid, 3] = 255
    return texels


def checker_texels(size: int = TEXTURE_SIZE) -> np.ndarray:
    """The floor's sRGB bytes, (size, size, 4) uint8, opaque: a checker of 4×4-texel squares."""
    rows, cols = np.indices((size, size))
    dark = ((rows // 4 + cols // 4) % 2).astype(bool)
    texels = np.empty((size, size, 4), np.uint8)
    texels[...] = (205, 195, 165, 255)
    texels[dark] = (95, 120, 85, 255)
    return texels


def _save_png(texels: np.ndarray, path: Path) -> bpy.types.Image:
    """Save sRGB bytes (row 0 at the top) as an 8-bit RGBA PNG through Blender; return the image
    datablock (its path is made relative to the .blend when the scene is saved)."""
    height, width = texels.shape[:2]
    image = bpy.data.images.new(path.stem, width, height, alpha=True)
    image.pixels.foreach_set((texels[::-1].astype(np.float32) / 255.0).ravel())  # rows bottom-up
    image.filepath_raw = str(path)
    image.file_format = "PNG"
    image.save()
    image.colorspace_settings.name = "sRGB"
    image.alpha_mode = "STRAIGHT"
    return image


def _textured_material(
    name: str, image: bpy.types.Image, *, alpha: bool, custom: tuple | None = None
) -> bpy.types.Material:
    """A Principled material whose Base Color (and Alpha) come from ``image`` (Closest, Repeat).

    ``custom``: ``(ambient, diffuse)`` Blinn-Phong coefficients with no specular (the texture then
    modulates them); None derives them from the Principled BSDF.
    """
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    principled = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    principled.inputs["Roughness"].default_value = 0.7
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Closest"
    tex.extension = "REPEAT"
    links.new(tex.outputs["Color"], principled.inputs["Base Color"])
    if alpha:
        links.new(tex.outputs["Alpha"], principled.inputs["Alpha"])
        # Alpha clip: Blender 4.2+ (EEVEE Next) renders it as "Dithered" (the texels' alpha is 0
        # or 1, so dithering is a clip); older versions have the Alpha Clip blend mode.
        if hasattr(mat, "surface_render_method"):
            mat.surface_render_method = "DITHERED"
        else:  # pragma: no cover - Blender < 4.2
            mat.blend_method = "CLIP"
            mat.alpha_threshold = 0.5
    if custom is not None:
        bp = mat.blinn_phong
        bp.source = "CUSTOM"
        bp.ambient, bp.diffuse = custom
        bp.specular = (0.0, 0.0, 0.0)
    return mat


def make_textures(images: Path) -> bpy.types.Scene:
    """An alpha-clipped fence card on a textured floor beside an untextured box, under a sun."""
    scene = _reset("Textures")
    scene.blinn_phong.samples_per_axis = 2
    checker = _save_png(checker_texels(), images / "floor_checker.png")
    fence = _save_png(fence_texels(), images / "fence.png")
    _add(
        "primitive_plane_add",
        _textured_material("Checker floor", checker, alpha=False, custom=((0.9,) * 3, (0.9,) * 3)),
        smooth=False,
        size=FLOOR_SIZE,
        location=(0, 0, 0),
    )
    _add(
        "primitive_plane_add",
        _textured_material("Fence", fence, alpha=True),
        smooth=False,
        size=1.8,
        location=(-0.3, 0, 0.9),
        rotation=(math.radians(90), 0, 0),
    )
    _add(
        "primitive_cube_add",
        _material("Box", (0.3, 0.45, 0.75), specular=0.0),
        smooth=False,
        size=0.8,
        location=(1.7, 0.4, 0.4),
    )
    _light(scene, "SUN", "Sun", (5, -2, 6), (0, 0, 0), 3.0)
    _set_world_colour(scene.world, (0.08, 0.08, 0.1))
    _camera(scene, (0.3, -6.5, 2.6), (0.2, 0.6, 0.5), lens=35.0)
    scene.blinn_phong.shadows = "AUTO"
    return scene


def main(argv: list[str] | None = None) -> int:
    """Write every sample scene (and the backplate) into ``--out``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent)
    args = parser.parse_args(argv)
    out = args.out.resolve()
    (out / "images").mkdir(parents=True, exist_ok=True)
    from compositing.io import write_image

    plate = out / "images" / "backplate.exr"
    write_image(plate, backplate(), float_format="half")
    makers = {
        "showcase": make_showcase,
        "transparency": make_transparency,
        "shadows": make_shadows,
        "compositing": lambda: make_compositing(plate),
        "textures": lambda: make_textures(out / "images"),
        "passes": lambda: make_passes(plate),
    }
    properties.register()
    engine.register()
    try:
        for name in SCENES:
            makers[name]()
            bpy.context.preferences.filepaths.save_version = 0  # no .blend1 backups
            path = out / f"{name}.blend"
            bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True, relative_remap=True)
            if any(i.filepath and not i.filepath.startswith("//") for i in bpy.data.images):
                bpy.ops.file.make_paths_relative()  # "//images/…": the .blend opens anywhere
                bpy.ops.wm.save_mainfile(compress=True)
            print(f"wrote {path}")
    finally:
        engine.unregister()
        properties.unregister()
    return 0


if __name__ == "__main__":
    sys.exit(main())
