"""Image files: sRGB decoding against the IEC 61966-2-1 formula, files written by and read
with Pillow (an independent codec), round trips within quantisation, α = 1 when absent."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio  # noqa: N813
import pytest
from PIL import Image

from compositing import premultiply
from compositing.io import read_image, write_image


def srgb_decode(v: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1:1999 sRGB EOTF, written out."""
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def _bytes_rgba(h=6, w=7, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    px = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    px[0, 0, 3] = 0
    px[0, 1, 3] = 255
    return px


def test_png_from_pillow_is_decoded_and_premultiplied(tmp_path):
    px = _bytes_rgba()
    Image.fromarray(px, "RGBA").save(tmp_path / "a.png")
    got = read_image(tmp_path / "a.png")
    straight = np.concatenate([srgb_decode(px[..., :3] / 255.0), px[..., 3:] / 255.0], axis=-1)
    assert got.dtype == np.float32 and got.shape == (6, 7, 4)
    np.testing.assert_allclose(got, premultiply(straight), rtol=2e-6, atol=1e-7)


@pytest.mark.parametrize("mode", ["RGB", "L"])
def test_files_without_alpha_are_opaque(tmp_path, mode):
    px = _bytes_rgba()[..., :3] if mode == "RGB" else _bytes_rgba()[..., 0]
    Image.fromarray(px, mode).save(tmp_path / "a.png")
    got = read_image(tmp_path / "a.png")
    np.testing.assert_array_equal(got[..., 3], 1.0)
    want = srgb_decode((px if mode == "RGB" else px[..., None].repeat(3, -1)) / 255.0)
    np.testing.assert_allclose(got[..., :3], want, rtol=2e-6, atol=1e-7)


def test_written_png_holds_encoded_straight_bytes_top_row_first(tmp_path):
    rng = np.random.default_rng(1)
    straight = rng.random((5, 8, 4))
    straight[0] = [1.0, 0.0, 0.0, 0.5]  # top row: half-transparent red
    write_image(tmp_path / "b.png", premultiply(straight))
    px = np.asarray(Image.open(tmp_path / "b.png").convert("RGBA"))
    want = np.rint(np.concatenate([srgb_encode(straight[..., :3]), straight[..., 3:]], axis=-1) * 255)
    assert np.abs(px.astype(int) - want).max() <= 1  # unpremultiply may round across a .5 boundary
    np.testing.assert_array_equal(px[0, 0], [255, 0, 0, 128])


@pytest.mark.parametrize(
    ("ext", "bits", "step"), [("png", 8, 1 / 255), ("png", 16, 1 / 65535), ("tif", 16, 1 / 65535)]
)
def test_round_trip_within_quantisation(tmp_path, ext, bits, step):
    rng = np.random.default_rng(2)
    straight = rng.random((9, 10, 4))
    straight[..., 3] = np.maximum(straight[..., 3], 0.2)
    img = premultiply(straight).astype(np.float32)
    write_image(tmp_path / f"c.{ext}", img, bits=bits)
    back = read_image(tmp_path / f"c.{ext}").astype(np.float64)
    back_straight = back[..., :3] / back[..., 3:]
    # Compare in the encoded domain, where the file quantises: at most half a step each.
    assert (
        np.abs(srgb_encode(back_straight) - srgb_encode(straight[..., :3])).max()
        <= step * (0.5 + 1e-3) + 1e-6
    )
    assert np.abs(back[..., 3] - straight[..., 3]).max() <= step * 0.5 + 1e-7


def test_exr_round_trip_is_exact_and_keeps_hdr(tmp_path):
    rng = np.random.default_rng(3)
    img = (rng.random((4, 6, 4)) * 5).astype(np.float32)
    img[..., 3] = rng.random((4, 6)) * 2  # alpha above 1 (a 'plus' result) is kept in float files
    write_image(tmp_path / "d.exr", img)
    np.testing.assert_array_equal(read_image(tmp_path / "d.exr"), img)
    spec = oiio.ImageInput.open(str(tmp_path / "d.exr")).spec()
    assert spec.format == oiio.FLOAT and spec.channelnames == ("R", "G", "B", "A")


def test_integer_files_refuse_values_they_cannot_hold(tmp_path):
    img = np.zeros((2, 2, 4), np.float32)
    img[..., 3] = 0.5
    img[0, 0, 0] = 0.9  # straight 1.8
    with pytest.raises(ValueError, match=r"rgba: 1 pixels have straight colour outside \[0, 1\].*clip=True"):
        write_image(tmp_path / "e.png", img)
    write_image(tmp_path / "e.png", img, clip=True)
    assert np.asarray(Image.open(tmp_path / "e.png"))[0, 0, 0] == 255
    img[1, 1, 3] = 1.5
    with pytest.raises(ValueError, match=r"expected alpha .* 8-bit file cannot hold it: pass clip=True"):
        write_image(tmp_path / "e.png", img)


def test_jpeg_needs_explicit_flatten(tmp_path):
    img = np.full((8, 8, 4), 0.5, np.float32)
    with pytest.raises(ValueError, match="flatten: JPEG has no alpha"):
        write_image(tmp_path / "f.jpg", img)
    write_image(tmp_path / "f.jpg", img, flatten=True)
    back = read_image(tmp_path / "f.jpg")
    np.testing.assert_array_equal(back[..., 3], 1.0)
    assert np.abs(back[..., :3] - 0.5).max() < 0.01  # the colour over black, up to JPEG loss


def test_bad_paths_and_arguments(tmp_path):
    img = np.zeros((2, 2, 4), np.float32)
    with pytest.raises(ValueError, match=r"path: unsupported extension '\.bmp'"):
        write_image(tmp_path / "g.bmp", img)
    with pytest.raises(ValueError, match="bits: expected 8 or 16"):
        write_image(tmp_path / "g.png", img, bits=12)
    with pytest.raises(OSError, match="path: cannot open"):
        read_image(tmp_path / "missing.png")
