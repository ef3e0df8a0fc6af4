"""Refine a coarse head before the rig goes on it.

A face tracker's canonical mesh has about 470 vertices: a lid is a triangle or two deep, a lip a
row of long triangles, a brow landmark snaps to a vertex half a triangle off the brow, and skin
simulated on such facets bends only at their edges. A head whose edges near the landmarks are more
than `COARSE` x the reference's (both over the eyes' width) is refined for the simulation, until
they are within `FINE` x, by Loop subdivision (C. Loop, "Smooth subdivision surfaces based on
triangles", 1987): each triangle split into four at its edges, the new edge points at 3/8, 3/8,
1/8, 1/8 of the edge's ends and its two opposite corners (the middle on a border edge), the old
points moved to (1 - k beta) v + beta sum(neighbours) with beta = 3 / (8 k) for k > 3 neighbours
(3/16 for k = 3; Warren's simplification of Loop's beta), a border point to 3/4 v + 1/8 of its two
border neighbours. Only the face is split (`subdivide`'s `near`): a head's back and neck are held
and would only cost simulation time. The surface becomes smooth, so it bends where the rig asks,
and the eye and mouth rims become smooth curves. Every original vertex keeps its index (it moves by
a fraction of a coarse edge, towards the smooth surface), so landmarks and openings given by index
stay valid; the new vertices are appended. Opening loops gain their edges' new vertices in order
and stay closed loops along the refined border.

Tried on the 470-vertex development mask (`benchmarks/observer_mesh.py`): Phong tessellation
(original vertices kept in place, the new ones lifted off the flat facets) left the facets' creases
in the skin at rest; one split (edges 1.85 x the reference's) read worse than two.
"""

from __future__ import annotations

import numpy as np

FloatArray = np.ndarray
IntArray = np.ndarray
COARSE = 2.5  # a head whose edges near the landmarks are longer than this x the reference's is refined
FINE = 1.5  # ... until they are at most this x the reference's
MAX_LEVELS = 2  # a 470-vertex mask needs two; more would only cost simulation time


def edge_scale(vertices: FloatArray, triangles: IntArray, near: np.ndarray, width: float) -> float:
    """The median length of the mesh edges whose both ends are `near` (the face's landmark region),
    over the face's outer-eye-corner distance `width`: a density comparable between heads."""
    e = _edges(np.asarray(triangles, np.int64))
    e = e[near[e].all(axis=1)]
    if len(e) == 0:
        return 0.0
    return float(np.median(np.linalg.norm(vertices[e[:, 1]] - vertices[e[:, 0]], axis=1))) / width


def levels_needed(scale: float, reference_scale: float) -> int:
    """How many splits (each halves the edges) a head of this `edge_scale` takes: none unless it
    is over `COARSE` x the reference's, then as many as bring it to at most `FINE` x, at most
    `MAX_LEVELS`."""
    if scale <= COARSE * reference_scale:
        return 0
    levels = 0
    while levels < MAX_LEVELS and scale > FINE * reference_scale:
        scale *= 0.5
        levels += 1
    return levels


def _edges(tri: IntArray) -> IntArray:
    return np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1), axis=0)


