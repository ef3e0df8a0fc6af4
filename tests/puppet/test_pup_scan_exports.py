"""Exports of the scanned head keep the scan's vertices: the OBJ beside a PC2 (and `puppet pose --out
.obj`) holds the 26,719 vertices in the scan's order, equal to the scan's neutral head plus the
identity, with the scan's faces; the point cache has as many points per sample."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from puppet import live
from puppet.export.pc2 import read_pc2
from puppet.export.runner import ExportOptions, export
from puppet.faces import parse_face
from puppet.replay import build_performance
from puppet.session import read_session
from sim.face.scan.data import N_VERTICES, scan_data

from test_pup_faces import _record


def _obj(path: Path) -> tuple[np.ndarray, list[list[int]]]:
    v, f = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            f.append([int(x) for x in line.split()[1:]])
    return np.array(v), f


@pytest.fixture(scope="module")
def face() -> live.Face:
    return live.load_face(face="ict?identity=5")


def test_pc2_and_obj_carry_the_scan(tmp_path: Path, face: live.Face) -> None:
    rec, _ = _record(tmp_path, face, "take")
    perf = build_performance(read_session(rec), None)
    out = tmp_path / "take.pc2"
    export(perf, out, ExportOptions(fps=30.0))
    verts, faces = _obj(out.with_suffix(".obj"))
    d = scan_data()
    want = d.neutral + d.identity_delta(parse_face("ict?identity=5").weights)
    assert verts.shape == (N_VERTICES, 3)
    # the scan's order: every vertex where the scan's own model puts it (the simulated skin's rest
    # is the scan's, to float precision), not just the same count
    assert np.abs(verts - want).max() < 1e-4
    assert len(faces) == len(d.faces)
    assert faces[0] == [i + 1 for i in d.faces[0] if i >= 0] and faces[-1] == [i + 1 for i in d.faces[-1] if i >= 0]
    head, samples = read_pc2(out)
    assert head["num_points"] == N_VERTICES and samples.shape == (15, N_VERTICES, 3)
    assert np.abs(samples[0] - want).max() < 0.05  # the first frame is near rest
    moved = np.linalg.norm(samples[-1] - samples[0], axis=1)
    assert moved[:9409].max() > 0.1 and moved[9409:11248].max() < moved[:9409].max()  # the face moved


def test_pose_obj_is_the_posed_scan(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from puppet.cli import main

    out = tmp_path / "smile.obj"
    assert main(["pose", "--face", "ict", "--expression", "happiness", "--seconds", "0.3", "--out", str(out)]) == 0
    said = capsys.readouterr().out  # the count it names is the file's, not only the simulated skin's
    assert f"the scan's {N_VERTICES}" in said, said
    verts, faces = _obj(out)
    d = scan_data()
    assert verts.shape == (N_VERTICES, 3) and len(faces) == len(d.faces)
    lo, hi = 17039, 21451  # the teeth: the upper row stays with the skull
    assert np.abs(verts[lo:lo + 2208] - d.neutral[lo:lo + 2208]).max() < 1e-4
    assert np.abs(verts[:9409] - d.neutral[:9409]).max() > 0.2  # the face smiles
