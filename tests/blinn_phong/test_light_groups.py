"""Light group passes: each against the closed-form lighting of its own emitters, and their sum
against Combined.

A quad facing an orthographic camera, lit by two directional lights (specular 0, so each light
gives ``d_cm · L_d · max(n·l, 0)``, OpenGL 2.1 §2.14.1), a global ambient ``a_cs · a_cm`` and an
emission ``e_cm``: every pixel of a group's pass is the sum of its emitters' terms.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import blinn_phong as bp

W, H = 8, 6
MATERIAL = bp.Material(
    ambient=(0.3, 0.2, 0.1), diffuse=(0.6, 0.5, 0.4), specular=(0, 0, 0), emission=(0.05, 0.1, 0)
)
KEY = bp.DirectionalLight((0.0, -0.6, -0.8), color=(1.0, 0.9, 0.8), intensity=1.5)  # n·l = 0.8
FILL = bp.DirectionalLight((0.6, 0.0, -0.8), color=(0.2, 0.3, 0.9), intensity=0.7)  # n·l = 0.8
AMBIENT = (0.1, 0.2, 0.3)


def _scene(glass: bool = False) -> bp.Scene:
    quad = bp.Mesh(
        np.array([(0.5, 0.5, -1.0), (7.5, 0.5, -1.0), (7.5, 5.5, -1.0), (0.5, 5.5, -1.0)]),
        np.array([[0, 1, 2], [0, 2, 3]]),
        material=MATERIAL,
    )
    meshes = [quad]
    if glass:
        pane = bp.Material(
            ambient=(0.5, 0.5, 0.5), diffuse=(0.2, 0.2, 0.6), opacity=0.4, emission=(0.0, 0.0, 0.2)
        )
        meshes.append(
            bp.Mesh(
                np.array([(2, 1, -0.5), (5, 1, -0.5), (5, 5, -0.5), (2, 5, -0.5)]),
                np.array([[0, 1, 2], [0, 2, 3]]),
                material=pane,
            )
        )
    return bp.Scene(meshes, [KEY, FILL], bp.Camera.orthographic(0, W, 0, H, 0.1, 5.0), ambient=AMBIENT)


def _diffuse(light: bp.DirectionalLight) -> np.ndarray:
    n_dot_l = max(0.0, -float(np.dot(light.direction, (0.0, 0.0, 1.0))))
    return np.asarray(MATERIAL.diffuse) * np.asarray(light.diffuse) * n_dot_l


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_each_group_is_its_emitters_closed_form(engine: str) -> None:
    groups = bp.LightGroups(("key", "fill", "glow"), lights=("key", "fill"), meshes=("glow",), world="key")
    result = bp.render(_scene(), W, H, engine=engine, shadows="none", light_groups=groups)
    covered = result.rgba[..., 3] == 1.0
    assert covered.sum() == 7 * 5  # the quad covers pixel centres x 0.5..6.5, y 0.5..4.5
    expected = {
        "key": _diffuse(KEY) + np.asarray(AMBIENT) * MATERIAL.ambient,
        "fill": _diffuse(FILL),
        "glow": np.asarray(MATERIAL.emission),
    }
    assert math.isclose(float(np.dot(KEY.direction, (0, 0, -1))), 0.8)
    for group, colour in expected.items():
        got = result.passes[f"Combined_{group}"]
        assert got.shape == (H, W, 3) and got.dtype == np.float32
        np.testing.assert_allclose(
            got[covered], np.broadcast_to(colour, (covered.sum(), 3)), rtol=0, atol=1e-6
        )
        assert not got[~covered].any()
    total = sum(result.passes[f"Combined_{g}"] for g in groups.groups)
    np.testing.assert_allclose(total, result.rgba[..., :3], rtol=0, atol=1e-6)


@pytest.mark.parametrize("method", ["a_buffer", "weighted_blended", "zbuffer"])
def test_groups_sum_to_combined_through_transparency_and_samples(method: str) -> None:
    groups = bp.LightGroups(("a", "b", "c", "d"), lights=("a", "b"), meshes=("c", "d"), world="c")
    result = bp.render(
        _scene(glass=True),
        W,
        H,
        samples=4,
        engine="numpy",
        shadows="none",
        transparency=method,
        light_groups=groups,
    )
    assert 0 < result.rgba[..., 3].min() < 1 or result.rgba[..., 3].min() == 0  # edges and glass
    total = sum(result.passes[f"Combined_{g}"] for g in groups.groups)
    np.testing.assert_allclose(total, result.rgba[..., :3], rtol=0, atol=1e-6)


def test_a_light_in_no_group_is_in_no_pass() -> None:
    groups = bp.LightGroups(("key",), lights=("key", None), meshes=(None,))
    result = bp.render(_scene(), W, H, engine="numpy", shadows="none", light_groups=groups)
    covered = result.rgba[..., 3] == 1.0
    np.testing.assert_allclose(
        result.passes["Combined_key"][covered],
        np.broadcast_to(_diffuse(KEY), (covered.sum(), 3)),
        rtol=0,
        atol=1e-6,
    )


def test_an_empty_group_is_black_and_checks_name_the_field() -> None:
    groups = bp.LightGroups(("key", "empty"), lights=("key", "key"), meshes=("key",), world="key")
    result = bp.render(_scene(), W, H, engine="numpy", shadows="none", light_groups=groups)
    assert not result.passes["Combined_empty"].any()
    with pytest.raises(ValueError, match="one entry per light"):
        bp.render(_scene(), W, H, light_groups=bp.LightGroups(("k",), lights=("k",), meshes=("k",)))
    with pytest.raises(ValueError, match=r"LightGroups.lights\[0\]"):
        bp.LightGroups(("k",), lights=("x",), meshes=())
    with pytest.raises(ValueError, match="gl_compat"):
        bp.render(_scene(), W, H, gl_compat=True, light_groups=groups)


@pytest.mark.parametrize("shadows", ["shadow_map", "planar"])
def test_groups_keep_their_lights_shadows(shadows: str) -> None:
    from tests.blinn_phong.renderer_scenes import DIRECTIONAL, MATTE, POINT, SHINY, floor_mesh, sphere_mesh

    camera = bp.Camera.perspective(45.0, 4 / 3, 0.5, 20.0, view=bp.look_at((0, 1.5, 6), (0, -0.3, 0)))
    scene = bp.Scene([sphere_mesh(SHINY), floor_mesh(MATTE)], [DIRECTIONAL, POINT], camera)
    groups = bp.LightGroups(("sun", "lamp"), lights=("sun", "lamp"), meshes=(None, None), world="sun")
    result = bp.render(scene, 64, 48, engine="numba", shadows=shadows, light_groups=groups)
    assert result.passes["shadow"].min() < 0.5  # something is in shadow
    total = result.passes["Combined_sun"] + result.passes["Combined_lamp"]
    np.testing.assert_allclose(total, result.rgba[..., :3], rtol=0, atol=1e-6)
    alone = bp.render(
        bp.Scene(scene.meshes, [POINT], camera, ambient=(0, 0, 0)), 64, 48, engine="numba", shadows=shadows
    )
    np.testing.assert_allclose(result.passes["Combined_lamp"], alone.rgba[..., :3], rtol=0, atol=1e-6)


def _alone(scene: bp.Scene, lights: tuple[int, ...], world: bool, glowing: tuple[int, ...]) -> bp.Scene:
    """``scene`` with only the given emitters: those lights (their links kept), the world's
    ambient if ``world``, the emission of the meshes ``glowing`` (written out here, not by
    LightGroups.group_scene)."""
    from dataclasses import replace

    def dark(m: bp.Material) -> bp.Material:
        return replace(m, emission=(0.0, 0.0, 0.0))

    meshes = [
        mesh if i in glowing else replace(mesh, material=dark(mesh.material))
        for i, mesh in enumerate(scene.meshes)
    ]
    links = None if scene.light_links is None else tuple(scene.light_links[i] for i in lights)
    return replace(
        scene,
        meshes=tuple(meshes),
        lights=tuple(scene.lights[i] for i in lights),
        light_links=links,
        ambient=scene.ambient if world else (0.0, 0.0, 0.0),
    )


@pytest.mark.parametrize("method", ["zbuffer", "a_buffer", "depth_peeling", "weighted_blended"])
@pytest.mark.parametrize("fogged", [False, True])
def test_compiled_groups_equal_renders_with_their_emitters_alone(method: str, fogged: bool) -> None:
    # The compiled engine at one sample: the frame's own (fused) pass makes the group passes for
    # the z-buffer, the A-buffer and depth peeling (no per-group renders: no "light_groups"
    # stage); weighted blended OIT renders each group apart. Either way each pass equals the
    # frame rendered with its emitters alone (fogged towards black), and without fog they sum
    # to Combined.
    scene = _scene(glass=True)
    fog = bp.Fog("linear", (0.5, 0.6, 0.7), start=0.2, end=3.0) if fogged else None
    black = None if fog is None else bp.Fog("linear", (0.0, 0.0, 0.0), start=0.2, end=3.0)
    groups = bp.LightGroups(("a", "b", "c", "d"), lights=("a", "b"), meshes=("c", "d"), world="c")
    kw = {"engine": "numba", "shadows": "none", "transparency": method}
    result = bp.render(scene, W, H, fog=fog, light_groups=groups, **kw)
    assert ("light_groups" in result.stats.seconds) == (method == "weighted_blended")
    emitters = {"a": ((0,), False, ()), "b": ((1,), False, ()), "c": ((), True, (0,)), "d": ((), False, (1,))}
    for group, (lights, world, glowing) in emitters.items():
        alone = bp.render(_alone(scene, lights, world, glowing), W, H, fog=black, **kw)
        np.testing.assert_allclose(result.passes[f"Combined_{group}"], alone.rgba[..., :3], rtol=0, atol=1e-6)
    if fog is None:
        total = sum(result.passes[f"Combined_{g}"] for g in groups.groups)
        np.testing.assert_allclose(total, result.rgba[..., :3], rtol=0, atol=1e-6)


@pytest.mark.parametrize("shadows", ["shadow_map", "ray_traced"])
def test_fused_groups_keep_shadows_linking_and_ambient_lights(shadows: str) -> None:
    # The fused opaque pass with the lights' shadows (shadow maps looked up in the kernel, or
    # ray-traced visibilities), a receiver link on the point light, an AmbientLight in a group and
    # a light in no group: each group equals a render with its emitters alone.
    from dataclasses import replace

    from tests.blinn_phong.renderer_scenes import DIRECTIONAL, MATTE, POINT, SHINY, floor_mesh, sphere_mesh

    camera = bp.Camera.perspective(45.0, 4 / 3, 0.5, 20.0, view=bp.look_at((0, 1.5, 6), (0, -0.3, 0)))
    glow = replace(SHINY, emission=(0.05, 0.02, 0.0))
    meshes = [sphere_mesh(glow), floor_mesh(MATTE)]
    spare = bp.DirectionalLight((0.3, -1.0, 0.2), color=(0.2, 0.2, 0.3))
    lamp = replace(POINT, ambient=(0.0, 0.0, 0.0))  # a light with receivers has no ambient term
    lights = [DIRECTIONAL, lamp, bp.AmbientLight((0.1, 0.05, 0.0)), spare]
    links = (None, bp.LightLink(receivers=np.array([True, False])), None, None)  # the lamp: the sphere only
    scene = bp.Scene(meshes, lights, camera, ambient=(0.05, 0.05, 0.1), light_links=links)
    groups = bp.LightGroups(
        ("sun", "lamp", "glow"), lights=("sun", "lamp", "glow", None), meshes=("glow", None), world="sun"
    )
    result = bp.render(scene, 64, 48, engine="numba", shadows=shadows, light_groups=groups)
    assert "light_groups" not in result.stats.seconds  # made in the frame's pass
    assert result.passes["shadow"].min() < 0.5  # something is in shadow
    emitters = {"sun": ((0,), True, ()), "lamp": ((1,), False, ()), "glow": ((2,), False, (0,))}
    for group, (lit, world, glowing) in emitters.items():
        alone = bp.render(_alone(scene, lit, world, glowing), 64, 48, engine="numba", shadows=shadows)
        assert alone.rgba[..., :3].max() > 0
        np.testing.assert_allclose(result.passes[f"Combined_{group}"], alone.rgba[..., :3], rtol=0, atol=1e-6)
