"""Seed 003 eq 8: relax the flattened reference mask as a damped spring mesh whose characteristic
points are held where the new face's characteristic points project.

The force terms and the time loop are compiled with numba (serial, fixed summation order, so
results are repeatable): a relaxation takes about a thousand steps over a few thousand nodes."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start

FloatArray = np.ndarray
IntArray = np.ndarray


@dataclass(frozen=True)
class Relaxation:
    """Result of `relax_mask`: positions (N, 2), steps taken, the largest residual force on a free
    node relative to the mean spring stiffness times mean rest length, and whether the system came
    to rest before the step limit."""

    positions: FloatArray
    steps: int
    residual: float
    converged: bool


@numba.njit(cache=True)
def spring_forces(positions: FloatArray, edges: IntArray, rest: FloatArray, stiffness: FloatArray) -> FloatArray:
    """Seed 003 eq 8, the spring sum: F_i = sum_j k_ij (|P_iP_j| - |P0_iP0_j|) P_iP_j / |P_iP_j|.
    A stretched spring pulls i towards j; each spring acts equally and oppositely on j."""
    out = np.zeros_like(positions)
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        length = max(np.sqrt(dx * dx + dy * dy), 1e-12)
        c = stiffness[e] * (length - rest[e]) / length
        out[i, 0] += c * dx
        out[i, 1] += c * dy
        out[j, 0] -= c * dx
        out[j, 1] -= c * dy
    return out


@numba.njit(cache=True)
def area_forces(positions: FloatArray, triangles: IntArray, rest_area: FloatArray, stiffness: float) -> FloatArray:
    """Not in the paper: -grad of sum_t stiffness (A_t - A0_t)^2 / (2 |A0_t|) over signed 2D
    triangle areas. Springs alone (eq 8) let a compressed 2D mesh fold; this term makes a flip
    cost about stiffness * A0 and so keeps the relaxed mask a valid chart. dA/dx at a corner is
    half the opposite edge turned by -90 degrees."""
    out = np.zeros_like(positions)
    for t in range(triangles.shape[0]):
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        ax, ay = positions[a, 0], positions[a, 1]
        bx, by = positions[b, 0], positions[b, 1]
        cx, cy = positions[c, 0], positions[c, 1]
        area = 0.5 * ((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))
        coef = -0.5 * stiffness * (area - rest_area[t]) / abs(rest_area[t])
        out[a, 0] += coef * (by - cy)
        out[a, 1] += coef * (cx - bx)
        out[b, 0] += coef * (cy - ay)
        out[b, 1] += coef * (ax - cx)
        out[c, 0] += coef * (ay - by)
        out[c, 1] += coef * (bx - ax)
    return out


@numba.njit(cache=True)
def _steps(p: FloatArray, v: FloatArray, edges: IntArray, rest: FloatArray, k: FloatArray, triangles: IntArray,
           rest_area: FloatArray, k_area: float, m: FloatArray, h: FloatArray, dt: float, free: np.ndarray,
           count: int) -> None:
    """`count` semi-implicit Euler steps of m a = F_springs (+ F_area) - h v, fixed nodes held."""
    for _ in range(count):
        f = spring_forces(p, edges, rest, k)
        if k_area > 0.0:
            f += area_forces(p, triangles, rest_area, k_area)
        for i in range(p.shape[0]):
            if free[i]:
                for d in range(2):
                    v[i, d] += dt * (f[i, d] - h[i] * v[i, d]) / m[i]
                    p[i, d] += dt * v[i, d]


def _bound(n: int, edges: IntArray, k: FloatArray, triangles: IntArray, rest_area: FloatArray,
           positions: FloatArray, k_area: float) -> FloatArray:
    """Per node, half the Gershgorin row sum of the stiffness matrix (springs plus area term)."""
    k_node = np.bincount(edges[:, 0], k, n) + np.bincount(edges[:, 1], k, n)
    if k_area > 0:
        tv = positions[triangles]
        grad = [0.5 * np.linalg.norm(tv[:, (c + 1) % 3] - tv[:, (c + 2) % 3], axis=1) for c in range(3)]
        for c in range(3):
            row = k_area * (grad[c] * sum(grad) / np.abs(rest_area) + 1.0)
            k_node += np.bincount(triangles[:, c], 0.5 * row, n)
    return k_node


def relax_mask(
    positions: FloatArray,
    edges: IntArray,
    rest: FloatArray,
    fixed: np.ndarray,
    stiffness: FloatArray | None = None,
    mass: FloatArray | None = None,
    damping: float | None = None,
    tol: float = 1e-4,
    max_steps: int = 20000,
    triangles: IntArray | None = None,
    rest_area: FloatArray | None = None,
    area_stiffness: float = 0.0,
) -> Relaxation:
    """Integrate eq 8, m_i a_i = spring forces - h v_i, until the mesh is at rest; fixed nodes do
    not move. The rest state does not depend on m_i or h, so they are chosen for speed: m_i
    defaults to (half the Gershgorin row of) the stiffness at node i, so every node has the same
    highest frequency whatever the edge lengths, and h to 0.02 * omega_max * m_i, found to settle
    fastest. Semi-implicit Euler at half the stability limit. With `triangles`, their signed
    `rest_area` and `area_stiffness` > 0 the `area_forces` term is added (see there)."""
    p = np.array(positions, dtype=np.float64)
    n = len(p)
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    rest = np.ascontiguousarray(rest, dtype=np.float64)
    k = np.ones(len(edges)) if stiffness is None else np.ascontiguousarray(stiffness, dtype=np.float64)
    use_area = triangles is not None and rest_area is not None and area_stiffness > 0
    if use_area:
        tris = np.ascontiguousarray(triangles, dtype=np.int64)
        r_area = np.where(np.abs(rest_area) > 1e-12, rest_area, 1e-12).astype(np.float64)
    else:
        tris, r_area, area_stiffness = np.zeros((0, 3), np.int64), np.zeros(0), 0.0
    k_node = _bound(n, edges, k, tris, r_area, p, area_stiffness)
    m = np.maximum(k_node, 1e-12) if mass is None else np.asarray(mass, dtype=np.float64)
    omega_max = float(np.sqrt(2.0 * (k_node / m).max()))
    dt = 1.0 / omega_max
    h = (0.02 * omega_max if damping is None else damping) * m
    free = ~np.asarray(fixed, bool)
    scale = float(np.mean(k) * np.mean(rest))
    start = p.copy()
    v = np.zeros_like(p)
    residual, step, chunk = np.inf, 0, 50
    while step < max_steps:
        _steps(p, v, edges, rest, k, tris, r_area, float(area_stiffness), m, h, dt, free, chunk)
        step += chunk
        force = spring_forces(p, edges, rest, k)
        if use_area:
            force += area_forces(p, tris, r_area, float(area_stiffness))
        residual = float(np.abs(force[free]).max() / scale) if free.any() else 0.0
        if residual < tol:
            return Relaxation(p, step, residual, True)
        if not np.isfinite(residual):  # cannot happen below the bound; never hand back NaN
            return Relaxation(start, step, residual, False)
    return Relaxation(p, step, residual, False)
