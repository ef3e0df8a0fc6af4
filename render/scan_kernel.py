"""The compiled per-frame kernel of the scanned head's drawing (render.scan_look.ScanRows): positions,
vertex normals and a fold-shadow term in one pass, in its own module so that importing the renderer
does not import numba (a render process of an export is handed the rows and never needs it)."""

from __future__ import annotations

import numba
import numpy as np
from sim.numba_start import prepare_blas_check

from render.normals_kernel import add_face_normal

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


@numba.njit(cache=True, nogil=True)
def _fold(pos: np.ndarray, nbr_ptr: np.ndarray, nbr: np.ndarray, inv_len: np.ndarray, scratch: np.ndarray,
          out: np.ndarray, skip_v: np.ndarray, closed: bool) -> None:
    """out[:, 6]: the fold term of scan_rows, from the positions and the unit normals in out
    (left as it was at the vertices skip_v marks when `closed`)."""
    n = pos.shape[0]
    for i in range(n):
        lo, hi = nbr_ptr[i], nbr_ptr[i + 1]
        if hi == lo or (closed and skip_v[i]):
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
        if closed and skip_v[i]:
            continue
        lo, hi = nbr_ptr[i], nbr_ptr[i + 1]
        s = scratch[i]
        for k in range(lo, hi):
            s += scratch[nbr[k]]
        out[i, 6] = s / np.float32(1 + hi - lo)


@numba.njit(cache=True, nogil=True)
def scan_rows(pos: np.ndarray, tri: np.ndarray, nbr_ptr: np.ndarray, nbr: np.ndarray, inv_len: np.ndarray,
              scratch: np.ndarray, out: np.ndarray, skip_tri: np.ndarray, skip_v: np.ndarray, closed: bool,
              group: np.ndarray, starts: np.ndarray, eye: np.ndarray, kept: np.ndarray,
              counts: np.ndarray) -> None:
    """out[:, 0:3] = pos; out[:, 3:6] = unit area-weighted vertex normals; out[:, 6] = how far the
    vertex lies below the mean of its mesh neighbours, along its normal, per neighbour distance
    (`inv_len`: 1 / the rest's mean edge length there), averaged once more over the neighbours:
    positive in a crease (a fold, the nasolabial groove, the frown lines), negative on a ridge.
    It is recomputed from the posed surface every frame, so a fold that deepens darkens.

    When `closed` (the mouth's inside is not drawn), the triangles skip_tri marks and the vertices
    skip_v marks (deep in the mouth: their normals and folds feed no drawn vertex) are passed over.

    In the same pass over the triangles, those of each drawn group g (group[t] = g >= 0) not
    clearly turned away from `eye` (the camera's position, model space) are listed, in order, at
    kept[starts[g]:starts[g] + counts[g]]. A triangle is left out only when the eye lies behind its
    plane by more than 1e-3 rad: OpenGL's back-face culling would drop it anyway, so the picture is
    the same and the rasterizer fetches and sets up only the rest."""
    n = pos.shape[0]
    for i in range(n):
        out[i, 0] = pos[i, 0]
        out[i, 1] = pos[i, 1]
        out[i, 2] = pos[i, 2]
        out[i, 3] = 0.0
        out[i, 4] = 0.0
        out[i, 5] = 0.0
    for g in range(counts.shape[0]):
        counts[g] = 0
    ex, ey, ez = np.float32(eye[0]), np.float32(eye[1]), np.float32(eye[2])
    hair = np.float32(1e-6)  # (1e-3)^2: compared with squares, no square root per triangle
    for t in range(tri.shape[0]):
        if closed and skip_tri[t]:
            continue
        cx, cy, cz = add_face_normal(pos, tri, t, out)
        g = group[t]
        if g < 0:
            continue
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        wx, wy, wz = ex - pos[a, 0], ey - pos[a, 1], ez - pos[a, 2]
        d = cx * wx + cy * wy + cz * wz
        if d < 0 and d * d > hair * (cx * cx + cy * cy + cz * cz) * (wx * wx + wy * wy + wz * wz):
            continue
        k = starts[g] + counts[g]
        kept[k, 0] = a
        kept[k, 1] = b
        kept[k, 2] = c
        counts[g] += 1
    for i in range(n):
        x, y, z = out[i, 3], out[i, 4], out[i, 5]
        length = np.sqrt(x * x + y * y + z * z)
        inv = np.float32(1.0) / max(length, np.float32(1e-12))
        out[i, 3] = x * inv
        out[i, 4] = y * inv
        out[i, 5] = z * inv
    _fold(pos, nbr_ptr, nbr, inv_len, scratch, out, skip_v, closed)
