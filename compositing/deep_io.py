"""Deep OpenEXR files to and from :class:`compositing.deep.DeepImage`, through OpenImageIO's DeepData.

* Writing: channels ``R, G, B, A, Z, ZBack`` (premultiplied linear RGBA, depth), one part,
  scanline (default) or tiled, compression ``zips`` (default) or ``none`` (OpenImageIO
  writes deep files with no other; OpenEXR would also allow ``rle``). RGBA is float32 or
  half (``float_format``); depth is always float32. The file is written under a temporary
  name and renamed over the target only after a successful close
  (:mod:`compositing._atomic`): a failed write leaves an existing file intact.
* Reading: channels are found by name as the OpenEXR deep document defines them: depth
  ``Z`` (required) and ``ZBack`` (OpenImageIO also accepts ``Zback``; missing: a copy of
  ``Z``, point samples), alpha ``A`` (required), colour ``R, G, B`` (or ``Y``, grey). Other
  channels are ignored with a ``UserWarning`` naming them. The data window is read
  (row 0 at its top).
* Values pass through OpenImageIO's Python ``DeepData`` one sample value at a time (it has
  no bulk accessor): about 0.3 µs per value, so a 1920×1080 file of 4 samples per pixel
  (50 million values) takes some 15 s each way. :func:`read_deep` and :func:`write_deep`
  take a ``progress`` callback for long files.

:func:`to_deepdata` and :func:`from_deepdata` convert without a file, e.g. to hand an image
to ``OpenImageIO.ImageBufAlgo``'s deep functions.
"""

from __future__ import annotations

import collections
import os
import warnings
from collections.abc import Callable

import numpy as np
import OpenImageIO as oiio  # noqa: N813 (the name OpenImageIO documents)

from .deep import DeepImage
from .io import write_atomic

__all__ = ["COMPRESSIONS", "from_deepdata", "read_deep", "to_deepdata", "write_deep"]

#: Compressions OpenImageIO writes deep files with (it turns any other into zips).
COMPRESSIONS = ("zips", "none")

#: Channel names written, in file order.
CHANNELS = ("R", "G", "B", "A", "Z", "ZBack")

#: Values moved through DeepData per step (one progress report each).
_CHUNK_VALUES = 1 << 20


def _consume(iterator) -> None:
    collections.deque(iterator, maxlen=0)


