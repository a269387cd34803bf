"""Deep OpenEXR files: round trips checked by OpenImageIO's own reader, files made by
OpenImageIO's writer read back, failed writes, and the ``deep-merge`` / ``deep-flatten``
command lines (checked against the library functions, whose tests have the oracles)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813
import pytest
from deep_testdata import from_imagebuf, random_deep, to_imagebuf

import compositing.io as compositing_io
from compositing.__main__ import main
from compositing.deep import DeepImage, flatten, merge
from compositing.deep_io import read_deep, write_deep
from compositing.io import read_image, write_image

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def image() -> DeepImage:
    return random_deep(np.random.default_rng(0), (21, 34))


def assert_identical(a: DeepImage, b: DeepImage) -> None:
    for x, y in ((a.counts, b.counts), (a.z, b.z), (a.zback, b.zback), (a.rgba, b.rgba)):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("tiled", [False, True], ids=["scanline", "tiled"])
@pytest.mark.parametrize("compression", ["zips", "none"])
def test_written_file_reads_back_identically_in_openimageio(tmp_path, image, tiled, compression):
    path = tmp_path / "deep.exr"
    write_deep(path, image, tiled=tiled, tile_size=16, compression=compression)
    buf = oiio.ImageBuf(str(path))  # OpenImageIO's own reader, sample by sample
    spec = buf.spec()
    assert buf.deep and spec.tile_width == (16 if tiled else 0)
    assert spec.getattribute("compression") == compression
    assert list(spec.channelnames) == ["R", "G", "B", "A", "Z", "ZBack"]
    assert_identical(from_imagebuf(buf), image)
    assert_identical(read_deep(path), image)


def test_half_rgba_rounds_colour_only(tmp_path, image):
    path = tmp_path / "half.exr"
    write_deep(path, image, float_format="half")
    back = read_deep(path)
    np.testing.assert_array_equal(back.z, image.z)
    np.testing.assert_array_equal(back.rgba, image.rgba.astype(np.float16).astype(np.float32))


def test_reads_files_written_by_openimageio(tmp_path, image):
    path = tmp_path / "oiio.exr"
    assert to_imagebuf(image).write(str(path))
    assert_identical(read_deep(path), image)


def test_missing_zback_means_point_samples_and_extra_channels_warn(tmp_path):
    spec = oiio.ImageSpec(2, 1, 6, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B", "A", "Z", "id")
    spec.deep = True
    buf = oiio.ImageBuf(spec)
    buf.set_deep_samples(1, 0, 0, 1)
    for c, v in enumerate((0.1, 0.2, 0.3, 0.5, 4.0, 7.0)):
        buf.set_deep_value(1, 0, 0, c, 0, v)
    path = tmp_path / "noback.exr"
    assert buf.write(str(path))
    with pytest.warns(UserWarning, match="ignored deep channels id"):
        back = read_deep(path)
    np.testing.assert_array_equal(back.counts, [[0, 1]])
    np.testing.assert_array_equal(back.zback, np.float32([4.0]))


def test_flat_files_and_bad_options_are_refused(tmp_path, image):
    flat = tmp_path / "flat.exr"
    write_image(flat, np.zeros((2, 2, 4), np.float32))
    with pytest.raises(ValueError, match="is a flat image, not a deep one"):
        read_deep(flat)
    with pytest.raises(OSError, match="cannot open"):
        read_deep(tmp_path / "missing.exr")
    with pytest.raises(ValueError, match=r"compression: expected one of \('zips', 'none'\)"):
        write_deep(tmp_path / "x.exr", image, compression="piz")
    with pytest.raises(ValueError, match=r"expected a \.exr path"):
        write_deep(tmp_path / "x.png", image)


def test_failed_write_leaves_the_existing_file_intact(tmp_path, image, monkeypatch):
    path = tmp_path / "keep.exr"
    write_deep(path, image)
    before = path.read_bytes()

    class Failing:
        """An ImageOutput that writes part of a file, then fails."""

        @staticmethod
        def create(name):
            return Failing()

        def open(self, name, spec):
            Path(name).write_bytes(b"partial")
            return True

        def write_deep_image(self, dd):
            return False

        def geterror(self):
            return "disk full"

        def close(self):
            return True

    class Shim:
        def __getattr__(self, name):
            return Failing if name == "ImageOutput" else getattr(oiio, name)

    monkeypatch.setattr(compositing_io, "oiio", Shim())  # the one atomic writer of compositing.io
    with pytest.raises(OSError, match="disk full"):
        write_deep(path, random_deep(np.random.default_rng(1), (3, 3)))
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["keep.exr"]


# --- command line ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def deep_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("deep")
    rng = np.random.default_rng(3)
    a, b = random_deep(rng, (9, 13)), random_deep(rng, (9, 13))
    write_deep(d / "a.exr", a)
    write_deep(d / "b.exr", b, tiled=True, tile_size=8)
    return d, a, b


def test_cli_deep_merge_writes_the_merge(deep_files, capsys):
    d, a, b = deep_files
    out = d / "ab.exr"
    assert main(["deep-merge", str(d / "a.exr"), str(d / "b.exr"), "-o", str(out), "--tiled"]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out}"
    back = read_deep(out)
    assert back.is_tidy() and oiio.ImageInput.open(str(out)).spec().tile_width == 64
    assert_identical(back, merge(a, b))


def test_cli_deep_flatten_writes_the_flat_image(deep_files):
    d, a, b = deep_files
    out = d / "flat.exr"
    assert main(["deep-flatten", str(d / "a.exr"), str(d / "b.exr"), "-o", str(out)]) == 0
    np.testing.assert_array_equal(read_image(out), flatten(merge(a, b)))


def test_cli_deep_bad_data_exits_1(deep_files, tmp_path, capsys):
    d, _, _ = deep_files
    small = tmp_path / "small.exr"
    write_deep(small, DeepImage.empty(2, 2))
    assert main(["deep-merge", str(d / "a.exr"), str(small), "-o", str(tmp_path / "o.exr")]) == 1
    assert "expected deep images of equal shape" in capsys.readouterr().err
    flat = tmp_path / "flat.exr"
    write_image(flat, np.zeros((2, 2, 4), np.float32))
    assert main(["deep-flatten", str(flat), "-o", str(tmp_path / "o.png")]) == 1
    assert "is a flat image, not a deep one" in capsys.readouterr().err
    assert not (tmp_path / "o.exr").exists() and not (tmp_path / "o.png").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["deep-merge", "a.exr", "-o", "o.exr"], "expected two or more deep images"),
        (["deep-merge", "a.exr", "b.exr", "-o", "o.exr", "--compression", "piz"], "--compression"),
        (["deep-flatten", "a.exr"], "the following arguments are required: -o/--out"),
    ],
)
def test_cli_deep_usage_errors_exit_2(args, message):
    proc = subprocess.run(
        [sys.executable, "-m", "compositing", *args], capture_output=True, text=True, cwd=ROOT, timeout=120
    )
    assert proc.returncode == 2 and message in proc.stderr


@pytest.mark.blender
@pytest.mark.timeout(300)
def test_blender_reads_the_flattened_output(deep_files, tmp_path):
    if importlib.util.find_spec("bpy") is None:  # bpy runs in a subprocess, never imported here
        pytest.skip("the bpy module is not installed")
    d, a, b = deep_files
    out = tmp_path / "flat.exr"
    assert main(["deep-flatten", str(d / "a.exr"), str(d / "b.exr"), "-o", str(out)]) == 0
    script = (
        "import sys, bpy, numpy as np\n"
        "img = bpy.data.images.load(sys.argv[1])\n"
        "w, h = img.size\n"
        "px = np.empty(w * h * 4, np.float32); img.pixels.foreach_get(px)\n"
        "np.save(sys.argv[2], px.reshape(h, w, 4)[::-1])\n"  # Blender's row 0 is the bottom
    )
    npy = tmp_path / "blender.npy"
    proc = subprocess.run(
        [sys.executable, "-c", script, str(out), str(npy)], capture_output=True, text=True, timeout=240
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    np.testing.assert_array_equal(np.load(npy), flatten(merge(a, b)))
