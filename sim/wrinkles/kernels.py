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
from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start

# the paper's grid (fixed by section 5.1, so safe to freeze into the compiled code)
_D0 = float(D_NODES[0])
_D_MAX = float(D_NODES[-1])
_A_MAX = float(A_NODES[-1])


@njit(cache=True, fastmath=False, nogil=True)
def _cell(x: float, first: float, step: float, n: int) -> tuple[int, float]:
    t = min(max((x - first) / step, 0.0), n - 1.0)
    i = min(int(t), n - 2)
    return i, t - i


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def _solve_one(values: np.ndarray, d: float, target: float, alpha_min: float, a_cap: float,
               n_samples: int) -> tuple[float, float]:
    """bulge.solve_segment for one cross-section: (a, alpha)."""
    half_pi = 0.5 * math.pi
    n_alpha = values.shape[2]
    amin = min(max(alpha_min, 0.0), half_pi)
    amax = amin + half_pi
    a0 = d / 3.0
    prev_al = amin
    prev_s = _s(values, d, a0, amin)
    if prev_s >= target:
        return a0, amin
    for m in range(n_alpha + 1):
        al = m * ALPHA_STEP if m < n_alpha else amax
        if al <= amin:
            continue
        if al >= amax:
            al = amax
        s = max(_s(values, d, a0, al), prev_s)
        if s >= target:
            f = (target - prev_s) / (s - prev_s) if s > prev_s else 1.0
            return a0, prev_al + min(max(f, 0.0), 1.0) * (al - prev_al)
        prev_al, prev_s = al, s
        if al >= amax:
            break
    return _grow(values, d, target, amax, a_cap, n_samples), amax


@njit(cache=True, nogil=True)
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
    for q in range(d.shape[0]):
        out_a[q], out_alpha[q] = _solve_one(tables[which[q]], d[q], d_real[q], alpha_min[q], a_cap,
                                            n_samples)


