"""Texture construction: peak memory and time for a large image, against a plain copy.

``blinn_phong.model.texture.Texture`` converts the given image into its stored float32 premultiplied
RGBA block by block. Measured here for a ``side × side`` RGBA image (default 8192², 1 GiB
stored) of each kind of input — float32 linear premultiplied (cast only), float32 straight
(premultiplied on the way), float32 straight sRGB (decoded by the IEC 61966-2-1 EOTF) and float16
premultiplied:

* **peak memory**: ``tracemalloc``'s peak of the construction (numpy reports its buffers to it)
  and, on Linux, the growth of the process's peak resident set (``VmHWM``, reset through
  ``/proc/self/clear_refs`` before each construction), both as multiples of the stored size;
* **time**: median of ``repeat`` constructions, interleaved with the peer — ``np.array(image,
  np.float32)``, the one copy any construction must make — and the ratio between them.

Usage::

    python -m benchmarks.bench_texture --out benchmarks/results [--side 8192] [--repeat 3]

Writes ``texture.json``.
"""

from __future__ import annotations

import argparse
import gc
import os
import tracemalloc
from pathlib import Path

import numpy as np

from benchmarks._util import machine_info, markdown_table, time_interleaved, write_json
from blinn_phong.model.texture import BLOCK_TEXELS, Texture

INPUTS = {
    "float32 linear premultiplied": (np.float32, {}),
    "float32 linear straight": (np.float32, {"alpha": "straight"}),
    "float32 sRGB straight": (np.float32, {"colorspace": "sRGB", "alpha": "straight"}),
    "float16 linear premultiplied": (np.float16, {}),
}


def _status(key: str) -> int | None:
    """A ``/proc/self/status`` field in bytes (Linux), or None."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _reset_peak_rss() -> bool:
    """Reset the peak resident set (``VmHWM``) to the current one; False where Linux does not allow it."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def image(side: int, dtype: type) -> np.ndarray:
    """A random premultiplied RGBA image (colour ≤ alpha), filled in bands to keep the set-up small."""
    rng = np.random.default_rng(0)
    out = np.empty((side, side, 4), dtype)
    for r in range(0, side, 256):
        block = rng.random((min(256, side - r), side, 4), dtype=np.float32)
        block[..., :3] *= block[..., 3:4]
        out[r : r + 256] = block
    return out


def peak(side: int, dtype: type, kwargs: dict) -> dict[str, float | None]:
    """Peak memory of one construction, as multiples of the stored size (16 bytes per texel)."""
    img = image(side, dtype)
    stored = side * side * 16
    gc.collect()
    rss_reset = _reset_peak_rss()
    rss0 = _status("VmRSS")
    tracemalloc.start()
    try:
        texture = Texture(img, **kwargs)
        _, traced = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    hwm = _status("VmHWM")
    del texture
    rss = (hwm - rss0) / stored if rss_reset and hwm is not None and rss0 is not None else None
    return {
        "traced_peak_x_stored": traced / stored,
        "traced_extra_mib": (traced - stored) / 2**20,
        "rss_peak_x_stored": rss,
    }


def _timing(img: np.ndarray, kwargs: dict, repeat: int) -> dict[str, dict[str, float]]:
    """Construction and the plain float32 copy, interleaved (``time_interleaved``)."""
    return time_interleaved(
        {"texture": lambda: Texture(img, **kwargs), "copy": lambda: np.array(img, np.float32)},
        repeat=repeat,
        warmup=0,
    )


def run(out_dir: str | os.PathLike, *, side: int = 8192, repeat: int = 3) -> dict:
    """Measure every input kind; write ``texture.json`` into ``out_dir``; return the results."""
    results: dict[str, object] = {
        "benchmark": "texture",
        "machine": machine_info(),
        "side": side,
        "stored_bytes": side * side * 16,
        "block_texels": BLOCK_TEXELS,
        "repeat": repeat,
    }
    rows = []
    for name, (dtype, kwargs) in INPUTS.items():
        print(f"-- {name}", flush=True)
        memory = peak(side, dtype, kwargs)
        timing = _timing(image(side, dtype), kwargs, repeat)
        entry = {**memory, "texture_s": timing["texture"], "copy_s": timing["copy"]}
        entry["time_x_copy"] = timing["texture"]["median_s"] / timing["copy"]["median_s"]
        results[name] = entry
        rss = memory["rss_peak_x_stored"]
        rows.append(
            [
                name,
                f"{memory['traced_peak_x_stored']:.3f}",
                "—" if rss is None else f"{rss:.3f}",
                f"{timing['texture']['median_s']:.2f}",
                f"{timing['copy']['median_s']:.2f} ({entry['time_x_copy']:.1f}×)",
            ]
        )
    results["table"] = markdown_table(
        ["input", "peak traced (× stored)", "peak RSS (× stored)", "construction s", "copy peer s (ratio)"],
        rows,
    )
    write_json(Path(out_dir) / "texture.json", results)
    print(results["table"])
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="benchmarks/results")
    parser.add_argument("--side", type=int, default=8192)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    run(args.out, side=args.side, repeat=args.repeat)


if __name__ == "__main__":
    main()
