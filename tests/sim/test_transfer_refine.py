"""A coarse head (a face tracker's few hundred vertices) is refined before the rig goes on it
(sim.face.transfer.refine): the refined surface keeps the file's vertices and openings, is smoother,
and its rig moves the landmarks the right way without turning the face's skin over."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from sim.antifold import turned_over_area
from sim.build import compile_model
from sim.face import default_rig
from sim.face.transfer.geometry import boundary_loops, edge_use_counts
from sim.face.transfer.landmarks import parse_landmarks
from sim.face.transfer.meshfile import from_arrays
from sim.face.transfer.openings import is_hole_loop
from sim.face.transfer.pipeline import TransferOptions, transfer_rig
from sim.face.transfer.refine import COARSE, FINE, MAX_LEVELS, levels_needed, subdivide
from sim.face.transfer.synthetic import synthetic_mesh, synthetic_rig
from sim.facs import apply_expression
from sim.integrator import Simulator
from sim.state import FaceControl

COARSE_GRID = (26, 22)  # the synthetic full head at 572 vertices: 4.2 x the reference's edges
FOLD_LIMIT_CM2 = 0.1


def test_a_split_keeps_every_vertex_index_and_every_opening_closed() -> None:
    v, t, _ = synthetic_mesh(*COARSE_GRID, full_head=True)
    loops = {f"hole{i}": np.asarray(loop) for i, loop in enumerate(boundary_loops(t))}
    assert len(loops) >= 3  # the eyes and the mouth
    fine_v, fine_t, fine_loops = subdivide(v, t, loops)
    edges = {tuple(sorted(e)) for tri in t.tolist() for e in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0]))}
    assert len(fine_v) == len(v) + len(edges) and len(fine_t) == 4 * len(t)
    directed = np.concatenate([fine_t[:, [0, 1]], fine_t[:, [1, 2]], fine_t[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)  # still consistently wound
    for name, loop in fine_loops.items():
        assert len(loop) == 2 * len(loops[name])
        assert np.array_equal(loop[::2], loops[name])  # the file's rim vertices, in order
        assert is_hole_loop(loop, fine_t)  # a closed loop along the refined border
    # an original vertex moves by a fraction of a coarse edge only
    coarse_edge = np.median([np.linalg.norm(v[a] - v[b]) for a, b in edges])
    assert np.linalg.norm(fine_v[: len(v)] - v, axis=1).max() < 0.5 * coarse_edge


def test_a_split_of_the_face_only_leaves_the_rest_and_leaves_no_crack() -> None:
    v, t, _ = synthetic_mesh(*COARSE_GRID, full_head=True)
    loops = {f"hole{i}": np.asarray(loop) for i, loop in enumerate(boundary_loops(t))}
    near = v[:, 2] > 0.0  # the front of the head
    fine_v, fine_t, fine_loops = subdivide(v, t, loops, near)
    back = ~near
    assert np.array_equal(fine_v[: len(v)][back], v[back])  # the back keeps its vertices in place
    untouched = t[back[t].all(axis=1)]
    assert len({tuple(x) for x in untouched.tolist()} - {tuple(x) for x in fine_t.tolist()}) < len(untouched) / 2
    edges, counts = edge_use_counts(fine_t)
    assert counts.max() == 2  # manifold, and every border edge is an opening's: no crack at the seam
    assert (counts == 1).sum() == sum(len(loop) for loop in fine_loops.values())
    assert len(t) < len(fine_t) < 4 * len(t)


def test_a_split_makes_a_coarse_surface_smoother() -> None:
    """On a coarse sphere the refined points lie closer to one radius than the facets' midpoints."""
    ball = trimesh.creation.icosphere(subdivisions=1)
    fine_v, fine_t, _ = subdivide(np.asarray(ball.vertices), np.asarray(ball.faces), {})
    flat = trimesh.Trimesh(ball.vertices, ball.faces, process=False).subdivide()
    spread = lambda p: float(np.ptp(np.linalg.norm(p, axis=1)) / np.linalg.norm(p, axis=1).mean())  # noqa: E731
    assert spread(fine_v) < 0.5 * spread(np.asarray(flat.vertices))


