"""Image files to and from the package convention (linear, premultiplied, float RGBA, row 0 at the top).

Reading and writing go through OpenImageIO; the sRGB transfer functions are
colour-science's (IEC 61966-2-1:1999, ``colour.models.eotf_sRGB`` and
``eotf_inverse_sRGB``).

* **Float files** (EXR, float TIFF, HDR) hold linear premultiplied RGBA and are
  taken as they are.
* **8/16-bit files** (PNG, TIFF, JPEG) hold sRGB-encoded colour with straight
  alpha: reading decodes the colour to linear and premultiplies; writing
  unpremultiplies (α = 0 keeps its colour), encodes and quantises (round to
  nearest). OpenImageIO's own alpha association is turned off
  (``oiio:UnassociatedAlpha``) so it never premultiplies encoded values.
* Channels are chosen by name, never guessed from their count. Alpha is the
  file's declared alpha channel (OpenImageIO's ``spec.alpha_channel``) or a
  channel named ``A``/``alpha``; without one alpha is 1 (opaque), not 0. Colour is
  the channels named ``R``, ``G``, ``B`` of one layer (``layer.R`` ...: the alpha channel's layer first, then
  file order, so layers are never mixed); failing that, a single remaining channel
  is grey and two or more fill R, G (and B) in file order, B = 0 when only two.
  Whenever channels are ignored or not named R, G, B (an ``R,G,B,Z`` EXR, a
  ``U,V`` file) :func:`read_image` warns (``UserWarning``) saying which channels
  it read; :func:`image_channels` gives the same mapping without reading pixels.
* JPEG and Radiance HDR (RGBE) have no alpha: writing one stores the premultiplied
  colour (the image over black) and needs alpha to be dropped explicitly with
  ``flatten=True``. RGBE cannot hold negative colour either (refused unless
  ``clip=True``).
* Every write is atomic (:mod:`compositing._atomic`): the file is written next to
  the target under a temporary name and renamed over it only after a successful
  close, so a failed write (full disk, bad value, killed process) leaves an
  existing file byte-for-byte intact.
* Float files are written and read as they are, even with alpha above 1 (the
  result of ``plus``, say). Values an integer file cannot hold (alpha outside
  [0, 1], straight colour above 1 or below 0) raise a ValueError unless
  ``clip=True`` asks for clipping (alpha first, then the straight colour).
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import OpenImageIO as oiio  # noqa: N813 (the name OpenImageIO documents)

from ._atomic import atomic_path
from .alpha import premultiply, unpremultiply
from .validate import as_rgba, check_alpha_range

__all__ = [
    "FLOAT_EXTENSIONS",
    "INTEGER_EXTENSIONS",
    "ChannelMap",
    "image_channels",
    "read_image",
    "write_atomic",
    "write_image",
]


def _srgb():
    """colour-science's sRGB EOTF and inverse, imported on first use (the package is slow to import)."""
    from colour.models import eotf_inverse_sRGB, eotf_sRGB

    return eotf_sRGB, eotf_inverse_sRGB


#: Extensions written as linear premultiplied float.
FLOAT_EXTENSIONS = (".exr", ".hdr")
#: Extensions written as sRGB-encoded straight alpha, 8 or 16 bits.
INTEGER_EXTENSIONS = (".png", ".tif", ".tiff", ".jpg", ".jpeg")


@dataclass(frozen=True)
class ChannelMap:
    """Which file channels :func:`read_image` reads as R, G, B and A.

    Attributes:
        names: the file's channel names, in file order.
        rgb: three channel indices for R, G, B; ``-1`` means 0 (B of a two-channel file).
        alpha: the alpha channel's index, or None (alpha = 1).
        ignored: indices of channels not read.
        guessed: True when the colour channels are not named R, G, B (taken by position).
    """

    names: tuple[str, ...]
    rgb: tuple[int, int, int]
    alpha: int | None
    ignored: tuple[int, ...]
    guessed: bool

    def describe(self) -> str:
        """One line, e.g. ``"R←R, G←G, B←B; alpha = 1 (no alpha channel); ignored: Z"``."""
        parts = [
            f"{target}←{self.names[i] if i >= 0 else '0'}" for target, i in zip("RGB", self.rgb, strict=True)
        ]
        text = ", ".join(parts) + "; "
        if self.alpha is not None:
            text += f"A←{self.names[self.alpha]}"
        else:
            text += "alpha = 1 (no alpha channel declared)"
        if self.ignored:
            text += "; ignored: " + ", ".join(self.names[i] for i in self.ignored)
        return text


