"""The case deep compositing exists for: two renders of object sets that interpenetrate.

The sets (a sphere, front and back surfaces, through a tilted transparent pane) are
computed in closed form by :mod:`compositing.deep_demo`. Oracle: the A-buffer of both
sets together, :func:`blinn_phong.effects.oit.resolve_a_buffer` (per-pixel depth sort and front-to-
back ``over`` of all fragments, Carpenter 1984), on the fragments of both sets.
"""

from __future__ import annotations

import numpy as np
import pytest

from blinn_phong.effects.oit import resolve_a_buffer
from compositing.deep import flatten, merge
from compositing.deep_demo import deep_of, flat_of, main, scene_fragments
from compositing.deep_io import read_deep
from compositing.operators import composite

H, W = 60, 80


def a_buffer(sets, n_samples: int) -> np.ndarray:
    """Both sets' fragments resolved per (sub)pixel by the A-buffer."""
    frags = list(sets.values())
    return resolve_a_buffer(
        np.concatenate([f.subpixel for f in frags]),
        np.concatenate([f.depth for f in frags]),
        np.concatenate([f.rgba for f in frags]),
        n_samples,
    )


def test_deep_merge_of_two_renders_equals_one_render_of_both():
    sets = scene_fragments(H, W)
    reference = a_buffer(sets, H * W).reshape(H, W, 4)
    deep = flatten(merge(deep_of(sets["sphere"], (H, W)), deep_of(sets["pane"], (H, W))))
    np.testing.assert_allclose(deep, reference, rtol=0, atol=1e-6)
    # Flat compositing cannot do it: sphere over pane is wrong where the pane is in front.
    flat = composite(flat_of(sets["sphere"], (H, W)), flat_of(sets["pane"], (H, W)), "src_over")
    wrong = np.abs(flat - reference).max(axis=-1) > 0.05
    assert wrong.sum() > 0.05 * H * W
    # ... and right where the pane is behind both sphere surfaces or absent.
    last_sphere = np.full(H * W, -np.inf)
    np.maximum.at(last_sphere, sets["sphere"].pixel, sets["sphere"].depth)
    pane_depth = np.full(H * W, np.inf)
    pane_depth[sets["pane"].pixel] = sets["pane"].depth
    pane_first = pane_depth < last_sphere
    np.testing.assert_allclose(
        flat.reshape(-1, 4)[~pane_first], reference.reshape(-1, 4)[~pane_first], atol=1e-6
    )
    assert (wrong.reshape(-1) <= pane_first).all()


@pytest.mark.parametrize("subpixels", [2, 4])
def test_supersampled_renders_follow_the_coverage_bound(subpixels):
    """Each subpixel's fragment enters its pixel with weight 1/s (s = subpixels²).

    With an opaque sphere front S (colour c_S, alpha a_S = 1) and the pane P (c_P, a_P),
    constant colours, let f_S, f_P be the fractions of a pixel's subpixels each covers, and
    f_SP, f_PS the fractions covered by both with S, respectively P, in front. The
    A-buffer (average of the subpixels' resolved colours) is

        T = f_S c_S + f_P c_P - a_S c_P f_SP - a_P c_S f_PS,

    the deep result with S's sample in front (nearest depths) is

        D = f_S c_S + (1 - f_S a_S) f_P c_P,   so  D - T = a_S c_P (f_SP - f_S f_P) + a_P c_S f_PS,

    and with P in front D - T = a_P c_S (f_PS - f_S f_P) + a_S c_P f_SP. The error is 0 where
    a surface covers the whole pixel or not at all and the order does not change inside the
    pixel; elsewhere |D - T| ≤ a_S |c_P| |f_SP - f_S f_P| + a_P |c_S| f_PS (or the mirror).
    """
    s = subpixels**2
    sets = scene_fragments(H, W, subpixels, sphere_alpha=1.0, back_faces=False, shading=False)
    truth = a_buffer(sets, H * W * s)
    n_sub = H * W * s
    rows = np.arange(H * subpixels)[:, None] // subpixels
    cols = np.arange(W * subpixels)[None, :] // subpixels
    sub_pixel = (rows * W + cols).reshape(-1)
    T = np.zeros((H * W, 4))
    np.add.at(T, sub_pixel, truth / s)
    deep_s, deep_p = deep_of(sets["sphere"], (H, W), subpixels), deep_of(sets["pane"], (H, W), subpixels)
    D = flatten(merge(deep_s, deep_p)).reshape(-1, 4).astype(np.float64)

    sphere, pane = sets["sphere"], sets["pane"]
    zs = np.full(n_sub, np.inf)
    zs[sphere.subpixel] = sphere.depth
    zp = np.full(n_sub, np.inf)
    zp[pane.subpixel] = pane.depth
    has_s, has_p = np.isfinite(zs), np.isfinite(zp)
    count = lambda m: np.bincount(sub_pixel, weights=m.astype(float), minlength=H * W) / s  # noqa: E731
    f_s, f_p = count(has_s), count(has_p)
    f_sp, f_ps = count(has_s & has_p & (zs < zp)), count(has_s & has_p & (zp < zs))
    near_s = np.full(H * W, np.inf)
    np.minimum.at(near_s, sub_pixel[has_s], zs[has_s])
    near_p = np.full(H * W, np.inf)
    np.minimum.at(near_p, sub_pixel[has_p], zp[has_p])
    c_s, c_p = sphere.rgba[0], pane.rgba[0]
    s_first = (near_s <= near_p)[:, None]
    a_s, a_p = c_s[3], c_p[3]
    predicted = np.where(
        s_first,
        a_s * c_p * (f_sp - f_s * f_p)[:, None] + a_p * c_s * f_ps[:, None],
        a_p * c_s * (f_ps - f_s * f_p)[:, None] + a_s * c_p * f_sp[:, None],
    )
    np.testing.assert_allclose(D - T, predicted, rtol=0, atol=1e-6)
    bound = np.where(
        s_first,
        a_s * np.abs(c_p) * np.abs(f_sp - f_s * f_p)[:, None] + a_p * np.abs(c_s) * f_ps[:, None],
        a_p * np.abs(c_s) * np.abs(f_ps - f_s * f_p)[:, None] + a_s * np.abs(c_p) * f_sp[:, None],
    )
    assert (np.abs(D - T) <= bound + 1e-6).all()
    uniform = bound.max(axis=-1) == 0
    assert uniform.mean() > 0.9
    np.testing.assert_allclose(D[uniform], T[uniform], rtol=0, atol=1e-6)
    assert np.abs(D - T).max() > 1e-3  # the bound is not empty: edge and crossing pixels differ


def test_demo_writes_deep_exrs_that_flatten_to_the_a_buffer(tmp_path, capsys):
    assert main(["--out", str(tmp_path), "--size", "64x48", "--figure", str(tmp_path / "fig.png")]) == 0
    assert "wrote" in capsys.readouterr().out
    merged = read_deep(tmp_path / "merged.deep.exr")
    sets = scene_fragments(48, 64)
    np.testing.assert_allclose(flatten(merged), a_buffer(sets, 48 * 64).reshape(48, 64, 4), atol=1e-6)
    assert (tmp_path / "fig.png").stat().st_size > 0
