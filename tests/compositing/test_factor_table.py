"""The factor table against the closed forms of Porter & Duff (1984), table 1.

The expected (Fa, Fb) are written out here from the paper, independently of the
expression trees in ``compositing.factors``.
"""

import numpy as np
import pytest

from compositing.factors import ALL_OPERATORS, OPERATORS, PORTER_DUFF, evaluate
from tests.porter_duff_paper import PAPER, TWELVE

ALPHAS = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
SA, DA = (a.ravel() for a in np.meshgrid(ALPHAS, ALPHAS))


def test_twelve_operators_in_paper_order():
    assert OPERATORS == TWELVE


@pytest.mark.parametrize("name", OPERATORS)
def test_factors_match_the_paper(name):
    spec = PORTER_DUFF[name]
    fa = np.broadcast_to(evaluate(spec.fa_expr, SA, DA), SA.shape)
    fb = np.broadcast_to(evaluate(spec.fb_expr, SA, DA), SA.shape)
    want_fa, want_fb = (f(SA, DA) for f in PAPER[name])
    np.testing.assert_array_equal(fa, want_fa)
    np.testing.assert_array_equal(fb, want_fb)


def test_disjoint_and_conjoint_over_follow_blender_5():
    # Blender 5.0 node_composite_alpha_over.cc, written out per branch.
    disjoint = ALL_OPERATORS["disjoint_over"]
    conjoint = ALL_OPERATORS["conjoint_over"]
    fb_d = evaluate(disjoint.fb_expr, SA, DA)
    fb_c = evaluate(conjoint.fb_expr, SA, DA)
    for s, d, got_d, got_c in zip(SA, DA, fb_d, fb_c, strict=True):
        want_d = 1.0 if s + d < 1 else ((1 - s) / d if d != 0 else 0.0)
        want_c = 0.0 if s > d else 1 - (s / d if d != 0 else 0.0)
        assert got_d == pytest.approx(want_d, abs=1e-15)
        assert got_c == pytest.approx(want_c, abs=1e-15)
