"""Compositing a stack of layers, back to front or front to back.

Premultiplied ``over`` is associative (Porter & Duff 1984, §4; Blinn, "Compositing,
Part 1", IEEE CG&A 1994), so a stack ``L[n-1] over … over L[1] over L[0]`` may be
evaluated from either end:

* back to front: ``acc ← L[i] over acc`` for i = 1 … n−1 (the painter's order);
* front to back: ``acc ← acc over L[i]`` for i = n−2 … 0, i.e. the next layer
  goes *under* the accumulated one (Porter-Duff ``dst_over``). Once every pixel
  of ``acc`` is opaque (α ≥ ``opaque_threshold``), nothing behind can show and the
  remaining layers are not even read: the early termination of front-to-back
  volume rendering (Levoy 1990) and ray marching.

With the default threshold 1 both orders agree to rounding; a threshold below 1
trades an error of at most ``1 − threshold`` (times the brightest remaining
layer) for earlier termination.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .operators import composite
from .validate import as_rgba, check_alpha_range

__all__ = ["STACK_ORDERS", "composite_stack", "composite_stack_front_to_back"]

#: Orders ``composite_stack`` accepts.
STACK_ORDERS = ("back_to_front", "front_to_back")


def _check_layers(layers: Sequence[np.ndarray]) -> None:
    if isinstance(layers, np.ndarray) or not isinstance(layers, Sequence) or len(layers) == 0:
        raise TypeError(
            "layers: expected a non-empty sequence (list or tuple) of premultiplied RGBA arrays, "
            f"backmost first; got {type(layers).__name__}"
            + (" (pass list(array) for a stacked array)" if isinstance(layers, np.ndarray) else "")
        )


def _layer(layers: Sequence[np.ndarray], i: int) -> np.ndarray:
    layer = as_rgba(layers[i], f"layers[{i}]")
    check_alpha_range(layer, f"layers[{i}]")
    return layer


def composite_stack_front_to_back(
    layers: Sequence[np.ndarray], *, opaque_threshold: float = 1.0
) -> tuple[np.ndarray, int]:
    """Front-to-back ``over`` of ``layers`` (``layers[0]`` backmost) with early termination.

    ``acc ← acc over L[i]`` (Porter-Duff ``dst_over``) from the front layer back, stopping
    once every pixel has ``α ≥ opaque_threshold``. Equal to back-to-front ``over`` because
    premultiplied ``over`` is associative (Porter & Duff 1984, §4; Blinn, "Compositing,
    Part 1", IEEE CG&A 1994); the early termination is that of front-to-back volume
    rendering (Levoy, "Efficient ray tracing of volume data", ACM TOG 9(3), 1990).

    Args:
        layers: premultiplied linear RGBA arrays ``(..., 4)`` that broadcast together,
            float32 or float64, alpha in [0, 1], backmost first.
        opaque_threshold: alpha in (0, 1] at which a pixel counts as opaque. With 1 the
            result equals back to front up to rounding; below 1 the error is at most
            ``1 − opaque_threshold`` times the brightest layer not read.

    Returns:
        ``(image, used)``: the composite (premultiplied RGBA of the broadcast shape) and how
        many layers were read (fewer than ``len(layers)`` when the accumulated alpha
        saturated first).
    """
    _check_layers(layers)
    if not 0.0 < opaque_threshold <= 1.0:
        raise ValueError(f"opaque_threshold: expected a number in (0, 1], got {opaque_threshold!r}")
    acc = np.array(_layer(layers, len(layers) - 1), copy=True)
    used = 1
    for i in range(len(layers) - 2, -1, -1):
        if bool((acc[..., 3] >= opaque_threshold).all()):
            break
        acc = composite(_layer(layers, i), acc, "dst_over")
        used += 1
    return acc, used


def composite_stack(
    layers: Sequence[np.ndarray], order: str = "back_to_front", *, opaque_threshold: float = 1.0
) -> np.ndarray:
    """Composite premultiplied layers with ``over``; ``layers[0]`` is the backmost.

    Args:
        layers: premultiplied linear RGBA arrays ``(..., 4)`` that broadcast
            together, alpha in [0, 1], backmost first.
        order: ``"back_to_front"`` or ``"front_to_back"`` (stops once every pixel
            is opaque, see :func:`composite_stack_front_to_back`). Both give the same
            image up to float rounding.
        opaque_threshold: front to back only: alpha at which a pixel counts as opaque.

    Returns:
        The composite, premultiplied RGBA of the broadcast shape.
    """
    _check_layers(layers)
    if order not in STACK_ORDERS:
        raise ValueError(f"order: expected one of {STACK_ORDERS}, got {order!r}")
    if order == "front_to_back":
        return composite_stack_front_to_back(layers, opaque_threshold=opaque_threshold)[0]
    acc = np.array(_layer(layers, 0), copy=True)
    for i in range(1, len(layers)):
        acc = composite(_layer(layers, i), acc, "src_over")
    return acc
