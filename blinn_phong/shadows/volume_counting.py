"""Stencil counts of projected receivers, on either engine: :func:`stencil_counts`, the receivers'
projection and tile binning (reused by a frame's next light) and :func:`pixel_binning` (a frame's
pixel tiles) (:mod:`blinn_phong.shadows.volume` describes the method).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from blinn_phong._checks import choice_error
from blinn_phong._numba import use_compiled
from blinn_phong._scratch import carve, carved_bytes
from blinn_phong.shadows.volume_kernels import _fast_kernels, _kernel, _pixel_binning_kernel
from blinn_phong.shadows.volume_mesh import _points
from blinn_phong.shadows.volume_setup import (
    _bin_numpy,
    _clip,
    _count_numpy,
    _grid_params,
    _offset_numpy,
    _project_numpy,
    _Setup,
    _setup,
    _transform,
)

__all__ = ["STENCIL_METHODS", "pixel_binning", "stencil_counts"]

#: Counting methods: ``zpass`` (Heidmann 1991) and ``zfail`` (Everitt & Kilgard 2002).
STENCIL_METHODS: tuple[str, ...] = ("zfail", "zpass")
#: Fewer receivers are projected, binned and counted on the calling thread: shares on threads
#: paid from between 181k and 724k receivers on the 2-core VM (45k: 10 % slower than one thread;
#: 181k: the same; 724k: 1.7× faster), and a frame's pixels are usually more.
_PARALLEL_RECEIVERS = 100_000
_PARALLEL_FACES = 10_000  # fewer volume triangles are set up on one thread


def _threads() -> int:
    """Threads the compiled kernels run on (:func:`compositing._threads.thread_count`: numba's
    setting): the number of bands of tile rows the count is split into."""
    from compositing._threads import thread_count

    return thread_count()


def _shares(kernel: object, n: int, threaded: bool, *args: object) -> None:
    """``kernel(items, *args)`` for the indices ``range(n)``: in shares on threads
    (:func:`compositing._threads.in_shares`) when ``threaded``, else at once on this thread (a
    small job: handing shares to threads would cost more than it saves)."""
    if threaded:
        from compositing._threads import in_shares

        in_shares(kernel, n, *args)  # type: ignore[arg-type]
    else:
        kernel(np.arange(n, dtype=np.int64), *args)  # type: ignore[operator]


def _spread(ny: int) -> np.ndarray:
    """Rows ``0..ny-1`` interleaved (every 16th row, then the next, ...): contiguous shares of
    this order spread the busy rows of the screen over the threads."""
    return np.argsort(np.arange(ny) % 16, kind="stable")


def stencil_counts(
    volume_triangles: np.ndarray,
    view: np.ndarray,
    projection: np.ndarray,
    points: np.ndarray,
    *,
    stencil: str = "zfail",
    engine: str = "auto",
) -> np.ndarray:
    """Per receiver, the stencil count of the shadow-volume faces along its camera ray.

    Args:
        volume_triangles: (m, 3, 4) homogeneous world-space volume triangles, outward
            (counter-clockwise seen from outside), e.g. from :func:`shadow_volume_triangles`.
        view: 4×4 world → eye matrix of the camera.
        projection: 4×4 eye → clip matrix (OpenGL conventions); only the near plane clips.
        points: (n, 3) world-space receivers; each must lie in front of the camera (clip w > 0).
        stencil: ``"zfail"`` (faces behind the receiver: +1 back, −1 front) or ``"zpass"``
            (faces in front of it: +1 front, −1 back).
        engine: ``"numba"``, ``"numpy"`` (the reference) or ``"auto"``.

    Returns:
        (n,) int64 counts; 0 means outside every volume (lit) when the method is valid.
    """
    if stencil not in STENCIL_METHODS:
        raise choice_error("stencil", stencil, STENCIL_METHODS)
    vol = np.asarray(volume_triangles, dtype=np.float64)
    if vol.ndim != 3 or vol.shape[1:] != (3, 4) or not np.all(np.isfinite(vol)):
        raise ValueError(f"volume_triangles: expected finite (m, 3, 4), got shape {vol.shape}")
    p = _points("points", points)
    vp = np.asarray(projection, dtype=np.float64) @ np.asarray(view, dtype=np.float64)
    if vp.shape != (4, 4) or not np.all(np.isfinite(vp)):
        raise ValueError(f"view/projection: expected finite 4×4 matrices, got product shape {vp.shape}")
    numba_path = use_compiled(engine)
    if len(p) == 0:
        return np.zeros(0, np.int64)
    rec = _projected(p, p, np.zeros(3), False, 0.0, False, vp, numba_path)
    return _count(vol, vp, rec, stencil == "zfail")


@dataclass(frozen=True, eq=False)
class _Receivers:
    """Projected receivers: normalised-device (x, y, z) and their (xmin, xmax, ymin, ymax).

    The numpy engine keeps them in input order (``order`` None). The compiled engine keeps them
    sorted by the tiles of ``grid`` (receiver ``order[k]`` at ``k``, tile c holding
    ``cell_start[c]:cell_start[c + 1]``), with ``slack`` = (x, y): how far a receiver may lie
    outside its tile (0 when binned from these very positions).
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    bounds: tuple[float, float, float, float]
    grid: tuple[float, float, float, float, int, int] | None = None
    order: np.ndarray | None = None
    cell_start: np.ndarray | None = None
    slack: tuple[float, float] = (0.0, 0.0)
    depths: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # ``tile_depths``, if known


