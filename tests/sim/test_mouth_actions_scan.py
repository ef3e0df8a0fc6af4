"""The lips' and cheeks' actions on the scanned head (rigged by transfer): pucker narrows the mouth
and brings the lips forward, the sideways shift carries the lips to that side, the puff pushes the
cheeks out, a pressure patch carried into the scan's frame keeps pushing along the skin's normal."""

from __future__ import annotations

import numpy as np
import pytest

from sim.model import PatchMuscle


@pytest.fixture(scope="module")
def scan():  # type: ignore[no-untyped-def]
    from puppet.face_cache import scan_model
    from sim.fit.basis import Settler

    model = scan_model()
    return model, Settler(model, max_seconds=2.0)


def test_new_actions_on_the_scanned_head(scan) -> None:  # type: ignore[no-untyped-def]
    model, settler = scan
    lm = model.mesh.landmarks
    puff = model.rig.muscles["cheek_puff"]
    assert all(isinstance(p, PatchMuscle) and not np.any(p.direction) for p in puff)  # still a pressure
    pucker = (settler.pose(settler.values_for({"incisivus": 1.0})) - settler.rest) * 10.0
    assert pucker[lm["mouth_corner_l"], 0] < -2.0 and pucker[lm["mouth_corner_r"], 0] > 2.0
    assert pucker[lm["upper_lip_center"], 2] > 2.0
    left = (settler.pose(settler.values_for({"mouth_shift_l": 1.0})) - settler.rest) * 10.0
    assert left[lm["upper_lip_center"], 0] > 2.0 and left[lm["lower_lip_center"], 0] > 2.0
    cheeks = (settler.pose(settler.values_for({"cheek_puff": 1.0})) - settler.rest) * 10.0
    out = np.einsum("ij,ij->i", cheeks, model.rest_normal)
    # the pressure reaches the lips' inside (the vestibule), so it pushes the corners apart; their
    # rim's normals face into the mouth (the scan's own puff moves them 4-6 mm against them): the
    # skin within 3 mm of a corner is not held to "out"
    corners = np.zeros(len(out), bool)
    for c in ("mouth_corner_l", "mouth_corner_r"):
        corners |= np.linalg.norm(model.rest - model.rest[lm[c]], axis=1) < 0.3
    assert out.max() > 3.0 and out[~corners].min() > -2.0


def test_mouth_close_lifts_the_lower_lip_up_and_forward_closed(scan) -> None:  # type: ignore[no-untyped-def]
    """ARKit mouthClose, the lips meeting over an open jaw, as the scan's: the lower lip's middle
    lifted and carried forward (the scan's 38 mm up and 17 forward; before the lips' lift, 11 up
    and 3.5 back), the chin with it, the lips still closed and no skin turned over; a spoken "m"
    (mouthClose 0.1 over jawOpen 0.08, the lips pressed) still closes the lips."""
    from puppet.capture.arkit_in import shape_channels
    from sim.antifold import turned_over_area

    model, settler = scan
    lm = model.mesh.landmarks
    x = settler.pose(shape_channels({"MouthClose": np.ones(1)}, 1)[0])
    d = (x - settler.rest) * 10.0  # mm
    lower, upper = d[lm["lower_lip_center"]], d[lm["upper_lip_center"]]
    assert lower[1] > 14.0 and lower[2] > 1.0
    assert d[lm["chin"], 1] > 7.0
    assert abs(upper[1] - lower[1]) < 1.0  # the lips meet: the upper one rides on the lower
    assert turned_over_area(model.triangles, model.rest, x) < 0.1

    def gap(p: np.ndarray) -> float:
        return float(p[lm["upper_lip_center"], 1] - p[lm["lower_lip_center"], 1])

    m = {"JawOpen": 0.08, "MouthClose": 0.1, "MouthPressLeft": 0.35, "MouthPressRight": 0.35, "MouthRollLower": 0.15}
    said = settler.pose(shape_channels({k: np.array([v]) for k, v in m.items()}, 1)[0])
    jaw = settler.pose(shape_channels({"JawOpen": np.array([0.08])}, 1)[0])
    assert gap(jaw) > gap(settler.rest) + 0.2  # the jaw alone parts them
    assert gap(said) < gap(settler.rest) + 0.1
