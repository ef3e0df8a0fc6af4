"""Read a head mesh (OBJ, PLY, glTF/GLB via trimesh) and weld it into one indexed surface, keeping
the file's vertex order for landmark indices."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import re

import numpy as np

from safefile import BadFile, not_a_file, quote, read_bytes
from sim.face.transfer.landmarks import TransferError

FloatArray = np.ndarray
IntArray = np.ndarray

MESH_SUFFIXES = (".obj", ".ply", ".gltf", ".glb", ".off", ".stl")
MAX_MESH_BYTES = 512 * 1024 * 1024
MAX_COORD = 1e9  # in the file's own units, whatever they are


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
    why = not_a_file(path, "mesh file")
    if why:
        raise TransferError(why)
    if Path(path).suffix.lower() not in MESH_SUFFIXES:
        raise TransferError(f"{path}: unsupported mesh format; use one of {', '.join(MESH_SUFFIXES)}")
    suffix = Path(path).suffix.lower()
    try:
        data = read_bytes(path, "mesh file", MAX_MESH_BYTES)
    except BadFile as err:
        raise TransferError(str(err)) from err
    _precheck(path, suffix, data)
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as err:  # trimesh raises many types for malformed files: one short line
        what = f"the field {err} is missing" if isinstance(err, KeyError) else quote(str(err) or type(err).__name__, 80)
        raise TransferError(f"{path}: not a readable {suffix[1:].upper()} mesh ({what}); is the file complete?") from err
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))))
    if faces.ndim != 2 or len(faces) == 0 or faces.shape[1] != 3:
        raise TransferError(f"{path}: the file holds no triangles (a point cloud or empty scene)")
    verts = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), float)
    if verts.ndim != 2 or verts.shape[1] != 3 or len(verts) < 3:
        raise TransferError(f"{path}: the file holds fewer than 3 vertices")
    if not np.isfinite(verts).all() or np.abs(verts).max() > MAX_COORD:
        raise TransferError(f"{path}: the mesh has non-finite or huge (beyond {MAX_COORD:g}) vertex coordinates")
    if faces.dtype.kind not in "iu" or faces.min() < 0 or faces.max() >= len(verts):
        raise TransferError(f"{path}: triangles refer to vertices outside 1..{len(verts)} (a damaged file)")
    head = from_arrays(verts, faces, path)
    extent = np.sort(np.ptp(head.vertices, axis=0))
    if len(head.triangles) == 0 or extent[1] <= 1e-9 * max(extent[2], 1e-300):
        raise TransferError(f"{path}: the mesh collapses to a point or a line ({len(head.vertices)} distinct "
                            "vertices, no triangle of non-zero size); is it the right file?")
    return head


def _precheck(path: str, suffix: str, data: bytes) -> None:
    """What trimesh would otherwise meet with a confusing error or an allocation sized by the file:
    a binary STL whose size does not match its triangle count and is not ASCII STL either, a PLY
    whose header promises more elements than its bytes can hold."""
    if suffix == ".stl":
        if len(data) >= 84 and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little"):
            return
        try:
            text = data.decode("ascii")
        except UnicodeDecodeError:
            text = ""
        if not text.lstrip().lower().startswith("solid"):
            n = int.from_bytes(data[80:84], "little") if len(data) >= 84 else 0
            raise TransferError(f"{path}: not a valid STL file (binary STL of {len(data)} bytes should be "
                                f"84 + 50 x {n} triangles, and it is not ASCII STL either); is the file complete?")
    elif suffix == ".ply":
        head = data[:65536].split(b"end_header", 1)[0]
        for m in re.finditer(rb"element\s+(\w+)\s+(-?\d+)", head):
            count = int(m.group(2))
            if count < 0 or count > len(data):
                raise TransferError(f"{path}: the PLY header promises {count} {m.group(1).decode(errors='replace')} "
                                    f"elements, which a file of {len(data)} bytes cannot hold (a damaged file)")
