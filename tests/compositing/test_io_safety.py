"""Image files and command lines that must not lose data: a failed write leaves the existing
file byte-for-byte intact (a real write failure from the kernel's file-size limit, and a
writer failing half-way), channels are picked by name (never alpha guessed from a channel
count), formats without alpha (JPEG, Radiance HDR) need an explicit flatten, and the command
lines print what they wrote, accept ``--operator`` and exit 0 / 1 / 2."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio  # noqa: N813
import pytest

import compositing.io as cio
from compositing.__main__ import main
from compositing._atomic import atomic_path, write_json_atomic, write_text_atomic
from compositing.demo import main as demo_main
from compositing.io import image_channels, read_image, write_image
from compositing.samples import sample_paths

ROOT = Path(__file__).resolve().parents[2]


def _image(seed: int, h: int = 48, w: int = 40) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = rng.random((h, w, 4)).astype(np.float32)
    img[..., :3] *= img[..., 3:]  # premultiplied
    return img


def _write_raw_exr(path: Path, data: np.ndarray, names: tuple[str, ...]) -> None:
    """Write float channels with the given names straight through OpenImageIO (no alpha declared)."""
    h, w, c = data.shape
    spec = oiio.ImageSpec(w, h, c, oiio.FLOAT)
    spec.channelnames = names
    spec.alpha_channel = -1
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(np.ascontiguousarray(data, np.float32))
    out.close()


# --------------------------------------------------------------------------- failed writes


def _limit_file_size() -> None:  # runs in the child before exec
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of killing
    resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))


def test_a_write_failing_for_lack_of_space_leaves_the_input_intact(tmp_path):
    # The command line writes its output over one of its inputs while the kernel refuses every
    # byte past 4096 (RLIMIT_FSIZE: the same short write a full disk gives).
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    write_image(a, _image(0))
    write_image(b, _image(1))
    before = a.read_bytes()
    assert len(before) > 4096
    proc = subprocess.run(
        [sys.executable, "-m", "compositing", "src_over", str(a), str(b), "-o", str(a)],
        preexec_fn=_limit_file_size,
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert proc.returncode == 1, proc.stderr
    assert "cannot write" in proc.stderr and "wrote" not in proc.stdout
    assert a.read_bytes() == before  # byte-for-byte
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "b.exr"]  # no temporary left


class _FailingOutput:
    """An OpenImageIO output that writes the header and half the rows, then reports a failure."""

    def __init__(self, real):
        self.real = real

    def open(self, path, spec):
        return self.real.open(path, spec)

    def write_image(self, pixels):
        half = pixels.shape[0] // 2
        self.real.write_scanlines(0, half, 0, pixels[:half])
        return False

    def geterror(self):
        return "No space left on device"

    def close(self):
        return self.real.close()


@pytest.mark.parametrize("name", ["out.exr", "out.png", "out.tif"])
def test_a_writer_failing_half_way_leaves_the_old_file_intact(tmp_path, monkeypatch, name):
    target = tmp_path / name
    write_image(target, _image(2))
    before = target.read_bytes()
    real_image_output = oiio.ImageOutput

    class FailingImageOutput:
        @staticmethod
        def create(path):
            return _FailingOutput(real_image_output.create(path))

    monkeypatch.setattr(cio.oiio, "ImageOutput", FailingImageOutput)
    with pytest.raises(OSError, match="No space left on device"):
        write_image(target, _image(3))
    monkeypatch.undo()
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [name]
    np.testing.assert_array_equal(read_image(target), read_image(target))  # still a readable file


def test_bad_values_raise_before_the_old_file_is_touched(tmp_path):
    target = tmp_path / "keep.png"
    write_image(target, _image(4))
    before = target.read_bytes()
    hdr = _image(5)
    hdr[..., 0] = 3.0  # straight colour above 1: an 8-bit file cannot hold it
    with pytest.raises(ValueError, match="pass clip=True"):
        write_image(target, hdr)
    assert target.read_bytes() == before


def test_atomic_text_and_json_writers(tmp_path):
    target = tmp_path / "report.json"
    write_json_atomic(target, {"ok": True}, indent=1)
    assert json.loads(target.read_text()) == {"ok": True}
    before = target.read_bytes()
    with pytest.raises(TypeError):  # not serialisable: raised before the file is touched
        write_json_atomic(target, {"bad": object()})
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        Path(tmp).write_text('{"half": ')
        raise RuntimeError("writer died")
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["report.json"]
    os.chmod(target, 0o640)
    write_text_atomic(target, "new\n")
    assert target.read_text() == "new\n" and (target.stat().st_mode & 0o777) == 0o640  # mode kept


def test_a_missing_directory_is_named(tmp_path):
    with pytest.raises(OSError, match=r"path: cannot write .*x\.png.*No such file or directory"):
        write_image(tmp_path / "missing" / "x.png", _image(12, 2, 2))


# --------------------------------------------------------------------------- channels by name


def test_rgbz_exr_does_not_read_depth_as_alpha(tmp_path):
    rng = np.random.default_rng(6)
    data = rng.random((5, 6, 4)).astype(np.float32)
    data[..., 3] = 7.5  # a depth, not a coverage
    path = tmp_path / "rgbz.exr"
    _write_raw_exr(path, data, ("R", "G", "B", "Z"))
    with pytest.warns(UserWarning, match=r"alpha = 1 \(no alpha channel declared\); ignored: Z"):
        got = read_image(path)
    np.testing.assert_array_equal(got[..., :3], data[..., :3])
    np.testing.assert_array_equal(got[..., 3], 1.0)
    assert image_channels(path).alpha is None


def test_cli_says_which_channels_it_read(tmp_path, capsys):
    rng = np.random.default_rng(13)
    data = rng.random((5, 6, 4)).astype(np.float32)
    _write_raw_exr(tmp_path / "rgbz.exr", data, ("R", "G", "B", "Z"))
    out = tmp_path / "o.exr"
    assert main(["src_over", str(tmp_path / "rgbz.exr"), str(tmp_path / "rgbz.exr"), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.out.strip() == f"wrote {out}"
    assert (
        captured.err.count("warning: ") == 2
        and "alpha = 1 (no alpha channel declared); ignored: Z" in captured.err
    )
    np.testing.assert_array_equal(read_image(out)[..., 3], 1.0)  # opaque over opaque


def test_uv_file_does_not_read_v_as_alpha(tmp_path):
    rng = np.random.default_rng(7)
    data = rng.random((4, 3, 2)).astype(np.float32)
    path = tmp_path / "uv.exr"
    _write_raw_exr(path, data, ("U", "V"))
    with pytest.warns(UserWarning, match=r"R←U, G←V, B←0; alpha = 1"):
        got = read_image(path)
    np.testing.assert_array_equal(got[..., 0], data[..., 0])
    np.testing.assert_array_equal(got[..., 1], data[..., 1])
    np.testing.assert_array_equal(got[..., 2], 0.0)
    np.testing.assert_array_equal(got[..., 3], 1.0)


def test_named_alpha_is_used_wherever_it_sits(tmp_path):
    rng = np.random.default_rng(8)
    data = rng.random((3, 4, 5)).astype(np.float32)
    path = tmp_path / "rgbaz.exr"
    _write_raw_exr(path, data, ("R", "G", "B", "A", "Z"))
    with pytest.warns(UserWarning, match="ignored: Z"):
        got = read_image(path)
    mapping = image_channels(path)
    want = np.stack([data[..., mapping.names.index(c)] for c in "RGBA"], axis=-1)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("first", ["Combined", "Diffuse"])
def test_a_multilayer_exr_never_mixes_one_layers_colour_with_anothers_alpha(tmp_path, first):
    # Blender's multilayer EXR: RGBA of the render pass plus RGB passes, in any file order.
    rng = np.random.default_rng(21)
    layers = {"Combined": "RGBA", "Diffuse": "RGB"}
    order = [first] + [n for n in layers if n != first]
    names = tuple(f"{layer}.{c}" for layer in order for c in layers[layer])
    data = rng.random((3, 4, len(names))).astype(np.float32)
    path = tmp_path / "layers.exr"
    _write_raw_exr(path, data, names)
    with pytest.warns(UserWarning, match="ignored: Diffuse.R, Diffuse.G, Diffuse.B"):
        got = read_image(path)
    want = np.stack([data[..., names.index(f"Combined.{c}")] for c in "RGBA"], axis=-1)
    np.testing.assert_array_equal(got, want)


def test_plain_rgba_and_grey_alpha_files_read_silently(tmp_path, recwarn):
    img = _image(9, 4, 4)
    write_image(tmp_path / "a.exr", img)
    np.testing.assert_array_equal(read_image(tmp_path / "a.exr"), img)
    grey = np.zeros((4, 4, 2), np.uint8)
    grey[..., 0], grey[..., 1] = 255, 128
    from PIL import Image

    Image.fromarray(grey, "LA").save(tmp_path / "la.png")
    got = read_image(tmp_path / "la.png")
    np.testing.assert_allclose(got[..., 3], 128 / 255, rtol=1e-6)
    np.testing.assert_allclose(got[..., :3], 128 / 255, rtol=1e-6)  # white at half coverage
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]


# --------------------------------------------------------------------------- formats without alpha


def test_hdr_needs_flatten_like_jpeg(tmp_path):
    img = _image(10, 6, 5)
    with pytest.raises(ValueError, match="flatten: Radiance HDR"):
        write_image(tmp_path / "x.hdr", img)
    assert not (tmp_path / "x.hdr").exists()
    write_image(tmp_path / "x.hdr", img, flatten=True)
    back = read_image(tmp_path / "x.hdr")
    np.testing.assert_array_equal(back[..., 3], 1.0)
    # RGBE: 8-bit mantissa with a shared exponent, relative error below 2^-8 of the largest channel
    err = np.abs(back[..., :3] - img[..., :3]).max(axis=-1)
    assert (err <= img[..., :3].max(axis=-1) * 2.0**-7 + 1e-6).all()


def test_hdr_refuses_negative_colour_unless_clipped(tmp_path):
    img = _image(11, 3, 3)
    img[0, 0, 1] = -0.25
    with pytest.raises(ValueError, match="negative colour"):
        write_image(tmp_path / "n.hdr", img, flatten=True)
    write_image(tmp_path / "n.hdr", img, flatten=True, clip=True)
    assert read_image(tmp_path / "n.hdr")[0, 0, 1] == 0.0


@pytest.mark.parametrize("ext", [".jpg", ".hdr"])
def test_cli_flatten_writes_formats_without_alpha(tmp_path, capsys, ext):
    a_path, b_path = sample_paths()
    out = tmp_path / f"o{ext}"
    assert main(["src_over", str(a_path), str(b_path), "-o", str(out)]) == 1
    assert "flatten" in capsys.readouterr().err and not out.exists()
    assert main(["src_over", str(a_path), str(b_path), "-o", str(out), "--flatten"]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out}"
    assert read_image(out).shape == read_image(a_path).shape


# --------------------------------------------------------------------------- command lines


def test_cli_operator_option_is_an_alias_of_the_positional(tmp_path, capsys):
    a_path, b_path = sample_paths()
    outs = [tmp_path / f"{k}.exr" for k in range(3)]
    assert main(["xor", str(a_path), str(b_path), "-o", str(outs[0])]) == 0
    assert main(["--operator", "xor", str(a_path), str(b_path), "-o", str(outs[1])]) == 0
    assert main([str(a_path), str(b_path), "--op", "xor", "-o", str(outs[2])]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed == [f"wrote {p}" for p in outs]
    a, b = read_image(a_path).astype(np.float64), read_image(b_path).astype(np.float64)
    want = a * (1 - b[..., 3:]) + b * (1 - a[..., 3:])  # Porter & Duff: A xor B
    for p in outs:
        np.testing.assert_allclose(read_image(p), want, atol=1e-6)


@pytest.mark.parametrize(
    "argv",
    [
        ["src_over", "a.png", "-o", "x.exr"],  # one image short
        ["--operator", "src_over", "src_over", "a.png", "b.png", "-o", "x.exr"],  # operator twice
        ["src_over", "a.png", "b.png"],  # no -o
    ],
)
def test_cli_usage_errors_exit_2_naming_the_module(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "usage: python -m compositing" in err and "error:" in err


def test_cli_unreadable_input_exits_1(tmp_path, capsys):
    assert main(["src_over", str(tmp_path / "missing.png"), str(sample_paths()[1]), "-o", "x.exr"]) == 1
    assert "missing.png" in capsys.readouterr().err


def test_demo_without_arguments_prints_where_it_writes(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert demo_main([]) == 0
    out = capsys.readouterr().out
    where = (tmp_path / "out" / "demo-compositing").resolve()
    assert out.splitlines()[0] == f"writing to {where}"
    assert out.rstrip().endswith(f"results.json to {where}")
    assert (where / "src_over.exr").is_file() and (where / "results.json").is_file()


def test_demo_usage_names_the_module(capsys):
    with pytest.raises(SystemExit) as exc:
        demo_main(["--bogus"])
    assert exc.value.code == 2
    assert capsys.readouterr().err.startswith("usage: python -m compositing.demo")
