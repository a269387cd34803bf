"""Deep operations against OpenImageIO's DeepData and ImageBufAlgo deep functions.

Random images (``deep_testdata.random_deep(layout="oiio")``: 0–16 samples per pixel,
overlapping volume samples, zero-thickness samples, coincident samples, alpha 0 and 1)
are compared with ``DeepData.sort/split/merge_overlaps`` (OpenImageIO's tidy, the steps of
its ``merge_deep_pixels``), ``ImageBufAlgo.flatten``, ``deep_merge``, ``deepen`` and
``deep_holdout``, to 1e-6. OpenImageIO works in float32 and splits pieces again; we
work in float64 from the original samples and store float32, so samples agree to a few
float32 rounding steps.

Where OpenImageIO departs from OpenEXR's "Interpreting OpenEXR Deep Pixels" we follow the
document; each such case has a test below that computes the document's answer, ours,
and OpenImageIO's (as installed, 3.0), and shows the difference.
"""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio  # noqa: N813
import pytest
from deep_testdata import flat_pixels, from_imagebuf, oiio_tidy, one_pixel, random_deep, to_imagebuf

from compositing.deep import DeepImage, flatten, from_flat, holdout, merge, tidy

TOL = 1e-6
IBA = oiio.ImageBufAlgo


def over(front, back):
    front, back = np.asarray(front, np.float64), np.asarray(back, np.float64)
    return front + (1.0 - front[..., 3:]) * back


def assert_same_samples(ours: DeepImage, theirs: DeepImage, atol: float = TOL) -> None:
    np.testing.assert_array_equal(ours.counts, theirs.counts)
    np.testing.assert_array_equal(ours.z, theirs.z)
    np.testing.assert_array_equal(ours.zback, theirs.zback)
    np.testing.assert_allclose(ours.rgba, theirs.rgba, rtol=0, atol=atol)


@pytest.fixture(scope="module", params=range(3), ids=lambda s: f"seed{s}")
def pair(request):
    rng = np.random.default_rng(100 + request.param)
    a = random_deep(rng, (16, 16), layout="oiio")
    b = random_deep(rng, (16, 16), layout="oiio", opaque_at=15.0)
    return a, b


def test_random_images_hold_every_kind_of_sample(pair):
    a, _ = pair
    point = a.zback == a.z
    assert a.counts.min() == 0 and a.counts.max() == 16
    assert point.any() and (~point).any()
    assert (a.rgba[:, 3] == 0).any() and (a.rgba[:, 3] == 1).any() and (a.rgba[point, 3] == 1).any()
    assert (a.rgba[~point, 3] == 1).any()
    assert not a.is_tidy()


def test_tidy_matches_openimageio(pair):
    a, _ = pair
    assert_same_samples(tidy(a), oiio_tidy(a))


def test_flatten_matches_openimageio(pair):
    a, _ = pair
    theirs = flat_pixels(IBA.flatten(to_imagebuf(oiio_tidy(a))))  # OIIO flattens tidy input only
    np.testing.assert_allclose(flatten(a), theirs, rtol=0, atol=TOL)


def test_merge_and_flatten_match_openimageio(pair):
    a, b = pair
    a_buf, b_buf = to_imagebuf(oiio_tidy(a)), to_imagebuf(oiio_tidy(b))
    merged = merge(a, b)
    theirs = IBA.deep_merge(a_buf, b_buf, occlusion_cull=False)
    assert_same_samples(merged, from_imagebuf(theirs))
    np.testing.assert_allclose(flatten(merged), flat_pixels(IBA.flatten(theirs)), rtol=0, atol=TOL)
    culled = IBA.deep_merge(a_buf, b_buf)  # its default drops samples behind an opaque one
    np.testing.assert_allclose(flatten(merged), flat_pixels(IBA.flatten(culled)), rtol=0, atol=TOL)


