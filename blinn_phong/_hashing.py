"""Integer hashing shared by the mesh facts and the shadow volumes: one splitmix64 mixer, one hash weld.

* :func:`splitmix64` — the finaliser of Steele, Lea & Flood's SplitMix64 generator ("Fast
  splittable pseudorandom number generators", OOPSLA 2014; the constants of Vigna's
  ``splitmix64.c``), on uint64 with wrapping arithmetic. Written once, as plain arithmetic, it
  runs on numpy uint64 arrays (the numpy engine) and, compiled, as :func:`mix` (inlined into the
  kernels that call it).
* :func:`weld_rows` — merge equal rows of an (m, 3) integer array with an open-addressing hash
  table (linear probing over :func:`mix` of the three entries): the distinct rows in order of
  first occurrence, without a sort. Used by :mod:`blinn_phong.geometry._mesh_kernels` (vertices in one
  grid cell) and :mod:`blinn_phong.shadows.volume_mesh` (bit-identical float64 positions).

The compiled functions live at module level (numba's disk cache keys a closure's functions by
their pickled cells, which differ from one process to the next) and exist only when numba
imports; :func:`splitmix64` always does.
"""

from __future__ import annotations

import numpy as np

__all__ = ["mix", "splitmix64", "weld_rows"]


def splitmix64(z):  # type: ignore[no-untyped-def]  # numpy uint64 array or scalar; numba uint64
    """SplitMix64's finaliser of uint64 ``z`` (wrapping arithmetic): a bijection that spreads every
    input bit over the output."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


try:
    import numba
except Exception:  # the numpy engine only: no compiled twins
    numba = None

if numba is not None:
    #: :func:`splitmix64` compiled, inlined where it is called.
    mix = numba.njit(inline="always", cache=True)(splitmix64)

    @numba.njit(inline="always", cache=True)
    def weld_rows(rows):  # pragma: no cover - compiled
        """Equal rows of (m, 3) integer ``rows`` merged: ``(first, label)``, ``first[k]`` the first
        row of the k-th distinct row (in order of first occurrence), ``label[r]`` the distinct row
        of row ``r``."""
        m = rows.shape[0]
        size = 1
        while size < 2 * m:
            size *= 2
        table = np.full(size, -1, np.int64)
        label = np.empty(m, np.int64)
        first = np.empty(m, np.int64)
        n = 0
        for r in range(m):
            h = np.uint64(0)
            for c in range(3):
                h = mix(np.uint64(rows[r, c]) ^ h)
            slot = np.int64(h & np.uint64(size - 1))
            while True:
                u = table[slot]
                if u < 0:
                    table[slot] = n
                    first[n] = r
                    label[r] = n
                    n += 1
                    break
                q = first[u]
                if rows[q, 0] == rows[r, 0] and rows[q, 1] == rows[r, 1] and rows[q, 2] == rows[r, 2]:
                    label[r] = u
                    break
                slot = (slot + 1) & (size - 1)
        return first[:n].copy(), label

else:
    mix = None
    weld_rows = None
