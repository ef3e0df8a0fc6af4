"""The compiled per-frame pass of render.scan_soften, in its own module so that importing the
renderer does not import numba (a render process of an export is handed the rows)."""

from __future__ import annotations

import numba
import numpy as np
from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


@numba.njit(cache=True, nogil=True)
def soften_zone(posed: np.ndarray, rest: np.ndarray, support: np.ndarray, zone: np.ndarray, ptr: np.ndarray,
                cols: np.ndarray, gauss: np.ndarray, weight: np.ndarray, normal: np.ndarray, limit: np.ndarray,
                shadow: float, shadow_depth: float, disp: np.ndarray, out: np.ndarray, crease: np.ndarray) -> None:
    """For each zone vertex i = zone[z]: r = (posed - rest)[i] minus the Gaussian mean of
    (posed - rest) over cols[ptr[z]:ptr[z + 1]] (weights gauss, summing to 1); out[i] = posed[i]
    - weight[z] (1 - limit[z] tanh(|r| / limit[z]) / |r|) r. Reads `posed` only, writes `out` only;
    `disp` (N, 4) is scratch, written at the rows `support` lists (every index of cols and zone).
    crease[z] = shadow tanh(d / shadow_depth), d the Gaussian mean over the same neighbours of
    weight max(0, -r . normal): how deep the skin around the vertex was pushed in below its
    surroundings' motion (the folds of a buckle, spread over it), 0 where it moved smoothly."""
    for k in range(support.shape[0]):
        j = support[k]
        disp[j, 0] = posed[j, 0] - rest[j, 0]
        disp[j, 1] = posed[j, 1] - rest[j, 1]
        disp[j, 2] = posed[j, 2] - rest[j, 2]
        disp[j, 3] = np.float32(0.0)
    for z in range(zone.shape[0]):
        i = zone[z]
        sx = sy = sz = np.float32(0.0)
        for k in range(ptr[z], ptr[z + 1]):
            j = cols[k]
            g = gauss[k]
            sx += g * disp[j, 0]
            sy += g * disp[j, 1]
            sz += g * disp[j, 2]
        rx = disp[i, 0] - sx
        ry = disp[i, 1] - sy
        rz = disp[i, 2] - sz
        depth = -(rx * normal[z, 0] + ry * normal[z, 1] + rz * normal[z, 2])
        disp[i, 3] = weight[z] * depth if depth > 0.0 else np.float32(0.0)
        length = np.sqrt(rx * rx + ry * ry + rz * rz)
        if length < 1e-9:
            continue
        c = weight[z] * (np.float32(1.0) - limit[z] * np.tanh(length / limit[z]) / length)
        out[i, 0] = posed[i, 0] - c * rx
        out[i, 1] = posed[i, 1] - c * ry
        out[i, 2] = posed[i, 2] - c * rz
    for z in range(zone.shape[0]):  # the depth spread as the Gaussian spreads it
        s = np.float32(0.0)
        for k in range(ptr[z], ptr[z + 1]):
            s += gauss[k] * disp[cols[k], 3]
        crease[z] = shadow * np.tanh(s / shadow_depth)
