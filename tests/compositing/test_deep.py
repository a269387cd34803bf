"""Deep images against closed forms and a literal reading of OpenEXR's deep-pixel document.

Oracles: the document's formulas ("Interpreting OpenEXR Deep Pixels", openexr.com) written
out here in float64 with ``pow`` and ``log`` (not the kernels' ``log1p``/``expm1`` form); the
document's tidy procedure done literally (repeated pairwise splits and merges, then a
sort) in pure Python; the limit that defines the merge rule (interleaving many thin slices
of two coincident volumes with ``over``, "Theory of Deep Samples"); and algebraic
identities (``over`` of split pieces gives the sample back, holdouts partition a merge).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from deep_testdata import one_pixel, random_deep

from compositing.deep import DeepImage, crop, flatten, from_flat, holdout, merge, tidy

# Float32 storage of every result: values of order 1 are rounded by 6e-8 per operation;
# 1e-6 leaves room for a chain of 16 samples.
TOL = 1e-6


def over(front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """Porter-Duff over on premultiplied RGBA (the document's "over")."""
    return front + (1.0 - front[..., 3:]) * back


# --- the document, literally -------------------------------------------------------------


def doc_split(s, z):
    """Split volume sample ``s = [zf, zb, r, g, b, a]`` at ``z`` (document: "Splitting a Volume Sample")."""
    zf, zb, *c, a = s

    def alpha_at(d):  # alpha_i(d) = 1 - (1 - a)^x(d)
        x = (d - zf) / (zb - zf)
        return 1.0 - (1.0 - a) ** x, x

    def colour_at(d):
        alpha, x = alpha_at(d)
        return [ci * alpha / a for ci in c] if a > 0 else [ci * x for ci in c]

    a_front, _ = alpha_at(z)
    a_back, _ = alpha_at(zf + zb - z)
    return [zf, z, *colour_at(z), a_front], [z, zb, *colour_at(zf + zb - z), a_back]


def doc_merge(group):
    """Merge perfectly overlapping samples (document: "Merging Overlapping Samples").

    Pairwise rule for two samples; for more, the pairwise rule folded (associative while at
    most one is opaque); several opaque samples: their mean (the order-free extension).
    """
    opaque = [s for s in group if s[5] == 1.0]
    if opaque:
        return [group[0][0], group[0][1], *np.mean([s[2:5] for s in opaque], axis=0), 1.0]
    merged = list(group[0])
    for s in group[1:]:
        a1, a2 = merged[5], s[5]
        am = 1.0 - (1.0 - a1) * (1.0 - a2)
        u1 = -math.log(1.0 - a1) if a1 > 0 else 0.0
        u2 = -math.log(1.0 - a2) if a2 > 0 else 0.0
        v1 = u1 / a1 if a1 > 0 else 1.0
        v2 = u2 / a2 if a2 > 0 else 1.0
        w = am / (u1 + u2) if u1 + u2 != 0 else 1.0
        merged = [merged[0], merged[1], *(w * (merged[k] * v1 + s[k] * v2) for k in (2, 3, 4)), am]
    return merged


def doc_tidy(samples):
    """The document's "Making an Image Tidy" for one pixel, step by step, in float64."""
    ss = [list(map(float, s)) for s in samples]
    for s in ss:
        s[1] = max(s[0], s[1])  # ZBack <= Z: a point sample at Z
    # 1. Split partially overlapping samples. Splitting creates no new boundary (a piece
    # begins and ends where some sample does), so "repeat until none is left" ends with
    # every volume split at every sample front and volume back strictly inside it, in turn.
    cuts = sorted({s[0] for s in ss} | {s[1] for s in ss if s[1] > s[0]})
    pieces = []
    for s in ss:
        rest = s
        for cut in cuts:
            if rest[1] > rest[0] and rest[0] < cut < rest[1]:
                front, rest = doc_split(rest, cut)
                pieces.append(front)
        pieces.append(rest)
    ss = pieces
    groups: dict[tuple[float, float], list] = {}  # 2. merge perfectly overlapping samples
    for s in ss:
        groups.setdefault((s[0], s[1]), []).append(s)
    merged = [doc_merge(g) for g in groups.values()]
    return sorted(merged, key=lambda s: (s[0], s[1]))  # 3. sort by Z, then ZBack


def doc_flatten(samples):
    """Composite the tidy samples front to back with over."""
    acc = np.zeros(4)
    for s in doc_tidy(samples):
        acc = over(acc, np.array(s[2:]))
    return acc


def pixel_rows(image: DeepImage, row: int, col: int) -> list[list[float]]:
    z, zb, rgba = image.pixel(row, col)
    return [[float(z[k]), float(zb[k]), *map(float, rgba[k])] for k in range(len(z))]


# --- splitting ---------------------------------------------------------------------------


@pytest.mark.parametrize("alpha", [0.0, 1e-6, 0.3, 0.9, 0.999999, 1.0])
@pytest.mark.parametrize("pieces", [2, 7, 64])
def test_split_pieces_follow_the_log_rule_and_compose_back(alpha, pieces):
    rng = np.random.default_rng(pieces)
    z0, z1 = 2.0, 5.0
    colour = np.array([0.6, 0.25, 0.1]) * (alpha if alpha > 0 else 0.1)
    cuts = np.sort(rng.uniform(z0, z1, pieces - 1)).astype(np.float32)
    # Zero point samples (alpha 0, colour 0) at the cuts make tidy split the volume there and
    # add nothing when composited.
    rows = [(z0, z1, *colour, alpha)] + [(c, c, 0, 0, 0, 0) for c in cuts]
    result = tidy(one_pixel(rows))
    volume = result.zback > result.z
    z, zb, rgba = result.z[volume], result.zback[volume], result.rgba[volume].astype(np.float64)
    assert len(z) == pieces and z[0] == np.float32(z0) and zb[-1] == np.float32(z1)
    np.testing.assert_array_equal(z[1:], zb[:-1])
    x = (zb.astype(np.float64) - z) / (np.float32(z1) - np.float32(z0))
    want_alpha = 1.0 - (1.0 - np.float32(alpha)) ** x
    want_rgb = np.outer(want_alpha / alpha, colour.astype(np.float32)) if alpha > 0 else np.outer(x, colour)
    np.testing.assert_allclose(rgba[:, 3], want_alpha, rtol=0, atol=TOL)
    np.testing.assert_allclose(rgba[:, :3], want_rgb, rtol=0, atol=TOL)
    acc = np.zeros(4)
    for piece in rgba:
        acc = over(acc, piece)
    np.testing.assert_allclose(acc, [*colour, alpha], rtol=0, atol=TOL)
    np.testing.assert_allclose(flatten(result)[0, 0], [*colour, alpha], rtol=0, atol=TOL)


def test_split_of_a_faint_sample_keeps_its_colour():
    # alpha = 1e-30: 1 - (1 - a)^x is 0 in float arithmetic; the log1p/expm1 form keeps a·x.
    result = tidy(one_pixel([(0.0, 4.0, 2e-30, 1e-30, 0.0, 1e-30), (1.0, 1.0, 0, 0, 0, 0)]))
    z, zb, rgba = result.pixel(0, 0)
    front = rgba[(zb == 1.0) & (z == 0.0)][0]
    np.testing.assert_allclose(front, [0.5e-30, 0.25e-30, 0.0, 0.25e-30], rtol=1e-6)


# --- merging coincident samples ----------------------------------------------------------


@pytest.mark.parametrize(
    ("a1", "a2"),
    [(0.3, 0.6), (0.0, 0.5), (0.0, 0.0), (1.0, 0.4), (0.4, 1.0), (1.0, 1.0), (1e-7, 0.2), (0.999, 0.999)],
)
@pytest.mark.parametrize("thick", [False, True])
def test_two_coincident_samples_merge_by_the_documents_rule(a1, a2, thick):
    zb = 3.0 if thick else 1.0
    s1 = (1.0, zb, 0.5 * a1 + 0.01, 0.2 * a1, 0.1, a1)
    s2 = (1.0, zb, 0.1 * a2, 0.7 * a2 + 0.02, 0.3, a2)
    result = tidy(one_pixel([s1, s2]))
    assert result.counts[0, 0] == 1
    want = doc_merge([list(s1), list(s2)])
    np.testing.assert_allclose(result.rgba[0], want[2:], rtol=0, atol=TOL)


def test_merge_rule_is_the_limit_of_interleaved_slices():
    # Theory of Deep Samples: two coincident volumes equal their k thin slices interleaved.
    a1, c1, a2, c2 = 0.7, np.array([0.5, 0.1, 0.2]), 0.4, np.array([0.05, 0.3, 0.1])
    k = 20000
    acc = np.zeros(4)
    for _ in range(k):
        for a, c in ((a1, c1), (a2, c2)):
            piece_alpha = 1 - (1 - a) ** (1 / k)
            acc = over(acc, np.array([*(c * piece_alpha / a), piece_alpha]))
    result = tidy(one_pixel([(0.0, 1.0, *c1, a1), (0.0, 1.0, *c2, a2)]))
    np.testing.assert_allclose(result.rgba[0], acc, rtol=0, atol=5e-5)  # O(1/k) from the limit


def test_many_coincident_samples_merge_as_pairwise_merges_in_any_order():
    rng = np.random.default_rng(5)
    rows = [(2.0, 2.0 + t, *(rng.random(3) * a), a) for a in rng.uniform(0, 0.95, 9) for t in [1.5]]
    want = doc_merge([list(r) for r in rows])
    for perm in range(3):
        order = rng.permutation(len(rows))
        result = tidy(one_pixel([rows[i] for i in order]))
        assert result.counts[0, 0] == 1
        np.testing.assert_allclose(result.rgba[0], want[2:], rtol=0, atol=TOL, err_msg=f"perm {perm}")


def test_point_samples_never_merge_with_volume_samples():
    result = tidy(one_pixel([(1.0, 2.0, 0.1, 0.1, 0.1, 0.5), (1.0, 1.0, 0.2, 0.2, 0.2, 0.5)]))
    np.testing.assert_array_equal(result.z, [1.0, 1.0])
    np.testing.assert_array_equal(result.zback, [1.0, 2.0])  # the point first (sorted by ZBack)


def test_zback_below_z_is_a_point_sample():
    # Document: Z >= ZBack marks a point sample at Z; two such at the same Z coincide.
    a = tidy(one_pixel([(2.0, 1.0, 0.1, 0.2, 0.3, 0.4), (2.0, 2.0, 0.3, 0.1, 0.0, 0.5)]))
    assert a.counts[0, 0] == 1 and a.zback[0] == 2.0
    want = doc_merge([[2, 2, 0.1, 0.2, 0.3, 0.4], [2, 2, 0.3, 0.1, 0.0, 0.5]])
    np.testing.assert_allclose(a.rgba[0], want[2:], rtol=0, atol=TOL)


# --- tidy and flatten on messy images: the literal procedure ------------------------------


@pytest.mark.parametrize("seed", range(3))
def test_tidy_matches_the_documents_procedure(seed):
    rng = np.random.default_rng(seed)
    image = random_deep(rng, (6, 6), max_samples=12)
    result = tidy(image)
    assert result.known_tidy and result.is_tidy()
    for row in range(6):
        for col in range(6):
            want = doc_tidy(pixel_rows(image, row, col))
            got = pixel_rows(result, row, col)
            assert len(got) == len(want), (row, col)
            got, want = np.array(got).reshape(-1, 6), np.array(want).reshape(-1, 6)
            np.testing.assert_array_equal(got[:, :2], np.float32(want[:, :2]))
            np.testing.assert_allclose(got[:, 2:], want[:, 2:], rtol=0, atol=TOL)


@pytest.mark.parametrize("seed", range(3))
def test_flatten_matches_the_documents_procedure(seed):
    rng = np.random.default_rng(10 + seed)
    image = random_deep(rng, (8, 8), max_samples=16)
    flat = flatten(image)
    assert flat.shape == (8, 8, 4) and flat.dtype == np.float32
    for row in range(8):
        for col in range(8):
            np.testing.assert_allclose(flat[row, col], doc_flatten(pixel_rows(image, row, col)), atol=TOL)


def test_flatten_of_a_hand_worked_pixel():
    # A point (a .5) in front of a volume (a .6) cut by a point (a .2) at its middle.
    image = one_pixel(
        [(3.0, 5.0, 0.3, 0.0, 0.0, 0.6), (1.0, 1.0, 0.0, 0.5, 0.0, 0.5), (4.0, 4.0, 0.0, 0.0, 0.2, 0.2)]
    )
    half = 1 - 0.4**0.5  # each half of the volume
    front = np.array([0.3 * half / 0.6, 0, 0, half])
    want = over(over(over(np.array([0, 0.5, 0, 0.5]), front), np.array([0, 0, 0.2, 0.2])), front)
    np.testing.assert_allclose(flatten(image)[0, 0], want, atol=TOL)
    assert tidy(image).counts[0, 0] == 4


def test_flatten_ignores_the_stored_order_and_large_pixels_take_the_other_sort():
    rng = np.random.default_rng(3)
    image = random_deep(rng, (1, 1), max_samples=16)
    n = 200  # more than the insertion-sort limit: the mergesort path
    rows = [tuple(r) for r in rng.uniform(0, 5, (n, 2))]
    rows = [
        (z, z + t * (k % 3 > 0), 0.3 * (k % 5) / 5, 0.1, 0.2, (k % 7) / 7) for k, (z, t) in enumerate(rows)
    ]
    big = one_pixel(rows)
    shuffled = one_pixel([rows[i] for i in rng.permutation(n)])
    np.testing.assert_allclose(flatten(big), flatten(shuffled), atol=TOL)
    np.testing.assert_allclose(flatten(big)[0, 0], doc_flatten(rows), atol=1e-5)  # 200 samples deep
    assert image.counts.shape == (1, 1)


def test_tidy_is_idempotent_and_keeps_tidy_pixels_exactly():
    rng = np.random.default_rng(4)
    once = tidy(random_deep(rng, (9, 7)))
    plain = DeepImage(once.counts, once.z, once.zback, once.rgba)  # not marked tidy
    twice = tidy(plain)
    for a, b in (
        (once.counts, twice.counts),
        (once.z, twice.z),
        (once.zback, twice.zback),
        (once.rgba, twice.rgba),
    ):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(flatten(plain), flatten(once))


# --- merge, holdout, crop, from_flat ----------------------------------------------------


def test_merge_is_symmetric_and_equals_tidy_of_the_union():
    rng = np.random.default_rng(6)
    a, b = random_deep(rng, (10, 10)), random_deep(rng, (10, 10))
    ab, ba = merge(a, b), merge(b, a)
    np.testing.assert_array_equal(ab.counts, ba.counts)
    np.testing.assert_allclose(ab.rgba, ba.rgba, rtol=0, atol=1e-7)
    for row in range(10):
        for col in range(10):
            union = pixel_rows(a, row, col) + pixel_rows(b, row, col)
            np.testing.assert_allclose(flatten(ab)[row, col], doc_flatten(union), atol=TOL)
    np.testing.assert_array_equal(merge(a, DeepImage.empty(10, 10)).rgba, tidy(a).rgba)


def test_holdouts_partition_the_merge():
    rng = np.random.default_rng(7)
    a, b = random_deep(rng, (12, 12)), random_deep(rng, (12, 12))
    ha, hb = holdout(a, b), holdout(b, a)
    assert ha.known_tidy and ha.is_tidy()
    np.testing.assert_allclose(flatten(ha) + flatten(hb), flatten(merge(a, b)), rtol=0, atol=2 * TOL)
    same = holdout(a, DeepImage.empty(12, 12))  # nothing held out: the tidy image, cut where opaque
    np.testing.assert_array_equal(flatten(same), flatten(tidy(a)))
    see_through = (tidy(a).counts == same.counts) & (flatten(a)[..., 3] < 1)
    assert see_through.sum() > 20
    for row, col in np.argwhere(see_through):
        for x, y in zip(same.pixel(row, col), tidy(a).pixel(row, col), strict=True):
            np.testing.assert_array_equal(x, y)


def test_holdout_by_an_opaque_point_cuts_what_is_behind():
    image = one_pixel([(1.0, 1.0, 0.2, 0, 0, 0.5), (2.0, 4.0, 0, 0.3, 0, 0.6), (5.0, 5.0, 0, 0, 0.4, 0.8)])
    mask = one_pixel([(3.0, 3.0, 0.9, 0.9, 0.9, 1.0)])
    held = holdout(image, mask)
    z, zb, rgba = held.pixel(0, 0)
    np.testing.assert_array_equal(z, [1.0, 2.0])
    np.testing.assert_array_equal(zb, [1.0, 3.0])
    half = 1 - 0.4**0.5
    np.testing.assert_allclose(rgba, [[0.2, 0, 0, 0.5], [0, 0.3 * half / 0.6, 0, half]], atol=TOL)


def test_holdout_by_a_transparent_sample_attenuates_what_is_behind():
    image = one_pixel([(2.0, 2.0, 0.4, 0.2, 0.0, 0.8)])
    mask = one_pixel([(1.0, 1.0, 0.1, 0.1, 0.1, 0.25)])
    np.testing.assert_allclose(
        flatten(holdout(image, mask))[0, 0], 0.75 * np.array([0.4, 0.2, 0, 0.8]), atol=TOL
    )
    # The image's sample is behind the mask's: the mask keeps all of itself.
    np.testing.assert_array_equal(flatten(holdout(mask, image))[0, 0], np.float32([0.1, 0.1, 0.1, 0.25]))


def test_crop_commutes_with_flatten():
    rng = np.random.default_rng(8)
    image = random_deep(rng, (9, 11))
    part = crop(image, 2, 3, 5, 6)
    assert part.shape == (5, 6) and part.n_samples == int(image.counts[2:7, 3:9].sum())
    np.testing.assert_array_equal(flatten(part), flatten(image)[2:7, 3:9])
    assert crop(image, 0, 0, 0, 0).n_samples == 0
    with pytest.raises(ValueError, match="outside the image"):
        crop(image, 5, 0, 5, 1)


def test_from_flat_flattens_back_and_skips_empty_pixels():
    rng = np.random.default_rng(9)
    flat = rng.random((5, 6, 4)).astype(np.float32)
    flat[..., :3] *= flat[..., 3:]
    flat[0, 0] = 0
    flat[1, 1] = [0.2, 0.1, 0.0, 0.0]  # alpha 0, emission: kept
    depth = rng.uniform(1, 2, (5, 6))
    deep = from_flat(flat, depth)
    assert deep.counts[0, 0] == 0 and deep.counts[1, 1] == 1 and deep.n_samples == 29
    np.testing.assert_array_equal(flatten(deep), flat)
    np.testing.assert_array_equal(deep.pixel(2, 3)[0], [np.float32(depth[2, 3])])
    np.testing.assert_array_equal(from_flat(flat, 3.0, 4.0).zback, np.full(29, 4.0, np.float32))


def test_from_samples_groups_by_pixel_keeping_order():
    image = DeepImage.from_samples((2, 2), np.array([3, 0, 3]), [1.0, 2.0, 0.5], np.eye(4)[:3] * 0.5)
    np.testing.assert_array_equal(image.counts, [[1, 0], [0, 2]])
    np.testing.assert_array_equal(image.pixel(1, 1)[0], [1.0, 0.5])


# --- edge cases and bad input --------------------------------------------------------------


def test_empty_pixels_and_empty_images():
    empty = DeepImage.empty(3, 4)
    np.testing.assert_array_equal(flatten(empty), np.zeros((3, 4, 4), np.float32))
    assert merge(empty, empty).n_samples == 0 and tidy(empty).n_samples == 0
    assert flatten(DeepImage.empty(0, 5)).shape == (0, 5, 4)


def test_opaque_front_sample_hides_everything_behind():
    image = one_pixel([(2.0, 2.0, 9.0, 9.0, 9.0, 0.5), (1.0, 3.0, 0.3, 0.2, 0.1, 1.0)])
    # The volume (alpha 1) is opaque from its front: the point at 2 lies inside it and its
    # front piece [1, 2) is already opaque.
    np.testing.assert_allclose(flatten(image)[0, 0], [0.3, 0.2, 0.1, 1.0], atol=TOL)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("z", np.nan, r"z: expected finite values; got 1 non-finite of 2 \(1 NaN, 0 Inf\)"),
        ("zback", np.inf, r"zback: expected finite"),
        ("rgba", np.inf, r"rgba: expected finite"),
        ("z", -1.0, r"z: expected depths >= 0"),
        ("rgba", 1.5, r"rgba: expected alpha \(last channel\) in \[0, 1\]; got 1 of 2"),
        ("z", 1e300, r"z: expected finite values within float32's range"),
    ],
)
def test_bad_values_are_refused(field, value, message):
    arrays = {"z": np.array([1.0, 2.0]), "zback": np.array([1.0, 2.0]), "rgba": np.full((2, 4), 0.5)}
    if field == "rgba":
        arrays["rgba"][1, 3] = value
    else:
        arrays[field][1] = value
    with pytest.raises(ValueError, match=message):
        DeepImage(np.array([[2]]), **arrays)


