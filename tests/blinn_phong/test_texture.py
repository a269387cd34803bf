"""Texture lookup and textured rendering against closed forms.

Sources: the sRGB EOTF of IEC 61966-2-1:1999 (published values), the OpenGL 2.1 texel-centre
and filtering rules (§3.8.8: nearest texel ``floor(u·W)``, bilinear weights from
``u·W − 0.5``), and for the rendered cases the ray–plane intersection of a pixel's ray.
"""

from __future__ import annotations

import numpy as np
import pytest

import blinn_phong as bp
from blinn_phong.model.texture import Texture, srgb_to_linear

# A 2×3 (H×W) image of distinct opaque colours, row 0 at the TOP.
IMAGE = np.array(
    [
        [[0.1, 0.0, 0.0, 1.0], [0.2, 0.0, 0.0, 1.0], [0.3, 0.0, 0.0, 1.0]],
        [[0.0, 0.4, 0.0, 1.0], [0.0, 0.5, 0.0, 1.0], [0.0, 0.6, 0.0, 1.0]],
    ],
    np.float32,
)


def test_srgb_eotf_published_values() -> None:
    # IEC 61966-2-1: linear = c/12.92 below 0.04045, ((c + 0.055)/1.055)^2.4 above.
    assert srgb_to_linear(np.array([0.0, 1.0]))[0] == 0.0
    assert srgb_to_linear(np.array([1.0]))[0] == pytest.approx(1.0, abs=1e-15)
    assert srgb_to_linear(np.array([0.04045]))[0] == pytest.approx(0.0031308, abs=1e-7)
    assert srgb_to_linear(np.array([0.5]))[0] == pytest.approx(0.214041140, abs=1e-9)
    assert srgb_to_linear(np.array([128 / 255]))[0] == pytest.approx(0.2158605, abs=1e-7)


def test_closest_v_runs_bottom_to_top() -> None:
    tex = Texture(IMAGE, interpolation="closest")
    # (u, v) = (1/6, 1/4): column 0, bottom row = image row 1 (row 0 is the top).
    got = tex.sample(np.array([[1 / 6, 0.25], [5 / 6, 0.75], [0.5, 0.74]]))
    np.testing.assert_array_equal(got, IMAGE[[1, 0, 0], [0, 2, 1]].astype(np.float64))


def test_extensions_for_closest() -> None:
    uv = np.array([[1 / 6 + 1.0, 0.25 - 2.0], [-0.3, 1.7], [1.2, 0.25]])
    repeat = Texture(IMAGE, interpolation="closest", extension="repeat").sample(uv)
    np.testing.assert_array_equal(repeat[0], IMAGE[1, 0])  # (u mod 1, v mod 1) = (1/6, 1/4)
    extend = Texture(IMAGE, interpolation="closest", extension="extend").sample(uv)
    np.testing.assert_array_equal(extend[1], IMAGE[0, 0])  # left column, top row
    np.testing.assert_array_equal(extend[2], IMAGE[1, 2])  # right column, bottom row
    clip = Texture(IMAGE, interpolation="closest", extension="clip").sample(uv)
    assert (clip == 0.0).all()  # all three lie outside [0, 1]²


def test_linear_is_exact_at_texel_centres_and_bilinear_between() -> None:
    tex = Texture(IMAGE, interpolation="linear", extension="extend")
    centres = np.array([[(i + 0.5) / 3, (j + 0.5) / 2] for j in range(2) for i in range(3)])
    expected = np.array([IMAGE[1 - j, i] for j in range(2) for i in range(3)], np.float64)
    np.testing.assert_allclose(tex.sample(centres), expected, atol=1e-15)
    # Centre of the 4 lower-left texel centres: the mean of the four.
    mid = tex.sample(np.array([[1 / 3, 0.5]]))[0]
    np.testing.assert_allclose(mid, IMAGE[:, :2].reshape(4, 4).mean(axis=0), atol=1e-7)
    # A quarter of the way from texel (0, bottom) to (1, bottom), at the bottom row's centre v.
    q = tex.sample(np.array([[0.5 / 3 + 0.25 / 3, 0.25]]))[0]
    np.testing.assert_allclose(q, 0.75 * IMAGE[1, 0] + 0.25 * IMAGE[1, 1], atol=1e-7)


def test_linear_wraps_and_clip_border() -> None:
    uv = np.array([[0.0, 0.25]])  # u = 0: halfway between column 0 and the column left of it
    repeat = Texture(IMAGE, interpolation="linear", extension="repeat").sample(uv)[0]
    np.testing.assert_allclose(repeat, 0.5 * IMAGE[1, 0] + 0.5 * IMAGE[1, 2], atol=1e-7)
    extend = Texture(IMAGE, interpolation="linear", extension="extend").sample(uv)[0]
    np.testing.assert_allclose(extend, IMAGE[1, 0], atol=1e-7)
    clip = Texture(IMAGE, interpolation="linear", extension="clip").sample(uv)[0]
    np.testing.assert_allclose(clip, 0.5 * IMAGE[1, 0], atol=1e-7)  # half transparent black


