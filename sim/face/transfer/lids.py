"""Open the closed eyes of a head whose lids were cut along the lid line (a scan taken with the
eyes shut). The rig's rest shape is the relaxed face with the eyes open: the reference's lids
part there, its lid channels close them (AU43/45) and its expressions widen or narrow them. A head
whose lids meet at rest would look asleep in every expression, so after the cut its upper lid is
raised and its lower lid lowered until the lids part by the reference's opening, measured against
the eye's width (about a third on an adult), with the skin around them following smoothly."""

from __future__ import annotations

import numpy as np

FloatArray = np.ndarray
IntArray = np.ndarray

UPPER_SHARE = 0.75  # of the opening made by the upper lid (it moves most in a real blink)
REACH_UP = 0.55  # how far above the lid line (of the eye's width) the skin follows the upper lid
REACH_DOWN = 0.3  # and below it, the lower lid
SIDE_REACH = 2.0  # of the width: how far along the skin `lid_sides` tells the lids apart
TIE = 0.05  # of the width: skin whose distances along the skin to the two margins differ less is a tie
DEPTH = 0.5  # skin further than this (of the eye's width) in front of or behind the lid line stays


def slit_sides(loop: IntArray) -> tuple[IntArray, IntArray]:
    """(upper path corner to corner, its lower copies in the same order) of a loop made by
    `openings.cut_slit` (the path, then the copies of its inner vertices in reverse)."""
    loop = np.asarray(loop, dtype=np.int64)
    n = (len(loop) + 2) // 2
    path = loop[:n]
    lower = np.r_[path[0], loop[n:][::-1], path[-1]]
    return path, lower


