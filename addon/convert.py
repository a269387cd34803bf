"""Evaluated depsgraph -> ``blinn_phong.model.scene.Scene``.

Reads what the renderer needs out of Blender and nothing else; every formula lives in
``addon/mapping.py``. What is converted:

* meshes and everything that evaluates to a mesh (modifiers applied, geometry-node and collection
  instances, via ``depsgraph.object_instances``), as loop triangles: one vertex per face corner,
  carrying Blender's corner normal, so custom split normals, sharp edges and flat faces all come
  through unchanged; split per material slot;
* object transforms (``matrix_world`` of each instance, parenting included);
* the scene camera (perspective or orthographic, sensor fit, shift, clipping, pixel aspect), the
  resolution percentage and the render border;
* point, spot, sun and area lights, and the world colour as the global ambient light;
* holdouts (a Holdout node on the active Material Output's Surface, ``Object.is_holdout``, a
  collection marked *Holdout* in the view layer) as ``Mesh.holdout``, and light and shadow linking
  (``Object.light_linking`` receiver and blocker collections) as ``Scene.light_links``
  (:func:`light_links`).

Convention changes happen here: Blender's matrices are row-major ``Matrix`` objects acting on column
vectors, which numpy reads unchanged (``np.array(matrix)``); Blender's camera looks down -Z with +Y
up in its local frame, exactly OpenGL's eye space, so the view matrix is the inverse of the camera's
(scale-free) world matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import bpy
import numpy as np

from blinn_phong.model.lights import AmbientLight, DirectionalLight, PointLight, SpotLight
from blinn_phong.model.scene import Camera, LightLink, LightModel, Material, Mesh, Scene

from . import compat, mapping, textures
from .options import RenderOptions
from .principled import clamp_to_socket_range, principled_inputs

__all__ = [
    "DEFAULT_SURFACE",
    "ConvertedScene",
    "RenderOptions",
    "camera_from_object",
    "camera_parameters",
    "clamp_to_socket_range",
    "cryptomatte_names",
    "derived_light_values",
    "holdout_weight",
    "light_from_object",
    "light_links",
    "light_radius",
    "material_from_blender",
    "material_holdout",
    "material_is_holdout",
    "mesh_arrays",
    "principled_inputs",
    "scene_from_depsgraph",
    "viewport_camera",
    "world_ambient",
]


@dataclass
class ConvertedScene:
    """A Blender scene ready for ``blinn_phong``.

    Attributes:
        scene: the renderer's scene; its camera covers ``region`` only when a border is set.
        width: full frame width in pixels (after the resolution percentage).
        height: full frame height in pixels.
        region: ``(x0, y0, x1, y1)`` pixel rectangle to render, y from the top row; the whole frame
            without a render border.
        options: render settings.
        mesh_names: ``"<object>/<material>"`` for each mesh in ``scene.meshes``.
        light_group_names: the light group (``Object.lightgroup``, "" for none) of each entry of
            ``scene.lights``, of each mesh's object (its emission), and of the world
            (``World.lightgroup``): keys ``"lights"``, ``"meshes"``, ``"world"``.
        cryptomatte_names: per Cryptomatte layer (``"object"``, ``"material"``, ``"asset"``), the
            name Cycles hashes for each mesh in ``scene.meshes`` (:func:`cryptomatte_names`).
        extras: per mesh, the material settings the core ``Material`` does not hold (the
            shading override, already applied to ``Mesh.shading``).
        light_radii: per entry of ``scene.lights``, the light's radius (``light_radius``; 0 for suns),
            for soft shadows.
        casts_shadows: per entry of ``scene.lights``, Blender's Light › Cast Shadow
            (``Light.use_shadow``).
        background: the world colour the frame is composited over (``src_over``) when
            *Film → Transparent* is off, as Blender's own engines show the world behind the
            objects; None when it is on (coverage alpha is kept).
        notes: things that were skipped or approximated, for the log and the Render panel.
    """

    scene: Scene
    width: int
    height: int
    region: tuple[int, int, int, int]
    options: RenderOptions
    mesh_names: list[str] = field(default_factory=list)
    extras: list[dict[str, object]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    light_radii: list[float] = field(default_factory=list)
    background: tuple[float, float, float] | None = None
    casts_shadows: list[bool] = field(default_factory=list)
    cryptomatte_names: dict[str, list[str]] = field(default_factory=dict)
    light_group_names: dict[str, object] = field(default_factory=dict)

    @property
    def region_size(self) -> tuple[int, int]:
        """Width and height of :attr:`region` in pixels."""
        x0, y0, x1, y1 = self.region
        return x1 - x0, y1 - y0


# --------------------------------------------------------------------------- meshes


def mesh_arrays(mesh: bpy.types.Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Corner-based triangle arrays of a Blender mesh (object space).

    Returns:
        ``positions`` (L, 3) and ``normals`` (L, 3) float64, one row per face corner (loop);
        ``triangles`` (T, 3) int64 corner indices, counter-clockwise seen from the front;
        ``material_index`` (T,) int64 material slot of each triangle.
    """
    mesh.calc_loop_triangles()
    n_verts, n_loops, n_tris = len(mesh.vertices), len(mesh.loops), len(mesh.loop_triangles)
    co = np.empty(n_verts * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    loop_vertex = np.empty(n_loops, dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", loop_vertex)
    corner_normals = np.empty(n_loops * 3, dtype=np.float32)
    mesh.corner_normals.foreach_get("vector", corner_normals)
    tri_loops = np.empty(n_tris * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", tri_loops)
    material_index = np.empty(n_tris, dtype=np.int32)
    mesh.loop_triangles.foreach_get("material_index", material_index)
    positions = co.reshape(-1, 3).astype(np.float64)[loop_vertex]
    return (
        positions,
        corner_normals.reshape(-1, 3).astype(np.float64),
        tri_loops.reshape(-1, 3).astype(np.int64),
        material_index.astype(np.int64),
    )


# --------------------------------------------------------------------------- materials


def _surface_node(material: bpy.types.Material | None) -> bpy.types.Node | None:
    """The node feeding the Surface of the material's active Material Output (None: unlinked)."""
    tree = None if material is None else material.node_tree
    if tree is None:
        return None
    outputs = [n for n in tree.nodes if n.type == "OUTPUT_MATERIAL"]
    output = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    surface = output.inputs.get("Surface") if output is not None else None
    if surface is None or not surface.is_linked:
        return None
    return surface.links[0].from_node


def _shader_source(socket: bpy.types.NodeSocket) -> bpy.types.Node | None:
    """The node feeding a shader input (through reroutes); None when unlinked."""
    node = socket.links[0].from_node if socket.is_linked else None
    while node is not None and node.type == "REROUTE":
        node = node.inputs[0].links[0].from_node if node.inputs[0].is_linked else None
    return node


def holdout_weight(node: bpy.types.Node | None) -> float | None:
    """The holdout weight of the shader tree ending at ``node``, as Cycles sums it: 1 for a
    *Holdout* node, ``(1 − fac)·w(first) + fac·w(second)`` for a *Mix Shader* (the shader closure
    weights Cycles gives the two inputs, ``svm_node_mix_closure``), 0 for any other shader or an
    unlinked input; None when a Mix Shader's factor is linked (a weight per shading point).
    """
    if node is None:
        return 0.0
    if node.type == "HOLDOUT":
        return 1.0
    if node.type != "MIX_SHADER":
        return 0.0
    fac_socket, first, second = node.inputs[0], node.inputs[1], node.inputs[2]
    w_first = holdout_weight(_shader_source(first))
    w_second = holdout_weight(_shader_source(second))
    if w_first is None or w_second is None:
        return None
    if w_first == w_second:
        return w_first  # the factor does not matter (e.g. two shaders without a holdout)
    if fac_socket.is_linked:
        return None
    fac = min(max(float(fac_socket.default_value), 0.0), 1.0)  # Cycles clamps the factor to [0, 1]
    return (1.0 - fac) * w_first + fac * w_second


def material_holdout(material: bpy.types.Material | None) -> tuple[bool, str | None]:
    """Whether the material's surface is a holdout, and a note when it is a partial one.

    The surface is a full holdout when its holdout weight (:func:`holdout_weight`) is 1: a
    *Holdout* node on the active Material Output's Surface, or a *Mix Shader* with the Holdout
    at factor 1 (second input) or 0 (first input). The core's holdouts are whole
    (``Mesh.holdout``), so a weight strictly between 0 and 1 (Cycles: alpha reduced by the
    weight) or a linked factor is not rendered as a holdout: the note names the material and
    says so, and the surface is rendered as its other shader.
    """
    node = _surface_node(material)
    weight = holdout_weight(node)
    if weight == 1.0:
        return True, None
    if weight == 0.0:
        return False, None
    name = material.name if material is not None else "(none)"
    if weight is None:
        what = "a Holdout mixed by a linked factor"
    else:
        what = f"a partial holdout (a Holdout mixed at weight {weight:.3g})"
    return False, (
        f"{name}: the surface is {what}; only whole holdouts (weight 0 or 1) are rendered, "
        "so it is rendered without the holdout"
    )


def material_is_holdout(material: bpy.types.Material | None) -> bool:
    """True when the material's surface is a whole holdout (:func:`material_holdout`): a Holdout
    node on the active Material Output's Surface, or one mixed in at weight 1."""
    return material_holdout(material)[0]


def _linked_objects(collection: object) -> dict[str, bool] | None:
    """Per object name, whether a light-linking collection links it (None: no collection: all).

    Blender's rule (``depsgraph_light_linking.cc``, ``EmitterSetMembership::get_mask``): when the
    collection includes anything, only its included objects are linked; otherwise every object
    but its excluded ones. Names not in the dict follow the ``"*"`` entry.
    """
    if collection is None:
        return None
    states: dict[str, str] = {}
    for obj, state in compat.collection_link_states(collection):  # type: ignore[arg-type]
        states[obj.name] = state
    any_included = "INCLUDE" in states.values()
    out = {
        name: (state == "INCLUDE") if any_included else (state != "EXCLUDE") for name, state in states.items()
    }
    out["*"] = not any_included
    return out


def light_links(
    light_objects: list[bpy.types.Object], mesh_objects: list[str]
) -> tuple[LightLink | None, ...] | None:
    """``Scene.light_links`` of the lights (their objects, in ``scene.lights`` order) over the meshes
    (the name of each mesh's original object): a receiver mask from ``receiver_collection``, a
    blocker mask from ``blocker_collection`` (:func:`_linked_objects`); None when no light links."""
    links: list[LightLink | None] = []
    for obj in light_objects:
        masks = []
        for collection in compat.light_linking_collections(obj):
            linked = _linked_objects(collection)
            masks.append(
                None
                if linked is None
                else np.array([linked.get(name, linked["*"]) for name in mesh_objects], dtype=bool)
            )
        links.append(None if masks[0] is None and masks[1] is None else LightLink(masks[0], masks[1]))
    return tuple(links) if any(link is not None for link in links) else None


def material_from_blender(
    material: bpy.types.Material | None,
) -> tuple[Material, dict[str, object], list[str]]:
    """The Blinn-Phong material of a Blender material, its per-mesh settings and notes.

    ``Material.blinn_phong.source == "CUSTOM"`` uses the stored coefficients; otherwise they are
    derived from the Principled BSDF (``mapping.blinn_phong_from_principled``). The transparency
    model, Kay-Greenberg parameters and specular wash-out go to the core ``Material``; the shading
    override (``extras["shading"]``) goes to the ``Mesh``.
    """
    settings = getattr(material, "blinn_phong", None) if material is not None else None
    notes: list[str] = []
    if settings is not None and settings.source == "CUSTOM":
        values: dict[str, object] = {
            "ambient": tuple(settings.ambient),
            "diffuse": tuple(settings.diffuse),
            "specular": tuple(settings.specular),
            "emission": tuple(settings.emission),
            "shininess": float(settings.shininess),
            "opacity": float(settings.opacity),
        }
    else:
        inputs, notes = principled_inputs(material)
        values = mapping.blinn_phong_from_principled(**inputs)
    extras: dict[str, object] = {"shading": None}
    if settings is not None:
        values["transparency_model"] = settings.transparency_model.lower()
        values["specular_washout"] = bool(settings.specular_washout)
        if settings.use_kay_greenberg:
            values["kay_greenberg"] = (
                float(settings.kay_min_transmission),
                float(settings.kay_max_transmission),
                float(settings.kay_exponent),
            )
        extras["shading"] = None if settings.shading == "SCENE" else settings.shading.lower()
    return Material(**values), extras, notes


# --------------------------------------------------------------------------- lights


def light_radius(light: bpy.types.Light) -> float:
    """Radius of a Blender light for the softened inverse-square falloff (``point_light_attenuation``).

    Point and spot: ``shadow_soft_size``; area: the radius of the disc of equal area.
    """
    if light.type != "AREA":
        return float(light.shadow_soft_size)
    sx = light.size
    sy = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
    area = sx * sy * (math.pi / 4.0 if light.shape in ("DISK", "ELLIPSE") else 1.0)
    return math.sqrt(area / math.pi)


def derived_light_values(light: bpy.types.Light) -> dict[str, float]:
    """kc, kl, kq and spot exponent derived from a Blender light's own values (``mapping``).

    Spot: exponent from Spot Size and Spot Blend; area: 1 (the Lambertian ``cos θ`` lobe); else 0.
    """
    kc, kl, kq = mapping.point_light_attenuation(light_radius(light))
    exponent = {"SPOT": None, "AREA": 1.0}.get(light.type, 0.0)
    if exponent is None:
        exponent = mapping.spot_exponent(light.spot_size, light.spot_blend)
    return {"constant": kc, "linear": kl, "quadratic": kq, "spot_exponent": exponent}


def _light_falloff(light: bpy.types.Light) -> tuple[float, float, float, float]:
    """``(kc, kl, kq, spot exponent)``: custom values, or the derived ones."""
    settings = getattr(light, "blinn_phong", None)
    if settings is not None and settings.source == "CUSTOM":
        return settings.constant, settings.linear, settings.quadratic, settings.spot_exponent
    values = derived_light_values(light)
    return values["constant"], values["linear"], values["quadratic"], values["spot_exponent"]


def light_from_object(
    light: bpy.types.Light, matrix_world: np.ndarray
) -> DirectionalLight | PointLight | SpotLight:
    """The Blinn-Phong light of a Blender light placed by ``matrix_world`` (4×4).

    Sun -> DirectionalLight (``S/π``); point -> PointLight (``P/(4π²)``, inverse square softened
    by the radius); spot -> SpotLight (cutoff = half the cone, exponent from Spot Blend);
    area -> SpotLight with cutoff 90° and exponent 1 (the Lambertian ``cos θ`` lobe, ``P/π²``).
    Power and colour come from ``compat.light_emission`` (exposure and blackbody colour where
    Blender has them); the light's Diffuse and Specular factors scale the OpenGL diffuse and
    specular colours.
    """
    m = np.asarray(matrix_world, dtype=np.float64)
    position = m[:3, 3]
    axis = -m[:3, 2]
    settings = getattr(light, "blinn_phong", None)
    scale = float(settings.intensity_scale) if settings is not None else 1.0
    power, colour = compat.light_emission(light)
    if light.type == "SUN":
        intensity = mapping.sun_light_intensity(power)
    elif light.type in ("POINT", "SPOT"):
        intensity = mapping.point_light_intensity(power)
    elif light.type == "AREA":
        intensity = mapping.area_light_intensity(power)
    else:
        raise ValueError(f"light.type: expected SUN, POINT, SPOT or AREA, got {light.type!r}")
    rgb = np.asarray(colour) * intensity * scale
    colours = {
        "diffuse": tuple(float(c) for c in rgb * float(light.diffuse_factor)),
        "specular": tuple(float(c) for c in rgb * float(light.specular_factor)),
    }
    if light.type == "SUN":
        return DirectionalLight(direction=axis, **colours)
    kc, kl, kq, exponent = _light_falloff(light)
    falloff = {"constant": kc, "linear": kl, "quadratic": kq}
    if light.type == "POINT":
        return PointLight(position=position, **falloff, **colours)
    cutoff = mapping.spot_cutoff_degrees(light.spot_size) if light.type == "SPOT" else 90.0
    return SpotLight(
        position=position, direction=axis, cutoff=cutoff, exponent=exponent, **falloff, **colours
    )


def world_ambient(world: bpy.types.World | None) -> tuple[float, float, float]:
    """Global ambient colour: the world's Background node Color × Strength when Blender renders the
    world from nodes, else ``world.color``.

    A uniform environment of radiance ``L`` reflects ``albedo · L`` from an unoccluded Lambertian
    surface, so the world colour is the ambient intensity for ``ka = albedo``.
    """
    if world is None:
        return (0.0, 0.0, 0.0)
    tree = world.node_tree if compat.world_uses_nodes(world) else None
    node = None if tree is None else next((n for n in tree.nodes if n.type == "BACKGROUND"), None)
    if node is None:
        return tuple(float(c) for c in world.color[:3])
    color = node.inputs["Color"].default_value
    strength = float(node.inputs["Strength"].default_value)
    return (color[0] * strength, color[1] * strength, color[2] * strength)


# --------------------------------------------------------------------------- camera


def view_matrix(matrix_world: np.ndarray) -> np.ndarray:
    """World -> eye matrix of a Blender camera: the inverse of its world matrix with scale removed."""
    m = np.array(matrix_world, dtype=np.float64)
    m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
    return np.linalg.inv(m)


def camera_from_object(camera_object: bpy.types.Object, render: bpy.types.RenderSettings) -> Camera:
    """The Blinn-Phong camera of a Blender camera object for the full frame of ``render``."""
    data = camera_object.data
    if data.type not in ("PERSP", "ORTHO"):
        raise ValueError(f"camera.type: panoramic cameras are not supported, got {data.type!r}")
    width, height = mapping.render_size(
        render.resolution_x, render.resolution_y, render.resolution_percentage
    )
    projection = mapping.camera_projection(
        kind=data.type,
        width=width,
        height=height,
        lens_mm=data.lens,
        sensor_width_mm=data.sensor_width,
        sensor_height_mm=data.sensor_height,
        sensor_fit=data.sensor_fit,
        ortho_scale=data.ortho_scale,
        shift_x=data.shift_x,
        shift_y=data.shift_y,
        clip_start=data.clip_start,
        clip_end=data.clip_end,
        pixel_aspect_x=render.pixel_aspect_x,
        pixel_aspect_y=render.pixel_aspect_y,
    )
    kind = "perspective" if data.type == "PERSP" else "orthographic"
    return Camera(view_matrix(np.array(camera_object.matrix_world)), projection, kind)


def camera_parameters(camera_data: bpy.types.Camera) -> dict[str, object]:
    """The keyword arguments of ``mapping.camera_projection`` that describe a Blender camera."""
    if camera_data.type not in ("PERSP", "ORTHO"):
        raise ValueError(f"camera.type: panoramic cameras are not supported, got {camera_data.type!r}")
    return {
        "kind": camera_data.type,
        "lens_mm": camera_data.lens,
        "sensor_width_mm": camera_data.sensor_width,
        "sensor_height_mm": camera_data.sensor_height,
        "sensor_fit": camera_data.sensor_fit,
        "ortho_scale": camera_data.ortho_scale,
        "shift_x": camera_data.shift_x,
        "shift_y": camera_data.shift_y,
        "clip_start": camera_data.clip_start,
        "clip_end": camera_data.clip_end,
    }


def viewport_camera(
    space: bpy.types.SpaceView3D, region: bpy.types.Region, region_data: bpy.types.RegionView3D
) -> Camera:
    """The camera of a 3D view (``context.space_data``, ``context.region``, ``context.region_data``):
    its view matrix and ``mapping.viewport_projection`` (perspective, orthographic, camera view)."""
    camera = None
    if region_data.view_perspective == "CAMERA":
        camera = camera_parameters(space.camera.data)
    projection, kind = mapping.viewport_projection(
        view_perspective=region_data.view_perspective,
        region_width=int(region.width),
        region_height=int(region.height),
        lens_mm=space.lens,
        clip_start=space.clip_start,
        clip_end=space.clip_end,
        view_distance=region_data.view_distance,
        camera=camera,
        camera_zoom=region_data.view_camera_zoom,
        camera_offset=tuple(region_data.view_camera_offset),
    )
    return Camera(np.array(region_data.view_matrix, dtype=np.float64), projection, kind)


# --------------------------------------------------------------------------- scene


#: The material name Cycles gives a surface without a material (its default surface shader).
DEFAULT_SURFACE = "default_surface"


def cryptomatte_names(obj: bpy.types.Object, material: bpy.types.Material | None) -> tuple[str, str, str]:
    """``(object, material, asset)``: the names Cycles hashes for a surface's Cryptomatte IDs.

    The object's name; the material's (:data:`DEFAULT_SURFACE` without one); the asset is the
    object's top-most parent (Blender's ``BKE_cryptomatte_asset_hash``), or the object itself.
    """
    asset = obj
    while asset.parent is not None:
        asset = asset.parent
    return obj.name, DEFAULT_SURFACE if material is None else material.name, asset.name


def render_options(settings: object | None) -> RenderOptions:
    """Render options from ``Scene.blinn_phong`` (defaults when the property group is missing)."""
    return RenderOptions.from_settings(settings)


def scene_from_depsgraph(
    depsgraph: bpy.types.Depsgraph,
    view: tuple[Camera, int, int] | None = None,
    geometry_cache: dict[str, tuple] | None = None,
) -> ConvertedScene:
    """Convert the evaluated scene of ``depsgraph`` (meshes, lights, camera, world, settings).

    Args:
        depsgraph: the evaluated depsgraph (render or viewport).
        view: for the 3D viewport, ``(camera, width, height)`` replacing the scene camera and the
            render resolution (``viewport_camera``); the render border does not apply.
        geometry_cache: object name -> object-space triangle arrays, kept between calls by the
            viewport (``engine.ViewportState``) so that only objects whose geometry changed are read
            again; a fresh dict per call when None.

    Raises:
        ValueError: the scene has no camera (and no ``view``), or the camera is panoramic.
    """
    bl_scene = depsgraph.scene
    render = bl_scene.render
    settings = getattr(bl_scene, "blinn_phong", None)
    options = render_options(settings)
    if view is not None:
        camera, width, height = view
        region = (0, 0, width, height)
    else:
        if bl_scene.camera is None:
            raise ValueError("scene.camera: the scene has no camera to render from")
        camera_object = bl_scene.camera.evaluated_get(depsgraph)
        camera = camera_from_object(camera_object, render)
        width, height = mapping.render_size(
            render.resolution_x, render.resolution_y, render.resolution_percentage
        )
        region = (0, 0, width, height)
        if render.use_border:
            region = mapping.border_rectangle(
                render.border_min_x,
                render.border_max_x,
                render.border_min_y,
                render.border_max_y,
                width,
                height,
            )
            if region[2] <= region[0] or region[3] <= region[1]:
                raise ValueError(f"render border: the border covers no pixel ({region})")
            camera = Camera(
                camera.view, mapping.crop_projection(camera.projection, width, height, region), camera.kind
            )

    meshes: list[Mesh] = []
    names: list[str] = []
    crypto: dict[str, list[str]] = {"object": [], "material": [], "asset": []}
    groups: dict[str, object] = {"lights": [], "meshes": [], "world": ""}
    extras: list[dict[str, object]] = []
    notes: list[str] = []
    lights: list[DirectionalLight | PointLight | SpotLight | AmbientLight] = []
    light_radii: list[float] = []
    casts_shadows: list[bool] = []
    light_objects: list[bpy.types.Object] = []
    mesh_objects: list[str] = []  # the original object of each mesh, for light linking
    no_shadow_objects: list[str] = []
    shadow_objects = 0
    if geometry_cache is None:
        geometry_cache = {}
    texture_cache: dict = {}  # one Texture per image and settings, however many objects use it

    for instance in depsgraph.object_instances:
        obj = instance.object
        matrix = np.array(instance.matrix_world, dtype=np.float64)
        if obj.type == "LIGHT":
            lights.append(light_from_object(obj.data, matrix))
            light_objects.append(getattr(obj, "original", obj))
            groups["lights"].append(str(getattr(obj, "lightgroup", "")))  # type: ignore[union-attr]
            light_radii.append(0.0 if obj.data.type == "SUN" else light_radius(obj.data))
            # Light > Cast Shadow off, or Object > Visibility > Ray Visibility > Shadow off on the lamp
            casts_shadows.append(bool(getattr(obj.data, "use_shadow", True)))
            continue
        if obj.type not in ("MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES"):
            continue
        if not instance.show_self:  # an instancer whose "Show Instancer" is off for this depsgraph
            continue
        if not getattr(obj, "visible_camera", True):  # Object > Visibility > Ray Visibility > Camera
            continue
        key = obj.name
        if key not in geometry_cache:
            try:
                mesh = obj.to_mesh()
            except RuntimeError:
                mesh = None
            if mesh is None:
                notes.append(f"{obj.name}: has no mesh geometry; skipped")
                continue
            try:
                arrays = mesh_arrays(mesh)
                uvs = textures.mesh_uvs(mesh)  # per-corner UV layers (image textures)
            finally:
                obj.to_mesh_clear()
            slots = [slot.material for slot in obj.material_slots]
            geometry_cache[key] = (*arrays, slots, uvs)
        positions, normals, triangles, material_index, slots, uvs = geometry_cache[key]
        if len(triangles) == 0:
            continue
        determinant = np.linalg.det(matrix[:3, :3])
        if abs(determinant) < 1e-12:
            notes.append(f"{obj.name}: zero scale; skipped")
            continue
        if determinant < 0:
            # A mirroring transform (negative scale) turns counter-clockwise faces clockwise on
            # screen; Blender keeps them front-facing, so the winding is reversed here.
            triangles = triangles[:, ::-1]
        object_meshes: list[tuple[Mesh, str, dict[str, object], tuple[str, str, str]]] = []
        failed = None
        held_out = compat.object_holdout(obj, getattr(depsgraph, "view_layer", None))
        for slot_index in np.unique(material_index):
            blender_material = slots[slot_index] if 0 <= slot_index < len(slots) else None
            material_name = blender_material.name if blender_material else "(none)"
            try:
                material, extra, material_notes = material_from_blender(blender_material)
                material, uv = textures.textured_material(
                    material, blender_material, material_notes, uvs, texture_cache
                )  # image textures (addon/textures.py)
            except (ValueError, TypeError) as error:
                failed = (
                    f"object '{obj.name}', material '{material_name}': {error}; the object is not rendered"
                )
                break
            material_held_out, holdout_note = material_holdout(blender_material)
            if holdout_note is not None and not held_out:
                material_notes.append(holdout_note)
            notes.extend(n for n in material_notes if n not in notes)
            used = triangles[material_index == slot_index]
            mesh = Mesh(
                positions=positions,
                triangles=used,
                normals=normals,
                transform=matrix,
                material=material,
                shading=extra.pop("shading"),
                uv=uv,
                casts_shadows=bool(getattr(obj, "visible_shadow", True)),  # Ray Visibility > Shadow
                holdout=held_out or material_held_out,
            )
            ids = cryptomatte_names(obj, blender_material)
            object_meshes.append((mesh, f"{obj.name}/{material_name}", extra, ids))
        if failed is not None:
            notes.append(failed)
            continue
        if getattr(obj, "visible_shadow", True):
            shadow_objects += 1
        else:
            no_shadow_objects.append(obj.name)
        for mesh, name, extra, ids in object_meshes:
            meshes.append(mesh)
            names.append(name)
            extras.append(extra)
            for layer, value in zip(("object", "material", "asset"), ids, strict=True):
                crypto[layer].append(value)
            groups["meshes"].append(str(getattr(obj, "lightgroup", "")))  # type: ignore[union-attr]
            mesh_objects.append(getattr(obj, "original", obj).name)

    if no_shadow_objects and shadow_objects == 0:
        # Object > Visibility > Ray Visibility > Shadow off on every object: nothing casts a shadow,
        # so no light needs shadow work (a subset is left out per mesh: Mesh.casts_shadows).
        casts_shadows = [False] * len(casts_shadows)
    ambient = world_ambient(bl_scene.world)
    groups["world"] = str(getattr(bl_scene.world, "lightgroup", "")) if bl_scene.world is not None else ""
    light_model = LightModel(
        specular="phong" if options.specular_model == "PHONG" else "blinn",
        local_viewer=camera.kind == "perspective",
        two_sided=options.two_sided,
    )
    scene = Scene(
        meshes=tuple(meshes),
        lights=tuple(lights),
        camera=camera,
        ambient=ambient,
        light_model=light_model,
        light_links=light_links(light_objects, mesh_objects),
    )
    background = None if render.film_transparent else ambient
    return ConvertedScene(
        scene, width, height, region, options, names, extras, notes, light_radii, background, casts_shadows,
        crypto, groups,
    )  # fmt: skip