def test_only_a_coarse_head_is_refined() -> None:
    assert (COARSE, FINE) == (2.5, 1.5)
    assert levels_needed(2.1, 1.0) == 0  # a little coarser than the reference (a 5,200-vertex full head): left alone
    assert levels_needed(2.9, 1.0) == 1  # over 2.5 x the reference's edges: split to within 1.5 x
    assert levels_needed(3.7, 1.0) == 2  # the 470-vertex development mask
    assert levels_needed(100.0, 1.0) == MAX_LEVELS


def _landmarks(scale: float) -> dict:
    syn = synthetic_rig(48, 44)
    return {k: (scale * syn.mesh.landmark(k)).tolist() for k in syn.mesh.landmarks}


def _import(grid: tuple[int, int], refine: bool):
    v, t, _ = synthetic_mesh(*grid, full_head=True)
    options = TransferOptions(refine=refine, seat_eyes=True, rest_lips=True, cover_sheets=True, match_forces=True)
    return len(v), transfer_rig(default_rig(0), from_arrays(0.95 * v, t, "head.obj"),
                                parse_landmarks(_landmarks(0.95), "lm.json"), options=options)


def test_a_head_as_fine_as_the_reference_is_left_as_it_is() -> None:
    n, res = _import((100, 52), refine=True)
    # nothing split but the one vertex where this head's mouth border touches itself
    assert len(res.rig.mesh.vertices) == n + 1 and any("1 vertex where" in note for note in res.notes)
    assert not any("coarse" in note for note in res.notes)


@pytest.fixture(scope="module")
def coarse():
    n, res = _import(COARSE_GRID, refine=True)
    return n, res, compile_model(res.rig)


def _settled(model, expression: str) -> np.ndarray:
    sim = Simulator(model, wrinkles=False)
    state, control = model.rest_state(), FaceControl(model)
    apply_expression(control, expression)
    for _ in range(40):
        sim.step(state, control)
    sim.settle(state, control)
    return np.asarray(state.positions)


def test_a_coarse_head_is_refined_and_says_so(coarse) -> None:
    n, res, _ = coarse
    assert len(res.rig.mesh.vertices) > 4 * n
    assert any("coarse" in note and "split 2 time" in note for note in res.notes)
    lm = res.rig.mesh.landmarks
    for side in "lr":  # the lids are distinct vertices with an opening between them
        up, low = res.rig.mesh.vertices[[lm[f"upper_lid_{side}"], lm[f"lower_lid_{side}"]]]
        assert up[1] > low[1] + 0.1


def test_a_coarse_heads_rig_moves_the_landmarks_the_right_way_without_folds(coarse) -> None:
    _, res, model = coarse
    rest = np.asarray(model.rest)
    lm = res.rig.mesh.landmarks
    poses = {e: _settled(model, e) for e in ("happiness", "surprise", "anger", "sadness", "fear", "disgust")}
    y = lambda e, n: float(poses[e][lm[n], 1] - rest[lm[n], 1])  # noqa: E731
    for s in "lr":
        assert y("happiness", f"mouth_corner_{s}") > 0.3
        assert y("happiness", f"lower_lid_{s}") > y("happiness", f"upper_lid_{s}") + 0.2  # the eyes narrow
        assert y("surprise", f"brow_mid_{s}") > 0.5 and y("surprise", f"upper_lid_{s}") > 0.5
        assert y("anger", f"brow_inner_{s}") < -0.3
        assert y("sadness", f"brow_inner_{s}") > 0.5 and y("sadness", f"mouth_corner_{s}") < -0.1
        assert y("disgust", f"nose_wing_{s}") > 0.3
    assert y("surprise", "chin") < -0.5
    # the face's skin (above the chin) turns over nowhere; the synthetic head's neck folds under the
    # chin as the jaw drops whatever its resolution (docs/import-face.md)
    tri = np.asarray(res.rig.mesh.triangles)
    face = tri[(rest[tri, 1] > rest[lm["chin"], 1]).all(axis=1)]
    folded = {e: round(turned_over_area(face, rest, p), 3) for e, p in poses.items()}
    assert all(a < FOLD_LIMIT_CM2 for a in folded.values()), folded
