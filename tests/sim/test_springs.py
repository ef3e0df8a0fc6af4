"""Seed 000 eqs 1-5 against hand-computed values, and the spring network built on a mesh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.springs import (
    biphasic_stiffness,
    build_springs,
    elastic_forces,
    mesh_edges,
    spring_direction,
    spring_force,
    spring_strain,
    spring_tension,
    vertex_areas,
)


def test_eq2_relative_strain() -> None:
    assert spring_strain(np.array([1.2]), np.array([1.0]))[0] == pytest.approx(0.2)
    assert spring_strain(np.array([0.5]), np.array([2.0]))[0] == pytest.approx(-0.75)


def test_eq3_switch_is_exactly_at_the_threshold() -> None:
    eps_c = 0.15
    strains = np.array([-0.3, 0.0, eps_c, np.nextafter(eps_c, 1.0), 0.5])
    k = biphasic_stiffness(strains, np.full(5, 2.0), np.full(5, 7.0), eps_c)
    assert k.tolist() == [2.0, 2.0, 2.0, 7.0, 7.0]


def test_tension_slope_switches_at_threshold_and_is_continuous() -> None:
    r0, kl, kh, eps_c = np.array([2.0]), np.array([10.0]), np.array([40.0]), 0.1
    knee = r0 * (1 + eps_c)
    below = spring_tension(knee - 1e-6, r0, kl, kh, eps_c)
    at = spring_tension(knee, r0, kl, kh, eps_c)
    above = spring_tension(knee + 1e-6, r0, kl, kh, eps_c)
    assert at[0] == pytest.approx(10.0 * 0.2)  # k_l * (r - r^r) at the knee
    assert (at - below)[0] / 1e-6 == pytest.approx(10.0, rel=1e-3)
    assert (above - at)[0] / 1e-6 == pytest.approx(40.0, rel=1e-3)
    # 30 % stretch: soft part up to the knee, stiff part beyond
    assert spring_tension(np.array([2.6]), r0, kl, kh, eps_c)[0] == pytest.approx(10 * 0.2 + 40 * 0.4)


def test_eq4_direction_and_eq1_force() -> None:
    xi, xj = np.array([[0.0, 0.0, 0.0]]), np.array([[3.0, 4.0, 0.0]])
    u, r = spring_direction(xi, xj)
    assert r[0] == pytest.approx(5.0) and np.allclose(u, [[0.6, 0.8, 0.0]])
    q = spring_force(xi, xj, np.array([4.0]), np.array([2.0]), np.array([9.0]), 0.5)
    assert np.allclose(q, [[2.0 * 1.0 * 0.6, 2.0 * 1.0 * 0.8, 0.0]])  # stretched: pulls i towards j
    q = spring_force(xi, xj, np.array([6.0]), np.array([2.0]), np.array([9.0]), 0.5)
    assert np.allclose(q, [[-1.2, -1.6, 0.0]])  # compressed: pushes i away


def test_eq5_sums_springs_per_node_and_conserves_momentum() -> None:
    pos = np.array([[0.0, 0, 0], [2.0, 0, 0], [0.0, 3.0, 0]])
    springs = np.array([[0, 1], [0, 2]])
    f = elastic_forces(pos, springs, np.array([1.0, 1.0]), np.array([1.0, 2.0]), np.array([1.0, 2.0]), 10.0)
    assert np.allclose(f[0], [1.0, 4.0, 0.0])
    assert np.allclose(f[1], [-1.0, 0, 0]) and np.allclose(f[2], [0, -4.0, 0])


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000))
def test_elastic_forces_sum_to_zero(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(6, 3))
    springs = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [0, 5], [1, 4]])
    rest = rng.uniform(0.5, 2.0, len(springs))
    f = elastic_forces(pos, springs, rest, rest * 0 + 3.0, rest * 0 + 8.0, 0.1)
    assert np.allclose(f.sum(axis=0), 0.0, atol=1e-9)


def _hexagon() -> tuple[np.ndarray, np.ndarray]:
    ang = np.arange(6) * np.pi / 3
    v = np.vstack([[0.0, 0, 0], np.stack([np.cos(ang), np.sin(ang), 0 * ang], 1)])
    t = np.array([[0, 1 + k, 1 + (k + 1) % 6] for k in range(6)])
    return v, t


def test_network_edges_bending_springs_and_membrane_stiffness() -> None:
    v, t = _hexagon()
    edges, first, second = mesh_edges(t)
    assert len(edges) == 12 and np.sum(second >= 0) == 6
    idx, rest, k, n_edge = build_springs(v, t, sheet_modulus=100.0, bend_ratio=0.5)
    assert n_edge == 12 and len(idx) == 18
    # the interior spokes have two equilateral triangles: lattice value (sqrt 3 / 2) Y
    spokes = [e for e in range(12) if 0 in idx[e]]
    assert np.allclose(k[spokes], np.sqrt(3) / 2 * 100.0)
    # bending springs join the rim vertices two apart, across each spoke
    bend = idx[12:]
    assert np.allclose(rest[12:], np.sqrt(3)) and not np.any(bend == 0)
    assert vertex_areas(v, t).sum() == pytest.approx(6 * np.sqrt(3) / 4)
