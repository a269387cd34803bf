"""Test images: random premultiplied RGBA with the edge cases every operator must handle."""

from __future__ import annotations

import numpy as np


def premultiplied_pixels(n: int, seed: int, dtype=np.float32) -> np.ndarray:
    """``n`` premultiplied RGBA pixels: random, plus α = 0, α = 1, glow (rgb > 0 at α = 0) and HDR (> 1)."""
    rng = np.random.default_rng(seed)
    alpha = rng.random(n)
    straight = rng.random((n, 3))
    kind = np.arange(n) % 6
    alpha[kind == 1] = 0.0  # fully transparent
    alpha[kind == 2] = 1.0  # opaque
    rgb = straight * alpha[:, None]
    glow = kind == 3  # emission without coverage
    alpha[glow] = 0.0
    rgb[glow] = rng.random((int(glow.sum()), 3)) * 2.0
    hdr = kind == 4  # colour above 1
    rgb[hdr] *= 1.0 + 7.0 * rng.random((int(hdr.sum()), 1))
    return np.concatenate([rgb, alpha[:, None]], axis=1).astype(dtype)


def image_pair(shape: tuple[int, int], seed: int, dtype=np.float32) -> tuple[np.ndarray, np.ndarray]:
    """Two independent premultiplied images of ``shape`` (rows, columns)."""
    n = shape[0] * shape[1]
    a = premultiplied_pixels(n, seed, dtype).reshape(*shape, 4)
    b = premultiplied_pixels(n, seed + 1000, dtype)
    b = np.random.default_rng(seed).permutation(b).reshape(*shape, 4)
    return a, b
