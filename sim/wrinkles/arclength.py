"""The arc length S(d, a, alpha) of a wrinkle's cross-section (seed 003, section 5.1, eqs 11-14).

A wrinkle's cross-section between two points P0, P1 of the skin is a planar cubic whose arc length
must equal the dilated skin length. S is tabulated once on the paper's grid and read by trilinear
interpolation (eq 14), so the per-frame solve is a handful of array look-ups.

Readings chosen where the scanned text is ambiguous:
- "C-spline segment passing through P0, P1 with tangents P0P'0 and P1P'1": we read P0, P'0, P'1,
  P1 as the control polygon of a cubic Bezier segment (so C'(0) = 3 P0P'0 and C'(1) = 3 P'1P1).
  With a = d/3 and alpha = 0 the segment is the straight chord at uniform speed: flat skin.
  Hermite tangents of norm a would give bulges a third as tall and exhaust the table's a-range.
- Table units. S is exactly homogeneous of degree one: S(k d, k a, alpha) = k S(d, a, alpha).
  The paper's grid is coarse where d is small (steps of 1 in a when d < 10 straddle the kink
  where the segment starts to loop): read there, eq 14 errs by up to ~75 %. So a query in
  centimetres is read at table coordinates (k d, k a) with k = min(20.1 / d, 10 / a) table units
  per cm -- the largest scale that stays on the grid -- and the result divided by k. With the
  solver's a <= 0.95 d this lands at d in [10.5, 20.1], where eq 14 on the paper's grid is within
  0.7 % (measured against quadrature; the lower half of the grid errs by up to ~90 %).
- Asymmetric wrinkles (section 5.2, "a tabulation of S more adapted to that case"): the far end
  P0 rises at ASYM_RATIO * alpha, the end on the furrow P1 at alpha, both with norm a, so the crest
  leans towards the furrow as a nasolabial cheek roll does. It has its own table.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

FloatArray = np.ndarray

D_NODES = 0.1 + np.arange(21, dtype=np.float64)  # 0.1 .. 20.1 by 1
A_NODES = np.arange(11, dtype=np.float64)  # 0 .. 10 by 1
ALPHA_STEP = np.pi / 20.0
ALPHA_NODES_2D = ALPHA_STEP * np.arange(11)  # 0 .. pi/2 (section 5.1)
ALPHA_NODES_3D = ALPHA_STEP * np.arange(21)  # 0 .. pi (section 5.2 footnote)
ASYM_RATIO = 0.25

# Composite Gauss-Legendre rule on [0, 1]: 16 panels of 8 nodes, so the sharp speed dips of
# nearly looping segments are still integrated to ~1e-6.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_PANELS = 16
_U = ((np.arange(_PANELS)[:, None] + (_GL_X[None, :] + 1.0) / 2.0) / _PANELS).ravel()
_W = np.tile(_GL_W / (2.0 * _PANELS), _PANELS)


def control_points(
    d: FloatArray, a: FloatArray, alpha0: FloatArray, alpha1: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Eqs 11-12: P'0 = (a cos alpha, a sin alpha), P'1 = (d - a cos alpha, a sin alpha), with
    P0 = (0, 0), P1 = (d, 0). alpha0 / alpha1 are the angles at P0 / P1 (equal in the paper's
    symmetric case). Returns (x1, y1, x2, y2), broadcast."""
    x1 = a * np.cos(alpha0)
    y1 = a * np.sin(alpha0)
    x2 = d - a * np.cos(alpha1)
    y2 = a * np.sin(alpha1)
    return x1, y1, x2, y2


def arc_length(
    d: FloatArray, a: FloatArray, alpha0: FloatArray, alpha1: FloatArray | None = None
) -> FloatArray:
    """Eq 13: S = integral over u in [0, 1] of |C'(u)| for the Bezier segment P0, P'0, P'1, P1,
    by composite Gauss-Legendre quadrature, vectorised over broadcast inputs."""
    if alpha1 is None:
        alpha1 = alpha0
    d, a, alpha0, alpha1 = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (d, a, alpha0, alpha1))
    )
    x1, y1, x2, y2 = (v[..., None] for v in control_points(d, a, alpha0, alpha1))
    u = _U
    b0 = 3.0 * (1.0 - u) ** 2
    b1 = 6.0 * (1.0 - u) * u
    b2 = 3.0 * u**2
    dx = b0 * x1 + b1 * (x2 - x1) + b2 * (d[..., None] - x2)
    dy = b0 * y1 + b1 * (y2 - y1) - b2 * y2
    return np.einsum("...k,k->...", np.sqrt(dx * dx + dy * dy), _W)  # not `@`: BLAS's bits vary (sim.rowmath)


