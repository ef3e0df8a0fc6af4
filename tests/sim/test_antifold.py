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


def test_the_forehead_bends_as_its_bound_layer_and_nothing_else_changes() -> None:
    """On the procedural face (whose parameter is 1) the skin's bending is as before and its hash
    too; with the bound layer the forehead bends 8 times as stiffly, the glabella below the brows,
    the nose, cheeks, lips and the lids' thin skin as before, with the same matrix pattern (no new
    fill in the step's factors)."""
    from dataclasses import replace

    from sim.antifold import FOREHEAD_BENDING, THIN_SMOOTHING, bending_of, bending_weights
    from sim.build import SkinParams, _rig_digest, compile_model
    from sim.face import default_rig

    rig = default_rig(0)
    plain = compile_model(rig, SkinParams(gravity=False))
    bound = compile_model(rig, SkinParams(gravity=False, forehead_bending=FOREHEAD_BENDING))
    assert plain.hash == _rig_digest(rig, SkinParams(gravity=False)) != bound.hash
    w0, w1 = bending_weights(plain), bending_weights(bound)
    regions = {k: np.asarray(v, bool) for k, v in rig.mesh.regions.items()}
    thin = np.zeros(len(w0), bool)
    for name, mask in regions.items():
        if "lid" in name or "lip" in name:
            thin |= mask
    assert np.all(w0[thin] == THIN_SMOOTHING) and np.all(w0[~thin] == 1.0)
    forehead = regions["forehead"] & ~thin
    assert np.median(w1[forehead]) == FOREHEAD_BENDING
    for name in ("nose", "cheek_l", "chin", "upper_lip", "lower_lip", "upper_lid_l", "lower_lid_l"):
        assert np.array_equal(w1[regions[name]], w0[regions[name]]), name
    a, b = bending_of(plain), bending_of(bound)
    assert a.nnz == b.nnz and np.array_equal(a.indices, b.indices) and np.array_equal(a.indptr, b.indptr)
    assert abs(b - a).sum() > 0.0
    # the bound layer's bending leaves a translation and a rest pose alone (no force at rest)
    shift = np.ones(len(w0))
    assert np.abs(b @ shift).max() < 1e-9 * abs(b).max()
    assert replace(SkinParams(), forehead_bending=1.0) == SkinParams()


def test_the_guard_in_two_passes_has_the_bits_of_one_pass() -> None:
    """The guard's kernel (every triangle's determinant first, then the term of those that act:
    `_fold_forces`) adds the very bits of the term taken triangle by triangle in one pass (as the
    kernel was written before), counts the same triangles, and treats a triangle whose determinant
    is not a number as acting."""
    import numba

    from sim.antifold import _fold_at, _fold_forces

    @numba.njit
    def one_pass(y, tri, frame, dm_inv, area, k, floor, out):  # type: ignore[no-untyped-def]
        acting = 0
        for t in range(tri.shape[0]):
            acting += _fold_at(y, tri, frame, dm_inv, area, k, floor, out, t)
        return acting

    rng = np.random.default_rng(7)
    n = 40
    rest = np.c_[rng.uniform(0.0, 4.0, (n, 2)), rng.normal(0.0, 0.05, n)]
    tri = np.array([rng.choice(n, 3, replace=False) for _ in range(60)])
    springs = np.unique(np.sort(np.r_[tri[:, :2], tri[:, 1:], tri[:, ::2]], axis=1), axis=0)
    g = FoldGuard(rest, tri, springs, np.full(len(springs), 100.0))
    t3 = np.ascontiguousarray(3 * g.tri, dtype=np.uint32)
    for k in range(12):
        y = rest + rng.normal(0.0, 0.6, rest.shape)  # squeezed hard: some triangles turn over
        if k == 11:
            y[int(tri[5, 0]), 1] = np.nan
        base = rng.normal(0.0, 1.0, rest.shape)
        one, two = base.copy(), base.copy()
        acting = one_pass(y, g.tri, g.frame, g.dm_inv, g.area, g.k, g.floor, one)
        assert _fold_forces(y, t3, g.tri, g.frame, g.dm_inv, g.area, g.k, g.floor, two, np.zeros(len(g.tri))) == acting
        assert one.tobytes() == two.tobytes(), k
        assert 0 < acting < len(g.tri)


def test_lid_margin_distances_are_a_kd_trees_to_the_bit() -> None:
    """The bound layer's distance to the lid margins is found by brute force (no scipy.spatial import
    before a start's first tick); it must be a k-d tree's query bit for bit, or every take recorded on
    a face with a bound forehead would replay to other bits."""
    from scipy.spatial import cKDTree

    from sim.antifold import _nearest_distance

    rng = np.random.default_rng(7)
    points = rng.normal(size=(3000, 3)) * np.array([6.0, 8.0, 4.0])
    margins = points[rng.choice(len(points), 60, replace=False)] + rng.normal(size=(60, 3)) * 0.01
    assert np.array_equal(_nearest_distance(points, margins), cKDTree(margins).query(points)[0])
