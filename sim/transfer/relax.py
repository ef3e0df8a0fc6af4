"""Seed 003 eq 8: relax the flattened reference mask as a damped spring mesh whose characteristic
points are held where the new face's characteristic points project."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

FloatArray = np.ndarray
IntArray = np.ndarray


@dataclass(frozen=True)
class Relaxation:
    """Result of `relax_mask`: positions (N, D), steps taken, the largest residual spring force on
    a free node relative to the mean spring stiffness times mean rest length, and whether the
    system came to rest before the step limit."""

    positions: FloatArray
    steps: int
    residual: float
    converged: bool


def incidence(edges: IntArray, n: int) -> sp.csr_matrix:
    """(n, E) sparse matrix gathering each spring's force onto its two nodes (+1 at i, -1 at j)."""
    e = len(edges)
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    vals = np.concatenate([np.ones(e), -np.ones(e)])
    return sp.csr_matrix((vals, (rows, np.tile(np.arange(e), 2))), shape=(n, e))


def spring_forces(
    positions: FloatArray,
    edges: IntArray,
    rest: FloatArray,
    stiffness: FloatArray,
    gather: sp.csr_matrix | None = None,
) -> FloatArray:
    """Seed 003 eq 8, the spring sum: F_i = sum_j k_ij (|P_iP_j| - |P0_iP0_j|) P_iP_j / |P_iP_j|.
    A stretched spring pulls i towards j; each spring acts equally and oppositely on j. `gather`
    is `incidence(edges, n)`, passed in by loops that call this many times."""
    vec = positions[edges[:, 1]] - positions[edges[:, 0]]
    length = np.linalg.norm(vec, axis=1)
    coef = stiffness * (length - rest) / np.maximum(length, 1e-12)
    if gather is None:
        gather = incidence(edges, len(positions))
    return gather @ (coef[:, None] * vec)


def area_forces(
    positions: FloatArray,
    triangles: IntArray,
    rest_area: FloatArray,
    stiffness: float,
    gather: sp.csr_matrix | None = None,
) -> FloatArray:
    """Not in the paper: -grad of sum_t stiffness (A_t - A0_t)^2 / (2 |A0_t|) over signed 2D
    triangle areas. Springs alone (eq 8) let a compressed 2D mesh fold; this term makes a flip
    cost about stiffness * A0 and so keeps the relaxed mask a valid chart. `gather` is
    `corner_gather(triangles, n)`."""
    a, b, c = (positions[triangles[:, k]] for k in range(3))
    area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    coef = -0.5 * stiffness * (area - rest_area) / np.abs(rest_area)
    # 2 dA/dx at corner k is the opposite edge (p -> q) turned by -90 degrees
    grads = np.concatenate([np.stack([p[:, 1] - q[:, 1], q[:, 0] - p[:, 0]], axis=1)
                            for p, q in ((b, c), (c, a), (a, b))])
    if gather is None:
        gather = corner_gather(triangles, len(positions))
    return gather @ (np.tile(coef, 3)[:, None] * grads)


def corner_gather(triangles: IntArray, n: int) -> sp.csr_matrix:
    """(n, 3M) sparse matrix summing per-corner values (corner 0 of every triangle, then 1, 2)."""
    m = len(triangles)
    return sp.csr_matrix((np.ones(3 * m), (triangles.T.ravel(), np.arange(3 * m))), shape=(n, 3 * m))


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
    defaults to the sum of the stiffnesses at node i (every node then has the same highest
    frequency, whatever the mesh's edge lengths) and h to 0.05 * omega_max * m_i, found to settle
    fastest. Semi-implicit Euler at half the stability limit (Gershgorin bound on K/M).
    With `triangles`, their signed `rest_area` and `area_stiffness` > 0 the `area_forces` term
    is added (see there)."""
    p = np.array(positions, float)
    n = len(p)
    k = np.ones(len(edges)) if stiffness is None else np.asarray(stiffness, float)
    free = ~np.asarray(fixed, bool)
    k_node = np.zeros(n)
    np.add.at(k_node, edges[:, 0], k)
    np.add.at(k_node, edges[:, 1], k)
    use_area = triangles is not None and rest_area is not None and area_stiffness > 0
    if use_area:
        tv = p[triangles]
        rest_area = np.where(np.abs(rest_area) > 1e-12, rest_area, 1e-12)
        for k in range(3):  # curvature of the area term at each corner, for the step bound
            opp = np.linalg.norm(tv[:, (k + 1) % 3] - tv[:, (k + 2) % 3], axis=1)
            k_node += np.bincount(triangles[:, k], area_stiffness * opp ** 2 / (4 * np.abs(rest_area)), n)
        corners = corner_gather(triangles, n)
    m = np.maximum(k_node, 1e-12) if mass is None else np.asarray(mass, float)
    omega_max = float(np.sqrt(2.0 * (k_node / m).max()))
    dt = 1.0 / omega_max
    h = (0.05 * omega_max if damping is None else damping) * m
    scale = float(np.mean(k) * np.mean(rest))
    gather = incidence(edges, n)
    v = np.zeros_like(p)
    residual = np.inf
    step = 0
    for step in range(1, max_steps + 1):
        f = spring_forces(p, edges, rest, k, gather) - h[:, None] * v
        if use_area:
            f += area_forces(p, triangles, rest_area, area_stiffness, corners)
        v += dt * f / m[:, None]
        v[~free] = 0.0
        p += dt * v
        if step % 50 == 0:
            spring = spring_forces(p, edges, rest, k, gather)
            if use_area:
                spring += area_forces(p, triangles, rest_area, area_stiffness, corners)
            spring = spring[free]
            residual = float(np.abs(spring).max() / scale) if spring.size else 0.0
            if residual < tol:
                return Relaxation(p, step, residual, True)
    return Relaxation(p, step, residual, False)
