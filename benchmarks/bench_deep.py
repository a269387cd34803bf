"""Deep merge + flatten against OpenImageIO's ``ImageBufAlgo.deep_merge`` + ``flatten``, in the same run.

Two 1920×1080 deep images, 0–8 samples per pixel (4 on average), each tidy as a
renderer writes it (sorted, non-overlapping; depths uniform in [1, 20): point samples in
front of 10.5, volume samples behind, filling part of the gap to the next sample), with
independent depths, so that merging them interleaves, splits and merges samples. Points
stay in front of the volumes because OpenImageIO 3.0 composites a volume piece before a
point sample at its front (``tests/compositing/test_deep_oiio.py`` shows it); so laid out,
both sides compute the same image and the benchmark compares them. Alpha is uniform in [0, 0.95] with one
sample in twenty opaque. Timed, interleaved round by round
(:func:`benchmarks._util.time_interleaved`), after a warm-up call:

* ``ours``: :func:`compositing.deep.merge` then :func:`compositing.deep.flatten`;
* ``oiio``: ``ImageBufAlgo.deep_merge(A, B, occlusion_cull=False)`` then ``flatten``
  (the merge that keeps every sample, as ours does);
* ``oiio_culled``: ``deep_merge`` with its default ``occlusion_cull=True`` (drops the samples
  behind the first opaque one, so its flatten has less to do) then ``flatten``.

OpenImageIO's inputs are read from deep EXR files written with :mod:`compositing.deep_io`
(OpenImageIO's own reader fills its ImageBufs); the results are compared (max abs
difference of the flat images). Target: ``ours / oiio`` ≤ 1 (median times).

Memory: a child process makes the two images, then runs merge + flatten once; its peak
resident set (``ru_maxrss``) is reported next to the bytes of the inputs, the merged image
and the flat image.

Usage::

    .venv/bin/python -m benchmarks.bench_deep [--out benchmarks/results] [--repeat 5] [--quick]

Writes ``deep.json`` to ``--out`` and prints a markdown table.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._util import machine_info, markdown_table, time_interleaved, write_json
from compositing.deep import DeepImage, flatten, merge

__all__ = ["main", "make_image", "run"]

SIZES = {"full": (1080, 1920), "quick": (270, 480)}


def make_image(shape: tuple[int, int], seed: int, mean_samples: int = 4) -> DeepImage:
    """A tidy deep image with 0..2·mean_samples samples per pixel (module docstring)."""
    rng = np.random.default_rng(seed)
    h, w = shape
    counts = rng.integers(0, 2 * mean_samples + 1, size=(h, w))
    n = int(counts.sum())
    pixel = np.repeat(np.arange(h * w), counts.reshape(-1))
    z = np.sort(rng.uniform(1.0, 20.0, n) + 100.0 * pixel)  # sorted within each pixel
    nxt = np.append(z[1:], np.inf)
    last = np.zeros(n, bool)
    last[np.cumsum(counts.reshape(-1))[counts.reshape(-1) > 0] - 1] = True
    gap = np.where(last, 2.0, nxt - z)
    volume = (z - 100.0 * pixel) >= 10.5  # points in [1, 10.5), volumes behind
    zback = z + volume * gap * rng.uniform(0.2, 1.0, n)
    base = 100.0 * pixel
    alpha = rng.uniform(0.0, 0.95, n)
    alpha[rng.random(n) < 0.05] = 1.0
    rgba = np.concatenate([rng.random((n, 3)) * alpha[:, None], alpha[:, None]], axis=1)
    return DeepImage(counts, (z - base).astype(np.float32), (zback - base).astype(np.float32), rgba)


def _memory_child(shape: tuple[int, int]) -> dict[str, float]:
    """Peak RSS of a fresh process making the two images and running merge + flatten once."""
    code = (
        "import json, resource, sys\n"
        "from benchmarks.bench_deep import make_image\n"
        "from compositing.deep import flatten, merge\n"
        f"a, b = make_image({shape!r}, 1), make_image({shape!r}, 2)\n"
        "flatten(merge(a.__class__.empty(1, 1), a.__class__.empty(1, 1)))  # compile/load kernels\n"
        "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "m = merge(a, b); f = flatten(m)\n"
        "peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "print(json.dumps({'rss_before_kib': before, 'peak_rss_kib': peak,"
        " 'inputs_bytes': a.nbytes + b.nbytes, 'merged_bytes': m.nbytes, 'flat_bytes': f.nbytes,"
        " 'merged_samples': m.n_samples}))\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        cwd=Path(__file__).parents[1],
    )
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run(out: Path | None = None, repeat: int = 5, quick: bool = False) -> dict:
    """Run the benchmark; write ``deep.json`` into ``out`` when given; return the results."""
    import OpenImageIO as oiio  # noqa: N813

    from compositing.deep_io import write_deep

    shape = SIZES["quick" if quick else "full"]
    t0 = time.perf_counter()
    a, b = make_image(shape, 1), make_image(shape, 2)
    made_s = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        write_deep(Path(tmp) / "a.exr", a)
        write_deep(Path(tmp) / "b.exr", b)
        write_s = time.perf_counter() - t0
        bufs = [oiio.ImageBuf(str(Path(tmp) / name)) for name in ("a.exr", "b.exr")]
        for buf in bufs:
            if not buf.read(force=True):
                raise RuntimeError(f"OpenImageIO cannot read the benchmark image: {buf.geterror()}")
    iba = oiio.ImageBufAlgo
    results: dict[str, np.ndarray] = {}

    def ours() -> None:
        results["ours"] = flatten(merge(a, b))

    def theirs() -> None:
        results["oiio"] = iba.flatten(iba.deep_merge(bufs[0], bufs[1], occlusion_cull=False))

    def theirs_culled() -> None:
        results["oiio_culled"] = iba.flatten(iba.deep_merge(bufs[0], bufs[1], occlusion_cull=True))

    timings = time_interleaved({"ours": ours, "oiio": theirs, "oiio_culled": theirs_culled}, repeat=repeat)
    diffs = {}
    for name in ("oiio", "oiio_culled"):
        spec = results[name].spec()
        px = np.asarray(results[name].get_pixels(oiio.FLOAT)).reshape(spec.height, spec.width, -1)
        rgba = px[..., [list(spec.channelnames).index(k) for k in "RGBA"]]
        diffs[name] = float(np.abs(rgba - results["ours"]).max())
    report = {
        "benchmark": "deep merge + flatten",
        "size": f"{shape[1]}x{shape[0]}",
        "samples": [a.n_samples, b.n_samples],
        "mean_samples_per_pixel": (a.n_samples + b.n_samples) / (2 * shape[0] * shape[1]),
        "repeat": repeat,
        "timings": timings,
        "ratio_vs_oiio": timings["ours"]["median_s"] / timings["oiio"]["median_s"],
        "ratio_vs_oiio_culled": timings["ours"]["median_s"] / timings["oiio_culled"]["median_s"],
        "target_ratio": 1.0,
        "max_abs_diff_flat": diffs,
        "setup_s": {"make_images": made_s, "write_two_deep_exr": write_s},
        "memory": _memory_child(shape),
        "machine": machine_info(),
    }
    if out is not None:
        write_json(Path(out) / ("deep_quick.json" if quick else "deep.json"), report)
    return report


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.bench_deep", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="480×270 instead of 1920×1080")
    args = parser.parse_args(argv)
    r = run(args.out, repeat=args.repeat, quick=args.quick)
    t = r["timings"]
    rows = [
        [name, f"{t[name]['median_s'] * 1e3:.0f}", f"{t[name]['min_s'] * 1e3:.0f}"]
        for name in ("ours", "oiio", "oiio_culled")
    ]
    print(markdown_table(["merge + flatten", "median ms", "min ms"], rows))
    mem = r["memory"]
    print(
        f"ratio ours/oiio {r['ratio_vs_oiio']:.3f} (culled {r['ratio_vs_oiio_culled']:.3f}); "
        f"max |diff| {r['max_abs_diff_flat']}; peak RSS {mem['peak_rss_kib'] / 1024:.0f} MiB "
        f"(inputs {mem['inputs_bytes'] / 2**20:.0f} MiB, merged {mem['merged_bytes'] / 2**20:.0f} MiB)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
