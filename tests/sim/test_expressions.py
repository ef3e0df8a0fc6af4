"""Expression presets, blink and jaw on the procedural default face: each moves the landmarks the way
the expression does (FACS descriptions), clearly (mm to ~1 cm) but boundedly."""

from __future__ import annotations

import numpy as np
import pytest

from sim import facs
from sim.build import FaceModel
from sim.channels import ChannelError
from sim.integrator import Simulator
from sim.state import FaceControl


@pytest.fixture(scope="module")
def poses(face_model: FaceModel) -> dict[str, np.ndarray]:
    """Settled displacement (N,3) for every preset (wrinkles off: only the dynamics matter here)."""
    out = {}
    for name in facs.EXPRESSIONS:
        c = FaceControl()
        facs.apply_expression(c, name, 1.0)
        sim = Simulator(face_model, wrinkles=False)
        state = face_model.rest_state()
        sim.settle(state, c, max_seconds=3.0)
        assert not sim.guard_events
        out[name] = state.positions - face_model.rest
    return out


def _d(model: FaceModel, disp: np.ndarray, name: str) -> np.ndarray:
    return disp[model.mesh.landmarks[name]]


def test_every_preset_is_visible_and_bounded(face_model: FaceModel, poses: dict[str, np.ndarray]) -> None:
    for name, disp in poses.items():
        mag = np.linalg.norm(disp, axis=1)
        assert 0.3 < mag.max() < 2.5, name  # mm to ~1 cm (the open jaw of surprise moves the chin more)


def test_happiness_mouth_corners_up_and_out(face_model: FaceModel, poses: dict[str, np.ndarray]) -> None:
    left, right = (_d(face_model, poses["happiness"], f"mouth_corner_{s}") for s in "lr")
    assert left[1] > 0.3 and right[1] > 0.3
    assert left[0] > 0.2 and right[0] < -0.2  # +X is the face's left


def test_surprise_brows_up(face_model: FaceModel, poses: dict[str, np.ndarray]) -> None:
    for lm in ("brow_inner_l", "brow_inner_r", "brow_mid_l", "brow_outer_r"):
        assert _d(face_model, poses["surprise"], lm)[1] > 0.2, lm
    assert _d(face_model, poses["surprise"], "chin")[1] < -0.5  # AU26 jaw drop


def test_anger_inner_brows_down_and_together(face_model: FaceModel, poses: dict[str, np.ndarray]) -> None:
    left, right = (_d(face_model, poses["anger"], f"brow_inner_{s}") for s in "lr")
    assert left[1] < -0.1 and right[1] < -0.1
    assert left[0] < -0.2 and right[0] > 0.2  # towards the midline


def test_sadness_inner_brows_up_mouth_corners_down(face_model: FaceModel, poses: dict[str, np.ndarray]) -> None:
    for s in "lr":
        assert _d(face_model, poses["sadness"], f"brow_inner_{s}")[1] > 0.1
        assert _d(face_model, poses["sadness"], f"mouth_corner_{s}")[1] < -0.3


def test_disgust_nose_wings_and_upper_lip_up(face_model: FaceModel, poses: dict[str, np.ndarray]) -> None:
    for lm in ("nose_wing_l", "nose_wing_r", "upper_lip_center"):
        assert _d(face_model, poses["disgust"], lm)[1] > 0.3, lm


def test_fear_brows_up_lips_stretched(face_model: FaceModel, poses: dict[str, np.ndarray]) -> None:
    assert _d(face_model, poses["fear"], "brow_inner_l")[1] > 0.1
    assert _d(face_model, poses["fear"], "mouth_corner_l")[0] > 0.2  # AU20 pulls the corners sideways


def test_contempt_moves_one_mouth_corner_only(face_model: FaceModel, poses: dict[str, np.ndarray]) -> None:
    moved = np.linalg.norm(_d(face_model, poses["contempt"], "mouth_corner_r"))
    still = np.linalg.norm(_d(face_model, poses["contempt"], "mouth_corner_l"))
    assert moved > 0.4 and still < 0.2 * moved


def test_blink_closes_the_lids(face_model: FaceModel) -> None:
    m = face_model
    c = FaceControl()
    facs.apply_au(c, "AU45", 1.0)
    sim = Simulator(m, wrinkles=False)
    state = m.rest_state()
    sim.settle(state, c, max_seconds=2.0)
    for s in "lr":
        up, low = m.mesh.landmarks[f"upper_lid_{s}"], m.mesh.landmarks[f"lower_lid_{s}"]
        opening = m.rest[up, 1] - m.rest[low, 1]
        now = state.positions[up, 1] - state.positions[low, 1]
        assert opening > 0.8 and abs(now) < 0.2 * opening  # from ~1 cm to within 2 mm


