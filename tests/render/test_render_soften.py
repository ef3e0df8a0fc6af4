"""The upper face's buckles softened before the scanned head is shaded (render.scan_soften): a buckle
a few vertices wide becomes a soft fold under a soft shadow, the expression's broad motion, a rigid
move and the lids are left as they are."""

from __future__ import annotations

import numpy as np
import pytest

from render.scan_look import ScanLook, eye_centres
from render.scan_soften import LID_CLEAR, LIMIT, FoldSoftener
from sim.face.scan.data import scan_data


@pytest.fixture(scope="module")
def soft() -> FoldSoftener:
    return FoldSoftener(ScanLook(scan_data().neutral))


def _forehead(s: FoldSoftener) -> np.ndarray:
    """The zone's vertices that get all of it, on the brows and the glabella between them."""
    rest = s.rest[s.zone]
    eye_y = eye_centres(s.rest.astype(float))[:, 1].mean()
    return s.zone[(s.weight > 0.999) & (rest[:, 1] > eye_y + 1.0) & (rest[:, 1] < eye_y + 2.5)
                  & (np.abs(rest[:, 0]) < 3.5)]


def test_the_forehead_above_the_brows_is_drawn_as_simulated(soft: FoldSoftener) -> None:
    """Its bound layer bends stiffly enough in the simulation (sim.antifold.bound_layer)."""
    rest = soft.rest[soft.zone]
    eye_y = eye_centres(soft.rest.astype(float))[:, 1].mean()
    assert len(soft.zone) > 100 and rest[:, 1].max() < eye_y + 4.5


def _normal(s: FoldSoftener) -> np.ndarray:
    n = np.zeros_like(s.rest)
    n[s.zone] = s.normal
    return n


def test_rest_and_a_rigid_move_are_left_as_they_are(soft: FoldSoftener) -> None:
    rest = soft.rest
    assert np.array_equal(soft.soften(rest), rest)
    moved = rest + np.array([0.3, -0.2, 0.5], np.float32)
    np.testing.assert_allclose(soft.soften(moved), moved, atol=2e-5)
    rows = np.zeros((len(rest), 7), np.float32)
    soft.soften(rest)
    assert not soft.shade(rows).any()  # no fold, no shadow


def test_a_buckle_becomes_a_soft_fold_and_the_broad_motion_stays(soft: FoldSoftener) -> None:
    rest = soft.rest.astype(np.float64)
    fh = _forehead(soft)
    assert len(fh) > 50
    eyes = eye_centres(rest)
    # a brow raise: 6 mm up, fading over a few centimetres, and on it vertical ridges 1 cm apart,
    # 2.5 mm high along the skin's normal (the simulated glabella's buckles are 1.5-3 mm)
    lift = 0.6 * np.exp(-0.5 * np.sum((rest[:, :2] - [0.0, eyes[0, 1] + 2.0]) ** 2, axis=1) / 3.0**2)
    ripple = 0.25 * np.sin(2.0 * np.pi * rest[:, 0] / 1.0)
    broad = rest + lift[:, None] * [0.0, 1.0, 0.0]
    posed = (broad + ripple[:, None] * _normal(soft)).astype(np.float32)
    out = soft.soften(posed).astype(np.float64)
    left = np.linalg.norm(out[fh] - broad[fh], axis=1)
    assert left.max() <= LIMIT + 0.03  # the ripple down to a soft fold of about LIMIT
    assert np.linalg.norm(posed[fh] - broad[fh], axis=1).max() > 0.2
    # the broad motion alone is kept
    smooth = soft.soften(broad.astype(np.float32)).astype(np.float64)
    assert np.abs(smooth[fh] - broad[fh]).max() < 0.02
    # the buckled skin keeps a soft shadow over it (the fold term grows), skin moved smoothly none
    rows = np.zeros((len(rest), 7), np.float32)
    soft.soften(posed)
    fold = soft.shade(rows)[:, 6].copy()
    assert (fold[fh] > 0.05).all()
    rows[:] = 0.0
    soft.soften(broad.astype(np.float32))
    assert np.abs(soft.shade(rows)[fh, 6]).max() < 0.1 * fold[fh].min()  # under 1 % darker