def _sample_indices(lo: int, hi: int, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For samples ``[lo, hi)`` in pixel order: each one's pixel index and its index within the pixel."""
    pixel = np.searchsorted(offsets, np.arange(lo, hi), side="right") - 1
    return pixel, np.arange(lo, hi) - offsets[pixel]


def to_deepdata(
    image: DeepImage,
    *,
    float_format: str = "float",
    progress: Callable[[float], None] | None = None,
) -> oiio.DeepData:
    """An OpenImageIO ``DeepData`` holding ``image`` (channels ``R, G, B, A, Z, ZBack``, pixels row by row).

    Args:
        image: the deep image.
        float_format: ``"float"`` or ``"half"`` for the RGBA channels (depth stays float32).
        progress: called with the fraction of values done.
    """
    if not isinstance(image, DeepImage):
        raise TypeError(f"image: expected a DeepImage, got {type(image).__name__}")
    if float_format not in ("float", "half"):
        raise ValueError(f"float_format: expected 'float' or 'half', got {float_format!r}")
    colour_type = oiio.FLOAT if float_format == "float" else oiio.HALF
    h, w = image.shape
    dd = oiio.DeepData()
    dd.init(h * w, len(CHANNELS), (colour_type,) * 4 + (oiio.FLOAT,) * 2, CHANNELS)
    counts = image.counts.reshape(-1)
    filled = np.flatnonzero(counts)
    _consume(map(dd.set_samples, filled.tolist(), counts[filled].tolist()))
    values = np.empty((image.n_samples, len(CHANNELS)), np.float32)
    values[:, :4] = image.rgba
    values[:, 4] = image.z
    values[:, 5] = image.zback
    n = image.n_samples
    step = max(1, _CHUNK_VALUES // len(CHANNELS))
    channel = np.tile(np.arange(len(CHANNELS)), step).tolist()
    for lo in range(0, n, step):
        hi = min(n, lo + step)
        pixel, sample = _sample_indices(lo, hi, image.offsets)
        k = (hi - lo) * len(CHANNELS)
        _consume(
            map(
                dd.set_deep_value,
                np.repeat(pixel, len(CHANNELS)).tolist(),
                channel[:k],
                np.repeat(sample, len(CHANNELS)).tolist(),
                values[lo:hi].reshape(-1).tolist(),
            )
        )
        if progress is not None:
            progress(hi / n)
    return dd


def _find(names: list[str], *wanted: str, case: bool = True) -> int:
    for want in wanted:
        for i, name in enumerate(names):
            if name == want or (not case and name.lower() == want.lower()):
                return i
    return -1


def from_deepdata(
    dd: oiio.DeepData,
    height: int,
    width: int,
    *,
    source: str = "deepdata",
    progress: Callable[[float], None] | None = None,
) -> DeepImage:
    """A :class:`DeepImage` from an OpenImageIO ``DeepData`` of ``height × width`` pixels (row by row).

    Channels are found by name (module docstring); ``source`` names the data in messages.

    Raises:
        ValueError: the pixel count disagrees, a required channel is missing, or the values
            are not a valid deep image (NaN/Inf, negative depth, alpha outside [0, 1]).
    """
    if dd.pixels != height * width:
        raise ValueError(f"{source}: expected {height * width} pixels ({height}×{width}), got {dd.pixels}")
    names = [dd.channelname(c) for c in range(dd.channels)]
    z_c = _find(names, "Z")
    zb_c = _find(names, "ZBack", "Zback", case=False)
    a_c = _find(names, "A", "alpha", case=False)
    rgb = [_find(names, k) for k in "RGB"]
    if any(c < 0 for c in rgb):
        grey = _find(names, "Y")
        rgb = [grey] * 3 if grey >= 0 else rgb
    required = (("Z", z_c), ("A", a_c), ("R", rgb[0]), ("G", rgb[1]), ("B", rgb[2]))
    missing = [label for label, c in required if c < 0]
    if missing:
        raise ValueError(
            f"{source}: expected deep channels R, G, B (or Y), A and Z; missing {', '.join(missing)} "
            f"among {names}"
        )
    used = {*rgb, a_c, z_c, zb_c}
    ignored = [n for i, n in enumerate(names) if i not in used]
    if ignored:
        warnings.warn(f"{source}: ignored deep channels {', '.join(ignored)}", UserWarning, stacklevel=3)
    counts = np.fromiter(map(dd.samples, range(dd.pixels)), dtype=np.int64, count=dd.pixels)
    offsets = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    n = int(offsets[-1])
    chans = [*rgb, a_c, z_c, zb_c if zb_c >= 0 else z_c]
    values = np.empty((n, len(chans)), np.float32)
    step = max(1, _CHUNK_VALUES // len(chans))
    channel = np.tile(np.array(chans), step).tolist()
    for lo in range(0, n, step):
        hi = min(n, lo + step)
        pixel, sample = _sample_indices(lo, hi, offsets)
        k = (hi - lo) * len(chans)
        values[lo:hi] = np.fromiter(
            map(
                dd.deep_value,
                np.repeat(pixel, len(chans)).tolist(),
                channel[:k],
                np.repeat(sample, len(chans)).tolist(),
            ),
            dtype=np.float32,
            count=k,
        ).reshape(hi - lo, len(chans))
        if progress is not None:
            progress(hi / n)
    try:
        return DeepImage(counts.reshape(height, width), values[:, 4], values[:, 5], values[:, :4])
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None


def write_deep(
    path: str | os.PathLike,
    image: DeepImage,
    *,
    tiled: bool = False,
    tile_size: int = 64,
    compression: str = "zips",
    float_format: str = "float",
    progress: Callable[[float], None] | None = None,
    atomic: bool = True,
) -> None:
    """Write ``image`` as a deep OpenEXR file (channels ``R, G, B, A, Z, ZBack``).

    Args:
        path: output file, ``.exr``.
        image: the deep image.
        tiled: write tiles of ``tile_size × tile_size`` pixels instead of scanlines.
        tile_size: tile edge in pixels (≥ 1).
        compression: ``"zips"`` or ``"none"``.
        float_format: ``"float"`` or ``"half"`` for RGBA (depth is float32).
        progress: called with the fraction of values handed to OpenImageIO.
        atomic: True: through a temporary file renamed over ``path`` on success. False: straight
            into ``path``, for a caller whose ``path`` is its own temporary file (e.g.
            ``addon.batch_files.atomic_target``, which names it after the job and checks it first).

    Raises:
        ValueError: not ``.exr``, bad options.
        OSError: the file cannot be written (OpenImageIO's message); ``path`` is unchanged.
    """
    path = os.fspath(path)
    if not isinstance(image, DeepImage):
        raise TypeError(f"image: expected a DeepImage, got {type(image).__name__}")
    if os.path.splitext(path)[1].lower() != ".exr":
        raise ValueError(f"path: deep images are written as OpenEXR; expected a .exr path, got {path!r}")
    if compression not in COMPRESSIONS:
        raise ValueError(
            f"compression: expected one of {COMPRESSIONS} (deep OpenEXR through OpenImageIO), "
            f"got {compression!r}"
        )
    if isinstance(tile_size, bool) or not isinstance(tile_size, int) or tile_size < 1:
        raise ValueError(f"tile_size: expected an integer >= 1, got {tile_size!r}")
    h, w = image.shape
    if h == 0 or w == 0:
        raise ValueError(f"image: OpenEXR cannot hold an image without pixels, got shape {(h, w)}")
    dd = to_deepdata(image, float_format=float_format, progress=progress)
    spec = oiio.ImageSpec(w, h, len(CHANNELS), oiio.FLOAT)
    spec.channelnames = CHANNELS
    if float_format == "half":
        spec.channelformats = (oiio.HALF,) * 4 + (oiio.FLOAT,) * 2
    spec.deep = True
    spec.alpha_channel = 3
    spec.z_channel = 4
    spec.attribute("compression", compression)
    if tiled:
        spec.tile_width = spec.tile_height = tile_size
    write_atomic(path, spec, lambda out: out.write_deep_image(dd), atomic=atomic)


def read_deep(path: str | os.PathLike, *, progress: Callable[[float], None] | None = None) -> DeepImage:
    """Read a deep OpenEXR file (scanline or tiled) as a :class:`DeepImage`.

    Raises:
        OSError: the file cannot be opened or read (OpenImageIO's message).
        ValueError: the file is flat, lacks a required channel, or holds values that are not
            a valid deep image.
    """
    path = os.fspath(path)
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise OSError(f"path: cannot open {path!r}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        if not spec.deep:
            raise ValueError(
                f"path: {path!r} is a flat image, not a deep one; read it with compositing.io.read_image"
            )
        dd = inp.read_native_deep_image(0, 0)
        if dd is None or not dd.initialized():
            raise OSError(f"path: cannot read {path!r}: {inp.geterror()}")
    finally:
        inp.close()
    return from_deepdata(dd, spec.height, spec.width, source=path, progress=progress)
