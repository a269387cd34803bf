"""One kernel cache per user and machine (``compositing/_kernel_cache.py``), shared by checkouts.

The independent source throughout is numba's own bookkeeping: a dispatcher's
``stats.cache_hits`` / ``stats.cache_misses`` (a miss is a compilation), its cache's directory,
numba's per-overload compile timer (``metadata["timers"]["compiler_lock"]``), and the files
numba writes (``.nbi`` index, ``.nbc`` machine code). Each process is a fresh interpreter with a
private cache directory (``BLINN_PHONG_KERNEL_CACHE``); the kernels are a small family (one
mesh pass of ``blinn_phong.geometry._mesh_kernels`` and the generated ``src_over`` compositing kernel,
about a second to compile) so the default run stays quick.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

import blinn_phong  # noqa: F401  (registers the package, as a render would)
from compositing import _kernel_cache as kc

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import json, sys
import numpy as np
import blinn_phong, compositing
from blinn_phong.geometry import _mesh_kernels as m
from compositing import _fused
from compositing._kernel_cache import compile_clock

rng = np.random.default_rng(3)
pos = rng.random((40, 3))
transform = np.array([[1, 0, 0, 1], [0, 2, 0, 0], [0, 0, 1, -1], [0, 0, 0, 1]], float)
with compile_clock() as log:
    world, lo, hi, radius = m.world_bounds(pos, np.ones(40, np.bool_), transform)
    a = rng.random((16, 16, 4), dtype=np.float32)
    a[..., :3] *= a[..., 3:]
    over = compositing.composite(a, a[::-1].copy(), "src_over", engine="numba")
kernel = _fused._compiled("src_over", compositing.PORTER_DUFF["src_over"], "float32", False)
counts = {
    name: [sum(k.stats.cache_hits.values()), sum(k.stats.cache_misses.values()), k.stats.cache_path]
    for name, k in (("world_bounds", m.world_bounds), ("src_over", kernel))
}
print(json.dumps({
    "source": m.__file__, "counts": counts, "compile_s": log.seconds, "by_module": dict(log.by_module),
    "world": world.tolist(), "over": float(over.sum()),
}))
"""


def _copy_checkout(target: Path, mtime: float) -> Path:
    """The packages copied to ``target`` (another clone's path), every file's mtime set to ``mtime``."""
    for package in ("blinn_phong", "compositing"):
        shutil.copytree(ROOT / package, target / package, ignore=shutil.ignore_patterns("__pycache__"))
    for path in target.rglob("*.py"):
        os.utime(path, (mtime, mtime))
    return target


def _run(checkout: Path, cache: Path, code: str = CHILD) -> dict:
    env = {**os.environ, kc.ENVIRONMENT_VARIABLE: str(cache), "PYTHONPATH": str(checkout)}
    env.pop("NUMBA_CACHE_DIR", None)
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600, cwd=checkout
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _hits_misses(report: dict) -> dict[str, list[int]]:
    return {name: counts[:2] for name, counts in report["counts"].items()}


def _machine_code(cache: Path) -> dict[str, int]:
    return {str(p.relative_to(cache)): p.stat().st_mtime_ns for p in cache.rglob("*.nbc")}


