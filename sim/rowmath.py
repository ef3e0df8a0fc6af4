"""Small vector products that give the same bits whatever BLAS is loaded.

numpy sends `a @ b`, `np.dot` and `np.linalg.norm` of a whole vector to BLAS, and OpenBLAS picks its
kernel per CPU (or from OPENBLAS_CORETYPE): the last bits of a product change with it. On the path
that builds a face and steps it, that made the compiled face's hash and every replay digest depend
on the process's environment (a take recorded under one OpenBLAS kernel "did not replay" under
another, on the same machine). These helpers spell the 3-component products out as elementwise
multiply-adds, which IEEE arithmetic rounds the same everywhere.
"""

from __future__ import annotations

import math

import numpy as np


def dot3(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """a (..., 3) . v (3,) per row."""
    return a[..., 0] * v[0] + a[..., 1] * v[1] + a[..., 2] * v[2]


def times3(a: np.ndarray, m: np.ndarray) -> np.ndarray:
    """a (..., 3) @ m (3, 3), row by row."""
    m = np.asarray(m, dtype=np.float64)
    return np.stack([dot3(a, m[:, j]) for j in range(3)], axis=-1)


def norm3(v: np.ndarray) -> float:
    """Length of one 3-vector."""
    x, y, z = (float(c) for c in np.asarray(v, dtype=np.float64).reshape(3))
    return math.sqrt(x * x + y * y + z * z)
