"""The tissue round the globe carried by the turning eye (`FaceRig.gaze`, `sim.gaze_lids.tissue_fields`):
at a full look each eye pulls the skin's tethers by its rig's own field for that look, the implicit
step adds the same pull as responses as the explicit step as forces, the scanned head's look shapes
settle closer to the scan's with it than without, and a still gaze leaves every step's bits as they
were."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face.scan.anatomy import skin_layout
from sim.face.scan.data import scan_data
from sim.face.scan.rig import scan_model
from sim.gaze_lids import add_tissue_forces, tissue_fields
from sim.integrator import Simulator
from sim.state import FaceControl

#: each scanned look (ARKit's shape) and the most its settled skin may miss of the scan's motion
#: with the tissue (relative RMS error): `scan_match.py --no-fit` measured 0.231, 0.294, 0.318,
#: 0.403 with it, 0.425, 0.488, 0.351, 0.440 without
LOOKS = {"eyeLookIn_L": ("EyeLookInLeft", 0.25), "eyeLookOut_L": ("EyeLookOutLeft", 0.31),
         "eyeLookUp_L": ("EyeLookUpLeft", 0.335), "eyeLookDown_L": ("EyeLookDownLeft", 0.42)}


@pytest.fixture(scope="module")
def ict():  # type: ignore[no-untyped-def]
    return scan_model()


def test_a_full_look_pulls_by_the_rigs_own_fields(ict) -> None:  # type: ignore[no-untyped-def]
    """Both eyes turned fully to the face's left: the left eye looks out and the right one in, and
    the tethers pull by k_r (out_l + in_r); fully up, by k_r (up_l + up_r); one eye alone in (the
    other held straight by the vergence), by that eye's field alone."""
    gaze = ict.rig.gaze
    assert sorted(gaze) == sorted(f"{look}_{s}" for s in "lr" for look in ("in", "out", "up", "down"))
    tissue = tissue_fields(ict)
    kr = np.asarray(ict.rest_stiffness)[:, None]
    for turn, want in (((1.0, 0.0, 0.0), gaze["out_l"] + gaze["in_r"]), ((0.0, 1.0, 0.0), gaze["up_l"] + gaze["up_r"]),
                       ((0.0, -1.0, 0.0), gaze["down_l"] + gaze["down_r"]),
                       ((-0.5, 0.0, 0.5), gaze["in_l"])):
        out = np.zeros_like(kr * want)
        add_tissue_forces(tissue, *turn, out)
        assert np.abs(kr * want).max() > 100.0
        assert np.abs(out - kr * want).max() < 1e-9 * np.abs(kr * want).max()


def test_a_turn_part_of_the_way_carries_the_looks_by_their_coefficients(ict) -> None:  # type: ignore[no-untyped-def]
    """Any gaze pulls by the rig's look fields times `look_coefficients` (what the fit of the fields
    assumes), the same forces the basis fields' coefficients give; a still gaze pulls by none."""
    from sim.gaze_lids import look_coefficients

    tissue = tissue_fields(ict)
    kr = np.asarray(ict.rest_stiffness)[:, None]
    rng = np.random.default_rng(3)
    for gaze in [(0.0, 0.0, 0.0), (0.0, 0.5, 0.0), *rng.uniform(-1, 1, (4, 3))]:
        out = np.zeros((len(kr), 3))
        add_tissue_forces(tissue, *gaze, out)
        want = sum(c * kr * ict.rig.gaze[n] for n, c in look_coefficients(*gaze).items())
        assert np.abs(out - want).max() <= 1e-9 * max(np.abs(want).max(), 1e-300)
    half_up = look_coefficients(0.0, 0.5, 0.0)
    assert 0.37 < half_up["up_l"] == half_up["up_r"] < 0.39 and -0.13 < half_up["down_l"] < -0.12


def test_a_face_without_it_has_none() -> None:
    from dataclasses import replace

    from sim.build import compile_model
    from sim.face.scan.rig import RIG_FILE, scan_params
    from sim.rig import load_rig

    model = compile_model(replace(load_rig(RIG_FILE), gaze={}), scan_params())
    assert tissue_fields(model) is None


def _settled(model, values: np.ndarray, tissue: bool = True) -> np.ndarray:  # type: ignore[no-untyped-def]
    sim = Simulator(model, wrinkles=False)
    sim.gaze_tissue = tissue
    c = FaceControl(model)
    c.values[...] = values
    state = model.rest_state()
    sim.settle(state, c, max_seconds=2.0)
    assert not sim.guard_events
    return state.positions - np.asarray(model.rest)


def test_the_looks_settle_closer_to_the_scan(ict) -> None:  # type: ignore[no-untyped-def]
    from puppet.capture.arkit_in import shape_channels

    data, skin = scan_data(), skin_layout().vertices
    for label, (shape, limit) in LOOKS.items():
        target = data.expression(label)[skin]
        values = shape_channels({shape: np.ones(1)}, 1)[0]
        rel = {}
        for tissue in (False, True):
            d = _settled(ict, values, tissue)
            rel[tissue] = float(np.sqrt(np.sum((d - target) ** 2) / np.sum(target ** 2)))
        assert rel[True] < limit, (label, rel)
        assert rel[True] < rel[False] - 0.02, (label, rel)


def test_a_still_gaze_keeps_its_bits(ict) -> None:  # type: ignore[no-untyped-def]
    """A smile with the eyes straight: the same bits with the tissue or without (its responses are
    read only when the gaze is off centre)."""
    c = FaceControl(ict)
    c.set("zygomaticus_major_l", 0.6)
    out = []
    for tissue in (False, True):
        sim = Simulator(ict, wrinkles=False)
        sim.gaze_tissue = tissue
        state = ict.rest_state()
        for _ in range(20):
            sim.step(state, c)
        out.append(state.positions.copy())
    assert np.array_equal(out[0], out[1])