def test_straight_and_srgb_inputs_become_linear_premultiplied() -> None:
    img = np.array([[[0.5, 0.5, 0.5, 0.5]]])
    straight = Texture(img, alpha="straight", colorspace="sRGB").image[0, 0]
    np.testing.assert_allclose(straight, [0.5 * 0.214041140] * 3 + [0.5], atol=1e-7)
    premul = Texture(img, alpha="premultiplied", colorspace="sRGB").image[0, 0]  # straight colour 1
    np.testing.assert_allclose(premul, [0.5, 0.5, 0.5, 0.5], atol=1e-7)
    rgb = Texture(np.full((1, 1, 3), 0.25)).image[0, 0]
    np.testing.assert_array_equal(rgb, [0.25, 0.25, 0.25, 1.0])


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"interpolation": "cubic"}, ValueError, "Texture.interpolation"),
        ({"extension": "mirror"}, ValueError, "Texture.extension"),
        ({"colorspace": "ACES"}, ValueError, "Texture.colorspace"),
        ({"image": np.zeros((2, 2, 4), np.uint8)}, TypeError, "Texture.image.*dtype uint8"),
        ({"image": np.zeros((2, 2))}, ValueError, r"Texture.image.*\(2, 2\)"),
        ({"image": np.full((1, 1, 4), 2.0)}, ValueError, "alpha in"),
        ({"image": np.full((1, 1, 4), np.nan)}, ValueError, "finite"),
        ({"image": np.full((1, 1, 3), 1.5), "colorspace": "sRGB"}, ValueError, "sRGB"),
        ({"use_alpha": "no"}, TypeError, "Texture.use_alpha"),
    ],
)
def test_bad_texture_arguments_are_named(kwargs: dict, error: type, match: str) -> None:
    args = {"image": IMAGE, **kwargs}
    with pytest.raises(error, match=match):
        Texture(**args)


def test_accepted_texel_dtypes_are_the_ones_the_message_names() -> None:
    # float16 (half-float EXR data) is accepted and converted exactly (every float16 is a float32).
    half = IMAGE.astype(np.float16)
    np.testing.assert_array_equal(Texture(half).image, half.astype(np.float32))
    with pytest.raises(TypeError) as refused:
        Texture(np.zeros((2, 2, 4), np.uint8))
    named = str(refused.value)
    for dtype in (np.float16, np.float32, np.float64):
        assert np.dtype(dtype).name in named, named  # the message lists every accepted dtype
        Texture(IMAGE.astype(dtype))
    if np.dtype(np.longdouble) != np.float64:  # extended precision: a float dtype not accepted
        with pytest.raises(TypeError, match=r"float16, float32 or float64 .*got dtype float128"):
            Texture(IMAGE.astype(np.longdouble))


def test_material_and_mesh_validation() -> None:
    with pytest.raises(TypeError, match=r"Material\.base_color_texture"):
        bp.Material(base_color_texture=IMAGE)
    with pytest.raises(ValueError, match=r"Material\.alpha_clip"):
        bp.Material(alpha_clip=1.5)
    textured = bp.Material(base_color_texture=Texture(IMAGE))
    tri = np.array([[0, 1, 2]])
    pos = np.eye(3)
    with pytest.raises(ValueError, match=r"Mesh\.uv: required"):
        bp.Mesh(pos, tri, material=textured)
    with pytest.raises(ValueError, match=r"Mesh.uv: expected shape \(3, 2\)"):
        bp.Mesh(pos, tri, material=textured, uv=np.zeros((2, 2)))


def quad_scene(material: bp.Material, camera: bp.Camera, size: float = 1.0) -> bp.Scene:
    """A square [-size, size]² in the z = 0 plane, uv (0,0) at the bottom-left, no lights."""
    s = size
    pos = np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]], float)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    mesh = bp.Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]]), material=material, uv=uv)
    return bp.Scene([mesh], [], camera, ambient=(0.0, 0.0, 0.0))


