"""The default face is a head: a held cranium, ears and neck around the simulated mask
(sim.face.head), stitched to the mask's border so the join stays closed when the face moves, in
adult proportions, never in front of the face, and only for the default rig."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim.face import default_model
from sim.face.head import hair_weight, head_shell, shell_for
from sim.facs import apply_expression
from sim.integrator import Simulator
from sim.face import default_rig
from sim.state import FaceControl, FaceState


def _outer_border_edges(tris: np.ndarray) -> set[tuple[int, int]]:
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    e.sort(axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    return {(int(a), int(b)) for a, b in u[c == 1]}


def _normals(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    c = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    return c / np.maximum(np.linalg.norm(c, axis=1, keepdims=True), 1e-12)


@pytest.fixture(scope="module")
def moved() -> dict[str, FaceState]:
    """The default face (resolution 0) held at rest, with the jaw fully open, and in three
    expressions (each dialled in over 30 steps)."""
    model = default_model(0)
    out = {}
    for name in ("rest", "jaw", "happiness", "surprise", "anger"):
        sim = Simulator(model)
        st = model.rest_state()
        for k in range(30):
            c = FaceControl(model)
            if name == "jaw":
                c.set("jaw", min(1.0, (k + 1) / 15))
            elif name != "rest":
                apply_expression(c, name, min(1.0, (k + 1) / 15))
            sim.step(st, c)
        out[name] = st
    return out


def test_head_proportions_and_mesh() -> None:
    rig = default_rig(0)
    shell = shell_for(rig)
    assert shell is not None
    v, t = shell.vertices, shell.triangles
    assert t.min() >= 0 and t.max() < len(v) and np.isfinite(v).all()
    assert ((shell.hair >= 0) & (shell.hair <= 1)).all() and shell.hair.max() == 1.0
    chin_y = rig.mesh.landmark("chin")[1]
    assert 21.0 < v[:, 1].max() - chin_y < 25.0  # vertex to chin ~23 cm
    assert 13.0 < np.ptp(v[v[:, 1] > -6.0, 0]) < 17.5  # breadth with the ears
    back = v[v[:, 1] > -6.0, 2].min()
    assert 17.0 < rig.mesh.landmark("glabella")[2] - back < 21.0  # glabella to the back ~19 cm
    assert v[:, 1].min() < chin_y - 5.0  # a neck below the chin


def test_neck_proportions() -> None:
    """An adult neck: ~11 cm wide and ~11-12 cm deep at mid-neck, narrower than the face at the
    cheekbones, leaning forward going up, widening towards the shoulders at its base."""
    rig = default_rig(0)
    shell = shell_for(rig)
    assert shell is not None
    v = shell.vertices
    tris = shell.triangles[: shell.head_triangles]  # cranium and neck, no ears
    e = np.unique(np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1), axis=0)

    def slab(y: float) -> np.ndarray:
        """The head's cross-section at height y: where its edges cross the plane."""
        a, b = v[e[:, 0]], v[e[:, 1]]
        cross = (a[:, 1] - y) * (b[:, 1] - y) < 0
        t = (y - a[cross, 1]) / (b[cross, 1] - a[cross, 1])
        return a[cross] + t[:, None] * (b[cross] - a[cross])

    mid = slab(-15.0)
    assert 10.0 < np.ptp(mid[:, 0]) < 12.5
    assert 10.5 < np.ptp(mid[:, 2]) < 12.5
    face = rig.mesh.vertices
    cheeks = face[np.abs(face[:, 1] - rig.mesh.landmark("cheek_l")[1]) < 0.5]
    assert np.ptp(mid[:, 0]) < np.ptp(cheeks[:, 0])
    top, low = slab(-12.0), slab(-18.0)
    assert top[:, 2].mean() - low[:, 2].mean() > 0.5  # the neck's top is ahead of its base
    assert np.ptp(slab(-23.0)[:, 0]) > np.ptp(mid[:, 0]) + 3.0  # the trapezius widening


