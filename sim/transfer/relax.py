"""Seed 003 eq 8: relax the flattened reference mask as a damped spring mesh whose characteristic
points are held where the new face's characteristic points project."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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


def spring_forces(
    positions: FloatArray, edges: IntArray, rest: FloatArray, stiffness: FloatArray
) -> FloatArray:
    """Seed 003 eq 8, the spring sum: F_i = sum_j k_ij (|P_iP_j| - |P0_iP0_j|) P_iP_j / |P_iP_j|.
    A stretched spring pulls i towards j; each spring acts equally and oppositely on j."""
    vec = positions[edges[:, 1]] - positions[edges[:, 0]]
    length = np.linalg.norm(vec, axis=1)
    coef = stiffness * (length - rest) / np.maximum(length, 1e-12)
    f_edge = coef[:, None] * vec
    forces = np.zeros_like(positions)
    np.add.at(forces, edges[:, 0], f_edge)
    np.add.at(forces, edges[:, 1], -f_edge)
    return forces


def relax_mask(
    positions: FloatArray,
    edges: IntArray,
    rest: FloatArray,
    fixed: np.ndarray,
    stiffness: FloatArray | None = None,
    mass: FloatArray | None = None,
    damping: float | None = None,
    tol: float = 1e-5,
    max_steps: int = 20000,
) -> Relaxation:
    """Integrate eq 8, m_i a_i = spring forces - h v_i, until the mesh is at rest; fixed nodes do
    not move. The rest state does not depend on m_i or h, so they are chosen for speed: m_i
    defaults to the sum of the stiffnesses at node i (every node then has the same highest
    frequency, whatever the mesh's edge lengths) and h to 0.05 * omega_max * m_i, found to settle
    fastest. Semi-implicit Euler at half the stability limit (Gershgorin bound on K/M)."""
    p = np.array(positions, float)
    n = len(p)
    k = np.ones(len(edges)) if stiffness is None else np.asarray(stiffness, float)
    free = ~np.asarray(fixed, bool)
    k_node = np.zeros(n)
    np.add.at(k_node, edges[:, 0], k)
    np.add.at(k_node, edges[:, 1], k)
    m = np.maximum(k_node, 1e-12) if mass is None else np.asarray(mass, float)
    omega_max = float(np.sqrt(2.0 * (k_node / m).max()))
    dt = 1.0 / omega_max
    h = (0.05 * omega_max if damping is None else damping) * m
    scale = float(np.mean(k) * np.mean(rest))
    v = np.zeros_like(p)
    residual = np.inf
    step = 0
    for step in range(1, max_steps + 1):
        f = spring_forces(p, edges, rest, k) - h[:, None] * v
        v += dt * f / m[:, None]
        v[~free] = 0.0
        p += dt * v
        if step % 50 == 0:
            spring = spring_forces(p, edges, rest, k)[free]
            residual = float(np.abs(spring).max() / scale) if spring.size else 0.0
            if residual < tol:
                return Relaxation(p, step, residual, True)
    return Relaxation(p, step, residual, False)
