"""The light protocol (:mod:`blinn_phong.model.lights`): what each light type knows of itself,
checked against closed forms, and a light type the renderer has never seen rendering through it.

The renderer asks a light for its homogeneous position, its direction to points, its eye-space
row of the lighting equation and its shadow cameras, never for its type; a new light type is
therefore one class implementing these. The last tests prove it with a class defined here.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model import lights as lights_module
from blinn_phong.model import scene as scene_module
from blinn_phong.model.lights import CUBE_FACES, AmbientLight, DirectionalLight, PointLight, SpotLight
from blinn_phong.model.primitives import grid_plane, uv_sphere
from blinn_phong.model.transforms import look_at
from blinn_phong.shadows.method import embree_available

VIEW = look_at((3.0, -4.0, 5.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))  # rigid: rotation and translation


def test_homogeneous_positions_are_gl_position() -> None:
    # OpenGL 2.1 §2.14.1: GL_POSITION = (p, 1) for a positional light, (−d, 0) towards a directional one.
    np.testing.assert_array_equal(DirectionalLight((0.0, 0.6, -0.8)).homogeneous(), [0.0, -0.6, 0.8, 0.0])
    np.testing.assert_array_equal(PointLight((1.0, 2.0, 3.0)).homogeneous(), [1.0, 2.0, 3.0, 1.0])
    np.testing.assert_array_equal(SpotLight((1.0, 2.0, 3.0)).homogeneous(), [1.0, 2.0, 3.0, 1.0])


def test_direction_to_points_is_the_unit_vector_and_distance() -> None:
    points = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [1.0, 2.0, 3.0]])
    towards, distance = PointLight((0.0, 0.0, 0.0)).direction_to(points)
    np.testing.assert_allclose(distance, [0.0, 5.0, np.sqrt(14.0)], rtol=1e-15)
    np.testing.assert_allclose(towards[1], [-0.6, -0.8, 0.0], rtol=1e-15)
    np.testing.assert_array_equal(towards[0], 0.0)  # at the light: no direction, no NaN
    towards, distance = DirectionalLight((0.0, 0.0, -1.0)).direction_to(points)
    np.testing.assert_array_equal(towards, np.tile([0.0, 0.0, 1.0], (3, 1)))
    assert np.isinf(distance).all()


@pytest.mark.parametrize(
    "light",
    [
        DirectionalLight((1.0, -2.0, -2.0)),
        PointLight((1.0, 2.0, 3.0), linear=0.5),
        SpotLight((1, 2, 3), (0, 0, -1), 30.0, 2.0),
    ],
)
def test_eye_space_rows_keep_angles_and_distances_under_a_rigid_view(light) -> None:
    # A rigid view preserves dot products and lengths: the eye-space row must describe the same
    # light as the world-space one, seen from the camera.
    row = light.eye_space(VIEW)
    point = np.array([0.3, -0.2, 0.1])
    eye_point = (VIEW @ np.r_[point, 1.0])[:3]
    world_towards, world_distance = light.direction_to(point[None])
    if row.position[3] == 0:
        eye_towards = row.position[:3]
    else:
        offset = row.position[:3] - eye_point
        eye_towards = offset / np.linalg.norm(offset)
        np.testing.assert_allclose(np.linalg.norm(offset), world_distance[0], rtol=1e-12)
    np.testing.assert_allclose(VIEW[:3, :3].T @ eye_towards, world_towards[0], atol=1e-12)
    if isinstance(light, SpotLight):
        np.testing.assert_allclose(VIEW[:3, :3].T @ row.spot_direction, light.direction, atol=1e-12)
        assert row.cos_cutoff == pytest.approx(np.cos(np.radians(30.0))) and row.spot_exponent == 2.0
    else:
        assert row.cos_cutoff == -np.inf
    expected = (1.0, 0.0, 0.0) if row.position[3] == 0 else (light.constant, light.linear, light.quadratic)
    assert row.attenuation == expected
    assert AmbientLight().eye_space(VIEW) is None


def _project(camera: tuple[np.ndarray, np.ndarray], points: np.ndarray) -> np.ndarray:
    view, projection = camera
    clip = (projection @ view @ np.c_[points, np.ones(len(points))].T).T
    return clip[:, :3] / clip[:, 3:]


def _sphere_points(centre: np.ndarray, radius: float, n: int = 400) -> np.ndarray:
    rng = np.random.default_rng(7)
    v = rng.normal(size=(n, 3))
    return centre + radius * v / np.linalg.norm(v, axis=1, keepdims=True) * rng.random((n, 1)) ** (1 / 3)


def test_a_directional_shadow_camera_holds_the_casters_bounding_sphere() -> None:
    centre, radius = np.array([0.5, -1.0, 2.0]), 1.5
    (camera,) = DirectionalLight((0.2, 0.3, -1.0)).shadow_cameras(centre, radius)
    ndc = _project(camera, _sphere_points(centre, radius))
    assert np.abs(ndc).max() <= 1.0


def test_a_point_lights_cube_faces_follow_the_major_axis_rule() -> None:
    # OpenGL 4.6 §8.13 table 8.19: a direction is looked up in the face of its major axis; that
    # face's camera sees the point inside its frustum.
    light = PointLight((0.0, 0.0, 0.0))
    cameras = light.shadow_cameras(np.array([0.0, 0.0, 0.0]), 10.0)
    assert len(cameras) == 6
    points = _sphere_points(np.zeros(3), 9.0)
    points = points[np.linalg.norm(points, axis=1) > 0.5]
    for p in points:
        axis = int(np.argmax(np.abs(p)))
        face = CUBE_FACES.index(next(f for f in CUBE_FACES if f[0] == axis and f[1] == np.sign(p[axis])))
        ndc = _project(cameras[face], p[None])[0]
        assert np.abs(ndc[:2]).max() <= 1.0 + 1e-12 and -1.0 <= ndc[2] <= 1.0


def test_a_narrow_spot_has_one_camera_and_a_wide_one_a_cube() -> None:
    centre, radius = np.array([0.0, 0.0, 0.0]), 1.0
    narrow = SpotLight((0.0, 0.0, 5.0), (0.0, 0.0, -1.0), 30.0).shadow_cameras(centre, radius)
    wide = SpotLight((0.0, 0.0, 5.0), (0.0, 0.0, -1.0), 85.0).shadow_cameras(centre, radius)
    assert len(narrow) == 1 and len(wide) == 6
    ndc = _project(narrow[0], _sphere_points(centre, radius))  # within the 30° cone seen from z = 5
    assert np.abs(ndc).max() <= 1.0


@dataclasses.dataclass(frozen=True)
class Lamp:
    """A light type the renderer has never seen: a bare lamp with the protocol of a point light,
    defined here and nowhere in the package."""

    position: tuple[float, float, float]
    ambient: tuple[float, float, float] = (0.0, 0.0, 0.0)
    diffuse: tuple[float, float, float] = (1.0, 0.9, 0.8)
    specular: tuple[float, float, float] = (1.0, 0.9, 0.8)
    constant: float = 1.0
    linear: float = 0.0
    quadratic: float = 0.0
    positional = True
    casts_shadows = True
    axis = None

    def homogeneous(self) -> np.ndarray:
        return np.r_[np.asarray(self.position, dtype=np.float64), 1.0]

    def direction_to(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        offset = np.asarray(self.position) - np.asarray(points, dtype=np.float64).reshape(-1, 3)
        distance = np.linalg.norm(offset, axis=1)
        return offset / np.where(distance > 0, distance, 1)[:, None], distance

    def eye_space(self, view: np.ndarray) -> lights_module.EyeLight:
        position = np.asarray(view, dtype=np.float64) @ np.r_[self.position, 1.0]
        attenuation = (self.constant, self.linear, self.quadratic)
        return lights_module.EyeLight(position, np.zeros(3), -np.inf, 0.0, attenuation)

    def shadow_cameras(self, centre: np.ndarray, radius: float) -> list:
        return PointLight(self.position).shadow_cameras(centre, radius)


def _scene(light: object) -> bp.Scene:
    p, t, _ = uv_sphere(24, 12, radius=0.5)
    ball = bp.Mesh(p + np.array([0.0, 0.0, 0.6]), t, material=bp.Material(diffuse=(0.8, 0.3, 0.2)))
    gp, gt, _ = grid_plane(2, 2, size=(4.0, 4.0))
    floor = bp.Mesh(gp, gt, material=bp.Material(diffuse=(0.6, 0.6, 0.6)))
    view = look_at((0.0, -4.0, 3.0), (0.0, 0.0, 0.3), (0, 0, 1))
    camera = bp.Camera.perspective(45.0, 4 / 3, 0.1, 50.0, view=view)
    return bp.Scene((floor, ball), (light,), camera)


@pytest.mark.parametrize("shadows", ["none", "shadow_map", "shadow_volume", "ray_traced", "auto"])
def test_a_new_light_type_renders_as_the_point_light_it_describes(shadows: str, monkeypatch) -> None:
    if shadows == "ray_traced" and not embree_available():
        pytest.skip("ray-traced shadows cast rays with embreex")
    monkeypatch.setattr(scene_module, "LIGHT_TYPES", (*lights_module.LIGHT_TYPES, Lamp))
    position = (1.0, -1.0, 3.0)
    known_light = PointLight(position, color=(1.0, 0.9, 0.8))
    known = bp.render(_scene(known_light), 64, 48, shadows=shadows)
    new = bp.render(_scene(Lamp(position)), 64, 48, shadows=shadows)
    np.testing.assert_array_equal(new.rgba, known.rgba)
    assert new.plan.shadows[0].method == known.plan.shadows[0].method
    if shadows not in ("none", "auto"):  # the ball does shadow the floor
        unshadowed = bp.render(_scene(known_light), 64, 48, shadows="none")
        assert np.abs(unshadowed.rgba - known.rgba).max() > 0.05
