"""Shadow mapping against Mesa llvmpipe: the same two passes done by a real OpenGL implementation.

:mod:`oracles.gl_shadows` renders depth maps from the same light cameras with OpenGL's
rasterizer and ``glPolygonOffset(slope_bias, 0)``, then looks them up in a GLSL shader
with the same constant bias, PCF kernel and map resolution. Compared:

* the depth maps: identical coverage on all but 0.05 % of texels (a texel centre within
  rounding of an edge may go either way: GL transforms in float32, we in float64) and
  depths within 4e-6 where both cover (float32 vertex transform and depth interpolation
  at window depths ≤ 1: a few float32 ulps; observed ≤ 1.1e-6);
* the frames, after OpenGL's float → UNORM8 rounding: within 1/255 per channel on every
  pixel both cover that is *away from shadow edges* — the edge rule: a pixel is left out
  when our per-pixel light visibility (the ``shadow`` pass) is not the same over its 3×3
  neighbourhood, since there a receiver a float32 rounding away from a texel boundary or a
  stored depth may be classified either way. On all covered pixels, at most 0.5 % may
  differ by more than 1/255 (observed: none).
"""

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.shadows.maps import light_shadow_maps
from blinn_phong.shadows.raytrace import world_triangles
from oracles.gl_common import to_unorm8
from testbeds.shadow_scenes import away_from_shadow_edges, two_spheres_over_ground

pytestmark = pytest.mark.mesa

SIZE = 128


GL_ORACLE = "gl_shadows"  # the gl fixture (tests/conftest.py)


def two_spheres(lights) -> bp.Scene:
    """Two 24×12 UV spheres over a ground plane (the benchmark's scene, small)."""
    return two_spheres_over_ground(24, 1.0, lights, rings=12)


LIGHT_SETS = {
    "directional_and_point": [
        bp.DirectionalLight((-0.5, -1.0, -0.4), (0.8, 0.8, 0.8)),
        bp.PointLight((2.0, 4.0, 2.0), (0.6, 0.6, 0.6)),
    ],
    "spot": [bp.SpotLight((0.0, 5.0, 1.0), (0.0, -1.0, -0.2), cutoff=50.0, color=(0.9, 0.9, 0.8))],
}
SLOPE = {"nearest": 2.0, "bilinear": 3.0, "box3": 3.0, "box5": 5.0}  # 1 + 2h: shadows.maps


@pytest.mark.parametrize("lights", list(LIGHT_SETS))
def test_depth_maps_match_mesa(gl, lights):
    scene = two_spheres(LIGHT_SETS[lights])
    theirs = gl.render_shadow_mapped(scene, 16, 16, resolution=256, slope_bias=2.0, read_maps=True).maps
    tris, _ = world_triangles(scene)
    ours = [m for light in scene.lights for m in light_shadow_maps(light, tris, 256, slope_bias=2.0)]
    assert len(ours) == len(theirs)
    covered = 0
    for a, b in zip(ours, theirs, strict=True):
        assert np.mean((a.depth < 1) != (b < 1)) <= 5e-4
        both = (a.depth < 1) & (b < 1)
        covered += int(both.sum())
        if both.any():
            assert np.abs(a.depth - b)[both].max() <= 4e-6
    assert covered > 20000


@pytest.mark.parametrize("lights", list(LIGHT_SETS))
@pytest.mark.parametrize("kernel", list(SLOPE))
def test_shadow_mapped_frame_matches_mesa(gl, lights, kernel):
    scene = two_spheres(LIGHT_SETS[lights])
    options = bp.ShadowOptions(
        "shadow_map", resolution=128, constant_bias=1e-4, slope_bias=SLOPE[kernel], kernel=kernel
    )
    result = bp.render(scene, SIZE, SIZE, shading="phong", shadows=options, transparency="zbuffer")
    theirs = gl.render_shadow_mapped(
        scene, SIZE, SIZE, resolution=128, constant_bias=1e-4, slope_bias=SLOPE[kernel], kernel=kernel
    ).rgba.astype(np.int64)
    ours = to_unorm8(result.rgba)
    covered = (ours[..., 3] > 0) & (theirs[..., 3] > 0)
    assert np.mean((ours[..., 3] > 0) != (theirs[..., 3] > 0)) <= 2e-3  # silhouettes: fill-rule ties only
    diff = np.abs(ours[..., :3] - theirs[..., :3]).max(axis=-1)
    shadow = result.passes["shadow"][..., 0]
    interior = covered & away_from_shadow_edges(shadow)
    in_shadow = interior & (shadow < 0.999)
    assert in_shadow.sum() > 150  # shadows are there and compared, not only lit pixels
    assert interior.sum() > 0.5 * covered.sum()
    assert diff[interior].max() <= 1
    assert np.mean(diff[covered] > 1) <= 5e-3