def test_from_flat_matches_deepen():
    rng = np.random.default_rng(1)
    flat = rng.random((7, 9, 4)).astype(np.float32)
    flat[..., :3] *= flat[..., 3:]
    flat[rng.random((7, 9)) < 0.3] = 0  # empty pixels get no sample in either
    flat[0, 1] = [0.1, 0.2, 0.3, 0.0]
    spec = oiio.ImageSpec(9, 7, 4, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B", "A")
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, 9, 0, 7, 0, 1, 0, 4), flat)
    deep = IBA.deepen(buf, 2.5)
    ours = from_flat(flat, 2.5)
    counts = np.array([[deep.deep_samples(x, y, 0) for x in range(9)] for y in range(7)])
    np.testing.assert_array_equal(ours.counts, counts)
    names = list(deep.spec().channelnames)
    theirs = [
        [deep.deep_value(x, y, 0, names.index(k), 0) for k in ("R", "G", "B", "A", "Z")]
        for y in range(7)
        for x in range(9)
        if counts[y, x]
    ]
    np.testing.assert_array_equal(np.c_[ours.rgba, ours.z], np.array(theirs, np.float32))


def test_holdout_by_opaque_points_matches_deep_holdout(pair):
    a, _ = pair
    rng = np.random.default_rng(2)
    has = rng.random(a.shape) < 0.7
    pixel = np.flatnonzero(has)
    z = rng.uniform(0, 12, len(pixel))
    mask = DeepImage.from_samples(a.shape, pixel, z, np.tile([0.2, 0.3, 0.4, 1.0], (len(pixel), 1)))
    theirs = IBA.deep_holdout(to_imagebuf(oiio_tidy(a)), to_imagebuf(mask))
    ours = holdout(a, mask)
    np.testing.assert_allclose(flatten(ours), flat_pixels(IBA.flatten(theirs)), rtol=0, atol=TOL)


# --- where OpenImageIO departs from the document --------------------------------------------


def oiio_merge_flat(a: DeepImage, b: DeepImage) -> np.ndarray:
    return flat_pixels(IBA.flatten(IBA.deep_merge(to_imagebuf(a), to_imagebuf(b), occlusion_cull=False)))[
        0, 0
    ]


def test_point_inside_a_volume_is_composited_between_its_pieces():
    # Document: tidy splits the volume at the point, and sorts by Z then ZBack, so the point
    # (Z = ZBack = 2) comes before the back piece [2, 3). OpenImageIO 3.0's DeepData::sort
    # compares Z only (its ZBack index is the Z channel; fixed in 3.1), so the back piece
    # that split() inserted stays in front of the point.
    volume = one_pixel([(1.0, 3.0, 0.4, 0.0, 0.0, 0.5)])
    point = one_pixel([(2.0, 2.0, 0.0, 0.4, 0.0, 0.5)])
    a_half = 1 - 0.5**0.5
    front = back = [0.4 * a_half / 0.5, 0, 0, a_half]
    document = over(over(front, [0, 0.4, 0, 0.5]), back)
    np.testing.assert_allclose(flatten(merge(volume, point))[0, 0], document, atol=TOL)
    theirs = oiio_merge_flat(volume, point)
    if oiio.VERSION < 30100:
        np.testing.assert_allclose(theirs, over(over(front, back), [0, 0.4, 0, 0.5]), atol=TOL)
        assert np.abs(theirs - document).max() > 0.01
    else:
        np.testing.assert_allclose(theirs, document, atol=TOL)


def test_an_opaque_sample_stays_opaque_when_merged_with_two_more():
    # Document: the merged alpha is 1 - (1 - a1)(1 - a2) = 1 when a2 = 1, and an opaque
    # sample's colour wins. OpenImageIO computes a1 + a2 - a1·a2 in float32: for a1 = 0.3
    # that is 0.99999994, so the next coincident sample is blended in by the log rule.
    a = one_pixel([(0.0, 1.0, 0.1, 0.2, 0.0, 0.3), (0.0, 1.0, 0.9, 0.0, 0.0, 1.0)])
    b = one_pixel([(0.0, 1.0, 0.0, 0.0, 0.5, 0.5)])
    ours = merge(a, b)
    assert ours.counts[0, 0] == 1
    np.testing.assert_array_equal(ours.rgba[0], np.float32([0.9, 0.0, 0.0, 1.0]))
    theirs = oiio_merge_flat(a, b)
    assert np.float32(np.float32(0.3) + np.float32(1.0)) - np.float32(0.3) < 1  # the rounding
    assert np.abs(theirs[:3] - [0.9, 0, 0]).max() > 0.01


