"""The rest pose is an equilibrium with gravity on: the tether targets carry each vertex's weight
(`sim.build.gravity_offsets`), so an unactivated face stays in its rest shape; gravity still pulls."""

from __future__ import annotations

import numpy as np
import pytest
from coarse_head import coarse_head_model

from sim.build import FaceModel, SkinParams, compile_model
from sim.integrator import Simulator
from sim.state import FaceControl

TOLERANCE_CM = 0.005  # 0.05 mm


def _rest_drift(model: FaceModel, seconds: float = 1.0, method: str = "auto") -> float:
    sim = Simulator(model, wrinkles=False, method=method)
    state = model.rest_state()
    for _ in range(int(seconds * 60)):
        sim.step(state, FaceControl())
    assert not sim.guard_events
    return float(np.abs(state.positions - model.rest).max())


@pytest.fixture(scope="module")
def default_rig0():
    from sim.face import default_rig

    return default_rig(0)


@pytest.mark.parametrize("method", ["rk2", "implicit"])
def test_default_face_rests_in_its_rest_shape_under_gravity(default_rig0, method) -> None:
    model = compile_model(default_rig0)
    assert model.params.gravity and np.abs(model.weight).max() > 0
    assert _rest_drift(model, method=method) < TOLERANCE_CM


def test_transferred_coarse_head_rests_in_its_rest_shape() -> None:
    assert _rest_drift(coarse_head_model()) < TOLERANCE_CM


def test_gravity_still_acts(default_rig0) -> None:
    """Without the balance the face sags (so the test above can fail), and with it gravity still
    acts on an opened jaw's skin: the offsets turn with the jaw, the weight does not."""
    unbalanced = compile_model(default_rig0, SkinParams(gravity_balanced=False))
    assert _rest_drift(unbalanced) > 0.05
    on, off = compile_model(default_rig0), compile_model(default_rig0, SkinParams(gravity=False))
    poses = []
    for model in (on, off):
        sim = Simulator(model, wrinkles=False)
        state, control = model.rest_state(), FaceControl()
        control.set("jaw", 1.0)
        sim.settle(state, control, max_seconds=2.0)
        poses.append(state.positions.copy())
    assert np.abs(poses[0] - poses[1]).max() > 0.005
