"""Where compositing methods fail: unpremultiply as α → 0, float16 accumulation, straight-alpha filtering.

Each test drives a method into its known failure, asserts its error is above a bound derived
in the comments (closed form), asserts the robust method's error is below a bound, and that no
output holds NaN or Inf. Errors are in 8-bit steps (1/255 of the unit range).
"""

from __future__ import annotations

import numpy as np

from compositing import composite, premultiply, unpremultiply
from testbeds.error_metrics import error_metrics, has_nonfinite


def _unorm8(x: np.ndarray) -> np.ndarray:
    """An 8-bit buffer: values rounded to the nearest multiple of 1/255."""
    return np.rint(np.clip(x, 0.0, 1.0) * 255.0) / 255.0


def test_unpremultiply_amplifies_8bit_rounding_as_alpha_goes_to_zero() -> None:
    # Straight colours c in [0, 1] at alpha = k/255, premultiplied and stored in 8 bits.
    c = np.linspace(0.0, 1.0, 1001)
    worst_by_alpha = {}
    for k in (1, 4, 32, 255):
        alpha = k / 255.0
        straight = np.stack([c, c, c, np.full_like(c, alpha)], axis=-1)
        stored = _unorm8(premultiply(straight))  # an 8-bit premultiplied file
        recovered = unpremultiply(stored)
        assert not has_nonfinite(recovered)
        worst_by_alpha[k] = error_metrics(recovered[:, :3], straight[:, :3])["max_steps"]
        # Robust: keep premultiplied; the stored value is within half a step of the exact one.
        assert error_metrics(stored, premultiply(straight))["max_steps"] <= 0.5 + 1e-9
    # Closed form: the stored colour is round(255·c·a)/255, so unpremultiplying divides the
    # rounding error (up to 1/2 step) by a: up to 0.5/a steps, i.e. 0.5·255/k steps, capped by
    # the colour range. For k = 1 that is 127.5 steps (c near 0.5 comes back as 0 or 1).
    assert worst_by_alpha[1] > 120.0
    assert worst_by_alpha[4] > 0.5 * 255 / 4 - 2.0  # 31.9 steps, minus the sweep's granularity
    assert worst_by_alpha[255] <= 0.5 + 1e-9  # opaque: no amplification
    assert worst_by_alpha[1] > worst_by_alpha[4] > worst_by_alpha[32] > worst_by_alpha[255]


def test_unpremultiply_at_alpha_zero_and_denormal_alpha_stays_finite() -> None:
    x = np.array([[0.0, 0.0, 0.0, 0.0], [0.3, 0.2, 0.1, 0.0], [1e-310, 1e-310, 0.0, 1e-308]])
    for policy in ("keep", "zero"):
        out = unpremultiply(x, policy)
        assert not has_nonfinite(out)
    assert np.allclose(unpremultiply(x, "zero")[:2, :3], 0.0)


def test_float16_framebuffer_loses_small_increments_over_many_layers() -> None:
    # 5000 additive (plus) layers of emitted light 2e-4 (alpha 0) on opaque black: exact sum 1.0.
    n, increment = 5000, 2e-4
    layer = np.zeros((4, 4, 4), np.float32)
    layer[..., :3] = increment
    background = np.zeros((4, 4, 4), np.float32)
    background[..., 3] = 1.0
    acc16 = background.astype(np.float16)
    acc32 = background.copy()
    for _ in range(n):
        # float16 storage (an RGBA16F target): blend in float32, store in float16.
        acc16 = composite(layer, acc16.astype(np.float32), "plus").astype(np.float16)
        acc32 = composite(layer, acc32, "plus")
    exact = background.astype(np.float64)
    exact[..., :3] = n * increment
    assert not has_nonfinite(acc16, acc32)
    # Closed form: float16 spacing in [0.5, 1) is 2⁻¹¹ ≈ 4.9e-4; an increment of 2e-4 is less
    # than half of it, so round-to-nearest drops it once the sum reaches 0.5 (below 0.5 the
    # spacing is 2⁻¹² ≈ 2.4e-4 and each add rounds up to one ulp). The sum stalls at 0.5:
    # error 0.5 = 127.5 steps.
    err16 = error_metrics(acc16.astype(np.float64), exact)["max_steps"]
    assert err16 > 120.0
    # float32: each add rounds by at most half an ulp of 1 (2⁻²⁴), n of them: 5000·6e-8 = 3e-4,
    # plus 2e-4 itself not being representable (relative 6e-8 per add, same order): < 0.2 steps.
    err32 = error_metrics(acc32.astype(np.float64), exact)["max_steps"]
    assert err32 < 0.2


def _half_covered_layer() -> tuple[np.ndarray, np.ndarray]:
    """A red square on a transparent layer (straight black, alpha 0), 16×16, and its 2×2-box coverage."""
    straight = np.zeros((16, 16, 4))
    straight[4:11, 4:11] = (1.0, 0.0, 0.0, 1.0)  # 7 px wide: odd, so 2×2 blocks on its edges are half covered
    coverage = straight[..., 3].reshape(8, 2, 8, 2).mean(axis=(1, 3))
    return straight, coverage


def _box_filter_2x2(image: np.ndarray) -> np.ndarray:
    h, w, c = image.shape
    return image.reshape(h // 2, 2, w // 2, 2, c).mean(axis=(1, 3))


def test_filtering_straight_alpha_darkens_edges() -> None:
    straight, coverage = _half_covered_layer()
    white = np.ones((8, 8, 4))
    # Exact: each output pixel shows red over the covered fraction and white elsewhere.
    exact = np.empty((8, 8, 4))
    exact[..., 0] = 1.0
    exact[..., 1] = exact[..., 2] = 1.0 - coverage
    exact[..., 3] = 1.0
    # Robust: premultiply, then filter (the average of premultiplied colours is the coverage-weighted colour).
    robust = composite(_box_filter_2x2(premultiply(straight)), white, "src_over")
    # Failing: filter the straight colours, then premultiply: the black of the empty pixels is averaged in.
    failing = composite(premultiply(_box_filter_2x2(straight)), white, "src_over")
    assert not has_nonfinite(robust, failing)
    assert error_metrics(robust, exact)["max_steps"] < 1e-6
    # Closed form: a pixel covered a fraction a gets straight colour a·red, premultiplied a²·red,
    # over white: a²·red + (1 − a)·white, against a·red + (1 − a)·white: red off by a(1 − a),
    # 0.25 at a = 1/2 (edge pixels) = 63.75 steps; a = 1/4 (corners) gives 3/16 = 47.8 steps.
    err = error_metrics(failing, exact)
    assert err["max_steps"] > 63.0
    half = np.isclose(coverage, 0.5)
    assert np.allclose(np.abs(failing - exact)[half][:, 0], 0.25)
