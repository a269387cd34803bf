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

8-bit straight-alpha layers (``uint8``, as read from a PNG or an RGBA8 framebuffer) are
composited back to front as an RGBA8 straight-alpha buffer stores them: each layer and the
stored value are premultiplied, combined with ``over``, unpremultiplied (α = 0 keeps the
colour) and stored back rounded to the nearest 8-bit value (the arithmetic in float32). That
is what a chain of Pillow ``Image.alpha_composite`` calls computes, up to Pillow's own
fixed-point rounding of each step. That buffer has one order, so both ``order`` values give
this image.

Two engines compute the same values: the compiled one (:mod:`compositing._stack_fused`, the
whole stack in one pass per tile of pixels, front to back stopping per tile where alpha
saturates) and the numpy reference (one :func:`compositing.composite` per layer). Back to
front, the compiled engine first looks, per tile, for the frontmost layer that is opaque
(α = 1, or 255) on every pixel of the tile and starts there: ``over`` onto anything gives
that layer exactly, so the layers behind it are not read (nor checked). It is equal to the
reference for back to front (bitwise, but for the sign of a zero); front to back stops per
tile instead of for the whole image, which with the default threshold gives equal values.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ._engine import ENGINES, use_compiled
from .operators import composite
from .validate import as_rgba, check_alpha_range, check_finite

__all__ = ["STACK_ENGINES", "STACK_ORDERS", "composite_stack", "composite_stack_front_to_back"]

#: Orders ``composite_stack`` accepts.
STACK_ORDERS = ("back_to_front", "front_to_back")

#: Engines ``composite_stack`` accepts (:data:`compositing._engine.ENGINES`).
STACK_ENGINES = ENGINES

_UNORM8_MAX = np.float32(255.0)


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


def _arrays(layers: Sequence[np.ndarray]) -> tuple[list[np.ndarray], tuple[int, ...], bool]:
    """The layers as arrays (shape and dtype checked, values not yet), their broadcast shape, and
    whether they are 8-bit straight (uint8). Errors name the layer (``layers[2]``)."""
    arrays: list[np.ndarray] = []
    for i, layer in enumerate(layers):
        name = f"layers[{i}]"
        if isinstance(layer, np.ndarray) and layer.dtype == np.uint8:
            if layer.ndim == 0 or layer.shape[-1] != 4:
                raise ValueError(
                    f"{name}: expected RGBA in the last axis, shape (..., 4); got shape {layer.shape}"
                )
            arrays.append(layer)
        else:
            arrays.append(as_rgba(layer, name, check_values=False))
    straight8 = [a.dtype == np.uint8 for a in arrays]
    if any(straight8) and not all(straight8):
        i = straight8.index(not straight8[0])
        raise TypeError(
            f"layers[{i}]: expected dtype {arrays[0].dtype} like layers[0] (a stack is either 8-bit straight "
            f"uint8 or premultiplied float); got {arrays[i].dtype}"
        )
    shape = arrays[0].shape
    for i, a in enumerate(arrays[1:], start=1):
        try:
            shape = np.broadcast_shapes(shape, a.shape)
        except ValueError:
            raise ValueError(
                f"layers[{i}]: shape {a.shape} does not broadcast with the layers before it "
                f"(layers[0] to layers[{i - 1}] broadcast to {shape})"
            ) from None
    return arrays, shape, all(straight8)


def _fused(
    arrays: list[np.ndarray], shape: tuple[int, ...], kind: str, threshold: float, straight8: bool
) -> tuple[np.ndarray, int]:
    """The compiled stack on same-shape, same-dtype, C-contiguous layers; exact checks when flagged."""
    from ._stack_fused import stack_fused

    dtype = np.dtype(np.uint8) if straight8 else np.result_type(*arrays)
    ready = [
        a
        if a.shape == shape and a.dtype == dtype and a.flags.c_contiguous
        else np.ascontiguousarray(np.broadcast_to(a.astype(dtype, copy=False), shape))
        for a in arrays
    ]
    out, read, suspicious = stack_fused(ready, "straight8" if straight8 else kind, threshold)
    if suspicious:  # the pass flags; the exact checks name the layer
        front_to_back = kind == "front_to_back"
        checked = range(len(arrays) - 1, len(arrays) - 1 - read, -1) if front_to_back else range(len(arrays))
        for i in checked:
            check_finite(arrays[i], f"layers[{i}]")
            check_alpha_range(arrays[i], f"layers[{i}]")
        if not np.isfinite(out).all():
            raise ValueError(
                f"the stack overflowed {out.dtype}; the layers' colours are too large for this dtype"
            )
    return out, read