def emissive(texture: Texture, **kwargs: object) -> bp.Material:
    return bp.Material(
        ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(1, 1, 1), base_color_texture=texture, **kwargs
    )


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_emissive_quad_reproduces_the_image_row_0_at_the_top(engine: str) -> None:
    rng = np.random.default_rng(0)
    img = np.concatenate([rng.random((6, 8, 3)), np.ones((6, 8, 1))], -1).astype(np.float32)
    camera = bp.Camera(
        np.eye(4) @ bp.look_at((0, 0, 2), (0, 0, 0)), bp.orthographic_matrix(-1, 1, -1, 1, 0.5, 5)
    )
    scene = quad_scene(emissive(Texture(img, interpolation="closest")), camera)
    out = bp.render(scene, 8, 6, engine=engine).rgba
    np.testing.assert_allclose(out, img, atol=1e-6)


def test_perspective_correct_uv_equals_ray_plane_intersection() -> None:
    # Texture = a ramp whose texel i holds (i + 0.5)/W: bilinear lookup returns u itself inside.
    w = 64
    ramp = np.zeros((1, w, 4))
    ramp[0, :, 0] = (np.arange(w) + 0.5) / w
    ramp[..., 3] = 1.0
    tex = Texture(ramp, interpolation="linear", extension="extend")
    c, s = np.cos(1.1), np.sin(1.1)
    tilt = np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])  # about y
    eye = np.array([0.0, 0.0, 3.0])
    camera = bp.Camera(bp.look_at(eye, (0, 0, 0)), bp.perspective_matrix(40.0, 1.0, 0.5, 10.0))
    base = quad_scene(emissive(tex), camera)
    mesh = base.meshes[0]
    scene = bp.Scene(
        [bp.Mesh(mesh.positions, mesh.triangles, transform=tilt, material=mesh.material, uv=mesh.uv)],
        [],
        camera,
        ambient=(0.0, 0.0, 0.0),
    )
    n = 48
    out = bp.render(scene, n, n, engine="numpy").rgba
    # Ray through each pixel centre (view looks down -z from eye), hits the tilted plane at p;
    # u = (x_local + 1)/2 with x_local the coordinate along the plane's rotated x axis.
    tan = np.tan(np.radians(20.0))
    xs = ((np.arange(n) + 0.5) / n * 2 - 1) * tan
    ys = (1 - (np.arange(n) + 0.5) / n * 2) * tan
    dx, dy = np.meshgrid(xs, ys)
    d = np.stack([dx, dy, -np.ones_like(dx)], -1)
    normal = tilt[:3, 2]
    t = -(eye @ normal) / (d @ normal)
    p = eye + t[..., None] * d
    u = (p @ tilt[:3, 0] + 1) / 2
    inside = (out[..., 3] > 0) & (u > 1 / w) & (u < 1 - 1 / w)
    assert inside.sum() > 300
    np.testing.assert_allclose(out[..., 0][inside], u[inside], atol=2e-6)


def test_texture_alpha_is_partial_occlusion_and_alpha_clip_is_binary() -> None:
    img = np.array([[[0.4, 0.4, 0.4, 0.4], [0.9, 0.9, 0.9, 0.9]]], np.float32)  # premultiplied
    camera = bp.Camera(bp.look_at((0, 0, 2), (0, 0, 0)), bp.orthographic_matrix(-1, 1, -1, 1, 0.5, 5))
    tex = Texture(img, interpolation="closest")
    out = bp.render(quad_scene(emissive(tex), camera), 2, 1, engine="numpy").rgba
    # Straight colour 1 (emission 1 × texel 1), opacity 0.4 and 0.9: premultiplied (α, α, α, α).
    np.testing.assert_allclose(out[0], img[0], atol=1e-6)
    clipped = bp.render(quad_scene(emissive(tex, alpha_clip=0.5), camera), 2, 1, engine="numpy").rgba
    np.testing.assert_allclose(clipped[0], [[0, 0, 0, 0], [1, 1, 1, 1]], atol=1e-6)


def test_specular_is_added_after_modulation() -> None:
    # A black texture: only the specular term survives (GL_SEPARATE_SPECULAR_COLOR).
    black = Texture(np.zeros((1, 1, 3)), interpolation="closest")
    material = bp.Material(
        ambient=(0.2, 0.2, 0.2),
        diffuse=(0.8, 0.8, 0.8),
        specular=(0.5, 0.5, 0.5),
        shininess=1.0,
        base_color_texture=black,
    )
    camera = bp.Camera(bp.look_at((0, 0, 2), (0, 0, 0)), bp.orthographic_matrix(-1, 1, -1, 1, 0.5, 5))
    light = bp.DirectionalLight((0, 0, -1))
    scene = bp.Scene(
        quad_scene(material, camera).meshes, [light], camera, light_model=bp.LightModel(local_viewer=False)
    )
    out = bp.render(scene, 4, 4, engine="numpy").rgba
    # n = v = l = (0, 0, 1): n·h = 1, so specular = s_cm · s_cl = 0.5; ambient, diffuse × 0.
    np.testing.assert_allclose(out[..., :3], 0.5, atol=1e-12)
    np.testing.assert_allclose(out[..., 3], 1.0)


