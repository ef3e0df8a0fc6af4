"""Small, vectorised mesh geometry the transfer needs: edges, normals, boundary loops, closest
points, point location in a flat triangulation and radial ray casts. Written here (not trimesh)
because trimesh's proximity and ray queries need optional spatial-index libraries."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from sim.springs import boundary_loops  # noqa: F401  (re-exported: the transfer's modules take it from here)

FloatArray = np.ndarray
IntArray = np.ndarray


def unique_edges(triangles: IntArray) -> IntArray:
    """(E, 2) sorted vertex pairs, each mesh edge once."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def edge_use_counts(triangles: IntArray) -> tuple[IntArray, IntArray]:
    """Each distinct edge (E, 2) and how many triangles use it (E,)."""
    e = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    edges, counts = np.unique(e, axis=0, return_counts=True)
    return edges, counts


def triangle_normals(vertices: FloatArray, triangles: IntArray) -> FloatArray:
    """(M, 3) area-weighted (unnormalised) triangle normals, right-hand rule."""
    v = vertices[triangles]
    return np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])


def vertex_normals(vertices: FloatArray, triangles: IntArray) -> FloatArray:
    """(N, 3) unit area-weighted vertex normals (zero for unused vertices)."""
    tn = triangle_normals(vertices, triangles)
    n = np.zeros_like(vertices, dtype=float)
    for k in range(3):
        np.add.at(n, triangles[:, k], tn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def in_polygon(points: FloatArray, polygon: FloatArray) -> np.ndarray:
    """Even-odd rule: which 2D points lie inside the closed polygon (K, 2)."""
    x, y = points[:, 0][:, None], points[:, 1][:, None]
    x0, y0 = polygon[:, 0][None], polygon[:, 1][None]
    x1, y1 = np.roll(polygon[:, 0], -1)[None], np.roll(polygon[:, 1], -1)[None]
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return (crosses & (x < xc)).sum(axis=1) % 2 == 1


def outer_loop(points2d: FloatArray, triangles: IntArray) -> IntArray:
    """The boundary loop enclosing the largest flat area: a mask's outer border (the others are
    its openings)."""
    def area(loop: IntArray) -> float:
        p = points2d[loop]
        return abs(float(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1))))
    return max(boundary_loops(triangles), key=area)


