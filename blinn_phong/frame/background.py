"""The world behind a frame, as Blender's engines show it with an opaque film (Film → Transparent
off): an opaque world colour composited behind every part of each pixel that is neither covered
nor held out. Where a holdout is seen the pixel stays transparent black, as in Cycles.

The held-out share of each pixel is measured with the frame's own Cryptomatte coverage
(:mod:`blinn_phong.frame.id_passes`): coverage is the share of a pixel's samples that a mesh's
fragments take after the transparent fragments in front of them (``αᵢ·∏(1 − αⱼ)``,
``docs/compositor_passes.md``), so the coverage of the holdout meshes is exactly the part of the
pixel where a holdout is seen. Arrays are float32, premultiplied RGBA, row 0 at the top.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from blinn_phong.frame.id_passes import Cryptomatte
from compositing.cryptomatte import pass_names

__all__ = ["HOLDOUT_NAME", "HoldoutRequest", "holdout_coverage", "holdout_request", "world_behind"]


HOLDOUT_NAME = "holdout"
"""The Cryptomatte name that :func:`holdout_request` gives every holdout mesh (when a layer of the
request is its own)."""


@dataclasses.dataclass(frozen=True)
class HoldoutRequest:
    """A Cryptomatte request that also measures each pixel's held-out coverage (:func:`holdout_request`).

    Attributes:
        request: the render's request: the caller's layers, and ``layer`` when it is not one of them.
        layer: the layer type whose coverages are read.
        ids: the Cryptomatte IDs (float32) of that layer that belong to holdout meshes.
        extra_passes: pass names made for the measurement only (removed from the result).
    """

    request: Cryptomatte
    layer: str
    ids: np.ndarray
    extra_passes: tuple[str, ...]


def holdout_request(meshes: Any, cryptomatte: Cryptomatte | None) -> HoldoutRequest:
    """The Cryptomatte request that measures the held-out coverage of each pixel of a frame of
    ``meshes`` (``Scene.meshes``), on top of the caller's ``cryptomatte`` (or None).

    Cryptomatte coverage is the share of a pixel's samples that a mesh's fragments take after
    the transparent fragments in front of them (``αᵢ·∏(1 − αⱼ)``, ``docs/compositor_passes.md``),
    so the coverage of the holdout meshes is exactly the part of the pixel where a holdout is
    seen. A layer type the caller does not ask for names every holdout mesh :data:`HOLDOUT_NAME`
    and every other mesh ``""`` (two IDs; levels at least 2, so every ID of every pixel is kept: a
    caller's request of one level gets its second pair filled too); when the
    caller asks for all three, its object layer is read instead (the IDs of the holdout objects'
    names; exact when its levels hold every object of the pixel).
    """
    flags = [bool(m.holdout) for m in meshes]
    requested = dict(cryptomatte.names) if cryptomatte is not None else {}
    free = [layer for layer in ("asset", "material", "object") if layer not in requested]
    if free:
        layer = free[0]
        names = [HOLDOUT_NAME if held else "" for held in flags]
        levels = cryptomatte.levels if cryptomatte is not None else 2
        request = Cryptomatte({**requested, layer: names}, max(2, levels))
        extra = tuple(pass_names(layer, request.levels))
        ids = request.ids(layer)[np.array(flags, bool)][:1]
        return HoldoutRequest(request, layer, ids, extra)
    assert cryptomatte is not None
    ids = np.unique(cryptomatte.ids("object")[np.array(flags, bool)])
    return HoldoutRequest(cryptomatte, "object", ids, ())


def holdout_coverage(passes: dict[str, np.ndarray], holdout: HoldoutRequest) -> np.ndarray:
    """(H, W) float32: the coverage of the holdout meshes in each pixel, read from the Cryptomatte
    passes of ``holdout.layer`` (pairs ``(id, coverage)``); the measurement's own passes are removed
    from ``passes``."""
    names = pass_names(holdout.layer, holdout.request.levels)
    first = passes[names[0]]
    held = np.zeros(first.shape[:2], np.float32)
    for name in names:
        rank = passes[name]
        for pair in (0, 2):
            mine = np.isin(rank[..., pair], holdout.ids)
            held += np.where(mine, rank[..., pair + 1], 0.0).astype(np.float32)
    for name in holdout.extra_passes:
        passes.pop(name, None)
    return held


def world_behind(rgba: np.ndarray, world: np.ndarray, held: np.ndarray) -> np.ndarray:
    """``rgba`` (premultiplied, (H, W, 4)) with the opaque ``world`` colour behind it where no holdout
    is seen: ``rgba + world · (1 − α − held)`` (Porter & Duff's ``over`` on the part of each pixel
    neither covered nor held out; ``held`` (H, W) from :func:`holdout_coverage`).

    ``1 − α − held`` is the pixel's share that saw nothing; float rounding of the coverage sums
    can leave it a few ulps below 0, which is taken as 0.
    """
    open_share = np.maximum(1.0 - rgba[..., 3] - held, 0.0).astype(np.float32)
    return (rgba + world[None, None, :] * open_share[..., None]).astype(np.float32)