def lid_sides(vertices: FloatArray, triangles: IntArray, upper: IntArray, lower: IntArray,
              ties_upper: bool = False) -> np.ndarray:
    """(N,) bool: the vertices nearer, along the mesh's edges, to the upper chain's inner vertices
    than to the lower's, within SIDE_REACH x the opening's width of them; the rest False. A thick
    lid's front can hang below the rims' middle (the scanned head's upper lid, blinked, reaches
    down over its own margin to the lower lid's): by height such skin would be taken for the lower
    lid's and torn from its own when the lids part. `ties_upper`: skin between the corners about as
    far from either chain (within TIE x the width) is given to the upper lid. Such skin is reached
    from both only round the corners (a sheet lying over the opening, such as a shut lid's front
    hanging over a line cut behind it), and which chain is nearer turns on an edge at a corner: a
    sheet torn between the lids is stretched across the opening when they part."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    v = np.asarray(vertices, float)
    t = np.asarray(triangles, dtype=np.int64)
    upper, lower = np.asarray(upper, dtype=np.int64), np.asarray(lower, dtype=np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    graph = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(v), len(v))).tocsr()
    limit = SIDE_REACH * float(np.linalg.norm(v[upper[-1]] - v[upper[0]]))
    to_upper = dijkstra(graph, directed=False, indices=upper[1:-1], min_only=True, limit=limit)
    to_lower = dijkstra(graph, directed=False, indices=lower[1:-1], min_only=True, limit=limit)
    sides = np.isfinite(to_upper) & (to_upper < to_lower)
    if ties_upper:
        axis = v[upper[-1]] - v[upper[0]]
        along = (v - v[upper[0]]) @ axis / (axis @ axis)
        tie = np.isfinite(to_upper) & np.isfinite(to_lower) & (along > 0.0) & (along < 1.0)
        tie[tie] = np.abs(to_upper[tie] - to_lower[tie]) < TIE * limit / SIDE_REACH
        sides[tie] = True
    return sides


def set_gap(vertices: FloatArray, upper: IntArray, lower: IntArray, gap: float, up: FloatArray,
            upper_share: float = UPPER_SHARE, upper_side: np.ndarray | None = None,
            profile: FloatArray | None = None, whole: np.ndarray | None = None) -> FloatArray:
    """The vertices with the opening between two chains (corner to corner, both from the same
    corner) made `gap` wide at the middle: a shut line opens along a sine that is nothing at the
    corners; an open one keeps its shape, scaled. The upper chain takes `upper_share` of the
    change, the lower the rest, and the skin within REACH_UP / REACH_DOWN of the eye's (mouth's)
    width above (below) follows smoothly; nothing beyond the corners or far in depth moves. Which
    lid a vertex follows: `upper_side` (N,) bool (`lid_sides`) when given, else whether it lies
    above the middle between the chains; a vertex of one lid lying beyond the other's chain
    (skin hanging over the opening) follows less the further it lies beyond, over the other
    side's reach. `profile` (K,): the gap wanted at K evenly spaced points from corner to corner
    (over `gap`, the middle's), closing only: each column narrower than that is left as it is.
    `whole` (N,) bool: vertices that follow their lid whole wherever they lie (a sheet of one lid
    hanging in front of the opening beyond the other's chain, `covering_sheet`)."""
    v = np.asarray(vertices, float).copy()
    upper, lower = np.asarray(upper, dtype=np.int64), np.asarray(lower, dtype=np.int64)
    a, b = v[upper[0]], v[upper[-1]]
    axis = b - a
    width = float(np.linalg.norm(axis))
    if width <= 0 or gap < 0:
        return v
    up = np.asarray(up, float) - (np.asarray(up, float) @ axis) * axis / width ** 2
    up /= np.linalg.norm(up)
    forward = np.cross(axis / width, up)

    def line(chain: IntArray, t: FloatArray, direction: FloatArray) -> FloatArray:
        tc = (v[chain] - a) @ axis / width ** 2
        order = np.argsort(tc)
        return np.interp(t, tc[order], ((v[chain] - a) @ direction)[order])

    t = np.clip((v - a) @ axis / width ** 2, 0.0, 1.0)
    inside = (((v - a) @ axis / width ** 2) > 0.0) & (((v - a) @ axis / width ** 2) < 1.0)
    top, bottom = line(upper, t, up), line(lower, t, up)
    now = top - bottom
    mid = float(line(upper, np.array([0.5]), up)[0] - line(lower, np.array([0.5]), up)[0])
    shape = now / mid if mid > 1e-3 * width else np.sin(np.pi * t)
    change = gap * shape - now
    if profile is not None:
        want = gap * np.interp(t, np.linspace(0.0, 1.0, len(profile)), np.asarray(profile, float))
        change = np.minimum(want - now, 0.0)
    h = (v - a) @ up
    depth = (v - a) @ forward - 0.5 * (line(upper, t, forward) + line(lower, t, forward))
    near = inside & (np.abs(depth) < DEPTH * width)
    centre = 0.5 * (top + bottom)
    move = np.zeros(len(v))
    high = h >= centre if upper_side is None else np.asarray(upper_side, bool)
    above = near & high
    below = near & ~high
    over = np.clip(h - top, 0.0, None) / (REACH_UP * width)
    under = np.clip(bottom - h, 0.0, None) / (REACH_DOWN * width)
    beyond_top, beyond_bottom = over.copy(), under.copy()  # of the other lid's chain: follows less
    if whole is not None:
        beyond_top[np.asarray(whole, bool)] = 0.0
        beyond_bottom[np.asarray(whole, bool)] = 0.0
    move[above] = upper_share * (np.clip(1.0 - over[above], 0.0, 1.0)
                                 * np.clip(1.0 - beyond_bottom[above], 0.0, 1.0)) ** 2
    move[below] = -(1.0 - upper_share) * (np.clip(1.0 - under[below], 0.0, 1.0)
                                          * np.clip(1.0 - beyond_top[below], 0.0, 1.0)) ** 2
    move[upper[1:-1]] = upper_share
    move[lower[1:-1]] = -(1.0 - upper_share)
    move[[upper[0], upper[-1]]] = 0.0
    return v + (move * change)[:, None] * up


def open_lids(vertices: FloatArray, loop: IntArray, ratio: float, up: FloatArray,
              triangles: IntArray | None = None) -> FloatArray:
    """The vertices with the lids of one cut eye (`openings.cut_slit`'s loop) parted by `ratio` x
    the eye's width at the middle, tapering to nothing at the corners; with `triangles`, each
    vertex follows the lid it belongs to along the skin (`lid_sides`), else the one it lies on the
    side of, and the margin whose skin lies higher is the upper one, whichever side of the cut
    holds the copies."""
    path, lower = slit_sides(loop)
    width = float(np.linalg.norm(vertices[path[-1]] - vertices[path[0]]))
    sides = None
    if triangles is not None:
        sides = lid_sides(vertices, triangles, path, lower)
        other = lid_sides(vertices, triangles, lower, path)
        h = np.asarray(vertices, float) @ np.asarray(up, float)
        if sides.any() and other.any() and h[sides].mean() < h[other].mean():
            # the cut gave the path's copies to the upper lid's skin (a lid line that winds along a
            # scan's edges can start on either side): the copies are the upper margin
            path, lower, sides = lower, path, other
    return set_gap(vertices, path, lower, ratio * width, up, upper_side=sides)
