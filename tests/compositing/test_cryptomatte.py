"""compositing.cryptomatte: hash, float conversion, manifest, header keys and rank/coverage packing.

Independent sources: the MurmurHash3_x86_32 test vectors published with SMHasher (and quoted on
its Wikipedia page); the hashes, header keys and manifest a Cycles render of Blender 5.0.1
wrote (``cryptomatte/542cafa/manifest = {"Cubé":"eb1afb7b","Sphere child":"e06ce80f"}`` …; the
bpy test ``tests/addon/test_addon_cryptomatte.py`` renders them again); IEEE 754 bit layouts
worked by hand; coverages summed by hand.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from compositing import cryptomatte as cm

# (data, seed, hash): SMHasher's MurmurHash3_x86_32 verification values
SMHASHER_VECTORS = [
    (b"", 0, 0x00000000),
    (b"", 1, 0x514E28B7),
    (b"", 0xFFFFFFFF, 0x81F16F39),
    (b"\x00\x00\x00\x00", 0, 0x2362F9DE),
    (b"aaaa", 0x9747B28C, 0x5A97808A),
    (b"test", 0, 0xBA6BD213),
    (b"Hello, world!", 0, 0xC0363E43),
    (b"Hello, world!", 1234, 0xFAF6CDB3),
    (b"The quick brown fox jumps over the lazy dog", 0, 0x2E4FF723),
]


@pytest.mark.parametrize(("data", "seed", "expected"), SMHASHER_VECTORS)
def test_murmurhash3_matches_published_vectors(data: bytes, seed: int, expected: int) -> None:
    assert cm.murmurhash3_32(data, seed) == expected


# names and hashes from a Cycles render's manifest (Blender 5.0.1)
CYCLES_MANIFEST = {
    "Cubé": 0xEB1AFB7B,  # non-ASCII: hashed as UTF-8
    "Sphere child": 0xE06CE80F,
    "Mat A": 0x4FBB3920,
    "default_surface": 0x78D05529,
}


@pytest.mark.parametrize(("name", "expected"), CYCLES_MANIFEST.items())
def test_name_hash_matches_cycles(name: str, expected: int) -> None:
    assert cm.name_hash(name) == expected


@pytest.mark.parametrize(
    ("hash_value", "bits"),
    [
        (0x3F800000, 0x3F800000),  # exponent 127: kept as it is (1.0)
        (0x00000001, 0x00800001),  # exponent 0 (a denormal): raised to 1
        (0x80000000, 0x80800000),  # -0.0: exponent raised to 1, sign kept
        (0x7F800000, 0x7F000000),  # +inf: exponent lowered to 254
        (0xFFFFFFFF, 0xFF7FFFFF),  # a NaN: exponent 254, mantissa and sign kept
        (0xEB1AFB7B, 0xEB1AFB7B),  # "Cubé": a normal float, unchanged
    ],
)
def test_hash_to_float_clamps_the_exponent(hash_value: int, bits: int) -> None:
    f = cm.hash_to_float(hash_value)
    assert f.dtype == np.float32
    assert int(np.array([f]).view(np.uint32)[0]) == bits
    assert math.isfinite(float(f)) and (float(f) == 0.0 or abs(float(f)) >= np.finfo(np.float32).tiny)


def test_every_exponent_gives_a_normal_finite_float() -> None:
    for exponent in range(256):
        for sign in (0, 1):
            f = float(cm.hash_to_float((sign << 31) | (exponent << 23) | 0x1234))
            assert math.isfinite(f) and abs(f) >= np.finfo(np.float32).tiny


def test_layer_keys_and_metadata_match_cycles() -> None:
    # the keys Cycles wrote for view layer "ViewLayer"
    assert cm.layer_key("ViewLayer.CryptoObject") == "cryptomatte/542cafa/"
    assert cm.layer_key("ViewLayer.CryptoMaterial") == "cryptomatte/c7dbf5e/"
    assert cm.layer_key("ViewLayer.CryptoAsset") == "cryptomatte/aa21542/"
    meta = cm.layer_metadata("ViewLayer", "object", ["Cubé", "Sphere child"])
    assert meta == {
        "cryptomatte/542cafa/name": "ViewLayer.CryptoObject",
        "cryptomatte/542cafa/hash": "MurmurHash3_32",
        "cryptomatte/542cafa/conversion": "uint32_to_float32",
        "cryptomatte/542cafa/manifest": '{"Cubé":"eb1afb7b","Sphere child":"e06ce80f"}',
    }


def test_manifest_is_json_in_order_with_each_name_once_and_escaped() -> None:
    names = ["b", 'q"uote', "a\\b", "b", "Ünï"]
    text = cm.manifest(names)
    parsed = json.loads(text)
    assert list(parsed) == ["b", 'q"uote', "a\\b", "Ünï"]
    assert all(parsed[n] == f"{cm.name_hash(n):08x}" for n in parsed)
    assert " " not in text and '"q\\"uote"' in text


def test_pass_names_as_cycles() -> None:
    assert cm.pass_names("object") == ["CryptoObject00", "CryptoObject01", "CryptoObject02"]
    assert cm.pass_names("material", 3) == ["CryptoMaterial00", "CryptoMaterial01"]
    assert cm.pass_names("asset", 1) == ["CryptoAsset00"]
    with pytest.raises(ValueError, match="levels"):
        cm.pass_names("object", 0)
    with pytest.raises(ValueError, match="layer_type"):
        cm.pass_names("objects")


def test_rank_coverage_sums_sorts_and_truncates() -> None:
    a, b, c = (cm.name_id(n) for n in ("A", "B", "C"))
    # pixel 0: A 0.25 + A 0.25, B 0.125, C 0.375 ; pixel 3: B 1.0 ; pixels 1, 2 empty
    pixel = np.array([0, 0, 0, 0, 3])
    ids = np.array([a, b, a, c, b], np.float32)
    weight = np.array([0.25, 0.125, 0.25, 0.375, 1.0])
    ranked = cm.rank_coverage(pixel, ids, weight, (2, 2), levels=3)
    assert ranked.shape == (2, 2, 3, 2) and ranked.dtype == np.float32
    expected0 = [(a, 0.5), (c, 0.375), (b, 0.125)]
    for r, (i, w) in enumerate(expected0):
        assert ranked[0, 0, r, 0].view(np.uint32) == np.float32(i).view(np.uint32)
        assert ranked[0, 0, r, 1] == w
    assert ranked[1, 1, 0, 1] == 1.0 and ranked[1, 1, 0, 0] == b
    assert not ranked[0, 1].any() and not ranked[1, 0].any() and not ranked[1, 1, 1:].any()
    two = cm.rank_coverage(pixel, ids, weight, (2, 2), levels=2)  # the smallest ID is dropped
    assert two[0, 0, :, 1].tolist() == [0.5, 0.375]


def test_split_passes_and_matte_round_trip() -> None:
    a, b = cm.name_id("A"), cm.name_id("B")
    pixel = np.array([0, 0, 1])
    ranked = cm.rank_coverage(pixel, np.array([a, b, b], np.float32), np.array([0.75, 0.25, 1.0]), (1, 2), 3)
    passes = cm.split_passes(ranked)
    assert len(passes) == 2 and passes[0].shape == (1, 2, 4)
    assert passes[0][0, 0].tolist() == [float(a), 0.75, float(b), 0.25]
    assert not passes[1].any()  # rank 2 empty, rank 3 does not exist
    assert cm.matte(passes, [a]).tolist() == [[0.75, 0.0]]
    assert cm.matte(passes, [b]).tolist() == [[0.25, 1.0]]
    assert cm.matte(passes, [a, b]).tolist() == [[1.0, 1.0]]


def test_bad_inputs_name_the_argument() -> None:
    with pytest.raises(TypeError, match="ids"):
        cm.rank_coverage(np.array([0]), np.array([1.0]), np.array([1.0]), (1, 1))
    with pytest.raises(ValueError, match="pixel"):
        cm.rank_coverage(np.array([5]), np.array([1.0], np.float32), np.array([1.0]), (1, 1))
    with pytest.raises(ValueError, match="weight"):
        cm.rank_coverage(np.array([0]), np.array([1.0], np.float32), np.array([np.nan]), (1, 1))
    with pytest.raises(TypeError, match="name"):
        cm.name_hash(b"bytes")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="hash_value"):
        cm.hash_to_float(-1)


@pytest.mark.parametrize("levels", [1, 4, 5])
def test_coverage_passes_equal_split_rank_coverage(levels: int) -> None:
    rng = np.random.default_rng(3)
    names = [cm.name_id(f"n{i}") for i in range(7)]
    pixel = np.sort(rng.integers(0, 12, 200))
    ids = np.array(names, np.float32)[rng.integers(0, 7, 200)]
    weight = rng.integers(0, 5, 200) / 16.0
    direct = cm.coverage_passes(pixel, ids, weight, (3, 4), levels)
    split = cm.split_passes(cm.rank_coverage(pixel, ids, weight, (3, 4), levels))
    assert len(direct) == len(split) == math.ceil(levels / 2)
    for a, b in zip(direct, split, strict=True):
        assert a.flags.c_contiguous
        np.testing.assert_array_equal(a.view(np.uint32), b.view(np.uint32))
