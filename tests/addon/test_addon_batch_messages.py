"""Messages of the batch and verify command lines: misspelled names get the closest valid one,
lists of names read as text (not a Python tuple), and flags are named as typed."""

from __future__ import annotations

from pathlib import Path

import pytest

from addon import batch, verify


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--operator", "src_ovr"], "--operator: expected one of clear, src, dst, src_over"),
        (["--operator", "src_ovr"], "got 'src_ovr' (did you mean 'src_over'?)"),
        (
            ["--format", "open_exr_multilayr"],
            "got 'OPEN_EXR_MULTILAYR' (did you mean 'OPEN_EXR_MULTILAYER'?)",
        ),
        (["--format", "PNGG"], "--format: expected one of BMP, JPEG, OPEN_EXR, OPEN_EXR_MULTILAYER, PNG"),
    ],
)
def test_batch_names_the_closest_valid_name(
    tmp_path: Path, capsys: pytest.CaptureFixture, args: list[str], expected: str
) -> None:
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER-v405")
    with pytest.raises(SystemExit) as exit_info:
        batch.main([str(blend), "--out", str(tmp_path / "out"), *args])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and expected in err, err
    assert "('" not in err  # no Python tuple


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--operator", "over"], "error: --operator: for kind 'node_group' expected one of clear, src, dst"),
        (["--operator", "over"], "got 'over' (did you mean 'src_over'?)"),
        (
            ["--op", "src_atop", "--via", "alpha_over"],
            "expected one of src_over, disjoint_over, conjoint_over;",
        ),
        (["--op", "xor", "--via", "alpha_ovr"], "got 'alpha_ovr' (did you mean 'alpha_over'?)"),
    ],
)
def test_verify_names_the_closest_valid_name(
    capsys: pytest.CaptureFixture, args: list[str], expected: str
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        verify.main(args)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and expected in err, err
    assert "('" not in err and "--operator/--via" not in err  # readable names, one flag


def test_a_name_with_nothing_close_gets_no_guess(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        verify.main(["--operator", "qqqqqq"])
    assert "did you mean" not in capsys.readouterr().err
