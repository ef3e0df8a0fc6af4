"""The compiled per-frame pass of render.scan_seam, in its own module so that importing the
renderer does not import numba (a render process of an export is handed the rows). The lids'
contact with the eyeballs, which exports use too, is sim.face.scan.lid_kernel's."""

from __future__ import annotations

import numba
import numpy as np
from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


@numba.njit(cache=True, nogil=True, inline="always")
def _smoothstep(x: float) -> float:
    t = min(max(x, 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


@numba.njit(cache=True, nogil=True)
def seam_shadow(pos: np.ndarray, upper: np.ndarray, lower: np.ndarray, rest_gap: np.ndarray, gap: np.ndarray,
                closed: np.ndarray, out: np.ndarray) -> None:
    """out[k], 0..1, for each margin vertex of one eye (upper then lower; `pos` (N, >=3), its first
    three columns the positions): how closed the seam is there, from its distance to the other
    lid's margin (a polyline) against `gap` (cm: all of the shadow at gap[0], none beyond gap[1])
    and the share of its rest distance `rest_gap` closed (taken as at least gap[2]; none below
    closed[0], all above closed[1])."""
    nu = upper.shape[0]
    for k in range(nu + lower.shape[0]):
        v = upper[k] if k < nu else lower[k - nu]
        line = lower if k < nu else upper
        px, py, pz = np.float64(pos[v, 0]), np.float64(pos[v, 1]), np.float64(pos[v, 2])
        best = 1e30
        for j in range(line.shape[0] - 1):
            a, b = line[j], line[j + 1]
            ax, ay, az = np.float64(pos[a, 0]), np.float64(pos[a, 1]), np.float64(pos[a, 2])
            bx, by, bz = np.float64(pos[b, 0]) - ax, np.float64(pos[b, 1]) - ay, np.float64(pos[b, 2]) - az
            t = ((px - ax) * bx + (py - ay) * by + (pz - az) * bz) / max(bx * bx + by * by + bz * bz, 1e-12)
            t = min(max(t, 0.0), 1.0)
            dx, dy, dz = px - ax - t * bx, py - ay - t * by, pz - az - t * bz
            best = min(best, dx * dx + dy * dy + dz * dz)
        g = np.sqrt(best)
        shut = (rest_gap[k] - g) / max(rest_gap[k], gap[2])
        out[k] = (_smoothstep((gap[1] - g) / (gap[1] - gap[0]))
                  * _smoothstep((shut - closed[0]) / (closed[1] - closed[0])))


@numba.njit(cache=True, nogil=True)
def seam_shade(rows: np.ndarray, upper: np.ndarray, lower: np.ndarray, rest_gap: np.ndarray, band: np.ndarray,
               weight: np.ndarray, at: np.ndarray, middle: np.ndarray, ball_lo: int, ball_hi: int,
               fold: float, gap: np.ndarray, closed: np.ndarray, shut: np.ndarray, scratch: np.ndarray) -> None:
    """One eye of render.scan_seam.LidSeam.shade on the rows x y z nx ny nz fold: the skin `band`
    gets fold * weight * its margin vertex's shadow added to its fold term, and the eyeball's rows
    (ball_lo:ball_hi) their fold term set to how shut the eye is (the mean shadow over the `middle`
    margin vertices against `shut`)."""
    seam_shadow(rows, upper, lower, rest_gap, gap, closed, scratch)
    for i in range(band.shape[0]):
        s = scratch[at[i]]
        if s > 0.0:
            rows[band[i], 6] += np.float32(fold * weight[i] * s)
    total, count = 0.0, 0
    for k in range(middle.shape[0]):
        total += scratch[middle[k]]
        count += 1
    m = _smoothstep((total / max(count, 1) - shut[0]) / (shut[1] - shut[0]))
    for v in range(ball_lo, ball_hi):
        rows[v, 6] = np.float32(m)
