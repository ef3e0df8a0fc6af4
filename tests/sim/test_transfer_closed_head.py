"""A head scanned with its eyes and lips shut (sim.face.transfer.synthetic, no eye or mouth holes),
its lid and lip lines declared: the imported rig opens the eyes at rest, its presets move the
landmarks the right way without turning skin over, and it marks the head's own cavity lining."""

from __future__ import annotations

import numpy as np
import pytest

from sim.antifold import turned_over_area
from sim.build import compile_model
from sim.face import default_rig
from sim.face.transfer.landmarks import parse_landmarks
from sim.face.transfer.meshfile import from_arrays
from sim.face.transfer.pipeline import IMPORTED_PRESETS, transfer_rig
from sim.face.transfer.synthetic import EYES, synthetic_mesh, synthetic_rig
from sim.facs import apply_expression
from sim.integrator import Simulator
from sim.state import FaceControl

SCALE = 0.95  # the head a little smaller than the reference: a user's mesh is never its twin


def _row(param: np.ndarray, h: float, lo: float, hi: float) -> np.ndarray:
    """Vertices of one grid row between two angles, in order: a path along mesh edges."""
    line = np.nonzero((np.abs(param[:, 1] - h) < 0.01) & (param[:, 0] >= lo) & (param[:, 0] <= hi))[0]
    return line[np.argsort(param[line, 0])]


