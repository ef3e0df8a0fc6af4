"""Recover required edges in a planar triangulation by edge flips (a small constrained Delaunay).

Delaunay of the chart points almost always already contains the loop and border edges; where a
thin spot (a mouth corner) breaks that, flipping the edges that cross the missing one restores it
(Sloan 1993's edge-recovery loop), so no triangle ever spans a hole.
"""

from __future__ import annotations

import numpy as np

FloatArray = np.ndarray


def _orient(a: FloatArray, b: FloatArray, c: FloatArray) -> float:
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _cross(p: FloatArray, a: int, b: int, c: int, d: int) -> bool:
    """Segments a-b and c-d cross at an interior point."""
    return (_orient(p[a], p[b], p[c]) * _orient(p[a], p[b], p[d]) < 0) and (
        _orient(p[c], p[d], p[a]) * _orient(p[c], p[d], p[b]) < 0
    )


def recover_edges(pts: FloatArray, tri: np.ndarray, edges: list[tuple[int, int]]) -> np.ndarray:
    """Triangles (CCW) containing every edge in `edges`, by flipping crossing edges."""
    tris = [list(map(int, t)) for t in tri]
    have0 = {frozenset(e) for t in tris for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
    for a, b in (e for e in edges if frozenset(e) not in have0):
        for _ in range(200):
            have = {frozenset(e) for t in tris for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))}
            if frozenset((a, b)) in have:
                break
            flipped = False
            edge_tris: dict[frozenset[int], list[int]] = {}
            for k, t in enumerate(tris):
                for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
                    edge_tris.setdefault(frozenset(e), []).append(k)
            for e, ks in edge_tris.items():
                if len(ks) != 2:
                    continue
                c, d = tuple(e)
                if not _cross(pts, a, b, c, d):
                    continue
                t1, t2 = tris[ks[0]], tris[ks[1]]
                x = next(v for v in t1 if v not in e)
                y = next(v for v in t2 if v not in e)
                # The quad x-c-y-d must be convex for the flip c-d -> x-y.
                if _orient(pts[x], pts[y], pts[c]) * _orient(pts[x], pts[y], pts[d]) >= 0:
                    continue
                if not _cross(pts, x, y, c, d):
                    continue
                for k, (p, q) in zip(ks, ((x, y), (y, x))):
                    r = c if _orient(pts[p], pts[q], pts[c]) > 0 else d
                    tris[k] = [p, q, r]
                flipped = True
                break
            if not flipped:
                raise RuntimeError(f"cannot recover edge {a}-{b}")
        else:
            raise RuntimeError(f"edge {a}-{b} not recovered")
    out = np.array(tris, dtype=np.int64)
    a_, b_, c_ = pts[out[:, 0]], pts[out[:, 1]], pts[out[:, 2]]
    area = (b_[:, 0] - a_[:, 0]) * (c_[:, 1] - a_[:, 1]) - (b_[:, 1] - a_[:, 1]) * (c_[:, 0] - a_[:, 0])
    out[area < 0] = out[area < 0][:, [0, 2, 1]]
    return out
