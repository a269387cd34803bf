"""Deep images: every pixel keeps its list of samples, each with a depth, a back depth and a colour.

A :class:`DeepImage` of ``H × W`` pixels holds ``counts`` (``(H, W)`` uint32, the number
of samples of each pixel, row 0 at the top) and, for the ``N = counts.sum()`` samples in
pixel order (row by row, the samples of one pixel together), the flat arrays ``z`` and
``zback`` (``(N,)`` float32, distance from the viewer, ≥ 0) and ``rgba`` (``(N, 4)``
float32, linear premultiplied RGBA, alpha in [0, 1]). A sample with ``zback > z`` is a
*volume* sample covering ``z ≤ depth < zback``; one with ``zback ≤ z`` is a *point* sample
at ``z`` (zero thickness).

The operations follow OpenEXR's "Interpreting OpenEXR Deep Pixels" (F. Kainz,
P. Hillman; openexr.com/en/latest/InterpretingDeepPixels.html), "the document" below:

* :func:`tidy` — sort the samples by ``z`` then ``zback``, split volume samples that
  partially overlap others (a piece of relative length ``x`` of a sample of alpha ``a`` and
  colour ``c`` gets alpha ``1 - (1 - a)^x`` and colour ``c·alpha'/a``, ``c·x`` for ``a = 0``, so
  the pieces composited with ``over`` give back the sample), and merge coincident samples
  (alpha ``1 - Π(1 - a_k)``, colour ``w·Σ c_k·v_k`` with ``u_k = -log(1 - a_k)``,
  ``v_k = u_k/a_k`` (1 for ``a_k = 0``), ``w = alpha/Σu_k``; opaque samples win, their
  colours averaged). Point samples never merge with volume samples.
* :func:`flatten` — tidy, then composite the samples front to back with ``over``.
* :func:`merge` — the union of two images' samples, then :func:`tidy`. It does not depend
  on the order of its arguments.
* :func:`holdout` — an image with the samples of another in front of (or coincident with)
  its samples taken into account: ``flatten(holdout(a, b))`` is what ``a`` contributes to
  ``flatten(merge(a, b))``, so ``flatten(holdout(a, b)) + flatten(holdout(b, a))`` equals
  ``flatten(merge(a, b))``.
* :func:`crop`, :func:`from_flat` (a flat image as one sample per pixel at a depth),
  :meth:`DeepImage.from_samples` (samples listed by pixel index), :func:`from_fragments`
  (a renderer's fragments, supersampled or not: each subpixel's fragment enters its pixel
  with weight 1/samples, the fragments of one surface in one pixel summed into one sample).

Compiled kernels: :mod:`compositing._deep_kernels` (numba, cached on disk); a call runs
ranges of pixels on the calling thread and the helper threads of :mod:`compositing._fused`.
Memory: an operation holds its inputs, its output and, while running, one more copy of
the output (each range's samples before they are joined).

Files: :mod:`compositing.deep_io` (deep OpenEXR through OpenImageIO).
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from . import _deep_kernels as _k
from ._fused import MIN_PIXELS_PER_THREAD, RANGES_PER_THREAD, THREADS, _pool
from .validate import as_rgba

__all__ = ["DeepImage", "crop", "flatten", "from_flat", "from_fragments", "holdout", "merge", "tidy"]

#: Samples per range below which a call runs on the calling thread only.
_MIN_SAMPLES_PER_RANGE = 1 << 15


def _describe(x: object) -> str:
    if isinstance(x, np.ndarray):
        return f"array of shape {x.shape}, dtype {x.dtype}"
    return type(x).__name__


def _float_samples(x: object, name: str, shape_tail: tuple[int, ...], copy: bool = True) -> np.ndarray:
    """``x`` as a C-contiguous float32 array of shape ``(N, *shape_tail)``, finite, or a clear error.

    With ``copy`` the result never shares memory with ``x`` (the image owns its arrays).
    """
    if isinstance(x, np.ndarray):
        arr = x
    else:
        try:
            arr = np.asarray(x, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name}: expected a float array, got {_describe(x)}") from exc
    if arr.dtype.kind != "f" or arr.dtype.itemsize < 4:
        raise TypeError(f"{name}: expected a float32 or float64 array, got dtype {arr.dtype}")
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        expected = "(N,)" if not shape_tail else f"(N, {', '.join(map(str, shape_tail))})"
        raise ValueError(f"{name}: expected shape {expected}, got {arr.shape}")

    def nonfinite(values: np.ndarray, what: str) -> ValueError:
        n_nan = int(np.count_nonzero(np.isnan(values)))
        n_inf = int(np.count_nonzero(np.isinf(values)))
        return ValueError(
            f"{name}: expected finite values{what}; got {n_nan + n_inf} non-finite of {values.size} "
            f"({n_nan} NaN, {n_inf} Inf)"
        )

    if not np.isfinite(arr).all():
        raise nonfinite(arr, "")
    with np.errstate(over="ignore"):
        out = np.array(arr, dtype=np.float32, order="C", copy=copy)
    if not np.isfinite(out).all():
        raise nonfinite(out, f" within float32's range (|x| < {float(np.finfo(np.float32).max):.4g})")
    return out


class DeepImage:
    """A deep image: ``counts`` samples per pixel and the samples' ``z``, ``zback`` and ``rgba``.

    Attributes:
        counts: ``(H, W)`` uint32, samples per pixel.
        z: ``(N,)`` float32, each sample's front depth (≥ 0).
        zback: ``(N,)`` float32, each sample's back depth; ``zback ≤ z`` marks a point sample.
        rgba: ``(N, 4)`` float32, premultiplied linear RGBA; alpha in [0, 1].
        offsets: ``(H·W + 1,)`` int64; pixel ``p = row·W + column`` owns samples
            ``offsets[p]:offsets[p + 1]``.

    The arrays are read-only. Images made by :func:`tidy`, :func:`merge` and
    :func:`holdout` are known to be tidy (:attr:`known_tidy`), which lets :func:`flatten`
    skip the tidy step.
    """

    __slots__ = ("_known_tidy", "counts", "offsets", "rgba", "z", "zback")

    counts: np.ndarray
    z: np.ndarray
    zback: np.ndarray
    rgba: np.ndarray
    offsets: np.ndarray

    def __init__(self, counts: object, z: object, zback: object, rgba: object) -> None:
        """Check and store copies of the arrays (float64 input is rounded to float32).

        Raises:
            TypeError: an argument is not an array of the right kind.
            ValueError: shapes disagree (``counts.sum()`` samples needed), values are
                NaN or infinite, a depth is negative, or an alpha lies outside [0, 1].
        """
        if not isinstance(counts, np.ndarray) or counts.dtype.kind not in "iu":
            raise TypeError(f"counts: expected an integer array of shape (H, W), got {_describe(counts)}")
        if counts.ndim != 2:
            raise ValueError(f"counts: expected shape (H, W), got {counts.shape}")
        if counts.size and counts.min() < 0:
            raise ValueError(f"counts: expected sample counts >= 0, got minimum {int(counts.min())}")
        if counts.size and int(counts.max()) > np.iinfo(np.uint32).max:
            raise ValueError(f"counts: expected counts below 2**32, got maximum {int(counts.max())}")
        self._check_and_set(counts, z, zback, rgba, copy=True)

    def _check_and_set(self, counts: np.ndarray, z: object, zback: object, rgba: object, copy: bool) -> None:
        zs = _float_samples(z, "z", (), copy)
        zbs = _float_samples(zback, "zback", (), copy)
        cs = _float_samples(rgba, "rgba", (4,), copy)
        n = int(counts.sum(dtype=np.int64))
        if not len(zs) == len(zbs) == len(cs) == n:
            raise ValueError(
                f"samples: counts add up to {n} samples, got z {len(zs)}, zback {len(zbs)}, rgba {len(cs)}"
            )
        for name, depth in (("z", zs), ("zback", zbs)):
            if n and depth.min() < 0:
                bad = int(np.count_nonzero(depth < 0))
                raise ValueError(
                    f"{name}: expected depths >= 0 (OpenEXR deep images); got {bad} negative, "
                    f"minimum {float(depth.min()):.6g}"
                )
        if n:
            alpha = cs[:, 3]
            outside = (alpha < 0) | (alpha > 1)
            if outside.any():
                raise ValueError(
                    f"rgba: expected alpha (last channel) in [0, 1]; got {int(np.count_nonzero(outside))} "
                    f"of {n} samples outside, alpha range "
                    f"[{float(alpha.min()):.6g}, {float(alpha.max()):.6g}]"
                )
        self._set(counts.astype(np.uint32, copy=True), zs, zbs, cs, known_tidy=False)

    def _set(
        self, counts: np.ndarray, z: np.ndarray, zback: np.ndarray, rgba: np.ndarray, *, known_tidy: bool
    ):
        offsets = np.zeros(counts.size + 1, np.int64)
        np.cumsum(counts.reshape(-1), out=offsets[1:])
        for arr in (counts, z, zback, rgba, offsets):
            arr.flags.writeable = False
        object.__setattr__(self, "counts", counts)
        object.__setattr__(self, "z", z)
        object.__setattr__(self, "zback", zback)
        object.__setattr__(self, "rgba", rgba)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "_known_tidy", known_tidy)

    @classmethod
    def _trusted(
        cls, counts: np.ndarray, z: np.ndarray, zback: np.ndarray, rgba: np.ndarray, known_tidy: bool
    ) -> DeepImage:
        """An image from arrays a kernel produced (already checked; no copy)."""
        image = object.__new__(cls)
        image._set(counts, z, zback, rgba, known_tidy=known_tidy)
        return image

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"DeepImage is immutable (cannot set {name!r})")

    @classmethod
    def empty(cls, height: int, width: int) -> DeepImage:
        """An image of ``height × width`` pixels without samples."""
        for name, v in (("height", height), ("width", width)):
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 0:
                raise ValueError(f"{name}: expected an integer >= 0, got {v!r}")
        return cls._trusted(
            np.zeros((int(height), int(width)), np.uint32),
            np.zeros(0, np.float32),
            np.zeros(0, np.float32),
            np.zeros((0, 4), np.float32),
            True,
        )

    @classmethod
    def from_samples(
        cls,
        shape: tuple[int, int],
        pixel: object,
        z: object,
        rgba: object,
        zback: object | None = None,
    ) -> DeepImage:
        """An image from samples listed in any order, each with its pixel index.

        Args:
            shape: ``(H, W)``.
            pixel: ``(N,)`` integer, the flat pixel index ``row·W + column`` of each sample.
            z: ``(N,)`` front depths (≥ 0).
            rgba: ``(N, 4)`` premultiplied RGBA.
            zback: ``(N,)`` back depths, or None for point samples (``zback = z``).

        The samples of each pixel keep their order in the input (stable grouping).
        """
        if (
            not isinstance(shape, tuple | list)
            or len(shape) != 2
            or not all(isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= 0 for v in shape)
        ):
            raise ValueError(f"shape: expected (height, width) with integers >= 0, got {shape!r}")
        h, w = int(shape[0]), int(shape[1])
        pix = np.asarray(pixel)
        if pix.ndim != 1 or pix.dtype.kind not in "iu":
            raise TypeError(f"pixel: expected a 1-D integer array, got {_describe(pix)}")
        if len(pix) and (pix.min() < 0 or pix.max() >= h * w):
            raise ValueError(
                f"pixel: expected indices in [0, {h * w}) for shape {(h, w)}, "
                f"got range [{int(pix.min())}, {int(pix.max())}]"
            )
        zs = _float_samples(z, "z", (), copy=False)
        zbs = zs if zback is None else _float_samples(zback, "zback", (), copy=False)
        cs = _float_samples(rgba, "rgba", (4,), copy=False)
        if not len(pix) == len(zs) == len(zbs) == len(cs):
            raise ValueError(
                f"samples: expected equal lengths, got pixel {len(pix)}, z {len(zs)}, zback {len(zbs)}, "
                f"rgba {len(cs)}"
            )
        order = np.argsort(pix, kind="stable")
        counts = np.bincount(pix, minlength=h * w).reshape(h, w).astype(np.uint32)
        image = object.__new__(cls)
        image._check_and_set(counts, zs[order], zbs[order], cs[order], copy=False)  # fresh arrays
        return image

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.counts.shape  # type: ignore[return-value]

    @property
    def n_samples(self) -> int:
        """The total number of samples."""
        return len(self.z)

    @property
    def known_tidy(self) -> bool:
        """True if the image was made tidy by an operation of this module."""
        return self._known_tidy

    @property
    def nbytes(self) -> int:
        """Bytes held by the arrays."""
        return sum(a.nbytes for a in (self.counts, self.z, self.zback, self.rgba, self.offsets))

    def pixel(self, row: int, column: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(z, zback, rgba)`` of one pixel's samples (read-only views)."""
        h, w = self.shape
        if not (0 <= row < h and 0 <= column < w):
            raise IndexError(f"pixel: ({row}, {column}) is outside the image of shape {(h, w)}")
        p = row * w + column
        s = slice(self.offsets[p], self.offsets[p + 1])
        return self.z[s], self.zback[s], self.rgba[s]

    def is_tidy(self) -> bool:
        """True if every pixel is sorted and non-overlapping as stored (the document's "tidy")."""
        if self._known_tidy:
            return True
        flags = _map_ranges(
            lambda lo, hi: _k.tidy_flags(self.offsets, self.z, self.zback, lo, hi),
            self.counts.size,
            self.offsets,
        )
        return bool(all(f.all() for f in flags))

    def __repr__(self) -> str:
        h, w = self.shape
        return f"DeepImage({h}×{w}, {self.n_samples} samples{', tidy' if self._known_tidy else ''})"


