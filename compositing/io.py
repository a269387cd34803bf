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
* A file without alpha gets α = 1 (opaque), not 0. Grey files become grey RGB.
* JPEG has no alpha: writing one stores the premultiplied colour (the image over
  black) and needs ``alpha`` to be dropped explicitly with ``flatten=True``.
* Float files are written and read as they are, even with alpha above 1 (the
  result of ``plus``, say). Values an integer file cannot hold (alpha outside
  [0, 1], straight colour above 1 or below 0) raise a ValueError unless
  ``clip=True`` asks for clipping (alpha first, then the straight colour).
"""

from __future__ import annotations

import os

import numpy as np
import OpenImageIO as oiio  # noqa: N813 (the name OpenImageIO documents)

from .alpha import premultiply, unpremultiply
from .validate import as_rgba, check_alpha_range

__all__ = ["FLOAT_EXTENSIONS", "INTEGER_EXTENSIONS", "read_image", "write_image"]


def _srgb():
    """colour-science's sRGB EOTF and inverse, imported on first use (the package is slow to import)."""
    from colour.models import eotf_inverse_sRGB, eotf_sRGB

    return eotf_sRGB, eotf_inverse_sRGB


#: Extensions written as linear premultiplied float.
FLOAT_EXTENSIONS = (".exr", ".hdr")
#: Extensions written as sRGB-encoded straight alpha, 8 or 16 bits.
INTEGER_EXTENSIONS = (".png", ".tif", ".tiff", ".jpg", ".jpeg")


def _to_rgba(pixels: np.ndarray, alpha_channel: int, path: str) -> tuple[np.ndarray, bool]:
    """Arrange ``(H, W, C)`` pixels as RGB + A; returns the array and whether the file had alpha."""
    h, w, c = pixels.shape
    has_alpha = 0 <= alpha_channel < c or c in (2, 4)
    a_index = alpha_channel if 0 <= alpha_channel < c else (c - 1 if c in (2, 4) else None)
    colour_channels = [i for i in range(c) if i != a_index]
    if len(colour_channels) == 1:
        rgb = np.repeat(pixels[..., colour_channels[0] : colour_channels[0] + 1], 3, axis=-1)
    elif len(colour_channels) >= 3:
        rgb = pixels[..., colour_channels[:3]]
    else:
        raise ValueError(f"path: cannot read {path!r}: expected 1-4 channels (grey, RGB, ±alpha), got {c}")
    alpha = pixels[..., a_index : a_index + 1] if a_index is not None else np.ones((h, w, 1), pixels.dtype)
    return np.concatenate([rgb, alpha], axis=-1).astype(np.float32), has_alpha


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as linear premultiplied float32 RGBA ``(H, W, 4)``, row 0 at the top.

    8/16-bit files are decoded from sRGB (straight alpha) and premultiplied;
    float files are taken as linear premultiplied. Missing alpha becomes 1.

    Raises:
        OSError: the file cannot be opened or read (OpenImageIO's message).
        ValueError: unsupported channel layout, or non-finite values in a float file.
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
    rgba, _ = _to_rgba(pixels, spec.alpha_channel, path)
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
        flatten: required for JPEG, which has no alpha channel: stores the
            premultiplied colour, i.e. the image over black.
        float_format: ``"float"`` (exact) or ``"half"`` for EXR.

    Raises:
        ValueError: bad image, unknown extension, bad ``bits``, JPEG without
            ``flatten``, or colour outside [0, 1] for an integer file without ``clip``.
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
        if ext == ".hdr":  # RGBE has no alpha: store the image over black
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
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    spec.channelnames = names
    spec.alpha_channel = 3 if c == 4 else -1
    if unassociated:
        spec.attribute("oiio:UnassociatedAlpha", 1)
    out = oiio.ImageOutput.create(path)
    if out is None:
        raise OSError(f"path: cannot create {path!r}: {oiio.geterror()}")
    try:
        if not out.open(path, spec):
            raise OSError(f"path: cannot open {path!r} for writing: {out.geterror()}")
        if not out.write_image(pixels):
            raise OSError(f"path: cannot write {path!r}: {out.geterror()}")
    finally:
        out.close()
