"""The compiled per-frame kernel of the scanned head's drawing (render.scan_look.ScanRows): positions,
vertex normals and a fold-shadow term in one pass, in its own module so that importing the renderer
does not import numba (a render process of an export is handed the rows and never needs it)."""

from __future__ import annotations

import numba
import numpy as np
from render.normals_kernel import interleave_normals
from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


@numba.njit(cache=True, nogil=True)
def scan_rows(pos: np.ndarray, tri: np.ndarray, nbr_ptr: np.ndarray, nbr: np.ndarray,
              inv_len: np.ndarray, scratch: np.ndarray, out: np.ndarray) -> None:
    """out[:, 0:3] = pos; out[:, 3:6] = unit area-weighted vertex normals; out[:, 6] = how far the
    vertex lies below the mean of its mesh neighbours, along its normal, per neighbour distance
    (`inv_len`: 1 / the rest's mean edge length there), averaged once more over the neighbours:
    positive in a crease (a fold, the nasolabial groove, the frown lines), negative on a ridge.
    It is recomputed from the posed surface every frame, so a fold that deepens darkens."""
    interleave_normals(pos, tri, out)  # columns 0-5: the positions and unit vertex normals
    n = pos.shape[0]
    for i in range(n):
        lo, hi = nbr_ptr[i], nbr_ptr[i + 1]
        if hi == lo:
            scratch[i] = 0.0
            continue
        sx = np.float32(0.0)
        sy = np.float32(0.0)
        sz = np.float32(0.0)
        for k in range(lo, hi):
            j = nbr[k]
            sx += pos[j, 0]
            sy += pos[j, 1]
            sz += pos[j, 2]
        m = np.float32(1.0) / np.float32(hi - lo)
        dx, dy, dz = sx * m - pos[i, 0], sy * m - pos[i, 1], sz * m - pos[i, 2]
        scratch[i] = (dx * out[i, 3] + dy * out[i, 4] + dz * out[i, 5]) * inv_len[i]
    for i in range(n):
        lo, hi = nbr_ptr[i], nbr_ptr[i + 1]
        s = scratch[i]
        for k in range(lo, hi):
            s += scratch[nbr[k]]
        out[i, 6] = s / np.float32(1 + hi - lo)