def closed_head(reference):
    """(head, landmark file) of the synthetic full head with shut eyes and lips, lines declared."""
    v, t, param = synthetic_mesh(64, 45, full_head=True, mouth_open=False, eyes_open=False)
    pts = {k: (SCALE * reference.mesh.landmark(k)).tolist() for k in reference.mesh.landmarks}
    openings = {"mouth": _row(param, -5.0, -0.3, 0.3)}
    for side, (theta, h) in zip("lr", EYES):
        openings[f"eye_{side}"] = _row(param, h, theta - 0.2, theta + 0.2)
    for side in "lr":
        line = openings[f"eye_{side}"]
        inner, outer = (line[0], line[-1]) if side == "l" else (line[-1], line[0])
        mid = int(line[len(line) // 2])
        pts.update({f"eye_inner_{side}": int(inner), f"eye_outer_{side}": int(outer),
                    f"upper_lid_{side}": mid, f"lower_lid_{side}": mid})
    mouth = openings["mouth"]
    pts.update(mouth_corner_r=int(mouth[0]), mouth_corner_l=int(mouth[-1]),
               upper_lip_center=int(mouth[len(mouth) // 2]), lower_lip_center=int(mouth[len(mouth) // 2]))
    data = {"landmarks": pts, "openings": {k: x.tolist() for k, x in openings.items()}}
    return from_arrays(SCALE * v, t, "head.obj"), parse_landmarks(data, "lm.json")


@pytest.fixture(scope="module")
def synthetic_import():
    reference = synthetic_rig(48, 44)
    head, lms = closed_head(reference)
    return reference, transfer_rig(reference, head, lms)


def _aperture(mesh, side: str) -> float:
    lm = mesh.landmarks
    width = np.linalg.norm(mesh.vertices[lm[f"eye_outer_{side}"]] - mesh.vertices[lm[f"eye_inner_{side}"]])
    gap = mesh.vertices[lm[f"upper_lid_{side}"]] - mesh.vertices[lm[f"lower_lid_{side}"]]
    return float(np.linalg.norm(gap) / width)


def test_shut_eyes_are_opened_by_the_references_aperture(synthetic_import) -> None:
    reference, res = synthetic_import
    m = res.rig.mesh
    for side in "lr":
        want = _aperture(reference.mesh, side)
        assert want > 0.1
        assert _aperture(m, side) == pytest.approx(want, rel=0.25)  # the lid landmark: a vertex near the middle
        up, low = m.vertices[m.landmarks[f"upper_lid_{side}"]], m.vertices[m.landmarks[f"lower_lid_{side}"]]
        assert up[1] > low[1]  # the upper lid went up, the lower down: not the other way round
    assert any("were parted at rest" in n for n in res.notes)
    # the mouth was cut but stays closed at rest: a relaxed mouth
    lm = m.landmarks
    assert np.allclose(m.vertices[lm["upper_lip_center"]], m.vertices[lm["lower_lip_center"]])


def test_opening_turns_no_triangle_over_and_keeps_the_rest_far_away(synthetic_import) -> None:
    reference, res = synthetic_import
    v, t, _ = synthetic_mesh(64, 45, full_head=True, mouth_open=False, eyes_open=False)
    m = res.rig.mesh
    n = len(v)  # the cut's copies come after the file's vertices
    moved = np.linalg.norm(m.vertices[:n] - res.similarity.apply(SCALE * v), axis=1)
    chin = m.vertices[m.landmarks["chin"]]
    corners = m.vertices[[m.landmarks[f"eye_{k}_{s}"] for k in ("inner", "outer") for s in "lr"]]
    width = np.linalg.norm(corners[0] - corners[2])
    far = np.linalg.norm(m.vertices[:n, None] - corners[None], axis=2).min(axis=1) > 1.5 * width
    assert moved[~far].max() > 0.2  # the lids did move
    assert moved[far].max() < 1e-9 and np.isfinite(chin).all()
    original = np.vstack([res.similarity.apply(SCALE * v), m.vertices[n:]])
    assert turned_over_area(m.triangles, original, m.vertices) == 0.0


def _settled(model, expression: str | None):
    sim = Simulator(model, wrinkles=False)
    state, control = model.rest_state(), FaceControl(model)
    if expression:
        apply_expression(control, expression)
    for _ in range(40):
        sim.step(state, control)
    sim.settle(state, control)
    return state.positions


@pytest.fixture(scope="module")
def default_import():
    """The built-in face (resolution 0) onto the shut synthetic head, compiled."""
    reference = default_rig(0)
    head, lms = closed_head(synthetic_rig(48, 44))
    res = transfer_rig(reference, head, lms)
    return res, compile_model(res.rig)


def test_presets_move_the_landmarks_the_right_way_without_folds(default_import) -> None:
    res, model = default_import
    m = res.rig.mesh
    rest = np.asarray(model.rest)
    lm = m.landmarks
    y = lambda p, n: float(p[lm[n], 1] - rest[lm[n], 1])  # noqa: E731
    smile = _settled(model, "happiness")
    assert y(smile, "mouth_corner_l") > 0.1 and y(smile, "mouth_corner_r") > 0.1
    surprise = _settled(model, "surprise")
    assert y(surprise, "brow_mid_l") > 0.1 and y(surprise, "chin") < -0.2
    anger = _settled(model, "anger")
    assert y(anger, "brow_inner_l") < 0.0 and y(anger, "brow_inner_r") < 0.0
    assert model.rig.integrator == "implicit"  # an imported head runs with the fold guard
    folds = {"happiness": smile, "anger": anger}
    folds.update({e: _settled(model, e) for e in ("sadness", "fear", "disgust")})
    # (surprise folds ~1 cm2 under the synthetic head's chin as the jaw drops: docs/import-face.md)
    assert {e: round(turned_over_area(m.triangles, rest, p), 3) for e, p in folds.items()} == dict.fromkeys(folds, 0.0)


def test_an_imported_head_takes_the_presets_of_a_face_without_teeth(default_import) -> None:
    """Its fear keeps the jaw shut (a dropped jaw shows a dark hole), and still raises the inner
    brows and stretches the lips on the transferred rig."""
    from sim.facs import preset_face

    res, model = default_import
    assert res.rig.presets == IMPORTED_PRESETS
    rest = np.asarray(model.rest)
    lm = res.rig.mesh.landmarks
    sim, state, control = Simulator(model, wrinkles=False), model.rest_state(), FaceControl(model)
    apply_expression(control, "fear", 1.0, preset_face(res.rig))
    assert control.get("jaw") == 0.0
    for _ in range(40):
        sim.step(state, control)
    sim.settle(state, control)
    p = state.positions
    assert p[lm["brow_inner_l"], 1] - rest[lm["brow_inner_l"], 1] > 0.05
    width = lambda q: np.linalg.norm(q[lm["mouth_corner_l"]] - q[lm["mouth_corner_r"]])  # noqa: E731
    assert width(p) > width(rest) + 0.1
    assert abs(p[lm["chin"], 1] - rest[lm["chin"], 1]) < 0.1


def test_a_layer_under_the_skin_is_found_as_cavity() -> None:
    """Two coaxial sheets seen from a cylinder chart: the inner one (a mouth's lining behind the
    lips) lies under the outer and is hidden; the outer, and a lone sheet, are not."""
    from sim.face.transfer.cylinder import Cylinder
    from sim.face.transfer.flatten import CylinderChart, flat_triangulation, hidden_under

    th, h = np.meshgrid(np.linspace(-0.6, 0.6, 13), np.linspace(-2.0, 2.0, 9))
    grid = np.arange(th.size).reshape(th.shape)
    a, b, c, d = grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1], grid[1:, 1:]
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([b, d, c], -1).reshape(-1, 3)])
    sheet = lambda r: np.stack([r * np.sin(th.ravel()), h.ravel(), r * np.cos(th.ravel())], 1)  # noqa: E731
    verts = np.vstack([sheet(8.0), sheet(7.5)])
    both = np.vstack([tris, tris + th.size])
    chart = CylinderChart.facing(Cylinder(np.zeros(3), np.array([0.0, 1.0, 0.0]), 8.0), np.array([0.0, 0.0, 1.0]))
    uv, _, keep = flat_triangulation(chart, verts, both)
    hidden = hidden_under(chart, verts, both, uv, keep, 0.1)
    assert not hidden[:th.size].any() and hidden[th.size:].all()
    uv1, _, keep1 = flat_triangulation(chart, verts[th.size:], tris)
    assert not hidden_under(chart, verts[th.size:], tris, uv1, keep1, 0.1).any()


def test_a_lid_line_traced_past_the_corner_has_its_lids_meet_at_its_end() -> None:
    """The lids meet where the cut lid line ends, whichever vertex the corner landmark names: a
    line traced one edge past the inner corner (as one snapped to a scan's vertices can start, up
    and towards the nose) left the landmark on the line's second vertex, and the eye's loop, split
    there into the lids, began the lower lid's margin with that vertex of the upper one and went back
    to the line's start (the lid contact's rows, and the rims the eyes are seated by)."""
    import dataclasses

    from sim.face.transfer.lids import slit_sides
    from sim.smoothness import margin_rows, out_of_order

    reference = synthetic_rig(48, 44)
    head, lms = closed_head(reference)
    v, t = head.vertices, head.triangles
    openings = dict(lms.openings)
    for side in "lr":
        line = [int(x) for x in openings[f"eye_{side}"]]
        inner, outer = int(lms.entries[f"eye_inner_{side}"]), int(lms.entries[f"eye_outer_{side}"])
        axis = v[outer] - v[inner]
        ring = [int(n) for n in np.unique(t[(t == inner).any(axis=1)]) if n not in line]
        past = ring[int(np.argmin([(v[n] - v[inner]) @ axis - (v[n, 1] - v[inner, 1]) for n in ring]))]
        openings[f"eye_{side}"] = np.asarray([past, *line] if line[0] == inner else [*line, past])
    res = transfer_rig(reference, head, dataclasses.replace(lms, openings=openings))
    m = res.rig.mesh
    rows = margin_rows(m)
    for k, side in enumerate("lr"):
        path, _ = slit_sides(m.eye_loops[k])
        assert m.landmarks[f"eye_inner_{side}"] in (path[0], path[-1])
        for name in ("upper", "lower"):  # each margin runs from corner to corner without turning back
            assert out_of_order(m.vertices, m.vertices, rows[f"eye_{side}_{name}"]) == 0, (side, name)
    assert any("put on the end of its cut line" in n for n in res.notes)
