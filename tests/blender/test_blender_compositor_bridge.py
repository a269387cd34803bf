"""Blender's own compositor against our kernels and against the formulas in Blender's source.

One Blender process (``sys.executable``, so the 4.2 run uses bpy 4.2) composites the
whole matrix of :func:`addon.verify.standard_cases` on 97×61 images with α = 0, α = 1,
glow (rgb ≠ 0 at α = 0), HDR and negative colour; the pixels come back through a
32-bit multilayer EXR read with OpenImageIO. The node groups are the ones the add-on's
operator puts into the file. Each case is then checked three ways:

* against ``compositing`` (the issue's requirement: max abs error ≤ 1e-6);
* against closed forms written out here: Porter & Duff (1984) table 1 for the node
  groups, and the Alpha Over / Alpha Convert formulas of Blender's source
  (4.5/5.0: ``node_composite_alpha_over.cc``, ``node_composite_premulkey.cc``; 4.2:
  ``COM_AlphaOver{Premultiply,Key}Operation.cc``, ``COM_ConvertOperation.cc``);
* exact pass-through of ``src`` and ``dst``, which catches any flip or transpose.
"""

from __future__ import annotations

import importlib.metadata
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from addon.verify import ALPHA_OVER_OPERATORS, Case, sample_images, standard_cases, verify_cases
from tests.porter_duff_paper import PAPER

pytestmark = [pytest.mark.blender, pytest.mark.timeout(300)]

REPO = Path(__file__).resolve().parents[2]
BPY_VERSION = tuple(int(p) for p in importlib.metadata.version("bpy").split(".")[:2])
HAS_ALPHA_OVER_MODES = BPY_VERSION >= (5, 0)
# Blender 4.4 replaced the CPU compositor (release notes 4.4, Compositor); 4.2 still runs the old
# operations (source/blender/compositor/operations/COM_*Operation.cc).
LEGACY_CPU_COMPOSITOR = BPY_VERSION < (4, 4)
EXPECTED_MODES = ALPHA_OVER_OPERATORS if HAS_ALPHA_OVER_MODES else ("src_over",)
CASES = standard_cases(EXPECTED_MODES)
TOLERANCE = 1e-6


@pytest.fixture(scope="module")
def images() -> tuple[np.ndarray, np.ndarray]:
    return sample_images(61, 97, seed=4)


@pytest.fixture(scope="module")
def matrix(images):
    src, dst = images
    results, report = verify_cases(src, dst, CASES, timeout=240)
    return {r.case: r for r in results}, report


def _ids(cases):
    return [c.label.replace(" ", "-") for c in cases]


def test_blender_reports_its_version_and_modes(matrix) -> None:
    _, report = matrix
    assert report["blender_version"].startswith(f"{BPY_VERSION[0]}.{BPY_VERSION[1]}")
    assert tuple(report["alpha_over_modes"]) == EXPECTED_MODES


def test_operator_adds_the_artist_groups_to_the_file(matrix) -> None:
    _, report = matrix
    titles = {
        "src": "A",
        "dst": "B",
        "clear": "clear",
        "plus": "A plus B",
        "src_over": "A over B",
        "disjoint_over": "A disjoint-over B",
    }
    for title in titles.values():
        assert f"Porter-Duff · {title}" in report["groups_in_file"]
    assert len(report["groups_in_file"]) == 15  # 12 Porter-Duff operators, plus, disjoint/conjoint over


def test_images_pass_through_unchanged(matrix, images) -> None:
    results, _ = matrix
    src, dst = images
    np.testing.assert_array_equal(results[Case("node_group", "src")].blender, src)
    np.testing.assert_array_equal(results[Case("node_group", "dst")].blender, dst)
    np.testing.assert_array_equal(results[Case("alpha_over", "src_over", 0.0)].blender, dst)


