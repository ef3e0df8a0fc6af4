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