def _closest_on_segments(p: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    ab = b - a
    t = np.einsum("...k,...k->...", p - a, ab) / np.maximum(np.einsum("...k,...k->...", ab, ab), 1e-300)
    return a + np.clip(t, 0.0, 1.0)[..., None] * ab


def barycentric(p: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    """Barycentric coordinates (..., 3) of p in triangles abc, in 2D or 3D (projected on the plane)."""
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.einsum("...k,...k->...", v0, v0)
    d01 = np.einsum("...k,...k->...", v0, v1)
    d11 = np.einsum("...k,...k->...", v1, v1)
    d20 = np.einsum("...k,...k->...", v2, v0)
    d21 = np.einsum("...k,...k->...", v2, v1)
    den = d00 * d11 - d01 * d01
    den = np.where(np.abs(den) > 1e-300, den, 1e-300)
    w1 = (d11 * d20 - d01 * d21) / den
    w2 = (d00 * d21 - d01 * d20) / den
    return np.stack([1.0 - w1 - w2, w1, w2], axis=-1)


def closest_points(
    points: FloatArray, vertices: FloatArray, triangles: IntArray, k: int = 24
) -> tuple[FloatArray, IntArray, FloatArray, FloatArray]:
    """Closest point on the mesh surface for each query: (closest (P,3), triangle (P,),
    barycentric (P,3), distance (P,)). Candidates are the k triangles with the nearest centroids,
    exact point-triangle distance among those."""
    points = np.atleast_2d(np.asarray(points, float))
    tri_v = vertices[triangles]
    tree = cKDTree(tri_v.mean(axis=1))
    k = min(k, len(triangles))
    _, cand = tree.query(points, k=k)
    cand = cand.reshape(len(points), k)
    a, b, c = tri_v[cand, 0], tri_v[cand, 1], tri_v[cand, 2]
    p = points[:, None, :]
    bary = barycentric(p, a, b, c)
    inside = (bary >= 0).all(axis=-1)
    on_plane = bary[..., :1] * a + bary[..., 1:2] * b + bary[..., 2:] * c
    options = [on_plane, _closest_on_segments(p, a, b), _closest_on_segments(p, b, c),
               _closest_on_segments(p, c, a)]
    dists = np.stack([np.linalg.norm(o - p, axis=-1) for o in options], axis=-1)
    dists[..., 0] = np.where(inside, dists[..., 0], np.inf)
    which = dists.argmin(axis=-1)
    best_d = np.take_along_axis(dists, which[..., None], -1)[..., 0]
    j = best_d.argmin(axis=1)
    rows = np.arange(len(points))
    stacked = np.stack(options, axis=2)  # (P, k, 4, 3)
    closest = stacked[rows, j, which[rows, j]]
    tri = cand[rows, j]
    bary_c = barycentric(closest, a[rows, j], b[rows, j], c[rows, j])
    return closest, tri, bary_c, best_d[rows, j]


def locate_2d(
    queries: FloatArray, verts2d: FloatArray, triangles: IntArray, k: int = 16, slack: float = 1e-3
) -> tuple[IntArray, FloatArray, np.ndarray]:
    """Which flat triangle holds each 2D query: (triangle (Q,), barycentric (Q,3), inside (Q,)).
    Outside the triangulation the candidate with the largest smallest coordinate is returned
    (a mild extrapolation) and inside is False; points within `slack` (in barycentric units) of a
    triangle count as inside, so a mesh's own border vertices are not lost to rounding."""
    tri_v = verts2d[triangles]
    tree = cKDTree(tri_v.mean(axis=1))
    k = min(k, len(triangles))
    _, cand = tree.query(queries, k=k)
    cand = cand.reshape(len(queries), k)
    bary = barycentric(queries[:, None, :], tri_v[cand, 0], tri_v[cand, 1], tri_v[cand, 2])
    score = bary.min(axis=-1)
    j = score.argmax(axis=1)
    rows = np.arange(len(queries))
    return cand[rows, j], bary[rows, j], score[rows, j] >= -slack


def ray_triangle(
    origins: FloatArray, dirs: FloatArray, a: FloatArray, b: FloatArray, c: FloatArray
) -> FloatArray:
    """Moller-Trumbore distance t along each ray to each triangle (broadcast), inf on a miss."""
    e1, e2 = b - a, c - a
    pv = np.cross(dirs, e2)
    det = np.einsum("...k,...k->...", e1, pv)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    tv = origins - a
    u = np.einsum("...k,...k->...", tv, pv) * inv
    qv = np.cross(tv, e1)
    v = np.einsum("...k,...k->...", dirs, qv) * inv
    t = np.einsum("...k,...k->...", e2, qv) * inv
    eps = 1e-9
    hit = ok & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t > 0)
    return np.where(hit, t, np.inf)


def split_pinched(vertices: FloatArray, triangles: IntArray, where: np.ndarray) -> tuple[FloatArray, IntArray, IntArray]:
    """Split each vertex of `where` (a (N,) mask) that a border loop (`boundary_loops`) passes twice:
    the border touches itself there (e.g. lips modelled meeting at one point of the mouth's hole)
    and the walk went round both holes as one. Every fan of its triangles joined to the others only
    through the vertex gets a copy of its own, appended after the existing vertices, so the
    opening's border is a simple loop (the simulation's lid and lip rows walk it corner to corner).
    A border touching itself where the walk kept the holes apart is left as it is. Returns
    (vertices, triangles, the split vertices' original indices)."""
    twice: set[int] = set()
    for loop in boundary_loops(triangles):
        seen, count = np.unique(loop, return_counts=True)
        twice.update(int(v) for v in seen[count > 1] if where[v])
    pinched = np.array(sorted(twice), dtype=np.int64)
    if not len(pinched):
        return vertices, triangles, pinched
    tris = np.array(triangles, copy=True)
    extra: list[int] = []
    for v in pinched.tolist():
        edges, counts = edge_use_counts(tris)  # again: a split before may have renamed this fan's edges
        shared = {tuple(e) for e in edges[counts == 2].tolist()}
        fan = np.flatnonzero((tris == v).any(axis=1))
        group = -np.ones(len(fan), dtype=np.int64)
        for start in range(len(fan)):
            if group[start] >= 0:
                continue
            group[start] = group.max() + 1
            stack = [start]
            while stack:  # triangles of the fan that share an inner edge (v, w) are one fan
                a = stack.pop()
                ws = set(tris[fan[a]].tolist()) - {v}
                for b in np.flatnonzero(group < 0).tolist():
                    common = ws & set(tris[fan[b]].tolist())
                    if any((min(v, w), max(v, w)) in shared for w in common):
                        group[b] = group[start]
                        stack.append(b)
        for g in range(1, int(group.max()) + 1):
            block = tris[fan[group == g]]
            block[block == v] = len(vertices) + len(extra)
            tris[fan[group == g]] = block
            extra.append(v)
    return np.vstack([vertices, vertices[extra]]), tris, pinched
