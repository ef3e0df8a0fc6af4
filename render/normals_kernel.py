"""The compiled vertex-normal kernel of render.meshdata.NormalComputer, in its own module so that
importing the renderer does not import numba (a render process of an export never needs it)."""

from __future__ import annotations

import numba
import numpy as np
from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


@numba.njit(cache=True, nogil=True, inline="always")
def face_cross(pos: np.ndarray, a: int, b: int, c: int) -> tuple[float, float, float]:
    """(b - a) x (c - a): twice the triangle's area times its normal."""
    e1x, e1y, e1z = pos[b, 0] - pos[a, 0], pos[b, 1] - pos[a, 1], pos[b, 2] - pos[a, 2]
    e2x, e2y, e2z = pos[c, 0] - pos[a, 0], pos[c, 1] - pos[a, 1], pos[c, 2] - pos[a, 2]
    return e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x


@numba.njit(cache=True, nogil=True, inline="always")
def add_face_normal(pos: np.ndarray, tri: np.ndarray, t: int, out: np.ndarray) -> tuple[float, float, float]:
    """Triangle t's cross product (twice its area times its normal) added to out[:, 3:6] of its
    three corners; returned too."""
    a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
    cx, cy, cz = face_cross(pos, a, b, c)
    for v in (a, b, c):
        out[v, 3] += cx
        out[v, 4] += cy
        out[v, 5] += cz
    return cx, cy, cz


@numba.njit(cache=True, nogil=True, inline="always")
def start_rows(pos: np.ndarray, out: np.ndarray) -> None:
    """out[:, 0:3] = pos, out[:, 3:6] = 0: the rows before the triangles' normals are added."""
    for i in range(pos.shape[0]):
        out[i, 0] = pos[i, 0]
        out[i, 1] = pos[i, 1]
        out[i, 2] = pos[i, 2]
        out[i, 3] = 0.0
        out[i, 4] = 0.0
        out[i, 5] = 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def unit_normals(out: np.ndarray, n: int) -> None:
    """The summed normals in out[:n, 3:6] made unit length (a vertex with none stays zero)."""
    for i in range(n):
        x, y, z = out[i, 3], out[i, 4], out[i, 5]
        length = np.sqrt(x * x + y * y + z * z)
        inv = np.float32(1.0) / max(length, np.float32(1e-12))
        out[i, 3] = x * inv
        out[i, 4] = y * inv
        out[i, 5] = z * inv


@numba.njit(cache=True, nogil=True)
def interleave_normals(pos: np.ndarray, tri: np.ndarray, out: np.ndarray) -> None:
    """out[:, 0:3] = pos; out[:, 3:6] = unit area-weighted vertex normals, in one pass over the
    triangles (each triangle's cross product, twice its area times its normal, added to its three
    corners) and one over the vertices."""
    start_rows(pos, out)
    for t in range(tri.shape[0]):
        add_face_normal(pos, tri, t, out)
    unit_normals(out, pos.shape[0])