def test_bad_shapes_and_types_are_refused():
    ok = {"z": np.zeros(2), "zback": np.zeros(2), "rgba": np.zeros((2, 4))}
    with pytest.raises(ValueError, match=r"counts add up to 3 samples, got z 2"):
        DeepImage(np.array([[3]]), **ok)
    with pytest.raises(TypeError, match="counts: expected an integer array"):
        DeepImage(np.array([[2.0]]), **ok)
    with pytest.raises(ValueError, match=r"rgba: expected shape \(N, 4\)"):
        DeepImage(np.array([[2]]), ok["z"], ok["zback"], np.zeros((2, 3)))
    with pytest.raises(TypeError, match="expected a float32 or float64 array, got dtype int64"):
        DeepImage(np.array([[2]]), np.zeros(2, np.int64), ok["zback"], ok["rgba"])
    with pytest.raises(TypeError, match="a: expected a DeepImage"):
        merge(np.zeros((2, 2, 4)), DeepImage.empty(2, 2))
    with pytest.raises(ValueError, match="expected deep images of equal shape"):
        merge(DeepImage.empty(2, 2), DeepImage.empty(2, 3))
    with pytest.raises(ValueError, match=r"pixel: expected indices in \[0, 4\)"):
        DeepImage.from_samples((2, 2), np.array([4]), [1.0], np.zeros((1, 4)))


def test_images_own_read_only_arrays():
    z = np.array([1.0, 2.0], np.float32)
    image = DeepImage(np.array([[2]]), z, z, np.zeros((2, 4), np.float32))
    z[0] = 7.0
    assert image.z[0] == 1.0 and not image.z.flags.writeable
    with pytest.raises(AttributeError, match="immutable"):
        image.z = z