def _channel_map(names: tuple[str, ...], declared_alpha: int, path: str) -> ChannelMap:
    """The channel mapping of a file with channel ``names`` and OIIO's ``alpha_channel``."""
    c = len(names)
    lower = [n.rsplit(".", 1)[-1].lower() for n in names]  # "Combined.R" (a layered EXR) counts as R
    if 0 <= declared_alpha < c:
        alpha: int | None = declared_alpha
    else:
        named = [i for i, n in enumerate(lower) if n in ("a", "alpha")]
        alpha = named[0] if named else None
    rest = [i for i in range(c) if i != alpha]
    # R, G, B of one layer ("Combined.R" ... or unprefixed): alpha's layer first, then file order,
    # so a multilayer EXR never mixes one layer's colour with another layer's alpha.
    layers = [n.rsplit(".", 1)[0] if "." in n else "" for n in names]
    order = ([layers[alpha]] if alpha is not None else []) + layers
    rgb_layer = next(
        (
            layer
            for layer in order
            if all(any(layers[i] == layer and lower[i] == k for i in rest) for k in ("r", "g", "b"))
        ),
        None,
    )
    guessed = False
    if rgb_layer is not None:
        by_name = {lower[i]: i for i in reversed(rest) if layers[i] == rgb_layer}  # first wins
        rgb = (by_name["r"], by_name["g"], by_name["b"])
        if not 0 <= declared_alpha < c and ("a" in by_name or "alpha" in by_name):
            alpha = by_name.get("a", by_name.get("alpha"))  # the colour layer's own alpha
    elif len(rest) == 1:
        rgb = (rest[0],) * 3
        guessed = lower[rest[0]] not in ("y", "l", "grey", "gray", "luminance", "i")
    elif len(rest) >= 2:
        rgb = (rest[0], rest[1], rest[2] if len(rest) > 2 else -1)
        guessed = True
    else:
        raise ValueError(f"path: cannot read {path!r}: no colour channel among {list(names)} (only alpha)")
    used = {i for i in rgb if i >= 0} | ({alpha} if alpha is not None else set())
    ignored = tuple(i for i in range(c) if i not in used)
    return ChannelMap(tuple(names), rgb, alpha, ignored, guessed)


def _channel_names(spec) -> tuple[str, ...]:
    names = tuple(spec.channelnames)
    if len(names) != spec.nchannels:  # a format without names: OIIO's defaults
        names = tuple(f"channel{i}" for i in range(spec.nchannels))
    return names


def image_channels(path: str | os.PathLike) -> ChannelMap:
    """The channels :func:`read_image` would read from ``path`` as R, G, B, A (no pixels read).

    Raises:
        OSError: the file cannot be opened.
        ValueError: the file has no colour channel.
    """
    path = os.fspath(path)
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise OSError(f"path: cannot open {path!r}: {oiio.geterror()}")
    try:
        spec = inp.spec()
    finally:
        inp.close()
    return _channel_map(_channel_names(spec), spec.alpha_channel, path)


