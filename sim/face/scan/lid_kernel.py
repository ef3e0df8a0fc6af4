"""The scan's lids laid back onto the eyeballs (sim.face.scan.lid_contact) as one compiled pass per
eye: 0.03 ms a pose against 0.7-0.9 ms for the same steps in numpy (`LidContact.press_steps`, the
reference it is checked against, to the bit), once per drawn frame and per exported one."""

from __future__ import annotations

import numba
import numpy as np

from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


@numba.njit(cache=True, nogil=True, inline="always")
def _front(qx: float, qy: float, qz: float, ax: float, ay: float, az: float, profile: np.ndarray,
           bin_deg: float) -> tuple[float, float]:
    """(the point q's distance from the eyeball's centre, the eyeball's drawn front's radius in its
    direction: `profile` read by the angle from the axis a, linearly)."""
    r = np.sqrt(qx * qx + qy * qy + qz * qz)
    cos = min(max((qx * ax + qy * ay + qz * az) / max(r, 1e-9), -1.0), 1.0)
    f = np.degrees(np.arccos(cos)) / bin_deg
    k = min(int(f), profile.shape[0] - 2)
    w = min(f - k, 1.0)
    return r, profile[k] + w * (profile[k + 1] - profile[k])


@numba.njit(cache=True, nogil=True)
def lid_pushes(pos: np.ndarray, band: np.ndarray, allowed: np.ndarray, weight: np.ndarray, near: np.ndarray,
               n_chain: int, centre: np.ndarray, apex: int, profile: np.ndarray, bin_deg: float,
               out: np.ndarray) -> None:
    """sim.face.scan.lid_contact for one eye: out[i] (3,) cm, how far the lid vertex band[i] must move
    out along the eyeball's normal (from its `centre`) to lie no deeper in the eyeball's drawn front
    (`profile`, its radius by the angle from the gaze axis through the vertex `apex`, in bins of
    `bin_deg` degrees) than allowed[i]; past the margins (the first `n_chain` of the band) at least
    weight[i] times its nearest margin vertex's (near[i]), the longer of the two."""
    cx, cy, cz = centre[0], centre[1], centre[2]
    ax, ay, az = np.float64(pos[apex, 0]) - cx, np.float64(pos[apex, 1]) - cy, np.float64(pos[apex, 2]) - cz
    n = np.sqrt(ax * ax + ay * ay + az * az)
    ax, ay, az = ax / n, ay / n, az / n
    for i in range(band.shape[0]):
        v = band[i]
        qx, qy, qz = np.float64(pos[v, 0]) - cx, np.float64(pos[v, 1]) - cy, np.float64(pos[v, 2]) - cz
        r, front = _front(qx, qy, qz, ax, ay, az, profile, bin_deg)
        s = front + allowed[i] - r
        if s > 1e-4:  # sunk (past a micrometre of rounding): out along the normal, onto the front
            out[i, 0], out[i, 1], out[i, 2] = s * qx / r, s * qy / r, s * qz / r
        else:
            out[i, 0], out[i, 1], out[i, 2] = 0.0, 0.0, 0.0
    for i in range(n_chain, band.shape[0]):
        j = near[i]
        w = weight[i]
        if w * w * (out[j, 0] ** 2 + out[j, 1] ** 2 + out[j, 2] ** 2) > out[i, 0] ** 2 + out[i, 1] ** 2 + out[i, 2] ** 2:
            out[i, 0], out[i, 1], out[i, 2] = w * out[j, 0], w * out[j, 1], w * out[j, 2]


@numba.njit(cache=True, nogil=True)
def lid_press(pos: np.ndarray, band: np.ndarray, allowed: np.ndarray, weight: np.ndarray, near: np.ndarray,
              n_chain: int, centre: np.ndarray, apex: int, profile: np.ndarray, bin_deg: float,
              things: np.ndarray, ends: np.ndarray, t: np.ndarray, backs: np.ndarray, back_at: np.ndarray,
              push: np.ndarray) -> None:
    """sim.face.scan.lid_contact.LidContact.press for one eye, in place on `pos` (N, 3): the band's
    pushes (`lid_pushes`, into push[:len(band)]), the lid things by their margin segment's ends'
    (ends (T, 2) places in the chain, t (T,) along it) and the lids' backs by their margin
    vertex's (back_at)."""
    lid_pushes(pos, band, allowed, weight, near, n_chain, centre, apex, profile, bin_deg, push)
    moved = False
    for i in range(band.shape[0]):
        if push[i, 0] != 0.0 or push[i, 1] != 0.0 or push[i, 2] != 0.0:
            moved = True
            break
    if not moved:
        return
    for i in range(band.shape[0]):
        v = band[i]
        for c in range(3):
            pos[v, c] += push[i, c]
    for k in range(things.shape[0]):
        v = things[k]
        for c in range(3):
            pos[v, c] += (1.0 - t[k]) * push[ends[k, 0], c] + t[k] * push[ends[k, 1], c]
    for k in range(backs.shape[0]):
        v = backs[k]
        for c in range(3):
            pos[v, c] += push[back_at[k], c]
