"""addon.pipeline against the z-buffer reference, closed-form fog, over-compositing and shadow geometry."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest

from addon.pipeline import RenderOptions, render_frame
from blinn_phong.frame.render import render
from blinn_phong.model.lights import DirectionalLight
from blinn_phong.model.scene import Camera, LightModel, Material, Scene
from blinn_phong.model.transforms import look_at
from tests.meshes import square


def _top_camera(size: float = 4.0) -> Camera:
    """Orthographic camera 10 units above the origin looking down -Z, ``size`` units across."""
    return Camera.orthographic(
        -size / 2, size / 2, -size / 2, size / 2, 1.0, 20.0, view=look_at((0, 0, 10), (0, 0, 0), (0, 1, 0))
    )


def test_effects_recipe_without_effects_equals_the_z_buffer_renderer() -> None:
    # Forcing the A-buffer and zero-density fog on an opaque scene must reproduce blinn_phong.frame.render.
    # The two quads cannot shadow each other, so any shadow method leaves the reference unchanged.
    material = Material(diffuse=(0.6, 0.5, 0.4), specular=(0.3, 0.3, 0.3), shininess=20.0)
    scene = Scene(
        (
            square(0.0, 0.8, material, centre=(-1.0, 0.0)),
            square(0.5, 0.6, Material(diffuse=(0.1, 0.7, 0.2)), centre=(1.0, 0.0)),
        ),
        (DirectionalLight((0.3, -0.2, -1.0), intensity=1.2),),
        _top_camera(),
        ambient=(0.1, 0.1, 0.1),
    )
    reference = render(scene, 40, 40, samples=4)
    got = render_frame(
        scene,
        40,
        40,
        RenderOptions(transparency="A_BUFFER", shadows="NONE", fog="EXP", fog_density=0.0),
    )
    assert got.choices["transparency"] == "a_buffer" and got.choices["fog"] == "EXP"
    np.testing.assert_allclose(got.rgba, reference.rgba, atol=1e-6)
    np.testing.assert_allclose(got.depth, reference.depth, atol=1e-7)
    light = got.passes["ambient"] + got.passes["diffuse"] + got.passes["specular"]
    np.testing.assert_allclose(light, got.rgba[..., :3], atol=1e-6)


@pytest.mark.parametrize(
    ("mode", "factor"),
    [
        ("EXP", lambda d: math.exp(-0.15 * d)),
        ("EXP2", lambda d: math.exp(-((0.15 * d) ** 2))),
        ("LINEAR", lambda d: (12.0 - d) / (12.0 - 2.0)),
    ],
)
def test_fog_follows_the_opengl_fog_equations(mode: str, factor: Callable[[float], float]) -> None:
    # One emissive quad filling the view at eye distance 10: C = f·c + (1 - f)·C_fog (opaque).
    material = Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(0.8, 0.4, 0.2))
    scene = Scene((square(0.0, 5.0, material),), (), _top_camera(), ambient=(0.0, 0.0, 0.0))
    fog = (0.3, 0.5, 0.7)
    got = render_frame(
        scene,
        8,
        8,
        options=RenderOptions(
            samples_per_axis=1, fog=mode, fog_color=fog, fog_density=0.15, fog_start=2.0, fog_end=12.0
        ),
    )
    f = factor(10.0)
    expected = np.array([f * c + (1 - f) * g for c, g in zip((0.8, 0.4, 0.2), fog, strict=True)] + [1.0])
    np.testing.assert_allclose(got.rgba, np.broadcast_to(expected, (8, 8, 4)), atol=1e-6)


@pytest.mark.parametrize("method", ["AUTO", "A_BUFFER", "SORTED", "DEPTH_PEELING", "WEIGHTED"])
def test_transparent_quad_composites_over_the_one_behind(method: str) -> None:
    # Emissive glass (α = 0.4) above an opaque emissive floor: premultiplied over, per Porter-Duff.
    glass = Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(0.2, 0.6, 1.0), opacity=0.4)
    floor = Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(1.0, 0.5, 0.0))
    scene = Scene((square(0.0, 5.0, floor), square(1.0, 5.0, glass)), (), _top_camera(), ambient=(0, 0, 0))
    got = render_frame(scene, 8, 8, options=RenderOptions(samples_per_axis=1, transparency=method))
    expected = 0.4 * np.array([0.2, 0.6, 1.0]) + 0.6 * np.array([1.0, 0.5, 0.0])
    np.testing.assert_allclose(got.rgba[..., :3], np.broadcast_to(expected, (8, 8, 3)), atol=1e-6)
    np.testing.assert_allclose(got.rgba[..., 3], 1.0, atol=1e-7)


@pytest.mark.parametrize("shadows", ["AUTO", "HARD"])
def test_shadow_of_a_square_under_an_overhead_sun(shadows: str) -> None:
    # Sun straight down: the occluder's shadow on the floor is its own footprint, |x|, |y| < 0.5.
    floor = Material(ambient=(0, 0, 0), diffuse=(1.0, 1.0, 1.0))
    occluder = Material(ambient=(0, 0, 0), diffuse=(0.2, 0.2, 0.2))
    scene = Scene(
        (square(0.0, 2.0, floor), square(1.0, 0.5, occluder, centre=(1.2, 0.0))),
        (DirectionalLight((0.0, 0.0, -1.0), intensity=1.0),),
        _top_camera(),
        ambient=(0, 0, 0),
    )
    got = render_frame(scene, 40, 40, options=RenderOptions(samples_per_axis=1, shadows=shadows))
    # The planner may pick planar shadows (exact here: one receiving plane); HARD forces ray tracing.
    assert got.choices["shadows"] == (["ray_traced"] if shadows == "HARD" else ["planar"])
    # Pixel (row, col) centre -> world x = -2 + (col + 0.5)·0.1, y = 2 - (row + 0.5)·0.1.
    rows, cols = np.indices((40, 40))
    x, y = -2 + (cols + 0.5) * 0.1, 2 - (rows + 0.5) * 0.1
    under = (np.abs(x - 1.2) < 0.45) & (np.abs(y) < 0.45)  # seen from above: the occluder itself
    outside = (np.abs(x - 1.2) > 0.55) | (np.abs(y) > 0.55)
    np.testing.assert_allclose(got.rgba[..., 0][outside], 1.0, atol=1e-6)  # lit floor: kd·I·(n·l) = 1
    np.testing.assert_allclose(got.rgba[..., 0][under], 0.2, atol=1e-6)  # the lit occluder top
    # The shadow pass is of the nearest opaque surface: the occluder top is lit too.
    np.testing.assert_allclose(got.passes["shadow"][..., 0][outside | under], 1.0, atol=1e-6)


def test_shadow_falls_beside_the_occluder_under_a_slanted_sun() -> None:
    # Sun direction (1, 0, -1)/√2: the shadow of a square at height 1 is shifted +1 in x on the floor.
    floor = Material(ambient=(0, 0, 0), diffuse=(1.0, 1.0, 1.0))
    scene = Scene(
        (square(0.0, 2.0, floor), square(1.0, 0.3, Material(), centre=(-1.0, 0.0))),
        (DirectionalLight((1.0, 0.0, -1.0), intensity=1.0),),
        _top_camera(),
        ambient=(0, 0, 0),
    )
    got = render_frame(scene, 40, 40, options=RenderOptions(samples_per_axis=1, shadows="HARD"))
    rows, cols = np.indices((40, 40))
    x, y = -2 + (cols + 0.5) * 0.1, 2 - (rows + 0.5) * 0.1
    shadow = (np.abs(x - 0.0) < 0.25) & (np.abs(y) < 0.25)
    lit = ((np.abs(x) > 0.35) | (np.abs(y) > 0.35)) & ((np.abs(x + 1.0) > 0.35) | (np.abs(y) > 0.35))
    assert (got.passes["shadow"][..., 0][shadow] == 0).all()
    np.testing.assert_allclose(got.rgba[..., 0][shadow], 0.0, atol=1e-7)
    np.testing.assert_allclose(got.rgba[..., 0][lit], 1 / math.sqrt(2), atol=1e-6)


def test_bad_options_are_named() -> None:
    with pytest.raises(ValueError, match="transparency"):
        RenderOptions(transparency="MAGIC")
    with pytest.raises(ValueError, match="fog"):
        RenderOptions(fog="SMOKE")


@pytest.mark.parametrize("tilt_degrees", [0.0, 60.0])
def test_kay_greenberg_glass_opacity_follows_the_eye_normal(tilt_degrees: float) -> None:
    # Kay & Greenberg: t = t_min + (t_max - t_min)·(1 - (1 - |N_z|)^p); the glass has α = 1 - t.
    c, s = math.cos(math.radians(tilt_degrees)), math.sin(math.radians(tilt_degrees))
    rotate = np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 1.0], [0, 0, 0, 1]])  # about x, lifted to z = 1
    t_min, t_max, power = 0.1, 0.8, 2.0
    kay = Material(
        ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(0.0, 0.0, 1.0), kay_greenberg=(t_min, t_max, power)
    )
    glass = replace(square(0.0, 1.0, kay), transform=rotate)
    floor = square(0.0, 5.0, Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(1.0, 0.0, 0.0)))
    scene = Scene((floor, glass), (), _top_camera(), ambient=(0, 0, 0))
    got = render_frame(scene, 40, 40, RenderOptions(samples_per_axis=1))
    t = t_min + (t_max - t_min) * (1 - (1 - c) ** power)
    alpha = 1 - t
    centre = got.rgba[18:22, 18:22]  # inside the glass's footprint for both tilts
    np.testing.assert_allclose(centre[..., 2], alpha, atol=1e-6)
    np.testing.assert_allclose(centre[..., 0], 1 - alpha, atol=1e-6)
    assert got.choices["transparency"] != "zbuffer"


def test_without_embree_shadows_fall_back_to_shadow_volumes(monkeypatch: pytest.MonkeyPatch) -> None:
    # Blender's Python has no embreex: ray-traced shadows become shadow volumes, with the reason given.
    import sys

    monkeypatch.setitem(sys.modules, "embreex", None)
    monkeypatch.setitem(sys.modules, "blinn_phong.shadows.raytrace", None)
    floor = Material(ambient=(0, 0, 0), diffuse=(1.0, 1.0, 1.0))
    scene = Scene(
        (square(0.0, 2.0, floor), square(1.0, 0.3, Material(), centre=(-1.0, 0.0))),
        (DirectionalLight((1.0, 0.0, -1.0), intensity=1.0),),
        _top_camera(),
        ambient=(0, 0, 0),
    )
    got = render_frame(scene, 40, 40, options=RenderOptions(samples_per_axis=1, shadows="HARD"))
    assert got.choices["shadows"] == ["shadow_volume"]
    assert any("Embree" in reason for reason in got.choices["reasons"])
    rows, cols = np.indices((40, 40))
    x, y = -2 + (cols + 0.5) * 0.1, 2 - (rows + 0.5) * 0.1
    umbra = (np.abs(x) < 0.2) & (np.abs(y) < 0.2)  # the shadow of the square (slanted sun: shifted +1 in x)
    lit = ((np.abs(x) > 0.45) | (np.abs(y) > 0.45)) & ((np.abs(x + 1.0) > 0.35) | (np.abs(y) > 0.35))
    np.testing.assert_allclose(got.rgba[..., 0][umbra], 0.0, atol=1e-6)
    np.testing.assert_allclose(got.rgba[..., 0][lit], 1 / math.sqrt(2), atol=1e-6)


def test_auto_shading_is_exact_on_flat_faces_under_a_sun() -> None:
    # Planar faces, a directional light and an orthographic camera: flat shading is exact, so the
    # planner's per-mesh choice must give the per-pixel (Phong) image.
    material = Material(diffuse=(0.6, 0.5, 0.4), specular=(0.3, 0.3, 0.3), shininess=20.0)
    scene = Scene(
        (square(0.0, 1.5, material),),
        (DirectionalLight((0.3, -0.2, -1.0), intensity=1.2),),
        _top_camera(),
        ambient=(0.1, 0.1, 0.1),
        light_model=LightModel(local_viewer=False),
    )
    auto = render_frame(scene, 24, 24, RenderOptions(shading="AUTO"))
    phong = render_frame(scene, 24, 24, RenderOptions(shading="PHONG"))
    assert any("flat" in reason for reason in auto.choices["reasons"])
    np.testing.assert_allclose(auto.rgba, phong.rgba, atol=1e-6)


@pytest.mark.parametrize("shadows", ["AUTO", "HARD", "SOFT"])
def test_a_light_whose_cast_shadow_is_off_lights_the_shadow_region(shadows: str) -> None:
    # Blender's Light > Cast Shadow off: the slanted sun lights the floor behind the occluder as
    # everywhere else, kd·I·(n·l) = 1/√2; a second, overhead sun that does cast keeps the occluder's
    # own footprint dark for that light only.
    floor = Material(ambient=(0, 0, 0), diffuse=(1.0, 1.0, 1.0))
    scene = Scene(
        (square(0.0, 2.0, floor), square(1.0, 0.3, Material(), centre=(-1.0, 0.0))),
        (
            DirectionalLight((1.0, 0.0, -1.0), intensity=1.0),
            DirectionalLight((0.0, 0.0, -1.0), intensity=0.5),
        ),
        _top_camera(),
        ambient=(0, 0, 0),
    )
    options = RenderOptions(samples_per_axis=1, shadows=shadows)
    got = render_frame(scene, 40, 40, options, light_radii=(0.0, 0.0), casts_shadows=(False, True))
    rows, cols = np.indices((40, 40))
    x, y = -2 + (cols + 0.5) * 0.1, 2 - (rows + 0.5) * 0.1
    behind = (np.abs(x - 0.0) < 0.25) & (np.abs(y) < 0.25)  # the slanted sun's shadow if it cast one
    np.testing.assert_allclose(got.rgba[..., 0][behind], 1 / math.sqrt(2) + 0.5, atol=1e-6)
    assert got.choices["shadows"][0] == "none"
    assert got.choices["shadows"][1] != "none"


def test_cast_shadow_flags_must_match_the_lights() -> None:
    scene = Scene((square(0.0, 2.0, Material()),), (DirectionalLight((0, 0, -1.0)),), _top_camera())
    with pytest.raises(ValueError, match="casts_shadows"):
        render_frame(scene, 4, 4, RenderOptions(), casts_shadows=(True, False))


def test_status_line_names_kernels_embree_and_the_plan() -> None:
    from addon.pipeline import status_line

    scene = Scene(
        (square(0.0, 2.0, Material()), square(1.0, 0.3, Material(), centre=(-1.0, 0.0))),
        (DirectionalLight((1.0, 0.0, -1.0)),),
        _top_camera(),
    )
    got = render_frame(scene, 16, 16, RenderOptions(samples_per_axis=1, shadows="HARD", engine="NUMPY"))
    line = status_line(got.choices, 1.5, {"compile": 2.25})
    assert got.choices["engine"] == "numpy"
    assert line.startswith("Blinn-Phong 1.50 s (kernels compiled 2.25 s) | numpy, ")
    assert f"shadows {got.choices['shadows'][0]}" in line and "transparency zbuffer" in line
