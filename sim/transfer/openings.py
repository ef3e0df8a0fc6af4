"""Find the eye and mouth openings of a new head: boundary loops around the right landmarks, or
loops the landmark file declares. The simulation needs them (lids and lips part there)."""

from __future__ import annotations

import numpy as np

from sim.transfer.geometry import boundary_loops, unique_edges
from sim.transfer.landmarks import EYE_LANDMARKS, MOUTH_LANDMARKS, TransferError

FloatArray = np.ndarray
IntArray = np.ndarray

_WHERE = {"eye_l": EYE_LANDMARKS["eye_l"], "eye_r": EYE_LANDMARKS["eye_r"], "mouth": MOUTH_LANDMARKS}
_TITLE = {"eye_l": "left eye", "eye_r": "right eye", "mouth": "mouth"}


def _match(loops: list[IntArray], vertices: FloatArray, pts: FloatArray) -> IntArray | None:
    """The boundary loop that surrounds the landmark group: its centroid near the group's centre
    and its size comparable to the group's spread."""
    centre = pts.mean(axis=0)
    spread = float(np.linalg.norm(pts - centre, axis=1).max())
    best, best_d = None, np.inf
    for loop in loops:
        lv = vertices[loop]
        d = float(np.linalg.norm(lv.mean(axis=0) - centre))
        size = float(np.linalg.norm(lv - lv.mean(axis=0), axis=1).mean())
        if d < 0.5 * spread and 0.25 * spread < size < 1.6 * spread and d < best_d:
            best, best_d = loop, d
    return best


def check_declared_loop(loop: IntArray, triangles: IntArray, name: str, path: str) -> None:
    """A declared opening must be a closed loop of mesh edges."""
    edges = {tuple(e) for e in unique_edges(triangles).tolist()}
    for a, b in zip(loop, np.roll(loop, -1)):
        if (min(a, b), max(a, b)) not in edges:
            raise TransferError(f"{path}: opening {name!r}: vertices {a} and {b} are not joined by a "
                                "mesh edge; list the loop's vertices in order")


def find_openings(
    vertices: FloatArray,
    triangles: IntArray,
    landmarks: dict[str, FloatArray],
    declared: dict[str, IntArray],
    mesh_path: str,
    landmark_path: str,
) -> dict[str, IntArray]:
    """Loops for eye_l, eye_r and mouth: declared ones win; others must be holes in the mesh."""
    loops = boundary_loops(triangles)
    out: dict[str, IntArray] = {}
    for key, names in _WHERE.items():
        if key in declared:
            check_declared_loop(declared[key], triangles, key, landmark_path)
            out[key] = declared[key]
            continue
        found = _match(loops, vertices, np.stack([landmarks[n] for n in names]))
        if found is None:
            raise TransferError(
                f"{mesh_path}: no opening for the {_TITLE[key]} (near {', '.join(names)}); cut a "
                f"hole there or declare its vertex loop as openings.{key} in {landmark_path}")
        out[key] = found
    return out