def test_join_is_closed() -> None:
    """The shell's first ring is the mask's outer border: every border edge of the mask is an edge
    of exactly one shell triangle, so mask and head together leave open only the eyes, the mouth
    and the neck's base (and the ears' roots, inside the head)."""
    for res in (0, 2):
        rig = default_rig(res)
        shell = shell_for(rig)
        assert shell is not None
        n = len(rig.mesh.vertices)
        joined = shell.joined_triangles(n)[: shell.head_triangles]
        mask_border = _outer_border_edges(np.asarray(rig.mesh.triangles))
        outer = {e for e in mask_border if e[0] in set(shell.ring_mask.tolist())}
        assert len(outer) == len(shell.ring)
        both = _outer_border_edges(np.vstack([rig.mesh.triangles, joined]))
        assert not (outer & both)  # closed: no outer border edge is open any more
        assert np.array_equal(shell.vertices[shell.ring], rig.mesh.vertices[shell.ring_mask])


def test_join_stays_closed_and_unfolded_when_the_face_moves(moved: dict[str, FaceState]) -> None:
    """Posed on a moving face the ring sits on the mask's border exactly, and no triangle of the
    cranium and neck turns over (no tear, no fold) with the jaw open or in an expression."""
    rig = default_rig(0)
    shell = shell_for(rig)
    assert shell is not None
    k = shell.head_triangles
    rest_n = _normals(shell.vertices, shell.triangles[:k])
    for name, st in moved.items():
        p = shell.pose(st.surface)
        assert np.abs(p[shell.ring] - st.surface[shell.ring_mask]).max() == 0.0, name
        n = _normals(p, shell.triangles[:k])
        assert np.sum(n * rest_n, axis=1).min() > 0.0, name  # none turned over


def test_neck_follows_the_jaw(moved: dict[str, FaceState]) -> None:
    """Opening the mouth pulls the skin under the chin with the jaw (most of the chin's motion next
    to the border), fading to held down the neck and on the cranium."""
    rig = default_rig(0)
    mesh = rig.mesh
    shell = shell_for(rig)
    assert shell is not None
    st = moved["jaw"]
    chin = mesh.landmarks["chin"]
    chin_move = np.linalg.norm(st.surface[chin] - mesh.vertices[chin])
    assert chin_move > 1.5
    p = shell.pose(st.surface)
    d = np.linalg.norm(p - shell.vertices, axis=1)
    v = shell.vertices
    under_chin = (np.abs(v[:, 0]) < 1.5) & (v[:, 1] < -13.0) & (v[:, 1] > -14.5) & (v[:, 2] > -4.0)
    under_chin[shell.ring] = False
    assert under_chin.sum() >= 2
    assert d[under_chin].min() > 0.5 * chin_move
    assert d[v[:, 1] < -20.0].max() < 0.05 * chin_move  # blended to held down the neck
    assert d[v[:, 1] < -22.5].max() < 1e-9  # and its base stays
    assert d[v[:, 1] > -3.0].max() < 1e-9  # the cranium stays (its border is held)
    # at rest the posed head is the rest head
    assert np.abs(shell.pose(moved["rest"].surface) - v).max() < 0.05


def test_head_stays_behind_the_face(moved: dict[str, FaceState]) -> None:
    """Along the viewing direction no head vertex lies in front of the mask where the mask is
    (so the cranium never shows through the skin), at rest and with the jaw open."""
    mesh = default_rig(0).mesh
    shell = head_shell(mesh)
    from scipy.spatial import cKDTree

    off_ring = ~np.isin(shell.triangles, shell.ring).any(axis=1)
    for surface, verts in ((mesh.vertices, shell.vertices), (moved["jaw"].surface, shell.pose(moved["jaw"].surface))):
        tree = cKDTree(surface[:, :2])
        pose = np.vstack([verts[~np.isin(np.arange(len(verts)), shell.ring)],
                          verts[shell.triangles[off_ring]].mean(axis=1)])  # vertices and centroids
        d, i = tree.query(pose[:, :2])
        inside = (d < 0.3) & (np.abs(pose[:, 0]) < 5.5) & (pose[:, 1] > -11.0)
        assert inside.sum() > 50
        assert (pose[inside, 2] < surface[i[inside], 2] + 0.05).mean() > 0.99


