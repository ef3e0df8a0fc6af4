"""Closed lids and pressed lips stay clean (sim.smoothness): on the default face and on a coarse
transferred head, the lid margins keep their order along the closed lid and meet along the lid
line, no lid triangle folds over, and the lips press (AU23, AU24) without zig-zags or folds.
The lips are closed at rest."""

from __future__ import annotations

import numpy as np
import pytest
from coarse_head import coarse_head_model

from sim import expression_targets as et
from sim import smoothness as sm
from sim.build import FaceModel, default_model
from sim.integrator import Simulator

LID_GAP_CM = 0.1  # closed lids meet within 1 mm over the middle 60 % of the lid line
LIP_ZIGZAG_CM = 0.1  # a lip vertex stands at most 1 mm off its neighbours' midpoint


@pytest.fixture(scope="module", params=["default", "coarse head"])
def face(request) -> FaceModel:
    return default_model(0) if request.param == "default" else coarse_head_model()


def _pose(model: FaceModel, pose: str) -> np.ndarray:
    sim = Simulator(model, wrinkles=False)
    state = model.rest_state()
    sim.settle(state, et.pose_control(pose), max_seconds=3.0)
    assert not sim.guard_events
    return state.positions


def test_closed_lids_meet_in_order_without_folds(face: FaceModel) -> None:
    pos = _pose(face, "AU45")
    rows = sm.margin_rows(face.mesh)
    for s in "lr":
        upper, lower = rows[f"eye_{s}_upper"], rows[f"eye_{s}_lower"]
        tris = face.triangles[sm.near_triangles(face.mesh, [upper, lower], 1)]
        assert sm.out_of_order(face.rest, pos, upper) == 0 and sm.out_of_order(face.rest, pos, lower) == 0
        assert sm.folded(face.rest, pos, tris) == 0
        assert sm.meeting_gap(pos, upper, lower, inner=0.6) < LID_GAP_CM
        assert sm.meeting_gap(face.rest, upper, lower, inner=0.6) > 5 * LID_GAP_CM  # open at rest


@pytest.mark.parametrize("pose", ["AU23", "AU24"])
def test_pressed_lips_stay_smooth(face: FaceModel, pose: str) -> None:
    pos = _pose(face, pose)
    rows = sm.margin_rows(face.mesh)
    lips = [rows["lip_upper"], rows["lip_lower"]]
    tris = face.triangles[sm.near_triangles(face.mesh, lips, 1)]
    assert sm.folded(face.rest, pos, tris) == 0
    for row in lips:
        assert sm.out_of_order(face.rest, pos, row) == 0
        assert sm.zigzag(pos, row) < LIP_ZIGZAG_CM
    moved = np.abs(pos[np.concatenate(lips)] - face.rest[np.concatenate(lips)]).max()
    assert moved > 0.1  # the lips did press (so the checks above can fail)


def test_lips_closed_at_rest(face: FaceModel) -> None:
    rows = sm.margin_rows(face.mesh)
    assert sm.meeting_gap(face.rest, rows["lip_upper"], rows["lip_lower"], inner=0.9) < 0.15