#: The last compiled binning of receivers: (weak references to the points and normals, the
#: view-projection bytes, grid, order, cell_start). The lights of a frame count the same
#: receivers, moved by ``offset`` towards each light: the next light projects straight into
#: this order instead of sorting again. Any permutation would count the same (every tile's
#: bounds, depths and slack are measured again); a good one only makes the tiles tight.
_BINNING: list[tuple] = []


def _projected(
    p: np.ndarray,
    n: np.ndarray,
    light_vec: np.ndarray,
    directional: bool,
    offset: float,
    moved: bool,
    vp: np.ndarray,
    numba_path: bool,
    reuse: bool = False,
    binning: tuple | None = None,
) -> _Receivers:
    """Receivers (moved ``offset`` towards the light's side when ``moved``) in normalised-device
    coordinates; the compiled engine also bins them into tiles (reusing the last binning of the
    same point and normal arrays under the same camera when ``reuse``, or projecting into
    ``binning`` = (grid, order, cell_start) when given, e.g. :func:`pixel_binning`). Raises if a
    receiver is behind the camera or a point or normal is not finite."""
    m = len(p)
    if numba_path:
        # small jobs run on this thread: shares on threads cost more than they save
        threaded = m >= _PARALLEL_RECEIVERS
        kernels = _fast_kernels()
        key = vp.tobytes()
        cached = _BINNING[0] if reuse and _BINNING else None
        same = cached is not None and cached[0]() is p and cached[1]() is n and cached[2] == key
        if binning is not None and len(binning[1]) == m:
            cached = (None, None, key, *binning)
            same = True
        if same and len(cached[4]) == m:
            grid, order, cell_start = cached[3:]
            nx, ny = grid[4], grid[5]
            sx, sy, sz = np.empty(m), np.empty(m), np.empty(m)
            stats = np.zeros((ny, 8))
            depths = (np.full(nx * ny, np.inf), np.full(nx * ny, -np.inf), np.zeros((nx * ny, 5)))
            _shares(
                kernels[4], ny, threaded, _spread(ny), p, n, light_vec, directional, offset, moved, vp, order,
                cell_start, *grid, sx, sy, sz, stats, *depths,
            )  # fmt: skip
        else:
            px, py, pz = np.empty(m), np.empty(m), np.empty(m)
            stats = np.zeros((64, 8))  # per chunk of receivers
            args = (p, n, light_vec, directional, offset, moved, vp, px, py, pz, stats)
            _shares(kernels[0], 64, threaded, *args)
            cached = None
        bad = bool(stats[:, 5].any())
        w_ok = bool(stats[:, 4].min() > 0) if m else True
        lo, hi = stats.min(axis=0), stats.max(axis=0)
        bounds = (float(lo[0]), float(hi[1]), float(lo[2]), float(hi[3])) if m else (0.0,) * 4
    else:
        bad = not (np.all(np.isfinite(p)) and (not moved or np.all(np.isfinite(n))))
        q = _offset_numpy(p, n, light_vec, directional, offset) if moved else p
        px, py, pz, pw = _project_numpy(q, vp)
        w_ok = bool(np.all(pw > 0))
        bounds = (
            (float(px.min()), float(px.max()), float(py.min()), float(py.max())) if len(px) else (0.0,) * 4
        )
    if bad:
        raise ValueError("points/normals: expected finite coordinates, got NaN or Inf")
    if not w_ok:
        raise ValueError(f"points: some of the {len(p)} receivers lie behind the camera (clip w <= 0)")
    if not numba_path:
        return _Receivers(px, py, pz, bounds)
    if cached is not None:
        slack = (float(max(stats[:, 6].max(), 0.0)), float(max(stats[:, 7].max(), 0.0)))
        return _Receivers(sx, sy, sz, bounds, grid, order, cell_start, slack, tuple(depths))
    grid = _grid_params(m, bounds)
    order, cell_start, sx, sy, sz = kernels[1](px, py, pz, *grid)
    if reuse:
        try:
            _BINNING[:] = [(weakref.ref(p), weakref.ref(n), key, grid, order, cell_start)]
        except TypeError:  # an array that takes no weak reference: not kept
            _BINNING.clear()
    return _Receivers(sx, sy, sz, bounds, grid, order, cell_start)


