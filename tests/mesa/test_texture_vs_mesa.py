"""Image textures against Mesa llvmpipe: fixed-function lighting with a ``GL_MODULATE`` texture.

A lit plane, tilted away from a perspective camera, its texture coordinates running past
[0, 1] so every wrap mode is exercised, is rendered by ``blinn_phong.frame.render(gl_compat=True,
shading="gouraud")`` and by Mesa (``oracles.gl_texture``: the same lights and materials,
per-vertex lighting, ``GL_SEPARATE_SPECULAR_COLOR``) from the same Scene.

Compared: the premultiplied 8-bit colour (GL writes straight colour and alpha; its readback
is premultiplied as ``floor(c·a/255 + 0.5)``) on interior pixels, i.e.

* pixel centre ≥ 1/16 pixel from every edge of its triangle (the rule of
  test_renderer_vs_mesa.py: coverage cannot depend on the fill rule there), and
* for ``GL_NEAREST`` only, the pixel's texel coordinate ``(u·W, v·H)`` ≥ 1/64 texel from a
  texel boundary: llvmpipe interpolates ``uv`` in float32, which moves a boundary by about
  1e-5 texel at this size, so a pixel closer than that may pick the neighbour texel (a
  difference of a whole texel, not a rounding).

Tolerance: 1/255 per channel. The colour is computed in float by both (ours in float64),
then rounded to 8 bits: one rounding step. With ``GL_LINEAR`` on an ``GL_RGBA8`` texture
llvmpipe blends in 8-bit fixed point with 8-bit weights (the weight is rounded to a
multiple of 1/256: an error up to 1/512 of the difference of two texels, i.e. up to half an
8-bit step on the texel, before lighting scales it by < 1): measured 1 step at most on this
scene, and 0 with a ``GL_RGBA32F`` texture, which llvmpipe filters in float (checked below).
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.texture import Texture
from oracles.gl_common import to_unorm8
from tests.blinn_phong import renderer_scenes
from tests.pixels import interior_mask

pytestmark = pytest.mark.mesa

SIZE = 96
TEXELS = 8


GL_ORACLE = "gl_texture"  # the gl fixture (tests/conftest.py)


def byte_image(seed: int, *, alpha: bool = False) -> np.ndarray:
    """A random TEXELS² RGBA image of multiples of 1/255 (exact in GL_RGBA8), row 0 at the top."""
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, (TEXELS, TEXELS, 4)).astype(np.float64) / 255.0
    img[..., 3] = rng.integers(0, 256, (TEXELS, TEXELS)) / 255.0 if alpha else 1.0
    return img


def plane_scene(texture: Texture, *, specular: float = 0.3, alpha_clip: float | None = None) -> bp.Scene:
    """A 4×4-quad plane tilted 57° from the view, uv from about −0.4 to 1.4 (float32-exact)."""
    n = 4
    xs = np.linspace(-1.0, 1.0, n + 1)
    gx, gy = np.meshgrid(xs, xs)
    positions = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], -1)
    uv = np.stack([0.9 * gx.ravel() + 0.53, 0.9 * gy.ravel() + 0.57], -1)
    tris = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            tris += [(a, a + 1, a + n + 2), (a, a + n + 2, a + n + 1)]
    c, s = np.cos(-1.0), np.sin(-1.0)
    tilt = np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])
    material = bp.Material(
        ambient=(0.2, 0.2, 0.2),
        diffuse=(0.8, 0.75, 0.7),
        specular=(specular,) * 3,
        shininess=20.0,
        emission=(0.02, 0.0, 0.0),
        base_color_texture=texture,
        alpha_clip=alpha_clip,
    )
    mesh = bp.Mesh(
        np.float32(positions).astype(float),
        np.array(tris),
        np.tile([0.0, 0.0, 1.0], (len(positions), 1)),
        transform=tilt,
        material=material,
        uv=np.float32(uv).astype(float),
    )
    camera = bp.Camera(bp.look_at((0.2, 0.3, 2.2), (0, 0, 0)), bp.perspective_matrix(50.0, 1.0, 0.5, 10.0))
    light = bp.DirectionalLight((-0.3, -0.5, -1.0), diffuse=(0.7, 0.7, 0.7), specular=(0.6, 0.6, 0.6))
    return bp.Scene([mesh], [light], camera, light_model=bp.LightModel(separate_specular=True))


def texel_interior(scene: bp.Scene, texture: Texture, margin: float = 1.0 / 64.0) -> np.ndarray:
    """Pixels whose centre's texel coordinates lie ≥ ``margin`` texel from a texel boundary."""
    return renderer_scenes.texel_interior(scene, texture, SIZE, SIZE, margin)


def premultiplied_gl(rgba: np.ndarray) -> np.ndarray:
    gl = rgba.astype(np.int64)
    return np.floor(gl[..., :3] * gl[..., 3:4] / 255.0 + 0.5).astype(np.int64)


def worst(ours: np.ndarray, theirs: np.ndarray, mask: np.ndarray) -> int:
    assert mask.sum() > 1000, "too few interior pixels for a meaningful comparison"
    return int(np.abs(to_unorm8(ours)[..., :3] - theirs).max(axis=-1)[mask].max())