def test_smooth_join_and_hairline() -> None:
    """Across the join the mask's and the head's triangles meet nearly flat (no crease), and the
    hair is a smooth function of place: skin on the join itself, and close vertices never differ
    by a jump (no stair-stepped hairline)."""
    rig = default_rig(0)
    mesh = rig.mesh
    shell = shell_for(rig)
    assert shell is not None
    n = len(mesh.vertices)
    allv = np.vstack([mesh.vertices, shell.vertices])
    joined = shell.joined_triangles(n)
    tm, ts = np.asarray(mesh.triangles), joined
    n_m, n_s = _normals(allv, tm), _normals(allv, ts)
    where: dict[tuple[int, int], list[int]] = {}
    for tris, tag in ((tm, 0), (ts, 1)):
        for i, (a, b, c) in enumerate(tris):
            for e in ((a, b), (b, c), (c, a)):
                where.setdefault((min(e), max(e)), [-1, -1])[tag] = i
    angles = [np.degrees(np.arccos(np.clip(n_m[i] @ n_s[j], -1.0, 1.0)))
              for i, j in where.values() if i >= 0 and j >= 0]
    assert len(angles) == len(shell.ring)
    assert np.max(angles) < 30.0 and np.mean(angles) < 10.0  # (a crease would be 40+; normals are shared)
    assert shell.hair[shell.ring].max() == 0.0
    # the hair comes from two coordinates (cm above the hairline, cm from the join) that the
    # renderer interpolates over each triangle: they change with distance, not by jumps
    tris = shell.triangles[: shell.head_triangles]
    e = np.unique(np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1), axis=0)
    length = np.linalg.norm(shell.vertices[e[:, 0]] - shell.vertices[e[:, 1]], axis=1)
    step = np.abs(shell.hair_coords[e[:, 0]] - shell.hair_coords[e[:, 1]])
    h = shell.hair[e]
    edge = ((h > 0.02) & (h < 0.98)).any(axis=1)  # along the hairline (elsewhere it is saturated)
    assert edge.sum() > 50
    assert (step[edge, 0] <= 3.0 * length[edge] + 0.05).all()
    assert (step[:, 1] <= 1.0 * length + 0.05).all()
    assert np.allclose(shell.hair, hair_weight(shell.hair_coords))
    v = shell.vertices
    area = 0.5 * np.linalg.norm(np.cross(v[tris[:, 1]] - v[tris[:, 0]], v[tris[:, 2]] - v[tris[:, 0]]), axis=1)
    scalp = np.sum(area * shell.hair[tris].mean(axis=1)) / area.sum()
    assert 0.2 < scalp < 0.6  # a scalp, not a bald or furry head


def test_ear_proportions() -> None:
    """Each ear spans brow level to nose-base level, stands just behind the jaw hinge, leans back
    ~15 degrees, sticks out of the head, and has a rim standing proud of its hollow."""
    rig = default_rig(0)
    mesh = rig.mesh
    shell = shell_for(rig)
    assert shell is not None
    first = int(shell.triangles[: shell.head_triangles].max()) + 1
    ears = shell.vertices[first:]
    brow_y = mesh.landmark("brow_mid_l")[1]
    nose_base_y = mesh.landmark("subnasale")[1]
    for side in (1.0, -1.0):
        ear = ears[ears[:, 0] * side > 0]
        out = ear[ear[:, 0] * side > np.percentile(ear[:, 0] * side, 40)]  # the outer, visible part
        assert abs(out[:, 1].max() - brow_y) < 0.8
        assert abs(out[:, 1].min() - nose_base_y) < 0.8
        front = out[:, 2].max()
        assert -1.5 < front - mesh.jaw_pivot[2] < 0.0  # just behind the hinge
        # lean: the ear's long axis (its lowest tenth, the lobe, to its highest, the helix's top)
        top = out[out[:, 1] >= np.percentile(out[:, 1], 90)].mean(axis=0)
        low = out[out[:, 1] <= np.percentile(out[:, 1], 10)].mean(axis=0)
        lean = np.degrees(np.arctan2(low[2] - top[2], top[1] - low[1]))
        assert 10.0 < lean < 22.0
        assert np.abs(ear[:, 0]).max() - 7.0 > 0.8  # stands out of the head's side
    # relief: across the ear's middle, the rim's outermost point stands out of the hollow inside it
    ear = ears[ears[:, 0] > 0]
    mid = ear[np.abs(ear[:, 1] - (brow_y + nose_base_y) / 2) < 0.4]
    assert np.ptp(mid[:, 0]) > 0.8


def test_only_the_default_face_gets_a_head() -> None:
    rig = default_rig(0)
    assert shell_for(dataclasses.replace(rig, name="imported")) is None
