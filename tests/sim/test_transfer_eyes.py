"""An imported head shows its eyes as a resting face does: the upper lid covers the top of the
iris, the lower lid meets its bottom, the iris sits in the middle of the opening and the eyeball
lies behind the lids (sim.face.transfer.eyes). Checked on a head with open eyes and on one
scanned with its eyes shut; without the seating both fail (the carried eyeball bulges through the
lids or sits to one side, the lids show white above the iris)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

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
    skin = len(rim) + int((~inside).sum())
    face = Delaunay(v[:skin, :2]).simplices
    middle = v[face].mean(axis=1)
    face = face[(middle[:, 0] / 1.5) ** 2 + (middle[:, 1] / 0.5) ** 2 > 1.0]  # the opening is a hole
    tri = np.vstack([face, skin + Delaunay(socket[:, :2]).simplices])
    loop = np.arange(len(rim))
    radius = 1.2
    out, centre, _ = seat_eye(v, tri, loop, rim[16], rim[0], radius)
    gap = np.linalg.norm(out[loop] - centre, axis=1) - radius
    assert 0.0 < gap.min() < 0.1  # the lid margins rest on the eyeball
    without_socket, centre2, _ = seat_eye(v[:skin], face, loop, rim[16], rim[0], radius)
    assert np.allclose(centre, centre2)


def _thick_lids(reference) -> tuple[object, np.ndarray]:
    """The stretched open head before seating, its upper lids made thick as a scan's are: each
    rim drawn up and back into the socket (by up to 0.8 cm at the middle, nothing at the
    corners), so the lid's front skin hangs over the opening below its own rim. Returns the mesh
    and its vertices with the rolled rims."""
    head, lms = _open_head(reference)
    mesh = transfer_rig(reference, head, lms, options=TransferOptions(seat_eyes=False)).rig.mesh
    v = np.asarray(mesh.vertices, float).copy()
    roll = 0.8
    for k, s in enumerate("lr"):
        inner, outer = mesh.landmark(f"eye_inner_{s}"), mesh.landmark(f"eye_outer_{s}")
        upper, _ = lid_chains(v, mesh.eye_loops[k], inner, outer)
        ends = v[upper[-1]] - v[upper[0]]
        t = np.clip((v[upper] - v[upper[0]]) @ ends / (ends @ ends), 0.0, 1.0)
        v[upper] += np.outer(np.sin(np.pi * t), [0.0, roll, -0.6 * roll])
    return mesh, v


def test_a_thick_lid_is_opened_to_what_is_seen_alike_on_both_eyes(reference) -> None:
    """A scan's thick lid hangs over its own rim: seated by the rims' gap its eye showed as a slit
    (the scanned head's identity imported: rims 0.64 cm apart, 0.04 cm seen). The seating opens
    what is seen from the front to a resting eye's opening, on both eyes alike (the two sides are
    mirror images: a view direction taken from the corner-to-corner axis once opened one eye
    only), and the iris shows under the lid that hangs over it."""
    from sim.face.transfer.eyes import rest_gap, seat_eye, seen_opening

    mesh, v = _thick_lids(reference)
    seen = {}
    for k, s in enumerate("lr"):
        inner, outer = mesh.landmark(f"eye_inner_{s}"), mesh.landmark(f"eye_outer_{s}")
        upper, lower = lid_chains(v, mesh.eye_loops[k], inner, outer)
        top, bottom = seen_opening(v, mesh.triangles, upper, lower)
        rims = v[upper, 1].max() - v[lower, 1].min()
        assert top - bottom < rims - 0.4, (s, top - bottom, rims)  # the rolled rim hides behind the lid
        seated, centre, _ = seat_eye(v, mesh.triangles, mesh.eye_loops[k], inner, outer, float(mesh.eye_radius))
        top, bottom = seen_opening(seated, mesh.triangles, upper, lower)
        seen[s] = top - bottom
        assert abs(seen[s] - rest_gap(mesh.eye_radius)) < 0.03, (s, seen[s])
        cover = centre[1] + iris_radius(mesh.eye_radius) - (seated[upper[0], 1] + top)
        assert 0.1 < cover < 0.4, (s, cover)  # 1-4 mm of the iris under the lid one sees
    assert abs(seen["l"] - seen["r"]) < 0.02, seen


def test_by_the_rims_alone_a_thick_lid_leaves_a_slit(reference) -> None:
    """What the test above asks is the seen opening's doing: the same lids set by the rims' gap
    (to the resting opening, as the seating did before) leave the hanging skin over the iris: what
    one sees is short of a resting eye's by more than 2 mm."""
    from sim.face.transfer.eyes import rest_gap, seen_opening
    from sim.face.transfer.lids import set_gap

    mesh, v = _thick_lids(reference)
    inner, outer = mesh.landmark("eye_inner_l"), mesh.landmark("eye_outer_l")
    upper, lower = lid_chains(v, mesh.eye_loops[0], inner, outer)
    by_rims = set_gap(v, upper, lower, rest_gap(mesh.eye_radius), np.array([0.0, 1.0, 0.0]))
    top, bottom = seen_opening(by_rims, mesh.triangles, upper, lower)
    assert top - bottom < rest_gap(mesh.eye_radius) - 0.2, top - bottom


