"""Reusable scratch memory for per-frame work arrays.

Some frame stages need large work arrays of which they write only a part (the shadow-map
set-up's per-triangle records: a slot per triangle and face, most of them never drawn). A
fresh ``np.empty`` of hundreds of megabytes costs a page fault for every page written, and on
Linux numpy asks for transparent huge pages, whose first faults may stall in memory
compaction (tens of milliseconds in the first frames of a process). A :class:`ScratchPool`
hands out a buffer kept from an earlier frame instead: its pages are already mapped. Only
buffers up to a byte limit are kept, and at most ``keep`` of them, so the memory a pool holds
between frames is bounded.
"""

from __future__ import annotations

import contextlib
import threading
import weakref
from collections.abc import Iterator

import numpy as np

__all__ = ["ScratchPool", "carve", "carved_bytes", "release_scratch"]

#: Every pool of the process (weakly), for :func:`release_scratch`.
_POOLS: weakref.WeakSet[ScratchPool] = weakref.WeakSet()


def release_scratch() -> int:
    """Free the scratch memory every pool keeps between frames (e.g. after the last render of a
    batch, in a long-lived process). Returns the bytes released; the next frame allocates anew."""
    return sum(pool.clear() for pool in list(_POOLS))


class ScratchPool:
    """A thread-safe pool of reusable byte buffers.

    Args:
        max_bytes: the largest buffer kept for reuse (bigger ones are freed after use).
        keep: how many free buffers are kept at most.
    """

    def __init__(self, max_bytes: int, keep: int = 1) -> None:
        if max_bytes < 0 or keep < 0:
            raise ValueError(f"max_bytes and keep must be >= 0, got {max_bytes}, {keep}")
        self.max_bytes = int(max_bytes)
        self.keep = int(keep)
        self._free: list[np.ndarray] = []
        self._lock = threading.Lock()
        _POOLS.add(self)

    @contextlib.contextmanager
    def bytes(self, n: int) -> Iterator[np.ndarray]:
        """A (n,) uint8 buffer of unspecified content for the ``with`` block (8-byte aligned)."""
        with self._lock:
            fits = [i for i, b in enumerate(self._free) if len(b) >= n]
            buf = self._free.pop(fits[0]) if fits else None
        if buf is None:
            buf = np.empty(max(int(n), 8), np.uint8)
        try:
            yield buf[:n]
        finally:
            if len(buf) <= self.max_bytes:
                with self._lock:
                    self._free.append(buf)
                    self._free.sort(key=len, reverse=True)
                    del self._free[self.keep :]

    def clear(self) -> int:
        """Free every kept buffer; returns their bytes."""
        with self._lock:
            freed = sum(len(b) for b in self._free)
            self._free.clear()
        return freed


def carve(buf: np.ndarray, *parts: tuple[tuple[int, ...], type]) -> list[np.ndarray]:
    """Consecutive C-contiguous arrays of the given (shape, dtype) laid out in ``buf`` (uint8),
    each starting at a multiple of 8 bytes."""
    out = []
    at = 0
    for shape, dtype in parts:
        size = int(np.prod(shape)) * np.dtype(dtype).itemsize
        out.append(buf[at : at + size].view(dtype).reshape(shape))
        at += -(-size // 8) * 8
    if at > len(buf):
        raise ValueError(f"buf: {len(buf)} bytes, the parts need {at}")
    return out


def carved_bytes(*parts: tuple[tuple[int, ...], type]) -> int:
    """The bytes :func:`carve` needs for ``parts``."""
    return sum(-(-int(np.prod(s)) * np.dtype(d).itemsize // 8) * 8 for s, d in parts)
