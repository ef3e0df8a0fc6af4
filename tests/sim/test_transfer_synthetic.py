"""Transfer the synthetic reference rig onto transformed, re-meshed copies of itself (known
answer) and check the error cases, independently of the default face."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim.face.transfer.carry import muscle_points
from sim.face.transfer.landmarks import TransferError, parse_landmarks
from sim.face.transfer.meshfile import from_arrays
from sim.face.transfer.pipeline import TransferOptions, transfer_rig
from sim.face.transfer.synthetic import synthetic_mesh, synthetic_rig

ROT = Rotation.from_euler("xyz", [20, -35, 60], degrees=True).as_matrix()
OFFSET = np.array([3.0, -40.0, 7.0])
# Points of the rig (skin and up to 1.3 cm under it) land within this of where the known
# transform puts them, in cm of the project frame; 12% anisotropy, different vertex count.
TOLERANCE_CM = 0.3


@pytest.fixture(scope="module")
def reference():
    return synthetic_rig(48, 44)


def _target(reference, stretch=(1.12, 0.93, 1.05), n=(70, 58), scale=10.0):
    v, t, _ = synthetic_mesh(*n, full_head=True)
    affine = scale * ROT @ np.diag(stretch)
    head = from_arrays(v @ affine.T + OFFSET, t, "head.obj")
    points = {k: (reference.mesh.landmark(k) @ affine.T + OFFSET).tolist() for k in reference.mesh.landmarks}
    return head, points, lambda p: np.asarray(p) @ affine.T + OFFSET


@pytest.fixture(scope="module")
def transferred(reference):
    head, points, known = _target(reference)
    # the correspondence alone (the eyes seated on the head's own lids are tests/sim/test_transfer_eyes.py's)
    return transfer_rig(reference, head, parse_landmarks(points, "lm.json"), name="head",
                        options=TransferOptions(seat_eyes=False)), known


def test_muscles_recovered_after_undoing_the_known_transform(reference, transferred) -> None:
    res, known = transferred
    assert set(res.rig.muscles) == set(reference.muscles)
    for ch, parts in reference.muscles.items():
        for before, after in zip(parts, res.rig.muscles[ch]):
            expected = res.similarity.apply(known(muscle_points(before)))
            err = np.linalg.norm(muscle_points(after) - expected, axis=1)
            assert err.max() < TOLERANCE_CM, (ch, before.name, err)


def test_eyes_jaw_and_landmarks_follow(reference, transferred) -> None:
    res, known = transferred
    mesh = res.rig.mesh
    sim = res.similarity
    assert np.linalg.norm(mesh.eye_centers - sim.apply(known(reference.mesh.eye_centers)), axis=1).max() < TOLERANCE_CM
    assert mesh.eye_radius == pytest.approx(reference.mesh.eye_radius, rel=0.15)
    # the hinge lies well off the mask; a looser bound
    assert np.linalg.norm(mesh.jaw_pivot - sim.apply(known(reference.mesh.jaw_pivot))) < 3 * TOLERANCE_CM
    assert abs(mesh.jaw_axis @ [1.0, 0.0, 0.0]) > 0.99
    # landmarks are vertices of the new mesh: within one edge of where they belong
    edge = np.linalg.norm(mesh.vertices[mesh.triangles[:, 1]] - mesh.vertices[mesh.triangles[:, 0]], axis=1).max()
    for name in reference.mesh.landmarks:
        expected = sim.apply(known(reference.mesh.landmark(name)))
        assert np.linalg.norm(mesh.landmark(name) - expected) < edge, name


def test_new_mesh_is_in_the_project_frame(reference, transferred) -> None:
    """cm, +Y up, looking along +Z, +X = the face's own left, whatever the file's frame."""
    res, _ = transferred
    m = res.rig.mesh
    assert m.landmark("forehead_center")[1] > m.landmark("chin")[1] + 15
    assert m.landmark("eye_outer_l")[0] > m.landmark("eye_outer_r")[0] + 7
    assert m.landmark("nose_tip")[2] > m.landmark("eye_outer_l")[2] + 2
    assert res.similarity.scale == pytest.approx(0.1, rel=0.1)  # the file was in mm


def test_back_of_head_is_held_and_face_is_free(transferred) -> None:
    res, _ = transferred
    m = res.rig.mesh
    behind = m.vertices[:, 2] < -2
    assert m.held[behind].all()
    assert not m.held[m.landmarks["mouth_corner_l"]] and not m.held[m.landmarks["cheek_r"]]
    assert m.jaw_weight[m.landmarks["chin"]] > 0.9 and m.jaw_weight[m.landmarks["forehead_center"]] == 0
    assert m.regions["forehead"][m.landmarks["forehead_center"]]


def test_openings_are_found_around_the_right_landmarks(transferred) -> None:
    res, _ = transferred
    m = res.rig.mesh
    for loop, lm in ((m.eye_loops[0], "upper_lid_l"), (m.eye_loops[1], "upper_lid_r"),
                     (m.mouth_loop, "mouth_corner_l")):
        assert m.landmarks[lm] in set(loop.tolist())


def test_already_aligned_copy_is_reproduced_exactly(reference) -> None:
    v, t = reference.mesh.vertices, reference.mesh.triangles
    points = {k: int(i) for k, i in reference.mesh.landmarks.items()}
    res = transfer_rig(reference, from_arrays(v, t), parse_landmarks(points))
    for ch, parts in reference.muscles.items():
        for before, after in zip(parts, res.rig.muscles[ch]):
            assert np.allclose(muscle_points(after), muscle_points(before), atol=1e-6)
    assert np.array_equal(res.rig.mesh.held, reference.mesh.held)


# --- errors -------------------------------------------------------------------------------------

def _points(reference):
    return {k: int(i) for k, i in reference.mesh.landmarks.items()}


def test_missing_landmark_is_named(reference) -> None:
    pts = _points(reference)
    del pts["nose_tip"], pts["chin"]
    with pytest.raises(TransferError, match=r"lm\.json: missing landmark\(s\) nose_tip, chin"):
        transfer_rig(reference, from_arrays(reference.mesh.vertices, reference.mesh.triangles),
                     parse_landmarks(pts, "lm.json"))


def test_landmark_off_the_surface_is_named(reference) -> None:
    pts = {k: reference.mesh.landmark(k).tolist() for k in reference.mesh.landmarks}
    pts["chin"] = (reference.mesh.landmark("chin") + [0, 0, 3.0]).tolist()
    with pytest.raises(TransferError, match="'chin' lies .* off the surface of face.obj"):
        transfer_rig(reference, from_arrays(reference.mesh.vertices, reference.mesh.triangles, "face.obj"),
                     parse_landmarks(pts, "lm.json"))


def test_swapped_sides_are_refused(reference) -> None:
    pts = _points(reference)
    swapped = {(k[:-1] + ("r" if k.endswith("_l") else "l")) if k[-2:] in ("_l", "_r") else k: v
               for k, v in pts.items()}
    with pytest.raises(TransferError, match="face's own left"):
        transfer_rig(reference, from_arrays(reference.mesh.vertices, reference.mesh.triangles),
                     parse_landmarks(swapped, "lm.json"))


def test_mirrored_mesh_is_refused(reference) -> None:
    m = reference.mesh
    with pytest.raises(TransferError, match="mirrored"):
        transfer_rig(reference, from_arrays(m.vertices * [-1, 1, 1], m.triangles[:, ::-1]),
                     parse_landmarks(_points(reference), "lm.json"))


def test_scrambled_landmarks_are_not_a_face(reference) -> None:
    pts = _points(reference)
    names = sorted(pts)
    rng = np.random.default_rng(0)
    vals = [pts[n] for n in names]
    keep = {"forehead_center", "chin", "nose_tip", "eye_outer_l", "eye_outer_r"}
    movable = [i for i, n in enumerate(names) if n not in keep]
    perm = rng.permutation(movable)
    for i, j in zip(movable, perm):
        pts[names[i]] = vals[j]
    with pytest.raises(TransferError, match="do not have the layout of a face"):
        transfer_rig(reference, from_arrays(reference.mesh.vertices, reference.mesh.triangles),
                     parse_landmarks(pts, "lm.json"))


def test_closed_mouth_needs_an_opening_or_a_declaration(reference) -> None:
    """Fill the mouth hole: refused naming the mouth; declaring a loop makes it acceptable."""
    m = reference.mesh
    loop = m.mouth_loop
    centre = len(m.vertices)
    verts = np.vstack([m.vertices, m.vertices[loop].mean(axis=0)])
    fan = np.stack([np.roll(loop, -1), loop, np.full(len(loop), centre)], axis=1)
    tris = np.vstack([m.triangles, fan])
    with pytest.raises(TransferError, match=r"closed.obj: no opening for the mouth .*openings\.mouth in lm\.json: the rim.s loop if the lips stand apart.*the line where they meet"):
        transfer_rig(reference, from_arrays(verts, tris, "closed.obj"), parse_landmarks(_points(reference), "lm.json"))
    data = {"landmarks": _points(reference), "openings": {"mouth": [int(i) for i in loop]}}
    res = transfer_rig(reference, from_arrays(verts, tris, "closed.obj"), parse_landmarks(data, "lm.json"))
    assert np.array_equal(res.rig.mesh.mouth_loop, loop)


def test_non_manifold_face_is_refused(reference) -> None:
    m = reference.mesh
    tri = m.triangles[np.nonzero((m.triangles == m.landmarks["cheek_l"]).any(axis=1))[0][0]]
    extra = len(m.vertices)
    verts = np.vstack([m.vertices, m.vertices[tri].mean(axis=0) + [0, 0, 0.5]])
    tris = np.vstack([m.triangles, [[tri[0], tri[1], extra]]])
    with pytest.raises(TransferError, match="bad.ply: the face is not manifold"):
        transfer_rig(reference, from_arrays(verts, tris, "bad.ply"), parse_landmarks(_points(reference), "lm.json"))


def test_a_non_manifold_edge_is_named_by_the_files_own_vertices(reference) -> None:
    """The refusal names the edge by the file's vertex numbers (0-based, as the landmark file
    counts), whatever the import renumbers: here the file splits its vertices at a texture seam
    (each triangle with its own three vertices, welded back on reading) and holds a loose part
    first, which the import drops. It named the renumbered vertices, which the file does not have."""
    m = reference.mesh
    tri = m.triangles[np.nonzero((m.triangles == m.landmarks["cheek_l"]).any(axis=1))[0][0]]
    verts = np.vstack([m.vertices, m.vertices[tri].mean(axis=0) + [0, 0, 0.5]])
    tris = np.vstack([m.triangles, [[tri[0], tri[1], len(m.vertices)]]])
    loose = np.array([[30.0, 0.0, 0.0], [31.0, 0.0, 0.0], [30.0, 1.0, 0.0]])  # a hair card, far off
    soup = np.vstack([loose, verts[tris.ravel()]])  # every triangle its own vertices, after the card
    soup_tris = np.vstack([[0, 1, 2], 3 + np.arange(3 * len(tris)).reshape(-1, 3)])
    points = {k: m.landmark(k).tolist() for k in m.landmarks}  # as points: the soup renumbers every vertex
    with pytest.raises(TransferError, match="not manifold") as err:
        transfer_rig(reference, from_arrays(soup, soup_tris, "bad.obj"), parse_landmarks(points, "lm.json"))
    named = [int(x) for x in re.findall(r"between vertices (\d+) and (\d+)", str(err.value))[0]]
    ends = {tuple(np.round(soup[i], 9)) for i in named}
    assert ends == {tuple(np.round(m.vertices[tri[0]], 9)), tuple(np.round(m.vertices[tri[1]], 9))}


def test_inward_winding_is_flipped(reference) -> None:
    m = reference.mesh
    res = transfer_rig(reference, from_arrays(m.vertices, m.triangles[:, ::-1]), parse_landmarks(_points(reference)))
    assert res.flipped_winding
    n = np.cross(*(res.rig.mesh.vertices[res.rig.mesh.triangles[:, k]] - res.rig.mesh.vertices[res.rig.mesh.triangles[:, 0]] for k in (1, 2)))
    assert n.sum(axis=0)[2] > 0


def test_closed_lips_are_cut_open_along_a_declared_lip_line(reference) -> None:
    """A head scanned with the mouth closed: the file names the lip line (corner to corner); the
    importer cuts a slit there, the lower lip takes the copies and the lower-lip landmark."""
    from sim.face.transfer.geometry import boundary_loops

    v, t, param = synthetic_mesh(64, 45, full_head=True, mouth_open=False)
    line = np.nonzero((np.abs(param[:, 1] + 5.0) < 0.01) & (np.abs(param[:, 0]) < 0.3))[0]
    line = line[np.argsort(param[line, 0])]
    pts = {k: reference.mesh.landmark(k).tolist() for k in reference.mesh.landmarks}
    pts.update(mouth_corner_r=int(line[0]), mouth_corner_l=int(line[-1]),
               upper_lip_center=int(line[3]), lower_lip_center=int(line[3]))
    data = {"landmarks": pts, "openings": {"mouth": line.tolist()}}
    res = transfer_rig(reference, from_arrays(v, t), parse_landmarks(data, "lm.json"))
    m = res.rig.mesh
    assert len(m.vertices) == len(v) + len(line) - 2
    assert any(set(lp.tolist()) == set(m.mouth_loop.tolist()) for lp in boundary_loops(m.triangles))
    upper, lower = m.mouth_loop[1:len(line) - 1], m.mouth_loop[len(line):]
    assert not m.regions["lower_lip"][upper].any() and m.regions["lower_lip"][lower[1:-1]].all()
    assert m.landmarks["lower_lip_center"] in set(lower.tolist())
    assert m.landmarks["upper_lip_center"] == line[3]
    assert np.allclose(m.vertices[lower], m.vertices[upper[::-1]])  # a slit: closed at rest


def test_declared_opening_must_follow_mesh_edges(reference) -> None:
    v, t, param = synthetic_mesh(64, 45, full_head=True, mouth_open=False)
    line = np.nonzero((np.abs(param[:, 1] + 5.0) < 0.01) & (np.abs(param[:, 0]) < 0.3))[0]
    pts = {k: reference.mesh.landmark(k).tolist() for k in reference.mesh.landmarks}
    data = {"landmarks": pts, "openings": {"mouth": [int(line[0]), int(line[3]), int(line[-1])]}}
    with pytest.raises(TransferError, match=r"lm\.json: opening 'mouth': vertices .* are not joined by a mesh edge"):
        transfer_rig(reference, from_arrays(v, t), parse_landmarks(data, "lm.json"))


def test_a_head_too_dense_to_simulate_live_is_told_what_to_change() -> None:
    """A scan of 45,000 vertices imported (in 192 s) into a rig whose every simulation step costs
    17 x the reference face's, without a word; now one line says so and what to do. A head of the
    scanned identity's density (11,382 vertices, 4.2 x) is not warned about."""
    from sim.face.transfer.pipeline import dense_warning

    line = dense_warning(45254, 2709)
    assert "45254" in line and "decimate" in line and "\n" not in line
    assert dense_warning(11382, 2709) == ""