# linear + clip blends opaque texels with the transparent border: GL filters the straight colour
# it stores, Texture the premultiplied one (no bleeding), so that pair is compared with a
# premultiplied upload in test_linear_clip_with_premultiplied_texels_matches_mesa.
MODES = [
    ("closest", "repeat"),
    ("closest", "extend"),
    ("closest", "clip"),
    ("linear", "repeat"),
    ("linear", "extend"),
]


@pytest.mark.parametrize("engine", ["numpy", "numba"])
@pytest.mark.parametrize(("interpolation", "extension"), MODES)
def test_textured_plane_matches_mesa(gl, interpolation: str, extension: str, engine: str) -> None:
    texture = Texture(byte_image(1), interpolation=interpolation, extension=extension)
    scene = plane_scene(texture)
    ours = bp.render(scene, SIZE, SIZE, shading="gouraud", gl_compat=True, engine=engine).rgba
    theirs = premultiplied_gl(gl.render_textured(scene, SIZE, SIZE, fmt="rgba8").rgba)
    mask = interior_mask(scene, SIZE, SIZE)
    if interpolation == "closest":
        mask &= texel_interior(scene, texture)
    assert worst(ours, theirs, mask) <= 1


def test_linear_filter_is_exact_against_a_float_texture(gl) -> None:
    """With GL_RGBA32F llvmpipe filters in float: then not even the 8-bit weight step remains."""
    texture = Texture(byte_image(2), interpolation="linear", extension="repeat")
    scene = plane_scene(texture)
    ours = bp.render(scene, SIZE, SIZE, shading="gouraud", gl_compat=True, engine="numpy").rgba
    theirs = premultiplied_gl(gl.render_textured(scene, SIZE, SIZE, fmt="rgba32f").rgba)
    assert worst(ours, theirs, interior_mask(scene, SIZE, SIZE)) == 0


def test_texture_alpha_and_alpha_clip_match_mesa(gl) -> None:
    """Texel alpha multiplies the opacity (nearest); glAlphaFunc(GL_GEQUAL) is alpha_clip."""
    image = byte_image(3, alpha=True)
    texture = Texture(image, interpolation="closest", extension="repeat", alpha="straight")
    scene = plane_scene(texture)
    ours = bp.render(scene, SIZE, SIZE, shading="gouraud", gl_compat=True, engine="numpy").rgba
    theirs = gl.render_textured(scene, SIZE, SIZE, fmt="rgba8").rgba
    mask = interior_mask(scene, SIZE, SIZE) & texel_interior(scene, texture)
    assert worst(ours, premultiplied_gl(theirs), mask) <= 1
    assert np.abs(to_unorm8(ours)[..., 3] - theirs[..., 3])[mask].max() <= 1

    clipped = plane_scene(texture, alpha_clip=0.5)
    ours = bp.render(clipped, SIZE, SIZE, shading="gouraud", gl_compat=True, engine="numpy").rgba
    theirs = gl.render_textured(clipped, SIZE, SIZE, fmt="rgba8").rgba.astype(np.int64)
    kept = theirs[..., 3] > 0  # GL keeps the fragment (alpha ≥ 0.5) and writes its colour
    assert np.array_equal((ours[..., 3] > 0)[mask], kept[mask])
    assert (ours[..., 3][mask & kept] == 1.0).all()  # alpha_clip: kept fragments are opaque
    assert kept[mask].any() and (~kept[mask]).any()
    diff = np.abs(to_unorm8(ours)[..., :3] - theirs[..., :3]).max(axis=-1)
    assert diff[mask & kept].max() <= 1


def test_linear_clip_with_premultiplied_texels_matches_mesa(gl) -> None:
    """GL_LINEAR at the Clip border: premultiplied filtering, compared with a premultiplied upload."""
    texture = Texture(byte_image(4), interpolation="linear", extension="clip")
    scene = plane_scene(texture, specular=0.0)
    ours = bp.render(scene, SIZE, SIZE, shading="gouraud", gl_compat=True, engine="numpy").rgba
    theirs = gl.render_textured(scene, SIZE, SIZE, fmt="rgba32f", premultiplied=True).rgba
    assert worst(ours, theirs[..., :3].astype(np.int64), interior_mask(scene, SIZE, SIZE)) <= 1


def test_srgb_texture_matches_mesa_srgb8_alpha8(gl) -> None:
    """An sRGB image decoded by Texture (IEC 61966-2-1 EOTF) against GL's sRGB texture decode."""
    encoded = (byte_image(5) * 255).round().astype(np.uint8)
    for interpolation in ("closest", "linear"):
        texture = Texture(encoded / 255.0, interpolation=interpolation, colorspace="sRGB")
        scene = plane_scene(texture)
        ours = bp.render(scene, SIZE, SIZE, shading="gouraud", gl_compat=True, engine="numpy").rgba
        theirs = gl.render_textured(scene, SIZE, SIZE, fmt="srgb8_alpha8", encoded=encoded).rgba
        mask = interior_mask(scene, SIZE, SIZE)
        if interpolation == "closest":
            mask &= texel_interior(scene, texture)
        assert worst(ours, premultiplied_gl(theirs), mask) <= 1, interpolation
