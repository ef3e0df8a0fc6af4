"""The bulge of a wrinkle (seed 003, section 5): how long the skin across a wrinkle has become
with age (eq 10) and which symmetric cubic of that arc length spans the current chord (eqs 11-14).

All lengths in cm, angles in rad, ages in years. Every function is vectorised over wrinkle
cross-sections so a frame solves all of them at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.wrinkles.arclength import ASYM_RATIO, ArcTable, lookup, lookup_alpha_profile, table

FloatArray = np.ndarray

AGE_0 = 35.0  # years: dilatation starts (section 5, "35 years old approx.")
AGE_MAX = 90.0  # years: the age of maximum dilatation
DIL_MAX = 0.4  # relative arc-length surplus across a wrinkle at AGE_MAX
FULL_RELEASE_STRAIN = 0.08  # compression strain across a wrinkle that frees all the surplus
INPLANE_LOSS_AT_MAX = 0.4  # fraction of a compression aged skin no longer absorbs in its plane
A_CAP_RATIO = 0.95  # the tangent norm stays below the chord: rolls at most ~0.7 as tall as wide
_A_SAMPLES = 9  # samples bracketing S(a) when the tangent norm must grow


def dilatation(d_init: FloatArray, age: float | FloatArray) -> FloatArray:
    """Eq 10: d_real = d_init * max(1, 1 + (t - AGE_0) * DIL_MAX / (AGE_MAX - AGE_0)).

    Reading: the paper lets t run on past AGE_MAX; we hold the dilatation at DIL_MAX beyond it
    so an over-turned age dial cannot tear the mesh."""
    t = np.minimum(np.asarray(age, dtype=np.float64), AGE_MAX)
    return np.asarray(d_init) * np.maximum(1.0, 1.0 + (t - AGE_0) * DIL_MAX / (AGE_MAX - AGE_0))


def released_surplus(
    d_init: FloatArray, s_now: FloatArray, age: float | FloatArray, emphasis: FloatArray
) -> FloatArray:
    """The arc length the skin across a wrinkle must lose into a bulge, in cm.

    Reading of section 5 chosen for a live face: eq 10's surplus dil(d_init) - d_init is skin the
    surrounding tension keeps flat while the face rests; compression across the wrinkle (the
    dynamics moving P0 and P1 together) releases it, fully at FULL_RELEASE_STRAIN. Aged skin
    has also lost elasticity (`sim.wrinkles.aging`: k_l falls by the same fraction), so that
    fraction of the compression itself, which young skin absorbs in its plane, goes into the
    bulge too. Young skin's in-plane shortening is the springs' job: no bulge forms below AGE_0
    and none without compression. `emphasis` is the paper's per-wrinkle coefficient."""
    compression = np.clip(d_init - s_now, 0.0, None)
    release = np.minimum(compression / (d_init * FULL_RELEASE_STRAIN), 1.0)
    unabsorbed = INPLANE_LOSS_AT_MAX * (dilatation(1.0, age) - 1.0) / DIL_MAX
    return ((dilatation(d_init, age) - d_init) * release + unabsorbed * compression) * emphasis


@dataclass(frozen=True)
class Segment:
    """Solved cross-sections: tangent norm a (cm) and angle alpha (rad) from the chord, (Q,)."""

    a: FloatArray
    alpha: FloatArray


def _first_crossing(x: FloatArray, y: FloatArray, target: FloatArray) -> FloatArray:
    """Per row, the x where the piecewise-linear y(x) first reaches target (y made monotone by a
    running maximum; rows that never reach it return their last x)."""
    y = np.maximum.accumulate(y, axis=1)
    n = y.shape[1]
    j = np.minimum((y < target[:, None]).sum(axis=1), n - 1)
    jm = np.maximum(j - 1, 0)
    rows = np.arange(len(target))
    y0, y1 = y[rows, jm], y[rows, j]
    x0, x1 = x[rows, jm], x[rows, j]
    f = np.where(y1 > y0, (target - y0) / np.where(y1 > y0, y1 - y0, 1.0), 1.0)
    return x0 + np.clip(f, 0.0, 1.0) * (x1 - x0)


def _profile_at(profile: FloatArray, alpha: FloatArray, step: float) -> FloatArray:
    """Linear interpolation of per-row node values (Q, K) at one alpha per row."""
    t = np.clip(alpha / step, 0.0, profile.shape[1] - 1.0)
    k = np.minimum(np.floor(t).astype(np.intp), profile.shape[1] - 2)
    rows = np.arange(len(alpha))
    f = t - k
    return profile[rows, k] * (1.0 - f) + profile[rows, k + 1] * f


