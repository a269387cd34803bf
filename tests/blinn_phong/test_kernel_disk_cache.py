"""Every compiled kernel a render uses is loaded from the disk cache by a new process — also
by a second checkout of the same code at another path.

A kernel that numba cannot key (one closing over another compiled function, whose pickled
form carries a per-process identity) is compiled again by every process: seconds before the
first frame of every batch job. A cache kept beside the sources (numba's default) is compiled
again by every clone. The check is numba's own: run a render of every effect in a fresh
process from this checkout, then from a copy of its packages in another directory (other
modification times), with the same per-user kernel cache; the second process must report no
cache miss for any kernel of ``blinn_phong`` or ``compositing``
(``Dispatcher.stats.cache_misses``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import gc
import numpy as np
import numba
import blinn_phong as bp
import compositing
from blinn_phong.model.primitives import grid_plane, uv_sphere

pos, tri, nrm = uv_sphere(24, 12, 1.0)
lifted = np.eye(4)
lifted[2, 3] = 1.2
glass = bp.Mesh(pos, tri, nrm, transform=lifted, material=bp.Material(opacity=0.6))
ball = bp.Mesh(pos, tri, nrm, transform=np.diag([0.5, 0.5, 0.5, 1.0]))
plane, ptri, pnrm = grid_plane(1, 1, (6.0, 6.0))
camera = bp.Camera.perspective(40, 1, 0.5, 50, view=bp.look_at((0, -6, 3), (0, 0, 0.5), (0, 0, 1)))
lights = [bp.DirectionalLight(direction=(0.3, 0.2, -1)), bp.PointLight((1, 1, 4))]
scene = bp.Scene(meshes=[bp.Mesh(plane, ptri, pnrm), glass, ball], lights=lights, camera=camera)
for options in (
    {"shadows": "none"},
    {"shadows": "shadow_map"},
    {"shadows": "ray_traced"},
    {"shadows": "shadow_volume"},
    {},
    {"fog": bp.Fog("exp", density=0.05)},
    {"shading": "gouraud", "shadows": "none", "samples": 4},
):
    result = bp.render(scene, 48, 48, **options)
opaque = bp.Scene(meshes=[bp.Mesh(plane, ptri, pnrm), ball], lights=lights, camera=camera)
for options in ({"shadows": "ray_traced", "shading": "flat"}, {"shadows": "none", "shading": "gouraud"}):
    bp.render(opaque, 48, 48, **options)  # culled shadow rays; flat and Gouraud on the fused pass
texture = bp.Texture(np.full((2, 2, 4), 0.5), interpolation="closest", extension="clip")
floor = bp.Mesh(
    plane, ptri, pnrm, material=bp.Material(base_color_texture=texture), uv=plane[:, :2] / 6 + 0.5
)
bp.render(bp.Scene(meshes=[floor, ball], lights=lights, camera=camera), 48, 48, shadows="none")  # textured
compositing.composite(result.rgba, result.rgba, "src_over", engine="numba")
missed = sorted(
    f"{o.py_func.__module__}.{o.py_func.__qualname__}"
    for o in gc.get_objects()
    if isinstance(o, numba.core.dispatcher.Dispatcher)
    and o.py_func.__module__.split(".")[0] in ("blinn_phong", "compositing")
    and sum(o.stats.cache_misses.values())
)
print("MISSED", ";".join(missed))
"""


@pytest.mark.slow
@pytest.mark.timeout(1800)  # the first run on a machine compiles every effect's kernels
def test_a_new_process_of_another_checkout_compiles_no_kernel_again(tmp_path: Path) -> None:
    copy = tmp_path / "second-clone"
    for package in ("blinn_phong", "compositing"):
        shutil.copytree(ROOT / package, copy / package, ignore=shutil.ignore_patterns("__pycache__"))
    for path in copy.rglob("*.py"):
        os.utime(path, (1_600_000_000, 1_600_000_000))
    reports = []
    # the first run may compile (the first on this machine); the second, elsewhere, must not
    for checkout in (ROOT, copy):
        env = {**os.environ, "PYTHONPATH": str(checkout)}
        done = subprocess.run(
            [sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=1700, cwd=checkout
        )
        assert done.returncode == 0, done.stderr[-3000:]
        reports.append(done.stdout.strip().splitlines()[-1])
    assert reports[1] == "MISSED", f"compiled again in a new process: {reports[1][7:]}"
