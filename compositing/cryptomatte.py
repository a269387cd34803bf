"""Cryptomatte: ID mattes as rank/coverage channel pairs, in the layout Blender and Cycles write.

The standard is Psyop's *Cryptomatte* specification (Friedman & Jones, 2015, version 1.2.0,
``specification/cryptomatte_specification.pdf`` in the Psyop/Cryptomatte repository). Every
name (an object's, a material's, an asset's) becomes a 32-bit ID:

* ``hash``: MurmurHash3_x86_32 (Appleby, SMHasher) of the name's UTF-8 bytes with seed 0
  (:func:`murmurhash3_32`, :func:`name_hash`);
* ``conversion`` ``uint32_to_float32``: the 32 bits read as an IEEE float after the exponent
  is clamped to [1, 254], so that no ID is a denormal, an infinity or a NaN
  (:func:`hash_to_float`; the specification's *Floating point conversion* section, Blender's
  ``CryptomatteHash::float_encoded``);
* a *manifest*: the JSON object ``{"name":"<8 hex digits>",...}`` of every name of the layer.

A layer of ``levels`` levels (6 by default, as Blender's ``ViewLayer.pass_cryptomatte_depth``)
is stored as ``ceil(levels / 2)`` RGBA passes ``<Layer>00``, ``<Layer>01``, … each holding
two ``(id, coverage)`` pairs, the IDs of each pixel sorted by decreasing coverage
(:func:`rank_coverage`, :func:`split_passes`). Coverage is the fraction of the pixel the ID
covers, weighted by its alpha contribution, so the coverages of a pixel sum to its alpha when
the levels hold every ID in it.

Names, as Blender writes them (``source/blender/blenkernel/intern/cryptomatte.cc``,
checked against Cycles renders by ``tests/addon/test_addon_cryptomatte.py``):

* layers ``<view layer>.CryptoObject``, ``<view layer>.CryptoMaterial``,
  ``<view layer>.CryptoAsset`` (:data:`LAYER_TYPES`);
* header keys ``cryptomatte/<key>/name``, ``…/hash``, ``…/conversion``, ``…/manifest``,
  ``<key>`` the first 7 hex digits of the MurmurHash3 of the layer name (:func:`layer_key`,
  :func:`layer_metadata`);
* manifest keys quoted as C++'s ``std::quoted`` does (``"`` and ``\\`` escaped with a
  backslash, other bytes as they are), in the order the names were given.

The matte of an ID (:func:`matte`) is the sum of its coverages over the levels: what Blender's
Cryptomatte node and other compositors extract.

Pure numpy; no Blender.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

__all__ = [
    "DEFAULT_LEVELS",
    "LAYER_TYPES",
    "MAX_LEVELS",
    "coverage_passes",
    "hash_to_float",
    "layer_key",
    "layer_metadata",
    "manifest",
    "matte",
    "murmurhash3_32",
    "name_hash",
    "name_id",
    "pass_names",
    "rank_coverage",
    "split_passes",
]

#: Blender's default number of levels (``ViewLayer.pass_cryptomatte_depth``).
DEFAULT_LEVELS = 6
#: Blender's largest setting of ``pass_cryptomatte_depth``.
MAX_LEVELS = 16
#: The three layers Blender writes and the pass-name stem of each (``RE_PASSNAME_CRYPTOMATTE_*``).
LAYER_TYPES: dict[str, str] = {"object": "CryptoObject", "material": "CryptoMaterial", "asset": "CryptoAsset"}

_MASK = 0xFFFFFFFF


def _rotl(x: int, r: int) -> int:
    return ((x << r) | (x >> (32 - r))) & _MASK


def murmurhash3_32(data: bytes, seed: int = 0) -> int:
    """MurmurHash3_x86_32 of ``data`` (Austin Appleby's SMHasher reference, ``MurmurHash3.cpp``).

    Args:
        data: the bytes to hash.
        seed: 32-bit seed (Cryptomatte uses 0).

    Returns:
        The unsigned 32-bit hash.
    """
    if not isinstance(data, bytes | bytearray | memoryview):
        raise TypeError(f"data: expected bytes, got {type(data).__name__}")
    if not isinstance(seed, int) or not 0 <= seed <= _MASK:
        raise ValueError(f"seed: expected an integer in [0, 2^32 - 1], got {seed!r}")
    data = bytes(data)
    c1, c2 = 0xCC9E2D51, 0x1B873593
    h = seed
    n_blocks = len(data) // 4
    for (k,) in struct.iter_unpack("<I", data[: 4 * n_blocks]):
        k = (k * c1) & _MASK
        k = _rotl(k, 15)
        k = (k * c2) & _MASK
        h ^= k
        h = _rotl(h, 13)
        h = (h * 5 + 0xE6546B64) & _MASK
    tail = data[4 * n_blocks :]
    k = 0
    for i in reversed(range(len(tail))):
        k ^= tail[i] << (8 * i)
    if tail:
        k = (k * c1) & _MASK
        k = _rotl(k, 15)
        k = (k * c2) & _MASK
        h ^= k
    h ^= len(data)
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & _MASK
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & _MASK
    h ^= h >> 16
    return h


def _check_name(name: object, what: str) -> str:
    if not isinstance(name, str):
        raise TypeError(f"{what}: expected a str, got {type(name).__name__}")
    return name


def name_hash(name: str) -> int:
    """The Cryptomatte hash of a name: :func:`murmurhash3_32` of its UTF-8 bytes, seed 0."""
    return murmurhash3_32(_check_name(name, "name").encode("utf-8"))


def hash_to_float(hash_value: int) -> np.float32:
    """The ``uint32_to_float32`` conversion: the hash's bits as a float32, exponent clamped to [1, 254].

    Sign and mantissa are kept; an exponent of 0 (zero, denormals) becomes 1 and one of 255
    (infinities, NaNs) becomes 254, so every ID is a normal finite float (the specification's
    *Floating point conversion*).
    """
    if not isinstance(hash_value, int | np.integer) or not 0 <= int(hash_value) <= _MASK:
        raise ValueError(f"hash_value: expected an integer in [0, 2^32 - 1], got {hash_value!r}")
    h = int(hash_value)
    exponent = min(max((h >> 23) & 0xFF, 1), 254)
    bits = (h & 0x80000000) | (exponent << 23) | (h & 0x7FFFFF)
    return np.array([bits], np.uint32).view(np.float32)[0]


def name_id(name: str) -> np.float32:
    """The float32 ID a Cryptomatte layer stores for ``name``: ``hash_to_float(name_hash(name))``."""
    return hash_to_float(name_hash(name))


def _quoted(text: str) -> str:
    """``std::quoted``: the text in double quotes, ``"`` and ``\\`` preceded by a backslash."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def manifest(names: Iterable[str]) -> str:
    """The manifest of a layer: ``{"name":"<hash, 8 lowercase hex digits>",...}``, no spaces.

    Names are kept in the order given, each once (a repeated name keeps its first place), and
    quoted as Blender's ``to_manifest`` does (``std::quoted``); the result is JSON for every name
    without control characters.
    """
    seen: dict[str, None] = {}
    for i, name in enumerate(names):
        seen.setdefault(_check_name(name, f"names[{i}]"), None)
    return "{" + ",".join(f'{_quoted(n)}:"{name_hash(n):08x}"' for n in seen) + "}"


def layer_key(layer_name: str) -> str:
    """The header prefix of a layer: ``cryptomatte/`` + the first 7 hex digits of its name's hash + ``/``."""
    return f"cryptomatte/{name_hash(_check_name(layer_name, 'layer_name')):08x}"[:19] + "/"


def _layer_type(layer_type: str) -> str:
    if layer_type not in LAYER_TYPES:
        raise ValueError(f"layer_type: expected one of {sorted(LAYER_TYPES)}, got {layer_type!r}")
    return LAYER_TYPES[layer_type]


def layer_metadata(view_layer: str, layer_type: str, names: Iterable[str]) -> dict[str, str]:
    """The four header entries of one layer, as Cycles stores them in a multilayer EXR.

    Args:
        view_layer: the view layer's name (``"ViewLayer"`` in a new Blender file).
        layer_type: ``"object"``, ``"material"`` or ``"asset"``.
        names: the layer's names, for the manifest (:func:`manifest`).

    Returns:
        ``{"cryptomatte/<key>/name": "<view layer>.Crypto<Type>", …/hash: "MurmurHash3_32",
        …/conversion: "uint32_to_float32", …/manifest: <manifest>}``.
    """
    layer = f"{_check_name(view_layer, 'view_layer')}.{_layer_type(layer_type)}"
    key = layer_key(layer)
    return {
        key + "name": layer,
        key + "hash": "MurmurHash3_32",
        key + "conversion": "uint32_to_float32",
        key + "manifest": manifest(names),
    }


def _check_levels(levels: object) -> int:
    if isinstance(levels, bool) or not isinstance(levels, int | np.integer) or not 1 <= levels <= MAX_LEVELS:
        raise ValueError(f"levels: expected an integer in [1, {MAX_LEVELS}], got {levels!r}")
    return int(levels)


def pass_names(layer_type: str, levels: int = DEFAULT_LEVELS) -> list[str]:
    """The RGBA passes of a layer: ``Crypto<Type>00`` … ``ceil(levels / 2)`` of them."""
    stem = _layer_type(layer_type)
    return [f"{stem}{i:02d}" for i in range(math.ceil(_check_levels(levels) / 2))]


def _checked_entries(
    pixel: np.ndarray, ids: np.ndarray, weight: np.ndarray, shape: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if len(shape) != 2 or min(int(shape[0]), int(shape[1])) < 0:
        raise ValueError(f"shape: expected (height, width), got {shape!r}")
    height, width = int(shape[0]), int(shape[1])
    pixel = np.asarray(pixel)
    ids = np.asarray(ids)
    weight = np.asarray(weight)
    if pixel.ndim != 1 or ids.shape != pixel.shape or weight.shape != pixel.shape:
        raise ValueError(
            "pixel, ids, weight: expected three (E,) arrays, "
            f"got shapes {pixel.shape}, {ids.shape}, {weight.shape}"
        )
    if pixel.size and (pixel.dtype.kind not in "iu" or pixel.min() < 0 or pixel.max() >= height * width):
        raise ValueError(f"pixel: expected integer indices in [0, {height * width}), got dtype {pixel.dtype}")
    if ids.dtype != np.float32:
        raise TypeError(f"ids: expected float32 IDs (name_id), got dtype {ids.dtype}")
    if weight.size and not (np.isfinite(weight).all() and weight.min() >= 0.0):
        raise ValueError("weight: expected finite values >= 0")
    return pixel, ids, weight


def rank_coverage(
    pixel: np.ndarray,
    ids: np.ndarray,
    weight: np.ndarray,
    shape: tuple[int, int],
    levels: int = DEFAULT_LEVELS,
) -> np.ndarray:
    """Per pixel, the ``levels`` IDs of largest coverage and their coverages.

    Args:
        pixel: (E,) integer flat pixel index ``row·width + column`` of each entry (a sample's
            surface, or a share of it).
        ids: (E,) float32 Cryptomatte ID of each entry (:func:`name_id`); entries of one pixel
            with the same ID are summed.
        weight: (E,) float coverage of each entry, in [0, 1] (a sample's share of the pixel
            times its alpha contribution).
        shape: ``(height, width)`` of the image.
        levels: how many ``(id, coverage)`` pairs to keep, 1 … :data:`MAX_LEVELS`.

    Returns:
        (H, W, levels, 2) float32: ``[..., r, 0]`` the ID of rank ``r``, ``[..., r, 1]`` its
        coverage, in decreasing coverage (ties: increasing ID bits); ``(0, 0)`` where a pixel has
        fewer IDs. Entries of zero weight are dropped.
    """
    levels = _check_levels(levels)
    pixel, ids, weight = _checked_entries(pixel, ids, weight, shape)
    height, width = int(shape[0]), int(shape[1])
    store = _rank(pixel, ids, weight, height * width, levels)
    ranked = store.transpose(1, 0, 2, 3).reshape(height * width, -1, 2)[:, :levels]
    return np.ascontiguousarray(ranked).reshape(height, width, levels, 2)


def coverage_passes(
    pixel: np.ndarray,
    ids: np.ndarray,
    weight: np.ndarray,
    shape: tuple[int, int],
    levels: int = DEFAULT_LEVELS,
) -> list[np.ndarray]:
    """:func:`split_passes` of :func:`rank_coverage`, computed straight into the passes' layout.

    The same arguments and values as ``split_passes(rank_coverage(...))``, without the
    intermediate array: ``ceil(levels / 2)`` contiguous (H, W, 4) float32 passes.
    """
    levels = _check_levels(levels)
    pixel, ids, weight = _checked_entries(pixel, ids, weight, shape)
    height, width = int(shape[0]), int(shape[1])
    store = _rank(pixel, ids, weight, height * width, levels)
    return [store[i].reshape(height, width, 4) for i in range(len(store))]


def _rank(pixel: np.ndarray, ids: np.ndarray, weight: np.ndarray, n_pixels: int, levels: int) -> np.ndarray:
    """(ceil(levels/2), P, 2, 2) float32: rank ``r`` of pixel ``p`` at ``[r // 2, p, r % 2]``."""
    store = np.zeros(((levels + 1) // 2, n_pixels, 2, 2), np.float32)
    keep = weight > 0
    if not keep.all():
        pixel, ids, weight = pixel[keep], ids[keep], weight[keep]
    if pixel.size == 0:
        return store
    if pixel.size < 2 or bool(np.all(pixel[1:] > pixel[:-1])):  # one entry per pixel (opaque, one sample)
        store[0, pixel, 0, 0] = ids
        store[0, pixel, 0, 1] = weight
        return store
    bits = ids.view(np.uint32).astype(np.int64)
    pixel = pixel.astype(np.int64)
    # group equal (pixel, id) and sum their weights (float64: exact sums of sample shares)
    key = pixel << 32 | bits
    order = np.argsort(key, kind="stable")
    key = key[order]
    start = np.r_[True, key[1:] != key[:-1]]
    sums = np.add.reduceat(weight[order].astype(np.float64), np.flatnonzero(start))
    key = key[start]
    run_pixel, run_bits = key >> 32, key & _MASK
    # rank inside each pixel: decreasing coverage, then increasing ID bits
    by_rank = np.lexsort((run_bits, -sums, run_pixel))
    run_pixel, run_bits, sums = run_pixel[by_rank], run_bits[by_rank], sums[by_rank]
    first = np.r_[True, run_pixel[1:] != run_pixel[:-1]]
    first_index = np.maximum.accumulate(np.where(first, np.arange(len(first)), 0))
    rank = np.arange(len(first)) - first_index
    kept = rank < levels
    out_pix, out_rank = run_pixel[kept], rank[kept]
    store[out_rank // 2, out_pix, out_rank % 2, 0] = run_bits[kept].astype(np.uint32).view(np.float32)
    store[out_rank // 2, out_pix, out_rank % 2, 1] = sums[kept]
    return store


def split_passes(ranked: np.ndarray) -> list[np.ndarray]:
    """The RGBA passes of a layer from :func:`rank_coverage`'s (H, W, levels, 2) array.

    Pass ``i`` holds ranks ``2i`` and ``2i + 1`` as ``(id, coverage, id, coverage)``; an odd
    last rank leaves the last pass's B and A at 0. Returns ``ceil(levels / 2)`` (H, W, 4)
    float32 arrays.
    """
    ranked = np.asarray(ranked)
    if ranked.ndim != 4 or ranked.shape[-1] != 2 or ranked.dtype != np.float32:
        raise ValueError(
            "ranked: expected float32 (H, W, levels, 2) from rank_coverage, "
            f"got {ranked.dtype} {ranked.shape}"
        )
    h, w, levels, _ = ranked.shape
    n = math.ceil(levels / 2)
    padded = np.zeros((h, w, 2 * n, 2), np.float32)
    padded[:, :, :levels] = ranked
    flat = padded.reshape(h, w, n, 4)
    return [np.ascontiguousarray(flat[:, :, i]) for i in range(n)]


def matte(passes: Sequence[np.ndarray] | Mapping[str, np.ndarray], ids: Iterable[float]) -> np.ndarray:
    """The matte of one or more IDs: the sum of their coverages over every level of a layer.

    Args:
        passes: the layer's RGBA passes in order (``Crypto<Type>00``, ``01``, …), each (H, W, 4),
            or a mapping of pass name to pass (sorted by name).
        ids: the float32 IDs to extract (:func:`name_id`); compared bit for bit.

    Returns:
        (H, W) float32 coverage of those IDs (as the Cryptomatte decoders compute it).
    """
    if isinstance(passes, Mapping):
        passes = [passes[k] for k in sorted(passes)]
    layers = [np.asarray(p, dtype=np.float32) for p in passes]
    if not layers or any(p.ndim != 3 or p.shape[-1] != 4 or p.shape != layers[0].shape for p in layers):
        raise ValueError(
            f"passes: expected one or more (H, W, 4) arrays of one shape, got {[np.shape(p) for p in layers]}"
        )
    wanted = np.array([np.float32(i) for i in ids], np.float32).view(np.uint32)
    out = np.zeros(layers[0].shape[:2], np.float64)
    for p in layers:
        for c in (0, 2):
            hit = np.isin(p[..., c].view(np.uint32), wanted)
            out += np.where(hit, p[..., c + 1], 0.0)
    return out.astype(np.float32)
