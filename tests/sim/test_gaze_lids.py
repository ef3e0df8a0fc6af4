"""The lids carried by the turning eye (`sim.gaze_lids`): on the scanned head and the procedural
face a sideways look carries the lids a couple of millimetres towards the side looked to and
leaves the brows' and mouth's skin where it was, the scanned head's skin then moves closer to the
scan's own look aside than without, and a still gaze leaves every step's bits as they were. The
coupling is measured alone here: the tissue round the globe fitted on top of it (the rig's `gaze`)
is off, and `test_gaze_tissue.py` holds the two together to the scan's looks."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face.scan.anatomy import skin_layout
from sim.face.scan.data import scan_data
from sim.face.scan.rig import scan_model
from sim.facs import apply_expression
from sim.integrator import Simulator
from sim.state import FaceControl


@pytest.fixture(scope="module")
def ict():  # type: ignore[no-untyped-def]
    return scan_model()


def _settled(model, values: dict[str, float], follow: bool = True) -> np.ndarray:  # type: ignore[no-untyped-def]
    sim = Simulator(model, wrinkles=False)
    sim.lids_follow_gaze = follow
    sim.gaze_tissue = False
    c = FaceControl(model)
    for name, v in values.items():
        c.set(name, v)
    state = model.rest_state()
    sim.settle(state, c, max_seconds=2.0)
    assert not sim.guard_events
    return state.positions.copy()


def _lids_follow(model) -> None:  # type: ignore[no-untyped-def]
    rest = _settled(model, {})
    lm = model.mesh.landmarks
    for yaw in (1.0, -1.0):
        d = _settled(model, {"eyes_yaw": yaw}) - rest
        lids = ("upper_lid_l", "upper_lid_r", "lower_lid_l", "lower_lid_r")
        for lid in lids:
            # towards the side looked to (+X is the face's left), about as far as the cornea carries
            # a lid margin (~2 mm at 30 degrees)
            assert 0.05 < yaw * d[lm[lid], 0] < 0.45, (lid, yaw, d[lm[lid]])
        least = min(abs(d[lm[lid], 0]) for lid in lids)
        for far in ("mouth_corner_l", "mouth_corner_r", "chin", "forehead_center"):
            assert np.linalg.norm(d[lm[far]]) < 0.2 * least, far  # (the forehead: 0.1 of it on the scan)
    for pitch in (1.0, -1.0):
        d = _settled(model, {"eyes_pitch": pitch}) - rest
        for lid in ("upper_lid_l", "lower_lid_l"):
            assert pitch * d[lm[lid], 1] > 0.05, (lid, pitch)


def test_a_sideways_look_carries_the_scanned_heads_lids(ict) -> None:  # type: ignore[no-untyped-def]
    _lids_follow(ict)


def test_a_sideways_look_carries_the_procedural_faces_lids(face_model) -> None:  # type: ignore[no-untyped-def]
    _lids_follow(face_model)


def test_the_scanned_look_aside_is_matched_closer(ict) -> None:  # type: ignore[no-untyped-def]
    """Both eyes looking towards the face's left (the scan's eyeLookOut_L with eyeLookIn_R) against
    the settled skin at eyes_yaw = 1: relative RMS error (1 = as wrong as not moving)."""
    data, skin = scan_data(), skin_layout().vertices
    target = (data.expression("eyeLookOut_L") + data.expression("eyeLookIn_R"))[skin]
    rest = _settled(ict, {})

    def rel(follow: bool) -> float:
        u = _settled(ict, {"eyes_yaw": 1.0}, follow) - rest
        return float(np.sqrt(np.sum((u - target) ** 2) / np.sum(target ** 2)))

    assert rel(False) > 0.99  # the lids still: nothing moves
    assert rel(True) < 0.7  # measured 0.55


def test_a_still_gaze_leaves_the_steps_bits(face_model) -> None:  # type: ignore[no-untyped-def]
    """What a take recorded before the lids followed the gaze needs: at gaze 0 the same bits with
    the coupling on and off; turned, they differ."""
    c = FaceControl(face_model)
    apply_expression(c, "surprise")
    out = {}
    for follow in (True, False):
        for yaw in (0.0, 0.6):
            sim = Simulator(face_model, wrinkles=False, method="implicit")
            sim.lids_follow_gaze = follow
            c.set("eyes_yaw", yaw)
            state = face_model.rest_state()
            for _ in range(20):
                sim.step(state, c)
            out[follow, yaw] = state.positions.copy()
    assert np.array_equal(out[True, 0.0], out[False, 0.0])
    assert not np.array_equal(out[True, 0.6], out[False, 0.6])


def test_one_eye_turned_alone_carries_its_own_lids(ict) -> None:  # type: ignore[no-untyped-def]
    """The vergence turns the eyes apart: the left eye looking out (yaw 0.5, vergence -0.5: the
    left eye turned fully, the right one not at all) carries the left lids and leaves the right."""
    from sim.gaze_lids import eye_yaws

    assert eye_yaws(0.5, -0.5) == (1.0, 0.0)
    lm = ict.mesh.landmarks
    d = _settled(ict, {"eyes_yaw": 0.5, "eyes_vergence": -0.5}) - _settled(ict, {})
    left = min(d[lm[k], 0] for k in ("upper_lid_l", "lower_lid_l"))
    assert left > 0.05
    for k in ("upper_lid_r", "lower_lid_r"):
        assert abs(d[lm[k], 0]) < 0.2 * left, k


def test_the_eyes_pull_is_its_fixed_fields_times_the_gazes_coefficients(ict) -> None:  # type: ignore[no-untyped-def]
    """What the implicit step adds as responses (`basis_fields` x `basis_coefficients`) is the pull
    of the turned eyes itself, for any gaze."""
    from sim.gaze_lids import basis_coefficients, basis_fields, coupling, gaze_forces

    rest = np.asarray(ict.rest)
    lids = coupling(rest, ict.area, ict.held, ict.mesh.eye_centers, float(ict.eye_contact_radius))
    fields = basis_fields(rest, *lids, ict.mesh.eye_centers)
    rng = np.random.default_rng(7)
    for gaze in [(1.0, 0.0, 0.0), (0.0, -1.0, 0.0), *rng.uniform(-1, 1, (5, 3))]:
        direct = np.zeros_like(rest)
        gaze_forces(rest, *lids, ict.mesh.eye_centers, *gaze, direct)
        summed = np.tensordot(basis_coefficients(*gaze), fields, axes=1)
        assert np.abs(direct).max() > 1.0
        assert np.abs(summed - direct).max() < 1e-9 * np.abs(direct).max()


def test_the_lids_apart_pull_is_its_fixed_fields_too(ict) -> None:  # type: ignore[no-untyped-def]
    """With the upper and lower lids apart in the sideways turn (`lid_couplings`), the pull the
    explicit step adds is still the sum of the fields the implicit step adds as responses; the turn
    up or down alone pulls as with the lids alike, the turn aside does not."""
    from sim.gaze_lids import basis_coefficients, basis_fields, gaze_forces, lid_couplings

    rest = np.asarray(ict.rest)
    (idx, eye, gain, none), (_, _, apart, pitch_gain) = lid_couplings(ict)
    assert none is None and pitch_gain is gain
    fields = basis_fields(rest, idx, eye, apart, ict.mesh.eye_centers, pitch_gain)
    rng = np.random.default_rng(8)
    for gaze in [(1.0, 0.0, 0.0), (0.0, -1.0, 0.0), *rng.uniform(-1, 1, (5, 3))]:
        direct = np.zeros_like(rest)
        gaze_forces(rest, idx, eye, apart, ict.mesh.eye_centers, *gaze, direct, pitch_gain)
        summed = np.tensordot(basis_coefficients(*gaze), fields, axes=1)
        assert np.abs(direct).max() > 1.0
        assert np.abs(summed - direct).max() < 1e-9 * np.abs(direct).max()
    for gaze, same in (((0.0, 0.7, 0.0), True), ((0.7, 0.0, 0.0), False)):
        alike, split = np.zeros_like(rest), np.zeros_like(rest)
        gaze_forces(rest, idx, eye, gain, ict.mesh.eye_centers, *gaze, alike)
        gaze_forces(rest, idx, eye, apart, ict.mesh.eye_centers, *gaze, split, pitch_gain)
        assert np.allclose(alike, split, rtol=0, atol=1e-9 * np.abs(alike).max()) == same


def test_a_sideways_look_carries_the_upper_lid_further_than_the_lower(ict) -> None:  # type: ignore[no-untyped-def]
    """The upper lid's margin rides the cornea's bulge: with the lids apart a look aside carries
    the upper lid's landmark further than with the lids alike and the lower one less far, and the
    settled skin comes closer to the scan's own look aside (both eyes towards the face's left)."""
    data, skin = scan_data(), skin_layout().vertices
    target = (data.expression("eyeLookOut_L") + data.expression("eyeLookIn_R"))[skin]
    lm = ict.mesh.landmarks
    rest = _settled(ict, {})
    moved = {}
    for apart in (False, True):
        sim = Simulator(ict, wrinkles=False)
        sim.lids_apart = apart
        sim.gaze_tissue = False
        c = FaceControl(ict)
        c.set("eyes_yaw", 1.0)
        state = ict.rest_state()
        sim.settle(state, c, max_seconds=2.0)
        moved[apart] = state.positions - rest
    for side in "lr":
        assert moved[True][lm[f"upper_lid_{side}"], 0] > 1.2 * moved[False][lm[f"upper_lid_{side}"], 0] > 0.0
        assert 0.0 < moved[True][lm[f"lower_lid_{side}"], 0] < moved[False][lm[f"lower_lid_{side}"], 0]

    def rel(u: np.ndarray) -> float:
        return float(np.sqrt(np.sum((u - target) ** 2) / np.sum(target ** 2)))

    assert rel(moved[True]) < rel(moved[False]) - 0.02
