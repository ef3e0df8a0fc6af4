"""The implicit step starts from the state's last jaw opening and skin age and moves the jaw by its
precomputed responses (`Simulator.jaw_responses`): a moved jaw or age takes the prepared step (no
whole step at the input), the jaw moves in the step that takes it, replays keep their bits, and the
face settles where the whole step settles it."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face import default_model
from sim.integrator import Simulator
from sim.state import FaceControl


@pytest.fixture(scope="module")
def model():  # type: ignore[no-untyped-def]
    return default_model(1)  # fine enough for the implicit integrator


def _chin(model) -> np.ndarray:  # type: ignore[no-untyped-def]
    return np.flatnonzero((np.asarray(model.jaw_weight) > 0.5) & ~np.asarray(model.held))


def test_a_moving_jaw_and_age_take_the_step_prepared_ahead_with_the_same_bits(model) -> None:  # type: ignore[no-untyped-def]
    ahead, plain = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    assert ahead.method == "implicit" and ahead.jaw_responses
    c = FaceControl(model)
    s_ahead, s_plain = model.rest_state(), model.rest_state()
    used = 0
    for k in range(40):
        c.set("jaw", 0.3 * (1.0 + np.sin(k / 4.0)))  # moves every tick
        c.set("age", 40.0 + k)
        c.set("zygomaticus_major_l", 0.5)
        ahead.prepare(s_ahead)
        impl = ahead._implicit
        assert impl is not None
        used += impl._is_predicted(s_ahead.positions, s_ahead.velocities, (ahead._jaw, ahead._skin_age))
        ahead.step(s_ahead, c)
        plain.step(s_plain, c)
        assert s_ahead.positions.tobytes() == s_plain.positions.tobytes(), k
        assert s_ahead.velocities.tobytes() == s_plain.velocities.tobytes(), k
    assert used == 40  # every step, the jaw and the age moving included, found its part made ahead


def test_the_jaw_moves_in_the_step_that_takes_it(model) -> None:  # type: ignore[no-untyped-def]
    """One tick opens the jaw: the held chin edge is on the opened jaw's target at once and the free
    chin follows about as far as the whole step moves it."""
    fast, whole = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    whole.jaw_responses = False
    c = FaceControl(model)
    state = model.rest_state()
    fast.settle(state, c, max_seconds=1.0)
    chin, held = _chin(model), np.flatnonzero(model.held)
    c.set("jaw", 0.5)
    moved = {}
    for name, s in (("fast", fast), ("whole", whole)):
        st = state.copy()
        s.step(st, c)
        moved[name] = st.positions - state.positions
        np.testing.assert_array_equal(st.positions[held], s.rest_target(0.5)[held])
    down_fast, down_whole = -moved["fast"][chin, 1].mean(), -moved["whole"][chin, 1].mean()
    assert down_whole > 0.0
    assert 0.85 * down_whole < down_fast < 1.15 * down_whole


def test_the_jaw_as_responses_settles_where_the_whole_step_does(model) -> None:  # type: ignore[no-untyped-def]
    """While the jaw opens the two steps part a little (the step from the last pose sees the held
    edge's springs and the support's normals as they were a tick before); held open, they meet."""
    fast, whole = Simulator(model, 1.0 / 120.0), Simulator(model, 1.0 / 120.0)
    whole.jaw_responses = False
    c = FaceControl(model)
    sf, sw = model.rest_state(), model.rest_state()
    chin = _chin(model)
    worst = 0.0
    for k in range(480):
        c.set("jaw", 0.7 * min(1.0, k / 36))  # opened over 0.3 s, then held
        fast.step(sf, c)
        whole.step(sw, c)
        worst = max(worst, float(np.abs(sf.positions - sw.positions).max()))
    travel = float(np.linalg.norm(sw.positions[chin] - model.rest[chin], axis=1).max())
    assert worst < 0.002 * travel  # under 0.1 mm on a 3.5 cm travel of the chin
    assert np.abs(sf.positions - sw.positions).max() < 1e-5 * travel