def test_a_shut_lid_parts_the_right_way_whichever_side_holds_the_cut_copies() -> None:
    """A lid line cut along a scan's edges can hand its copies to the upper lid's skin (a line
    that winds starts on either side; on the scanned head shut, one eye of two): parted by the
    loop's halves alone the upper lid's skin moved down and the lower margin up, the lids crossed
    and the eye stayed a blank lid. Parting decides by the skin: the margin whose skin lies higher
    rises, on either labelling, and the skin follows the lid it belongs to."""
    from sim.face.transfer.lids import open_lids, slit_sides
    from sim.face.transfer.openings import cut_slit

    x, y = np.meshgrid(np.linspace(-2.0, 2.0, 41), np.linspace(-1.5, 1.5, 31))
    v = np.stack([x.ravel(), y.ravel(), -0.05 * (x.ravel() ** 2 + y.ravel() ** 2)], axis=1)
    t = Delaunay(v[:, :2]).simplices
    row = np.flatnonzero((np.abs(v[:, 1]) < 1e-9) & (np.abs(v[:, 0]) <= 1.5 + 1e-9))
    path = row[np.argsort(v[row, 0])]
    up = np.array([0.0, 1.0, 0.0])
    verts, tris, loop, _ = cut_slit(v, t, path, up, "eye_l", "lm.json")
    top, copies = slit_sides(loop)
    swapped = np.r_[copies, top[1:-1][::-1]]  # the same loop, the copies listed as the path
    above = np.flatnonzero((np.abs(verts[:, 0]) < 0.3) & (np.abs(verts[:, 1] - 0.2) < 1e-9))
    below = np.flatnonzero((np.abs(verts[:, 0]) < 0.3) & (np.abs(verts[:, 1] + 0.2) < 1e-9))
    for labelled in (loop, swapped):
        opened = open_lids(verts, labelled, 0.33, up, tris)
        mid = len(top) // 2
        assert opened[top[mid], 1] - opened[copies[mid], 1] > 0.9, labelled[:3]  # 0.33 x 3 cm
        assert np.all(opened[above, 1] > verts[above, 1]) and np.all(opened[below, 1] < verts[below, 1])
    by_halves = open_lids(verts, swapped, 0.33, up)  # without the skin: the lids cross
    assert by_halves[top[mid], 1] < by_halves[copies[mid], 1]


def test_an_eyeball_too_small_for_the_opening_is_grown_to_fit_it(reference) -> None:
    """An eyeball carried at the reference's size for the eye's width can be too small for a head
    whose eyes are short and tall (the scanned head's: its iris 0.86 cm tall in an opening seen
    0.99 cm): brought to its resting opening the lids made a slit. Its eyeball is grown until
    its resting opening is the one the head shows, and the lids are left as the head has them;
    an eyeball whose iris fills the opening keeps its size."""
    import dataclasses

    from sim.face.transfer.eyes import rest_gap, seat_eyes, seen_opening

    head, lms = _open_head(reference)
    mesh = transfer_rig(reference, head, lms, options=TransferOptions(seat_eyes=False)).rig.mesh
    v = np.asarray(mesh.vertices, float)
    seen = []
    for k, s in enumerate("lr"):
        upper, lower = lid_chains(v, mesh.eye_loops[k], mesh.landmark(f"eye_inner_{s}"), mesh.landmark(f"eye_outer_{s}"))
        top, bottom = seen_opening(v, mesh.triangles, upper, lower)
        seen.append(top - bottom)
    small = dataclasses.replace(mesh, eye_radius=0.4 * float(np.mean(seen)))  # iris shorter than the opening
    seated, _ = seat_eyes(small)
    assert abs(rest_gap(seated.eye_radius) - np.mean(seen)) < 1e-6
    assert np.abs(seated.vertices - v).max() < 0.02  # the head's own lids are kept
    kept, _ = seat_eyes(mesh)
    assert kept.eye_radius == mesh.eye_radius


