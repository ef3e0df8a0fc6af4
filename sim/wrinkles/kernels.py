"""Compiled per-frame solve of every wrinkle cross-section (numba), the same algorithm as
`bulge.solve_segment` (the numpy reference, kept for reading and for the tests that compare them).

A frame solves a few hundred cross-sections; in numpy each step is a small array operation whose
call overhead dominates (about 2 ms a frame), here it is a scalar loop (tens of microseconds).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from sim.wrinkles.arclength import A_NODES, ALPHA_STEP, D_NODES

# the paper's grid (fixed by section 5.1, so safe to freeze into the compiled code)
_D0 = float(D_NODES[0])
_D_MAX = float(D_NODES[-1])
_A_MAX = float(A_NODES[-1])


@njit(cache=True, fastmath=False)
def _cell(x: float, first: float, step: float, n: int) -> tuple[int, float]:
    t = min(max((x - first) / step, 0.0), n - 1.0)
    i = min(int(t), n - 2)
    return i, t - i


@njit(cache=True)
def _s(values: np.ndarray, d: float, a: float, alpha: float) -> float:
    """Eq 14 read at the scaled coordinates of a query in cm (arclength.lookup)."""
    k = min(_D_MAX / max(d, 1e-12), _A_MAX / max(a, 1e-12))
    i, fd = _cell(k * d, _D0, 1.0, values.shape[0])
    j, fa = _cell(k * a, 0.0, 1.0, values.shape[1])
    m, fl = _cell(alpha, 0.0, ALPHA_STEP, values.shape[2])
    out = 0.0
    for di in range(2):
        wd = fd if di else 1.0 - fd
        for aj in range(2):
            wa = fa if aj else 1.0 - fa
            v0 = values[i + di, j + aj, m]
            v1 = values[i + di, j + aj, m + 1]
            out += wd * wa * ((1.0 - fl) * v0 + fl * v1)
    return out / k


@njit(cache=True)
def _grow(values: np.ndarray, d: float, target: float, alpha: float, a_cap: float, n: int) -> float:
    lo_a, hi_a = d / 3.0, a_cap * d
    a_l, s_l = lo_a, _s(values, d, lo_a, alpha)
    a_h, s_h = hi_a, s_l
    found = False
    for q in range(1, n):
        a_q = lo_a + (hi_a - lo_a) * q / (n - 1.0)
        s_q = max(_s(values, d, a_q, alpha), s_l)
        if s_q >= target:
            a_h, s_h = a_q, s_q
            found = True
            break
        a_l, s_l = a_q, s_q
    if not found:
        return hi_a
    for _ in range(2):
        f = min(max((target - s_l) / max(s_h - s_l, 1e-15), 0.0), 1.0)
        a_m = a_l + f * (a_h - a_l)
        s_m = _s(values, d, a_m, alpha)
        if s_m < target:
            a_l, s_l = a_m, s_m
        else:
            a_h, s_h = a_m, s_m
    f = min(max((target - s_l) / max(s_h - s_l, 1e-15), 0.0), 1.0)
    return a_l + f * (a_h - a_l)


@njit(cache=True)
def solve_rolls(
    tables: np.ndarray,
    which: np.ndarray,
    d: np.ndarray,
    d_real: np.ndarray,
    alpha_min: np.ndarray,
    out_a: np.ndarray,
    out_alpha: np.ndarray,
    a_cap: float,
    n_samples: int,
) -> None:
    """bulge.solve_segment for each cross-section q, with table tables[which[q]]; a_cap and
    n_samples are bulge.A_CAP_RATIO and bulge._A_SAMPLES (arguments, so a cached compiled kernel
    never keeps stale values)."""
    half_pi = 0.5 * math.pi
    for q in range(d.shape[0]):
        values = tables[which[q]]
        n_alpha = values.shape[2]
        amin = min(max(alpha_min[q], 0.0), half_pi)
        amax = amin + half_pi
        a0 = d[q] / 3.0
        target = d_real[q]
        prev_al = amin
        prev_s = _s(values, d[q], a0, amin)
        out_a[q] = a0
        if prev_s >= target:
            out_alpha[q] = amin
            continue
        done = False
        for m in range(n_alpha + 1):
            al = m * ALPHA_STEP if m < n_alpha else amax
            if al <= amin:
                continue
            if al >= amax:
                al = amax
            s = max(_s(values, d[q], a0, al), prev_s)
            if s >= target:
                f = (target - prev_s) / (s - prev_s) if s > prev_s else 1.0
                out_alpha[q] = prev_al + min(max(f, 0.0), 1.0) * (al - prev_al)
                done = True
                break
            prev_al, prev_s = al, s
            if al >= amax:
                break
        if not done:
            out_alpha[q] = amax
            out_a[q] = _grow(values, d[q], target, amax, a_cap, n_samples)
