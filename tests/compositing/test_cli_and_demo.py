"""The command line and the demo, run on the bundled sample images; results are checked
against the closed form of the operator applied to the decoded inputs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from compositing.__main__ import main
from compositing.demo import run_demo
from compositing.factors import ALL_OPERATORS
from compositing.io import read_image
from compositing.samples import make_samples, sample_paths

ROOT = Path(__file__).resolve().parents[2]


def test_bundled_samples_are_the_generated_ones():
    for path, image in zip(sample_paths(), make_samples(), strict=True):
        back = read_image(path)
        # 8-bit quantisation: half a step (0.5/255) of encoded colour is at most 0.5/255 · 2.4/1.055
        # in linear (the slope of the sRGB EOTF at 1), plus half a step of alpha times the colour.
        assert np.abs(back - image).max() <= 0.5 / 255 * (2.4 / 1.055 + 1) + 1e-6
        assert path.stat().st_size < 100_000


def test_cli_composites_two_files(tmp_path):
    a_path, b_path = sample_paths()
    out = tmp_path / "atop.exr"
    assert main(["src_atop", str(a_path), str(b_path), "-o", str(out), "--factor", "0.5"]) == 0
    a, b = read_image(a_path).astype(np.float64), read_image(b_path).astype(np.float64)
    atop = a * b[..., 3:] + b * (1 - a[..., 3:])  # Porter & Duff: A atop B
    np.testing.assert_allclose(read_image(out), 0.5 * b + 0.5 * atop, atol=1e-6)


def test_cli_blend_subcommand(tmp_path):
    pytest.importorskip("compositing.gl_blend")
    a_path, b_path = sample_paths()
    out = tmp_path / "gl.exr"
    args = ["blend", str(a_path), str(b_path), "-o", str(out), "--src-factor", "one", "--dst-factor"]
    assert main([*args, "ONE_MINUS_SRC_ALPHA"]) == 0
    a, b = read_image(a_path).astype(np.float64), read_image(b_path).astype(np.float64)
    np.testing.assert_allclose(read_image(out), a + b * (1 - a[..., 3:]), atol=1e-6)


def test_cli_unknown_operator_exits_2_with_closest_match():
    a_path, b_path = sample_paths()
    proc = subprocess.run(
        [sys.executable, "-m", "compositing", "dst_inn", str(a_path), str(b_path), "-o", "x.png"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "Did you mean 'dst_in'?" in proc.stderr and "src_over" in proc.stderr


def test_cli_bad_data_exits_1(tmp_path, capsys):
    a_path, b_path = sample_paths()
    out = tmp_path / "p.png"
    assert main(["plus", str(a_path), str(b_path), "-o", str(out)]) == 1
    err = capsys.readouterr().err  # the command line's flags, not the library's keywords
    assert f"error: --out {out}: " in err and "give --clip" in err and "clip=True" not in err, err
    assert main(["src_over", str(a_path), str(b_path), "-o", str(tmp_path / "p.jpg")]) == 1
    err = capsys.readouterr().err
    assert "JPEG has no alpha; give --flatten" in err and "flatten=True" not in err, err
    assert main(["src_over", str(a_path), str(b_path), "-o", str(out), "--factor", "2"]) == 1
    assert "error: --factor: expected a number in [0, 1]" in capsys.readouterr().err


def test_cli_misspelled_gl_names_get_the_closest_valid_one(tmp_path, capsys):
    pytest.importorskip("compositing.gl_blend")
    a_path, b_path = sample_paths()
    args = ["blend", str(a_path), str(b_path), "-o", str(tmp_path / "x.exr"), "--src-factor", "ONE"]
    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--dst-factor", "one_minus_src_alhpa"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    assert "error: --dst-factor: unknown blend factor" in err and "(did you mean ONE_MINUS_SRC_ALPHA?)" in err


def test_demo_writes_every_operator(tmp_path):
    rows = run_demo(tmp_path)
    assert [r["operator"] for r in rows] == list(ALL_OPERATORS)
    a, b = (read_image(p).astype(np.float64) for p in sample_paths())
    over = read_image(tmp_path / "src_over.exr")
    np.testing.assert_allclose(over, a + b * (1 - a[..., 3:]), atol=1e-6)
    xor = read_image(tmp_path / "xor.exr")
    np.testing.assert_allclose(xor, a * (1 - b[..., 3:]) + b * (1 - a[..., 3:]), atol=1e-6)
    for op in ALL_OPERATORS:
        assert (tmp_path / f"{op}.png").stat().st_size > 0
    table = json.loads((tmp_path / "results.json").read_text())
    assert table[3]["operator"] == "src_over" and abs(table[3]["mean_alpha"] - over[..., 3].mean()) < 1e-4
    assert read_image(tmp_path / "contact_sheet.png").shape[2] == 4
