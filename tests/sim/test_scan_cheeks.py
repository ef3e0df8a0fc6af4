"""The scanned head's mouth corner against its own scans (issue 20): the smile, the dimple and the
stretch come as close to their scans as the corner's muscles carrying the cheek's tissue over zones
grown 3 cm give (docs/scan-face.md, "The smile's cheek: the corner's muscles over grown zones")."""

from __future__ import annotations

import numpy as np
import pytest

from puppet.capture.arkit_in import shape_channels
from sim.face.scan.anatomy import skin_layout
from sim.face.scan.data import scan_data
from sim.face.scan.rig import scan_model
from sim.fit.basis import Settler


@pytest.fixture(scope="module")
def settler():  # type: ignore[no-untyped-def]
    return Settler(scan_model())


def _rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


@pytest.mark.parametrize(("scan", "shape", "bound"), [
    ("mouthSmile_L", "MouthSmileLeft", 0.35),
    ("mouthSmile_R", "MouthSmileRight", 0.35),
    ("mouthDimple_L", "MouthDimpleLeft", 0.47),
    ("mouthDimple_R", "MouthDimpleRight", 0.47),
    ("mouthStretch_L", "MouthStretchLeft", 0.34),
    ("mouthStretch_R", "MouthStretchRight", 0.34),
])
def test_the_corner_shapes_come_close_to_their_scans(settler, scan: str, shape: str, bound: float) -> None:  # type: ignore[no-untyped-def]
    """Driven through the import at 1 and settled, each shape's skin against its scan (relative error:
    0 the scan, 1 as wrong as not moving). While the corner's muscles carried only the tissue of their
    own zones the smile settled at 0.48, the dimple at 0.58 and the stretch at 0.45: the cheek beside
    the corner, the nasolabial band and the jowl over the jaw's body stayed behind. The smile is
    the modiolus drawn up and back by every muscle inserting into it, the zygomaticus at 0.55 of
    the shape (`SHAPE_SPAN`, `SHAPE_SHARES`): with the zygomaticus alone at 1 it settled at 0.436.
    The stretch draws the corner down with the depressor anguli oris and a trace of the buccinator:
    with the risorius alone it settled at 0.369 a side. Both entries were fitted on the left side
    only; the right side is held out. Then the corner's four fields refitted on the merged rig with
    those entries: the smile 0.371 -> 0.341, the dimple 0.498 -> 0.461, the stretch 0.356 -> 0.332."""
    target = scan_data().expression(scan)[skin_layout().vertices]
    ours = settler.pose(shape_channels({shape: np.ones(1)}, 1)[0]) - settler.rest
    assert _rms(ours - target) / _rms(target) < bound
