"""Input checks of ``addon.verify`` (no Blender needed): bad cases and images are refused up front."""

import numpy as np
import pytest

from addon.verify import Case, run_blender, sample_images


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"kind": "shader", "operator": "src_over"}, "kind: expected one of"),
        ({"kind": "alpha_over", "operator": "src_atop"}, "operator: for kind 'alpha_over'"),
        ({"kind": "node_group", "operator": "over"}, "operator: for kind 'node_group'"),
        ({"kind": "node_group", "operator": "xor", "factor": 1.5}, "factor: expected a number in"),
        (
            {"kind": "node_group", "operator": "xor", "straight_alpha": True},
            "straight_alpha: only Alpha Over",
        ),
    ],
)
def test_bad_cases_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Case(**kwargs)


def test_sample_images_hold_every_special_pixel() -> None:
    src, dst = sample_images(61, 97)
    assert src.shape == dst.shape == (61, 97, 4) and src.dtype == np.float32
    for image in (src, dst):
        alpha, rgb = image[..., 3], image[..., :3]
        assert (alpha == 0).any() and (alpha == 1).any() and ((alpha > 0) & (alpha < 1)).any()
        assert (rgb[alpha == 0] != 0).any()  # glow
        assert (rgb > 1).any() and (rgb < 0).any()  # HDR and negative colour
        assert alpha.min() >= 0 and alpha.max() <= 1
    assert (src[..., 3] == dst[..., 3]).any()  # the sa == da boundary of Conjoint Over


def test_images_are_checked_before_blender_starts() -> None:
    src, dst = sample_images(8, 8)
    bad = src.copy()
    bad[0, 0, 3] = 1.5
    with pytest.raises(ValueError, match="src"):
        run_blender(bad, dst, [Case("node_group", "xor")], python="/nonexistent/python")
    with pytest.raises(ValueError, match="src, dst: expected equal shapes"):
        run_blender(src, dst[:4], [Case("node_group", "xor")], python="/nonexistent/python")
    with pytest.raises(ValueError, match="cases: expected at least one Case"):
        run_blender(src, dst, [], python="/nonexistent/python")
