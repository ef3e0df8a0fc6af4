"""The layered tissue's stiffness (`sim.layered`): physical invariants on a flat patch and the scan."""

from __future__ import annotations

import numpy as np
import pytest

from sim.layered import DEEP, SKIN, layered


def patch(rows: int = 9, cols: int = 9, edge: float = 0.35):  # type: ignore[no-untyped-def]
    """A flat triangular lattice (every inner vertex has six neighbours 60 degrees apart), normal +z."""
    j, i = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    pts = np.stack([(i + 0.5 * j).ravel() * edge, (j * np.sqrt(3) / 2).ravel() * edge, np.zeros(i.size)], axis=1)
    idx = np.arange(rows * cols).reshape(rows, cols)
    tri = np.concatenate([np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1]], -1).reshape(-1, 3),
                          np.stack([idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 3)])
    e = np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1), axis=0)
    normal = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    rim = (j == 0) | (j == rows - 1) | (i == 0) | (i == cols - 1)
    return pts, normal, tri, e, rim.ravel(), idx


def build(shear=1.0, held=None, **kw):  # type: ignore[no-untyped-def]
    pts, normal, tri, e, rim, idx = patch()
    n = len(pts)
    layers = layered(pts, normal, tri, e, np.full(len(e), 3000.0), np.full(n, 800.0), np.full(n, 110.0),
                     rim if held is None else held, np.full(n, 0.4), skin_shear=shear, **kw)
    return layers, idx


def test_stiffness_is_symmetric_and_positive_definite_where_free() -> None:
    layers, _ = build(shear=np.linspace(0.05, 20.0, 81), deep_modulus=3.0)
    k = layers.stiffness().toarray()
    assert np.allclose(k, k.T)
    free = layers.free_dofs()
    assert np.linalg.eigvalsh(k[np.ix_(free, free)]).min() > 0.0
    # with nothing held, the whole tissue floats: six rigid motions cost nothing
    assert np.sum(np.abs(np.linalg.eigvalsh(k)) < 1e-6 * np.abs(k).max()) == 6


def test_forces_are_internal_and_rigid_motion_of_the_bone_strains_nothing() -> None:
    layers, _ = build()
    k = layers.stiffness()
    p = layers.rest
    rng = np.random.default_rng(3)
    f = (k @ rng.normal(size=p.size)).reshape(-1, 3)
    scale = np.abs(f).max()
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * scale * len(p)  # no net force
    assert np.abs(np.cross(p, f).sum(axis=0)).max() < 1e-9 * scale * len(p) * np.abs(p).max()  # no net torque
    # every node, bone included, translated and turned (infinitesimally): no spring stretches
    omega, shift = np.array([0.3, -0.2, 0.5]), np.array([1.0, 2.0, -0.5])
    rigid = (shift + np.cross(omega, p)).ravel()
    assert np.abs(k @ rigid).max() < 1e-9 * np.abs(k).max() * np.abs(rigid).max()


def test_the_tissue_sliding_whole_holds_the_skin_by_the_sheets_tether() -> None:
    """Skin slid u across, the deep layer u/2, the bone still: an inner skin vertex feels the
    sheet's tether force (110 dyn/cm times u), the deep node between none; a skin-deep tie twice as
    lax lets the deep layer take the difference."""
    for shear in (1.0, 0.5):
        layers, idx = build(shear=shear)
        n = layers.n
        u = np.array([0.1, 0.05, 0.0])
        x = np.zeros((3 * n, 3))
        share = 1.0 / (1.0 + shear)  # of the slide taken by the skin-deep tie (the ties in series)
        x[SKIN * n:(SKIN + 1) * n] = u
        x[DEEP * n:(DEEP + 1) * n] = u * (1.0 - share)
        f = (layers.stiffness() @ x.ravel()).reshape(-1, 3)
        centre = idx[4, 4]
        expected = 110.0 * shear / (1.0 + shear) * 2.0 * u  # series of 2T*shear and 2T
        assert np.allclose(f[SKIN * n + centre], expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
        assert np.abs(f[DEEP * n + centre]).max() < 1e-9 * np.abs(expected).max()


def test_a_ligament_holds_the_skin_where_fat_lets_it_slide() -> None:
    """The same pull on the deep layer's middle: the skin above it follows less under a lax tie."""
    from scipy.sparse.linalg import spsolve

    moved = []
    for shear in (0.05, 20.0):
        layers, idx = build(shear=shear)
        n, free = layers.n, layers.free_dofs()
        f = np.zeros((3 * n, 3))
        f[DEEP * n + idx[4, 4]] = [50.0, 0.0, 0.0]
        x = np.zeros(9 * n)
        x[free] = spsolve(layers.stiffness()[free][:, free].tocsc(), f.ravel()[free])
        x = x.reshape(-1, 3)
        moved.append(x[SKIN * n + idx[4, 4], 0] / x[DEEP * n + idx[4, 4], 0])
    assert 0.0 < 4.0 * moved[0] < moved[1] <= 1.0, moved


def test_layers_need_a_thickness() -> None:
    with pytest.raises(ValueError):
        pts, normal, tri, e, rim, _ = patch()
        layered(pts, normal, tri, e, np.ones(len(e)), np.ones(len(pts)), np.ones(len(pts)), rim, np.zeros(len(pts)))


def test_scan_tissue_is_thin_on_the_lids_and_thick_on_the_cheeks() -> None:
    from sim.face.scan.layers import THICKNESS_MAX, THICKNESS_MIN, ligaments, tissue_thickness
    from sim.face.scan.rig import scan_model

    model = scan_model()
    t = tissue_thickness(model)
    assert THICKNESS_MIN <= t.min() and t.max() <= THICKNESS_MAX
    assert t[model.landmark_index("upper_lid_l")] < 0.4 < t[model.landmark_index("cheek_l")]
    lig = ligaments(model)
    assert lig[model.landmark_index("upper_lip_center")] > 0.9  # the lips' skin lies on the muscle
    assert lig[model.landmark_index("nose_tip")] < 0.1
