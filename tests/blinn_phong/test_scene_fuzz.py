"""Random everyday scenes at real sizes render, and the two engines agree on them.

Each seed is a scene of :mod:`blinn_phong.scene_fuzz` (objects on a floor under open sky, lights of
every type, opaque, transparent and textured materials, fog sometimes) at a drawn frame size from
1×1 to 1920×1080 and a drawn sample count, with a drawn shadow and transparency method. The
frame must render with finite pixels in the premultiplied range; a downscaled copy rendered by
the compiled engine must match the numpy engine (an independent implementation of every stage).
``python -m benchmarks.scene_fuzz`` runs the long sweep.
"""

from __future__ import annotations

import numpy as np
import pytest

from blinn_phong.planning.frame_plan import SHADOW_CHOICES, TRANSPARENCY_CHOICES
from blinn_phong.scene_fuzz import FRAME_SIZES, SAMPLE_COUNTS, check_case, downscaled_size, fuzz_case

#: Frames above this many samples drop to fewer samples per pixel (the suite's time budget).
MAX_SAMPLES = 2_000_000


def _forced(seed: int, concern: str) -> str | None:
    value = fuzz_case(seed, max_samples=MAX_SAMPLES).options.get(concern)
    return None if value is None else str(getattr(value, "method", value))


def _first_seed(concern: str, method: str) -> int:
    """The first seed whose case forces ``method`` for ``concern`` (a fixed seed, found by search)."""
    return next(seed for seed in range(10_000) if _forced(seed, concern) == method)


#: The suite's seeds: the first 24, then the first seed forcing each shadow and transparency method.
SEEDS = sorted(
    set(range(24))
    | {_first_seed("shadows", m) for m in SHADOW_CHOICES}
    | {_first_seed("transparency", m) for m in TRANSPARENCY_CHOICES}
)


@pytest.mark.parametrize("seed", SEEDS)
def test_everyday_scene_renders(seed: int) -> None:
    report = check_case(fuzz_case(seed, max_samples=MAX_SAMPLES))
    assert report.compared is not None


def test_the_seeds_cover_the_settings() -> None:
    """The fixed seeds reach every size class and shadow/transparency choice they are meant to."""
    cases = [fuzz_case(seed, max_samples=MAX_SAMPLES) for seed in SEEDS]
    sizes = {(c.width, c.height) for c in cases}
    assert any(w * h >= 640 * 480 for w, h in sizes) and any(w * h <= 16 for w, h in sizes)
    assert any(w != h and max(w, h) % 2 for w, h in sizes)  # an odd side
    assert len({c.samples for c in cases}) >= 4
    assert {_forced(seed, "shadows") for seed in SEEDS} >= set(SHADOW_CHOICES)
    assert {_forced(seed, "transparency") for seed in SEEDS} >= set(TRANSPARENCY_CHOICES)
    assert any("fog" in c.options for c in cases) and any("tolerance" in c.options for c in cases)


def test_cases_are_deterministic() -> None:
    a, b = fuzz_case(7), fuzz_case(7)
    assert a.describe() == b.describe()
    for ma, mb in zip(a.scene.meshes, b.scene.meshes, strict=True):
        np.testing.assert_array_equal(ma.positions, mb.positions)


def test_vocabulary() -> None:
    assert (1, 1) in FRAME_SIZES and (1920, 1080) in FRAME_SIZES
    assert set(SAMPLE_COUNTS) == {1, 4, 9, 16, 36}
    for width, height in FRAME_SIZES:
        w, h = downscaled_size(width, height, 3072)
        assert w * h <= 3072 and (w, h) <= (width, height)
        assert abs(w / h - width / height) <= width / height * (1 / min(w, h) + 1e-12)  # aspect to a pixel
    assert downscaled_size(1, 13) == (1, 13)