@dataclass(frozen=True, eq=False)
class ArcTable:
    """S tabulated on D_NODES x A_NODES x alpha_nodes, in table units.

    values: (21, 11, K) float64; alpha_nodes: (K,) rad from 0 by ALPHA_STEP; asymmetric: whether
    the end angles follow the asymmetric law (ASYM_RATIO * alpha at P0)."""

    values: FloatArray
    alpha_nodes: FloatArray
    asymmetric: bool


def build_table(alpha_nodes: FloatArray, asymmetric: bool = False) -> ArcTable:
    """Tabulate S (eq 13) on the paper's (d, a) grid and the given alpha nodes."""
    al = np.asarray(alpha_nodes, dtype=np.float64)
    alpha0 = ASYM_RATIO * al if asymmetric else al
    values = arc_length(D_NODES[:, None, None], A_NODES[None, :, None], alpha0, al)
    values.setflags(write=False)
    return ArcTable(values=values, alpha_nodes=al, asymmetric=asymmetric)


@lru_cache(maxsize=None)
def table(asymmetric: bool = False, alpha_to_pi: bool = True) -> ArcTable:
    """The shared tables, built on first use (milliseconds, so no file cache is kept)."""
    return build_table(ALPHA_NODES_3D if alpha_to_pi else ALPHA_NODES_2D, asymmetric)


def _cell(x: FloatArray, first: float, step: float, n: int) -> tuple[FloatArray, FloatArray]:
    """Cell index and local coordinate in [0, 1] of x on a uniform grid (clamped to the grid)."""
    t = np.minimum(np.maximum((x - first) / step, 0.0), n - 1.0)
    i = np.minimum(t.astype(np.intp), n - 2)
    return i, t - i


def trilinear(tab: ArcTable, d: FloatArray, a: FloatArray, alpha: FloatArray) -> FloatArray:
    """Eq 14: S at (d, a, alpha) in table units, the weighted sum of the eight corners of the
    grid cube around the point (clamped to the grid)."""
    d, a, alpha = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (d, a, alpha)))
    n_a, n_k = tab.values.shape[1], tab.values.shape[2]
    i, fd = _cell(d, D_NODES[0], 1.0, len(D_NODES))
    j, fa = _cell(a, A_NODES[0], 1.0, n_a)
    k, fl = _cell(alpha, 0.0, ALPHA_STEP, n_k)
    flat = tab.values.ravel()
    base = (i * n_a + j) * n_k + k
    out = np.zeros(d.shape)
    for di, wd in ((0, 1.0 - fd), (1, fd)):
        for aj, wa in ((0, 1.0 - fa), (1, fa)):
            w = wd * wa
            corner = base + (di * n_a + aj) * n_k
            out += w * ((1.0 - fl) * np.take(flat, corner) + fl * np.take(flat, corner + 1))
    return out


def table_scale(d: FloatArray, a: FloatArray) -> FloatArray:
    """Table units per cm for a query: the largest k with k d <= 20.1 and k a <= 10."""
    d = np.asarray(d, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    return np.minimum(D_NODES[-1] / np.maximum(d, 1e-12), A_NODES[-1] / np.maximum(a, 1e-12))


def lookup(tab: ArcTable, d: FloatArray, a: FloatArray, alpha: FloatArray) -> FloatArray:
    """S in cm for a chord d and tangent norm a in cm: eq 14 read at the scaled coordinates."""
    k = table_scale(d, a)
    return trilinear(tab, k * d, k * a, alpha) / k


def lookup_alpha_profile(tab: ArcTable, d: FloatArray, a: FloatArray) -> FloatArray:
    """S in cm at every alpha node of the table for each query, (Q, K): eq 14 with the alpha
    weights left to the caller (S is then piecewise linear in alpha, which the solver inverts)."""
    d = np.asarray(d, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    k = table_scale(d, a)
    i, fd = _cell(k * d, D_NODES[0], 1.0, len(D_NODES))
    j, fa = _cell(k * a, A_NODES[0], 1.0, len(A_NODES))
    s = tab.values
    out = s[i, j] * ((1 - fd) * (1 - fa))[:, None]
    out += s[i + 1, j] * (fd * (1 - fa))[:, None]
    out += s[i, j + 1] * ((1 - fd) * fa)[:, None]
    out += s[i + 1, j + 1] * (fd * fa)[:, None]
    return out / k[:, None]