@njit(cache=True, nogil=True)
def frame_displacement(
    pos: np.ndarray,
    anchor_tri: np.ndarray,
    anchor_bary: np.ndarray,
    rolls: tuple,
    entries: tuple,
    stations: tuple,
    furrows: tuple,
    tables: np.ndarray,
    params: np.ndarray,
    n_samples: int,
    out: np.ndarray,
    scratch: tuple,
) -> None:
    """layer.wrinkle_displacement in one pass (the numpy version is the reference).

    rolls = (far, line, asym, emphasis, d_init, prev, next); entries = (vertex, roll0, roll1, lam,
    b1, b2, taper); stations = (rolls (S, 2), furrow ratio); furrows = (vertex, station0, station1,
    lam, weight); params = (dil - 1, unabsorbed fraction, full-release strain, a_cap, asym ratio,
    furrow max depth, smoothing passes); scratch = work arrays (anchor points and normals (A, 3) x2,
    roll up and line normals (R, 3) x2, four (R,), station depths (S,) and normals (S, 3)), kept
    by the caller so that a frame allocates nothing here."""
    far, line, asym, emph, d_init, prev, nxt = rolls
    extra, unabsorbed, release_strain, a_cap, ratio, furrow_max = (
        params[0], params[1], params[2], params[3], params[4], params[5])
    passes = int(params[6])
    n_a = anchor_tri.shape[0]
    pts, nrm, up, n_line, dh0, dh1, s0, s1, depth, st_n = scratch
    for i in range(n_a):
        t0, t1, t2 = anchor_tri[i, 0], anchor_tri[i, 1], anchor_tri[i, 2]
        for c in range(3):
            pts[i, c] = (anchor_bary[i, 0] * pos[t0, c] + anchor_bary[i, 1] * pos[t1, c]
                         + anchor_bary[i, 2] * pos[t2, c])
        ux, uy, uz = pos[t1, 0] - pos[t0, 0], pos[t1, 1] - pos[t0, 1], pos[t1, 2] - pos[t0, 2]
        vx, vy, vz = pos[t2, 0] - pos[t0, 0], pos[t2, 1] - pos[t0, 1], pos[t2, 2] - pos[t0, 2]
        nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        ln = max(math.sqrt(nx * nx + ny * ny + nz * nz), 1e-12)
        nrm[i, 0], nrm[i, 1], nrm[i, 2] = nx / ln, ny / ln, nz / ln
    n_r = far.shape[0]
    dh0[:] = 0.0  # rolls without surplus keep 0
    dh1[:] = 0.0
    for r in range(n_r):
        p0, p1 = far[r], line[r]
        # scalars throughout: no small arrays allocated per roll
        cx = pts[p1, 0] - pts[p0, 0]
        cy = pts[p1, 1] - pts[p0, 1]
        cz = pts[p1, 2] - pts[p0, 2]
        d = max(math.sqrt(cx ** 2 + cy ** 2 + cz ** 2), 1e-9)
        ex, ey, ez = cx / d, cy / d, cz / d
        bx, by, bz = nrm[p0, 0] + nrm[p1, 0], nrm[p0, 1] + nrm[p1, 1], nrm[p0, 2] + nrm[p1, 2]
        nbe = bx * ex + by * ey + bz * ez
        ux, uy, uz = bx - nbe * ex, by - nbe * ey, bz - nbe * ez
        lu = max(math.sqrt(ux ** 2 + uy ** 2 + uz ** 2), 1e-12)
        ux, uy, uz = ux / lu, uy / lu, uz / lu
        up[r, 0], up[r, 1], up[r, 2] = ux, uy, uz
        n_line[r, 0], n_line[r, 1], n_line[r, 2] = nrm[p1, 0], nrm[p1, 1], nrm[p1, 2]
        n0e = nrm[p0, 0] * ex + nrm[p0, 1] * ey + nrm[p0, 2] * ez
        n0u = nrm[p0, 0] * ux + nrm[p0, 1] * uy + nrm[p0, 2] * uz
        n1e = nrm[p1, 0] * ex + nrm[p1, 1] * ey + nrm[p1, 2] * ez
        n1u = nrm[p1, 0] * ux + nrm[p1, 1] * uy + nrm[p1, 2] * uz
        amin = min(max(0.5 * (math.atan2(-n0e, n0u) + math.atan2(n1e, n1u)), 0.0), 0.5 * math.pi)
        s_nat = _s(tables[0], d, d / 3.0, amin)
        comp = max(d_init[r] - s_nat, 0.0)
        release = min(comp / (d_init[r] * release_strain), 1.0)
        surplus = (extra * d_init[r] * release + unabsorbed * comp) * emph[r]
        if surplus <= 1e-7:
            continue
        k = 1 if asym[r] else 0
        a, alpha = _solve_one(tables[k], d, s_nat + surplus, amin, a_cap, n_samples)
        nat = d / 3.0 * math.sin(amin)
        dh0[r] = a * math.sin((ratio if asym[r] else 1.0) * alpha) - nat
        dh1[r] = a * math.sin(alpha) - nat
    for _ in range(passes):
        for r in range(n_r):
            s0[r] = 0.25 * dh0[prev[r]] + 0.5 * dh0[r] + 0.25 * dh0[nxt[r]]
            s1[r] = 0.25 * dh1[prev[r]] + 0.5 * dh1[r] + 0.25 * dh1[nxt[r]]
        dh0, dh1, s0, s1 = s0, s1, dh0, dh1  # the smoothed values become the input of the next pass
    ev, er0, er1, elam, eb1, eb2, etaper = entries
    for q in range(ev.shape[0]):
        lam = elam[q]
        r0, r1 = er0[q], er1[q]
        h0 = (1.0 - lam) * dh0[r0] + lam * dh0[r1]
        h1 = (1.0 - lam) * dh1[r0] + lam * dh1[r1]
        h = max(eb1[q] * h0 + eb2[q] * h1, 0.0) * etaper[q]
        for c in range(3):
            out[ev[q], c] += h * ((1.0 - lam) * up[r0, c] + lam * up[r1, c])
    st_rolls, st_furrow = stations
    n_s = st_rolls.shape[0]
    st_n[:, :] = 0.0  # stations without a roll keep no normal
    for i in range(n_s):
        crest = 0.0
        for side in range(2):
            r = st_rolls[i, side]
            if r >= 0:
                crest = max(crest, 0.375 * (dh0[r] + dh1[r]))
        depth[i] = min(crest * st_furrow[i], furrow_max)
        r = st_rolls[i, 1] if st_rolls[i, 1] >= 0 else st_rolls[i, 0]
        if r >= 0:
            st_n[i, 0], st_n[i, 1], st_n[i, 2] = n_line[r, 0], n_line[r, 1], n_line[r, 2]
    fv, fs0, fs1, flam, fw = furrows
    for q in range(fv.shape[0]):
        lam = flam[q]
        dq = ((1.0 - lam) * depth[fs0[q]] + lam * depth[fs1[q]]) * fw[q]
        for c in range(3):
            out[fv[q], c] -= dq * ((1.0 - lam) * st_n[fs0[q], c] + lam * st_n[fs1[q], c])


def warm_up() -> None:
    """Compile (or load from numba's cache) `frame_displacement` for the very signature a show
    calls it with (sim.wrinkles.layer.compiled_displacement: writable C arrays, int64 indices), on
    an empty layer: no model and no layer build needed, so a show can have it before its first
    tick even when the layer itself is built later. A test checks a real layer then adds no
    signature."""
    def ints(*shape: int) -> np.ndarray:
        return np.zeros(shape or (0,), dtype=np.int64)

    def floats(*shape: int) -> np.ndarray:
        return np.zeros(shape or (0,))

    rolls = (ints(), ints(), np.zeros(0, dtype=np.bool_), floats(), floats(), ints(), ints())
    entries = (ints(), ints(), ints(), floats(), floats(), floats(), floats())
    furrows = (ints(), ints(), ints(), floats(), floats())
    scratch = (floats(0, 3), floats(0, 3), floats(0, 3), floats(0, 3), floats(), floats(), floats(), floats(),
               floats(), floats(0, 3))
    frame_displacement(floats(1, 3), ints(0, 3), floats(0, 3), rolls, entries, (ints(0, 2), floats()), furrows,
                       floats(2, 2, 2, 2), floats(7), 8, floats(1, 3), scratch)
