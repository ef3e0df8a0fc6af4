"""The scanned head's upper face against its own scans and the brows' amplitude targets (issues 19
and 20): the inner brows' raise lifts the brows rather than the forehead as the scan's browInnerUp
does, the cheek's squint carries the cheek up as a block as the scan's cheekSquint does, the brows
lowered carry the temple beside the brow's tail as the scan's browDown does, and the brows raised
or lowered in full stay within what real brows do."""

from __future__ import annotations

import numpy as np
import pytest

from puppet.capture.arkit_in import shape_channels
from sim.face import targets as et
from sim.face.scan.anatomy import skin_layout
from sim.face.scan.data import scan_data
from sim.face.scan.rig import scan_model
from sim.fit.basis import Settler
from sim.integrator import Simulator


@pytest.fixture(scope="module")
def settler():  # type: ignore[no-untyped-def]
    return Settler(scan_model())


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def _scan(*names: str) -> np.ndarray:
    """(N, 3) the scan's displacement of the simulated skin for the sum of these shapes, cm."""
    data = scan_data()
    return sum(data.expression(n) for n in names)[skin_layout().vertices]  # type: ignore[return-value]


def _ours(settler, shape: str) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(N, 3) the settled displacement of the ARKit shape at 1, driven through the import, cm."""
    return settler.pose(shape_channels({shape: np.ones(1)}, 1)[0]) - settler.rest


def test_the_inner_brows_raise_lifts_the_brows_more_than_the_forehead(settler) -> None:  # type: ignore[no-untyped-def]
    """The scan's browInnerUp lifts the brows 2.4 mm and the forehead above them a quarter as far;
    ours lifted the forehead with the brows (0.8 as far: the sheet's pull towards the scalp, the
    medial fibres' insertion into the brows missing), relative error 0.66."""
    scan = _scan("browInnerUp_L", "browInnerUp_R")
    ours = _ours(settler, "BrowInnerUp")
    assert _rms(ours - scan) / _rms(scan) < 0.6
    rest = np.asarray(settler.model.rest)
    brow_y = rest[settler.model.mesh.landmarks["brow_mid_l"], 1]
    side = np.abs(rest[:, 0]) > 1.0
    forehead = side & (rest[:, 1] > brow_y + 1.5)
    brow = side & (np.abs(rest[:, 1] - brow_y) < 0.5)
    assert scan[forehead, 1].mean() < 0.3 * scan[brow, 1].mean()
    assert ours[brow, 1].mean() > 0.15 and ours[forehead, 1].mean() < 0.65 * ours[brow, 1].mean()


def test_the_cheeks_squint_carries_the_cheek_up_as_a_block(settler) -> None:  # type: ignore[no-untyped-def]
    """The scan's cheekSquint lifts the whole cheek, down to the mouth corner's level (2.7 mm between
    the nose wing's and the corner's height, outside the corner); ours lifted the skin under the
    lower lid and the cheek below half as far (relative error 0.67); the orbital orbicularis now
    carries the cheek's tissue with it (its anchors over the cheek)."""
    scan = _scan("cheekSquint_L")
    ours = _ours(settler, "CheekSquintLeft")
    assert _rms(ours - scan) / _rms(scan) < 0.6
    rest = np.asarray(settler.model.rest)
    lm = settler.model.mesh.landmarks
    low = ((rest[:, 1] < rest[lm["nose_wing_l"], 1]) & (rest[:, 1] > rest[lm["mouth_corner_l"], 1])
           & (rest[:, 0] > rest[lm["mouth_corner_l"], 0] + 0.5) & (rest[:, 0] < rest[lm["eye_outer_l"], 0]))
    assert low.sum() > 50
    # 0.72 as far with the zygomaticus major's share at 0.06, 0.82 at 0.1 (docs/scan-face.md, "The cheek's
    # squint: the malar fat carried further")
    assert ours[low, 1].mean() > 0.75 * scan[low, 1].mean() > 0.0


@pytest.mark.parametrize(("scan", "shape", "bound"), [
    ("cheekSquint_L", "CheekSquintLeft", 0.545),
    ("eyeSquint_L", "EyeSquintLeft", 0.433),
])
def test_the_squints_come_closer_with_the_malar_fat_carried(settler, scan: str, shape: str, bound: float) -> None:  # type: ignore[no-untyped-def]
    """The orbital orbicularis' tissue field, refitted with a ridge that no longer held the wide
    zone's field small, carries the cheek's fat further forward under the lid (cheekSquint 0.556 ->
    0.543, and 0.537 with the zygomaticus major's share at 0.1; 0.552 with that share on the rig
    before) and leaves less of it on the eye's squint, whose scan barely lifts the cheek (eyeSquint
    0.438 -> 0.427): both settled above these bounds on the rig before."""
    target = _scan(scan)
    ours = _ours(settler, shape)
    assert _rms(ours - target) / _rms(target) < bound


def _temple(settler) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The left temple beside the brow's tail: 2 cm out from the brow's outer end, from the outer
    canthus' height to 1 cm above the brow's end (246 vertices)."""
    rest = np.asarray(settler.model.rest)
    lm = settler.model.mesh.landmarks
    outer = rest[lm["brow_outer_l"]]
    return ((rest[:, 0] > outer[0]) & (rest[:, 0] < outer[0] + 2.0) & (rest[:, 1] > rest[lm["eye_outer_l"], 1])
            & (rest[:, 1] < outer[1] + 1.0))


def _mean_length(d: np.ndarray) -> float:
    return float(np.linalg.norm(d, axis=1).mean())


def test_the_brows_lowered_carry_the_temple(settler) -> None:  # type: ignore[no-untyped-def]
    """The scan's browDown carries the temple beside the brow's tail in and forward with the brow
    (1.8 mm in, 2.3 forward on average); ours carried it 0.64 as far (relative error 0.41) until the
    corrugator's field reached it (its zone grown 4.5 cm: the layer it inserts in, continuous with the
    temporoparietal fascia): 0.78 as far, relative error 0.34."""
    scan = _scan("browDown_L")
    ours = _ours(settler, "BrowDownLeft")
    assert _rms(ours - scan) / _rms(scan) < 0.38
    temple = _temple(settler)
    assert temple.sum() > 150
    assert _mean_length(ours[temple]) > 0.72 * _mean_length(scan[temple])


@pytest.mark.parametrize("pose", ["AU4", "anger"])
def test_the_brows_lowered_stay_within_real_brows(settler, pose: str) -> None:  # type: ignore[no-untyped-def]
    """AU4 and anger lower the inner brow 3-9 mm and the mid brow 2-7 mm (the brows' drawing together,
    3+ mm, is still short: 2.5-2.7 mm)."""
    model = settler.model
    sim = Simulator(model, wrinkles=False)
    state = model.rest_state()
    sim.settle(state, et.pose_control(pose), max_seconds=3.0)
    for t in (t for t in et.TARGETS if t.pose == pose and t.component == "down"):
        value = et.measure(t, model.mesh.landmarks, model.rest, state.positions)
        assert t.lo <= value <= t.hi, f"{t.landmark} {t.component} = {value:.2f}, want {t.lo}-{t.hi}"


@pytest.mark.parametrize("pose", ["AU1", "AU1+2", "surprise"])
def test_the_brows_raised_stay_within_real_brows(settler, pose: str) -> None:  # type: ignore[no-untyped-def]
    """AU1+2 and surprise raise the mid brow 7.5-10.5 mm (Cruz 2004, Jorge 2012) and AU1 alone
    keeps the brow oblique (the outer end at most 0.4 of the inner's rise): the inner brows'
    anchors, fitted for the scan's shape at a span of 0.55 (1/0.55 of it at full), carried them
    10.8-10.9 mm and AU1's outer brow rose 0.48 as far as the inner."""
    model = settler.model
    sim = Simulator(model, wrinkles=False)
    state = model.rest_state()
    sim.settle(state, et.pose_control(pose), max_seconds=3.0)
    for t in (t for t in et.TARGETS if t.pose == pose):
        value = et.measure(t, model.mesh.landmarks, model.rest, state.positions)
        assert t.lo <= value <= t.hi, f"{t.landmark} {t.component} = {value:.2f}, want {t.lo}-{t.hi}"
