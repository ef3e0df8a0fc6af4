"""Refine a coarse head before the rig goes on it.

A face tracker's canonical mesh has about 470 vertices: a lid is a triangle or two deep, a lip a
row of long triangles, a brow landmark snaps to a vertex half a triangle off the brow, and skin
simulated on such facets bends only at their edges. A head whose edges near the landmarks are
more than `COARSE` x the reference's (both over the eyes' width) is refined for the simulation by
Loop subdivision (C. Loop, "Smooth subdivision surfaces based on triangles", 1987): each triangle
split into four at its edges, the new edge points at 3/8, 3/8, 1/8, 1/8 of the edge's ends and
its two opposite corners (the middle on a border edge), the old points moved to (1 - k beta) v +
beta sum(neighbours) with beta = 3 / (8 k) for k > 3 neighbours (3/16 for k = 3), a border point
to 3/4 v + 1/8 of its two border neighbours. The surface becomes smooth, so it bends where the
rig asks, and the eye and mouth rims become smooth curves. Every original vertex keeps its index
(it moves by a fraction of a coarse edge, towards the smooth surface), so landmarks and openings
given by index stay valid; the new vertices are appended. Opening loops gain their edges' new
vertices in order and stay closed loops along the refined border.

Tried on the 470-vertex development mask (`benchmarks/observer_mesh.py`): Phong tessellation
(original vertices kept in place, the new ones lifted off the flat facets) left the facets' creases
in the skin at rest; one split (edges 1.7 x the reference's) read worse than two.
"""

from __future__ import annotations

import numpy as np

FloatArray = np.ndarray
IntArray = np.ndarray
COARSE = 1.6  # a head is refined while its edges near the landmarks are longer than this x the reference's
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
    """How many splits (each halves the edges) bring a head's `edge_scale` to at most `COARSE` x
    the reference's, at most `MAX_LEVELS`."""
    levels = 0
    while levels < MAX_LEVELS and scale > COARSE * reference_scale:
        scale *= 0.5
        levels += 1
    return levels


def _edges(tri: IntArray) -> IntArray:
    return np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1), axis=0)


def subdivide(vertices: FloatArray, triangles: IntArray, loops: dict[str, IntArray]
              ) -> tuple[FloatArray, IntArray, dict[str, IntArray]]:
    """One Loop split (module docstring). `loops`: closed vertex loops along mesh edges (the
    openings), returned with each edge's new vertex inserted between its ends. Winding is kept;
    vertex i < len(vertices) is still vertex i."""
    x = np.asarray(vertices, float)
    tri = np.asarray(triangles, np.int64)
    n = len(x)
    key = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    edges, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    opposite = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    uses = np.bincount(inverse, minlength=len(edges))
    far = np.zeros((len(edges), 3))
    np.add.at(far, inverse, x[opposite])
    a, b = x[edges[:, 0]], x[edges[:, 1]]
    inner = uses == 2
    placed = 0.5 * (a + b)
    placed[inner] = 0.375 * (a[inner] + b[inner]) + 0.125 * far[inner]

    ring, k = np.zeros_like(x), np.zeros(n)
    np.add.at(ring, edges[:, 0], b)
    np.add.at(ring, edges[:, 1], a)
    np.add.at(k, edges.ravel(), 1.0)
    beta = np.where(k > 3, 3.0 / (8.0 * np.maximum(k, 1.0)), 3.0 / 16.0)
    moved = (1.0 - k * beta)[:, None] * x + beta[:, None] * ring
    border = edges[~inner]
    b_ring, b_k = np.zeros_like(x), np.zeros(n)
    np.add.at(b_ring, border[:, 0], x[border[:, 1]])
    np.add.at(b_ring, border[:, 1], x[border[:, 0]])
    np.add.at(b_k, border.ravel(), 1.0)
    moved = np.where(b_k[:, None] == 2, 0.75 * x + 0.125 * b_ring, np.where(b_k[:, None] > 0, x, moved))
    moved[k == 0] = x[k == 0]  # a vertex no triangle uses stays

    mid = inverse.reshape(3, len(tri)).T + n  # new vertex of edge (0,1), (1,2), (2,0) of each triangle
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    m01, m12, m20 = mid[:, 0], mid[:, 1], mid[:, 2]
    new_tri = np.concatenate([np.column_stack([v0, m01, m20]), np.column_stack([m01, v1, m12]),
                              np.column_stack([m20, m12, v2]), np.column_stack([m01, m12, m20])])
    lookup = {(int(p), int(q)): n + i for i, (p, q) in enumerate(edges.tolist())}
    out_loops: dict[str, IntArray] = {}
    for name, loop in loops.items():
        seq: list[int] = []
        for p, q in zip(loop.tolist(), np.roll(loop, -1).tolist()):
            seq.append(p)
            middle = lookup.get((min(p, q), max(p, q)))
            if middle is not None:
                seq.append(middle)
        out_loops[name] = np.asarray(seq, dtype=np.int64)
    return np.vstack([moved, placed]), new_tri.astype(np.int32), out_loops
