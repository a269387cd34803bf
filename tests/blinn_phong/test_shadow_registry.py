"""The registry of shadow methods (:mod:`blinn_phong.shadows.methods`): each method's stated facts
hold, checked against a closed form, and the dispatch and the frame plan read them.

The scene: a unit square occluder at height 1 over the ground z = 0, lit from straight above by
a directional light. A ground point (x, y, 0) is in shadow exactly when |x| < 1/2 and |y| < 1/2
(the occluder's orthographic projection); points within 0.05 of that edge are left out, where a
shadow map's texels may classify either way.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from blinn_phong.model.lights import DirectionalLight, PointLight
from blinn_phong.planning.frame_plan import ShadowOptions, _shadow_choice
from blinn_phong.planning.planner import Choice
from blinn_phong.shadows import method as method_module
from blinn_phong.shadows.method import embree_available
from blinn_phong.shadows.methods import METHODS, SHADOW_METHODS, light_visibility, shadow_method

LIGHT = DirectionalLight((0.0, 0.0, -1.0))
OCCLUDER = np.array(
    [
        [[-0.5, -0.5, 1.0], [0.5, -0.5, 1.0], [0.5, 0.5, 1.0]],
        [[-0.5, -0.5, 1.0], [0.5, 0.5, 1.0], [-0.5, 0.5, 1.0]],
    ]
)
GROUND = np.array(
    [
        [[-3.0, -3.0, 0.0], [3.0, -3.0, 0.0], [3.0, 3.0, 0.0]],
        [[-3.0, -3.0, 0.0], [3.0, 3.0, 0.0], [-3.0, 3.0, 0.0]],
    ]
)
TRIS = np.concatenate([OCCLUDER, GROUND])


def _ground_points() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    g = np.linspace(-1.2, 1.2, 49)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    keep = (np.abs(np.abs(x) - 0.5) > 0.05) & (np.abs(np.abs(y) - 0.5) > 0.05)
    points = np.c_[x[keep], y[keep], np.zeros(keep.sum())]
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    shadowed = (np.abs(points[:, 0]) < 0.5) & (np.abs(points[:, 1]) < 0.5)
    return points, normals, shadowed


PARAMS = {
    "planar": {"plane": (0.0, 0.0, 1.0, 0.0), "caster_triangles": OCCLUDER},
    "shadow_map": {"resolution": 512},
    "soft": {"radius": 0.0, "samples_per_axis": 1, "offset": 1e-4},
}


def _needs(m: object) -> None:
    if m.uses_rays and not embree_available():  # type: ignore[attr-defined]
        pytest.skip(f"{m.name} casts rays with embreex")  # type: ignore[attr-defined]


def test_the_registry_lists_every_method_once_and_render_takes_them_all() -> None:
    assert SHADOW_METHODS == tuple(METHODS)
    assert len(set(SHADOW_METHODS)) == len(SHADOW_METHODS)
    assert {"none", "planar", "shadow_map", "ray_traced", "shadow_volume", "soft"} == set(SHADOW_METHODS)
    for name, m in METHODS.items():
        assert m.name == name and m.title and m.summary
        if m.uses_rays:
            stand_in = shadow_method(str(m.without_embree))
            assert not stand_in.uses_rays  # a stand-in must work without Embree
    with pytest.raises(ValueError, match="method must be one of"):
        shadow_method("stencil")


@pytest.mark.parametrize("name", [n for n in SHADOW_METHODS if n not in ("none", "soft")])
def test_each_method_shadows_the_closed_form_region(name: str) -> None:
    m = shadow_method(name)
    _needs(m)
    points, normals, shadowed = _ground_points()
    tris = OCCLUDER if name == "shadow_volume" else TRIS
    vis = light_visibility(name, LIGHT, tris, points, normals, **PARAMS.get(name, {}))
    assert vis.shape == (len(points),)
    np.testing.assert_array_equal(vis, np.where(shadowed, 0.0, 1.0))


def test_no_shadows_lights_everything() -> None:
    points, normals, _ = _ground_points()
    np.testing.assert_array_equal(light_visibility("none", LIGHT, TRIS, points, normals), 1.0)


@pytest.mark.parametrize("name", [n for n, m in METHODS.items() if m.coloured])
def test_coloured_methods_pass_the_casters_transmittance(name: str) -> None:
    # Light crossing a caster of transmittance t keeps t per channel: t in the shadow, 1 outside.
    _needs(shadow_method(name))
    points, normals, shadowed = _ground_points()
    t = np.zeros((len(TRIS), 3))
    t[: len(OCCLUDER)] = (0.25, 0.5, 0.75)
    rgb = light_visibility(name, LIGHT, TRIS, points, normals, transmittance=t)
    want = np.where(shadowed[:, None], np.array([0.25, 0.5, 0.75]), 1.0)
    np.testing.assert_allclose(rgb, want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", [n for n, m in METHODS.items() if not m.coloured and n != "none"])
def test_binary_methods_refuse_a_transmittance(name: str) -> None:
    points, normals, _ = _ground_points()
    with pytest.raises(ValueError, match="coloured shadows are cast by"):
        light_visibility(name, LIGHT, TRIS, points, normals, transmittance=np.zeros((len(TRIS), 3)))


@pytest.mark.parametrize("name", [n for n, m in METHODS.items() if not m.uses_rays and n != "none"])
def test_methods_that_cast_no_rays_work_without_embree(name: str, monkeypatch) -> None:
    # The fact the planner relies on where Blender's Python lacks embreex.
    monkeypatch.setitem(sys.modules, "embreex", None)
    for module in [k for k in sys.modules if k.startswith("blinn_phong.shadows.raytrace")]:
        monkeypatch.delitem(sys.modules, module)
    points, normals, shadowed = _ground_points()
    tris = OCCLUDER if name == "shadow_volume" else TRIS
    vis = light_visibility(name, LIGHT, tris, points, normals, **PARAMS.get(name, {}))
    np.testing.assert_array_equal(vis, np.where(shadowed, 0.0, 1.0))


def test_unknown_parameters_name_the_method_and_what_it_takes() -> None:
    points, normals, _ = _ground_points()
    with pytest.raises(TypeError, match="not parameters of shadow_map"):
        light_visibility("shadow_map", LIGHT, TRIS, points, normals, stencil="zpass")


@pytest.mark.parametrize("name", [n for n, m in METHODS.items() if m.uses_rays])
def test_without_embree_the_frame_plan_casts_the_stand_in(name: str, monkeypatch) -> None:
    monkeypatch.setattr("blinn_phong.planning.frame_plan.embree_available", lambda: False)
    planned = Choice("ray_traced", "planned")
    options = ShadowOptions(method=name, plane=(0.0, 0.0, 1.0, 0.0), radius=0.5)
    choice = _shadow_choice(PointLight((0.0, 0.0, 3.0)), options, planned)
    stand_in = shadow_method(str(shadow_method(name).without_embree))
    assert choice.method == stand_in.name
    assert not shadow_method(choice.method).uses_rays
    assert f"instead of {name}" in choice.reason
    assert set(choice.params) <= set(stand_in.parameters)


def test_a_light_without_area_casts_hard_shadows_for_soft() -> None:
    planned = Choice("ray_traced", "planned")
    cases = (
        (LIGHT, ShadowOptions("soft", radius=0.5)),  # a directional light
        (PointLight((0, 0, 3)), ShadowOptions("soft", radius=0.0)),
    )
    for light, options in cases:
        choice = _shadow_choice(light, options, planned)
        assert choice.method == "ray_traced" and "has no area" in choice.reason


def test_embree_available_is_one_function() -> None:
    assert method_module.embree_available() == embree_available()
