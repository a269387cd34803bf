"""Scenes and sample helpers for the shadow-volume tests (effects, failures, Mesa)."""

from __future__ import annotations

import numpy as np

from blinn_phong.frame.render import prepare_scene
from blinn_phong.geometry.raster import interpolate, rasterize, resolve_nearest
from blinn_phong.model.lights import DirectionalLight, PointLight, SpotLight
from blinn_phong.model.primitives import uv_sphere
from blinn_phong.model.scene import Camera, LightModel, Material, Mesh, Scene
from blinn_phong.model.transforms import look_at
from blinn_phong.shadows.raytrace import RayScene, directional_light_visibility, point_light_visibility

from .scenes import flat_cube, horizontal_quad, world_triangles

WIDTH, HEIGHT = 160, 120

LIGHTS = {
    "point": PointLight((1.0, 0.5, 3.5)),
    "spot": SpotLight((1.0, 0.5, 3.5), (-0.3, -0.15, -1.0), 60.0),
    "directional": DirectionalLight((-0.5, -0.3, -1.0)),
}


def _material() -> Material:
    return Material(ambient=(0.8, 0.8, 0.8), diffuse=(0.8, 0.8, 0.8), specular=(0.2, 0.2, 0.2))


def sphere_mesh(centre, radius, segments=24, rings=12) -> Mesh:
    p, t, n = uv_sphere(segments, rings, radius)
    transform = np.eye(4)
    transform[:3, 3] = centre
    return Mesh(p, t, normals=n, transform=transform, material=_material())


def torus_mesh(centre, major=0.9, minor=0.32, nu=32, nv=16, tilt_deg=35.0) -> Mesh:
    """A closed torus (shared vertices, outward counter-clockwise faces) around +Z, tilted about X."""
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = major + minor * np.cos(vv)
    pos = np.stack([ring * np.cos(uu), ring * np.sin(uu), minor * np.sin(vv)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * nv + j).ravel()
    b = (((i + 1) % nu) * nv + j).ravel()
    c = (((i + 1) % nu) * nv + (j + 1) % nv).ravel()
    d = (i * nv + (j + 1) % nv).ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    t = np.radians(tilt_deg)
    rot = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    transform = np.eye(4)
    transform[:3, :3] = rot
    transform[:3, 3] = centre
    return Mesh(pos, tris.astype(np.int64), transform=transform, material=_material())


def casters(name: str) -> list[Mesh]:
    """The casters of a named test scene (all closed 2-manifolds)."""
    if name == "sphere":
        return [sphere_mesh((0.0, 0.0, 1.2), 0.7)]
    if name == "torus":
        return [torus_mesh((0.0, 0.0, 1.1))]
    if name == "box":
        return [flat_cube((0.0, 0.0, 0.5), 0.5)]
    if name == "pair":
        return [sphere_mesh((0.0, 0.0, 1.2), 0.7), sphere_mesh((0.55, 0.3, 1.55), 0.5, 20, 10)]
    raise ValueError(name)


def outside_camera() -> Camera:
    return Camera.perspective(
        40.0, WIDTH / HEIGHT, 0.5, 40.0, view=look_at((0.0, -6.0, 5.0), (0.0, 0.0, 0.5), (0, 0, 1))
    )


def inside_camera(light, centre, radius) -> Camera:
    """A camera just behind a caster as seen from the light: inside its shadow volume."""
    centre = np.asarray(centre, float)
    if isinstance(light, DirectionalLight):
        away = np.asarray(light.direction, float)
    else:
        away = centre - np.asarray(light.position, float)
    away /= np.linalg.norm(away)
    eye = centre + away * (radius + 0.25)
    target = eye + np.array([2.0, 1.2, -0.9])
    return Camera.perspective(70.0, WIDTH / HEIGHT, 0.05, 40.0, view=look_at(eye, target, (0, 0, 1)))


def scene_with(meshes: list[Mesh], light, camera: Camera, ground: bool = True) -> Scene:
    ground_mesh = [horizontal_quad(0.0, half=4.0)] if ground else []
    return Scene(tuple(ground_mesh + meshes), (light,), camera, light_model=LightModel())


def samples(scene: Scene, width: int = WIDTH, height: int = HEIGHT):
    """The nearest surface at every pixel centre: (world points, face normals, flat pixel index, depth)."""
    prepared = prepare_scene(scene)
    frags = rasterize(prepared.clip, prepared.triangles, width, height)
    win = resolve_nearest(frags)
    vis = frags.subset(win[win >= 0])
    eye = interpolate(vis, prepared.triangles, prepared.eye_position)
    world = (np.c_[eye, np.ones(len(eye))] @ np.linalg.inv(scene.camera.view).T)[:, :3]
    return world, prepared.face_world_normal[vis.triangle], vis.pixel, vis.depth


def embree_visibility(light, tris: np.ndarray, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Hard shadows by Embree shadow rays (origin offset 1e-4 along the normal, as the volumes use)."""
    rs = RayScene(tris)
    if isinstance(light, DirectionalLight):
        return directional_light_visibility(rs, points, normals, -np.asarray(light.direction))
    return point_light_visibility(rs, points, normals, light.position)


def embree_reference(scene: Scene, light, tris: np.ndarray | None = None):
    """The visible samples of ``scene`` and Embree's hard shadows of ``light`` there.

    ``tris``: the occluders (default: every triangle of ``scene``). Returns (world points, face
    normals, flat pixel index, visibility 0/1, boundary band): the band marks the samples touching
    a lit/shadowed boundary of the ray-traced mask (:func:`boundary_band`, radius 0).
    """
    pts, nrm, pix, _ = samples(scene)
    truth = embree_visibility(light, world_triangles(scene) if tris is None else tris, pts, nrm)
    band = boundary_band(image_of(truth.astype(np.int64), pix), radius=0).ravel()[pix]
    return pts, nrm, pix, truth, band


def image_of(values: np.ndarray, pixel: np.ndarray, width: int = WIDTH, height: int = HEIGHT, fill=-1):
    img = np.full(width * height, fill, dtype=np.int64)
    img[pixel] = values
    return img.reshape(height, width)


def boundary_band(mask: np.ndarray, radius: int = 1) -> np.ndarray:
    """Pixels within ``radius`` pixels (Chebyshev) of a lit/shadowed boundary of ``mask``.

    ``mask``: (H, W) int image, 1 lit, 0 shadowed, −1 uncovered (uncovered neighbours do not
    make a boundary).
    """
    h, w = mask.shape
    edge = np.zeros((h, w), bool)
    pad = np.pad(mask, 1, constant_values=-1)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            nb = pad[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
            edge |= (mask >= 0) & (nb >= 0) & (nb != mask)
    band = edge.copy()
    for _ in range(radius):
        pad = np.pad(band, 1)
        grown = band.copy()
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                grown |= pad[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
        band = grown
    return band
