"""The landmark files in examples/ stay valid for the meshes they describe (docs/import-face.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.face.transfer import LANDMARK_NAMES, TransferError, from_arrays, parse_landmarks, read_landmarks, transfer_rig
from sim.face.transfer.synthetic import synthetic_mesh

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def reference():
    from sim.face import default_rig

    return default_rig(0)


def test_default_face_example_points_land_on_the_default_face(reference) -> None:
    from sim.face.builder import build_face_mesh

    lf = read_landmarks(EXAMPLES / "landmarks_default_face.json")
    assert set(lf.entries) == set(LANDMARK_NAMES)
    mesh = build_face_mesh(1)
    res = transfer_rig(reference, from_arrays(mesh.vertices, mesh.triangles), lf)
    for name, point in lf.entries.items():
        assert np.linalg.norm(res.rig.mesh.landmark(name) - point) < 0.5, name


@pytest.mark.parametrize("file, mesh_args, loop", [
    ("landmarks_synthetic_head.json", dict(n_theta=100, n_h=52, full_head=True), None),
    ("landmarks_closed_mouth.json", dict(n_theta=64, n_h=45, full_head=True, mouth_open=False), 12),
])
def test_synthetic_examples_import(reference, file, mesh_args, loop) -> None:
    lf = read_landmarks(EXAMPLES / file)
    v, t, _ = synthetic_mesh(**mesh_args)
    res = transfer_rig(reference, from_arrays(v, t), lf)
    assert res.folded_triangles == 0 and res.relaxation.converged
    if loop:
        assert len(res.rig.mesh.mouth_loop) == loop


def test_the_synthetic_head_in_the_docs_makes_a_rig_that_simulates(reference) -> None:
    """docs/import-face.md's synthetic head has a mouth whose border touches itself at one vertex
    (the corner's last triangle missing): its loop walked that vertex twice, and building the
    imported rig's integrator stopped with a StopIteration traceback (`puppet pose --rig`). The
    vertex is split: every opening a simple loop, the rig steps, and the report says so."""
    from sim.build import compile_model
    from sim.integrator import Simulator
    from sim.smoothness import margin_rows

    lf = read_landmarks(EXAMPLES / "landmarks_synthetic_head.json")
    v, t, _ = synthetic_mesh(n_theta=100, n_h=52, full_head=True)
    res = transfer_rig(reference, from_arrays(v, t), lf)
    mesh = res.rig.mesh
    for loop in (*mesh.eye_loops, mesh.mouth_loop):
        assert len(np.unique(loop)) == len(loop)
    rows = margin_rows(mesh)
    assert not set(rows["lip_upper"][1:-1]) & set(rows["lip_lower"][1:-1])  # the lips share their corners only
    assert any("touched itself" in n for n in res.notes)
    model = compile_model(res.rig)
    sim = Simulator(model)
    state, control = model.rest_state(), model.control()
    control.set("jaw", 0.5)
    for _ in range(3):
        sim.step(state, control)
    assert np.isfinite(state.positions).all()


def test_landmark_file_format_errors_name_the_file(tmp_path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"nose_tip": 3,\n "chin": }')
    with pytest.raises(TransferError, match=r"bad\.json:2: not valid JSON"):
        read_landmarks(bad)
    with pytest.raises(TransferError, match=r"x\.json: unknown landmark\(s\) nose"):
        parse_landmarks({"nose": 1}, "x.json")
    with pytest.raises(TransferError, match=r"x\.json: landmark 'chin' must be a vertex index or \[x, y, z\]"):
        parse_landmarks({"chin": [1, 2]}, "x.json")
    with pytest.raises(TransferError, match=r"x\.json: unknown opening 'nostril'"):
        parse_landmarks({"landmarks": {}, "openings": {"nostril": [1, 2, 3]}}, "x.json")
    with pytest.raises(TransferError, match=r"missing\.json: cannot read landmark file"):
        read_landmarks(tmp_path / "missing.json")
