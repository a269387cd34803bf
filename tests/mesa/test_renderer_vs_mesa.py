"""The GL-compatibility preset against real OpenGL: Mesa llvmpipe, fixed function and a GLSL shader.

Every scene is rendered twice — by ``blinn_phong.frame.render(..., gl_compat=True)`` and by
Mesa (``oracles.gl_lighting``) from the same Scene object — and compared on the
pixels both cover away from triangle edges (pixel centre at least 1/16 pixel from
every edge of its visible triangle): at most 1/255 per channel after OpenGL's float -> UNORM8
rounding ``floor(255·c + 0.5)``, and identical coverage there. Hygiene as in
docs/renderer.md: shininess in [1, 128], spot boundaries not on a sample,
dithering off, GL_NORMALIZE on.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

import blinn_phong as bp
from oracles.gl_common import to_unorm8
from tests.blinn_phong.renderer_scenes import (
    DIRECTIONAL,
    MATTE,
    POINT,
    SHINY,
    SPOT,
    floor_mesh,
    ortho_camera,
    perspective_camera,
    sphere_mesh,
)
from tests.pixels import interior_mask

pytestmark = pytest.mark.mesa

SIZE = 128
ENGINES = ["numpy", "numba"]  # the reference and the compiled fast path


GL_ORACLE = "gl_lighting"  # the gl fixture (tests/conftest.py)


def compare(ours: np.ndarray, theirs: np.ndarray, interior: np.ndarray) -> tuple[int, int, int]:
    """(coverage mismatches in the interior, max |diff| in 8-bit units there, interior pixel count)."""
    mine = to_unorm8(ours)
    gl = theirs.astype(np.int64)
    coverage_mismatch = int(np.count_nonzero((mine[..., 3] > 0)[interior] != (gl[..., 3] > 0)[interior]))
    diff = np.abs(mine[..., :3] - gl[..., :3]).max(axis=-1)
    return coverage_mismatch, int(diff[interior].max()), int(interior.sum())


def non_uniform_transform() -> np.ndarray:
    c, s = np.cos(0.6), np.sin(0.6)
    rot = np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]])
    scale = np.diag([1.4, 0.6, 0.9, 1.0])
    tilt = np.array(
        [[1, 0, 0, 0.1], [0, np.cos(0.4), -np.sin(0.4), 0], [0, np.sin(0.4), np.cos(0.4), 0], [0, 0, 0, 1]]
    )
    return tilt @ rot @ scale


SceneFactory = Callable[[], bp.Scene]

SCENES: dict[str, SceneFactory] = {
    "directional_ortho_infinite_viewer": lambda: bp.Scene(
        [sphere_mesh(SHINY)],
        [DIRECTIONAL],
        ortho_camera(),
        ambient=(0.1, 0.1, 0.1),
        light_model=bp.LightModel(local_viewer=False),
    ),
    "directional_ortho_local_viewer": lambda: bp.Scene(
        [sphere_mesh(SHINY)], [DIRECTIONAL], ortho_camera(), light_model=bp.LightModel(local_viewer=True)
    ),
    "point_attenuated_perspective_local_viewer": lambda: bp.Scene(
        [sphere_mesh(SHINY), floor_mesh(MATTE)],
        [POINT],
        perspective_camera(),
        light_model=bp.LightModel(local_viewer=True),
    ),
    "spot_perspective_infinite_viewer": lambda: bp.Scene(
        [sphere_mesh(SHINY), floor_mesh(MATTE, n=24)],
        [SPOT, bp.AmbientLight((0.1, 0.1, 0.12))],
        perspective_camera(),
        light_model=bp.LightModel(local_viewer=False),
    ),
    "three_lights_perspective_local_viewer": lambda: bp.Scene(
        [sphere_mesh(SHINY), floor_mesh(MATTE, n=24)],
        [DIRECTIONAL, POINT, SPOT],
        perspective_camera(),
        light_model=bp.LightModel(local_viewer=True),
    ),
    "non_uniform_scale_perspective": lambda: bp.Scene(
        [sphere_mesh(SHINY, non_uniform_transform())],
        [DIRECTIONAL, POINT],
        perspective_camera(),
        light_model=bp.LightModel(local_viewer=True),
    ),
    "two_sided_back_material": lambda: bp.Scene(
        [
            bp.Mesh(
                *_open_hemisphere(),
                material=SHINY,
                back_material=bp.Material(diffuse=(0.2, 0.8, 0.3), specular=(0.5, 0.5, 0.5), shininess=20.0),
                transform=non_uniform_transform(),
            )
        ],
        [DIRECTIONAL, POINT],
        perspective_camera(),
        light_model=bp.LightModel(local_viewer=True, two_sided=True),
    ),
    "floor_through_near_plane": lambda: bp.Scene(
        [floor_mesh(MATTE, n=8, y=-0.6, size=8.0), sphere_mesh(SHINY)],
        [POINT, SPOT],
        bp.Camera.perspective(70.0, 1.0, 0.5, 20.0, view=bp.look_at((0.2, -0.3, 3.0), (0.0, -0.5, 0.0))),
        light_model=bp.LightModel(local_viewer=True),
    ),
    "separate_specular_overbright": lambda: bp.Scene(
        [sphere_mesh(SHINY)],
        [DIRECTIONAL, bp.PointLight((1.5, 2.0, 3.0), (1.0, 1.0, 1.0), 1.6, linear=0.1)],
        perspective_camera(),
        light_model=bp.LightModel(local_viewer=True, separate_specular=True),
    ),
}


def _open_hemisphere() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The upper half of a UV sphere, open at the bottom so its inside (back faces) shows."""
    from blinn_phong.model.primitives import uv_sphere

    pos, tris, normals = uv_sphere(40, 20)
    keep = (pos[tris][:, :, 1] >= -1e-9).all(axis=1)
    pos = np.asarray(pos, np.float32).astype(np.float64)
    normals = np.asarray(normals, np.float32).astype(np.float64)
    # Turn it upside down and towards the camera so both the outside and the inside are seen.
    flip = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]], float) @ np.array(
        [[1, 0, 0], [0, np.cos(1.1), -np.sin(1.1)], [0, np.sin(1.1), np.cos(1.1)]]
    )
    return (
        np.asarray(pos @ flip.T, np.float32).astype(np.float64),
        tris[keep][:, [0, 2, 1]],
        -(normals @ flip.T),
    )


