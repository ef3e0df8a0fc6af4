"""The transfer's mathematics (seed 003 section 3) on synthetic surfaces with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import approx_fprime
from scipy.spatial.transform import Rotation

from sim.face.transfer.cylinder import Cylinder, cylinder_energy, cylinder_gradient, fit_cylinder
from sim.face.transfer.flatten import CylinderChart, flat_triangulation, project_back
from sim.face.transfer.geometry import boundary_loops, closest_points, locate_2d, unique_edges
from sim.face.transfer.relax import area_forces, relax_mask, spring_forces


def cylinder_points(rng: np.random.Generator, axis, origin, r, n=400, arc=2.4, noise=0.0):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    e1 = np.cross(axis, [0.3, 0.1, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    th = rng.uniform(-arc / 2, arc / 2, n)
    h = rng.uniform(-8, 8, n)
    pts = np.asarray(origin) + np.outer(h, axis) + r * (np.outer(np.cos(th), e1) + np.outer(np.sin(th), e2))
    return pts + rng.normal(0, noise, pts.shape)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), fixed=st.sampled_from([0, 1, 2]))
def test_gradient_matches_finite_differences(seed: int, fixed: int) -> None:
    """Eqs 2-7 are the derivative of eq 1, whichever coordinate of d is held."""
    rng = np.random.default_rng(seed)
    pts = rng.normal(0, 3, (60, 3))
    x = np.concatenate([rng.normal(0, 1, 3), rng.normal(0, 0.5, 2), [rng.uniform(1, 4)]])
    analytic = cylinder_gradient(x, pts, fixed)
    numeric = approx_fprime(x, cylinder_energy, 1e-6 * np.maximum(1, np.abs(x)), pts, fixed)
    assert np.allclose(analytic, numeric, rtol=1e-4, atol=1e-4 * np.abs(analytic).max())


def test_energy_and_gradient_vanish_on_the_cylinder() -> None:
    rng = np.random.default_rng(1)
    pts = cylinder_points(rng, [0, 1, 0], [1.0, 2.0, 3.0], 5.0)
    x = np.array([1.0, 2.0, 3.0, 0.0, 0.0, 5.0])
    assert cylinder_energy(x, pts) < 1e-18
    assert np.abs(cylinder_gradient(x, pts)).max() < 1e-8
    assert cylinder_energy(x + [0, 0, 0, 0, 0, 0.1], pts) > 1.0


@pytest.mark.parametrize("axis", [[0, 1, 0], [0.3, 1, -0.2], [-0.4, 0.9, 0.3]])
def test_fit_recovers_a_known_partial_cylinder(axis) -> None:
    """CG on eq 1 finds the cylinder a noisy 140-degree arc was sampled from."""
    rng = np.random.default_rng(2)
    pts = cylinder_points(rng, axis, [2.0, -1.0, 4.0], 8.0, noise=0.02)
    cyl = fit_cylinder(pts)
    true = np.asarray(axis, float) / np.linalg.norm(axis)
    assert np.degrees(np.arccos(abs(cyl.axis @ true))) < 1.0
    assert cyl.radius == pytest.approx(8.0, rel=0.01)
    off_axis = (cyl.origin - [2.0, -1.0, 4.0]) - ((cyl.origin - [2.0, -1.0, 4.0]) @ true) * true
    assert np.linalg.norm(off_axis) < 0.1
    assert cyl.residual_rms < 0.05


def test_fit_is_independent_of_units_and_placement() -> None:
    rng = np.random.default_rng(3)
    pts = cylinder_points(rng, [0.1, 1, 0.1], [0, 0, 0], 7.0, noise=0.01)
    a = fit_cylinder(pts)
    b = fit_cylinder(pts * 10.0 + [100.0, -50.0, 20.0])
    assert b.radius == pytest.approx(10 * a.radius, rel=1e-4)
    assert abs(a.axis @ b.axis) > 1 - 1e-8


def _chart(r=6.0) -> CylinderChart:
    return CylinderChart.facing(Cylinder(np.zeros(3), np.array([0.0, 1.0, 0.0]), r), np.array([0.0, 0.0, 1.0]))


def test_flattening_unrolls_the_cylinder_isometrically() -> None:
    """On the cylinder itself, flat distances along u are arc lengths and v is height."""
    chart = _chart()
    th = np.array([0.0, 0.5, -1.0])
    pts = np.stack([6 * np.sin(th), [1.0, 2.0, -3.0], 6 * np.cos(th)], axis=1)
    uv, rho = chart.flatten(pts)
    assert np.allclose(uv[:, 0], 6 * th) and np.allclose(uv[:, 1], [1, 2, -3])
    assert np.allclose(rho, 6.0)
    assert np.allclose(chart.unflatten(uv, rho), pts)
    # +u is the face's own left (+X) when the axis is up and the face looks along +Z
    assert chart.flatten(np.array([[1.0, 0, 5.0]]))[0][0, 0] > 0


def _sphere(n_lat=40, n_lon=80, r=5.0):
    lat = np.linspace(-1.3, 1.3, n_lat)
    lon = np.linspace(-np.pi, np.pi, n_lon, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    v = r * np.stack([np.cos(la) * np.sin(lo), np.sin(la), np.cos(la) * np.cos(lo)], -1).reshape(-1, 3)
    idx = np.arange(v.shape[0]).reshape(n_lat, n_lon)
    a, b = idx[:-1], np.roll(idx, -1, 1)[:-1]
    c, d = idx[1:], np.roll(idx, -1, 1)[1:]
    t = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([b, d, c], -1).reshape(-1, 3)])
    return v, t


def test_project_back_lands_on_the_surface_along_the_radius() -> None:
    v, t = _sphere()
    chart = _chart(4.0)
    uv_mesh, _, keep = flat_triangulation(chart, v, t)
    rng = np.random.default_rng(4)
    uv = np.stack([rng.uniform(-4, 4, 200), rng.uniform(-3, 3, 200)], axis=1)
    pts, hit = project_back(chart, uv, v, t, uv_mesh, keep)
    assert hit.all()
    assert np.allclose(np.linalg.norm(pts, axis=1), 5.0, atol=0.05)  # on the (faceted) sphere
    back, _ = chart.flatten(pts)
    assert np.allclose(back, uv, atol=1e-9)  # same angle and height: moved only along the radius


def test_closest_points_agree_with_brute_force() -> None:
    v, t = _sphere(12, 24)
    rng = np.random.default_rng(5)
    q = rng.normal(0, 4, (50, 3))
    closest, tri, bary, dist = closest_points(q, v, t, k=len(t))
    dense = np.einsum("mk,mkj->mj", rng.dirichlet(np.ones(3), (len(t))), v[t])
    brute = np.linalg.norm(q[:, None] - np.concatenate([v, dense])[None], axis=2).min(axis=1)
    assert (dist <= brute + 1e-9).all()
    assert np.allclose(np.linalg.norm(closest - q, axis=1), dist)
    assert np.allclose(np.einsum("pk,pkj->pj", bary, v[t[tri]]), closest)


def test_locate_2d_and_boundary_loops_on_a_grid_with_a_hole() -> None:
    g = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0)), -1).reshape(-1, 2)
    idx = np.arange(100).reshape(10, 10)
    t = np.concatenate([np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1]], -1).reshape(-1, 3),
                        np.stack([idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 3)])
    cen = g[t].mean(axis=1)
    t = t[~((np.abs(cen - 4.0) < 1.0).all(axis=1))]  # a 2x2-cell hole
    loops = boundary_loops(t)
    assert sorted(len(lp) for lp in loops) == [8, 36]
    tri, bary, inside = locate_2d(np.array([[2.2, 7.7], [4.2, 3.9], [20.0, 3.0]]), g, t)
    assert inside.tolist() == [True, False, False]
    assert np.allclose(np.einsum("k,kj->j", bary[0], g[t[tri[0]]]), [2.2, 7.7])


def test_spring_forces_follow_eq8_and_balance() -> None:
    p = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]])
    e = np.array([[0, 1], [0, 2]])
    f = spring_forces(p, e, np.array([1.0, 1.0]), np.array([3.0, 3.0]))
    assert np.allclose(f.sum(axis=0), 0.0)  # action = reaction
    assert np.allclose(f[0], [3.0, 0.0]) and np.allclose(f[1], [-3.0, 0.0])  # stretched: pull together
    assert np.allclose(f[2], 0.0)  # at rest length: no force


def _grid_mesh(n=12):
    g = np.stack(np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float)), -1).reshape(-1, 2)
    idx = np.arange(n * n).reshape(n, n)
    t = np.concatenate([np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1]], -1).reshape(-1, 3),
                        np.stack([idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 3)])
    return g, t


def _signed_areas(p, t):
    a, b, c = p[t[:, 0]], p[t[:, 1]], p[t[:, 2]]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


def test_relaxation_returns_to_a_rigid_motion_of_the_fixed_points() -> None:
    """Pinned points moved rigidly, free nodes disturbed: eq 8 brings back the rigid copy."""
    g, t = _grid_mesh()
    e = unique_edges(t)
    rest = np.linalg.norm(g[e[:, 1]] - g[e[:, 0]], axis=1)
    fixed = np.zeros(len(g), bool)
    fixed[[0, 11, 132, 143, 70]] = True
    rot = Rotation.from_euler("z", 30, degrees=True).as_matrix()[:2, :2]
    target = g @ rot.T + [5.0, -2.0]
    start = target + np.where(fixed[:, None], 0.0, np.random.default_rng(6).normal(0, 0.15, g.shape))
    out = relax_mask(start, e, rest, fixed)
    assert out.converged
    assert np.abs(out.positions - target).max() < 1e-3
    assert np.array_equal(out.positions[fixed], target[fixed])


def test_area_term_keeps_the_mask_from_folding() -> None:
    """Start far from the answer (pins turned 60 degrees, the rest left behind): springs alone
    settle folded; with the area term the same relaxation ends unfolded and rigid."""
    g, t = _grid_mesh()
    e = unique_edges(t)
    rest = np.linalg.norm(g[e[:, 1]] - g[e[:, 0]], axis=1)
    fixed = np.zeros(len(g), bool)
    fixed[[0, 11, 132, 143, 70]] = True
    rot = Rotation.from_euler("z", 60, degrees=True).as_matrix()[:2, :2]
    target = g @ rot.T
    start = g.copy()
    start[fixed] = target[fixed]
    rest_area = 0.5 * _signed_areas(g, t)
    springs_only = relax_mask(start, e, rest, fixed)
    assert (_signed_areas(springs_only.positions, t) < 0).any()
    with_area = relax_mask(start, e, rest, fixed, triangles=t, rest_area=rest_area, area_stiffness=10.0)
    assert with_area.converged
    assert (_signed_areas(with_area.positions, t) > 0).all()
    assert np.abs(with_area.positions - target).max() < 1e-2
    forces = area_forces(target, t.astype(np.int64), rest_area, 10.0)
    assert np.abs(forces).max() < 1e-9  # the term is zero at the rest shape


def test_relaxation_comes_to_rest_between_stretched_anchors() -> None:
    """A chain pinned at both ends, stretched: free nodes end evenly spaced (equal tensions)."""
    p = np.stack([np.linspace(0, 4, 5) ** 1.5, np.zeros(5)], axis=1)
    e = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])
    fixed = np.array([True, False, False, False, True])
    out = relax_mask(p, e, np.ones(4), fixed)
    assert out.converged
    assert np.allclose(np.diff(out.positions[:, 0]), out.positions[4, 0] / 4, atol=1e-3)
    assert np.abs(spring_forces(out.positions, e, np.ones(4), np.ones(4))[1:4]).max() < 1e-3