def test_lid_tightener_raises_the_lower_lid(face_model: FaceModel) -> None:
    """AU7 narrows the eye from below: the lower lid's own palpebral orbicularis lifts it further
    than the lid channel's share alone does."""
    m = face_model
    lifts = []
    for channels in ({"orbicularis_oculi_lid": 0.45}, {"orbicularis_oculi_lid": 0.45, "orbicularis_oculi_lower_lid": 1.0}):
        c = FaceControl()
        for ch, v in channels.items():
            c.set(f"{ch}_l", v)
            c.set(f"{ch}_r", v)
        sim = Simulator(m, wrinkles=False)
        state = m.rest_state()
        sim.settle(state, c, max_seconds=2.0)
        i = m.mesh.landmarks["lower_lid_l"]
        lifts.append(10.0 * (state.positions[i, 1] - m.rest[i, 1]))  # mm
    assert lifts[1] > lifts[0] + 1.0 and lifts[1] > 2.0, lifts


def test_jaw_opens_and_closes(face_model: FaceModel) -> None:
    m = face_model
    sim = Simulator(m, wrinkles=False)
    state = m.rest_state()
    c = FaceControl()
    c.set("jaw", 1.0)
    sim.settle(state, c, max_seconds=2.0)
    chin = m.mesh.landmarks["chin"]
    brow = m.mesh.landmarks["brow_inner_l"]
    drop = m.rest[chin, 1] - state.positions[chin, 1]
    assert 1.5 < drop < 5.0 and abs(state.positions[brow, 1] - m.rest[brow, 1]) < 0.1
    sim.settle(state, FaceControl(), max_seconds=3.0)
    assert np.abs(state.positions - m.rest).max() < 1e-3


def test_facs_names_and_ranges() -> None:
    c = FaceControl()
    facs.apply_au(c, "au12_l", 0.5)
    assert c.get("zygomaticus_major_l") == 0.5 and c.get("zygomaticus_major_r") == 0.0
    facs.apply_au(c, "AU12", 0.3)  # max-combined, never lowers
    assert c.get("zygomaticus_major_l") == 0.5 and c.get("zygomaticus_major_r") == 0.3
    for bad in (lambda: facs.apply_au(c, "AU99", 1), lambda: facs.apply_au(c, "AU12", 1.5),
                lambda: facs.apply_expression(c, "joy"), lambda: c.set("nope", 0.0),
                lambda: c.set("jaw", -0.1)):
        with pytest.raises(ChannelError):
            bad()
    for expr in facs.EXPRESSIONS.values():
        assert all(au in facs.AU_TABLE for au in expr)


def test_the_scanned_head_has_its_own_preset_intensities() -> None:
    """The scanned head's presets push harder where its actions are weaker (fear raises its upper lids
    further); other faces take the shared table; a map's expr: target sets what the preset does."""
    from types import SimpleNamespace

    from puppet.mapping.targets import Vocabulary
    from sim.channels import CHANNEL_SPECS

    scan, shared = FaceControl(), FaceControl()
    facs.apply_expression(scan, "fear", face="ict")
    facs.apply_expression(shared, "fear", face="procedural")
    assert shared.get("levator_palpebrae_l") == pytest.approx(0.8) and scan.get("levator_palpebrae_l") > 0.8
    assert set(facs.expressions_for("ict")) == set(facs.EXPRESSIONS)
    vocab = Vocabulary.from_model(SimpleNamespace(channels=CHANNEL_SPECS, rig=SimpleNamespace(name="ict")))
    for name in facs.EXPRESSIONS:
        want = FaceControl()
        facs.apply_expression(want, name, face="ict")
        got = dict(vocab.resolve(f"expr:{name}").channels)
        moved = {i for i in range(len(want.values)) if want.values[i] != CHANNEL_SPECS[i].default}
        assert set(got) == moved, name
        for i in moved:
            assert got[i] == pytest.approx(want.values[i]), (name, CHANNEL_SPECS[i].name)


def test_an_imported_heads_fear_keeps_the_jaw_shut() -> None:
    """A head without teeth shows a dark hole when the jaw drops (read as surprise): its fear
    raises the lids, draws the brows together and stretches the lips with the jaw shut; a map's
    vocabulary on such a rig (its `presets`, whatever its name) sets the same."""
    from types import SimpleNamespace

    from puppet.mapping.targets import Vocabulary
    from sim.channels import CHANNEL_SPECS

    imported, shared = FaceControl(), FaceControl()
    facs.apply_expression(imported, "fear", face="imported")
    facs.apply_expression(shared, "fear", face="procedural")
    assert imported.get("jaw") == 0.0 < shared.get("jaw")
    assert imported.get("levator_palpebrae_l") > 0.0 and imported.get("risorius_r") > 0.0
    assert imported.get("corrugator_l") > shared.get("corrugator_l")
    rig = SimpleNamespace(name="my head", presets="imported")
    vocab = Vocabulary.from_model(SimpleNamespace(channels=CHANNEL_SPECS, rig=rig))
    assert vocab.expressions["fear"] == facs.expressions_for("imported")["fear"]