GOURAUD_CASES = list(SCENES)
FLAT_CASES = [
    "directional_ortho_infinite_viewer",
    "three_lights_perspective_local_viewer",
    "two_sided_back_material",
]
PHONG_CASES = [
    "directional_ortho_local_viewer",
    "floor_through_near_plane",
    "point_attenuated_perspective_local_viewer",
    "spot_perspective_infinite_viewer",
    "three_lights_perspective_local_viewer",
    "non_uniform_scale_perspective",
    "two_sided_back_material",
]


@pytest.mark.parametrize("case", GOURAUD_CASES)
@pytest.mark.parametrize("engine", ENGINES)
def test_gouraud_matches_fixed_function_smooth(gl, case: str, engine: str) -> None:
    scene = SCENES[case]()
    ours = bp.render(scene, SIZE, SIZE, shading="gouraud", gl_compat=True, engine=engine).rgba
    theirs = gl.render_fixed_function(scene, SIZE, SIZE).rgba
    mismatch, max_diff, n = compare(ours, theirs, interior_mask(scene, SIZE, SIZE))
    assert n > 2000
    assert mismatch == 0
    assert max_diff <= 1


@pytest.mark.parametrize("case", FLAT_CASES)
@pytest.mark.parametrize("engine", ENGINES)
def test_flat_matches_fixed_function_provoking_vertex(gl, case: str, engine: str) -> None:
    scene = SCENES[case]()
    ours = bp.render(scene, SIZE, SIZE, shading="flat", gl_compat=True, engine=engine).rgba
    theirs = gl.render_fixed_function(scene, SIZE, SIZE, flat=True).rgba
    mismatch, max_diff, _ = compare(ours, theirs, interior_mask(scene, SIZE, SIZE))
    assert mismatch == 0
    assert max_diff <= 1


@pytest.mark.parametrize("case", PHONG_CASES)
@pytest.mark.parametrize("engine", ENGINES)
def test_phong_matches_glsl_per_pixel_shader(gl, case: str, engine: str) -> None:
    scene = SCENES[case]()
    ours = bp.render(scene, SIZE, SIZE, shading="phong", gl_compat=True, engine=engine).rgba
    theirs = gl.render_glsl_phong(scene, SIZE, SIZE).rgba
    mismatch, max_diff, _ = compare(ours, theirs, interior_mask(scene, SIZE, SIZE))
    assert mismatch == 0
    assert max_diff <= 1


def test_single_sample_coverage_matches_including_edges_and_ties(gl) -> None:
    # Edges through pixel centres (exact ties) and arbitrary ones: the fill rule, the sub-pixel
    # snapping and near-plane handling give the same covered set as llvmpipe, edges included.
    width, height = 48, 40
    pts = np.array(
        [
            [2.5, 3.5],
            [17.5, 3.5],
            [17.5, 21.5],
            [2.5, 21.5],
            [30.5, 2.5],
            [44.5, 16.5],
            [30.5, 30.5],
            [20.25, 36.75],
            [33.1, 25.3],
            [46.9, 39.2],
            [5.0, 25.0],
            [14.0, 38.0],
            [3.0, 37.5],
        ]
    )
    tris = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [7, 8, 9], [10, 11, 12], [2, 1, 4]])
    pos = np.c_[pts, np.zeros(len(pts))]
    mesh = bp.Mesh(
        pos, tris, np.tile([0.0, 0.0, 1.0], (len(pts), 1)), material=bp.Material(ambient=(1, 1, 1))
    )
    scene = bp.Scene([mesh], [], bp.Camera.orthographic(0, width, 0, height, -1, 1), ambient=(1, 1, 1))
    ours = bp.render(scene, width, height, shading="gouraud", gl_compat=True).rgba[..., 3] > 0
    theirs = gl.render_fixed_function(scene, width, height).rgba[..., 3] > 0
    assert ours.sum() > 400
    np.testing.assert_array_equal(ours, theirs)