@pytest.mark.parametrize("engine", ["numpy", "numba"])
def test_alpha_clipped_and_translucent_texels_over_an_opaque_surface(engine: str) -> None:
    # Front quad (z = 0.5): left texel alpha 0.2, right texel alpha 0.8, emission 1 (white).
    # Back quad (z = 0): opaque emission (0, 0, 1). Orthographic view down -z.
    img = np.array([[[0.2, 0.2, 0.2, 0.2], [0.8, 0.8, 0.8, 0.8]]], np.float32)  # premultiplied white
    camera = bp.Camera(bp.look_at((0, 0, 2), (0, 0, 0)), bp.orthographic_matrix(-1, 1, -1, 1, 0.5, 5))
    back = quad_scene(bp.Material(ambient=(0, 0, 0), diffuse=(0, 0, 0), emission=(0, 0, 1)), camera).meshes[0]
    lift = np.eye(4)
    lift[2, 3] = 0.5
    for clip, expected in ((None, [[0.2, 0.2, 1.0], [0.8, 0.8, 1.0]]), (0.5, [[0, 0, 1], [1, 1, 1]])):
        front_material = emissive(Texture(img, interpolation="closest"), alpha_clip=clip)
        front = quad_scene(front_material, camera).meshes[0]
        front = bp.Mesh(
            front.positions, front.triangles, transform=lift, material=front.material, uv=front.uv
        )
        scene = bp.Scene([back, front], [], camera, ambient=(0.0, 0.0, 0.0))
        result = bp.render(scene, 2, 1, engine=engine)
        assert result.plan.transparency.method != "zbuffer"  # the planner saw a transparent material
        # α·white + (1 − α)·blue: (α, α, 1); alpha clip: blue where α < 0.5, white where kept.
        np.testing.assert_allclose(result.rgba[0, :, :3], expected, atol=1e-6)
        np.testing.assert_allclose(result.rgba[0, :, 3], 1.0, atol=1e-6)


@pytest.mark.parametrize("gl_compat", [False, True])
@pytest.mark.parametrize("separate", [False, True])
def test_compiled_texture_stage_equals_the_reference(gl_compat: bool, separate: bool) -> None:
    pytest.importorskip("numba")
    from blinn_phong.frame.texturing import texture_fragments

    rng = np.random.default_rng(5)
    img = rng.random((5, 7, 4)).astype(np.float32)
    img[..., :3] *= img[..., 3:4]  # premultiplied, alpha in [0, 1)
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    pos = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    uv = rng.uniform(-1.5, 2.5, (4, 2))
    meshes = []
    for k, (interp, ext) in enumerate(
        [(i, e) for i in ("closest", "linear") for e in ("repeat", "extend", "clip")]
    ):
        material = bp.Material(
            specular=(0.4, 0.4, 0.4),
            shininess=10.0,
            emission=(0.3, 0.1, 0.0),
            base_color_texture=Texture(img, interpolation=interp, extension=ext, use_alpha=k % 3 != 2),
            alpha_clip=0.3 if k % 2 else None,
        )
        shift = np.eye(4)
        shift[0, 3] = 2.5 * k - 6
        meshes.append(bp.Mesh(pos, tri, transform=shift, material=material, uv=uv))
    meshes.append(bp.Mesh(pos, tri, material=bp.Material(opacity=0.5, alpha_clip=0.4)))  # clip only
    camera = bp.Camera(bp.look_at((0, 0, 8), (0, 0, 0)), bp.orthographic_matrix(-9, 9, -2, 2, 1, 20))
    scene = bp.Scene(
        meshes,
        [bp.DirectionalLight((0.2, -0.3, -1.0))],
        camera,
        light_model=bp.LightModel(separate_specular=separate),
    )
    prepared = bp.prepare_scene(scene)
    frags = bp.rasterize(prepared.clip, prepared.triangles, 180, 40)
    shaded = bp.shade_fragments(prepared, frags, shading="phong", gl_compat=gl_compat, engine="numpy")
    ref = texture_fragments(prepared, frags, shaded, gl_compat=gl_compat, engine="numpy")
    fast = texture_fragments(prepared, frags, shaded, gl_compat=gl_compat, engine="numba")
    assert len(frags) > 2500
    # Same formulas in the same order; the uv sum may round differently (einsum vs a loop).
    for name in ("rgb", "ambient", "diffuse", "alpha", "specular"):
        np.testing.assert_allclose(getattr(fast, name), getattr(ref, name), rtol=0, atol=1e-12, err_msg=name)