def _to_rgba(pixels: np.ndarray, mapping: ChannelMap) -> np.ndarray:
    """Arrange ``(H, W, C)`` pixels as float32 RGBA following ``mapping``."""
    h, w, _ = pixels.shape
    out = np.empty((h, w, 4), np.float32)
    for k, i in enumerate(mapping.rgb):
        out[..., k] = pixels[..., i] if i >= 0 else 0.0
    out[..., 3] = pixels[..., mapping.alpha] if mapping.alpha is not None else 1.0
    return out


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as linear premultiplied float32 RGBA ``(H, W, 4)``, row 0 at the top.

    8/16-bit files are decoded from sRGB (straight alpha) and premultiplied;
    float files are taken as linear premultiplied. Channels are chosen by name (module
    docstring): alpha is the declared alpha channel or one named ``A``/``alpha``, else 1;
    a ``UserWarning`` says which channels were read when some are ignored or the colour
    channels are not named R, G, B.

    Raises:
        OSError: the file cannot be opened or read (OpenImageIO's message).
        ValueError: no colour channel, or non-finite values in a float file.
    """
    path = os.fspath(path)
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        raise OSError(f"path: cannot open {path!r}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        if pixels is None:
            raise OSError(f"path: cannot read {path!r}: {inp.geterror()}")
    finally:
        inp.close()
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    mapping = _channel_map(_channel_names(spec), spec.alpha_channel, path)
    if mapping.guessed or mapping.ignored:
        warnings.warn(f"{path}: read {mapping.describe()}", UserWarning, stacklevel=2)
    rgba = _to_rgba(pixels, mapping)
    if spec.format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE):
        return as_rgba(rgba, f"pixels of {path}")
    rgba[..., :3] = _srgb()[0](rgba[..., :3])
    return premultiply(rgba)


def write_image(
    path: str | os.PathLike,
    rgba: np.ndarray,
    *,
    bits: int = 8,
    clip: bool = False,
    flatten: bool = False,
    float_format: str = "float",
) -> None:
    """Write linear premultiplied RGBA ``(H, W, 4)`` to a file chosen by extension.

    Args:
        path: output file; ``.exr``/``.hdr`` are written linear premultiplied
            float, ``.png``/``.tif``/``.tiff``/``.jpg``/``.jpeg`` sRGB-encoded
            straight alpha.
        rgba: the image, float32/float64, finite (alpha in [0, 1] for integer files).
        bits: 8 or 16 for integer files (JPEG: 8 only).
        clip: for an integer file, clip alpha and then straight colour to [0, 1]
            instead of raising.
        flatten: required for JPEG and ``.hdr`` (Radiance RGBE), which have no
            alpha channel: stores the premultiplied colour, i.e. the image over black.
        float_format: ``"float"`` (exact) or ``"half"`` for EXR.

    The file is written under a temporary name in the same directory and renamed
    over ``path`` only after a successful close: a failed write leaves an existing
    ``path`` untouched.

    Raises:
        ValueError: bad image, unknown extension, bad ``bits``, JPEG/HDR without
            ``flatten``, colour outside [0, 1] for an integer file (or negative for
            HDR) without ``clip``.
        OSError: the file cannot be written (OpenImageIO's message); ``path`` is unchanged.
    """
    path = os.fspath(path)
    img = as_rgba(rgba, "rgba", allow_scalar_colour=False)
    if img.ndim != 3:
        raise ValueError(f"rgba: expected an image of shape (H, W, 4), got {img.shape}")
    ext = os.path.splitext(path)[1].lower()
    if ext not in FLOAT_EXTENSIONS + INTEGER_EXTENSIONS:
        raise ValueError(
            f"path: unsupported extension {ext!r}; expected one of {FLOAT_EXTENSIONS + INTEGER_EXTENSIONS}"
        )
    if ext in FLOAT_EXTENSIONS:
        if float_format not in ("float", "half"):
            raise ValueError(f"float_format: expected 'float' or 'half', got {float_format!r}")
        fmt = oiio.FLOAT if float_format == "float" else oiio.HALF
        channels = img.astype(np.float32)
        names = ("R", "G", "B", "A")
        if ext == ".hdr":  # RGBE has no alpha and no sign: store the image over black
            if not flatten:
                raise ValueError(
                    "flatten: Radiance HDR (RGBE) has no alpha; pass flatten=True to store the image "
                    "over black, or write .exr to keep alpha"
                )
            negative = channels[..., :3] < 0
            if negative.any():
                if not clip:
                    raise ValueError(
                        f"rgba: {int(np.count_nonzero(negative.any(axis=-1)))} pixels have negative colour "
                        f"(min {float(channels[..., :3].min()):.6g}), which RGBE cannot hold; "
                        "pass clip=True to clip to 0, or write .exr"
                    )
                channels = np.maximum(channels, 0.0)
            channels, names = channels[..., :3], names[:3]
        _write(path, np.ascontiguousarray(channels), names, fmt, unassociated=False)
        return
    if bits not in (8, 16) or (bits == 16 and ext in (".jpg", ".jpeg")):
        raise ValueError(f"bits: expected 8 or 16 (JPEG: 8), got {bits!r}")
    if clip:
        img = img.astype(np.float64)
        img[..., 3] = np.clip(img[..., 3], 0.0, 1.0)
    try:
        check_alpha_range(img, "rgba")
    except ValueError as exc:
        raise ValueError(f"{exc}; a {bits}-bit file cannot hold it: pass clip=True to clip") from None
    if ext in (".jpg", ".jpeg"):
        if not flatten:
            raise ValueError("flatten: JPEG has no alpha; pass flatten=True to store the image over black")
        straight = img[..., :3].astype(np.float64)
        names: tuple[str, ...] = ("R", "G", "B")
    else:
        straight = unpremultiply(img, "keep").astype(np.float64)
        names = ("R", "G", "B", "A")
    colour_part = straight[..., :3]
    outside = (colour_part < 0) | (colour_part > 1)
    if outside.any():
        if not clip:
            raise ValueError(
                f"rgba: {int(np.count_nonzero(outside.any(axis=-1)))} pixels have straight colour outside "
                f"[0, 1] (range [{colour_part.min():.6g}, {colour_part.max():.6g}]), which a {bits}-bit "
                "file cannot hold; pass clip=True to clip"
            )
        straight[..., :3] = np.clip(colour_part, 0.0, 1.0)
    straight[..., :3] = _srgb()[1](straight[..., :3])
    scale = 255 if bits == 8 else 65535
    dtype, fmt = (np.uint8, oiio.UINT8) if bits == 8 else (np.uint16, oiio.UINT16)
    quantised = np.rint(straight * scale).astype(dtype)
    _write(path, np.ascontiguousarray(quantised), names, fmt, unassociated=True)


def _write(path: str, pixels: np.ndarray, names: tuple[str, ...], fmt, *, unassociated: bool) -> None:
    """Write ``pixels`` with OpenImageIO to a temporary file, then rename it over ``path``."""
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    spec.channelnames = names
    spec.alpha_channel = 3 if c == 4 else -1
    if unassociated:
        spec.attribute("oiio:UnassociatedAlpha", 1)
    write_atomic(path, spec, lambda out: out.write_image(pixels))


def write_atomic(
    path: str | os.PathLike, spec: object, write: Callable[[object], bool], *, atomic: bool = True
) -> None:
    """Open an OpenImageIO output with ``spec`` on a temporary file, ``write(output)``, close it and
    rename it over ``path``; any failure raises ``OSError`` naming ``path`` and leaves ``path`` as
    it was (:func:`compositing._atomic.atomic_path`).

    ``atomic=False`` writes ``path`` itself: for a caller whose ``path`` is already a temporary
    file of its own (it then owns what a failure leaves there)."""
    with atomic_path(path) if atomic else contextlib.nullcontext(os.fspath(path)) as tmp:
        out = oiio.ImageOutput.create(tmp)
        if out is None:
            raise OSError(f"path: cannot create {path!r}: {oiio.geterror()}")
        try:
            if not out.open(tmp, spec):
                raise OSError(f"path: cannot open {path!r} for writing: {out.geterror()}")
            if not write(out):
                raise OSError(f"path: cannot write {path!r}: {out.geterror()}")
        finally:
            closed = out.close()
        if not closed:
            raise OSError(f"path: cannot finish writing {path!r}: {out.geterror()}")
