"""The renderer's numpy parts: normals, edges, trail ring buffer, camera, eye rotation."""

from __future__ import annotations

import numpy as np
import pytest

from render.camera import OrbitCamera
from render.meshdata import NormalComputer, eye_rotation, unique_edges, uv_sphere
from render.trails import TrailHistory


def test_normals_of_a_sphere_point_outwards_and_are_unit() -> None:
    pos, tris = uv_sphere(12, 18)
    # uv_sphere winds its triangles outward-facing; the normals must agree with the radius
    n = NormalComputer(tris, len(pos))(pos * 3.0)
    body = np.abs(pos[:, 2]) < 0.999  # the seam's pole copies touch only degenerate triangles
    assert np.allclose(np.linalg.norm(n[body], axis=1), 1.0, atol=1e-5)
    assert np.einsum("ij,ij->i", n, pos)[body].min() > 0.95


def test_normals_follow_a_moving_surface() -> None:
    pos, tris = uv_sphere(8, 12)
    comp = NormalComputer(tris, len(pos))
    flat = pos.copy()
    flat[:, 2] = 0.0  # squash the sphere into a double disc: normals become +-Z
    n = comp(flat)
    cap = (np.abs(pos[:, 2]) > 0.5) & (np.abs(pos[:, 2]) < 0.999)
    assert np.abs(n[cap, 2]).min() > 0.99


def test_unique_edges_counts_each_edge_once() -> None:
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    assert sorted(map(tuple, unique_edges(tris))) == [(0, 1), (0, 2), (0, 3), (1, 2), (2, 3)]


def test_trail_history_samples_by_time_and_wraps() -> None:
    tr = TrailHistory(2, seconds=0.1, sample_dt=0.025)  # 4 slots
    assert tr.capacity == 4
    for k in range(10):
        tr.push(np.full((2, 3), k, np.float32), time=k * 0.0125)  # every other frame is sampled
    order = tr.ordered()[:, 0, 0]
    assert list(order) == [2, 4, 6, 8]
    assert not tr.push(np.zeros((2, 3)), time=9 * 0.0125 + 0.001)
    tr.push(np.zeros((2, 3)), time=0.0)  # time ran backwards: a new take
    assert tr.count == 1


def test_trail_history_set_rejects_wrong_shape() -> None:
    tr = TrailHistory(5)
    with pytest.raises(ValueError, match="history"):
        tr.set(np.zeros((3, 4, 3)))
    long = np.arange(100, dtype=np.float32)[:, None, None] * np.ones((100, 5, 3), np.float32)
    tr.set(long)  # more frames than slots: thinned evenly over the whole span
    kept = tr.ordered()[:, 0, 0]
    assert tr.count == tr.capacity and kept[0] == 0 and kept[-1] == 99


def test_eye_rotation_turns_gaze_left_and_up() -> None:
    gaze = np.array([0.0, 0.0, 1.0])
    assert (eye_rotation(0.5, 0.0) @ gaze)[0] > 0.4       # +yaw towards +X
    assert (eye_rotation(0.0, 0.3) @ gaze)[1] > 0.25      # +pitch towards +Y


def test_camera_frames_box_for_any_aspect_and_resets() -> None:
    cam = OrbitCamera()
    cam.fit(np.array([-7.0, -10.0, 0.0]), np.array([7.0, 10.0, 8.0]))
    near_tall = cam.distance(0.5)
    assert near_tall > cam.distance(16 / 9)  # a tall window needs the camera further back
    cam.orbit(0.3, 2.0)
    cam.zoom(3)
    assert cam.pitch < 1.5 and cam.scale < 1.0
    cam.reset()
    assert cam.yaw == 0.0 and cam.pitch == 0.0 and cam.scale == 1.0


def test_interleaved_buffer_holds_positions_and_area_weighted_normals() -> None:
    pos, tris = uv_sphere(6, 9)
    rng = np.random.default_rng(0)
    moved = (pos * (1.0 + 0.2 * rng.random((len(pos), 1)))).astype(np.float32)
    out = NormalComputer(tris, len(pos)).interleaved(moved)
    assert out.shape == (len(pos), 6) and out.dtype == np.float32
    assert np.array_equal(out[:, :3], moved)
    # reference: each triangle's cross product (twice its area times its normal) summed per corner
    a, b, c = (moved[tris[:, k]].astype(np.float64) for k in range(3))
    acc = np.zeros((len(pos), 3))
    for k in range(3):
        np.add.at(acc, tris[:, k], np.cross(b - a, c - a))
    ref = acc / np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-12)
    assert np.allclose(out[:, 3:], ref, atol=1e-5)


def test_spatial_order_keeps_every_triangle_and_its_winding() -> None:
    from render.meshdata import spatial_order

    gx, gy = np.meshgrid(np.arange(12.0), np.arange(9.0))
    pos = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    idx = np.arange(gx.size).reshape(gx.shape)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    tris = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    out = spatial_order(tris, pos)
    assert out.shape == tris.shape
    # same set of triangles, each as the same cyclic sequence (winding kept)
    def canon(t: np.ndarray) -> list[tuple[int, ...]]:
        return sorted(tuple(np.roll(r, -int(np.argmin(r)))) for r in t)
    assert canon(out) == canon(tris)
    # neighbours in the new order lie closer together than in a shuffled order
    c = pos[out].mean(axis=1)
    shuffled = pos[tris[np.random.default_rng(1).permutation(len(tris))]].mean(axis=1)
    step = np.linalg.norm(np.diff(c, axis=0), axis=1).mean()
    assert step < 0.5 * np.linalg.norm(np.diff(shuffled, axis=0), axis=1).mean()
