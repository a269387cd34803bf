"""``Mesh.casts_shadows``: a mesh left out of shadow casting still receives shadows and is seen.

Closed form: a sun travelling along (1, 0, −1) over a white Lambertian floor at z = 0 gives
kd·(N·L) = 1/√2 on open floor and 0 (no ambient) in the shadow of a square at height 1, which
falls shifted by +1 in x; the square itself, seen from above, is lit with 0.5·(1/√2).
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from tests.meshes import square

SIZE = 40
X = -2 + (np.arange(SIZE) + 0.5) * 0.1  # pixel centres of a 4 × 4 orthographic view


def _scene(occluder_casts: bool, floor_casts: bool = True) -> bp.Scene:
    white = bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1), specular=(0, 0, 0))
    floor = square(0.0, 2.0, white, casts_shadows=floor_casts)
    occluder = square(1.0, 0.5, bp.Material(ambient=(0, 0, 0), diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0)),
                     centre=(1.0, 0.0), casts_shadows=occluder_casts)  # fmt: skip
    camera = bp.Camera.orthographic(-2, 2, -2, 2, 0.5, 10.0, view=bp.look_at((0, 0, 5), (0, 0, 0), (0, 1, 0)))
    return bp.Scene((floor, occluder), (bp.DirectionalLight((0.0, 0.0, -1.0)),), camera, ambient=(0, 0, 0))


@pytest.mark.parametrize("shadows", ["ray_traced", "shadow_volume", "shadow_map"])
def test_the_shadow_of_a_slanted_sun_disappears_with_its_caster(shadows: str) -> None:
    # Sun travelling along (1, 0, −1): the occluder at height 1 shadows the floor shifted by +1 in x.
    def scene(casts: bool) -> bp.Scene:
        base = _scene(casts)
        return bp.Scene(base.meshes, (bp.DirectionalLight((1.0, 0.0, -1.0)),), base.camera, ambient=(0, 0, 0))

    occluder_top = np.ix_(np.abs(X) < 0.3, np.abs(X - 1.0) < 0.3)  # rows, cols
    beside = np.ix_(np.abs(X) < 0.3, X < -1.0)
    lit = 1.0 / np.sqrt(2.0)  # kd · N·L with L at 45°
    cast = bp.render(scene(True), SIZE, SIZE, shadows=shadows).rgba[..., 0]
    free = bp.render(scene(False), SIZE, SIZE, shadows=shadows).rgba[..., 0]
    np.testing.assert_allclose(cast[beside], lit, atol=1e-6)
    np.testing.assert_allclose(free[beside], lit, atol=1e-6)
    # Over x in [0.5, 1.5] the camera sees the occluder's top, kd 0.5 · N·L, cast or not.
    np.testing.assert_allclose(cast[occluder_top], 0.5 * lit, atol=1e-6)
    np.testing.assert_allclose(free[occluder_top], 0.5 * lit, atol=1e-6)
    # The shadow on the floor lies at x in [1.5, 2.5]: dark with the caster, lit without it.
    floor_shadow = np.ix_(np.abs(X) < 0.3, (X > 1.6) & (X < 1.95))
    assert cast[floor_shadow].max() < 1e-6
    np.testing.assert_allclose(free[floor_shadow], lit, atol=1e-6)


def test_casts_shadows_must_be_a_bool() -> None:
    with pytest.raises(TypeError, match=r"Mesh\.casts_shadows"):
        square(0.0, 1.0, bp.Material(), casts_shadows="no")  # type: ignore[arg-type]
