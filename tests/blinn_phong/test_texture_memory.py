"""Texture size: oversized images refused up front, construction without full-size float64 copies.

* The limit (``blinn_phong.model.texture.check_texture_size``): a texture stores 16 bytes per texel
  (float32 RGBA) and may take at most half the physical memory; a larger one is refused
  before anything is allocated, the message naming the field, the size, the bytes needed and
  the limit. A zero-stride ``np.broadcast_to`` view stands for a huge image without memory.
* Construction converts the image block by block (``BLOCK_TEXELS`` texels), so the allocations
  traced by ``tracemalloc`` (numpy reports its buffers to it) peak at the stored image plus a
  few block-sized arrays — before, a float32 RGBA image took 7.5× the stored size (float64
  copies of the whole image).
* The blocks must not change the values: compared with the conversion written out here on the
  whole image in float64 (IEC 61966-2-1 EOTF, straight → premultiplied), rounded once to float32.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from blinn_phong.model.texture import BLOCK_TEXELS, Texture, check_texture_size


def test_oversized_texture_is_refused_before_allocating() -> None:
    side = 1 << 20  # 2^40 texels: 16 TiB as float32 RGBA, more than any machine's memory
    huge = np.broadcast_to(np.zeros(4, np.float32), (side, side, 4))  # no memory behind it
    tracemalloc.start()
    try:
        with pytest.raises(ValueError) as refused:
            Texture(huge)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    message = str(refused.value)
    assert message.startswith("Texture.image:")
    assert f"{side} × {side}" in message
    assert f"{side * side * 16} bytes" in message  # the bytes needed: 16 per texel
    assert "at most 50%" in message
    assert peak < 1 << 20  # refused up front: nothing image-sized was allocated


def test_limit_is_half_the_memory() -> None:
    # 8192² texels × 16 bytes = 2^30 bytes: accepted with 2^31 bytes of memory, refused with less.
    check_texture_size(8192, 8192, memory=1 << 31)
    with pytest.raises(ValueError, match=r"8192 × 8192 texture needs .*1073741824 bytes.*1073741823 bytes"):
        check_texture_size(8192, 8192, memory=(1 << 31) - 2)


def srgb_eotf(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1:1999: c/12.92 up to 0.04045, else ((c + 0.055)/1.055)^2.4."""
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


@pytest.mark.parametrize(
    "kwargs", [{}, {"colorspace": "sRGB", "alpha": "straight"}], ids=["linear-premultiplied", "srgb-straight"]
)
def test_construction_peak_is_the_stored_image_plus_blocks(kwargs: dict) -> None:
    n = 2048  # a 64 MiB texture; 7.5× (480 MiB) before
    rng = np.random.default_rng(1)
    image = rng.random((n, n, 4), dtype=np.float32)
    image[..., :3] *= image[..., 3:4]
    stored = n * n * 16
    tracemalloc.start()
    try:
        Texture(image, **kwargs)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    block = BLOCK_TEXELS * 4 * 8  # one float64 RGBA block
    # The stored image, plus at most four float64 blocks of work (measured: 1 MiB for the
    # linear premultiplied input, 27 MiB with the sRGB decode).
    assert peak <= stored + 4 * block, (peak / stored, (peak - stored) / 2**20)


@pytest.mark.parametrize("shape", [(700, 600), (1, BLOCK_TEXELS + 1000)], ids=["row-blocks", "wide-row"])
def test_blocks_do_not_change_the_values(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(2)
    image = rng.random((*shape, 4))  # float64, straight sRGB, several blocks
    image[..., 3] = np.round(image[..., 3] * 4) / 4  # alpha 0 included
    got = Texture(image, colorspace="sRGB", alpha="straight").image
    alpha = image[..., 3:4]
    expected = np.concatenate([srgb_eotf(image[..., :3]) * alpha, alpha], -1).astype(np.float32)
    np.testing.assert_array_equal(got, expected)  # both round the float64 value once
    # An error in the last block is reported with the count over the whole image.
    image[-1, -1, 0] = np.nan
    image[0, 0, 1] = np.inf
    with pytest.raises(ValueError, match=rf"got 2 NaN/Inf of {image.size}"):
        Texture(image)


def test_compiled_texture_stage_does_not_copy_the_texture() -> None:
    """The compiled stage reads the stored image itself (it used to concatenate a copy per band)."""
    pytest.importorskip("numba")
    import blinn_phong as bp
    from blinn_phong.frame.texturing import texture_fragments

    n = 1024  # 16 MiB stored
    texture = Texture(np.random.default_rng(3).random((n, n, 3), dtype=np.float32), interpolation="closest")
    material = bp.Material(emission=(1, 1, 1), base_color_texture=texture)
    pos = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    mesh = bp.Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]]), material=material, uv=uv)
    camera = bp.Camera(bp.look_at((0, 0, 2), (0, 0, 0)), bp.orthographic_matrix(-1, 1, -1, 1, 0.5, 5))
    prepared = bp.prepare_scene(bp.Scene([mesh], [], camera))
    fragments = bp.rasterize(prepared.clip, prepared.triangles, 16, 16)
    shaded = bp.shade_fragments(prepared, fragments, engine="numpy")
    texture_fragments(prepared, fragments, shaded, engine="numba")  # compile / load the kernel
    tracemalloc.start()
    try:
        out = texture_fragments(prepared, fragments, shaded, engine="numba")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < texture.image.nbytes // 8, peak
    # The emissive quad shows the texel under each pixel centre (closest): a texel lookup happened.
    ref = texture_fragments(prepared, fragments, shaded, engine="numpy")
    np.testing.assert_allclose(out.rgb, ref.rgb, rtol=0, atol=1e-12)
