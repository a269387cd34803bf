"""Input checks of ``addon.verify`` (no Blender needed): bad cases and images are refused up front."""

import numpy as np
import pytest

from addon.verify import Case, run_blender, sample_images


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"kind": "shader", "operator": "src_over"}, "kind: expected one of"),
        ({"kind": "alpha_over", "operator": "src_atop"}, "operator: for kind 'alpha_over'"),
        ({"kind": "node_group", "operator": "over"}, "operator: for kind 'node_group'"),
        ({"kind": "node_group", "operator": "xor", "factor": 1.5}, "factor: expected a number in"),
        (
            {"kind": "node_group", "operator": "xor", "straight_alpha": True},
            "straight_alpha: only Alpha Over",
        ),
    ],
)
def test_bad_cases_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Case(**kwargs)


def test_sample_images_hold_every_special_pixel() -> None:
    src, dst = sample_images(61, 97)
    assert src.shape == dst.shape == (61, 97, 4) and src.dtype == np.float32
    for image in (src, dst):
        alpha, rgb = image[..., 3], image[..., :3]
        assert (alpha == 0).any() and (alpha == 1).any() and ((alpha > 0) & (alpha < 1)).any()
        assert (rgb[alpha == 0] != 0).any()  # glow
        assert (rgb > 1).any() and (rgb < 0).any()  # HDR and negative colour
        assert alpha.min() >= 0 and alpha.max() <= 1
    assert (src[..., 3] == dst[..., 3]).any()  # the sa == da boundary of Conjoint Over


def test_images_are_checked_before_blender_starts() -> None:
    src, dst = sample_images(8, 8)
    bad = src.copy()
    bad[0, 0, 3] = 1.5
    with pytest.raises(ValueError, match="src"):
        run_blender(bad, dst, [Case("node_group", "xor")], python="/nonexistent/python")
    with pytest.raises(ValueError, match="src, dst: expected equal shapes"):
        run_blender(src, dst[:4], [Case("node_group", "xor")], python="/nonexistent/python")
    with pytest.raises(ValueError, match="cases: expected at least one Case"):
        run_blender(src, dst, [], python="/nonexistent/python")


@pytest.mark.parametrize(
    ("args", "flag", "accepts"),
    [
        (["--operator", "xor", "--size", "0x0"], "--size", "each side in 1..8192"),
        (["--operator", "xor", "--size", "100000x100000"], "--size", "each side in 1..8192"),
        (["--operator", "xor", "--size", "97"], "--size", "WIDTHxHEIGHT"),
        (["--operator", "xor", "--python", "/nonexistent/python"], "--python", "executable Python"),
        (["--operator", "xor", "--tolerance", "-1"], "--tolerance", "finite number >= 0"),
        (["--operator", "xor", "--tolerance", "nan"], "--tolerance", "finite number >= 0"),
        (["--operator", "xor", "--factor", "1.5"], "--factor", "[0, 1]"),
        (["--operator", "over"], "--operator", "expected one of"),
        (["--op", "src_atop", "--via", "alpha_over"], "--operator", "for kind 'alpha_over'"),
        ([], "--operator", "or --all"),
        (
            ["--operator", "xor", "--src", "/nonexistent/a.exr", "--dst", "/nonexistent/b.exr"],
            "--src",
            "no such",
        ),
        (["--operator", "xor", "--src", "a.exr"], "--src and --dst", "together"),
    ],
)
def test_cli_usage_errors_exit_2_before_blender_starts(
    capsys: pytest.CaptureFixture, args: list[str], flag: str, accepts: str
) -> None:
    from addon.verify import main

    with pytest.raises(SystemExit) as exit_info:
        main(args)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    assert f"error: argument {flag}" in err or f"error: {flag}" in err, err
    assert accepts in err, err


def test_cli_out_must_not_be_an_existing_file(tmp_path, capsys: pytest.CaptureFixture) -> None:
    from addon.verify import main

    taken = tmp_path / "taken"
    taken.write_text("x")
    with pytest.raises(SystemExit) as exit_info:
        main(["--operator", "xor", "--out", str(taken)])
    assert (
        exit_info.value.code == 2
        and f"--out: {taken} exists and is not a directory" in capsys.readouterr().err
    )


def test_one_operator_flag_and_one_default_tolerance_for_both_command_lines() -> None:
    from addon import batch, verify

    verify_args = verify.build_parser().parse_args(["--op", "xor"])
    assert verify_args.operator == "xor"
    assert verify.build_parser().parse_args(["--operator", "xor"]).operator == "xor"
    batch_args = batch.build_parser().parse_args(["f.blend", "--out", "o", "--op", "xor"])
    assert batch_args.operator == "xor"
    assert batch_args.tolerance == verify_args.tolerance == verify.DEFAULT_TOLERANCE


@pytest.mark.blender
def test_cli_success_prints_what_it_wrote(tmp_path) -> None:
    import os
    import subprocess
    import sys
    from pathlib import Path

    from compositing.io import read_image

    repo = Path(__file__).resolve().parents[2]
    out = tmp_path / "diff"
    done = subprocess.run(
        [sys.executable, "-m", "addon.verify", "--op", "xor", "--size", "9x7", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=str(repo),
        env=dict(os.environ, PYTHONPATH=str(repo), BLENDER_USER_RESOURCES=str(tmp_path / "user")),
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    for name in ("blender", "ours", "difference"):
        assert f"wrote {out / name}.exr" in done.stdout
    # |Blender − ours| as written equals the difference of the two written images: both are the
    # correctly rounded float32 of an exact difference (values in [-0.5, 3]), so equal bit for bit.
    blender, ours = read_image(out / "blender.exr"), read_image(out / "ours.exr")
    np.testing.assert_array_equal(read_image(out / "difference.exr"), np.abs(blender - ours))
    assert sorted(p.name for p in out.iterdir()) == ["blender.exr", "difference.exr", "ours.exr"]
