"""Light and shadow linking (``Scene.light_links``) against closed forms, for every shadow method.

Seen from above by an orthographic camera: a floor at z = −3 and two occluders (O1, O2: quads at
z = −1, facing +z). A point light ``L`` at (6, 4, 3) lights them; a directional light ``M``
shines straight down (its shadows fall under the occluders, hidden from the camera). With zero
specular and ambient each surface's colour is ``Σ_i vis_i · d_cm · d_cl_i · max(n·l_i, 0)``
(OpenGL 2.1 §2.14.1, attenuation 1); ``vis_L`` at a floor point is 0 exactly when the segment to
``L`` crosses an occluder linked as a blocker (computed here by intersecting it with the plane
z = −1), and ``L``'s terms are 0 on meshes outside its receivers. Pixels whose classification
changes within ±0.35 px of their centre (edges of the occluders or of their shadows) are left out,
so the shadow maps' texels and the soft light's penumbra do not matter.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.planning.frame_plan import ShadowOptions
from tests.meshes import rectangle

W, H = 12, 8
LIGHT = np.array([6.0, 4.0, 3.0])
DIFFUSE = np.array([0.7, 0.6, 0.5])
L = bp.PointLight(tuple(LIGHT), color=(1.0, 0.9, 0.8))
M = bp.DirectionalLight((0.0, 0.0, -1.0), color=(0.1, 0.2, 0.3))
OCCLUDERS = {1: (2.0, 4.0, 2.0, 6.0), 2: (8.0, 10.0, 2.0, 6.0)}  # mesh index: x0, x1, y0, y1 at z = −1
FLOOR_Z, OCC_Z = -3.0, -1.0

METHODS = {
    "shadow_map": ShadowOptions("shadow_map", resolution=2048),
    "ray_traced": ShadowOptions("ray_traced"),
    "soft": ShadowOptions("soft", radius=0.02, samples=16),
    "shadow_volume": ShadowOptions("shadow_volume"),
    "planar": ShadowOptions("planar", plane=(0.0, 0.0, 1.0, -FLOOR_Z)),
}


def _quad(x0: float, x1: float, y0: float, y1: float, z: float) -> bp.Mesh:
    material = bp.Material(ambient=(0, 0, 0), diffuse=tuple(DIFFUSE), specular=(0, 0, 0))
    return rectangle(x0, x1, y0, y1, z, material)


def _scene(link: bp.LightLink | None) -> bp.Scene:
    meshes = [_quad(-1, W + 1, -1, H + 1, FLOOR_Z)] + [_quad(*r, OCC_Z) for r in OCCLUDERS.values()]
    camera = bp.Camera.orthographic(0, W, 0, H, 0.1, 10.0)
    links = None if link is None else (link, None)
    return bp.Scene(meshes, [L, M], camera, ambient=(0, 0, 0), light_links=links)


def _surface(x: float, y: float) -> tuple[int, float]:
    """The mesh seen at window point (x, y) and its height."""
    for index, (x0, x1, y0, y1) in OCCLUDERS.items():
        if x0 < x < x1 and y0 < y < y1:
            return index, OCC_Z
    return 0, FLOOR_Z


def _blocked_by(x: float, y: float) -> set[int]:
    """The occluders the segment from floor point (x, y) to the light crosses."""
    q = np.array([x, y, FLOOR_Z])
    t = (OCC_Z - FLOOR_Z) / (LIGHT[2] - FLOOR_Z)
    p = q + t * (LIGHT - q)
    return {i for i, (x0, x1, y0, y1) in OCCLUDERS.items() if x0 < p[0] < x1 and y0 < p[1] < y1}


def _expected(receivers: set[int], blockers: set[int]) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) expected colour and (H, W) mask of the pixels away from every edge."""
    colour = np.zeros((H, W, 3))
    clear = np.zeros((H, W), bool)
    for row in range(H):
        for col in range(W):
            x, y = col + 0.5, H - row - 0.5
            probes = [(x + dx, y + dy) for dx in (-0.35, 0.0, 0.35) for dy in (-0.35, 0.0, 0.35)]
            kinds = {(_surface(*p)[0], frozenset(_blocked_by(*p) & blockers)) for p in probes}
            clear[row, col] = len(kinds) == 1
            mesh, z = _surface(x, y)
            to_light = LIGHT - np.array([x, y, z])
            n_dot_l = max(0.0, float(to_light[2] / np.linalg.norm(to_light)))
            lit = mesh in receivers and not (mesh == 0 and _blocked_by(x, y) & blockers)
            colour[row, col] = DIFFUSE * (np.asarray(L.diffuse) * n_dot_l * lit + np.asarray(M.diffuse))
    return colour, clear


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("method", list(METHODS))
def test_blockers_only_cast_the_linked_lights_shadows(method: str, engine: str) -> None:
    blockers = np.array([False, True, False])  # only O1 shadows L
    scene = _scene(bp.LightLink(blockers=blockers))
    result = bp.render(scene, W, H, engine=engine, shadows=[METHODS[method], ShadowOptions("none")])
    colour, clear = _expected({0, 1, 2}, {1})
    unlinked, _ = _expected({0, 1, 2}, {1, 2})
    assert (np.abs(colour - unlinked).max(axis=-1) > 0.1)[clear].any()  # O2's shadow is gone
    assert clear.sum() > W * H // 2
    np.testing.assert_allclose(result.rgba[..., :3][clear], colour[clear], rtol=0, atol=1e-5)


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize("method", ["none", *METHODS])
def test_receivers_only_are_lit(method: str, engine: str) -> None:
    receivers = np.array([True, False, True])  # L lights the floor and O2, not O1
    scene = _scene(bp.LightLink(receivers=receivers))
    options = ShadowOptions("none") if method == "none" else METHODS[method]
    result = bp.render(scene, W, H, engine=engine, shadows=[options, ShadowOptions("none")])
    colour, clear = _expected({0, 2}, set() if method == "none" else {1, 2})
    np.testing.assert_allclose(result.rgba[..., :3][clear], colour[clear], rtol=0, atol=1e-5)


