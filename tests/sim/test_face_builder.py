"""The procedural default face: topology, symmetry, anatomy and rig facts, at every resolution."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face.builder import build_face_mesh
from sim.model import FaceMesh

SIDED = [
    "brow_inner", "brow_mid", "brow_outer", "eye_inner", "eye_outer", "upper_lid", "lower_lid",
    "nose_wing", "mouth_corner", "cheek", "jaw_angle",
]
MIDLINE = [
    "glabella", "forehead_center", "nose_bridge", "nose_tip", "subnasale", "upper_lip_top",
    "upper_lip_center", "lower_lip_center", "lower_lip_bottom", "chin",
]
REGIONS = [
    "forehead", "brow_l", "brow_r", "upper_lid_l", "upper_lid_r", "lower_lid_l", "lower_lid_r",
    "nose", "upper_lip", "lower_lip", "cheek_l", "cheek_r", "chin", "jaw",
]
COUNTS = {0: (550, 900), 1: (2200, 3800), 2: (9000, 15000)}


@pytest.fixture(scope="module", params=[0, 1, 2])
def mesh(request: pytest.FixtureRequest) -> FaceMesh:
    return build_face_mesh(request.param)


@pytest.fixture(scope="module")
def mesh0() -> FaceMesh:
    return build_face_mesh(0)


def _edges(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def _mirror_map(m: FaceMesh) -> np.ndarray:
    """For each vertex, the index of the vertex at its mirror position (-x, y, z), or -1."""
    key = {tuple(np.round(p, 9)): i for i, p in enumerate(m.vertices)}
    return np.array([key.get(tuple(np.round(p * [-1, 1, 1], 9)), -1) for p in m.vertices])


def test_counts_grow_with_resolution() -> None:
    sizes = [len(build_face_mesh(r).vertices) for r in (0, 1, 2)]
    for r, n in enumerate(sizes):
        assert COUNTS[r][0] <= n <= COUNTS[r][1]
    assert sizes[0] < sizes[1] < sizes[2]


def test_deterministic(mesh0: FaceMesh) -> None:
    again = build_face_mesh(0)
    assert np.array_equal(again.vertices, mesh0.vertices)
    assert np.array_equal(again.triangles, mesh0.triangles)


def test_exact_mirror_symmetry(mesh: FaceMesh) -> None:
    mirror = _mirror_map(mesh)
    assert (mirror >= 0).all()
    assert np.array_equal(mesh.vertices[mirror], mesh.vertices * [-1.0, 1.0, 1.0])
    # Triangles mirror to triangles (with reversed winding).
    tris = {tuple(sorted(t)) for t in mesh.triangles.tolist()}
    assert all(tuple(sorted(mirror[t])) in tris for t in mesh.triangles)
    assert np.array_equal(mesh.held, mesh.held[mirror])
    assert np.allclose(mesh.jaw_weight, mesh.jaw_weight[mirror])


def test_landmarks_present_and_mirrored(mesh: FaceMesh) -> None:
    mirror = _mirror_map(mesh)
    for name in SIDED:
        left, right = mesh.landmarks[name + "_l"], mesh.landmarks[name + "_r"]
        assert mirror[left] == right
        assert mesh.vertices[left, 0] > 0.0 > mesh.vertices[right, 0]
    for name in MIDLINE:
        assert mesh.vertices[mesh.landmarks[name], 0] == 0.0


def test_same_landmark_places_at_every_resolution(mesh: FaceMesh, mesh0: FaceMesh) -> None:
    for name in mesh0.landmarks:
        assert np.linalg.norm(mesh.landmark(name) - mesh0.landmark(name)) < 1e-9, name


def test_anatomical_order(mesh0: FaceMesh) -> None:
    y = {k: mesh0.landmark(k)[1] for k in mesh0.landmarks}
    assert y["forehead_center"] > y["glabella"] > y["nose_bridge"] > y["nose_tip"]
    assert min(y["brow_inner_l"], y["brow_mid_l"], y["brow_outer_l"]) > y["upper_lid_l"] > y["lower_lid_l"]
    assert y["lower_lid_l"] > y["nose_tip"] > y["subnasale"] > y["upper_lip_top"]
    assert y["upper_lip_top"] > y["upper_lip_center"] > y["lower_lip_center"] > y["lower_lip_bottom"]
    assert y["lower_lip_bottom"] > y["chin"]
    assert y["cheek_l"] < y["eye_inner_l"] and y["cheek_l"] > y["mouth_corner_l"]
    x = {k: mesh0.landmark(k)[0] for k in mesh0.landmarks}
    assert x["eye_outer_l"] > x["eye_inner_l"] > x["brow_inner_l"] * 0.5
    assert x["brow_outer_l"] > x["brow_mid_l"] > x["brow_inner_l"]
    z = mesh0.vertices[:, 2]
    assert np.argmax(z) == mesh0.landmarks["nose_tip"]
    assert mesh0.landmark("upper_lip_center")[2] > mesh0.landmark("chin")[2]


def _d(m: FaceMesh, a: str, b: str, axis: int | None = None) -> float:
    d = m.landmark(a) - m.landmark(b)
    return float(abs(d[axis]) if axis is not None else np.linalg.norm(d))


@pytest.mark.parametrize(
    "a, b, axis, expected",
    [
        ("eye_outer_l", "eye_outer_r", 0, 9.1),
        ("eye_inner_l", "eye_inner_r", 0, 3.3),
        ("eye_outer_l", "eye_inner_l", None, 3.1),
        ("upper_lid_l", "lower_lid_l", 1, 1.1),
        ("nose_wing_l", "nose_wing_r", 0, 3.5),
        ("nose_bridge", "subnasale", 1, 5.5),
        ("subnasale", "nose_tip", 2, 2.0),
        ("mouth_corner_l", "mouth_corner_r", 0, 5.4),
        ("subnasale", "upper_lip_center", 1, 2.2),
        ("subnasale", "chin", 1, 7.2),
        ("nose_bridge", "chin", 1, 12.1),
        ("jaw_angle_l", "jaw_angle_r", 0, 9.7),
    ],
)
def test_proportions_match_reference(mesh0: FaceMesh, a: str, b: str, axis: int | None, expected: float) -> None:
    assert _d(mesh0, a, b, axis) == pytest.approx(expected, rel=0.15)


def test_face_width_at_cheekbones(mesh0: FaceMesh) -> None:
    v = mesh0.vertices
    band = (v[:, 1] > -3.0) & (v[:, 1] < 0.0)
    assert 2 * v[band, 0].max() == pytest.approx(13.7, rel=0.15)


def test_edge_manifold_and_oriented(mesh: FaceMesh) -> None:
    edges, count = _edges(mesh.triangles)
    assert count.max() <= 2
    # Consistent orientation: every interior edge is used once in each direction.
    t = mesh.triangles
    directed = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)
    assert len(np.unique(t.ravel())) == len(mesh.vertices)


def test_normals_point_out_of_the_face(mesh: FaceMesh) -> None:
    v, t = mesh.vertices, mesh.triangles
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    c = v[t].mean(axis=1)
    central = (np.abs(c[:, 0]) < 4.0) & (c[:, 1] > -10.0) & (c[:, 1] < 6.0)
    assert (n[central, 2] > 0).mean() > 0.85
    # Everywhere the normal points away from the head's vertical axis (z = -8) on average.
    outward = (n[:, 0] * c[:, 0] + n[:, 2] * (c[:, 2] + 8.0)) > 0
    assert outward.mean() > 0.95


def test_no_degenerate_triangles(mesh: FaceMesh) -> None:
    v, t = mesh.vertices, mesh.triangles
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.max([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1), np.linalg.norm(a - c, axis=1)], axis=0)
    # area / longest^2 is 0.43 for an equilateral triangle and 0 for a degenerate one.
    assert (area / longest**2).min() > 0.02


def test_eye_and_mouth_loops_are_boundary_loops(mesh: FaceMesh) -> None:
    edges, count = _edges(mesh.triangles)
    boundary = {tuple(e) for e in edges[count == 1].tolist()}
    for loop in (*mesh.eye_loops, mesh.mouth_loop):
        assert len(set(loop.tolist())) == len(loop) >= 12
        for i, j in zip(loop.tolist(), np.roll(loop, -1).tolist()):
            assert tuple(sorted((i, j))) in boundary
    left = mesh.vertices[mesh.eye_loops[0]]
    assert (left[:, 0] > 0).all() and (mesh.vertices[mesh.eye_loops[1]][:, 0] < 0).all()
    assert mesh.landmarks["mouth_corner_l"] in mesh.mouth_loop
    assert mesh.landmarks["upper_lid_l"] in mesh.eye_loops[0]


def test_lids_rest_on_the_eyeballs(mesh0: FaceMesh) -> None:
    assert mesh0.eye_radius == pytest.approx(1.2, rel=0.1)
    assert mesh0.eye_centers[0, 0] > 0 and np.allclose(mesh0.eye_centers[1], mesh0.eye_centers[0] * [-1, 1, 1])
    for side, loop in enumerate(mesh0.eye_loops):
        p = mesh0.vertices[loop]
        d = np.linalg.norm(p - mesh0.eye_centers[side], axis=1)
        mid = np.abs(p[:, 0] - mesh0.eye_centers[side, 0]) < 0.6  # the middle of the lids
        assert np.all(np.abs(d[mid] - mesh0.eye_radius) < 0.15)
        assert np.all(d > mesh0.eye_radius * 0.98)  # never inside the eyeball


def test_held_is_outer_border_only(mesh: FaceMesh) -> None:
    edges, count = _edges(mesh.triangles)
    on_boundary = np.zeros(len(mesh.vertices), bool)
    on_boundary[edges[count == 1].ravel()] = True
    holes = np.concatenate([*mesh.eye_loops, mesh.mouth_loop])
    assert mesh.held.any()
    assert on_boundary[mesh.held].all()
    assert not mesh.held[holes].any()
    assert mesh.held[mesh.vertices[:, 1] > mesh.landmark("forehead_center")[1] + 1.5].mean() > 0.2


def test_jaw_weights(mesh: FaceMesh) -> None:
    w, lm = mesh.jaw_weight, mesh.landmarks
    assert ((w >= 0) & (w <= 1)).all()
    assert w[lm["chin"]] == pytest.approx(1.0) and w[lm["lower_lip_center"]] == pytest.approx(1.0)
    for name in ("upper_lip_center", "upper_lip_top", "subnasale", "nose_tip", "cheek_l"):
        assert w[lm[name]] == 0.0
    assert (w[mesh.regions["upper_lip"]] == 0).all()
    assert (w[mesh.vertices[:, 1] > mesh.landmark("upper_lip_center")[1]] == 0).all()
    assert (w[mesh.held] < 0.5).all()
    assert np.linalg.norm(mesh.jaw_axis) == pytest.approx(1.0)


def test_positive_jaw_rotation_opens_the_mouth(mesh0: FaceMesh) -> None:
    axis, pivot, angle = mesh0.jaw_axis, mesh0.jaw_pivot, 0.2
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rot = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    chin = rot @ (mesh0.landmark("chin") - pivot) + pivot
    assert chin[1] < mesh0.landmark("chin")[1] - 0.5
    assert pivot[2] < mesh0.landmark("eye_outer_l")[2] - 3.0
    assert mesh0.landmark("nose_tip")[1] - 1.5 < pivot[1] < mesh0.landmark("eye_inner_l")[1]


def test_regions(mesh: FaceMesh) -> None:
    n = len(mesh.vertices)
    for name in REGIONS:
        r = mesh.regions[name]
        assert r.dtype == bool and r.shape == (n,) and r.sum() >= 3, name
    x = mesh.vertices[:, 0]
    for name in REGIONS:
        if name.endswith("_l"):
            assert (x[mesh.regions[name]] > 0).all()
    assert mesh.regions["nose"][mesh.landmarks["nose_tip"]]
    assert mesh.regions["chin"][mesh.landmarks["chin"]]
    assert mesh.regions["upper_lid_l"][mesh.landmarks["upper_lid_l"]]
    assert mesh.regions["lower_lid_l"][mesh.landmarks["lower_lid_l"]]
    assert mesh.regions["cheek_l"][mesh.landmarks["cheek_l"]]
    assert not (mesh.regions["upper_lip"] & mesh.regions["lower_lip"]).any()


def test_finer_around_eyes_and_mouth_than_on_forehead(mesh0: FaceMesh) -> None:
    v, t = mesh0.vertices, mesh0.triangles
    e, _ = _edges(t)
    length = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    mid = v[e].mean(axis=1)
    near_eye = np.linalg.norm(mid[:, :2] - mesh0.eye_centers[0, :2], axis=1) < 1.8
    near_mouth = np.hypot(mid[:, 0] / 3.0, (mid[:, 1] - mesh0.landmark("upper_lip_center")[1]) / 0.8) < 1.0
    side = (np.abs(mid[:, 0]) > 4.8) & (mid[:, 1] < -1.5) & (mid[:, 1] > -6.5)  # lateral cheek
    assert np.median(length[near_eye]) < 0.6 * np.median(length[side])
    assert np.median(length[near_mouth]) < 0.6 * np.median(length[side])


def test_uv_chart_is_flat_and_mirrored(mesh: FaceMesh) -> None:
    uv = mesh.uv
    assert uv is not None and uv.shape == (len(mesh.vertices), 2)
    assert np.array_equal(np.sign(uv[:, 0]), np.sign(mesh.vertices[:, 0]))
    t = mesh.triangles
    a, b, c = uv[t[:, 0]], uv[t[:, 1]], uv[t[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert (area > 0).all()  # counter-clockwise in the chart: no fold-overs


def test_bad_resolution_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="resolution"):
        build_face_mesh(3)


def test_wrinkle_lines_have_rows_on_both_sides(mesh0: FaceMesh) -> None:
    """Seed 003 section 2: every expressive wrinkle line has vertices on it and on either side
    within about 3 mm, so a furrow and its rolls can be shaped (only on its lateral side for a
    line whose medial roll is another line's)."""
    from sim.face.chart import ONE_SIDED, resample, wrinkle_lines

    uv = mesh0.uv
    assert uv is not None
    for name, line in wrinkle_lines().items():
        if name.startswith("crows_flank"):
            continue  # rows beside the crow's feet, not wrinkles
        if name.startswith("crows_feet"):
            line = line[:3]  # the rays fan out: only near the eye corner are they 3 mm apart
        every = resample(line, 0.2)
        pts = every[1:-1]
        tang = np.gradient(every, axis=0)[1:-1]  # short lines (perioral) have one inner point
        tang /= np.linalg.norm(tang, axis=1, keepdims=True)
        for p, t in zip(pts, tang):
            rel = uv - p
            along = rel @ t
            across = rel @ np.array([-t[1], t[0]])
            near = np.abs(along) < 0.45
            assert (near & (np.abs(across) < 0.05)).any(), (name, p)
            assert name in ONE_SIDED or (near & (across > 0.1) & (across < 0.4)).any(), (name, p)
            assert (near & (across < -0.1) & (across > -0.4)).any(), (name, p)
