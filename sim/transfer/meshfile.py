"""Read a head mesh (OBJ, PLY, glTF/GLB via trimesh) and weld it into one indexed surface, keeping
the file's vertex order for landmark indices."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.transfer.landmarks import TransferError

FloatArray = np.ndarray
IntArray = np.ndarray

MESH_SUFFIXES = (".obj", ".ply", ".gltf", ".glb", ".off", ".stl")


@dataclass
class HeadMesh:
    """A welded triangle mesh. `file_to_vertex` (F,) maps the file's vertex indices (what the
    landmark file uses) to `vertices` rows; files that split vertices at texture seams weld back."""

    path: str
    vertices: FloatArray
    triangles: IntArray
    file_to_vertex: IntArray


def weld(vertices: FloatArray, triangles: IntArray, tol: float = 1e-9) -> tuple[FloatArray, IntArray, IntArray]:
    """Merge coincident vertices (relative tolerance of the bounding box) and drop degenerate
    triangles. Returns (vertices, triangles, old -> new index)."""
    span = float(np.ptp(vertices, axis=0).max()) or 1.0
    keys = np.round(vertices / (span * tol)).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # keep the file's vertex order (first occurrence wins)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    inverse = rank[inverse.ravel()]
    first = first[order]
    tris = inverse[triangles]
    good = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])
    return vertices[first], tris[good].astype(np.int32), inverse


def from_arrays(vertices: FloatArray, triangles: IntArray, path: str = "<mesh>") -> HeadMesh:
    """A HeadMesh from arrays (welded), for callers that already hold a mesh."""
    v, t, m = weld(np.asarray(vertices, float), np.asarray(triangles, np.int64))
    return HeadMesh(path, v, t, m)


def read_mesh(path: str | Path) -> HeadMesh:
    """Load a mesh file; one-line TransferError naming the file when it cannot be used."""
    import trimesh

    path = str(path)
    if not Path(path).is_file():
        raise TransferError(f"{path}: no such mesh file")
    if Path(path).suffix.lower() not in MESH_SUFFIXES:
        raise TransferError(f"{path}: unsupported mesh format; use one of {', '.join(MESH_SUFFIXES)}")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as err:  # trimesh raises many types for malformed files
        raise TransferError(f"{path}: cannot read mesh ({err})") from err
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))))
    if faces.ndim != 2 or len(faces) == 0:
        raise TransferError(f"{path}: the file holds no triangles (a point cloud or empty scene)")
    verts = np.asarray(mesh.vertices, float)
    if not np.isfinite(verts).all():
        raise TransferError(f"{path}: the mesh has non-finite vertex coordinates")
    return from_arrays(verts, faces, path)
