"""The integrator: rest stays rest, symmetry, release, bounds, the guard, determinism, substeps."""

from __future__ import annotations

import numpy as np
import pytest

from sim.build import FaceModel, SkinParams, compile_model
from sim.channels import CHANNEL_SPECS
from sim.integrator import Simulator, stable_step
from sim.model import FaceRig
from sim.state import FaceControl


def _run(model: FaceModel, control: FaceControl, seconds: float) -> tuple[Simulator, np.ndarray]:
    sim = Simulator(model)
    state = model.rest_state()
    for _ in range(int(round(seconds * 60))):
        sim.step(state, control)
    return sim, state.positions.copy()


def _mirror_partner(rest: np.ndarray) -> np.ndarray:
    flipped = rest * np.array([-1.0, 1.0, 1.0])
    d = ((rest[:, None, :] - flipped[None, :, :]) ** 2).sum(-1)
    partner = np.argmin(d, axis=0)
    assert np.allclose(rest[partner], flipped, atol=1e-9)
    return partner


def test_no_activation_keeps_rest_without_gravity(synth_model_nograv: FaceModel) -> None:
    _, pos = _run(synth_model_nograv, FaceControl(), 1.0)
    assert np.abs(pos - synth_model_nograv.rest).max() < 1e-9


def test_gravity_sags_a_little_and_stays_bounded(synth_rig) -> None:
    """Without the rest pose's gravity balance (test_rest_equilibrium.py has it on)."""
    synth_model = compile_model(synth_rig, SkinParams(gravity_balanced=False))
    sim, pos = _run(synth_model, FaceControl(), 1.0)
    disp = pos - synth_model.rest
    assert disp[:, 1].mean() < -0.01  # it does sag
    assert np.abs(disp).max() < 0.3  # but less than 3 mm
    state = synth_model.rest_state()
    state.positions[...] = pos
    for _ in range(60):
        sim.step(state, FaceControl())
    assert np.abs(state.positions - pos).max() < 1e-3  # settled, not drifting


def test_symmetric_activation_gives_mirror_motion(synth_model_nograv: FaceModel) -> None:
    c = FaceControl()
    for name in ("zygomaticus_major", "frontalis_inner", "corrugator", "depressor_anguli_oris"):
        c.set(f"{name}_l", 0.8)
        c.set(f"{name}_r", 0.8)
    c.set("orbicularis_oris", 0.5)
    c.set("jaw", 0.4)
    _, pos = _run(synth_model_nograv, c, 0.5)
    partner = _mirror_partner(synth_model_nograv.rest)
    mirrored = pos[partner] * np.array([-1.0, 1.0, 1.0])
    assert np.abs(pos - synth_model_nograv.rest).max() > 0.2
    assert np.abs(pos - mirrored).max() < 1e-6


def test_releasing_every_muscle_returns_to_rest(synth_model_nograv: FaceModel) -> None:
    m = synth_model_nograv
    sim = Simulator(m)
    state = m.rest_state()
    c = FaceControl()
    for spec in CHANNEL_SPECS:
        if spec.kind in ("muscle", "jaw"):
            c.set(spec.name, 0.7)
    for _ in range(30):
        sim.step(state, c)
    assert np.abs(state.positions - m.rest).max() > 0.3
    sim.settle(state, FaceControl(), max_seconds=3.0)
    assert np.abs(state.positions - m.rest).max() < 1e-3


def test_all_channels_full_for_ten_seconds_stay_finite_and_bounded(synth_model: FaceModel) -> None:
    c = FaceControl()
    for spec in CHANNEL_SPECS:
        c.set(spec.name, spec.hi)
    sim, pos = _run(synth_model, c, 10.0)
    assert np.all(np.isfinite(pos)) and not sim.guard_events
    assert np.abs(pos - synth_model.rest).max() < 5.0  # the open jaw moves the chin ~3.5 cm


@pytest.mark.parametrize("method", ["rk2", "implicit"])
def test_guard_restores_after_injected_nan(synth_model: FaceModel, method: str) -> None:
    sim = Simulator(synth_model, method=method)
    state = synth_model.rest_state()
    c = FaceControl()
    c.set("zygomaticus_major_l", 1.0)
    for _ in range(5):
        sim.step(state, c)
    good = state.positions.copy()
    free = int(np.flatnonzero(~synth_model.held)[0])
    state.velocities[free] = np.nan
    sim.step(state, c)
    assert len(sim.guard_events) == 1 and "non-finite" in sim.guard_events[0].reason
    assert np.array_equal(state.positions, good) and np.all(state.velocities == 0.0)
    sim.step(state, c)  # and it carries on
    assert np.all(np.isfinite(state.positions)) and len(sim.guard_events) == 1


