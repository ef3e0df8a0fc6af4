"""Find the eye and mouth openings of a new head: boundary loops around the right landmarks, or
loops the landmark file declares, or slits cut along a declared lip/lid line for heads scanned
with the mouth or eyes closed. The simulation needs them (lids and lips part there)."""

from __future__ import annotations

import numpy as np

from sim.face.transfer.geometry import boundary_loops, unique_edges
from sim.face.transfer.landmarks import EYE_LANDMARKS, MOUTH_LANDMARKS, TransferError

FloatArray = np.ndarray
IntArray = np.ndarray

_WHERE = {"eye_l": EYE_LANDMARKS["eye_l"], "eye_r": EYE_LANDMARKS["eye_r"], "mouth": MOUTH_LANDMARKS}
CORNERS = {"eye_l": EYE_LANDMARKS["eye_l"][:2], "eye_r": EYE_LANDMARKS["eye_r"][:2], "mouth": MOUTH_LANDMARKS[:2]}
_TITLE = {"eye_l": "left eye", "eye_r": "right eye", "mouth": "mouth"}


_PARTS = {"eye_l": "lids", "eye_r": "lids", "mouth": "lips"}


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


def check_declared_loop(loop: IntArray, triangles: IntArray, name: str, path: str, closed: bool = True) -> None:
    """A declared opening must follow mesh edges (a closed loop, or an open path to cut along)."""
    edges = {tuple(e) for e in unique_edges(triangles).tolist()}
    pairs = zip(loop, np.roll(loop, -1)) if closed else zip(loop[:-1], loop[1:])
    for a, b in pairs:
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
                f"hole there or declare its vertices as openings.{key} in {landmark_path}: the rim's loop "
                f"if the {_PARTS[key]} stand apart (what it encloses is removed), the line where they "
                "meet, from corner to corner, if they are shut")
        out[key] = found
    return out


def _boundary_edges(triangles: IntArray) -> set[tuple[int, int]]:
    from sim.face.transfer.geometry import edge_use_counts

    edges, counts = edge_use_counts(triangles)
    return {tuple(e) for e in edges[counts == 1].tolist()}


def is_hole_loop(loop: IntArray, triangles: IntArray) -> bool:
    """Whether a closed vertex list runs along the mesh's border (an existing opening)."""
    border = _boundary_edges(triangles)
    return all((min(a, b), max(a, b)) in border for a, b in zip(loop, np.roll(loop, -1)))


def cut_slit(
    vertices: FloatArray, triangles: IntArray, path: IntArray, up: FloatArray, name: str, path_file: str
) -> tuple[FloatArray, IntArray, IntArray, dict[int, int]]:
    """Open a closed mouth or eye along a path of mesh edges (corner to corner, e.g. the lip line):
    the path's inner vertices are doubled and the triangles on the lower side (along -`up`) take
    the copies. Returns (vertices, triangles, the new opening's loop, original -> lower copy)."""
    path = np.asarray(path, dtype=np.int64)
    check_declared_loop(path, triangles, name, path_file, closed=False)
    border = {v for e in _boundary_edges(triangles) for v in e}
    tris = triangles.copy()
    verts = [vertices]
    copies: list[int] = []
    n = len(vertices)
    for i in range(1, len(path) - 1):
        v, before, after = int(path[i]), int(path[i - 1]), int(path[i + 1])
        if v in border:
            raise TransferError(f"{path_file}: opening {name!r}: vertex {v} is on the mesh's border; "
                                "a cut must run inside the surface")
        fan = np.nonzero((tris == v).any(axis=1))[0]
        side = _split_fan(tris, fan, v, {before, after})
        if side is None:
            raise TransferError(f"{path_file}: opening {name!r}: the path does not split the surface "
                                f"at vertex {v}; list the lip (or lid) line's vertices in order")
        first, second = side
        if copies:  # the side that already holds the previous vertex's copy: a path that winds
            lower = first if (tris[first] == copies[-1]).any() else second  # keeps one lower lip
        else:
            cur = np.vstack(verts)
            c1 = (cur[tris[first]].mean(axis=(0, 1)) - vertices[v]) @ up
            c2 = (cur[tris[second]].mean(axis=(0, 1)) - vertices[v]) @ up
            lower = first if c1 < c2 else second
        new = n + len(copies)
        block = tris[lower]
        block[block == v] = new
        tris[lower] = block
        copies.append(new)
        verts.append(vertices[v][None])
    loop = np.concatenate([path, np.asarray(copies[::-1], dtype=np.int64)])
    return np.vstack(verts), tris, loop, {int(a): b for a, b in zip(path[1:-1], copies)}


