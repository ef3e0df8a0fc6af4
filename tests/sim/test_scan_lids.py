"""The scanned head's lids (`sim.face.scan.lids`): the shipped rig carries them as the code builds
them, and a blink closes the upper lid as the scan's does: down onto the lower lid, the brow
staying, the lower lid sliding towards the nose rather than rising."""

from __future__ import annotations

import numpy as np
import pytest

from sim.facs import apply_au
from sim.integrator import Simulator
from sim.state import FaceControl
from sim.face.scan.lids import CHANNEL, FOLD_KEY, LIGAMENT_KEY, with_lids
from sim.face.scan.rig import scan_model, scan_rig


def test_the_shipped_rig_carries_the_lids_the_code_builds() -> None:
    """`python -m sim.face.scan.lids` (or make_rig) was run after the last change to the lids."""
    shipped = scan_rig()
    built = with_lids(shipped)
    for key in (LIGAMENT_KEY, FOLD_KEY):
        assert np.array_equal(built.tissue[key], shipped.tissue[key]), key
    for side in ("l", "r"):
        ch = CHANNEL.format(side=side)
        assert np.array_equal(built.insertion[ch], shipped.insertion[ch])
        assert [m.name for m in built.muscles[ch]] == [m.name for m in shipped.muscles[ch]]
        for a, b in zip(built.muscles[ch], shipped.muscles[ch]):
            for key, val in vars(a).items():
                if key != "name":
                    assert np.allclose(val, getattr(b, key), atol=1e-6), (ch, a.name, key)


@pytest.fixture(scope="module")
def blink() -> tuple[object, np.ndarray]:
    model = scan_model()
    sim = Simulator(model, wrinkles=False)
    rest = model.rest_state()
    sim.settle(rest, FaceControl(model), max_seconds=2.0)
    closed = rest.copy()
    c = FaceControl(model)
    apply_au(c, "AU45", 1.0)
    sim.settle(closed, c, max_seconds=3.0)
    return model, closed.positions - rest.positions


def test_a_blink_brings_the_upper_lid_down_and_leaves_the_brow(blink) -> None:  # type: ignore[no-untyped-def]
    model, d = blink
    lm = model.mesh.landmarks
    for s in ("l", "r"):
        assert d[lm[f"upper_lid_{s}"], 1] < -0.7  # the scan's: 9.2 mm
        for brow in ("brow_inner", "brow_mid", "brow_outer"):
            assert np.linalg.norm(d[lm[f"{brow}_{s}"]]) < 0.1, brow  # the scan's: 0.1-0.2 mm


def test_a_blink_slides_the_lower_lid_towards_the_nose(blink) -> None:  # type: ignore[no-untyped-def]
    model, d = blink
    lm = model.mesh.landmarks
    for s, nose in (("l", -1.0), ("r", 1.0)):
        low = d[lm[f"lower_lid_{s}"]]
        assert abs(low[1]) < 0.1  # it does not rise (the scan's: 0.2 mm)
        assert low[0] * nose > 0.05  # it slides towards the nose (the scan's: 2.8 mm)


def test_the_blink_leaves_the_skin_above_the_fold_as_the_scan_does() -> None:
    """The scan's eyeBlink brings the margin down and the skin above it less and less: from 3.5 to
    10 mm above the margin 1.9 mm on average, where ours brought it 3.0 mm (the lid fold's skin
    dragged down with the margin; relative error 0.50). The lid channel's tissue (its tether's
    anchors, fitted with the closed lids held meeting) holds it: 2.6 mm, relative error 0.37."""
    from puppet.capture.arkit_in import shape_channels
    from sim.face.scan.anatomy import skin_layout
    from sim.face.scan.data import scan_data
    from sim.face.scan.lids import margin_distances
    from sim.fit.basis import Settler

    model = scan_model()
    settler = Settler(model)
    ours = settler.pose(shape_channels({"EyeBlinkLeft": np.ones(1)}, 1)[0]) - settler.rest
    scan = scan_data().expression("eyeBlink_L")[skin_layout().vertices]
    rms = lambda d: float(np.sqrt(np.mean(np.sum(d * d, axis=1))))  # noqa: E731
    assert rms(ours - scan) / rms(scan) < 0.45
    up, low = margin_distances(model.mesh, "l")
    lm = model.mesh.landmarks
    rest = np.asarray(model.rest)
    inner, outer = rest[lm["eye_inner_l"], 0], rest[lm["eye_outer_l"], 0]
    t = (rest[:, 0] - inner) / (outer - inner)
    band = (up < low) & (up >= 0.35) & (up < 1.0) & (t > -0.2) & (t < 1.2)
    assert band.sum() > 50
    assert scan[band, 1].mean() < -0.1  # the scan's comes down too
    assert ours[band, 1].mean() > 1.5 * scan[band, 1].mean()
