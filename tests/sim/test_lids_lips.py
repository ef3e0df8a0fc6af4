"""Closed lids and pressed lips stay clean (sim.smoothness): on the default face at each resolution
and on a coarse transferred head, the lid margins keep their order along the closed lid and meet
along the lid line (inner corner included) without passing each other, no lid triangle folds
over, and the lips press (AU23, AU24) without zig-zags, folds or passing each other. The lips are
closed at rest.

Resolutions 1 and 2 run the implicit integrator (as the live code does), with its own lid and lip
contact solved inside the step, and the margin rows' bending term (sim.margin_contact): without them
the upper margin next to the inner canthus went out of order and folded, the skin behind a stopped
margin rolled past it, and pressed lips buckled into a ~1 mm zig-zag there."""

from __future__ import annotations

import numpy as np
import pytest
from coarse_head import coarse_head_model

from sim.face import targets as et
from sim import smoothness as sm
from sim.build import FaceModel
from sim.face import default_model
from sim.integrator import Simulator

LID_GAP_CM = 0.1  # closed lids meet within 1 mm (open or overlapping) over the middle 90 % of the lid line
LIP_ZIGZAG_CM = 0.1  # a lip vertex stands at most 1 mm off its neighbours' midpoint
CROSS_CM = 0.05  # one margin passes the other by at most 0.5 mm
POSES = ("AU45", "AU23", "AU24")


@pytest.fixture(scope="module", params=["coarse head", 0, 1, 2])
def face(request) -> tuple[FaceModel, dict[str, np.ndarray]]:
    """The face and its settled poses (one settle per pose, shared by the tests)."""
    model = coarse_head_model() if request.param == "coarse head" else default_model(request.param)
    poses = {}
    for pose in POSES:
        sim = Simulator(model, wrinkles=False)
        state = model.rest_state()
        sim.settle(state, et.pose_control(pose), max_seconds=3.0)
        assert not sim.guard_events
        poses[pose] = state.positions.copy()
    return model, poses


def _crossing(pos: np.ndarray, upper: np.ndarray, lower: np.ndarray) -> float:
    """How far (cm) the upper margin has passed below the lower one at its worst (0 if nowhere)."""
    order = np.argsort(pos[lower, 0])
    below = np.interp(pos[upper, 0], pos[lower, 0][order], pos[lower, 1][order]) - pos[upper, 1]
    return float(max(below[1:-1].max(), 0.0))


def test_closed_lids_meet_in_order_without_folds(face) -> None:
    model, poses = face
    pos = poses["AU45"]
    rows = sm.margin_rows(model.mesh)
    for s in "lr":
        upper, lower = rows[f"eye_{s}_upper"], rows[f"eye_{s}_lower"]
        tris = model.triangles[sm.near_triangles(model.mesh, [upper, lower], 1)]
        assert sm.out_of_order(model.rest, pos, upper) == 0 and sm.out_of_order(model.rest, pos, lower) == 0
        assert sm.folded(model.rest, pos, tris) == 0
        assert sm.meeting_gap(pos, upper, lower, inner=0.9) < LID_GAP_CM
        assert _crossing(pos, upper, lower) < CROSS_CM
        assert sm.meeting_gap(model.rest, upper, lower, inner=0.6) > 5 * LID_GAP_CM  # open at rest


@pytest.mark.parametrize("pose", ["AU23", "AU24"])
def test_pressed_lips_stay_smooth(face, pose: str) -> None:
    model, poses = face
    pos = poses[pose]
    rows = sm.margin_rows(model.mesh)
    lips = [rows["lip_upper"], rows["lip_lower"]]
    tris = model.triangles[sm.near_triangles(model.mesh, lips, 1)]
    assert sm.folded(model.rest, pos, tris) == 0
    for row in lips:
        assert sm.out_of_order(model.rest, pos, row) == 0
        assert sm.zigzag(pos, row) < LIP_ZIGZAG_CM
    rest_cross = _crossing(model.rest, *lips)
    assert _crossing(pos, *lips) < rest_cross + CROSS_CM
    moved = np.abs(pos[np.concatenate(lips)] - model.rest[np.concatenate(lips)]).max()
    assert moved > 0.1  # the lips did press (so the checks above can fail)


def test_lips_closed_at_rest(face) -> None:
    model, _ = face
    rows = sm.margin_rows(model.mesh)
    assert sm.meeting_gap(model.rest, rows["lip_upper"], rows["lip_lower"], inner=0.9) < 0.15
