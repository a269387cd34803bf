"""Shadow volumes against a real stencil buffer: Mesa llvmpipe through EGL surfaceless.

:mod:`oracles.gl_stencil` draws the scene's depth and per-triangle shadow volumes with
``glStencilOpSeparate`` (``INCR_WRAP``/``DECR_WRAP``) into a ``GL_DEPTH24_STENCIL8``
framebuffer, z-fail with ``GL_DEPTH_CLAMP``; we count our silhouette volumes at the visible
samples of our own rasterizer (the same pixel centres).

Edge tolerance: the two masks must be identical on every covered pixel that does not touch a
lit/shadowed boundary of Mesa's mask (8-neighbourhood). On a boundary pixel the sample lies
within a pixel of a volume face, where the two legitimately differ: llvmpipe snaps vertex
window positions to 1/256 pixel (8 sub-pixel bits) and stores depth in 24 bits, we evaluate
unsnapped float64 positions of the sample moved 1e-4 along its normal, and the two volume
constructions (Mesa: every triangle extruded; ours: silhouettes) put their faces through the
same lines by different floating-point paths. Pixels whose nearest surface differs (depth
apart by more than 1e-5) would be excluded too; on these scenes there are none.
"""

import numpy as np
import pytest

from blinn_phong.shadows.volume import shadow_volume_visibility
from tests.effects.volume_scenes import (
    HEIGHT,
    LIGHTS,
    WIDTH,
    boundary_band,
    casters,
    image_of,
    inside_camera,
    outside_camera,
    samples,
    scene_with,
    world_triangles,
)

pytestmark = pytest.mark.mesa


@pytest.fixture(scope="module")
def stencil(mesa_context):
    from oracles.gl_stencil import render_stencil_shadows

    return render_stencil_shadows


def _masks(render_stencil_shadows, scene, light, method):
    gl = render_stencil_shadows(scene, light, WIDTH, HEIGHT, method=method)
    pts, nrm, pix, depth = samples(scene)
    ours = shadow_volume_visibility(
        light, world_triangles(scene), pts, nrm, camera=scene.camera, stencil=method
    )
    theirs = (gl.stencil.ravel()[pix] == 0).astype(np.int64)
    same_surface = np.abs(gl.depth.ravel()[pix] - depth) <= 1e-5
    band = boundary_band(image_of(theirs, pix), radius=0).ravel()[pix]
    return ours.astype(np.int64), theirs, same_surface, band


CASES = [
    (caster, light, "outside", method)
    for caster in ("sphere", "torus", "box", "pair")
    for light in sorted(LIGHTS)
    for method in ("zfail", "zpass")
] + [(caster, light, "inside", "zfail") for caster in ("sphere", "pair") for light in sorted(LIGHTS)]


@pytest.mark.parametrize(("caster", "light_name", "camera", "method"), CASES)
def test_shadow_mask_matches_mesa_stencil(stencil, caster, light_name, camera, method):
    light = LIGHTS[light_name]
    cam = (
        outside_camera()
        if camera == "outside"
        else inside_camera(light, casters(caster)[0].transform[:3, 3], 0.7)
    )
    scene = scene_with(casters(caster), light, cam)
    ours, theirs, same_surface, band = _masks(stencil, scene, light, method)
    compared = same_surface & ~band
    assert np.count_nonzero(same_surface) >= 0.99 * len(same_surface)  # same visible surfaces
    assert (
        np.count_nonzero(compared & (theirs == 0)) > 100 and np.count_nonzero(compared & (theirs == 1)) > 100
    )
    wrong = np.count_nonzero((ours != theirs) & compared)
    assert wrong == 0, (
        f"{wrong} of {np.count_nonzero(compared)} pixels away from shadow edges differ from Mesa"
    )
    # the boundary pixels that differ are a fringe: at most 1 % of the band
    assert np.count_nonzero(ours != theirs) <= max(2, 0.01 * np.count_nonzero(band))


def test_mesa_zpass_from_inside_a_volume_is_wrong_like_ours(stencil):
    """The failure mode is the stencil algorithm's, not ours: Mesa's z-pass inverts the same samples."""
    light = LIGHTS["point"]
    cam = inside_camera(light, casters("sphere")[0].transform[:3, 3], 0.7)
    scene = scene_with(casters("sphere"), light, cam)
    ours, theirs, same_surface, band = _masks(stencil, scene, light, "zpass")
    compared = same_surface & ~band
    assert np.count_nonzero((ours != theirs) & compared) == 0
    right, _, _, _ = _masks(stencil, scene, light, "zfail")
    assert np.count_nonzero((theirs != right) & compared) > 0.9 * np.count_nonzero(compared)