def test_unlinked_entries_cost_nothing() -> None:
    """Links that link nothing are stored as no links at all: the frame takes its unlinked path."""
    scene = _scene(bp.LightLink())
    assert scene.light_links is None
    base = bp.render(_scene(None), W, H)
    again = bp.render(scene, W, H)
    assert np.array_equal(base.rgba, again.rgba)


def test_planner_counts_only_linked_pairs() -> None:
    no_link = bp.render(_scene(None), W, H, engine="numpy").plan
    assert no_link.shadows[0].method != "none"  # both occluders can shadow the floor
    nothing_blocks = _scene(bp.LightLink(blockers=np.zeros(3, bool)))
    choice = bp.render(nothing_blocks, W, H, engine="numpy").plan.shadows[0]
    assert choice.method == "none" and "light linking" in choice.reason
    only_occluders = _scene(bp.LightLink(receivers=np.array([False, True, True])))
    assert bp.render(only_occluders, W, H, engine="numpy").plan.shadows[0].method == "none"
    one_blocker = _scene(bp.LightLink(blockers=np.array([False, False, True])))
    assert bp.render(one_blocker, W, H, engine="numpy").plan.shadows[0].method != "none"


def test_links_follow_the_light_groups_and_dropped_meshes() -> None:
    """A light group's pass keeps its light's links; an empty mesh dropped before rendering
    renumbers the masks."""
    link = bp.LightLink(receivers=np.array([True, False, True]), blockers=np.array([False, True, False]))
    scene = _scene(link)
    groups = bp.LightGroups(("l", "m"), lights=("l", "m"), meshes=(None, None, None))
    result = bp.render(scene, W, H, light_groups=groups, shadows=[METHODS["ray_traced"], "none"])
    colour, clear = _expected({0, 2}, {1})
    np.testing.assert_allclose(result.rgba[..., :3][clear], colour[clear], rtol=0, atol=1e-5)
    m_only = DIFFUSE * np.asarray(M.diffuse)
    np.testing.assert_allclose(
        result.passes["Combined_l"][clear], (colour - m_only)[clear], rtol=0, atol=1e-5
    )
    empty = bp.Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    padded_link = bp.LightLink(np.array([True, True, False, True]), np.array([False, False, True, False]))
    padded = bp.Scene(
        [scene.meshes[0], empty, *scene.meshes[1:]], scene.lights, scene.camera, ambient=(0, 0, 0),
        light_links=(padded_link, None),
    )  # fmt: skip
    again = bp.render(padded, W, H, shadows=[METHODS["ray_traced"], "none"])
    np.testing.assert_allclose(again.rgba[..., :3][clear], colour[clear], rtol=0, atol=1e-5)


def test_links_are_checked() -> None:
    with pytest.raises(ValueError, match=r"one entry per light \(2\)"):
        _scene(None).__class__([_quad(0, 1, 0, 1, -1)], [L, M], _scene(None).camera, light_links=(None,))
    with pytest.raises(
        ValueError, match=r"light_links\[0\]\.receivers: expected None or a bool array of shape \(1,\)"
    ):
        bp.Scene(
            [_quad(0, 1, 0, 1, -1)], [L], _scene(None).camera, light_links=(bp.LightLink(np.ones(2, bool)),)
        )
    with pytest.raises(ValueError, match="ambient colour must be 0"):
        bp.Scene(
            [_quad(0, 1, 0, 1, -1)],
            [bp.PointLight(ambient=(0.1, 0.1, 0.1))],
            _scene(None).camera,
            light_links=(bp.LightLink(np.ones(1, bool)),),
        )
