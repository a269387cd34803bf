"""Image textures: a :class:`Texture` and its texel lookup (no renderer dependencies).

Conventions:

* The stored image is the project's: float32 linear-light **premultiplied** RGBA, shape
  (H, W, 4), **row 0 at the top**. :class:`Texture` converts other inputs once, on
  construction (an sRGB-encoded or straight-alpha image, or an RGB image with no alpha).
* Texture coordinates follow Blender and OpenGL: ``u`` runs left → right and ``v``
  **bottom → top**: ``(0, 0)`` is the bottom-left corner of the image, ``(1, 1)`` the top
  right. OpenGL's ``t = 0`` is the first row uploaded by ``glTexImage2D``, so the image
  goes to GL flipped vertically (:meth:`Texture.gl_rows`).
* Texel ``(i, j)`` (column ``i`` from the left, ``j`` from the bottom) has its centre at
  ``((i + 0.5)/W, (j + 0.5)/H)`` (OpenGL 2.1 §3.8.8).

Filtering (OpenGL 2.1 §3.8.8, equations 3.25–3.27):

* ``"closest"`` (``GL_NEAREST``): the texel ``(floor(u·W), floor(v·H))``;
* ``"linear"`` (``GL_LINEAR``): with ``x = u·W − 0.5``, ``y = v·H − 0.5``,
  ``i0 = floor(x)``, ``α = x − i0`` (same for ``j0``, ``β``), the bilinear blend
  ``(1−α)(1−β)·T[i0,j0] + α(1−β)·T[i0+1,j0] + (1−α)β·T[i0,j0+1] + αβ·T[i0+1,j0+1]``.
  The blend is done on premultiplied texels (colour of fully transparent texels does not
  bleed); for an opaque image this is exactly GL's blend of the stored values.

Extension (wrap) of texel indices outside the image:

* ``"repeat"`` (``GL_REPEAT``): ``i mod W``. GL 2.1 §3.8.7: the integer part of the
  coordinate is ignored, so ``u`` is first reduced to ``fmod(u, 1)`` (exact in float64,
  the sign of ``u``; the index ``mod W`` then makes it ``u mod 1``). Where
  ``|u| ≥ 2^52`` float64 has no fractional bits (its spacing is ≥ 1): every such ``u``
  is an integer, ``u mod 1 = 0`` exactly, and the lookup is the one at ``u = 0``
  (closest: column 0; linear: half column ``W − 1``, half column 0).
* ``"extend"`` (``GL_CLAMP_TO_EDGE``): ``clamp(i, 0, W − 1)``;
* ``"clip"`` (Blender's *Clip*; ``GL_CLAMP_TO_BORDER`` with a transparent black border):
  texels outside the image are ``(0, 0, 0, 0)``.

  For these two, ``u`` and ``v`` are first clamped to ``[−1, 2]``: a coordinate a whole
  image outside looks up only edge (or border) texels, wherever it lies beyond, so the
  result is the same and texel indices stay small integers for any finite coordinate
  (``1e300`` included; an unclamped ``floor(u·W)`` overflows int64 above ``2^63/W``).

Alpha: with ``use_alpha=True`` (the default) a lookup returns the filtered premultiplied
RGBA. With ``use_alpha=False`` the texture is an RGB texture (OpenGL's base internal format
``RGB``: the texture contributes no alpha, §3.8.13 table 3.22, and the border colour's alpha
is dropped): a lookup returns the filtered **premultiplied** RGB with alpha 1, so a
transparent texel, and in ``"clip"`` the outside of the image, is opaque black. This is
Blender's Image Texture node when only its Color output is used: Cycles gives the Color
output associated (premultiplied) unless the Alpha output is linked.

Colour spaces of the input image: ``"linear"`` (alias ``"Linear Rec.709"``) and
``"Non-Color"`` are used as given; ``"sRGB"`` is decoded with the exact sRGB EOTF of
IEC 61966-2-1:1999 (:func:`srgb_to_linear`) before filtering, as OpenGL does for sRGB
textures (EXT_texture_sRGB: "conversion … is performed prior to filtering").

Size: a texture stores 16 bytes per texel (float32 RGBA; 8192² texels are 1 GiB) and may take
at most half the machine's physical memory (:func:`check_texture_size`, checked before
anything is allocated). Construction converts the image in blocks of
:data:`BLOCK_TEXELS` texels, so beyond the stored image it allocates only a few
block-sized work arrays (float64 only per block, for one rounding to float32).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from blinn_phong._checks import _bytes_text, choice_error, physical_memory

__all__ = [
    "ALPHAS",
    "BLOCK_TEXELS",
    "BYTES_PER_TEXEL",
    "COLORSPACES",
    "DTYPES",
    "EXTENSIONS",
    "INTERPOLATIONS",
    "MEMORY_SHARE",
    "UV_LIMIT",
    "Texture",
    "check_texture_size",
    "srgb_to_linear",
    "straight_colour",
    "texture_bytes",
]

#: OpenGL's and other tools' names for the interpolation and extension modes (for error hints).
_ALIASES = {
    "nearest": "closest",
    "gl_nearest": "closest",
    "bilinear": "linear",
    "gl_linear": "linear",
    "clamp": "extend",
    "clamp_to_edge": "extend",
    "gl_clamp_to_edge": "extend",
    "clamp_to_border": "clip",
    "gl_clamp_to_border": "clip",
    "gl_repeat": "repeat",
    "wrap": "repeat",
}

INTERPOLATIONS: tuple[str, ...] = ("closest", "linear")
EXTENSIONS: tuple[str, ...] = ("repeat", "extend", "clip")
COLORSPACES: tuple[str, ...] = ("linear", "Linear Rec.709", "Non-Color", "sRGB")
ALPHAS: tuple[str, ...] = ("premultiplied", "straight")
#: The accepted texel dtypes (half-float images, e.g. from EXR files, included).
DTYPES: tuple[np.dtype, ...] = (np.dtype(np.float16), np.dtype(np.float32), np.dtype(np.float64))
#: Bytes one stored texel takes: float32 RGBA.
BYTES_PER_TEXEL = 16
#: The share of the machine's physical memory one texture may take (a render needs the rest).
MEMORY_SHARE = 0.5
#: Texels converted per step of :class:`Texture` construction (its work arrays' size).
BLOCK_TEXELS = 1 << 18
#: ``2^53``: from here on every float64 is an even integer, so ``u mod 1 = 0`` and every
#: clamped extension is decided; the texture stage clamps interpolated coordinates to
#: ``±UV_LIMIT`` (only an interpolation overflowing to ±inf near the float64 maximum changes).
UV_LIMIT = 2.0**53


def srgb_to_linear(encoded: np.ndarray) -> np.ndarray:
    """The sRGB EOTF (IEC 61966-2-1:1999, §5.2): encoded value in [0, 1] → linear light.

    ``c/12.92`` for ``c ≤ 0.04045``, else ``((c + 0.055)/1.055)^2.4``. Computed in float64.
    """
    c = np.asarray(encoded, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


def straight_colour(premultiplied: np.ndarray) -> np.ndarray:
    """Straight (un-premultiplied) RGB of (N, 4) premultiplied RGBA; 0 where alpha is 0."""
    rgba = np.asarray(premultiplied, dtype=np.float64)
    a = rgba[:, 3:4]
    safe = np.where(a > 0.0, a, 1.0)
    return np.where(a > 0.0, rgba[:, :3] / safe, 0.0)


def texture_bytes(height: int, width: int) -> int:
    """Bytes a ``height × width`` :class:`Texture` stores (:data:`BYTES_PER_TEXEL` per texel)."""
    return int(height) * int(width) * BYTES_PER_TEXEL


def check_texture_size(height: int, width: int, memory: int | None = None) -> None:
    """Refuse a texture larger than :data:`MEMORY_SHARE` of ``memory``, before allocating it.

    Args:
        height: image rows, a positive integer.
        width: image columns, a positive integer.
        memory: bytes of memory; default: the machine's physical memory (when the OS says).

    Raises:
        ValueError: :func:`texture_bytes` above ``MEMORY_SHARE · memory``; the message names
            ``Texture.image``, the size, the bytes needed and the limit.
    """
    total = physical_memory() if memory is None else int(memory)
    if total is None:
        return
    limit = int(total * MEMORY_SHARE)
    need = texture_bytes(height, width)
    if need > limit:
        raise ValueError(
            f"Texture.image: a {height} × {width} texture needs {_bytes_text(need)} ({need} bytes: "
            f"{BYTES_PER_TEXEL} per texel, float32 RGBA) but a texture may take at most "
            f"{MEMORY_SHARE:.0%} of the {_bytes_text(total)} of memory ({limit} bytes); "
            "downscale the image"
        )


def _blocks(height: int, width: int) -> Iterator[tuple[slice, slice]]:
    """(rows, columns) slices covering the image in blocks of at most :data:`BLOCK_TEXELS`."""
    if width >= BLOCK_TEXELS:
        for r in range(height):
            for c in range(0, width, BLOCK_TEXELS):
                yield slice(r, r + 1), slice(c, c + BLOCK_TEXELS)
    else:
        rows = BLOCK_TEXELS // width
        for r in range(0, height, rows):
            yield slice(r, r + rows), slice(None)


@dataclass(frozen=True, eq=False)
class Texture:
    """An image texture sampled by ``(u, v)`` texture coordinates (see the module docstring).

    Attributes:
        image: (H, W, 4) or (H, W, 3) float16, float32 or float64 image, row 0 at the top
            (3 channels: alpha 1). After construction: the (H, W, 4) float32 linear
            premultiplied RGBA (a new array; 16 bytes per texel, at most
            :data:`MEMORY_SHARE` of the physical memory: :func:`check_texture_size`).
        interpolation: ``"closest"`` (GL_NEAREST) or ``"linear"`` (GL_LINEAR).
        extension: ``"repeat"`` (GL_REPEAT), ``"extend"`` (GL_CLAMP_TO_EDGE) or ``"clip"``
            (transparent black outside [0, 1]², Blender's Clip).
        colorspace: the colour space of the given image's RGB: ``"linear"``/``"Linear Rec.709"``
            or ``"Non-Color"`` (used as given) or ``"sRGB"`` (encoded values in [0, 1],
            decoded with :func:`srgb_to_linear`). After construction the stored image is linear.
        alpha: how the given image's RGB relates to its alpha: ``"premultiplied"`` (the
            project's convention) or ``"straight"``. sRGB encoding applies to the straight
            colour, so a premultiplied sRGB image is un-premultiplied, decoded and
            premultiplied again.
        use_alpha: True: lookups return the filtered RGBA (the texel alpha modulates the
            opacity). False: an RGB texture — lookups return the filtered premultiplied RGB
            and alpha 1 (transparent texels and the outside of a ``"clip"`` texture are opaque
            black; Blender's Image Texture with only its Color output used).

    Raises ValueError/TypeError naming the field for a wrong shape, dtype, non-finite value,
    alpha outside [0, 1], negative colour, sRGB values outside [0, 1], an unknown option, or a
    texture too large for the memory (checked before anything is allocated).
    """

    image: np.ndarray
    interpolation: str = "linear"
    extension: str = "repeat"
    colorspace: str = "linear"
    alpha: str = "premultiplied"
    use_alpha: bool = True

    def __post_init__(self) -> None:
        for name, allowed in (
            ("interpolation", INTERPOLATIONS),
            ("extension", EXTENSIONS),
            ("colorspace", COLORSPACES),
            ("alpha", ALPHAS),
        ):
            if getattr(self, name) not in allowed:
                raise choice_error(f"Texture.{name}", getattr(self, name), allowed, aliases=_ALIASES)
        if not isinstance(self.use_alpha, bool | np.bool_):
            raise TypeError(f"Texture.use_alpha: expected True or False, got {self.use_alpha!r}")
        object.__setattr__(self, "use_alpha", bool(self.use_alpha))
        arr = np.asarray(self.image)
        if arr.dtype not in DTYPES:
            raise TypeError(
                "Texture.image: expected a float16, float32 or float64 array (linear values, not "
                f"bytes: divide 8-bit data by 255), got dtype {arr.dtype}"
            )
        if arr.ndim != 3 or arr.shape[2] not in (3, 4) or arr.shape[0] < 1 or arr.shape[1] < 1:
            raise ValueError(
                f"Texture.image: expected shape (H, W, 4) or (H, W, 3), H, W >= 1, got {arr.shape}"
            )
        height, width = int(arr.shape[0]), int(arr.shape[1])
        check_texture_size(height, width)
        out = np.empty((height, width, 4), np.float32)
        stats = {"bad": 0, "alpha_min": np.inf, "alpha_max": -np.inf, "colour_min": np.inf}
        stats["srgb_max"] = -np.inf
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # reported below
            for rows, cols in _blocks(height, width):
                self._convert_block(arr[rows, cols], out[rows, cols], stats)
        if stats["bad"]:
            raise ValueError(
                f"Texture.image: expected finite values; got {stats['bad']} NaN/Inf of {arr.size}"
            )
        if stats["alpha_min"] < 0.0 or stats["alpha_max"] > 1.0:
            raise ValueError(
                f"Texture.image: expected alpha in [0, 1], got range "
                f"[{float(stats['alpha_min'])!r}, {float(stats['alpha_max'])!r}]"
            )
        if stats["colour_min"] < 0.0:
            raise ValueError(
                f"Texture.image: expected non-negative colour, got minimum {float(stats['colour_min'])!r}"
            )
        if stats["srgb_max"] > 1.0:
            raise ValueError(
                "Texture.image: sRGB-encoded (straight) colour must lie in [0, 1], "
                f"got maximum {float(stats['srgb_max'])!r}"
            )
        object.__setattr__(self, "image", out)

    def _convert_block(self, block: np.ndarray, dst: np.ndarray, stats: dict) -> None:
        """Check one block of the given image and write it converted into ``dst`` (float32 RGBA)."""
        channels = block.shape[2]
        stats["bad"] += int(block.size - np.count_nonzero(np.isfinite(block)))
        stats["colour_min"] = min(stats["colour_min"], float(block[..., :3].min()))
        if channels == 4:
            stats["alpha_min"] = min(stats["alpha_min"], float(block[..., 3].min()))
            stats["alpha_max"] = max(stats["alpha_max"], float(block[..., 3].max()))
        if self.colorspace != "sRGB" and (self.alpha == "premultiplied" or channels == 3):
            dst[..., :channels] = block  # already linear premultiplied: one cast, no float64 copy
            if channels == 3:
                dst[..., 3] = 1.0
            else:  # a fully transparent texel has no colour (its straight colour is 0)
                dst[..., :3][block[..., 3] == 0.0] = 0.0
            return
        work = block.astype(np.float64)  # one block: the result is rounded to float32 once
        a = work[..., 3:4] if channels == 4 else np.ones((*work.shape[:2], 1))
        straight = work[..., :3]
        if self.colorspace == "sRGB":
            if self.alpha == "premultiplied" and channels == 4:
                np.divide(straight, a, out=straight, where=a > 0.0)
                straight[np.broadcast_to(a <= 0.0, straight.shape)] = 0.0
            stats["srgb_max"] = max(stats["srgb_max"], float(straight.max()))
            straight = srgb_to_linear(straight)
        dst[..., :3] = straight * a
        dst[..., 3] = a[..., 0]

    @property
    def width(self) -> int:
        """W, texels per row."""
        return int(self.image.shape[1])

    @property
    def height(self) -> int:
        """H, rows."""
        return int(self.image.shape[0])

    @property
    def min_alpha(self) -> float:
        """The smallest alpha any lookup can return (0 with ``extension="clip"``; 1 without alpha)."""
        if not self.use_alpha:
            return 1.0
        if self.extension == "clip":
            return 0.0
        return float(self.image[..., 3].min())

    def gl_rows(self) -> np.ndarray:
        """The image with row 0 at the bottom (OpenGL's ``glTexImage2D`` order), C-contiguous."""
        return np.ascontiguousarray(self.image[::-1])

    def texel_coordinates(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(x, y) = (u'·W, v'·H)``, float64, with ``u', v'`` the coordinates the extension needs.

        ``"repeat"``: ``u' = fmod(u, 1) = u − trunc(u)`` (exact; the sign of ``u``), ``"extend"``/``"clip"``:
        ``u' = clamp(u, −1, 2)`` (module docstring). Either way ``|x| ≤ 2W``, ``|y| ≤ 2H``.
        """
        u, v = uv[:, 0], uv[:, 1]
        if self.extension == "repeat":
            u, v = u - np.trunc(u), v - np.trunc(v)  # fmod(·, 1), exact
        else:
            u, v = np.clip(u, -1.0, 2.0), np.clip(v, -1.0, 2.0)
        return u * self.width, v * self.height

    def _fetch(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Texels at integer column ``i`` (from the left) and row ``j`` (from the bottom), wrapped."""
        w, h = self.width, self.height
        if self.extension == "repeat":
            ii, jj, inside = np.mod(i, w), np.mod(j, h), None
        else:
            ii, jj = np.clip(i, 0, w - 1), np.clip(j, 0, h - 1)
            inside = (i >= 0) & (i < w) & (j >= 0) & (j < h) if self.extension == "clip" else None
        texels = self.image[h - 1 - jj, ii].astype(np.float64)
        if inside is not None:
            texels[~inside] = 0.0
        return texels

    def sample(self, uv: np.ndarray) -> np.ndarray:
        """Filtered texels at texture coordinates ``uv`` (N, 2): (N, 4) float64 premultiplied linear RGBA.

        ``u`` left → right, ``v`` bottom → top (module docstring); filtering and wrapping as
        ``interpolation`` and ``extension`` say (OpenGL 2.1 §3.8.7–3.8.8); any finite
        coordinate is valid. With ``use_alpha=False`` the alpha returned is 1.
        """
        coords = np.asarray(uv, dtype=np.float64)
        if coords.ndim != 2 or coords.shape[1] != 2:
            raise ValueError(f"uv: expected shape (N, 2), got {coords.shape}")
        if not np.isfinite(coords).all():
            raise ValueError("uv: expected finite texture coordinates")
        x, y = self.texel_coordinates(coords)
        if self.interpolation == "closest":
            out = self._fetch(np.floor(x).astype(np.int64), np.floor(y).astype(np.int64))
        else:
            x -= 0.5
            y -= 0.5
            i0, j0 = np.floor(x), np.floor(y)
            fa, fb = (x - i0)[:, None], (y - j0)[:, None]
            i0, j0 = i0.astype(np.int64), j0.astype(np.int64)
            out = (
                (1 - fa) * (1 - fb) * self._fetch(i0, j0)
                + fa * (1 - fb) * self._fetch(i0 + 1, j0)
                + (1 - fa) * fb * self._fetch(i0, j0 + 1)
                + fa * fb * self._fetch(i0 + 1, j0 + 1)
            )
            # A convex blend of alphas in [0, 1]: only rounding (an ulp) can leave [0, 1].
            np.clip(out[:, 3], 0.0, 1.0, out=out[:, 3])
        if not self.use_alpha:
            out[:, 3] = 1.0
        return out