def slit_corners(vertices: FloatArray, ends: tuple[int, int], points: tuple[FloatArray, FloatArray]
                 ) -> tuple[int, int]:
    """The ends of a cut line (corner to corner) that stand for the opening's two corner landmarks,
    in the landmarks' order: the pairing that puts them nearer their points. A cut's two sides meet
    only at its ends, so that is where the lids (lips) meet, whichever vertex the landmark itself
    snapped to: a lid line traced an edge past the corner, or a corner given as a point off the
    surface that snaps to the line's second vertex, left that vertex as the corner, and the
    opening's loop, split there into the two lids, gave one lid part of the other's margin."""
    a, b = (np.asarray(vertices[e], float) for e in ends)
    p, q = (np.asarray(x, float) for x in points)
    straight = np.linalg.norm(a - p) + np.linalg.norm(b - q)
    crossed = np.linalg.norm(b - p) + np.linalg.norm(a - q)
    return (ends[0], ends[1]) if straight <= crossed else (ends[1], ends[0])


def _split_fan(tris: IntArray, fan: IntArray, v: int, cut: set[int]) -> tuple[IntArray, IntArray] | None:
    """The triangles round v in two groups, connected across edges (v, w) with w not on the cut."""
    label = -np.ones(len(fan), dtype=np.int64)
    for start in range(len(fan)):
        if label[start] >= 0:
            continue
        group = int(label.max()) + 1
        label[start] = group
        stack = [start]
        while stack:
            a = stack.pop()
            others = set(tris[fan[a]].tolist()) - {v}
            for b in range(len(fan)):
                if label[b] < 0:
                    shared = (others & set(tris[fan[b]].tolist())) - cut
                    if shared:
                        label[b] = group
                        stack.append(b)
    if label.max() != 1:
        return None
    return fan[label == 0], fan[label == 1]


def is_closed_path(loop: IntArray, triangles: IntArray) -> bool:
    """Whether the last vertex of a declared list is joined to the first by a mesh edge."""
    a, b = int(loop[0]), int(loop[-1])
    return len(loop) >= 3 and bool(((triangles == a).any(axis=1) & (triangles == b).any(axis=1)).any())


def open_loop(triangles: IntArray, loop: IntArray, name: str, path_file: str) -> IntArray:
    """Remove what a declared closed loop encloses (a filled mouth, an eyeball fused to the lids):
    triangles are grouped across edges not on the loop and the smaller side is dropped."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    check_declared_loop(loop, triangles, name, path_file)
    on_loop = {(min(a, b), max(a, b)) for a, b in zip(loop.tolist(), np.roll(loop, -1).tolist())}
    m = len(triangles)
    half = np.concatenate([np.sort(triangles[:, [0, 1]], axis=1), np.sort(triangles[:, [1, 2]], axis=1),
                           np.sort(triangles[:, [2, 0]], axis=1)])
    owner = np.tile(np.arange(m), 3)
    keep = np.array([tuple(e) not in on_loop for e in half.tolist()])
    order = np.lexsort((half[keep, 1], half[keep, 0]))
    e, o = half[keep][order], owner[keep][order]
    same = (e[1:] == e[:-1]).all(axis=1)
    graph = coo_matrix((np.ones(int(same.sum())), (o[:-1][same], o[1:][same])), shape=(m, m))
    count, label = connected_components(graph, directed=False)
    if count < 2:
        raise TransferError(f"{path_file}: opening {name!r} does not enclose a part of the surface")
    sizes = np.bincount(label)
    touching = {int(label[i]) for i in np.nonzero((np.isin(triangles, loop)).any(axis=1))[0]}
    inner = [c for c in touching if c != int(sizes.argmax())]
    return triangles[~np.isin(label, inner)]


def zip_hole(vertices: FloatArray, loop: IntArray) -> list[list[int]]:
    """Triangles closing a hole: its loop split at its leftmost and rightmost vertices into two
    halves, joined by a strip walked from one corner to the other by each half's arc length (the
    inverse of `cut_slit`: a scan's shut lids made from open ones)."""
    loop = np.asarray(loop)
    a, b = int(np.argmin(vertices[loop, 0])), int(np.argmax(vertices[loop, 0]))
    i, j = min(a, b), max(a, b)
    one = [int(x) for x in loop[i:j + 1]]
    other = [int(x) for x in np.r_[loop[j:], loop[:i + 1]][::-1]]

    def frac(arc: list[int]) -> FloatArray:
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(vertices[arc], axis=0), axis=1))]
        return s / s[-1]

    f1, f2 = frac(one), frac(other)
    out, p, q = [], 0, 0
    while p < len(one) - 1 or q < len(other) - 1:
        if q >= len(other) - 1 or (p < len(one) - 1 and f1[p + 1] < f2[q + 1]):
            out.append([one[p], one[p + 1], other[q]])
            p += 1
        else:
            out.append([one[p], other[q + 1], other[q]])
            q += 1
    return out
