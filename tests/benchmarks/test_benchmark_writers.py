"""Benchmark results and charts are written atomically: a failed write keeps the previous file."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pytest

from benchmarks._util import save_figure, write_json

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"  # PNG specification, section 5.2


def test_write_json_creates_the_directory_and_keeps_the_old_file_on_failure(tmp_path: Path) -> None:
    target = tmp_path / "results" / "bench.json"
    write_json(target, {"ratio": 1.5})
    assert json.loads(target.read_text()) == {"ratio": 1.5}
    before = target.read_bytes()
    with pytest.raises(TypeError):  # not JSON-serialisable
        write_json(target, {"bad": object()})
    assert target.read_bytes() == before
    assert [p.name for p in target.parent.iterdir()] == ["bench.json"]


class _FailingArtist(matplotlib.artist.Artist):
    """An artist whose drawing fails: the figure's writer dies after it opened its output."""

    def draw(self, renderer: object) -> None:
        raise RuntimeError("drawing failed")


def test_save_figure_writes_a_png_and_keeps_the_old_chart_on_failure(tmp_path: Path) -> None:
    target = tmp_path / "charts" / "chart.png"
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    assert save_figure(fig, target, dpi=40) == target
    plt.close(fig)
    assert target.read_bytes().startswith(PNG_SIGNATURE)  # the extension chose the format


def test_a_figure_that_fails_while_streaming_leaves_the_old_file(tmp_path: Path) -> None:
    # The SVG writer opens the file and streams into it while drawing: a plain
    # ``fig.savefig(target)`` would leave a truncated SVG behind here.
    target = tmp_path / "chart.svg"
    target.write_text("<svg>old</svg>")
    fig = plt.figure(figsize=(2, 2))
    fig.add_artist(_FailingArtist())
    with pytest.raises(RuntimeError, match="drawing failed"):
        save_figure(fig, target)
    plt.close(fig)
    assert target.read_text() == "<svg>old</svg>"
    assert [p.name for p in tmp_path.iterdir()] == ["chart.svg"]
