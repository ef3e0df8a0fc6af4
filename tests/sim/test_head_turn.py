"""The head turns on the neck (head_yaw, head_pitch, head_roll): the face and head move rigidly,
the neck's base stays, the join between mask and held head stays closed, and nothing moves at 0."""

from __future__ import annotations

import numpy as np
import pytest

from render.meshdata import surface_rows
from sim.face import default_model
from sim.face.turn import turn_head, turn_weights
from sim.integrator import Simulator
from sim.state import FaceControl


def _pairwise(p: np.ndarray) -> np.ndarray:
    return np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)


def test_the_face_turns_rigidly_and_the_neck_base_stays() -> None:
    model = default_model(0)
    rest = np.asarray(model.rest)
    w = turn_weights(rest)
    assert np.all(w == 1.0)  # the whole mask lies above the neck
    nose = model.mesh.landmarks["nose_tip"]
    left = turn_head(rest, w, 0.3, 0.0, 0.0)
    assert left[nose, 0] > rest[nose, 0] + 2.0  # +yaw: the nose towards the face's left (+X)
    up = turn_head(rest, w, 0.0, 0.2, 0.0)
    assert up[nose, 1] > rest[nose, 1] + 1.0  # +pitch: chin up, the nose rises
    chin = model.mesh.landmarks["chin"]
    assert up[chin, 2] > rest[chin, 2]  # ... and the chin comes forward
    tilt = turn_head(rest, w, 0.0, 0.0, 0.2)
    top = int(np.argmax(rest[:, 1]))
    assert tilt[top, 0] > rest[top, 0] + 1.0  # +roll: the crown towards the face's left shoulder
    sample = np.arange(0, len(rest), 7)
    turned = turn_head(rest, w, 0.3, -0.2, 0.1)
    np.testing.assert_allclose(_pairwise(turned[sample]), _pairwise(rest[sample]), atol=1e-9)  # rigid
    assert turn_head(rest, w, 0.0, 0.0, 0.0) is rest  # no turn: untouched


def test_the_neck_blends_down_to_the_shoulders_and_the_join_stays_closed() -> None:
    model = default_model(0)
    rows = surface_rows(model)
    shell = rows.shell
    assert shell is not None
    n = len(model.rest)
    still = rows.interleaved(np.asarray(model.rest, np.float32)).copy()
    turned = rows.interleaved(np.asarray(model.rest, np.float32), (0.4, 0.1, -0.1)).copy()
    base = shell.vertices[:, 1] < -23.0
    assert base.any()
    np.testing.assert_allclose(turned[n:][base, :3], still[n:][base, :3], atol=1e-5)  # shoulders stay
    mid = (shell.vertices[:, 1] < -16.0) & (shell.vertices[:, 1] > -19.0)
    moved = np.linalg.norm(turned[n:][mid, :3] - still[n:][mid, :3], axis=1)
    assert moved.max() > 0.5  # the neck twists part of the way
    face = np.linalg.norm(turned[:n, :3] - still[:n, :3], axis=1)
    assert face.min() > 0.3  # the whole face has turned
    np.testing.assert_array_equal(turned[rows.ring, :3], turned[rows.ring_mask, :3])  # the join is shared
    # the neck's skin shears as the turn spreads down it, but no edge tears: none stretches by
    # more than 75 % at a 36-degree turn (a head turned above a still neck would tear it apart)
    tris = np.vstack([np.asarray(model.triangles), shell.joined_triangles(n)])
    edges = np.vstack([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    before = np.linalg.norm(still[edges[:, 0], :3] - still[edges[:, 1], :3], axis=1)
    after = np.linalg.norm(turned[edges[:, 0], :3] - turned[edges[:, 1], :3], axis=1)
    assert np.max(np.abs(after / before - 1.0)) < 0.75
    face_edges = np.all(edges < n, axis=1)
    np.testing.assert_allclose(after[face_edges], before[face_edges], rtol=1e-4)  # the face: rigid


def test_the_channels_reach_the_state_and_leave_the_physics_alone() -> None:
    model = default_model(0)
    a, b = Simulator(model), Simulator(model)
    sa, sb = model.rest_state(), model.rest_state()
    ca, cb = FaceControl(), FaceControl()
    for c in (ca, cb):
        c.set("zygomaticus_major_l", 0.6)
    cb.set("head_yaw", 0.5)
    cb.set("head_roll", -0.25)
    for _ in range(5):
        a.step(sa, ca)
        b.step(sb, cb)
    assert (sb.head_yaw, sb.head_pitch, sb.head_roll) == (0.5, 0.0, -0.25)
    np.testing.assert_array_equal(sa.positions, sb.positions)  # the skin's dynamics run in the head's frame
    with pytest.raises(ValueError):
        cb.set("head_pitch", 1.5)