def test_comparison_detects_a_wrong_viewer_model(gl) -> None:
    # The oracle comparison is discriminating: the infinite-viewer equation against a
    # local-viewer OpenGL render differs by far more than 1/255 on the highlight.
    scene = SCENES["point_attenuated_perspective_local_viewer"]()
    wrong = bp.Scene(scene.meshes, scene.lights, scene.camera, light_model=bp.LightModel(local_viewer=False))
    ours = bp.render(wrong, SIZE, SIZE, shading="gouraud", gl_compat=True).rgba
    theirs = gl.render_fixed_function(scene, SIZE, SIZE).rgba
    _, max_diff, _ = compare(ours, theirs, interior_mask(scene, SIZE, SIZE))
    assert max_diff > 10


def test_near_plane_scene_compares_pixels_of_clipped_triangles() -> None:
    # Guards the clipping comparison above: thousands of compared pixels lie on triangles
    # that cross the near plane (clipped by both renderers).
    scene = SCENES["floor_through_near_plane"]()
    prepared = bp.prepare_scene(scene)
    in_front = (prepared.clip[:, 2] + prepared.clip[:, 3] >= 0)[prepared.triangles].sum(axis=1)
    crossing = (in_front == 1) | (in_front == 2)
    frags = bp.rasterize(prepared.clip, prepared.triangles, SIZE, SIZE)
    winner = bp.resolve_nearest(frags)
    on_clipped = np.zeros(SIZE * SIZE, bool)
    hit = winner >= 0
    on_clipped[hit] = crossing[frags.triangle[winner[hit]]]
    assert (on_clipped & interior_mask(scene, SIZE, SIZE).ravel()).sum() > 1000


def test_window_depth_matches_the_depth_buffer(gl) -> None:
    # glDepthRange(0, 1) window depth, perspective (non-linear in eye z), near-plane clipping:
    # equal to the 24-bit depth buffer up to its quantisation and float32 vertex maths.
    scene = SCENES["floor_through_near_plane"]()
    ours = bp.render(scene, SIZE, SIZE, shading="gouraud", gl_compat=True, engine="numpy").depth
    theirs = gl.render_fixed_function(scene, SIZE, SIZE).depth
    interior = interior_mask(scene, SIZE, SIZE)
    np.testing.assert_allclose(ours[interior], theirs[interior], rtol=0, atol=2e-6)
    empty = ours == 1.0
    np.testing.assert_array_equal(theirs[empty], 1.0)


def test_random_triangles_cover_the_same_pixels_as_mesa(gl) -> None:
    # 60 random triangles (arbitrary sub-pixel positions, both windings, some sliver-thin), each
    # at its own depth with its own exactly representable 8-bit emission: the whole image —
    # edges included — must be identical, i.e. the same triangle wins every pixel.
    rng = np.random.default_rng(2024)
    width, height = 96, 80
    meshes = []
    for i in range(60):
        centre = rng.uniform([0, 0], [width, height])
        pts = centre + rng.normal(scale=rng.choice([2.0, 6.0, 15.0]), size=(3, 2))
        if i % 7 == 0:
            pts[2] = pts[0] + (pts[1] - pts[0]) * 0.5 + rng.normal(scale=0.3, size=2)  # a sliver
        z = -1.0 - i * 0.05  # later triangles further away: depth order = draw order reversed
        pos = np.c_[pts, np.full(3, z)].astype(np.float32).astype(np.float64)
        level = (i * 4 + 10) / 255.0
        material = bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(level, 1 - level, (i % 5) / 5))
        meshes.append(
            bp.Mesh(pos, np.array([[0, 1, 2]]), np.tile([0.0, 0.0, 1.0], (3, 1)), material=material)
        )
    scene = bp.Scene(meshes, [], bp.Camera.orthographic(0, width, 0, height, 0.5, 10.0), ambient=(0, 0, 0))
    ours = to_unorm8(bp.render(scene, width, height, shading="flat", gl_compat=True, engine="numpy").rgba)
    theirs = gl.render_fixed_function(scene, width, height, flat=True).rgba.astype(np.int64)
    assert (ours[..., 3] > 0).sum() > 2000
    np.testing.assert_array_equal(ours, theirs)
