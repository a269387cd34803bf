"""Inputs a newcomer feeds the renderer from the docs alone, each with the message or the result
it must give: a single light, complex or astronomically large coordinates, empty meshes, a frame
that cannot fit in memory, the GL preset asked for something fixed-function GL cannot do, the
documented sense of the light vectors and the eye-space attenuation distance (closed forms), and
what the first render and a long render print on stderr."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import blinn_phong as bp
import compositing
from blinn_phong._checks import BYTES_PER_SAMPLE, check_frame_size, frame_bytes
from blinn_phong.model.primitives import grid_plane, uv_sphere


def _camera(view=None):
    return bp.Camera.perspective(
        45.0, 1.0, 0.1, 100.0, view=bp.look_at((0, 0, 4), (0, 0, 0)) if view is None else view
    )


def _sphere(**kwargs):
    positions, triangles, normals = uv_sphere(16, 8)
    return bp.Mesh(positions, triangles, normals, **kwargs)


def _empty_mesh():
    return bp.Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))


# --------------------------------------------------------------------------- scene construction


def test_a_single_light_is_accepted_as_the_light_list():
    light = bp.DirectionalLight((0, -1, -1))
    one = bp.Scene([_sphere()], light, _camera())
    assert one.lights == (light,)
    assert bp.Scene(_sphere(), light, _camera()).meshes[0].triangles.shape == _sphere().triangles.shape
    listed = bp.Scene([_sphere()], [light], _camera())
    a = bp.render(one, 12, 12, engine="numpy").rgba
    b = bp.render(listed, 12, 12, engine="numpy").rgba
    np.testing.assert_array_equal(a, b)  # numpy engine on identical inputs: deterministic by construction


def test_a_non_light_in_lights_names_the_argument():
    with pytest.raises(TypeError, match=r"Scene\.lights: expected a light or a sequence of lights"):
        bp.Scene([_sphere()], 3.0, _camera())
    with pytest.raises(TypeError, match=r"Scene\.lights\[1\]: expected AmbientLight"):
        bp.Scene([_sphere()], [bp.DirectionalLight(), "sun"], _camera())


def test_complex_vertex_positions_are_refused():
    positions, triangles, _ = uv_sphere(8, 4)
    with pytest.raises(TypeError, match=r"Mesh\.positions: expected real numbers .* got dtype complex128"):
        bp.Mesh(positions + 1j, triangles)
    with pytest.raises(TypeError, match=r"Mesh\.normals: expected real numbers"):
        bp.Mesh(positions, triangles, positions.astype(np.complex64))


def test_coordinates_beyond_float32_are_refused_naming_the_field():
    positions, triangles, normals = uv_sphere(8, 4)
    with pytest.raises(ValueError, match=r"Mesh\.positions: expected coordinates within ±3\.403e\+38"):
        bp.Mesh(positions * 1e39, triangles, normals)
    scale = np.diag([1e20, 1e20, 1e20, 1.0])  # each factor representable, the product is not
    with pytest.raises(ValueError, match=r"Mesh\.positions in world space \(transform applied\)"):
        bp.Mesh(positions * 1e20, triangles, normals, transform=scale)


# --------------------------------------------------------------------------- render inputs


@pytest.mark.parametrize("engine", ["numpy", "auto"])
def test_meshes_without_vertices_render_as_nothing(engine):
    light = bp.DirectionalLight((0, -1, -1))
    with_empty = bp.Scene([_empty_mesh(), _sphere(), _empty_mesh()], light, _camera())
    without = bp.Scene([_sphere()], light, _camera())
    a = bp.render(with_empty, 16, 16, engine=engine)
    b = bp.render(without, 16, 16, engine=engine)
    # The same triangles in the same order: identical work (bitwise for numpy; numba's parallel
    # bands never mix samples, and shading is per fragment, so a tolerance of 0 holds too).
    np.testing.assert_array_equal(a.rgba, b.rgba)
    assert a.stats.triangles == b.stats.triangles == len(_sphere().triangles)


def test_a_scene_of_empty_meshes_is_an_empty_image():
    result = bp.render(bp.Scene([_empty_mesh()], bp.DirectionalLight(), _camera()), 8, 6)
    assert result.rgba.shape == (6, 8, 4)
    np.testing.assert_array_equal(result.rgba, 0.0)
    np.testing.assert_array_equal(result.depth, 1.0)  # the OpenGL depth clear value


def test_a_frame_too_large_for_memory_is_refused_before_any_work():
    scene = bp.Scene([_sphere()], bp.DirectionalLight(), _camera())
    with pytest.raises(ValueError) as info:
        bp.render(scene, 100_000, 100_000, engine="numpy")
    message = str(info.value)
    assert message.startswith("width, height, samples: a 100000 × 100000 frame with 1 sample(s)")
    # at least the float32 output images alone (RGBA, 3 passes, normal, depth: 17 channels)
    need = int(re.search(r"\((\d+) bytes", message).group(1))
    assert need >= 100_000 * 100_000 * 17 * 4
    # the estimate is what the message says: a machine with one byte less is refused, not one with it
    assert need == frame_bytes(100_000, 100_000, 1)
    with pytest.raises(ValueError, match="samples"):
        check_frame_size(100, 50, 4, memory=frame_bytes(100, 50, 4) - 1)
    check_frame_size(100, 50, 4, memory=frame_bytes(100, 50, 4))
    # more samples, more memory: 4 samples need more than 4× the per-sample buffers of 1
    assert frame_bytes(100, 50, 4) - frame_bytes(100, 50, 1) == 3 * 100 * 50 * BYTES_PER_SAMPLE


@pytest.mark.parametrize("width", [0, -3, 2.5, True])
def test_bad_frame_sizes_name_the_argument(width):
    with pytest.raises(ValueError, match=r"^width: expected a positive integer number of pixels"):
        bp.render(bp.Scene([_sphere()], bp.DirectionalLight(), _camera()), width, 8)


def test_coordinates_near_1e30_render_without_overflow_warnings():
    # pytest turns every RuntimeWarning into an error (pyproject filterwarnings), so an overflowing
    # integer cast in the rasterizer fails this test. A quad of half-size 1e30 in front of the
    # camera covers the whole view (closed form: it contains the frustum's cross-section); a
    # sphere of radius 1e30 around the camera is clipped by the near plane and shows its inside.
    positions, triangles, normals = grid_plane(1, 1, size=(2e30, 2e30))
    huge_quad = bp.Mesh(positions + np.array([0.0, 0.0, -5.0]), triangles, normals)
    for engine in ("numpy", "auto"):
        result = bp.render(
            bp.Scene([huge_quad], bp.DirectionalLight(), _camera(np.eye(4))), 9, 7, engine=engine
        )
        np.testing.assert_array_equal(result.rgba[..., 3], 1.0)
        # the quad's eye-space depth is 5 everywhere: window depth of gluPerspective(0.1, 100)
        near, far, d = 0.1, 100.0, 5.0
        window = 0.5 * ((far + near) / (far - near) - 2 * far * near / ((far - near) * d)) + 0.5
        np.testing.assert_allclose(result.depth, window, rtol=1e-6)
        inside = bp.render(
            bp.Scene([_sphere(transform=np.diag([1e30, 1e30, 1e30, 1]))], [], _camera()), 8, 8, engine=engine
        )
        assert np.isfinite(inside.rgba).all()


def test_gl_compat_refuses_the_phong_specular_like_out_of_range_shininess():
    phong = bp.Scene(
        [_sphere()], bp.DirectionalLight(), _camera(), light_model=bp.LightModel(specular="phong")
    )
    with pytest.raises(ValueError, match=r"^scene\.light_model\.specular: OpenGL's fixed-function .*'phong'"):
        bp.render(phong, 8, 8, gl_compat=True)
    shiny = bp.Scene([_sphere(material=bp.Material(shininess=200.0))], bp.DirectionalLight(), _camera())
    with pytest.raises(ValueError, match=r"^scene\.meshes\[0\]\.material\.shininess: OpenGL accepts"):
        bp.render(shiny, 8, 8, gl_compat=True)
    assert bp.render(phong, 8, 8).rgba.shape == (8, 8, 4)  # outside the preset Phong's form is fine


# --------------------------------------------------------------------------- documented conventions


def _lit_plane(light, view, *, size=9):
    """A plane z = 0 facing +Z, seen straight on by an orthographic camera; diffuse 1, nothing else."""
    positions, triangles, normals = grid_plane(1, 1, size=(40.0, 40.0))
    material = bp.Material(ambient=(0, 0, 0), diffuse=(1, 1, 1), specular=(0, 0, 0))
    camera = bp.Camera.orthographic(-1, 1, -1, 1, 0.1, 100.0, view=view)
    scene = bp.Scene(
        [bp.Mesh(positions, triangles, normals, material=material)], light, camera, ambient=(0, 0, 0)
    )
    return bp.render(scene, size, size, engine="numpy").rgba[size // 2, size // 2, 0]


def test_directional_light_direction_is_the_direction_of_travel():
    view = bp.look_at((0, 0, 5), (0, 0, 0))
    assert _lit_plane(bp.DirectionalLight((0, 0, -1)), view) == pytest.approx(1.0)  # shines onto the plane
    assert _lit_plane(bp.DirectionalLight((0, 0, 1)), view) == 0.0  # shines away from its front
    # GL_POSITION (1, 0, 1, 0) points towards the light: our direction (-1, 0, -1), N·L = cos 45°
    assert _lit_plane(bp.DirectionalLight((-1, 0, -1)), view) == pytest.approx(np.sqrt(0.5), rel=1e-6)


def test_point_light_attenuation_uses_the_eye_space_distance():
    # A point light 1 world unit above the plane's centre, linear attenuation 1/d. With a view
    # matrix scaling by 2 (not rigid) the eye-space distance is 2 and OpenGL (§2.14.1) gives
    # 1/2; the world-space distance would give 1.
    light = bp.PointLight((0, 0, 1), constant=0.0, linear=1.0)
    rigid = bp.look_at((0, 0, 5), (0, 0, 0))
    scaled = np.diag([2.0, 2.0, 2.0, 1.0]) @ rigid
    assert _lit_plane(light, rigid) == pytest.approx(1.0, rel=1e-6)
    assert _lit_plane(light, scaled) == pytest.approx(0.5, rel=1e-6)


# --------------------------------------------------------------------------- compositing argument names


def test_partial_occlusion_blames_the_callers_argument():
    ok = np.full((4, 4, 4), 0.25, np.float32)
    bad = ok.copy()
    bad[..., 3] = 2.0
    with pytest.raises(ValueError, match=r"^surface: expected alpha .* in \[0, 1\]"):
        compositing.partial_occlusion(bad, ok)
    with pytest.raises(ValueError, match=r"^background: expected alpha"):
        compositing.partial_occlusion(ok, bad)
    with pytest.raises(ValueError, match=r"surface \(4, 4, 4\), background \(8, 8, 4\)"):
        compositing.partial_occlusion(ok, np.zeros((8, 8, 4), np.float32))
    with pytest.raises(ValueError, match=r"^background: expected alpha"):
        compositing.emission(np.ones((4, 4, 3), np.float32), bad)


# --------------------------------------------------------------------------- stderr feedback


def _run(code: str, cache_dir, cwd) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
        env={"NUMBA_CACHE_DIR": str(cache_dir), "PATH": "/usr/bin:/bin", "PYTHONPATH": str(cwd)},
    )


def test_the_compile_notice_appears_once_and_only_when_numba_compiles(tmp_path):
    # A numba kernel of a module named like ours, cached on disk: the first process compiles it
    # (notice printed once, however many kernels), the second loads it from the cache (silent).
    # Kernels of other packages never print it.
    (tmp_path / "blinn_phong_probe_kernels.py").write_text(
        "import numba\n\n@numba.njit(cache=True)\ndef add(x):\n    return x + 1\n\n"
        "@numba.njit(cache=True)\ndef mul(x):\n    return x * 2\n"
    )
    (tmp_path / "other_kernels.py").write_text("import numba\n\n@numba.njit\ndef sub(x):\n    return x - 1\n")
    root = str(Path(__file__).resolve().parents[2])
    code = f"""
        import sys
        sys.path.insert(1, {root!r})
        from blinn_phong.frame._feedback import announce_compiles
        announce_compiles("auto")
        import other_kernels
        other_kernels.sub(1)
        print("after other", file=sys.stderr)
        import blinn_phong_probe_kernels as k
        assert k.add(1) == 2 and k.mul(3) == 6 and k.add(1.5) == 2.5
    """
    first = _run(code, tmp_path / "cache", tmp_path)
    assert first.returncode == 0, first.stderr
    assert first.stderr == "after other\ncompiling kernels (once per machine)…\n"
    second = _run(code, tmp_path / "cache", tmp_path)
    assert second.returncode == 0, second.stderr
    assert second.stderr == "after other\n"


def test_a_long_render_prints_progress_and_a_short_one_stays_silent(capsys, monkeypatch):
    scene = bp.Scene([_sphere()], bp.DirectionalLight(), _camera())
    bp.render(scene, 8, 8)  # kernels loaded
    capsys.readouterr()
    bp.render(scene, 8, 8)
    assert capsys.readouterr().err == ""
    import blinn_phong.frame._feedback as feedback

    monkeypatch.setattr(feedback, "PROGRESS_AFTER", 0.0)  # every render is "long" now
    bp.render(scene, 8, 8)
    assert capsys.readouterr().err == ""  # stderr is not a terminal here: the default stays silent
    monkeypatch.setattr(feedback, "_interactive", lambda: True)
    bp.render(scene, 8, 8)
    lines = capsys.readouterr().err.splitlines()
    assert lines[-1] == "render: done 100%" and lines[0].startswith("render: ")
    bp.render(scene, 8, 8, progress=False)
    assert capsys.readouterr().err == ""
    seen = []
    bp.render(scene, 8, 8, progress=lambda stage, f: seen.append((stage, f)))
    assert seen[-1] == ("done", 1.0) and capsys.readouterr().err == ""
    with pytest.raises(TypeError, match=r"^progress: expected None"):
        bp.render(scene, 8, 8, progress="yes")