def pixel_binning(
    rank: np.ndarray, width: int, height: int, tile: int = 6
) -> tuple[tuple[float, float, float, float, int, int], np.ndarray, np.ndarray]:
    """Tiles of a frame's covered pixels for :func:`shadow_volume_visibility` (``binning=``).

    A frame's receivers are its pixels' surface points, which the camera projects onto the
    pixel centres (``x = 2(col + ½)/W − 1``, ``y = 1 − 2(row + ½)/H``; the offset towards
    the light moves them a little, measured as the tiles' slack): a grid of ``tile × tile``
    pixel blocks bins them with no projection and no sort.

    Args:
        rank: (H·W,) int64 each pixel's receiver row (−1: empty), row-major from the top.
        width: the frame's width in pixels.
        height: the frame's height in pixels.
        tile: pixels per tile side (``tile² ≈`` the 32 receivers per tile of the default grid).

    Returns:
        ``(grid, order, cell_start)``: grid ``(xmin, ymin, cw, ch, nx, ny)`` in normalised
        device coordinates, the receivers' rows in tile order, and each tile's first position.
    """
    if len(rank) != width * height:
        raise ValueError(f"rank: expected {width}×{height} = {width * height} entries, got {len(rank)}")
    nx, ny = -(-width // tile), -(-height // tile)
    cw, ch = 2.0 * tile / width, 2.0 * tile / height
    grid = (-1.0, 1.0 - ny * ch, cw, ch, nx, ny)
    # a counting sort: each band of pixel rows counts its row of tiles, the counts are summed up,
    # then each band fills its tiles; the order is written into numpy's memory (reused between
    # frames without fresh page faults)
    kernel = _pixel_binning_kernel()
    threaded = width * height >= _PARALLEL_RECEIVERS
    args = (np.ascontiguousarray(rank, dtype=np.int64), int(width), int(height), int(tile), nx, ny)
    cell_start = np.zeros(nx * ny + 1, np.int64)
    order = np.empty(width * height, np.int64)
    spread = _spread(ny)
    _shares(kernel, ny, threaded, spread, False, *args, cell_start, order)
    np.cumsum(cell_start, out=cell_start)
    _shares(kernel, ny, threaded, spread, True, *args, cell_start, order)
    return grid, order[: cell_start[-1]], cell_start


_NO_CLIP = np.zeros((0, 3, 4))  # no clipped triangles (one array type for the set-up kernel)


def _setup_arrays(s: int) -> list[np.ndarray]:
    """Uninitialised arrays for the fields of :class:`_Setup` of ``s`` volume triangles, in its
    field order, carved from one numpy buffer (the set-up kernel initialises what it needs;
    numpy's memory is reused between frames without the page faults of fresh memory)."""
    f8, i8 = np.float64, np.int64
    parts = [((s, 3), f8)] * 5 + [((s, 3), np.bool_)] + [((s,), f8)] * 5 + [((s,), i8)] * 5 + [((s,), f8)] * 4
    return carve(np.empty(carved_bytes(*parts), np.uint8), *parts)


def _count(
    vol: np.ndarray, vp: np.ndarray, rec: _Receivers, zfail: bool, visibility: bool = False
) -> np.ndarray:
    """Stencil counts (or, with ``visibility``, 1.0 where the count is 0) of projected receivers,
    in their input order."""
    bounds = rec.bounds
    guard = 2.0 * max(*(abs(b) for b in bounds), 1.0) + 1.0
    if rec.order is None:  # the numpy engine
        grid = _grid_params(len(rec.x), bounds)
        st = _setup(_transform(vol, vp), grid, guard)
        cell_start, order = _bin_numpy(rec.x, rec.y, grid)
        counts = _count_numpy(st, rec.x, rec.y, rec.z, cell_start, order, grid[4], zfail)
        return (counts == 0).astype(np.float64) if visibility else counts
    grid = rec.grid
    xmin, ymin, cw, ch, nx, ny = grid
    slack_x, slack_y = rec.slack
    threaded = len(rec.x) >= _PARALLEL_RECEIVERS
    _, _, setup, tile_depths, _, to_clip = _fast_kernels()
    # a small volume is set up on this thread (no shares to hand to threads)
    faces_threaded = len(vol) >= _PARALLEL_FACES
    todo = np.empty(len(vol), np.bool_)
    _shares(to_clip, len(vol), faces_threaded, vol, vp, guard, todo)
    # the few faces crossing the near plane or the guard band: clipped, then set up after the rest
    cut = _clip(_transform(vol[todo], vp), guard) if todo.any() else _NO_CLIP
    fields = _setup_arrays(len(vol) + len(cut))
    _shares(setup, len(vol) + len(cut), faces_threaded, vol, cut, todo, vp, *grid, slack_x, slack_y, *fields)
    st = _Setup(*fields)
    depths = rec.depths
    if depths is None:
        depths = (np.full(nx * ny, np.inf), np.full(nx * ny, -np.inf), np.zeros((nx * ny, 5)))
        _shares(
            tile_depths, ny, threaded, _spread(ny), rec.x, rec.y, rec.z, rec.cell_start, xmin, ymin, cw, ch,
            nx, *depths,
        )  # fmt: skip
    zlo, zhi, fit = depths
    # small jobs run on this thread: shares on threads cost more than they save
    n_bands = min(ny, _threads()) if threaded else 1
    m = len(rec.x)
    counts, lit = np.empty(0 if visibility else m, np.int64), np.empty(m if visibility else 0)
    _shares(
        _kernel(), n_bands, threaded, n_bands, ny, nx, xmin, ymin, cw, ch,
        st.cx0, st.cx1, st.cy0, st.cy1, st.ex, st.ey, st.edx, st.edy, st.esign, st.etie,
        st.z0, st.x0, st.y0, st.gx, st.gy, st.front, st.bx0, st.bx1, st.by0, st.by1,
        rec.x, rec.y, rec.z, rec.cell_start, zlo, zhi, fit, rec.order, zfail, visibility,
        slack_x, slack_y,
        np.empty(m, np.int64), counts, lit,
    )  # fmt: skip
    return lit if visibility else counts
