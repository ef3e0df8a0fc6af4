"""The bulge mathematics of seed 003 section 5, checked against independent numerics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from sim.wrinkles import arclength as arc
from sim.wrinkles import bulge


def _quad_arc(d: float, a: float, alpha0: float, alpha1: float) -> float:
    """Eq 13 by adaptive quadrature of the Bezier speed written out independently."""
    p = np.array([[0.0, 0.0], [a * np.cos(alpha0), a * np.sin(alpha0)],
                  [d - a * np.cos(alpha1), a * np.sin(alpha1)], [d, 0.0]])

    def speed(u: float) -> float:
        v = 3 * (1 - u) ** 2 * (p[1] - p[0]) + 6 * (1 - u) * u * (p[2] - p[1]) + 3 * u**2 * (p[3] - p[2])
        return float(np.hypot(*v))

    return quad(speed, 0.0, 1.0, limit=200, points=[0.5])[0]


@pytest.mark.parametrize("asymmetric", [False, True])
def test_table_on_its_upper_half_matches_direct_arc_length(asymmetric: bool) -> None:
    rng = np.random.default_rng(1)
    tab = arc.table(asymmetric)
    for _ in range(300):
        d, a, al = rng.uniform(10.1, 20.1), rng.uniform(0, 10), rng.uniform(0, np.pi)
        a0 = arc.ASYM_RATIO * al if asymmetric else al
        exact = _quad_arc(d, a, a0, al)
        assert abs(arc.trilinear(tab, d, a, al) / exact - 1) < 0.01, (d, a, al)


@pytest.mark.parametrize("asymmetric", [False, True])
def test_lookup_in_cm_matches_direct_arc_length(asymmetric: bool) -> None:
    """Any chord in cm with a <= A_CAP_RATIO d (the solver's domain) is read within 1 %."""
    rng = np.random.default_rng(2)
    tab = arc.table(asymmetric)
    for _ in range(400):
        d = rng.uniform(0.02, 3.0)
        a, al = rng.uniform(0, bulge.A_CAP_RATIO * d), rng.uniform(0, np.pi)
        a0 = arc.ASYM_RATIO * al if asymmetric else al
        exact = _quad_arc(d, a, a0, al)
        assert abs(arc.lookup(tab, d, a, al) / exact - 1) < 0.01, (d, a, al)


def test_flat_segment_is_the_chord() -> None:
    assert arc.arc_length(0.7, 0.7 / 3, 0.0) == pytest.approx(0.7, rel=1e-9)


@pytest.mark.parametrize("asymmetric", [False, True])
def test_solved_segment_has_the_target_arc_length(asymmetric: bool) -> None:
    rng = np.random.default_rng(3)
    n = 400
    d = rng.uniform(0.1, 1.5, n)
    alpha_min = rng.uniform(0, 0.6, n)
    tab = arc.table(asymmetric)
    lo = arc.arc_length(d, d / 3, alpha_min)
    hi = arc.lookup(tab, d, bulge.A_CAP_RATIO * d, alpha_min + np.pi / 2)
    d_real = lo + rng.uniform(0.0, 1.0, n) * (hi - lo)
    seg = bulge.solve_segment(d, d_real, alpha_min, tab)
    a0 = arc.ASYM_RATIO * seg.alpha if asymmetric else seg.alpha
    got = arc.arc_length(d, seg.a, a0, seg.alpha)
    ok = d_real >= arc.lookup(tab, d, d / 3, alpha_min)  # reachable from alpha_min
    assert ok.mean() > 0.9
    np.testing.assert_array_less(np.abs(got[ok] / d_real[ok] - 1), 0.01)
    assert np.all(seg.alpha <= alpha_min + np.pi / 2 + 1e-12)
    assert np.all(seg.alpha >= alpha_min - 1e-12)


def test_tangent_norm_grows_only_once_alpha_is_at_its_maximum() -> None:
    d = np.full(50, 0.5)
    alpha_min = np.zeros(50)
    d_real = np.linspace(0.5, 0.9, 50)
    seg = bulge.solve_segment(d, d_real, alpha_min)
    grown = seg.a > 0.5 / 3 + 1e-9
    assert grown.any() and (~grown).any()
    np.testing.assert_allclose(seg.alpha[grown], np.pi / 2)
    assert np.all(np.diff(seg.a) >= -1e-12)
    h0, h1 = bulge.control_heights(seg)
    assert np.all(np.diff(bulge.bezier_height(0.5, h0, h1)) >= -1e-12)


def test_no_dilatation_before_age_0_then_linear() -> None:
    ages = np.array([0, 20, 30, bulge.AGE_0])
    np.testing.assert_array_equal(bulge.dilatation(1.0, ages), 1.0)
    later = np.linspace(bulge.AGE_0 + 1, bulge.AGE_MAX, 12)
    dil = bulge.dilatation(2.0, later)
    assert np.all(np.diff(dil) > 0)
    np.testing.assert_allclose(np.diff(dil, 2), 0.0, atol=1e-12)
    assert bulge.dilatation(1.0, bulge.AGE_MAX) == pytest.approx(1 + bulge.DIL_MAX)


def test_surplus_needs_both_age_and_compression() -> None:
    d_init = np.full(4, 0.5)
    compressed = np.full(4, 0.45)
    assert np.all(bulge.released_surplus(d_init, d_init, 80.0, 1.0) == 0)
    assert np.all(bulge.released_surplus(d_init, d_init * 1.1, 80.0, 1.0) == 0)
    assert np.all(bulge.released_surplus(d_init, compressed, 30.0, 1.0) == 0)
    s = [bulge.released_surplus(d_init, compressed, age, 1.0)[0] for age in (40, 55, 70, 85)]
    assert np.all(np.diff(s) > 0)


def test_compiled_kernel_matches_the_numpy_reference() -> None:
    from sim.wrinkles.kernels import solve_rolls

    rng = np.random.default_rng(4)
    n = 500
    d = rng.uniform(0.05, 1.5, n)
    alpha_min = rng.uniform(-0.2, 1.0, n)
    d_real = d * rng.uniform(0.95, 2.2, n)
    which = rng.integers(0, 2, n)
    tables = np.stack([arc.table(False).values, arc.table(True).values])
    a = np.empty(n)
    alpha = np.empty(n)
    solve_rolls(tables, which.astype(np.int64), d, d_real, alpha_min, a, alpha,
                bulge.A_CAP_RATIO, bulge._A_SAMPLES)
    for w in (0, 1):
        m = which == w
        ref = bulge.solve_segment(d[m], d_real[m], alpha_min[m], arc.table(bool(w)))
        np.testing.assert_allclose(a[m], ref.a, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(alpha[m], ref.alpha, rtol=1e-9, atol=1e-12)
