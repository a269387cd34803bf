"""A per-pixel mix factor given as a one-channel image, and factor shapes that only broadcast
*past* the pixel shape (the closed form is Blender's Alpha Over mix: dst·(1 − f) + over·f)."""

import numpy as np
import pytest
from compositing_testdata import image_pair

from compositing import composite


@pytest.mark.parametrize("shape", [(5, 5), (4, 7)])  # square images used to fail inside numpy
@pytest.mark.parametrize("engine", ["numpy", "auto"])
def test_factor_of_shape_h_w_1_is_one_value_per_pixel(shape, engine):
    src, dst = image_pair(shape, 3, np.float64)
    f = np.random.default_rng(1).random((*shape, 1))
    over = src + dst * (1 - src[..., 3:])
    want = dst * (1 - f) + over * f
    np.testing.assert_allclose(composite(src, dst, factor=f, engine=engine), want, rtol=1e-12, atol=1e-12)


def test_factor_that_broadcasts_beyond_the_pixel_shape_is_refused():
    src, dst = image_pair((5, 5), 4)
    with pytest.raises(
        ValueError, match=r"factor: expected a shape that broadcasts to the pixel shape \(5, 5\)"
    ):
        composite(src, dst, factor=np.ones((5, 5, 5), np.float32))
    with pytest.raises(ValueError, match=r"or \(5, 5, 1\); got \(2, 5, 5\)"):
        composite(src, dst, factor=np.ones((2, 5, 5), np.float32))
