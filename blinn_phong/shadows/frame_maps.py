"""A frame's shadow maps, stacked for the look-up inside the fused shading kernel (compiled).

When every shadowed light of an opaque one-sample frame uses a shadow map, the fused kernel
(:func:`blinn_phong.frame.fused.shade_plain_winners_compiled`) looks each pixel's world point up in
the maps as it shades it (:func:`blinn_phong.shadows.map_lookup_kernels.visibility_at`), so the frame
needs no world-point array and no visibility array. The maps must exist first, without the
points:

* a single map (directional light, narrow spot) is rendered whole, as always;
* a cube (point light) is rendered only over the texels the visible triangles can be looked
  up in (:func:`blinn_phong.shadows.map_receiver_kernels.receiver_triangle_rects`: each visible triangle's
  part in each face's cone, projected) — a bound from the z-buffer's winning triangles, found
  in one pass over the winners (:func:`visible_triangles`), instead of from the points.

A texel's depth is a minimum over the casters that cover it, so it does not depend on which
other texels are rendered: every texel a look-up reads holds the value of the complete map,
and the visibilities are those of :func:`blinn_phong.shadows.methods.light_visibility` at the
points :func:`blinn_phong.geometry.raster_kernels.winner_surfaces_compiled` computes, bit for bit
(``tests/effects/test_frame_maps.py``).
"""

from __future__ import annotations

import contextlib
import inspect
from collections.abc import Iterator
from typing import NamedTuple

import numba
import numpy as np

from blinn_phong._scratch import ScratchPool, carve
from blinn_phong.shadows.map_lookup_kernels import KERNEL_CODES
from blinn_phong.shadows.map_receiver_kernels import receiver_triangle_rects
from blinn_phong.shadows.map_render_kernels import _full_rects, _render_maps
from blinn_phong.shadows.maps import PCF_KERNELS, map_matrices
from blinn_phong.shadows.methods import light_visibility

__all__ = ["MAP_PARAMETERS", "MapStack", "frame_maps", "no_maps", "visible_triangles"]

#: The shadow-map options of :func:`blinn_phong.shadows.methods.light_visibility` a frame's lights set
#: (:class:`blinn_phong.planning.frame_plan.ShadowOptions`: no normal offset), and their defaults.
MAP_PARAMETERS: dict[str, object] = {
    name: inspect.signature(light_visibility).parameters[name].default
    for name in ("resolution", "constant_bias", "slope_bias", "kernel")
}


class MapStack(NamedTuple):
    """Every light's shadow map(s) in one stack, as the fused kernel reads them.

    ``depth`` (F, R, R) float64 window depths (texels no look-up reads are left unwritten);
    ``view_projection`` (F, 4, 4) world → clip; ``view_z`` (F, 3) row 2 of each world → light-eye
    matrix; per non-ambient light (L): ``first`` (L,) int64 its first map in the stack (−1: no
    shadow), ``faces`` (L,) int64 1 or 6, ``light_position`` (L, 3) (a cube's light),
    ``kernel`` (L,) int64 codes of :data:`blinn_phong.shadows.map_lookup_kernels.KERNEL_CODES`;
    ``rects`` (F, 4) int64 each map's rendered texels ``(r0, r1, c0, c1)``; ``miss`` (1,) int64,
    set to 1 by a look-up whose taps leave them (a point farther off its triangle than the
    bound allows: the frame is then shaded again by the general path). Look-ups take no
    normal offset.
    """

    depth: np.ndarray
    view_projection: np.ndarray
    view_z: np.ndarray
    first: np.ndarray
    faces: np.ndarray
    light_position: np.ndarray
    kernel: np.ndarray
    rects: np.ndarray
    miss: np.ndarray


def no_maps() -> MapStack:
    """The empty stack (no look-up in the kernel)."""
    return MapStack(
        np.zeros((0, 1, 1)), np.zeros((0, 4, 4)), np.zeros((0, 3)), np.zeros(0, np.int64),
        np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 4), np.int64),
        np.zeros(1, np.int64),
    )  # fmt: skip


@numba.njit(cache=True)
def _mark(winner, source, n_triangles):  # pragma: no cover - compiled
    seen = np.zeros(n_triangles, np.bool_)
    for key in range(winner.shape[0]):
        t = winner[key]
        if t >= 0:
            seen[source[t]] = True
    return np.flatnonzero(seen)


def visible_triangles(winner: np.ndarray, source: np.ndarray, n_triangles: int) -> np.ndarray:
    """The scene triangles that win at least one pixel of the z-buffer.

    Args:
        winner: (H·W,) int64 winning sub-triangle per pixel (−1: empty).
        source: (S,) int64 the scene triangle of each sub-triangle (the set-up's ``source``).
        n_triangles: the scene's triangle count.

    Returns:
        (k,) int64 increasing triangle indices.
    """
    return _mark(
        np.ascontiguousarray(winner, dtype=np.int64),
        np.ascontiguousarray(source, dtype=np.int64),
        int(n_triangles),
    )


