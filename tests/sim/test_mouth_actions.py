"""The mouth's, cheeks' and jaw's further actions, settled on the procedural face: each moves the
landmarks it is named for the way faces do, and at zero changes nothing."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face import default_model
from sim.integrator import Simulator
from sim.state import FaceControl


def _settled(values: dict[str, float], seconds: float = 2.0) -> np.ndarray:
    model = default_model(0)
    sim, state, c = Simulator(model), model.rest_state(), FaceControl()
    for k, v in values.items():
        c.set(k, v)
    sim.settle(state, c, seconds)
    return (state.positions - model.rest) * 10.0  # mm


def _at(d: np.ndarray, name: str) -> np.ndarray:
    return d[default_model(0).mesh.landmarks[name]]


@pytest.fixture(scope="module")
def moves() -> dict[str, np.ndarray]:
    return {name: _settled(values) for name, values in {
        "pucker": {"incisivus": 1.0},
        "funnel": {"orbicularis_oris_peripheralis_upper": 1.0, "orbicularis_oris_peripheralis_lower": 1.0},
        "shrug": {"orbicularis_oris_peripheralis_upper": 1.0},
        "roll": {"orbicularis_oris_marginalis_upper": 1.0, "orbicularis_oris_marginalis_lower": 1.0},
        "left": {"mouth_shift_l": 1.0},
        "right": {"mouth_shift_r": 1.0},
        "puff": {"cheek_puff": 1.0},
        "thrust": {"jaw_forward": 1.0},
        "jaw_left": {"jaw_sideways": 1.0},
        "open": {"jaw": 0.2},
        "open_closed": {"jaw": 0.2, "lip_closure": 1.0},
        "platysma_l": {"platysma_l": 1.0},
    }.items()}


def test_pucker_draws_the_corners_in_and_the_lips_forward(moves: dict[str, np.ndarray]) -> None:
    d = moves["pucker"]
    assert _at(d, "mouth_corner_l")[0] < -3.0 and _at(d, "mouth_corner_r")[0] > 3.0  # narrower mouth
    assert _at(d, "upper_lip_center")[2] > 3.0 and _at(d, "lower_lip_center")[2] > 1.0  # lips forward


def test_funnel_everts_both_lips_and_the_shrug_only_the_upper(moves: dict[str, np.ndarray]) -> None:
    f, s = moves["funnel"], moves["shrug"]
    up, low = _at(f, "upper_lip_center"), _at(f, "lower_lip_center")
    assert up[2] > 3.0 and low[2] > 3.0 and up[1] - low[1] > 3.0  # forward, and turned apart
    assert _at(s, "upper_lip_center")[1] > 2.0 and _at(s, "upper_lip_center")[2] > 3.0
    assert _at(s, "upper_lip_center")[1] - _at(s, "lower_lip_center")[1] > 1.0


def test_lip_suck_rolls_the_lips_in(moves: dict[str, np.ndarray]) -> None:
    d = moves["roll"]
    assert _at(d, "upper_lip_center")[2] < -2.0 and _at(d, "lower_lip_center")[2] < -2.0


def test_mouth_left_and_right_move_the_lips_sideways(moves: dict[str, np.ndarray]) -> None:
    for side, sign in (("left", 1.0), ("right", -1.0)):
        d = moves[side]
        for lm in ("upper_lip_center", "lower_lip_center"):
            assert sign * _at(d, lm)[0] > 3.0  # towards the face's own side (+X is its left)
        assert abs(_at(d, "chin")[0]) < 1.0  # the jaw stays


def test_cheek_puff_pushes_the_cheeks_out(moves: dict[str, np.ndarray]) -> None:
    model = default_model(0)
    d = moves["puff"]
    out = np.einsum("ij,ij->i", d, model.rest_normal)
    cheeks = model.mesh.regions["cheek_l"] | model.mesh.regions["cheek_r"]
    assert out[cheeks].max() > 5.0 and out.min() > -2.0  # outward along the normal, nothing sucked in
    assert abs(_at(d, "nose_tip")).max() < 0.5


def test_jaw_thrust_and_sideways_move_the_chin(moves: dict[str, np.ndarray]) -> None:
    assert _at(moves["thrust"], "chin")[2] > 5.0
    assert _at(moves["jaw_left"], "chin")[0] > 5.0
    assert abs(_at(moves["thrust"], "upper_lip_center")).max() < 1.0  # the maxilla stays


def test_the_platysma_draws_the_jowl_out_and_the_skin_under_the_chin_down(moves: dict[str, np.ndarray]) -> None:
    """AU21 on one side (platysma_l): the skin under the chin on that side goes down towards the
    chest, the jowl over the jaw's body out, the other side's jowl and the lips hardly move."""
    model = default_model(0)
    d, rest = moves["platysma_l"], model.rest
    chin = rest[model.mesh.landmarks["chin"]]
    under = (rest[:, 1] < chin[1] - 0.5) & (rest[:, 0] > 0.0) & (rest[:, 0] < 2.5)
    assert under.sum() >= 3 and d[under, 1].mean() < -3.0
    jowl = (rest[:, 1] < chin[1] + 3.5) & (rest[:, 1] > chin[1] + 1.5) & (np.abs(rest[:, 0]) > 4.0)
    left, right = jowl & (rest[:, 0] > 0), jowl & (rest[:, 0] < 0)
    assert left.sum() >= 2 and d[left, 0].max() > 0.5  # out (+X is the face's left)
    assert np.abs(d[right]).max() < 0.1
    assert np.abs(_at(d, "upper_lip_center")).max() < 0.5 and np.abs(_at(d, "mouth_corner_r")).max() < 0.5


def test_lips_meet_over_an_open_jaw(moves: dict[str, np.ndarray]) -> None:
    model = default_model(0)
    gap = lambda d: (model.rest[model.mesh.landmarks["upper_lip_center"]][1] + _at(d, "upper_lip_center")[1] / 10
                     - model.rest[model.mesh.landmarks["lower_lip_center"]][1] - _at(d, "lower_lip_center")[1] / 10)
    assert gap(moves["open_closed"]) < 0.6 * gap(moves["open"])  # the opening between the lips shrinks
    assert abs(_at(moves["open_closed"], "chin")[1] - _at(moves["open"], "chin")[1]) < 1.0  # the jaw stays open


def test_each_new_action_has_a_force_and_none_at_zero() -> None:
    model = default_model(0)
    names = list(model.channels and [c.name for c in model.channels])
    for ch in ("incisivus", "orbicularis_oris_peripheralis_upper", "orbicularis_oris_peripheralis_lower",
               "orbicularis_oris_marginalis_upper", "orbicularis_oris_marginalis_lower", "lip_closure",
               "mouth_shift_l", "mouth_shift_r", "cheek_puff", "platysma_l", "platysma_r"):
        assert model.muscle_matrix[:, names.index(ch)].nnz > 0, ch
    still = _settled({"tongue_out": 1.0, "jaw_forward": 0.0, "jaw_sideways": 0.0}, seconds=0.2)
    assert np.abs(still).max() < 1e-9  # the procedural face has no tongue: tongue_out moves no skin
