"""Reading head meshes: every supported format gives the same welded surface, file vertex order
is kept for landmark indices, and unusable files fail with one line naming the file."""

from __future__ import annotations

import numpy as np
import pytest

from sim.face.transfer import TransferError, read_mesh
from sim.face.transfer.meshfile import weld


@pytest.fixture(scope="module")
def face():
    from sim.face.transfer.synthetic import synthetic_mesh

    v, t, _ = synthetic_mesh(24, 20)
    return v, t


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".glb", ".stl"])
def test_formats_round_trip(face, tmp_path, suffix) -> None:
    import trimesh

    v, t = face
    path = tmp_path / f"face{suffix}"
    trimesh.Trimesh(v, t, process=False).export(path)
    head = read_mesh(path)
    assert len(head.triangles) == len(t)
    # whatever the format stores, file indices lead to the same points
    assert np.allclose(head.vertices[head.triangles], v[t], atol=1e-4)


def test_weld_keeps_file_order_and_merges_seams(face) -> None:
    v, t = face
    split = np.vstack([v, v[:5]])  # a texture seam: vertices 0-4 repeated at the end
    tris = t.copy()
    tris[:3] = np.where(tris[:3] < 5, tris[:3] + len(v), tris[:3])
    welded, wt, file_to_vertex = weld(split, tris)
    assert len(welded) == len(v)
    assert np.array_equal(file_to_vertex[: len(v)], np.arange(len(v)))
    assert np.array_equal(file_to_vertex[len(v):], np.arange(5))
    assert np.allclose(welded[wt], v[t])


def test_unusable_files_name_themselves(tmp_path) -> None:
    with pytest.raises(TransferError, match=r"nope\.obj: no such mesh file"):
        read_mesh(tmp_path / "nope.obj")
    (tmp_path / "a.fbx").write_text("x")
    with pytest.raises(TransferError, match=r"a\.fbx: unsupported mesh format"):
        read_mesh(tmp_path / "a.fbx")
    (tmp_path / "junk.obj").write_text("this is not\nan obj file\n")
    with pytest.raises(TransferError, match=r"junk\.obj: "):
        read_mesh(tmp_path / "junk.obj")
