"""The add-on's Image Texture mapping (``addon.textures.texture_from_pixels``), without ``bpy``.

What Cycles gives for an Image Texture node (Blender 5.0.1, measured with one-sample renders of
the node's Color output through an Emission shader, and of a Principled BSDF fed by it, in
``tests/blinn_phong/test_texture_vs_cycles.py``): an image is held with associated alpha — a
straight byte image's stored values multiplied by their alpha *before* its colour space is
decoded, a float buffer as it is — and the Color output is unassociated only when the Alpha output
is linked. With Clip, a lookup outside the image is (0, 0, 0, 0). So:

* Color → Base Color only: the colour is ``decode(c·a)`` (straight byte image) or the stored
  colour (float image), the texel alpha does not touch the opacity, and outside a Clip image the
  surface is opaque and black;
* Color and Alpha linked: the straight colour ``decode(c)`` and the opacity ``a``;
* Alpha only: the opacity ``a`` (0 outside a Clip image), the colour white.

The sRGB decode is the IEC 61966-2-1 EOTF, written out here. Byte values are chosen so that
``c·a`` is itself a multiple of 1/255 (no rounding on Cycles' side).
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from addon.textures import texture_from_pixels

# A 1×2 byte image (top-down): texel 0 straight (255, 0, 255) at alpha 102/255, texel 1 opaque.
BYTES = np.array([[[255, 0, 255, 102], [51, 153, 204, 255]]], np.float32) / 255.0
FLOAT = np.array([[[0.4, 0.2, 0.1, 0.5], [0.3, 0.6, 0.9, 1.0]]], np.float32)  # associated


def srgb_eotf(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1:1999: c/12.92 up to 0.04045, else ((c + 0.055)/1.055)^2.4."""
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


def convert(pixels: np.ndarray, *, base: bool, alpha: bool, is_float: bool = False, mode: str = "STRAIGHT"):
    notes: list[str] = []
    texture = texture_from_pixels(
        pixels,
        is_float=is_float,
        colorspace="sRGB",
        alpha_mode=mode,
        interpolation="Closest",
        extension="CLIP",
        base=base,
        alpha=alpha,
        notes=notes,
    )
    return texture, notes


# Texel centres (u = 0.25, 0.75 at v = 0.5) and two points outside the Clip image.
UV = np.array([[0.25, 0.5], [0.75, 0.5], [-0.3, 0.5], [0.5, 1.7]])


def test_color_only_is_the_associated_colour_and_opaque_outside_a_clip_image() -> None:
    texture, _ = convert(BYTES, base=True, alpha=False)
    got = texture.sample(UV)
    straight, a = BYTES[0, :, :3].astype(np.float64), BYTES[0, :, 3:4].astype(np.float64)
    np.testing.assert_allclose(got[:2, :3], srgb_eotf(straight * a), rtol=0, atol=1e-6)
    np.testing.assert_array_equal(got[:, 3], 1.0)  # the texel alpha never reaches the opacity
    np.testing.assert_array_equal(got[2:, :3], 0.0)  # Clip: black outside the image
    assert texture.min_alpha == 1.0  # the material stays opaque for the planner


def test_color_only_float_image_is_its_stored_colour() -> None:
    texture, _ = convert(FLOAT, base=True, alpha=False, is_float=True)
    got = texture.sample(UV)
    np.testing.assert_allclose(got[:2], np.concatenate([FLOAT[0, :, :3], np.ones((2, 1))], -1), atol=1e-7)
    np.testing.assert_array_equal(got[2:], [[0, 0, 0, 1], [0, 0, 0, 1]])


def test_color_and_alpha_give_the_straight_colour_and_the_alpha() -> None:
    texture, _ = convert(BYTES, base=True, alpha=True)
    got = texture.sample(UV)
    a = BYTES[0, :, 3:4].astype(np.float64)
    expected = np.concatenate([srgb_eotf(BYTES[0, :, :3]) * a, a], -1)  # premultiplied lookup
    np.testing.assert_allclose(got[:2], expected, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(got[2:], 0.0)  # Clip: transparent outside
    floats, _ = convert(FLOAT, base=True, alpha=True, is_float=True)
    np.testing.assert_allclose(floats.sample(UV)[:2], FLOAT[0], atol=1e-7)  # associated stays so


def test_alpha_only_is_white_with_the_texel_alpha() -> None:
    texture, _ = convert(BYTES, base=False, alpha=True)
    got = texture.sample(UV)
    a = BYTES[0, :, 3].astype(np.float64)
    np.testing.assert_allclose(got[:2], np.stack([a, a, a, a], -1), atol=1e-7)  # premultiplied white
    np.testing.assert_array_equal(got[2:], 0.0)


def test_channel_packed_keeps_colour_and_alpha_apart() -> None:
    texture, _ = convert(BYTES, base=True, alpha=True, mode="CHANNEL_PACKED")
    got = texture.sample(UV)
    np.testing.assert_allclose(got[:2, 3], BYTES[0, :, 3], atol=1e-7)
    colour = got[:2, :3] / got[:2, 3:4]
    np.testing.assert_allclose(colour, srgb_eotf(BYTES[0, :, :3]), atol=1e-6)  # not multiplied by alpha


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_color_only_clip_plane_renders_opaque_black_outside_the_image(engine: str) -> None:
    """The reported case: an emissive plane whose uv run past the Clip image (both engines)."""
    opaque = BYTES.copy()
    opaque[..., 3] = 1.0
    texture, _ = convert(opaque, base=True, alpha=False)
    pos = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    uv = np.array([[-0.5, -0.5], [1.5, -0.5], [1.5, 1.5], [-0.5, 1.5]])  # the image: the middle half
    material = bp.Material(
        ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(1, 1, 1), base_color_texture=texture
    )
    mesh = bp.Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]]), material=material, uv=uv)
    camera = bp.Camera(bp.look_at((0, 0, 2), (0, 0, 0)), bp.orthographic_matrix(-1, 1, -1, 1, 0.5, 5))
    out = bp.render(bp.Scene([mesh], [], camera, ambient=(0.0, 0.0, 0.0)), 8, 8, engine=engine).rgba
    np.testing.assert_array_equal(out[..., 3], 1.0)  # opaque everywhere (was 0 outside the image)
    inside = np.zeros((8, 8), bool)
    inside[2:6, 2:6] = True  # pixel centres with uv in (0, 1)
    np.testing.assert_array_equal(out[~inside][:, :3], 0.0)  # black outside
    left, right = srgb_eotf(opaque[0, 0, :3]), srgb_eotf(opaque[0, 1, :3])
    np.testing.assert_allclose(out[2:6, 2:4, :3], np.broadcast_to(left, (4, 2, 3)), atol=1e-6)
    np.testing.assert_allclose(out[2:6, 4:6, :3], np.broadcast_to(right, (4, 2, 3)), atol=1e-6)