#: The depth stacks of :func:`frame_maps`, reused by the next frame (up to 1 GiB: 21 maps of
#: 2048², 85 of 1024²): a fresh stack costs page faults for every texel rendered.
_DEPTH_SCRATCH = ScratchPool(1 << 30)


@contextlib.contextmanager
def frame_maps(
    lit: list[tuple[object, str, dict[str, object]]],
    world_triangles: np.ndarray,
    receivers: np.ndarray,
) -> Iterator[MapStack]:
    """Render the shadow maps of a frame's lights into one stack, valid inside the ``with`` block.

    Per light, the checks and maps of :func:`blinn_phong.shadows.methods.light_visibility` with
    ``method="shadow_map"`` and the compiled engine; a cube only over the texels that look-ups
    of the receiver triangles may read.

    Args:
        lit: ``(light, method, options)`` per non-ambient light in the light table's order;
            method ``"shadow_map"`` (options among :data:`MAP_PARAMETERS`, every light the same
            resolution) or ``"none"``.
        world_triangles: (n, 3, 3) float64 world-space casters (n ≥ 1).
        receivers: (k, 3, 3) float64 world-space triangles the look-ups are on.

    Yields:
        The :class:`MapStack` (its depth memory is reused after the block).
    """
    world = np.ascontiguousarray(world_triangles, dtype=np.float64).reshape(-1, 3, 3)
    n = len(lit)
    settings = []
    for i, (light, method, options) in enumerate(lit):
        if method == "none":
            continue
        unknown = set(options) - set(MAP_PARAMETERS)
        if method != "shadow_map" or unknown:
            raise ValueError(f"lit[{i}]: expected a shadow_map with options among {sorted(MAP_PARAMETERS)}")
        o = {**MAP_PARAMETERS, **options}
        if o["kernel"] not in PCF_KERNELS:
            raise ValueError(f"kernel must be one of {PCF_KERNELS}, got {o['kernel']!r}")
        vps, views, light_position = map_matrices(
            light,
            world,
            o["resolution"],
            o["constant_bias"],
            o["slope_bias"],  # type: ignore[arg-type]
        )
        settings.append((i, o, vps, views, light_position))
    resolutions = {int(o["resolution"]) for _, o, *_ in settings}  # type: ignore[call-overload]
    if len(resolutions) > 1:
        raise ValueError(f"lit: the stack holds maps of one resolution, got {sorted(resolutions)}")
    if not settings:
        yield no_maps()
        return
    res = resolutions.pop()
    n_maps = sum(len(vps) for _, _, vps, _, _ in settings)
    with _DEPTH_SCRATCH.bytes(n_maps * res * res * 8) as buf:
        depth = carve(buf, ((n_maps, res, res), np.float64))[0]  # texels outside the rectangles: never read
        yield _render_stack(settings, world, receivers, depth, n, res)


def _render_stack(
    settings: list[tuple], world: np.ndarray, receivers: np.ndarray, depth: np.ndarray, n: int, res: int
) -> MapStack:
    """The maps of ``settings`` (per shadowed light: index, options, matrices) rendered into
    ``depth``, and the stack's tables for ``n`` lights."""
    first = np.full(n, -1, np.int64)
    faces = np.ones(n, np.int64)
    position = np.zeros((n, 3))
    kernel = np.zeros(n, np.int64)
    n_maps = len(depth)
    vp_all = np.empty((n_maps, 4, 4))
    vz_all = np.empty((n_maps, 3))
    rects_all = np.empty((n_maps, 4), np.int64)
    at = 0
    for i, o, vps, views, light_position in settings:
        f = len(vps)
        first[i], faces[i] = at, f
        kernel[i] = KERNEL_CODES[str(o["kernel"])]
        if light_position is not None:
            position[i] = light_position
        if light_position is not None:
            rects = receiver_triangle_rects(receivers, vps, light_position, res, str(o["kernel"]))
        else:
            rects = _full_rects(f, res)
        constant, slope = float(o["constant_bias"]), float(o["slope_bias"])  # type: ignore[arg-type]
        _render_maps(world, vps, rects, constant, slope, depth[at : at + f])
        rects_all[at : at + f] = rects
        vp_all[at : at + f] = vps
        vz_all[at : at + f] = views[:, 2, :3]
        at += f
    return MapStack(depth, vp_all, vz_all, first, faces, position, kernel, rects_all, np.zeros(1, np.int64))