@pytest.mark.parametrize("case", CASES, ids=_ids(CASES))
def test_blender_matches_our_kernels(matrix, case: Case) -> None:
    result = matrix[0][case]
    assert result.blender.shape == (61, 97, 4)
    if case == Case("alpha_convert", "unpremultiply") and LEGACY_CPU_COMPOSITOR:
        # Blender 4.2 multiplies by the reciprocal (rgb·(1/a)), we divide: one rounding apart,
        # relative error ≤ 1 ulp (absolute error grows with rgb/a, ~2e-4 at rgb/a ≈ 2000).
        bound = np.finfo(np.float32).eps * np.abs(result.ours)
        assert (result.difference <= bound).all(), result.max_abs_error
        return
    assert result.max_abs_error <= TOLERANCE, (case.label, result.max_abs_error)


NODE_GROUP_CASES = [c for c in CASES if c.kind == "node_group" and c.operator in PAPER]


@pytest.mark.parametrize("case", NODE_GROUP_CASES, ids=_ids(NODE_GROUP_CASES))
def test_node_groups_match_porter_duff_closed_form(matrix, images, case: Case) -> None:
    src, dst = (x.astype(np.float64) for x in images)
    fa, fb = (f(src[..., 3:], dst[..., 3:]) for f in PAPER[case.operator])
    want = dst * (1 - case.factor) + (src * fa + dst * fb) * case.factor
    np.testing.assert_allclose(matrix[0][case].blender, want, rtol=0, atol=TOLERANCE)


def _alpha_over_5(src, dst, mode, straight, factor):
    """Blender 5.0 ``node_composite_alpha_over.cc``, transcribed (4.5 has its Over mode)."""
    fa = np.clip(src[..., 3:], 0, 1)
    ba = np.clip(dst[..., 3:], 0, 1)
    fg = np.concatenate([src[..., :3] * fa, fa], axis=-1) if straight else src

    def safe_divide(x, y):
        return np.where(y == 0, 0, x / np.where(y == 0, 1, y))

    if mode == "src_over":
        m = fg + dst * (1 - fa)
    elif mode == "disjoint_over":
        m = np.where(fa + ba < 1, fg + dst, fg + safe_divide(dst, ba) * (1 - fa))
    else:
        m = np.where(fa > ba, fg, fg + dst * (1 - safe_divide(fa, ba)))
    return dst * (1 - factor) + m * factor


def _alpha_over_4(src, dst, straight, factor):
    """Blender 4.2 ``COM_AlphaOverPremultiplyOperation`` / ``COM_AlphaOverKeyOperation``, transcribed."""
    fa = src[..., 3:]
    if straight:  # key: fa <= 0 -> bg, else lerp(bg, (fg.rgb, 1), f·fa)
        fg = np.concatenate([src[..., :3], np.ones_like(fa)], axis=-1)
        return np.where(fa <= 0, dst, dst * (1 - factor * fa) + fg * (factor * fa))
    out = (1 - factor * fa) * dst + factor * src  # premultiply
    return np.where(fa < 0, dst, np.where((factor == 1) & (fa >= 1), src, out))


ALPHA_OVER_CASES = [c for c in CASES if c.kind == "alpha_over"]


@pytest.mark.parametrize("case", ALPHA_OVER_CASES, ids=_ids(ALPHA_OVER_CASES))
def test_alpha_over_matches_blenders_formula(matrix, images, case: Case) -> None:
    src, dst = (x.astype(np.float64) for x in images)
    if not LEGACY_CPU_COMPOSITOR:
        want = _alpha_over_5(src, dst, case.operator, case.straight_alpha, case.factor)
    else:
        want = _alpha_over_4(src, dst, case.straight_alpha, case.factor)
    np.testing.assert_allclose(matrix[0][case].blender, want, rtol=0, atol=TOLERANCE)


def test_alpha_convert_matches_blenders_formula(matrix, images) -> None:
    src = images[0]
    a = src[..., 3:]
    premultiplied = np.concatenate([src[..., :3] * a, a], axis=-1)
    np.testing.assert_array_equal(matrix[0][Case("alpha_convert", "premultiply")].blender, premultiplied)
    with np.errstate(divide="ignore", invalid="ignore"):
        # 4.5 and 5.0 divide; 4.2 multiplies by the reciprocal. α = 0 keeps the colour (glow survives).
        rgb = src[..., :3] * (np.float32(1) / a) if LEGACY_CPU_COMPOSITOR else src[..., :3] / a
    straight = np.concatenate([np.where(a == 0, src[..., :3], rgb), a], axis=-1)
    np.testing.assert_array_equal(matrix[0][Case("alpha_convert", "unpremultiply")].blender, straight)