def composite_stack_front_to_back(
    layers: Sequence[np.ndarray], *, opaque_threshold: float = 1.0, engine: str = "auto"
) -> tuple[np.ndarray, int]:
    """Front-to-back ``over`` of ``layers`` (``layers[0]`` backmost) with early termination.

    ``acc ← acc over L[i]`` (Porter-Duff ``dst_over``) from the front layer back, stopping
    once every pixel has ``α ≥ opaque_threshold``. Equal to back-to-front ``over`` because
    premultiplied ``over`` is associative (Porter & Duff 1984, §4; Blinn, "Compositing,
    Part 1", IEEE CG&A 1994); the early termination is that of front-to-back volume
    rendering (Levoy, "Efficient ray tracing of volume data", ACM TOG 9(3), 1990). The
    compiled engine stops per tile of pixels (a tile whose pixels are all opaque reads no
    further layer); the numpy engine stops for the whole image.

    Args:
        layers: premultiplied linear RGBA arrays ``(..., 4)`` that broadcast together,
            float32 or float64, alpha in [0, 1], backmost first (8-bit straight ``uint8``
            layers give the image of :func:`composite_stack`, whose buffer has one order).
        opaque_threshold: alpha in (0, 1] at which a pixel counts as opaque. With 1 the
            result equals back to front up to rounding; below 1 the error is at most
            ``1 − opaque_threshold`` times the brightest layer not read.
        engine: ``"auto"`` (compiled when numba is installed), ``"numba"`` or ``"numpy"``.

    Returns:
        ``(image, used)``: the composite (premultiplied RGBA of the broadcast shape) and how
        many layers were read (fewer than ``len(layers)`` when the accumulated alpha
        saturated first). The compiled engine reports the most any tile read; it reads
        layers two at a time, so a tile may read one layer past the point where it became
        opaque (with the default threshold that layer changes no value).
    """
    _check_layers(layers)
    if not 0.0 < opaque_threshold <= 1.0:
        raise ValueError(f"opaque_threshold: expected a number in (0, 1], got {opaque_threshold!r}")
    if use_compiled(engine):
        arrays, shape, straight8 = _arrays(layers)
        # 8-bit straight layers: the RGBA8 buffer's order (back to front from the frontmost
        # opaque layer of each tile) is the only one with that buffer's rounding.
        return _fused(arrays, shape, "front_to_back", opaque_threshold, straight8)
    arrays, shape, straight8 = _arrays(layers)
    if straight8:
        return _straight8_numpy(arrays, shape), len(layers)
    acc = np.array(np.broadcast_to(_layer(layers, len(layers) - 1), shape), copy=True)
    used = 1
    for i in range(len(layers) - 2, -1, -1):
        if bool((acc[..., 3] >= opaque_threshold).all()):
            break
        acc = composite(_layer(layers, i), acc, "dst_over", engine="numpy")
        used += 1
    return acc, used


def composite_stack(
    layers: Sequence[np.ndarray],
    order: str = "back_to_front",
    *,
    opaque_threshold: float = 1.0,
    engine: str = "auto",
) -> np.ndarray:
    """Composite layers with ``over``; ``layers[0]`` is the backmost.

    Args:
        layers: premultiplied linear RGBA arrays ``(..., 4)`` that broadcast together,
            float32 or float64, alpha in [0, 1], backmost first; or 8-bit straight-alpha
            RGBA ``uint8`` arrays (all of them), composited as an RGBA8 straight buffer
            stores them (see the module docstring; both orders give that image).
        order: ``"back_to_front"`` or ``"front_to_back"`` (stops once every pixel
            is opaque, see :func:`composite_stack_front_to_back`). Both give the same
            image up to float rounding.
        opaque_threshold: front to back only: alpha at which a pixel counts as opaque.
        engine: ``"auto"`` (the compiled one-pass-per-tile engine when numba is installed),
            ``"numba"`` or ``"numpy"`` (one ``composite`` per layer, the reference).

    Returns:
        The composite of the broadcast shape: premultiplied RGBA in the layers' float dtype,
        or 8-bit straight RGBA (``uint8``) for ``uint8`` layers.

    Raises:
        TypeError: not a sequence of arrays, a dtype other than float32/float64/uint8, or
            uint8 layers mixed with float ones (the message names the layer).
        ValueError: unknown order or engine, a layer whose shape does not broadcast with the
            ones before it, NaN/Inf or an alpha outside [0, 1] (the message names the layer).
    """
    _check_layers(layers)
    if order not in STACK_ORDERS:
        raise ValueError(f"order: expected one of {STACK_ORDERS}, got {order!r}")
    if order == "front_to_back":
        return composite_stack_front_to_back(layers, opaque_threshold=opaque_threshold, engine=engine)[0]
    fused = use_compiled(engine)
    arrays, shape, straight8 = _arrays(layers)
    if straight8 and not fused:
        return _straight8_numpy(arrays, shape)
    if fused:
        return _fused(arrays, shape, "back_to_front", 1.0, straight8)[0]
    acc = np.array(np.broadcast_to(_layer(layers, 0), shape), copy=True)
    for i in range(1, len(layers)):
        acc = composite(_layer(layers, i), acc, "src_over", engine="numpy")
    return acc


def _straight8_numpy(arrays: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    """Reference for 8-bit straight layers: premultiply, ``over``, unpremultiply, store 8 bits, in float32."""
    acc = np.broadcast_to(arrays[0], shape).astype(np.float32) / _UNORM8_MAX
    for layer in arrays[1:]:
        straight = layer.astype(np.float32) / _UNORM8_MAX
        src = straight.copy()
        src[..., :3] *= straight[..., 3:]
        dst = acc.copy()
        dst[..., :3] *= acc[..., 3:]
        over = composite(src, dst, "src_over", engine="numpy")
        alpha = over[..., 3:]
        over[..., :3] /= np.where(alpha == 0, np.float32(1.0), alpha)
        acc = np.rint(np.clip(over, 0.0, 1.0) * _UNORM8_MAX) / _UNORM8_MAX
    return np.rint(acc * _UNORM8_MAX).astype(np.uint8)
