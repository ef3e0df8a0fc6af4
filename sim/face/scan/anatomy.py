"""Where the scan's anatomy is, in its own vertex numbering: the simulated skin, its openings, the
32 landmarks of the project's vocabulary, the eyeballs and the jaw.

Everything here is found from the generic neutral head and the scanned expression shapes and is
the same for every identity (all identities share the vertex numbering). The landmark indices are
stored as data (`landmarks.json`); `find_landmarks` is how they were found and a test checks that
it still finds them.

The simulated skin is the narrow face area (the first 6706 vertices) less the inside of the lips:
in the scan the lips roll into the mouth for 7 rows of vertices past the line where they meet; the
rows inside that line (`LIP_INSIDE_ROWS`, counted from the opening) follow the lips as dressing,
so the simulated mouth opening is the line where the lips touch (0.8 mm apart at the middle at
rest), as on the procedural face.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from sim.face.scan.data import NARROW_FACE, PARTS, SCLERA, ScanData
from sim.springs import boundary_loops

LANDMARK_FILE = Path(__file__).with_name("landmarks.json")
# rows of the lips' inner surface between the scan's mouth opening and the line where the lips meet
# (measured on the neutral: the upper and lower rows at the middle are 0.8 mm apart at row 7 and
# cross each other at row 6)
LIP_INSIDE_ROWS = 7


@dataclass(frozen=True)
class SkinLayout:
    """The simulated skin's vertices in the scan (`vertices` (N,) increasing scan indices), its
    triangles (M,3) in simulation numbering, the inside of the lips (scan indices) and the scan's
    mouth opening ring index of each (0 = the opening's edge)."""

    vertices: np.ndarray
    triangles: np.ndarray
    lip_inside: np.ndarray
    lip_row: np.ndarray


def _rings(tri: np.ndarray, n: int, sources: np.ndarray) -> np.ndarray:
    """Graph distance (edges) of every vertex from `sources` over the triangles' edges."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    return dijkstra(g + g.T, unweighted=True, indices=sources, min_only=True)


def _narrow_triangles(data: ScanData) -> np.ndarray:
    tri = data.triangles("face")
    return tri[(tri < NARROW_FACE).all(axis=1)]


def _openings(vertices: np.ndarray, tri: np.ndarray) -> dict[str, np.ndarray]:
    """The narrow face area's eye and mouth holes (the outer border is the longest loop)."""
    loops = sorted(boundary_loops(tri), key=len)[:-1]
    out = {}
    for loop in loops:
        c = vertices[loop].mean(axis=0)
        key = "mouth" if c[1] < 0 else ("eye_l" if c[0] > 0 else "eye_r")
        out[key] = np.asarray(loop, dtype=np.int64)
    return out


@lru_cache(maxsize=1)
def _layout_cached() -> SkinLayout:
    from sim.face.scan.data import scan_data

    data = scan_data()
    tri = _narrow_triangles(data)
    mouth = _openings(data.neutral, tri)["mouth"]
    row = _rings(tri, NARROW_FACE, mouth)
    keep = row >= LIP_INSIDE_ROWS
    inside = np.flatnonzero(~keep)
    verts = np.flatnonzero(keep)
    remap = -np.ones(NARROW_FACE, dtype=np.int64)
    remap[verts] = np.arange(len(verts))
    t = tri[keep[tri].all(axis=1)]
    for a in (verts, inside):
        a.setflags(write=False)
    return SkinLayout(verts, remap[t].astype(np.int32), inside, row[inside].astype(np.int64))


def skin_layout() -> SkinLayout:
    """The simulated skin (the same for every identity)."""
    return _layout_cached()


def load_landmarks() -> dict[str, int]:
    """The 32 landmarks as scan vertex indices (all in the simulated skin)."""
    with open(LANDMARK_FILE, encoding="utf-8") as fh:
        return {str(k): int(v) for k, v in json.load(fh).items()}


def eyeball_spheres(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres (2,3) (left, right) and radii (2,) of the eyeballs: least-squares spheres through
    each sclera's vertices of `points` (the scan's (26719,3) positions)."""
    centres, radii = [], []
    for part in ("eyeball_l", "eyeball_r"):
        lo = PARTS[part][0]
        p = points[lo:lo + SCLERA]
        a = np.column_stack([2.0 * p, np.ones(len(p))])
        b = np.sum(p * p, axis=1)
        sol = np.linalg.lstsq(a, b, rcond=None)[0]
        c = sol[:3]
        centres.append(c)
        radii.append(np.sqrt(sol[3] + c @ c))
    return np.array(centres), np.array(radii)


def _nearest(points: np.ndarray, candidates: np.ndarray, target: np.ndarray) -> int:
    return int(candidates[np.argmin(np.linalg.norm(points[candidates] - target, axis=1))])


def find_landmarks(data: ScanData) -> dict[str, int]:
    """The 32 landmarks, found on the generic neutral from its openings, its midline profile and
    the scanned expression shapes (`eyeBlink` moves the upper lid margin most, `browDown` the brow,
    `noseSneer` the nose wing); the cheeks, the jaw angles and the forehead centre, which have no
    sharp feature, are placed where the procedural face has them relative to the others."""
    v = data.neutral
    layout = skin_layout()
    skin = layout.vertices
    tri = _narrow_triangles(data)
    holes = _openings(v, tri)
    out: dict[str, int] = {}
    for side, sign in (("l", 1.0), ("r", -1.0)):
        loop = holes[f"eye_{side}"]
        x = sign * v[loop, 0]
        out[f"eye_inner_{side}"] = int(loop[np.argmin(x)])
        out[f"eye_outer_{side}"] = int(loop[np.argmax(x)])
        blink = np.linalg.norm(data.expression(f"eyeBlink_{side.upper()}")[loop], axis=1)
        upper = blink > 0.5 * blink.max()
        mid_x = 0.5 * (x.min() + x.max())
        out[f"upper_lid_{side}"] = int(loop[upper][np.argmin(np.abs(x[upper] - mid_x))])
        out[f"lower_lid_{side}"] = int(loop[~upper][np.argmin(np.abs(x[~upper] - mid_x))])
    # the simulated mouth opening: the row where the lips meet
    mouth = np.flatnonzero(np.isin(np.arange(len(v)), skin) & (np.abs(v[:, 1] + 3.3) < 1.0)
                           & (np.abs(v[:, 0]) < 4.0))
    row = _rings(tri, NARROW_FACE, holes["mouth"])
    line = mouth[row[mouth] == LIP_INSIDE_ROWS]
    out["mouth_corner_l"] = int(line[np.argmax(v[line, 0])])
    out["mouth_corner_r"] = int(line[np.argmin(v[line, 0])])
    mid = line[np.abs(v[line, 0]) < 1e-3]
    out["upper_lip_center"] = int(mid[np.argmax(v[mid, 1])])
    out["lower_lip_center"] = int(mid[np.argmin(v[mid, 1])])
    mouth_y = 0.5 * (v[out["upper_lip_center"], 1] + v[out["lower_lip_center"], 1])
    # the midline profile
    midline = skin[np.abs(v[skin, 0]) < 1e-3]
    midline = midline[np.argsort(v[midline, 1])]
    y, z = v[midline, 1], v[midline, 2]
    tip = int(np.argmax(np.where(np.abs(y - mouth_y) < 6.0, z, -np.inf)))
    out["nose_tip"] = int(midline[tip])
    between = (y < y[tip]) & (y > mouth_y)
    lip_front = int(np.argmax(np.where(between & (y < y[tip] - 1.5), z, -np.inf)))
    out["upper_lip_top"] = int(midline[lip_front])
    out["subnasale"] = int(midline[np.argmin(np.where((y < y[tip]) & (y > y[lip_front]), z, np.inf))])
    below = (y < mouth_y) & (y > mouth_y - 2.0)
    out["lower_lip_bottom"] = int(midline[np.argmax(np.where(below, z, -np.inf))])
    eye_y = float(np.mean([v[out[f"{k}_{s}"], 1] for k in ("eye_inner", "eye_outer") for s in "lr"]))
    bridge = (y > eye_y) & (y < eye_y + 2.0)
    k_bridge = int(np.argmin(np.where(bridge, z, np.inf)))
    out["nose_bridge"] = int(midline[k_bridge])
    above = (y > y[k_bridge]) & (y < y[k_bridge] + 2.5)
    k_glab = int(np.argmax(np.where(above, z, -np.inf)))
    out["glabella"] = int(midline[k_glab])
    # the brows: where browDown moves the skin most, above the eye's inner corner, centre, outer corner
    for side, sign in (("l", 1.0), ("r", -1.0)):
        down = np.linalg.norm(data.expression(f"browDown_{side.upper()}"), axis=1)
        xi, xo = v[out[f"eye_inner_{side}"], 0], v[out[f"eye_outer_{side}"], 0]
        lid_y = v[out[f"upper_lid_{side}"], 1]
        for name, x0 in (("inner", xi - 0.15 * (xo - xi)), ("mid", 0.5 * (xi + xo)), ("outer", xo + 0.1 * (xo - xi))):
            col = skin[(np.abs(v[skin, 0] - x0) < 0.25) & (v[skin, 1] > lid_y) & (v[skin, 1] < lid_y + 3.5)]
            out[f"brow_{name}_{side}"] = int(col[np.argmax(down[col])])
        sneer = np.linalg.norm(data.expression(f"noseSneer_{side.upper()}"), axis=1)
        wing = skin[(sign * v[skin, 0] > 0.8) & (sign * v[skin, 0] < 2.5)
                    & (v[skin, 1] < v[out["nose_tip"], 1]) & (v[skin, 1] > v[out["subnasale"], 1] - 0.3)]
        out[f"nose_wing_{side}"] = int(wing[np.argmax(sneer[wing])])
    # chin: as far below the nose tip as on the procedural face, relative to nose tip-glabella
    out["chin"] = _placed(out, v, skin, "chin")
    for name in ("forehead_center", "cheek_l", "cheek_r", "jaw_angle_l", "jaw_angle_r"):
        out[name] = _placed(out, v, skin, name)
    return out


def _placed(found: dict[str, int], v: np.ndarray, skin: np.ndarray, name: str) -> int:
    """A landmark without a sharp feature: the procedural face's, carried by the best similarity
    between the two faces' sharp landmarks, then the nearest simulated skin vertex facing it."""
    from sim.face.builder import build_face_mesh
    from sim.face.transfer.frame import fit_similarity

    ref = build_face_mesh(0)
    names = [n for n in found if n in ref.landmarks and not n.startswith(("chin", "cheek", "jaw", "forehead"))]
    sim = fit_similarity(np.stack([ref.landmark(n) for n in names]), np.stack([v[found[n]] for n in names]))
    target = sim.apply(ref.landmark(name)[None])[0]
    return _nearest(v, skin, target)