def test_coincident_opaque_samples_merge_to_their_mean_in_any_order():
    # Document: merge "does not distinguish between a foreground and a background image";
    # two opaque coincident samples give their mean. OpenImageIO folds pairwise in storage
    # order: three opaque samples get weights 1/4, 1/4, 1/2 and the result depends on the
    # order of the images.
    a = one_pixel([(0.0, 1.0, 0.8, 0, 0, 1.0), (0.0, 1.0, 0, 0.8, 0, 1.0)])
    b = one_pixel([(0.0, 1.0, 0, 0, 0.8, 1.0)])
    mean = np.float32([0.8 / 3, 0.8 / 3, 0.8 / 3, 1.0])
    np.testing.assert_allclose(flatten(merge(a, b))[0, 0], mean, atol=TOL)
    np.testing.assert_array_equal(merge(a, b).rgba, merge(b, a).rgba)
    np.testing.assert_allclose(oiio_merge_flat(a, b), [0.2, 0.2, 0.4, 1.0], atol=TOL)
    np.testing.assert_allclose(oiio_merge_flat(b, a), [0.2, 0.4, 0.2, 1.0], atol=TOL)


def test_flatten_makes_the_pixel_tidy_first():
    # Document: flattening is 1. make tidy, 2. composite front to back. OpenImageIO's
    # flatten composites the samples in storage order ("assumes sorted, non-overlapping
    # samples"), and deep_merge with an empty pixel hands the other pixel over untidied.
    far, near = (3.0, 3.0, 0.5, 0, 0, 0.5), (1.0, 1.0, 0, 0.5, 0, 0.5)
    messy = one_pixel([far, near])
    document = over(near[2:], far[2:])
    np.testing.assert_allclose(flatten(messy)[0, 0], document, atol=TOL)
    storage_order = over(far[2:], near[2:])
    np.testing.assert_allclose(flat_pixels(IBA.flatten(to_imagebuf(messy)))[0, 0], storage_order, atol=TOL)
    np.testing.assert_allclose(oiio_merge_flat(messy, DeepImage.empty(1, 1)), storage_order, atol=TOL)


def test_opaque_volume_hides_what_lies_inside_it():
    # Document ("Opaque Volume Samples"): for an opaque sample from Z to ZBack, alpha(z) is 1
    # for every z > Z: "any object within this layer would be completely hidden".
    # OpenImageIO's deep_holdout cuts at the opaque sample's back (DeepData::opaque_z).
    image = one_pixel([(2.0, 2.0, 0.5, 0.5, 0.5, 0.5)])
    mask = one_pixel([(1.0, 3.0, 0.0, 0.0, 0.0, 1.0)])
    np.testing.assert_array_equal(flatten(holdout(image, mask)), np.zeros((1, 1, 4), np.float32))
    theirs = flat_pixels(IBA.flatten(IBA.deep_holdout(to_imagebuf(image), to_imagebuf(mask))))
    np.testing.assert_allclose(theirs[0, 0], [0.5, 0.5, 0.5, 0.5], atol=TOL)


def test_zback_below_z_marks_a_point_sample():
    # Document: Z >= ZBack is a point sample at Z, so (Z 2, ZBack 1) and (Z 2, ZBack 2)
    # coincide and merge. OpenImageIO compares ZBack and keeps them apart, composited in
    # order with over.
    s1, s2 = (2.0, 1.0, 0.4, 0.0, 0.0, 0.5), (2.0, 2.0, 0.0, 0.4, 0.0, 0.5)
    u = -np.log(0.5)
    merged = np.array([0.4, 0.4, 0, 0]) * (u / 0.5) * (0.75 / (2 * u)) + [0, 0, 0, 0.75]
    np.testing.assert_allclose(flatten(one_pixel([s1, s2]))[0, 0], merged, atol=TOL)
    theirs = oiio_merge_flat(one_pixel([s1]), one_pixel([s2]))
    np.testing.assert_allclose(theirs, over(s1[2:], s2[2:]), atol=TOL)
