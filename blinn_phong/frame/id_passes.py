"""Cryptomatte passes from the renderer's own samples (:mod:`compositing.cryptomatte` holds the format).

A :class:`Cryptomatte` request names every mesh of the scene in each layer (object, material,
asset: the names Blender uses, see :mod:`addon.convert`) and gives the number of levels. The
frame's visibility stage already knows the surface of every sample of the supersampling grid;
the passes are computed from that, never from a second rasterization:

* each sample of the k×k grid is ``1/k²`` of its pixel;
* an opaque sample belongs wholly to the mesh of its nearest fragment;
* transparent fragments in front of it (transparency methods other than the plain z-buffer)
  share the sample front to back as Porter–Duff *over* shares it: the i-th fragment from the
  eye gets ``αᵢ·∏ⱼ₍ⱼ<ᵢ₎(1 − αⱼ)`` and the opaque one what is left, ``∏(1 − αⱼ)`` (Cycles'
  Cryptomatte accumulates the same per-path weights). ``α`` is the material's opacity (0 for
  the emission model, which hides nothing); a texture's alpha or Kay–Greenberg opacity is not
  looked up (such fragments count with ``Material.opacity``);
* under the plain z-buffer (every fragment opaque) a sample's nearest fragment weighs its
  material's opacity, as the frame's alpha does.

So with opaque surfaces the coverages of a pixel sum exactly to its alpha (the covered
fraction of its samples) when the levels hold every ID in the pixel. IDs of one name (an
object split into one mesh per material) add up in the same entry.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from compositing.cryptomatte import (
    DEFAULT_LEVELS,
    LAYER_TYPES,
    coverage_passes,
    layer_metadata,
    name_id,
    pass_names,
)

__all__ = ["Cryptomatte", "passes_from_fragments", "passes_from_winners"]


@dataclass(frozen=True)
class Cryptomatte:
    """What Cryptomatte passes a render makes.

    Attributes:
        names: per layer type (``"object"``, ``"material"``, ``"asset"``: any subset, at least
            one), one name per entry of ``Scene.meshes`` (the same length and order).
        levels: ``(id, coverage)`` pairs kept per pixel, 1 … 16 (Blender's default 6); each
            layer gets ``ceil(levels / 2)`` RGBA passes ``Crypto<Type>00`` … in
            ``RenderResult.passes``.
    """

    names: Mapping[str, Sequence[str]]
    levels: int = DEFAULT_LEVELS
    _ids: dict[str, np.ndarray] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.names, Mapping) or not self.names:
            raise ValueError(
                f"Cryptomatte.names: expected a non-empty mapping of layer type ({sorted(LAYER_TYPES)}) "
                f"to one name per mesh, got {self.names!r}"
            )
        names: dict[str, tuple[str, ...]] = {}
        for layer, values in self.names.items():
            if layer not in LAYER_TYPES:
                raise ValueError(
                    f"Cryptomatte.names: unknown layer type {layer!r}; expected {sorted(LAYER_TYPES)}"
                )
            if isinstance(values, str) or not all(isinstance(v, str) for v in values):
                raise TypeError(f"Cryptomatte.names[{layer!r}]: expected a sequence of str (one per mesh)")
            names[layer] = tuple(values)
        if len({len(v) for v in names.values()}) != 1:
            raise ValueError(
                "Cryptomatte.names: every layer needs one name per mesh, got lengths "
                f"{ {k: len(v) for k, v in names.items()} }"
            )
        pass_names(next(iter(names)), self.levels)  # checks levels
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "levels", int(self.levels))
        for layer, values in names.items():
            self._ids[layer] = np.array([name_id(n) for n in values], np.float32)

    @property
    def mesh_count(self) -> int:
        """The number of meshes the names are for."""
        return len(next(iter(self.names.values())))

    def subset(self, keep: Sequence[bool]) -> Cryptomatte:
        """The request for the meshes where ``keep`` is True (the render drops empty meshes)."""
        return Cryptomatte(
            {k: [n for n, kept in zip(v, keep, strict=True) if kept] for k, v in self.names.items()},
            self.levels,
        )

    def ids(self, layer: str) -> np.ndarray:
        """(M,) float32 Cryptomatte ID of each mesh in ``layer``."""
        return self._ids[layer]

    def pass_names(self) -> list[str]:
        """Every pass the request makes, layer by layer."""
        return [p for layer in self.names for p in pass_names(layer, self.levels)]

    def metadata(self, view_layer: str = "ViewLayer") -> dict[str, str]:
        """The header entries of every layer (:func:`compositing.cryptomatte.layer_metadata`);
        the manifests list each layer's names in mesh order."""
        out: dict[str, str] = {}
        for layer, values in self.names.items():
            out.update(layer_metadata(view_layer, layer, values))
        return out


def _passes(
    request: Cryptomatte, pixel: np.ndarray, mesh: np.ndarray, weight: np.ndarray, height: int, width: int
) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for layer in request.names:
        passes = coverage_passes(pixel, request.ids(layer)[mesh], weight, (height, width), request.levels)
        out.update(zip(pass_names(layer, request.levels), passes, strict=True))
    return out


def passes_from_winners(
    request: Cryptomatte,
    winner: np.ndarray,
    source: np.ndarray,
    triangle_mesh: np.ndarray,
    height: int,
    width: int,
) -> dict[str, np.ndarray]:
    """The passes of an opaque one-sample frame from the z-buffer's winners.

    Args:
        request: the :class:`Cryptomatte` request (for the prepared scene's meshes).
        winner: (H·W,) int64 sub-triangle nearest at each pixel, −1 where none
            (:func:`blinn_phong.geometry.raster_kernels.nearest_winners_compiled`).
        source: (S,) int64 prepared triangle of each sub-triangle (the set-up's ``source``).
        triangle_mesh: (T,) int64 mesh of each prepared triangle.
        height: image height.
        width: image width.
    """
    # One surface per pixel, coverage 1: each layer's first pass holds (ID, 1) where covered and
    # zeros elsewhere (what coverage_passes gives for these entries, without ranking or
    # scattering); the other passes are zeros. Every pass lies in one allocation: at this size a
    # fresh mapping whose pages stay zero until written (a frame-sized array would often reuse
    # freed memory, cleared byte by byte).
    layers = {layer: pass_names(layer, request.levels) for layer in request.names}
    block = np.zeros((sum(map(len, layers.values())), height, width, 4), np.float32)
    first = np.cumsum([0] + [len(names) for names in layers.values()])[:-1].astype(np.int64)
    tables = np.array([request.ids(layer) for layer in layers], np.float32).reshape(len(layers), -1)
    sub_mesh = np.ascontiguousarray(triangle_mesh[source], dtype=np.int64)
    winner = np.ascontiguousarray(winner, dtype=np.int64)
    from compositing._threads import in_shares

    in_shares(_winner_ids_kernel(), height, width, winner, sub_mesh, tables, first, block)
    out: dict[str, np.ndarray] = {}
    for start, names in zip(first, layers.values(), strict=True):
        out.update(zip(names, block[start : start + len(names)], strict=True))
    return out


@functools.lru_cache(maxsize=1)
def _winner_ids_kernel() -> object:  # a numba dispatcher
    """``kernel(rows, width, winner, sub_mesh, tables, first, block)``: for the pixels of ``rows``
    covered by a winner, each layer's ID of the winner's mesh and coverage 1 into the layer's
    first pass (``block[first[layer]]``); a serial loop on shares of rows (nogil)."""
    import numba

    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def winner_ids(rows, width, winner, sub_mesh, tables, first, block):  # pragma: no cover - compiled
        for row in rows:
            for col in range(width):
                o = winner[row * width + col]
                if o < 0:
                    continue
                mesh = sub_mesh[o]
                for layer in range(tables.shape[0]):
                    block[first[layer], row, col, 0] = tables[layer, mesh]
                    block[first[layer], row, col, 1] = 1.0

    return winner_ids


def passes_from_fragments(
    request: Cryptomatte, prepared: object, visible: object, method: str
) -> dict[str, np.ndarray]:
    """The passes from a frame's visible fragments (:class:`blinn_phong.frame.visibility.FrameFragments`).

    Args:
        request: the :class:`Cryptomatte` request.
        prepared: the frame's :class:`blinn_phong.frame.prepared.PreparedScene`.
        visible: its visible fragments.
        method: the frame's transparency method (``"zbuffer"``: each sample's nearest fragment
            weighs its material's opacity; otherwise the front-to-back shares of the module
            docstring).
    """
    from blinn_phong.frame.resolve import fragment_side, side_tables

    f = visible.fragments  # type: ignore[attr-defined]
    samples, height, width = f.samples, f.height, f.width
    materials, _ = side_tables(prepared.scene)  # type: ignore[attr-defined]
    side_alpha = np.array(
        [0.0 if m.transparency_model == "emission" else m.opacity for m in materials], np.float64
    )
    n_op = visible.n_opaque  # type: ignore[attr-defined]
    opaque = np.arange(n_op)
    keys = f.sample_key
    share = 1.0 / samples
    if method == "zbuffer" or len(f) == n_op:
        alpha = side_alpha[fragment_side(prepared, f.triangle[opaque], f.front_facing[opaque])]
        weight = share * (alpha if method == "zbuffer" else np.ones(n_op))
        index = opaque
    else:
        # transparent fragments of each sample, front to back
        t = np.arange(n_op, len(f))
        t = t[np.lexsort((f.depth[t], keys[t]))]
        t_keys = keys[t]
        t_alpha = side_alpha[fragment_side(prepared, f.triangle[t], f.front_facing[t])]
        start = np.r_[True, t_keys[1:] != t_keys[:-1]] if len(t) else np.zeros(0, bool)
        first = np.maximum.accumulate(np.where(start, np.arange(len(t)), 0)) if len(t) else start
        position = np.arange(len(t)) - first
        transmit = np.ones(len(t))  # ∏ (1 − α) of the fragments in front of each
        for p in range(1, int(position.max()) + 1 if len(t) else 1):
            at = np.flatnonzero(position == p)
            transmit[at] = transmit[at - 1] * (1.0 - t_alpha[at - 1])
        t_weight = share * t_alpha * transmit
        # what reaches each sample's opaque fragment: the transmittance after the last transparent one
        last = np.r_[start[1:], True] if len(t) else start
        behind_keys = t_keys[last]
        behind = transmit[last] * (1.0 - t_alpha[last])
        o_keys = keys[opaque]  # increasing
        o_weight = np.full(n_op, share)
        at = np.searchsorted(o_keys, behind_keys)
        hit = at < n_op
        hit[hit] = o_keys[at[hit]] == behind_keys[hit]
        o_weight[at[hit]] = share * behind[hit]
        index = np.concatenate([opaque, t])
        weight = np.concatenate([o_weight, t_weight])
    mesh = prepared.triangle_mesh[f.triangle[index]]  # type: ignore[attr-defined]
    pixel = keys[index] // samples
    return _passes(request, pixel, mesh, weight, height, width)