def test_the_lids_are_never_moved(soft: FoldSoftener) -> None:
    rest = soft.rest
    rng = np.random.default_rng(0)
    posed = rest + rng.normal(0.0, 0.2, rest.shape).astype(np.float32)
    out = soft.soften(posed)
    moved = np.flatnonzero(np.any(out != posed, axis=1))
    assert len(moved) > 100
    look = ScanLook(scan_data().neutral)
    eyes = eye_centres(rest.astype(float))
    margins = np.concatenate([lp for lp in look.openings
                              if np.min(np.linalg.norm(rest[lp].mean(axis=0) - eyes, axis=1)) < 1.5])
    dist = np.min(np.linalg.norm(rest[moved][:, None] - rest[margins][None], axis=2), axis=1)
    assert dist.min() >= LID_CLEAR[0]


def test_a_pleat_under_the_nose_is_smoothed_and_the_lip_lift_stays(soft: FoldSoftener) -> None:
    """The nostril sills: the upper lip raised into the nose's base crumpled the skin there into a
    pleat a few millimetres wide, drawn as a pale seam under the nostrils."""
    from render.scan_soften import NOSE_LIMIT
    from sim.face.scan.anatomy import load_landmarks

    rest = soft.rest.astype(np.float64)
    sub = rest[load_landmarks()["subnasale"]]
    zone = np.zeros(len(rest), bool)
    zone[soft.zone[soft.weight > 0.999]] = True
    rel = rest - sub
    sill = np.flatnonzero(zone & (np.abs(rel[:, 0]) < 1.0) & (rel[:, 1] > 0.0) & (rel[:, 1] < 0.6))
    assert len(sill) > 20
    # the lip and the nose's base raised 5 mm, fading over 2 cm, and on it a pleat: ridges 0.4 cm
    # apart across the sill, 1.5 mm high along the skin's normal
    lift = 0.5 * np.exp(-0.5 * np.sum(rel[:, :2] ** 2, axis=1) / 2.0**2)
    broad = rest + lift[:, None] * [0.0, 1.0, 0.0]
    pleat = 0.15 * np.sin(2.0 * np.pi * rel[:, 0] / 0.4)
    posed = (broad + pleat[:, None] * _normal(soft)).astype(np.float32)
    out = soft.soften(posed).astype(np.float64)
    assert np.linalg.norm(posed[sill] - broad[sill], axis=1).max() > 0.1
    assert np.linalg.norm(out[sill] - broad[sill], axis=1).max() <= NOSE_LIMIT + 0.02
    smooth = soft.soften(broad.astype(np.float32)).astype(np.float64)
    assert np.abs(smooth[sill] - broad[sill]).max() < 0.02


def test_the_glabellas_v_is_drawn_shallow(soft: FoldSoftener) -> None:
    """Between the brows the corrugators and procerus fold the skin into a V whose bottom is an edge
    or two wide (drawn as a dark seam): a V 2 mm deep and 1 cm across keeps at most 60 % of its depth."""
    from sim.face.scan.anatomy import load_landmarks

    rest = soft.rest.astype(np.float64)
    marks = load_landmarks()
    centre = 0.5 * (rest[marks["glabella"]] + rest[marks["nose_bridge"]])
    normal = _normal(soft)
    depth = 0.2 * np.clip(1.0 - np.abs(rest[:, 0] - centre[0]) / 0.5, 0.0, None)
    posed = (rest - depth[:, None] * normal).astype(np.float32)
    out = soft.soften(posed).astype(np.float64)
    zone = np.zeros(len(rest), bool)
    zone[soft.zone] = True
    bottom = np.flatnonzero(zone & (np.abs(rest[:, 0] - centre[0]) < 0.15) & (np.abs(rest[:, 1] - centre[1]) < 0.8))
    assert len(bottom) >= 5
    left = np.einsum("ij,ij->i", rest[bottom] - out[bottom], normal[bottom])
    assert (left > 0.0).all() and left.max() <= 0.6 * depth[bottom].max()