def _check_image(x: object, name: str) -> DeepImage:
    if not isinstance(x, DeepImage):
        raise TypeError(f"{name}: expected a DeepImage, got {_describe(x)}")
    return x


def _ranges(n: int, offsets: np.ndarray) -> list[tuple[int, int]]:
    """Split pixels ``[0, n)`` into ranges of about equal sample counts (a few per thread)."""
    total = int(offsets[-1]) if len(offsets) else 0
    parts = min(THREADS * RANGES_PER_THREAD, n // MIN_PIXELS_PER_THREAD + 1, total // _MIN_SAMPLES_PER_RANGE)
    parts = max(1, parts)
    if parts == 1 or n == 0:
        return [(0, n)]
    # Cut where the cumulative sample count (plus one per pixel, the per-pixel cost) crosses equal shares.
    work = offsets[: n + 1] + np.arange(n + 1)
    cuts = np.searchsorted(work, np.linspace(0, work[-1], parts + 1)[1:-1])
    bounds = [0, *sorted(set(int(c) for c in cuts if 0 < c < n)), n]
    return list(itertools.pairwise(bounds))


def _map_ranges(fn: Callable[[int, int], Any], n: int, offsets: np.ndarray) -> list[Any]:
    """``[fn(lo, hi) for (lo, hi) in ranges]`` with the ranges run on the calling and helper threads."""
    ranges = _ranges(n, offsets)
    if len(ranges) == 1:
        return [fn(*ranges[0])]
    results: list[Any] = [None] * len(ranges)
    queue = iter(enumerate(ranges))
    lock = threading.Lock()

    def work() -> None:
        while True:
            with lock:
                item = next(queue, None)
            if item is None:
                return
            i, (lo, hi) = item
            results[i] = fn(lo, hi)

    helpers = [_pool().submit(work) for _ in range(min(THREADS, len(ranges)) - 1)]
    work()
    for f in helpers:
        f.result()
    return results


def _max_count(image: DeepImage) -> int:
    return int(image.counts.max()) if image.counts.size else 0


def _join(shape: tuple[int, int], parts: list[tuple[np.ndarray, ...]], known_tidy: bool) -> DeepImage:
    """One image from the ``(counts, z, zback, rgba)`` of consecutive pixel ranges."""
    if len(parts) == 1:
        counts, z, zb, rgba = parts[0]
    else:
        counts = np.concatenate([p[0] for p in parts])
        z = np.concatenate([p[1] for p in parts])
        zb = np.concatenate([p[2] for p in parts])
        rgba = np.concatenate([p[3] for p in parts])
    return DeepImage._trusted(counts.reshape(shape), z, zb, rgba, known_tidy)


_NO_SAMPLES = (np.zeros(0, np.float32), np.zeros(0, np.float32), np.zeros((0, 4), np.float32))


def tidy(image: DeepImage) -> DeepImage:
    """The tidy form of ``image``: sorted, non-overlapping samples (the document's "Making an Image Tidy").

    Volume samples that partially overlap are split where other samples begin or end
    (alpha by the log rule, colour scaled by the alpha ratio), coincident samples are
    merged, and point samples are stored with ``zback = z``. Pixels that are already
    tidy keep their samples exactly. The result is a new image; ``image`` is unchanged.
    """
    image = _check_image(image, "image")
    if image.known_tidy:
        return image
    return merge(image, DeepImage.empty(*image.shape))


def merge(a: DeepImage, b: DeepImage) -> DeepImage:
    """The union of the samples of ``a`` and ``b`` (equal shapes), made tidy.

    The document's merge concatenates the two sample lists; this one then applies
    :func:`tidy`, so the result is ready to :func:`flatten` and does not depend on the order
    of ``a`` and ``b``.

    Raises:
        TypeError: an argument is not a DeepImage.
        ValueError: the shapes differ.
    """
    a = _check_image(a, "a")
    b = _check_image(b, "b")
    if a.shape != b.shape:
        raise ValueError(f"a, b: expected deep images of equal shape, got {a.shape} and {b.shape}")
    max_n = int((a.counts.astype(np.int64) + b.counts).max()) if a.counts.size else 0
    offsets = a.offsets + b.offsets
    parts = _map_ranges(
        lambda lo, hi: _k.merge_range(
            a.offsets, a.z, a.zback, a.rgba, b.offsets, b.z, b.zback, b.rgba, max_n, lo, hi
        ),
        a.counts.size,
        offsets,
    )
    return _join(a.shape, parts, True)


def flatten(image: DeepImage) -> np.ndarray:
    """The flat image ``(H, W, 4)`` float32 premultiplied RGBA: tidy, then front-to-back ``over``.

    ``over``: ``A ← A + (1 - A)·a_k``, ``C ← C + (1 - A)·c_k`` over the tidy samples in
    order (the document's "Flattening an Image"). Empty pixels are (0, 0, 0, 0).
    """
    image = _check_image(image, "image")
    h, w = image.shape
    out = np.zeros((h * w, 4), np.float32)
    max_n = _max_count(image)
    _map_ranges(
        lambda lo, hi: _k.flatten_range(
            image.offsets, image.z, image.zback, image.rgba, image.known_tidy, max_n, out, lo, hi
        ),
        h * w,
        image.offsets,
    )
    return out.reshape(h, w, 4)


def holdout(image: DeepImage, mask: DeepImage) -> DeepImage:
    """``image`` held out by ``mask``: what ``image`` contributes behind (and beside) ``mask``'s samples.

    Both images are made tidy together (split at each other's sample boundaries); each
    place where ``image`` has a sample keeps ``image``'s share of the coincident merge with
    ``mask``'s sample there (the document's merge rule splits the merged colour and alpha
    into one term per input), seen through the transmittance of both images' samples in
    front. The output samples store these contributions relative to the output's own
    transmittance, so that ``flatten(holdout(image, mask))`` is exactly ``image``'s part of
    ``flatten(merge(image, mask))`` (colour and alpha) and
    ``flatten(holdout(a, b)) + flatten(holdout(b, a)) = flatten(merge(a, b))``. Samples
    that contribute nothing (all four channels 0) are dropped, and so is everything behind
    the depth where the merged image becomes opaque; with an empty ``mask`` pixel the result
    is otherwise the tidy ``image`` pixel. The result is tidy.

    Raises:
        TypeError: an argument is not a DeepImage.
        ValueError: the shapes differ.
    """
    image = _check_image(image, "image")
    mask = _check_image(mask, "mask")
    if image.shape != mask.shape:
        raise ValueError(
            f"image, mask: expected deep images of equal shape, got {image.shape} and {mask.shape}"
        )
    max_n = int((image.counts.astype(np.int64) + mask.counts).max()) if image.counts.size else 0
    parts = _map_ranges(
        lambda lo, hi: _k.holdout_range(
            image.offsets,
            image.z,
            image.zback,
            image.rgba,
            mask.offsets,
            mask.z,
            mask.zback,
            mask.rgba,
            max_n,
            lo,
            hi,
        ),
        image.counts.size,
        image.offsets + mask.offsets,
    )
    return _join(image.shape, parts, True)


def crop(image: DeepImage, top: int, left: int, height: int, width: int) -> DeepImage:
    """The pixels ``[top, top + height) × [left, left + width)`` of ``image`` with their samples.

    Raises:
        ValueError: the window is empty of meaning (negative size) or reaches outside the image.
    """
    image = _check_image(image, "image")
    h, w = image.shape
    for name, v in (("top", top), ("left", left), ("height", height), ("width", width)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 0:
            raise ValueError(f"{name}: expected an integer >= 0, got {v!r}")
    if top + height > h or left + width > w:
        raise ValueError(
            f"crop: window rows [{top}, {top + height}) × columns [{left}, {left + width}) reaches outside "
            f"the image of shape {(h, w)}"
        )
    counts = np.ascontiguousarray(image.counts[top : top + height, left : left + width])
    rows = image.offsets[:-1].reshape(h, w)[top : top + height, left : left + width]
    starts = rows.reshape(-1)
    n = counts.reshape(-1).astype(np.int64)
    index = np.repeat(starts - np.concatenate([[0], np.cumsum(n)[:-1]]), n) + np.arange(int(n.sum()))
    return DeepImage._trusted(counts, image.z[index], image.zback[index], image.rgba[index], image.known_tidy)


def from_flat(rgba: np.ndarray, z: float | np.ndarray, zback: float | np.ndarray | None = None) -> DeepImage:
    """A flat image as a deep image: one sample per pixel at depth ``z`` (to ``zback``).

    Args:
        rgba: ``(H, W, 4)`` premultiplied RGBA (float32 or float64), alpha in [0, 1].
        z: the samples' depth, a number or an ``(H, W)`` array (≥ 0, finite).
        zback: back depths (a number or ``(H, W)``), or None for point samples.

    Pixels whose four channels are all 0 get no sample (they add nothing to any merge),
    as OpenImageIO's ``ImageBufAlgo.deepen`` does.
    """
    img = as_rgba(rgba, "rgba", allow_scalar_colour=False)
    if img.ndim != 3:
        raise ValueError(f"rgba: expected an image of shape (H, W, 4), got {img.shape}")
    h, w, _ = img.shape
    depth: dict[str, np.ndarray] = {}
    for name, value in (("z", z), ("zback", z if zback is None else zback)):
        arr = np.asarray(value, dtype=np.float64)
        try:
            depth[name] = np.broadcast_to(arr, (h, w))
        except ValueError:
            raise ValueError(
                f"{name}: expected a number or an array of shape {(h, w)}, got {arr.shape}"
            ) from None
    keep = (img != 0).any(axis=-1).reshape(-1)
    pixel = np.flatnonzero(keep)
    return DeepImage.from_samples(
        (h, w),
        pixel,
        depth["z"].reshape(-1)[pixel],
        img.reshape(-1, 4)[pixel],
        depth["zback"].reshape(-1)[pixel],
    )


def from_fragments(
    shape: tuple[int, int],
    pixel: np.ndarray,
    depth: np.ndarray,
    rgba: np.ndarray,
    *,
    samples_per_pixel: int = 1,
    surface: np.ndarray | None = None,
) -> DeepImage:
    """A deep image from a renderer's fragments (point samples), with supersampling coverage.

    Args:
        shape: ``(H, W)`` of the image.
        pixel: ``(N,)`` flat index ``row·W + column`` of the pixel each fragment's subpixel
            belongs to.
        depth: ``(N,)`` fragment depth (≥ 0, nearer is smaller).
        rgba: ``(N, 4)`` premultiplied RGBA of each fragment (as resolved for its subpixel).
        samples_per_pixel: subpixels per pixel ``s``: a fragment covers ``1/s`` of its pixel.
        surface: ``(N,)`` integer id of the surface (primitive, object) each fragment lies on,
            or None to keep every fragment as its own sample.

    Coverage: a subpixel's fragment enters its pixel with weight ``1/s``. Fragments of one
    surface in one pixel are summed into one point sample (premultiplied RGBA
    ``Σ rgba / s``, depth = the nearest of them), so a surface covering ``k`` of the ``s``
    subpixels has alpha ``k/s·α``: the coverage adds, it is not merged as coincident samples
    (which would make ``s`` quarter-covering copies of an opaque surface opaque). Flattening
    then treats the coverage of different surfaces as uncorrelated: where two surfaces share
    a pixel only in part, or change depth order inside it, the flat result differs from the
    average of the subpixels' resolved colours (docs/compositing.md gives the bound).
    """
    if isinstance(samples_per_pixel, bool) or not isinstance(samples_per_pixel, int) or samples_per_pixel < 1:
        raise ValueError(f"samples_per_pixel: expected an integer >= 1, got {samples_per_pixel!r}")
    pix = np.asarray(pixel)
    if pix.ndim != 1 or pix.dtype.kind not in "iu":
        raise TypeError(f"pixel: expected a 1-D integer array, got {_describe(pix)}")
    c = _float_samples(rgba, "rgba", (4,), copy=False).astype(np.float64)
    d = _float_samples(depth, "depth", (), copy=False)
    if not len(pix) == len(c) == len(d):
        raise ValueError(
            f"fragments: expected equal lengths, got pixel {len(pix)}, depth {len(d)}, rgba {len(c)}"
        )
    weight = 1.0 / samples_per_pixel
    if surface is None:
        return DeepImage.from_samples(shape, pix, d, c * weight)
    surf = np.asarray(surface)
    if surf.shape != pix.shape or surf.dtype.kind not in "iu":
        raise TypeError(f"surface: expected an integer array of shape {pix.shape}, got {_describe(surf)}")
    if not len(pix):
        return DeepImage.from_samples(shape, pix, d, c)
    keys, inverse = np.unique(
        np.stack([pix.astype(np.int64), surf.astype(np.int64)]), axis=1, return_inverse=True
    )
    inverse = inverse.reshape(-1)
    summed = np.zeros((keys.shape[1], 4))
    np.add.at(summed, inverse, c * weight)
    nearest = np.full(keys.shape[1], np.inf)
    np.minimum.at(nearest, inverse, d)
    return DeepImage.from_samples(shape, keys[0], nearest, summed)