def _toy_eye() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, upper, lower): an eye 2 cm wide along +X, margins 0.8 cm apart at the middle, in
    the plane z = 0, facing +Z; vertices 8-9 stand for a shut lid's back layer (behind the
    margins, inside the opening), 10 for the skin under the lower lid (behind the margins too, but
    below the opening), 11 for skin in front of the margins."""
    x = np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    h = np.array([0.0, 0.3, 0.4, 0.3, 0.0])
    v = np.concatenate([np.stack([x, h, 0 * x], 1), np.stack([x[1:-1], -h[1:-1], 0 * x[1:-1]], 1),
                        [[0.8, 0.1, -0.1], [1.2, 0.1, -0.1], [1.0, -0.6, -0.1], [1.0, 0.2, 0.1]]])
    return v, np.array([0, 1, 2, 3, 4]), np.array([0, 5, 6, 7, 4])


def test_a_shut_lids_back_layer_is_not_seen_as_lid() -> None:
    """A triangle from the lower margin up to the back layer crosses the opening's middle seen from
    the front, but lies behind the margins: the opening seen is the margins' (before, one vertex in
    front sufficed to count the triangle, and such a layer read as a lid covering half the eye)."""
    from sim.face.transfer.eyes import seen_opening

    v, upper, lower = _toy_eye()
    top, bottom = seen_opening(v, np.array([[6, 8, 9]]), upper, lower)
    assert top == pytest.approx(0.4) and bottom == pytest.approx(-0.4)


def test_the_back_layer_goes_behind_the_seated_eyeball() -> None:
    """Skin behind the margins, inside the opening and in front of the eyeball (a shut lid's back
    layer stretched across when the lids part) is moved behind the eyeball, where it hides; skin
    below the opening and skin in front of the margins stay where they are."""
    from sim.face.transfer.eyes import tuck_back_layer

    v, upper, lower = _toy_eye()
    centre, radius = np.array([1.0, 0.0, -1.2]), 1.0
    out = tuck_back_layer(v, upper, lower, centre, radius, np.array([0.0, 0.0, 1.0]))
    assert np.all(out[[8, 9], 2] < centre[2] - 0.9 * radius)  # behind the eyeball's back
    np.testing.assert_allclose(out[[8, 9], :2], v[[8, 9], :2])  # straight back
    stay = [0, 1, 2, 3, 4, 5, 6, 7, 10, 11]
    np.testing.assert_array_equal(out[stay], v[stay])


def _flapped_lid() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, triangles, the eye's loop) of a shut lid cut along its line (3 cm, on a gently
    curved sheet), with a flap of the lower lid's skin joined to it 3 mm under the line, rising in
    front of the line to 5 mm above it: a scan's lower lid pushed up over the shut upper one."""
    from sim.face.transfer.openings import cut_slit

    x, y = np.meshgrid(np.linspace(-2.0, 2.0, 41), np.linspace(-1.5, 1.5, 31))
    v = np.stack([x.ravel(), y.ravel(), -0.05 * (x.ravel() ** 2 + y.ravel() ** 2)], axis=1)
    t = Delaunay(v[:, :2]).simplices
    row = np.flatnonzero((np.abs(v[:, 1]) < 1e-9) & (np.abs(v[:, 0]) <= 1.5 + 1e-9))
    path = row[np.argsort(v[row, 0])]
    v, t, loop, _ = cut_slit(v, t, path, np.array([0.0, 1.0, 0.0]), "eye_l", "lm.json")
    base = np.flatnonzero((np.abs(v[:, 1] + 0.3) < 1e-9) & (np.abs(v[:, 0]) <= 1.0 + 1e-9))
    base = base[np.argsort(v[base, 0])]
    rows = [base]
    for k, h in enumerate((-0.1, 0.1, 0.3, 0.5)):  # the flap: up and in front of the line
        layer = v[base] * [1.0, 0.0, 1.0] + [0.0, h, 0.15 + 0.05 * k]
        rows.append(np.arange(len(v), len(v) + len(base)))
        v = np.vstack([v, layer])
    flap = [[a[i], a[i + 1], b[i + 1]] for a, b in zip(rows[:-1], rows[1:]) for i in range(len(base) - 1)]
    flap += [[a[i], b[i + 1], b[i]] for a, b in zip(rows[:-1], rows[1:]) for i in range(len(base) - 1)]
    return v, np.vstack([t, np.asarray(flap)]), loop


def test_a_sheet_of_the_lower_lid_over_the_shut_eye_goes_down_with_it() -> None:
    """A scan's shut eye can hang a sheet of the lower lid's skin in front of the upper margin,
    reached from the lower margin only (the lower lid pushed up over the upper one): parting the
    lids, skin lying beyond the other lid's margin followed its own lid less the further it lay,
    so the sheet stayed over the opening and the eye was a blank lid however far the lids parted.
    Seated, the sheet goes down whole with its lid and the eye opens to a resting eye's height."""
    from sim.face.transfer.eyes import rest_gap, seat_eye, seen_opening
    from sim.face.transfer.lids import slit_sides

    v, t, loop = _flapped_lid()
    upper, lower = slit_sides(loop)
    radius = 0.8
    top, bottom = seen_opening(v, t, upper, lower)
    assert top == bottom  # shut, and the flap lies over the line
    seated, _, seat = seat_eye(v, t, loop, v[upper[0]], v[upper[-1]], radius)
    assert seat.gap_after > 0.9 * rest_gap(radius), seat
    assert seat.uncovered, seat  # the report says what was moved off the opening
    flap = np.arange(len(v) - 4 * 21, len(v))
    assert np.all(seated[flap, 1] < v[flap, 1] - 0.1)  # the sheet went down with the lower lid