def test_a_second_checkout_at_another_path_compiles_nothing(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    first = _run(_copy_checkout(tmp_path / "one", 1_600_000_000), cache)
    assert first["source"].startswith(str(tmp_path / "one"))
    assert {name: c[:2] for name, c in first["counts"].items()} == {
        "world_bounds": [0, 1],
        "src_over": [0, 1],
    }
    assert first["compile_s"] > 0 and set(first["by_module"]) == {
        "blinn_phong.geometry._mesh_kernels",
        "compositing (generated)",
    }
    stored = _machine_code(cache)
    assert len(stored) == 2  # one machine code file per kernel, nothing beside the sources
    assert not list((tmp_path / "one").rglob("*.nbi"))  # no cache next to the sources

    # Another path, other modification times, same contents: every kernel loaded, none compiled.
    second = _run(_copy_checkout(tmp_path / "two", 1_700_000_000), cache)
    assert second["source"].startswith(str(tmp_path / "two"))
    assert {name: c[:2] for name, c in second["counts"].items()} == {
        "world_bounds": [1, 0],
        "src_over": [1, 0],
    }
    assert second["compile_s"] == 0.0 and second["by_module"] == {}
    assert _machine_code(cache) == stored  # nothing rewritten
    assert second["world"] == first["world"] and second["over"] == first["over"]
    for name, (_hits, _misses, path) in second["counts"].items():
        assert Path(path).is_relative_to(cache), name
        assert path == first["counts"][name][2]

    # The kernels' values, independently: world_bounds applies the affine transform.
    pos = np.random.default_rng(3).random((40, 3))
    expected = pos * [1, 2, 1] + [1, 0, -1]
    np.testing.assert_allclose(np.array(second["world"]), expected, rtol=0, atol=1e-15)


def test_edited_sources_get_their_own_entry_and_leave_the_others_alone(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    one = _copy_checkout(tmp_path / "one", 1_600_000_000)
    first = _run(one, cache)
    edited = _copy_checkout(tmp_path / "edited", 1_600_000_000)
    kernels = edited / "blinn_phong" / "geometry" / "_mesh_kernels.py"
    kernels.write_text(kernels.read_text() + "\n# an edit that changes the file, not the kernel\n")
    changed = _run(edited, cache)
    # The edited module compiles into a directory of its own; the unchanged family is shared.
    assert changed["counts"]["world_bounds"][:2] == [0, 1]
    assert changed["counts"]["src_over"][:2] == [1, 0]
    assert changed["counts"]["world_bounds"][2] != first["counts"]["world_bounds"][2]
    # The first checkout still loads its own entry: two versions of the code do not take turns.
    again = _run(one, cache)
    assert {name: c[:2] for name, c in again["counts"].items()} == {
        "world_bounds": [1, 0],
        "src_over": [1, 0],
    }


def test_a_change_in_an_imported_module_changes_the_stamp(tmp_path: Path) -> None:
    # numba keys a kernel by its own file only; a kernel inlining a function of another project
    # module must be compiled again when that module changes. The stamp follows the imports.
    stamp = "from blinn_phong.frame import fused; from compositing import _kernel_cache as kc; "
    stamp += "print(kc.source_stamp(fused.__file__))"

    def fast_stamp(checkout: Path) -> str:
        done = subprocess.run(
            [sys.executable, "-c", stamp],
            env={**os.environ, "PYTHONPATH": str(checkout)},
            capture_output=True,
            text=True,
            timeout=120,
            cwd=checkout,
        )
        assert done.returncode == 0, done.stderr[-3000:]
        return done.stdout.strip()

    copy = _copy_checkout(tmp_path / "copy", 1_600_000_000)
    original = fast_stamp(copy)
    assert original == fast_stamp(ROOT)  # same contents at another path
    planner = copy / "blinn_phong" / "planning" / "planner.py"
    lighting = copy / "blinn_phong" / "frame" / "lighting.py"
    planner.write_text(planner.read_text() + "\n# planner.py is not imported by fused.py\n")
    assert fast_stamp(copy) == original
    lighting.write_text(lighting.read_text() + "\n# lighting.py is (its kernels are inlined)\n")
    assert fast_stamp(copy) != original


def test_two_processes_compiling_at_once_both_succeed(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    env = {**os.environ, kc.ENVIRONMENT_VARIABLE: str(cache), "PYTHONPATH": str(ROOT)}
    workers = [
        subprocess.Popen(
            [sys.executable, "-c", CHILD],
            env=env,
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    reports = []
    for worker in workers:
        out, err = worker.communicate(timeout=600)
        assert worker.returncode == 0, err[-3000:]
        reports.append(json.loads(out.strip().splitlines()[-1]))
    assert reports[0]["world"] == reports[1]["world"] and reports[0]["over"] == reports[1]["over"]
    third = _run(ROOT, cache)  # the entries they left are whole: loaded, nothing compiled
    assert {name: c[:2] for name, c in third["counts"].items()} == {
        "world_bounds": [1, 0],
        "src_over": [1, 0],
    }
    assert third["world"] == reports[0]["world"]


def test_an_index_is_saved_under_the_entry_lock(tmp_path: Path) -> None:
    # Two workers saving different signatures of one kernel at once could otherwise each write
    # an index without the other's entry. While this process holds the entry's lock, a child
    # that has finished compiling cannot write numba's index; once released, it does.
    fcntl = pytest.importorskip("fcntl")
    cache = tmp_path / "cache"
    listen = textwrap.dedent(
        """
        import sys
        from numba.core import event
        class Done(event.Listener):
            def on_start(self, ev):
                pass
            def on_end(self, ev):
                print("COMPILED", flush=True)
        event.register("numba:compile", Done())
        """
    )
    child = subprocess.Popen(
        [sys.executable, "-c", listen + CHILD],
        env={**os.environ, kc.ENVIRONMENT_VARIABLE: str(cache), "PYTHONPATH": str(ROOT)},
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    entry = (
        cache
        / kc.environment_key()
        / "blinn_phong"
        / "geometry"
        / (
            "_mesh_kernels-"
            + kc.source_stamp(ROOT / "blinn_phong" / "geometry" / "_mesh_kernels.py")[:16]
            + "-"
            + hashlib.sha256(b"blinn_phong.geometry._mesh_kernels").hexdigest()[:8]  # the module's name
        )
    )
    entry.mkdir(parents=True)
    fd = os.open(entry / ".lock", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        assert child.stdout.readline().strip() == "COMPILED"  # world_bounds compiled, save pending
        time.sleep(0.5)
        assert child.poll() is None
        assert not list(entry.glob("*.nbi"))
    finally:
        os.close(fd)
    _out, err = child.communicate(timeout=600)
    assert child.returncode == 0, err[-3000:]
    assert len(list(entry.glob("*.nbi"))) == 1


def test_every_kernel_of_the_packages_uses_the_shared_cache(tmp_path: Path) -> None:
    # Kernels decorated at import (no compilation needed to see where they would be cached).
    code = textwrap.dedent(
        """
        import gc, json
        import numba
        import blinn_phong
        from blinn_phong.geometry import _mesh_kernels
        from blinn_phong.shadows import _volume_helpers
        from blinn_phong.shadows import frame_maps
        from blinn_phong.shadows import ray_culling
        from blinn_phong.shadows import map_lookup_kernels, map_receiver_kernels, map_render_kernels
        from blinn_phong.shadows import ray_setup_kernels
        found = {}
        for o in gc.get_objects():
            if isinstance(o, numba.core.dispatcher.Dispatcher) and o.py_func.__module__[:11] == "blinn_phong":
                found[o.py_func.__module__ + "." + o.py_func.__qualname__] = o.stats.cache_path
        print(json.dumps(found))
        """
    )
    cache = tmp_path / "cache"
    env = {**os.environ, kc.ENVIRONMENT_VARIABLE: str(cache), "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    found = json.loads(done.stdout.strip().splitlines()[-1])
    shadow_maps = "blinn_phong.shadows.map_render_kernels."
    assert len(found) > 20 and any(name.startswith(shadow_maps) for name in found), found
    outside = {name: path for name, path in found.items() if not Path(path).is_relative_to(cache)}
    assert not outside


def test_unused_entries_are_pruned_and_used_ones_kept(tmp_path: Path) -> None:
    root = tmp_path / "cache"
    now = 2_000_000_000.0
    day = 86400.0
    env = root / "cpython-311-numba0.0-cpu-0123456789ab"
    old = env / "blinn_phong" / "fast-aaaa"
    recent = env / "blinn_phong" / "fast-bbbb"
    other_env_old = root / "cpython-311-numba9.9-cpu-ba9876543210" / "compositing" / "x-cccc"
    for entry in (old, recent, other_env_old):
        entry.mkdir(parents=True)
        (entry / "fast.kernel-1.py311.nbi").write_bytes(b"index")
    generated_old = root / "generated" / "k_old.py"
    generated_new = root / "generated" / "k_new.py"
    legacy = root / "k_legacy.py"  # the previous layout: generated sources at the top
    for path in (generated_old, generated_new, legacy):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("# kernel\n")
    ages = {old: 40, recent: 2, other_env_old: 31, generated_old: 45, generated_new: 1, legacy: 90}
    for path, days in ages.items():
        os.utime(path, (now - days * day, now - days * day))
    removed = kc.prune(root, max_age_days=30, now=now)
    assert set(removed) == {old, other_env_old, generated_old, legacy}
    assert recent.is_dir() and (recent / "fast.kernel-1.py311.nbi").read_bytes() == b"index"
    assert generated_new.is_file()
    assert not (root / "cpython-311-numba9.9-cpu-ba9876543210").exists()  # emptied, removed
    assert not [p for p in root.iterdir() if p.name.startswith(".trash-")]
    with pytest.raises(ValueError, match="max_age_days"):
        kc.prune(root, max_age_days=-1)


def test_the_default_directory_is_the_users_cache(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv(kc.ENVIRONMENT_VARIABLE, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    if sys.platform.startswith("linux"):
        assert kc.cache_directory() == tmp_path / "blinn-phong-render" / "kernels"
        monkeypatch.setenv("XDG_CACHE_HOME", "relative/path")  # invalid by the XDG specification
        assert kc.cache_directory() == Path.home() / ".cache" / "blinn-phong-render" / "kernels"
    monkeypatch.setenv(kc.ENVIRONMENT_VARIABLE, str(tmp_path / "mine"))
    assert kc.cache_directory() == tmp_path / "mine"
