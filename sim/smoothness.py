"""Whether closed lids and pressed lips stay clean: the margins keep their order along the lid or
lip line (no zig-zag crossing), and no triangle next to them folds over (its normal turned more
than 90 degrees from rest). Pure geometry on a pose; used by tests and benchmarks."""

from __future__ import annotations

import numpy as np

from sim.model import FaceMesh


def _halves(loop: np.ndarray, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """The two paths of a closed vertex loop between vertices a and b (both ends included)."""
    loop = np.asarray(loop)
    ia, ib = int(np.flatnonzero(loop == a)[0]), int(np.flatnonzero(loop == b)[0])
    rolled = np.roll(loop, -ia)
    k = (ib - ia) % len(loop)
    return rolled[: k + 1], np.concatenate([rolled[k:], rolled[:1]])[::-1]


def margin_rows(mesh: FaceMesh) -> dict[str, np.ndarray]:
    """Vertex rows along each lid margin and each lip (ordered from one corner to the other):
    eye_l_upper, eye_l_lower, ..., lip_upper, lip_lower. Which half is upper is read at rest."""
    lm, v = mesh.landmarks, mesh.vertices
    out: dict[str, np.ndarray] = {}
    for s, loop in (("l", mesh.eye_loops[0]), ("r", mesh.eye_loops[1])):
        p, q = _halves(loop, lm[f"eye_inner_{s}"], lm[f"eye_outer_{s}"])
        up, low = (p, q) if v[p, 1].mean() > v[q, 1].mean() else (q, p)
        out[f"eye_{s}_upper"], out[f"eye_{s}_lower"] = up, low
    p, q = _halves(mesh.mouth_loop, lm["mouth_corner_r"], lm["mouth_corner_l"])
    up, low = (p, q) if v[p, 1].mean() > v[q, 1].mean() else (q, p)
    out["lip_upper"], out["lip_lower"] = up, low
    return out


def out_of_order(rest: np.ndarray, pos: np.ndarray, row: np.ndarray) -> int:
    """How many steps along the row go backwards along the corner-to-corner direction (measured at
    rest, in the frontal plane): 0 for a margin that keeps its order."""
    axis = rest[row[-1], :2] - rest[row[0], :2]
    axis /= np.linalg.norm(axis)
    t = pos[row, :2] @ axis
    return int(np.sum(np.diff(t) <= 0.0))


def near_triangles(mesh: FaceMesh, rows: list[np.ndarray], rings: int = 2) -> np.ndarray:
    """Indices of the triangles within `rings` edge rings of the given rows' vertices."""
    tri = np.asarray(mesh.triangles)
    mark = np.zeros(len(mesh.vertices), bool)
    mark[np.concatenate(rows)] = True
    for _ in range(rings):
        hit = mark[tri].any(axis=1)
        mark[tri[hit].ravel()] = True
    return np.flatnonzero(mark[tri].all(axis=1))


def folded(rest: np.ndarray, pos: np.ndarray, triangles: np.ndarray) -> int:
    """How many of the triangles have turned their normal more than 90 degrees from rest."""
    def normals(x: np.ndarray) -> np.ndarray:
        a, b, c = (x[triangles[:, k]] for k in range(3))
        return np.cross(b - a, c - a)

    return int(np.sum(np.sum(normals(rest) * normals(pos), axis=1) <= 0.0))


def creased(rest: np.ndarray, pos: np.ndarray, triangles: np.ndarray, degrees: float = 90.0) -> int:
    """How many interior edges among the triangles bend sharper than `degrees` between their two
    triangles' normals at the pose while they bent less than that at rest: a crumple or zig-zag,
    as opposed to a smooth roll of the skin."""
    tri = np.asarray(triangles)
    edges: dict[tuple[int, int], list[int]] = {}
    for t, (a, b, c) in enumerate(tri):
        for e in ((a, b), (b, c), (c, a)):
            edges.setdefault((min(e), max(e)), []).append(t)
    pairs = np.array([ts for ts in edges.values() if len(ts) == 2], dtype=np.int64).reshape(-1, 2)

    def unit_normals(x: np.ndarray) -> np.ndarray:
        a, b, c = (x[tri[:, k]] for k in range(3))
        n = np.cross(b - a, c - a)
        return n / np.maximum(np.linalg.norm(n, axis=1), 1e-30)[:, None]

    limit = np.cos(np.radians(degrees))
    n0, n1 = unit_normals(rest), unit_normals(pos)
    before = np.sum(n0[pairs[:, 0]] * n0[pairs[:, 1]], axis=1)
    after = np.sum(n1[pairs[:, 0]] * n1[pairs[:, 1]], axis=1)
    return int(np.sum((after < limit) & (before >= limit)))


def zigzag(pos: np.ndarray, row: np.ndarray) -> float:
    """The largest second difference of height along a row (cm): how far a vertex stands above or
    below the midpoint of its two neighbours. A clean margin bends smoothly; a zig-zag alternates."""
    y = pos[np.asarray(row), 1]
    return float(np.max(np.abs(y[1:-1] - 0.5 * (y[:-2] + y[2:])))) if len(y) > 2 else 0.0


def meeting_gap(pos: np.ndarray, upper: np.ndarray, lower: np.ndarray, inner: float = 0.8) -> float:
    """The largest height (cm) of the upper margin above or below the lower one, over the middle
    `inner` fraction of the opening's width: how far closed lids are from meeting along the line."""
    ux, uy = pos[upper, 0], pos[upper, 1]
    order = np.argsort(pos[lower, 0])
    lx, ly = pos[lower, 0][order], pos[lower, 1][order]
    lo, hi = min(ux[0], ux[-1]), max(ux[0], ux[-1])
    pad = 0.5 * (1.0 - inner) * (hi - lo)
    keep = (ux > lo + pad) & (ux < hi - pad)
    return float(np.max(np.abs(uy[keep] - np.interp(ux[keep], lx, ly)))) if keep.any() else 0.0