def solve_segment(
    d: FloatArray, d_real: FloatArray, alpha_min: FloatArray, tab: ArcTable | None = None
) -> Segment:
    """Section 5.1 / 5.2: the cubic across the chord d whose arc length is d_real.

    The tangent norm starts at a = d/3 (flat skin at alpha = 0). If S(d, a, alpha_max) with
    alpha_max = alpha_min + pi/2 reaches d_real, alpha in [alpha_min, alpha_max] is interpolated
    so that S = d_real; otherwise alpha = alpha_max and a grows until S(d, a, alpha_max) = d_real
    (capped at A_CAP_RATIO * d). S is eq 14's interpolation throughout: piecewise linear in alpha
    (inverted exactly), smooth and increasing in a (bracketed on a few samples, then two steps of
    false position)."""
    tab = table() if tab is None else tab
    d = np.asarray(d, dtype=np.float64)
    d_real = np.asarray(d_real, dtype=np.float64)
    alpha_min = np.clip(np.asarray(alpha_min, dtype=np.float64), 0.0, np.pi / 2)
    alpha_max = alpha_min + np.pi / 2
    a0 = d / 3.0
    # alpha search over the table's nodes inside [alpha_min, alpha_max] plus both ends
    profile = lookup_alpha_profile(tab, d, a0)
    step = float(tab.alpha_nodes[1] - tab.alpha_nodes[0])
    s_lo = _profile_at(profile, alpha_min, step)
    s_hi = _profile_at(profile, alpha_max, step)
    nodes = tab.alpha_nodes[None, :]
    below, above = nodes < alpha_min[:, None], nodes > alpha_max[:, None]
    alphas = np.clip(nodes, alpha_min[:, None], alpha_max[:, None])
    s_nodes = np.where(below, s_lo[:, None], np.where(above, s_hi[:, None], profile))
    alphas = np.concatenate([alpha_min[:, None], alphas, alpha_max[:, None]], axis=1)
    s_alpha = np.concatenate([s_lo[:, None], s_nodes, s_hi[:, None]], axis=1)
    alpha = _first_crossing(alphas, s_alpha, d_real)
    grow = np.maximum.reduce(s_alpha, axis=1) < d_real
    a = a0.copy()
    if np.any(grow):
        g = np.flatnonzero(grow)
        a[g] = _grow_tangent(tab, d[g], d_real[g], alpha_max[g])
        alpha[g] = alpha_max[g]
    return Segment(a=a, alpha=alpha)


def _grow_tangent(tab: ArcTable, d: FloatArray, d_real: FloatArray, alpha: FloatArray) -> FloatArray:
    """The tangent norm a in [d/3, A_CAP_RATIO d] with S(d, a, alpha) = d_real (or the cap)."""
    frac = np.linspace(0.0, 1.0, _A_SAMPLES)[None, :]
    lo_a, hi_a = d / 3.0, A_CAP_RATIO * d
    a_try = lo_a[:, None] + frac * (hi_a - lo_a)[:, None]
    s_a = lookup(tab, d[:, None], a_try, alpha[:, None])
    s_a = np.maximum.accumulate(s_a, axis=1)
    n = a_try.shape[1]
    j = np.clip((s_a < d_real[:, None]).sum(axis=1), 1, n - 1)
    rows = np.arange(len(d))
    a_l, a_h = a_try[rows, j - 1], a_try[rows, j]
    s_l, s_h = s_a[rows, j - 1], s_a[rows, j]
    capped = s_h < d_real
    for _ in range(2):  # false position inside the bracket
        f = np.clip((d_real - s_l) / np.maximum(s_h - s_l, 1e-15), 0.0, 1.0)
        a_m = a_l + f * (a_h - a_l)
        s_m = lookup(tab, d, a_m, alpha)
        up = s_m < d_real
        a_l, s_l = np.where(up, a_m, a_l), np.where(up, s_m, s_l)
        a_h, s_h = np.where(up, a_h, a_m), np.where(up, s_h, s_m)
    f = np.clip((d_real - s_l) / np.maximum(s_h - s_l, 1e-15), 0.0, 1.0)
    return np.where(capped, hi_a, a_l + f * (a_h - a_l))


def control_heights(
    seg: Segment, asymmetric: bool | FloatArray = False
) -> tuple[FloatArray, FloatArray]:
    """Heights above the chord of the inner control points P'0, P'1 (eqs 11-12), cm."""
    ratio = np.where(asymmetric, ASYM_RATIO, 1.0)
    return seg.a * np.sin(ratio * seg.alpha), seg.a * np.sin(seg.alpha)


def bezier_height(t: FloatArray, h0: FloatArray, h1: FloatArray) -> FloatArray:
    """Height of the cubic at parameter t given its control heights (end points on the chord)."""
    return 3.0 * (1.0 - t) ** 2 * t * h0 + 3.0 * (1.0 - t) * t**2 * h1


def segment_arc(d: FloatArray, seg: Segment, asymmetric: bool = False) -> FloatArray:
    """Arc length of a solved segment, interpolated from its table (for checks)."""
    tab = table(asymmetric)
    return lookup(tab, np.asarray(d, dtype=np.float64), seg.a, seg.alpha)