@pytest.mark.parametrize("method", ["rk2", "implicit"])
def test_guard_catches_a_blow_up(synth_model: FaceModel, method: str) -> None:
    sim = Simulator(synth_model, method=method)
    state = synth_model.rest_state()
    start = state.positions.copy()
    free = int(np.flatnonzero(~synth_model.held)[0])
    state.velocities[free] = [0.0, 0.0, 1e6]  # a kick far beyond anything a face does
    sim.step(state, FaceControl())
    assert sim.guard_events and "displacement" in sim.guard_events[0].reason
    assert np.array_equal(state.positions, start)


def test_same_inputs_give_bit_identical_positions(synth_rig: FaceRig) -> None:
    runs = []
    for _ in range(2):
        model = compile_model(synth_rig)
        c = FaceControl()
        c.set("zygomaticus_major_l", 0.9)
        c.set("jaw", 0.3)
        _, pos = _run(model, c, 0.3)
        runs.append(pos)
    assert runs[0].tobytes() == runs[1].tobytes()


def test_substeps_come_from_the_stability_bound(synth_model_nograv: FaceModel) -> None:
    sim = Simulator(synth_model_nograv)
    assert sim.substeps > 1 and sim.dt <= sim.stable_dt
    # a third of the derived substeps is beyond the bound: the explicit step blows up and the guard
    # catches it; the derived count keeps the same kick well behaved
    for substeps, should_fail in ((max(1, sim.substeps // 3), True), (sim.substeps, False)):
        s = Simulator(synth_model_nograv)
        s.substeps, s.dt = substeps, s.frame_dt / substeps
        state = synth_model_nograv.rest_state()
        rng = np.random.default_rng(1)
        state.positions += rng.normal(0.0, 0.01, state.positions.shape) * (~synth_model_nograv.held)[:, None]
        for _ in range(120):
            s.step(state, FaceControl())
        assert bool(s.guard_events) == should_fail


def test_stable_step_matches_the_rk2_real_axis_limit() -> None:
    # an overdamped mode with one fast real eigenvalue -lambda: RK2 is stable for h <= 2 / lambda
    omega = 100.0
    h = stable_step(omega, mass_rate=0.0, visc=0.0, high_ratio=1.0)
    assert h < 0.01 / omega  # undamped oscillators: RK2 amplifies them at any real step
    h = stable_step(omega, mass_rate=0.0, visc=2.0 / omega, high_ratio=1.0)
    assert 0.9 / omega < h <= 2.0 / omega + 1e-9


def test_pass_through_channels_reach_the_state(synth_model: FaceModel) -> None:
    sim = Simulator(synth_model)
    state = synth_model.rest_state()
    c = FaceControl()
    c.set("eyes_yaw", 0.5)
    c.set("eyes_pitch", -0.25)
    c.set("age", 71.0)
    sim.step(state, c)
    assert (state.eye_yaw, state.eye_pitch, state.age) == (0.5, -0.25, 71.0)
    assert state.time == pytest.approx(1 / 60)
    assert np.array_equal(state.surface, state.positions)


def test_gravity_switch(synth_rig: FaceRig) -> None:
    on = compile_model(synth_rig, SkinParams(gravity=True))
    off = compile_model(synth_rig, SkinParams(gravity=False))
    assert on.hash != off.hash
    assert on.gravity[1] < 0 and off.gravity[1] == 0


def test_skin_never_passes_through_the_eyeballs(face_model: FaceModel) -> None:
    m = face_model
    c = FaceControl()
    for name in ("orbicularis_oculi_lid_l", "orbicularis_oculi_lid_r", "orbicularis_oculi_l",
                 "frontalis_inner_r", "corrugator_l"):
        c.set(name, 1.0)
    sim = Simulator(m, wrinkles=False)
    state = m.rest_state()
    assert len(m.eye_contact) > 20
    for _ in range(60):
        sim.step(state, c)
        for k in range(2):
            d = np.linalg.norm(state.positions[m.eye_contact] - m.mesh.eye_centers[k], axis=1)
            assert d.min() >= m.eye_contact_radius - 1e-9


@pytest.mark.parametrize("method", ["rk2", "implicit"])
def test_default_face_all_channels_full_ten_seconds(face_model: FaceModel, method: str) -> None:
    c = FaceControl()
    for spec in CHANNEL_SPECS:
        c.set(spec.name, spec.hi)
    sim = Simulator(face_model, wrinkles=False, method=method)
    state = face_model.rest_state()
    for _ in range(600):
        sim.step(state, c)
    disp = np.linalg.norm(state.positions - face_model.rest, axis=1)
    assert np.all(np.isfinite(state.positions)) and not sim.guard_events
    assert 1.0 < disp.max() < 5.0  # the open jaw moves the chin ~3.5 cm


def test_default_face_survives_every_channel_slammed_between_its_ends(face_model: FaceModel) -> None:
    # the derived substeps under the harshest input a performer can give: every channel jumps
    # between its two ends three times a second, for ten seconds. (With this stress the default
    # face first blows up at 9 substeps; the derived count is 13.)
    sim = Simulator(face_model, wrinkles=False, method="rk2")
    assert sim.substeps >= 12
    state = face_model.rest_state()
    rng = np.random.default_rng(1)
    c = FaceControl()
    speed = 0.0
    for k in range(600):
        if k % 20 == 0:
            for spec in CHANNEL_SPECS:
                c.set(spec.name, float(rng.choice([spec.lo, spec.hi])))
        sim.step(state, c)
        speed = max(speed, float(np.sqrt((state.velocities**2).sum(axis=1)).max()))
    assert not sim.guard_events and np.all(np.isfinite(state.positions))
    assert speed < 500.0  # cm/s: the jaw snapping open is ~180; a blow-up is thousands


def test_a_moving_jaws_compiled_turn_gives_the_bits_of_its_numpy_expression() -> None:
    """The jaw's frame constants (eq 9's target, the turned rest shape, the support normals) are
    computed by a compiled pass every tick the jaw moves; a take replays only if they carry the
    exact bits of the row-by-row numpy expression they stand for, at every jaw pose."""
    from sim.face import default_rig
    from sim.integrator import jaw_motion
    from sim.rowmath import times3

    m = compile_model(default_rig(0))
    s = Simulator(m, 1.0 / 120.0, wrinkles=False)
    rng = np.random.default_rng(7)
    for k in range(12):
        pose = (float(rng.uniform(0.0, 1.0)), float(rng.uniform(0.0, 1.0)) * (k % 2),
                float(rng.uniform(-1.0, 1.0)) * (k % 3 == 0))
        rot, slide = jaw_motion(m, *pose)
        w = m.jaw_weight[:, None]
        turned = times3(m.rest - m.jaw_pivot, rot.T) + m.jaw_pivot
        base = m.rest + m.rest_offset
        target = base + w * (turned + times3(m.rest_offset, rot.T) + slide - base)
        shape = m.rest + w * (turned + slide - m.rest)
        n = m.rest_normal + w * (times3(m.rest_normal, rot.T) - m.rest_normal)
        got_target, got_shape, _ = s._jaw_turned(pose, shape=True)
        s._jaw = None
        s._set_jaw(pose)
        assert got_target.tobytes() == target.tobytes()
        assert got_shape is not None and got_shape.tobytes() == shape.tobytes()
        assert s._normal.tobytes() == (n / np.linalg.norm(n, axis=1)[:, None]).tobytes()
        assert not np.array_equal(got_target, base)  # the jaw did move the skin it carries


def test_the_guard_measured_in_two_parts_is_the_whole_measure() -> None:
    """The implicit step measures the free nodes' distance from the target while they are in the
    caches (`sim.implicit._free_deviation`) and the guard completes it over the held nodes
    (`_held_deviation`): the same answer as the measure over every row, a coordinate that is not
    finite anywhere giving -1."""
    from sim.implicit import _free_deviation
    from sim.integrator import _held_deviation, _max_deviation

    rng = np.random.default_rng(2)
    held = np.zeros(50, dtype=bool)
    held[rng.choice(50, 12, replace=False)] = True
    free, fixed = np.flatnonzero(~held), np.flatnonzero(held)
    for bad in (None, 0.0, np.inf, -np.inf, np.nan):
        for row in (int(free[3]), int(fixed[2])):
            x, target = rng.normal(0.0, 1.0, (50, 3)), rng.normal(0.0, 1.0, (50, 3))
            x[int(fixed[5]), 1] += 9.0  # the largest distance on a held node
            if bad is not None:
                x[row, 2] = bad
            whole = _max_deviation(x, target)
            assert _held_deviation(x, fixed, target, _free_deviation(x, free, target)) == whole, (bad, row)
            if bad is not None and not np.isfinite(bad):
                assert whole == -1.0


def test_save_hold_keeps_the_start_and_holds_like_the_copy_and_hold() -> None:
    """The step's start kept for the guard's restore and the held nodes put on their targets in
    one kernel give the values of numpy's copy followed by `_hold`, and the kept copy is the
    positions from before the hold (a restore returns to them)."""
    from sim.integrator import _hold, _save_hold

    rng = np.random.default_rng(7)
    x, v, target = rng.normal(size=(50, 3)), rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    held = np.array([0, 7, 8, 49], dtype=np.int64)
    x1, v1, saved1 = x.copy(), v.copy(), np.zeros((50, 3))
    np.copyto(saved1, x1)
    _hold(x1, v1, held, target)
    x2, v2, saved2 = x.copy(), v.copy(), np.zeros((50, 3))
    _save_hold(x2, v2, held, target, saved2)
    assert x2.tobytes() == x1.tobytes() and v2.tobytes() == v1.tobytes()
    assert saved2.tobytes() == x.tobytes()
    assert np.array_equal(x2[held], target[held]) and not v2[held].any()