def subdivide(vertices: FloatArray, triangles: IntArray, loops: dict[str, IntArray],
              near: np.ndarray | None = None) -> tuple[FloatArray, IntArray, dict[str, IntArray]]:
    """One Loop split (module docstring). `near` (N,) bool: only the triangles whose corners are
    all near (the face) are split into four, and the triangles next to them that this leaves with
    one split edge into two (two or three split edges: into four too), so the mesh stays conforming
    and the back of a head is not refined; where a vertex or edge touches an unsplit triangle it
    keeps its place, or the edge's middle. `loops`: closed vertex loops along mesh edges (the
    openings), returned with each split edge's new vertex inserted between its ends. Winding is
    kept; vertex i < len(vertices) is still vertex i."""
    x = np.asarray(vertices, float)
    tri = np.asarray(triangles, np.int64)
    n, m = len(x), len(tri)
    key = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    edges, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    tri_edge = inverse.reshape(3, m).T  # edge (0,1), (1,2), (2,0) of each triangle
    red = np.ones(m, bool) if near is None else np.asarray(near, bool)[tri].all(axis=1)
    while True:
        split = np.zeros(len(edges), bool)
        split[tri_edge[red].ravel()] = True
        count = split[tri_edge].sum(axis=1)
        grow = ~red & (count >= 2)
        if not grow.any():
            break
        red |= grow
    green = ~red & (count == 1)

    opposite = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    uses = np.bincount(inverse, minlength=len(edges))
    red_uses = np.bincount(inverse, weights=np.tile(red, 3).astype(float), minlength=len(edges))
    far = np.zeros((len(edges), 3))
    np.add.at(far, inverse, x[opposite])
    a, b = x[edges[:, 0]], x[edges[:, 1]]
    smooth_edge = (uses == 2) & (red_uses == 2)
    placed = 0.5 * (a + b)
    placed[smooth_edge] = 0.375 * (a[smooth_edge] + b[smooth_edge]) + 0.125 * far[smooth_edge]

    ring, k = np.zeros_like(x), np.zeros(n)
    np.add.at(ring, edges[:, 0], b)
    np.add.at(ring, edges[:, 1], a)
    np.add.at(k, edges.ravel(), 1.0)
    beta = np.where(k > 3, 3.0 / (8.0 * np.maximum(k, 1.0)), 3.0 / 16.0)
    moved = (1.0 - k * beta)[:, None] * x + beta[:, None] * ring
    border = edges[uses == 1]
    b_ring, b_k = np.zeros_like(x), np.zeros(n)
    np.add.at(b_ring, border[:, 0], x[border[:, 1]])
    np.add.at(b_ring, border[:, 1], x[border[:, 0]])
    np.add.at(b_k, border.ravel(), 1.0)
    moved = np.where(b_k[:, None] == 2, 0.75 * x + 0.125 * b_ring, np.where(b_k[:, None] > 0, x, moved))
    touches_unsplit = np.zeros(n, bool)
    touches_unsplit[tri[~red].ravel()] = True
    moved[touches_unsplit | (k == 0)] = x[touches_unsplit | (k == 0)]

    new_id = np.full(len(edges), -1, np.int64)
    new_id[split] = n + np.arange(int(split.sum()))
    mid = new_id[tri_edge]
    v0, v1, v2 = tri[red, 0], tri[red, 1], tri[red, 2]
    m01, m12, m20 = mid[red, 0], mid[red, 1], mid[red, 2]
    parts = [np.column_stack([v0, m01, m20]), np.column_stack([m01, v1, m12]),
             np.column_stack([m20, m12, v2]), np.column_stack([m01, m12, m20]), tri[~red & ~green]]
    if green.any():
        g = np.nonzero(green)[0]
        j = np.argmax(mid[g] >= 0, axis=1)  # the one split edge: (j, j+1) of the triangle
        ta, tb, tc = tri[g, j], tri[g, (j + 1) % 3], tri[g, (j + 2) % 3]
        mm = mid[g, j]
        parts += [np.column_stack([ta, mm, tc]), np.column_stack([mm, tb, tc])]
    new_tri = np.concatenate(parts)
    out_loops: dict[str, IntArray] = {}
    for name, loop in loops.items():
        seq: list[int] = []
        for p, q in zip(loop.tolist(), np.roll(loop, -1).tolist()):
            seq.append(p)
            e = np.searchsorted(edges[:, 0], min(p, q))
            while e < len(edges) and edges[e, 0] == min(p, q) and edges[e, 1] != max(p, q):
                e += 1
            if e < len(edges) and edges[e, 0] == min(p, q) and split[e]:
                seq.append(int(new_id[e]))
        out_loops[name] = np.asarray(seq, dtype=np.int64)
    return np.vstack([moved, placed[split]]), new_tri.astype(np.int32), out_loops
