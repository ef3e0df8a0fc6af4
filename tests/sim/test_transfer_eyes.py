"""An imported head shows its eyes as a resting face does: the upper lid covers the top of the
iris, the lower lid meets its bottom, the iris sits in the middle of the opening and the eyeball
lies behind the lids (sim.face.transfer.eyes). Checked on a head with open eyes and on one
scanned with its eyes shut; without the seating both fail (the carried eyeball bulges through the
lids or sits to one side, the lids show white above the iris)."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face.transfer.eyes import iris_radius, lid_chains
from sim.face.transfer.landmarks import parse_landmarks
from sim.face.transfer.meshfile import from_arrays
from sim.face.transfer.pipeline import TransferOptions, transfer_rig
from sim.face.transfer.synthetic import synthetic_mesh, synthetic_rig
from test_transfer_closed_head import closed_head

STRETCH = np.diag([1.1, 0.9, 1.05])  # a head of other proportions than the reference's


def _open_head(reference):
    v, t, _ = synthetic_mesh(60, 50, full_head=True)
    pts = {k: (reference.mesh.landmark(k) @ STRETCH.T).tolist() for k in reference.mesh.landmarks}
    return from_arrays(v @ STRETCH.T, t, "head.obj"), parse_landmarks(pts, "lm.json")


@pytest.fixture(scope="module")
def reference():
    return synthetic_rig(48, 44)


@pytest.fixture(scope="module", params=["open", "shut"])
def imported(request, reference):
    head, lms = _open_head(reference) if request.param == "open" else closed_head(reference)
    return transfer_rig(reference, head, lms, options=TransferOptions(seat_eyes=True)).rig.mesh


def _middle(v: np.ndarray, chain: np.ndarray, x: float) -> np.ndarray:
    """The chain's point (3,) where it crosses the height line at x (between the corners)."""
    p = v[chain]
    order = np.argsort(p[:, 0])
    return np.array([np.interp(x, p[order, 0], p[order, k]) for k in range(3)])


def _seated(mesh) -> dict[str, float]:
    """Per eye (cm): how much of the iris' top the upper lid covers, how far the lower lid is
    from the iris' bottom (positive: over it), how far the iris is off the opening's middle, and
    the lid margins' least distance outside the eyeball (negative: the ball pokes through)."""
    out = {}
    v = mesh.vertices
    r_iris = iris_radius(mesh.eye_radius)
    for k, s in enumerate("lr"):
        inner, outer = mesh.landmark(f"eye_inner_{s}"), mesh.landmark(f"eye_outer_{s}")
        upper, lower = lid_chains(v, mesh.eye_loops[k], inner, outer)
        c = mesh.eye_centers[k]
        top, bottom = _middle(v, upper, c[0])[1], _middle(v, lower, c[0])[1]
        rim = np.linalg.norm(v[np.r_[upper, lower]] - c, axis=1) - mesh.eye_radius
        out[s] = {"top": c[1] + r_iris - top, "bottom": bottom - (c[1] - r_iris),
                  "off": abs(c[0] - 0.5 * (v[upper[0], 0] + v[upper[-1], 0])), "rim": float(rim.min())}
    return out


def test_the_upper_lid_covers_the_top_of_the_iris_at_rest(imported) -> None:
    for side, f in _seated(imported).items():
        assert 0.1 < f["top"] < 0.4, (side, f)  # 1-4 mm of the iris under the upper lid
        assert -0.05 < f["bottom"] < 0.2, (side, f)  # the lower lid meets the iris' bottom
        assert f["off"] < 0.1, (side, f)  # the iris in the middle of the opening
        assert f["rim"] > 0.0, (side, f)  # the lids lie on the eyeball, not behind it


def test_without_seating_the_eyes_do_not_rest_like_a_face(reference) -> None:
    """The property above is the seating's doing: the eyeball carried by the correspondence alone
    onto the stretched head bulges through its lids and leaves the iris' top uncovered."""
    head, lms = _open_head(reference)
    mesh = transfer_rig(reference, head, lms, options=TransferOptions(seat_eyes=False)).rig.mesh
    bad = [f for f in _seated(mesh).values() if not (0.1 < f["top"] < 0.4 and f["rim"] > 0.0)]
    assert bad


def test_a_socket_behind_the_opening_does_not_push_the_eyeball_back() -> None:
    """A head modelled with its socket (or its own eye surface) behind the lid opening: the
    eyeball still rests on the lid margins; only what is in front of them is a lid."""
    from sim.face.transfer.eyes import seat_eye

    x, y = np.meshgrid(np.linspace(-3.0, 3.0, 61), np.linspace(-2.0, 2.0, 41))
    sheet = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    sheet[:, 2] = -0.05 * (sheet[:, 0] ** 2 + sheet[:, 1] ** 2)  # the face curving away
    t = np.linspace(0.0, 2.0 * np.pi, 32, endpoint=False)
    rim = np.stack([1.5 * np.cos(t), 0.5 * np.sin(t), np.zeros_like(t)], axis=1)
    rim[:, 2] = -0.05 * (rim[:, 0] ** 2 + rim[:, 1] ** 2)
    inside = (sheet[:, 0] / 1.5) ** 2 + (sheet[:, 1] / 0.5) ** 2 < 1.05
    socket = sheet[inside] * [1.0, 1.0, 0.0] + [0.0, 0.0, -1.2]  # 12 mm behind the opening
    v = np.vstack([rim, sheet[~inside], socket])
    loop = np.arange(len(rim))
    radius = 1.2
    out, centre, _ = seat_eye(v, loop, rim[16], rim[0], radius)
    gap = np.linalg.norm(out[loop] - centre, axis=1) - radius
    assert 0.0 < gap.min() < 0.1  # the lid margins rest on the eyeball
    without_socket, centre2, _ = seat_eye(v[:len(rim) + int((~inside).sum())], loop, rim[16], rim[0], radius)
    assert np.allclose(centre, centre2)