def test_register_and_unregister_leave_blender_clean(tmp_path: Path) -> None:
    out = tmp_path / "state.json"
    script = textwrap.dedent(
        f"""
        import json, sys
        sys.path.insert(0, {str(REPO)!r})
        import bpy, addon
        def state():
            return {{
                "menu": "NODE_MT_porter_duff" in dir(bpy.types),
                "operator": hasattr(bpy.types, "NODE_OT_porter_duff_add_groups"),
                "add_menu_hook": "draw_add_menu" in [f.__name__ for f in
                                                     getattr(bpy.types.NODE_MT_add.draw, "_draw_funcs", [])],
            }}
        before = state()
        addon.register()
        registered = state()
        addon.unregister()
        after = state()
        open({str(out)!r}, "w").write(json.dumps([before, registered, after]))
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        env={"BLENDER_USER_RESOURCES": str(tmp_path / "user"), "PATH": ""},
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    before, registered, after = json.loads(out.read_text())
    assert registered == {"menu": True, "operator": True, "add_menu_hook": True}
    assert before == after == {"menu": False, "operator": False, "add_menu_hook": False}


def test_add_menu_operator_places_a_working_group_node(tmp_path: Path, images) -> None:
    """The artist's path: Compositor › Add › Porter-Duff › A atop B, then render."""
    from addon.verify import read_exr_layers, write_exr

    src, dst = images
    write_exr(tmp_path / "src.exr", src)
    write_exr(tmp_path / "dst.exr", dst)
    script = textwrap.dedent(
        f"""
        import sys
        sys.path.insert(0, {str(REPO)!r})
        import bpy, addon
        from addon import compat
        bpy.ops.wm.read_homefile(use_factory_startup=True)
        addon.register()
        try:
            scene = bpy.context.scene
            scene.render.resolution_x, scene.render.resolution_y = {src.shape[1]}, {src.shape[0]}
            scene.render.resolution_percentage = 100
            compat.set_full_precision(scene)
            tree = compat.compositor_tree(scene)
            window = bpy.context.window_manager.windows[0]
            area = window.screen.areas[0]
            area.ui_type = "CompositorNodeTree"
            space = area.spaces.active
            if space.node_tree is None:
                space.node_tree = tree
            region = next(r for r in area.regions if r.type == "WINDOW")
            with bpy.context.temp_override(window=window, area=area, region=region, space_data=space):
                bpy.ops.node.porter_duff_add(operator="src_atop")
            (group,) = [n for n in tree.nodes if n.bl_idname == "CompositorNodeGroup"]
            for name, socket in (("src", "Source"), ("dst", "Destination")):
                image = bpy.data.images.load({str(tmp_path)!r} + f"/{{name}}.exr")
                image.colorspace_settings.name = "Non-Color"
                image.alpha_mode = "CHANNEL_PACKED"
                node = tree.nodes.new("CompositorNodeImage")
                node.image = image
                tree.links.new(node.outputs["Image"], group.inputs[socket])
            out = compat.add_file_output(tree, {str(tmp_path / "out")!r}, "atop", ["atop"])
            tree.links.new(group.outputs[0], out["atop"])
            bpy.ops.render.render(write_still=False)
        finally:
            addon.unregister()
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        env={"BLENDER_USER_RESOURCES": str(tmp_path / "user"), "PATH": ""},
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    (result_file,) = (tmp_path / "out").glob("atop*.exr")
    got = read_exr_layers(result_file)["atop"]
    s, d = (x.astype(np.float64) for x in images)
    want = s * d[..., 3:] + d * (1 - s[..., 3:])  # A atop B, Porter & Duff 1984
    np.testing.assert_allclose(got, want, rtol=0, atol=TOLERANCE)
