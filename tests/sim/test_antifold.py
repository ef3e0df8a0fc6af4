"""The skin's thickness term (sim.antifold): silent unless a triangle nears folding flat, then a
force that unfolds it, internal (it sums to zero) and along the rest plane only."""

from __future__ import annotations

import numpy as np

from sim.antifold import FoldGuard

REST = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, 0.9, 0.0], [1.2, 1.0, 0.1]])
TRI = np.array([[0, 1, 2], [1, 3, 2]])
SPRINGS = np.array([[0, 1], [1, 2], [0, 2], [1, 3], [2, 3]])


def _guard() -> FoldGuard:
    return FoldGuard(REST, TRI, SPRINGS, np.full(len(SPRINGS), 100.0))


def _det(g: FoldGuard, y: np.ndarray, t: int = 0) -> float:
    a, b, c = (y[g.tri[t, k]] for k in range(3))
    n0 = np.cross(REST[g.tri[t, 1]] - REST[g.tri[t, 0]], REST[g.tri[t, 2]] - REST[g.tri[t, 0]])
    return float(np.dot(np.cross(b - a, c - a), n0) / np.dot(n0, n0))


def test_silent_at_rest_and_under_ordinary_strain() -> None:
    g = _guard()
    rng = np.random.default_rng(1)
    for _ in range(20):
        y = REST * rng.uniform(0.7, 1.3) + rng.normal(0.0, 0.03, REST.shape)
        out = np.zeros_like(REST)
        assert min(_det(g, y, 0), _det(g, y, 1)) >= g.floor
        assert g.add_forces(y, out) == 0 and not out.any()


def test_a_turned_over_triangle_is_pushed_back_and_the_force_is_internal() -> None:
    g = _guard()
    y = REST.copy()
    y[2] = [0.5, -0.2, 0.05]  # vertex 2 pushed through edge 0-1: triangle 0 turned over
    assert _det(g, y) < 0
    out = np.zeros_like(y)
    assert g.add_forces(y, out) >= 1
    assert np.allclose(out.sum(axis=0), 0.0)  # no net force on the skin
    assert abs(out[:, 2]).max() < 1e-12  # in the rest plane (z) only
    steps = 0
    while _det(g, y) < 0.9 * g.floor and steps < 2000:  # follow the force: the triangle unfolds
        out[:] = 0.0
        g.add_forces(y, out)
        y += 1e-3 * out
        steps += 1
    assert _det(g, y) >= 0.9 * g.floor, steps
