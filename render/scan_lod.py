"""A coarser triangle list for the scanned head's plain skin, over the same vertices.

llvmpipe's cost for the scanned head is per triangle (fetch, set-up and binning on the calling
thread, then rasterising), and at 1280x720 the skin's triangles are small: a median of 9 px².
`coarse_plain()` is the plain skin (render.scan_look.ScanLook.skin_split: every triangle the brow
and vermilion terms do not reach) with fewer triangles, made by half-edge collapses: a vertex is
folded into a neighbour, so no vertex moves and every kept vertex keeps the normal and fold term
the full skin gives it (render.scan_kernel.scan_rows still runs on the full skin). The brows and
lips (the "features" triangles) and the plain skin's border with them are untouched, so the two
lists meet without cracks.

A collapse is judged by measuring what it loses, in every one of 26 poses of the head as the
renderer draws it (`_poses`: the default face at rest, with the jaw dropped and in the seven
presets, simulated, wrinkles included; ten of the scan's extreme shapes; identity modes): each
vertex it leaves out (the folded one and those folded into it before) against the new triangles
around the target, by distance and by the normal, fold term and baked occlusion interpolated there
against its own. Each error is taken over its tolerance (TOL_*); the collapses go cheapest first
while the worst stays within tolerance (the measured-error ordering of Hoppe's progressive meshes,
SIGGRAPH 1996, with a worst-case instead of a summed energy). Refused too: a collapse that turns a
triangle over (or nearly) in any pose, leaves a sliver or a long edge at rest, or breaks the
manifold (the link condition). Kept whole: the skin's openings and the rings next to them (the
lips' inner edge, the neck's cut), the skin around the eyes (lids, their folds, the crow's feet),
the glabella's frown lines, the nose, the ears and the chin (which crumples for a moment as the
jaw drops). The ears are then made coarser in a second pass over that list (`build_ears`): held to
0.4 mm (their rim is the head's outline from the front and the sides) and 0.12 rad of normal (the
plain shader lights per vertex: long triangles in the folds show stars of facets).

The eyeballs' shells as drawn are made coarser too (`build_eyes`): held to 0.2 mm (a convex shell:
facets lie inside it, so none pokes through a shut lid), and the gaze angle (the iris and pupil
are drawn per pixel from it) and the iris's chart coordinates interpolated at each left-out vertex
against its own.

The mouth's lining, gums and tongue as drawn (`build_inside`; the teeth stay whole: no collapse of
theirs keeps within the tolerances) are made coarser the same way, judged in the open mouth's
poses (INSIDE_POSES, the tongue out among them), each part's borders and the two rings next to
them kept whole (the lining's edge along the lips, the gums' and tongue's cut at their depth).

The lists are made once (`python -m render.scan_lod`, a few minutes; `python -m render.scan_lod
inside` the inside's alone, `... ears` the ears' pass alone over the list before it, `skin_plain`;
`... eyes` the eyeballs' alone) and shipped beside this module (`scan_lod.npz`): they depend only on
the scan's topology, which every identity shares. `error_cm` (`inside_error_cm`) is the largest
distance, over the poses, from a vertex of the full plain skin (inside) to the coarse one. The
renderer draws both coarse lists while the skin's triangles are small on screen
(render.scan_draw.ScanDraw.choose_level)."""

from __future__ import annotations

import heapq
import os
import sys
import tempfile
from functools import lru_cache
from pathlib import Path

import numpy as np

DATA = Path(__file__).with_name("scan_lod.npz")
TARGET = 0.5  # the share of the plain skin's triangles kept at most (the tolerances stop it sooner)
MIN_ANGLE = np.radians(12.0)  # the smallest angle a new triangle may have at rest
MAX_EDGE = 1.0  # cm: the longest edge a new triangle may have at rest
FLIP_COS = 0.5  # a new triangle's normal must stay within 60 degrees of the one it replaces, in every pose
OPENING_RINGS = 2  # rings of vertices around each opening of the skin kept whole
# what a left-out vertex may differ by from the coarse skin there, in any pose: a collapse moving
# the surface by more than TOL_CM is refused; the collapses are taken in the order of their worst
# error over these scales: distance, the turn of the normal interpolated there (the lighting), the
# fold term (render.scan_shaders: 1.8 of it darkens) and the baked occlusion
TOL_CM = 0.1
TOL_NORMAL = 0.35
TOL_FOLD = 0.06
TOL_OCCLUSION = 0.05
NOSE_BOX = ((-2.2, 2.2), (-2.2, 1.6), (9.2, 99.0))  # cm, the generic head: x, y, z of the nose kept whole
EAR_BOX = ((6.6, 99.0), (-2.5, 6.5), (-5.0, 3.0))  # cm, the generic head: |x|, y, z of the ears kept whole
GLABELLA_BOX = ((-1.8, 1.8), (3.0, 7.5), (8.0, 99.0))  # cm, the generic head: the frown lines kept whole
CHIN_BOX = ((-4.2, 4.2), (-8.4, -6.4), (4.0, 99.0))  # cm, the generic head: the chin, that crumples as the jaw drops
EAR_TOL_CM = 0.04  # cm: the ears' collapses (`build_ears`): a pixel at 1280x720 with the default camera
TOL_ALBEDO = 0.015  # the ears' collapses: the albedo interpolated at a left-out vertex against its own (of 1)
EAR_TOL_NORMAL = 0.12  # rad: the ears' collapses: their folds' shading (the skin's 0.35 left facets in the concha)
EYE_REACH = 0.8  # cm from the eyes' openings kept whole: lids, their folds and the crow's feet


def _poses() -> tuple[np.ndarray, np.ndarray]:
    """(P, N, 3) positions and (P, N, 4) normal and fold term (render.scan_kernel.scan_rows) of the
    scanned head as the renderer draws it: the default face at rest, with the jaw dropped (AU27)
    and in each of the seven presets, simulated and dressed (wrinkles included); the generic head
    in a few of the scan's own extreme shapes; the first four identity modes at +-2.5 standard
    deviations."""
    from render.scan_look import ScanLook
    from render.scan_rows import ScanRows
    from sim.face.scan.data import scan_data
    from sim.facs import EXPRESSIONS

    rows = _settled(((), ("AU27",), *EXPRESSIONS))
    d = scan_data()
    shapes = [d.neutral + d.expression(n) for n in EXTREMES]
    for k in range(4):
        for sd in (-2.5, 2.5):
            w = np.zeros(k + 1)
            w[k] = sd
            shapes.append(d.neutral + d.identity_delta(w))
    maker = ScanRows(ScanLook(d.neutral))
    rows += [maker.rows(p).copy() for p in shapes]
    r = np.stack(rows).astype(np.float64)
    return r[..., :3], r[..., 3:7]


EXTREMES = ("jawOpen", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L", "browInnerUp_L", "mouthPucker",
            "cheekPuff_L", "noseSneer_R", "mouthFunnel", "browDown_R")


def _border_rings(tri: np.ndarray, n: int) -> np.ndarray:
    """(n,) bool: the vertices of the triangles' borders and the OPENING_RINGS rings next to them."""
    from sim.springs import boundary_loops

    ring = np.zeros(n, bool)
    for lp in boundary_loops(tri):
        ring[np.asarray(lp)] = True
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    for _ in range(OPENING_RINGS):
        grow = ring.copy()
        grow[edges[ring[edges[:, 0]], 1]] = True
        grow[edges[ring[edges[:, 1]], 0]] = True
        ring = grow
    return ring


def _kept_whole(tri: np.ndarray, plain: np.ndarray, n: int) -> np.ndarray:
    """(n,) bool: the vertices no collapse may remove."""
    from sim.face.scan.data import scan_data
    from sim.springs import boundary_loops

    keep = np.zeros(n, bool)
    keep[tri[~plain].ravel()] = True  # the brows' and lips' triangles and their border
    keep |= _border_rings(tri, n)
    neutral = scan_data().neutral
    for box, x in ((NOSE_BOX, neutral[:, 0]), (EAR_BOX, np.abs(neutral[:, 0])), (GLABELLA_BOX, neutral[:, 0]),
                   (CHIN_BOX, neutral[:, 0])):
        (x0, x1), (y0, y1), (z0, z1) = box
        y, z = neutral[:, 1], neutral[:, 2]
        keep |= (x > x0) & (x < x1) & (y > y0) & (y < y1) & (z > z0) & (z < z1)
    from scipy.spatial import cKDTree

    loops = [np.asarray(lp) for lp in boundary_loops(tri)]
    eyes = sorted(loops, key=lambda lp: -float(neutral[lp, 1].mean()))[:2]  # the two highest openings
    near, _ = cKDTree(neutral[np.concatenate(eyes)]).query(neutral, distance_upper_bound=EYE_REACH)
    keep |= np.isfinite(near)
    return keep


class _Collapser:
    """Half-edge collapses over a triangle list; the live triangles are `tri[alive]`. Each removed
    vertex is owned by the vertex it was folded into (and passed on with it), and a collapse is
    judged by how well the new triangles around the target stand for every vertex the removed one
    owns, in every pose: distance, and the fold term, the normal and the baked occlusion
    interpolated there against the vertex's own."""

    def __init__(self, tri: np.ndarray, pos: np.ndarray, attr: np.ndarray, removable: np.ndarray) -> None:
        self.tri = tri.copy()
        self.alive = np.ones(len(tri), bool)
        self.pos = pos
        self.attr = attr  # (P, N, 5): nx ny nz fold occlusion
        self.removable = removable.copy()
        n = pos.shape[1]
        self.fan: list[set[int]] = [set() for _ in range(n)]
        for t, (a, b, c) in enumerate(tri):
            self.fan[a].add(t)
            self.fan[b].add(t)
            self.fan[c].add(t)
        self.owned: list[list[int]] = [[] for _ in range(n)]
        self.version = np.zeros(n, np.int64)
        self.tol_cm = TOL_CM  # the distance a left-out vertex may lie from the new triangles

    def neighbours(self, u: int) -> set[int]:
        out: set[int] = set()
        for t in self.fan[u]:
            out.update(int(v) for v in self.tri[t])
        out.discard(u)
        return out

    def cost(self, u: int, v: int) -> float:
        """The worst of the measured errors of folding u into v, each over its tolerance (above 1:
        refused), or inf when the collapse turns a triangle over, makes a sliver or a non-manifold."""
        nu, nv = self.neighbours(u), self.neighbours(v)
        if len(nu & nv) != 2:  # the link condition: the result stays a manifold
            return np.inf
        moved = [t for t in self.fan[u] if v not in self.tri[t]]
        if not moved:
            return np.inf
        old = self.tri[moved]
        new = np.where(old == u, v, old)
        P = self.pos
        a0, b0, c0 = P[:, old[:, 0]], P[:, old[:, 1]], P[:, old[:, 2]]
        a1, b1, c1 = P[:, new[:, 0]], P[:, new[:, 1]], P[:, new[:, 2]]
        n0 = np.cross(b0 - a0, c0 - a0)
        n1 = np.cross(b1 - a1, c1 - a1)
        l0, l1 = np.linalg.norm(n0, axis=2), np.linalg.norm(n1, axis=2)
        if (l1 < 1e-9).any() or ((n0 * n1).sum(axis=2) < FLIP_COS * l0 * l1).any():
            return np.inf
        r = P[0][new]  # the new triangles at rest: no slivers, none too long
        for k in range(3):
            e1 = r[:, (k + 1) % 3] - r[:, k]
            e2 = r[:, (k + 2) % 3] - r[:, k]
            l1_, l2_ = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
            if (l1_ > MAX_EDGE).any():
                return np.inf
            c = (e1 * e2).sum(axis=1) / np.maximum(l1_ * l2_, 1e-12)
            if (np.arccos(np.clip(c, -1, 1)) < MIN_ANGLE).any():
                return np.inf
        w = np.array([u, *self.owned[u]])
        x = P[:, w][:, :, None]  # (P, M, 1, 3)
        a, b, c = a1[:, None], b1[:, None], c1[:, None]  # (P, 1, F, 3)
        dist = _point_triangle(x, a, b, c)  # (P, M, F)
        f = np.argmin(dist, axis=2)  # the nearest new triangle to each owned vertex, per pose
        geo = np.take_along_axis(dist, f[..., None], 2)[..., 0]
        tri = new[f]  # (P, M, 3)
        pi = np.arange(P.shape[0])[:, None, None]
        ta, tb, tc = P[pi, tri[..., 0:1]][..., 0, :], P[pi, tri[..., 1:2]][..., 0, :], P[pi, tri[..., 2:3]][..., 0, :]
        bary = _barycentric(P[:, w], ta, tb, tc)  # (P, M, 3)
        at = self.attr[pi, tri]  # (P, M, 3, 5)
        guess = (bary[..., None] * at).sum(axis=2)
        own = self.attr[:, w]
        nrm = guess[..., :3] / np.maximum(np.linalg.norm(guess[..., :3], axis=-1, keepdims=True), 1e-12)
        turn = np.arccos(np.clip((nrm * own[..., :3]).sum(-1), -1.0, 1.0))
        err = np.maximum.reduce([geo / self.tol_cm, turn / TOL_NORMAL, np.abs(guess[..., 3] - own[..., 3]) / TOL_FOLD,
                                 np.abs(guess[..., 4] - own[..., 4]) / TOL_OCCLUSION])
        if at.shape[-1] > 5:  # the albedo (the ears' redder skin), at rest
            err = np.maximum(err, np.abs(guess[..., 5:] - own[..., 5:]).max(-1) / TOL_ALBEDO)
        worst = float(err.max())
        return worst if worst <= 1.0 else np.inf

    def best(self, u: int) -> tuple[float, int]:
        if not self.removable[u]:
            return np.inf, -1
        out = (np.inf, -1)
        for v in sorted(self.neighbours(u)):
            c = self.cost(u, v)
            if c < out[0]:
                out = (c, v)
        return out

    def collapse(self, u: int, v: int) -> set[int]:
        """Fold u into v; the vertices whose candidate collapses changed."""
        touched = self.neighbours(u) | {v}
        for t in list(self.fan[u]):
            if v in self.tri[t]:
                self.alive[t] = False
                for w in self.tri[t]:
                    self.fan[int(w)].discard(t)
            else:
                self.tri[t][self.tri[t] == u] = v
                self.fan[v].add(t)
        self.fan[u] = set()
        self.owned[v] += [u, *self.owned[u]]
        self.owned[u] = []
        self.removable[u] = False
        return touched


def _collapse(col: "_Collapser", keep: np.ndarray, goal: int, say_every: int = 0) -> "_Collapser":
    """Collapse the cheapest edges first (each vertex's best, re-judged when its fan changes) while
    the tolerances allow, until `goal` triangles are removed; `say_every` removed: a progress line."""
    heap = []
    for u in np.flatnonzero(~keep):
        c, v = col.best(int(u))
        if v >= 0:
            heap.append((c, int(u), v, 0))
    heapq.heapify(heap)
    removed = 0
    while heap and removed < goal:
        c, u, v, ver = heapq.heappop(heap)
        if ver != col.version[u] or not col.removable[u]:
            continue
        touched = col.collapse(u, v)
        removed += 2
        for w in touched:
            col.version[w] += 1
            c2, v2 = col.best(w)
            if v2 >= 0:
                heapq.heappush(heap, (c2, w, v2, int(col.version[w])))
        if say_every and removed % say_every == 0:
            print(f"removed {removed}/{goal} triangles, error {c:.3f} of the tolerance", flush=True)
    return col


def build(target: float = TARGET, verbose: bool = False) -> tuple[np.ndarray, float]:
    """(K, 3) int32 the coarse plain skin (scan vertex indices, the scan's winding) and its error
    (cm, see `deviation`)."""
    from render.scan_look import BROW_CLEAR, LIP_CLEAR, ScanLook, _static_layout
    from sim.face.scan.data import N_VERTICES, scan_data

    lay = _static_layout()
    tri = lay["skin"].astype(np.int64)
    plain = (lay["brow"][tri] >= BROW_CLEAR).all(axis=1) & (lay["lip"][tri] >= LIP_CLEAR).all(axis=1)
    n_skin = int(tri.max()) + 1
    pos, rows = _poses()
    occ = ScanLook(scan_data().neutral).material[:, 2].astype(np.float64)
    attr = np.concatenate([rows, np.broadcast_to(occ[None, :, None], (len(rows), N_VERTICES, 1))], axis=2)
    pos, attr = pos[:, :n_skin], attr[:, :n_skin]
    keep = _kept_whole(tri, plain, N_VERTICES)[:n_skin]
    goal = int(plain.sum() * (1.0 - target))  # triangles to remove (two per collapse)
    col = _collapse(_Collapser(tri, pos, attr, ~keep), keep, goal, 1000 if verbose else 0)
    out = col.tri[col.alive]
    # a triangle keeps its slot, and only plain triangles have a removable corner: the flags hold
    coarse = out[plain[col.alive]]
    return coarse.astype(np.int32), deviation(coarse, tri[plain], pos)


def _projection(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, ...]:
    """(p - a, the triangles' normal n, |n|², and the barycentrics v, s of b and c) of points p
    (..., 3) projected on the planes of the triangles a b c."""
    ab, ac = b - a, c - a
    n = np.cross(ab, ac)
    nn = np.maximum((n * n).sum(-1), 1e-18)
    w = p - a
    v = (np.cross(w, ac) * n).sum(-1) / nn
    s = (np.cross(ab, w) * n).sum(-1) / nn
    return w, n, nn, v, s


def _barycentric(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(..., 3) barycentric weights of the points nearest p on the triangles a b c, clamped to the
    triangle (negative weights dropped and the rest renormalised)."""
    _, _, _, v, s = _projection(p, a, b, c)
    out = np.clip(np.stack([1.0 - v - s, v, s], axis=-1), 0.0, None)
    return out / np.maximum(out.sum(-1, keepdims=True), 1e-12)


def _point_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distances from points p (..., 3) to triangles a b c (..., 3) (Ericson, Real-Time Collision
    Detection, 5.1.5: the closest point by Voronoi regions, here by clamping barycentrics on each
    edge when the projection falls outside)."""
    w, n, nn, v, s = _projection(p, a, b, c)
    inside = (v >= 0) & (s >= 0) & (v + s <= 1)
    d_plane = np.abs((w * n).sum(-1)) / np.sqrt(nn)

    def seg(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        e = p1 - p0
        t = np.clip(((p - p0) * e).sum(-1) / np.maximum((e * e).sum(-1), 1e-18), 0, 1)
        return np.linalg.norm(p - p0 - t[..., None] * e, axis=-1)

    d_edge = np.minimum(np.minimum(seg(a, b), seg(b, c)), seg(c, a))
    return np.where(inside, d_plane, d_edge)


def deviation(coarse: np.ndarray, fine: np.ndarray, poses: np.ndarray, every: bool = False) -> float:
    """cm: the largest distance, over the poses, from a vertex of the fine triangles to the
    coarse ones (the nearest 12 by centroid examined; `every`: all of them, for layered surfaces
    such as the tongue on the gums, where the nearest centroids may lie on the other layer)."""
    from scipy.spatial import cKDTree

    verts = np.unique(fine)
    worst = 0.0
    if every:
        for pos in poses:
            near = np.full(len(verts), np.inf)
            for lo in range(0, len(coarse), 512):
                t = coarse[lo:lo + 512]
                near = np.minimum(near, _point_triangle(pos[verts][:, None], pos[t[:, 0]][None], pos[t[:, 1]][None],
                                                        pos[t[:, 2]][None]).min(axis=1))
            worst = max(worst, float(near.max()))
        return worst
    for pos in poses:
        cen = pos[coarse].mean(axis=1)
        _, idx = cKDTree(cen).query(pos[verts], k=12)
        t = coarse[idx]
        d = _point_triangle(pos[verts][:, None], pos[t[..., 0]], pos[t[..., 1]], pos[t[..., 2]]).min(axis=1)
        worst = max(worst, float(d.max()))
    return worst


def ear_vertices(tri: np.ndarray, reach: int = 2) -> np.ndarray:
    """(N,) bool the vertices an ear collapse may remove: inside EAR_BOX (the generic head) with
    every vertex within `reach` edges of them inside it too, so the rest of the skin's list (judged
    by `build`, whose owners are not kept) is not touched."""
    from sim.face.scan.data import N_VERTICES, scan_data

    neutral = scan_data().neutral
    (x0, x1), (y0, y1), (z0, z1) = EAR_BOX
    x, y, z = np.abs(neutral[:, 0]), neutral[:, 1], neutral[:, 2]
    inner = (x > x0) & (x < x1) & (y > y0) & (y < y1) & (z > z0) & (z < z1)
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]).astype(np.int64)
    out = ~inner
    for _ in range(reach):
        grow = out.copy()
        grow[edges[out[edges[:, 0]], 1]] = True
        grow[edges[out[edges[:, 1]], 0]] = True
        out = grow
    return ~out & (np.bincount(tri.ravel(), minlength=N_VERTICES) > 0)


def _plain_full() -> np.ndarray:
    """(F, 3) int64 the full plain skin (render.scan_look.ScanLook.skin_split's "plain")."""
    from render.scan_look import BROW_CLEAR, LIP_CLEAR, _static_layout

    lay = _static_layout()
    tri = lay["skin"].astype(np.int64)
    plain = (lay["brow"][tri] >= BROW_CLEAR).all(axis=1) & (lay["lip"][tri] >= LIP_CLEAR).all(axis=1)
    return tri[plain]


def build_ears(plain: np.ndarray, verbose: bool = False) -> tuple[np.ndarray, float, float]:
    """The coarse plain skin `plain` with its ears made coarser: collapses of the ears' vertices
    (`ear_vertices`) judged in the skin's 26 poses by the skin's tolerances but the distance, held
    to EAR_TOL_CM, and the normal, to EAR_TOL_NORMAL, so the ears' rim (the head's outline from the
    front and the sides) stays within about a pixel at 1280x720 and their folds keep their shading.
    ((K, 3) int32 the new list; the largest distance (cm), over the poses, of a vertex of the full
    plain skin from it, and of one of the full ears')."""
    from render.scan_look import ScanLook
    from sim.face.scan.data import N_VERTICES, scan_data

    global TOL_NORMAL
    tri = plain.astype(np.int64)
    pos, rows = _poses()
    occ = ScanLook(scan_data().neutral).material[:, 2].astype(np.float64)
    attr = np.concatenate([rows, np.broadcast_to(occ[None, :, None], (len(rows), N_VERTICES, 1))], axis=2)
    look = ScanLook(scan_data().neutral)
    albedo = np.broadcast_to(look.albedo.astype(np.float64)[None], (len(rows), N_VERTICES, 3))
    attr = np.concatenate([attr, albedo], axis=2)
    removable = ear_vertices(tri) & ~_border_rings(tri, N_VERTICES)
    col = _Collapser(tri, pos, attr, removable)
    col.tol_cm = EAR_TOL_CM
    skin_normal, TOL_NORMAL = TOL_NORMAL, EAR_TOL_NORMAL
    try:
        col = _collapse(col, ~removable, len(tri), 200 if verbose else 0)
    finally:
        TOL_NORMAL = skin_normal
    out = col.tri[col.alive]
    full = _plain_full()
    ears = ear_vertices(full, 0)
    return (out.astype(np.int32), deviation(out, full, pos),
            deviation(out, full[ears[full].all(axis=1)], pos))


EYE_TOL_CM = 0.02  # cm: the eyeballs' collapses (`build_eyes`): the gap a facet may open behind a lid's margin
EYE_TOL_ANGLE = 0.01  # rad: the gaze angle interpolated at a left-out vertex (the iris's and pupil's edges)
EYE_TOL_UV = 0.005  # the iris's chart coordinates interpolated there (its fibres)


def build_eyes(verbose: bool = False) -> tuple[np.ndarray, float]:
    """A coarser list of the eyeballs' shells as drawn (render.scan_look's "eyes" group) over the
    same vertices: ((K, 3) int32, the largest distance (cm) of a full shell's vertex from it in the
    poses). Judged in the skin's 26 poses (the eyeball turns rigidly with the gaze) by the distance
    (EYE_TOL_CM: the shell is convex, so a collapse moves it inward only, never through a lid), the
    normal (TOL_NORMAL), the gaze angle (EYE_TOL_ANGLE: the iris and pupil are drawn per pixel from
    it, so its error would move their edges and lose their roundness) and the chart coordinates
    (EYE_TOL_UV); the shells' borders and the rings next to them kept whole."""
    from render.scan_look import ScanLook
    from sim.face.scan.data import N_VERTICES, scan_data

    global TOL_CM
    look = ScanLook(scan_data().neutral)
    tri = look.groups["eyes"].astype(np.int64)
    pos, rows = _poses()
    P = len(pos)
    angle = look.gaze_angle * TOL_FOLD / EYE_TOL_ANGLE  # in the fold term's slot, scaled to its tolerance
    attr = np.concatenate([rows[..., :3], np.broadcast_to(angle[None, :, None], (P, N_VERTICES, 1)),
                           np.zeros((P, N_VERTICES, 1)),
                           np.broadcast_to((look.uv * TOL_ALBEDO / EYE_TOL_UV)[None], (P, N_VERTICES, 2))], axis=2)
    removable = np.zeros(N_VERTICES, bool)
    removable[np.unique(tri)] = True
    removable &= ~_border_rings(tri, N_VERTICES)
    col = _Collapser(tri, pos, attr, removable)
    col.tol_cm = EYE_TOL_CM
    col = _collapse(col, ~removable, len(tri), 200 if verbose else 0)
    out = col.tri[col.alive]
    return out.astype(np.int32), deviation(out, tri, pos[:4], every=True)


@lru_cache(maxsize=1)
def coarse_eyes() -> np.ndarray:
    """(K, 3) int32 the shipped coarse eyeballs' shells (`build_eyes`)."""
    with np.load(DATA, allow_pickle=False) as d:
        return d["eyes"].astype(np.int32)


def inside_of(tri: np.ndarray) -> np.ndarray:
    """(T,) bool which of these triangles lie in INSIDE_PARTS (of the mouth's: what `coarse_inside`
    stands for)."""
    from sim.face.scan.data import PARTS

    t = np.asarray(tri)
    return (t >= PARTS[INSIDE_PARTS[0]][0]).all(axis=1) & (t < PARTS[INSIDE_PARTS[-1]][1]).all(axis=1)


@lru_cache(maxsize=1)
def coarse_inside() -> tuple[np.ndarray, float]:
    """(K, 3) int32 the shipped coarse lining, gums and tongue and their error (cm)."""
    with np.load(DATA, allow_pickle=False) as d:
        return d["inside"].astype(np.int32), float(d["inside_error_cm"])


@lru_cache(maxsize=1)
def coarse_plain() -> tuple[np.ndarray, float]:
    """(K, 3) int32 the shipped coarse plain skin and its error (cm)."""
    with np.load(DATA, allow_pickle=False) as d:
        return d["plain"].astype(np.int32), float(d["error_cm"])


# the open mouth's poses the coarse inside is judged in: the jaw dropped, the presets that part the
# lips (sadness settles with them shut), and action units that open the mouth, the tongue out in two
INSIDE_POSES = (("AU27",), ("AU27", "AU19"), ("AU19", "AU26"), ("AU25",), ("AU12", "AU25"), ("AU20", "AU25", "AU26"),
                ("AU22", "AU25"), ("AU10", "AU16", "AU25"), "happiness", "surprise", "fear", "disgust", "contempt")
INSIDE_PARTS = ("mouth_socket", "gums_tongue")  # the lining, the gums and the tongue (the teeth stay whole)


def _settled(poses: tuple) -> list[np.ndarray]:
    """The rows (render.scan_kernel.scan_rows) of the scanned head (the default face) as drawn in
    each pose, settled (60 steps, the onset over 40): a pose is a tuple of action units or a
    preset's name."""
    from render.scan_draw import ScanPoser, dressing_of
    from sim.build import compile_model
    from sim.face.scan.rig import SCAN_PARAMS, scan_rig
    from sim.facs import apply_au, apply_expression, preset_face
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = compile_model(scan_rig(None), SCAN_PARAMS)  # the default face (the application caches it)
    poser = ScanPoser(dressing_of(model))
    rows = []
    for pose in poses:
        sim, state = Simulator(model), model.rest_state()
        for k in range(60):
            control = FaceControl(model)
            w = min(1.0, (k + 1) / 40)
            if isinstance(pose, str):
                apply_expression(control, pose, w, preset_face(model.rig))
            else:
                for au in pose:
                    apply_au(control, au, w)
            sim.step(state, control)
        rows.append(poser.rows(state).copy())
    return rows


def _open_poses() -> tuple[np.ndarray, np.ndarray]:
    """(P, N, 3) positions and (P, N, 4) normal and fold term of the scanned head as drawn in
    INSIDE_POSES, each settled."""
    r = np.stack(_settled(INSIDE_POSES)).astype(np.float64)
    return r[..., :3], r[..., 3:7]


def build_inside(verbose: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """The mouth's lining, gums and tongue as drawn (render.scan_look's "mouth" group, the teeth
    left out) and a coarser list of them over the same vertices: ((F, 3) the full triangles
    replaced, (K, 3) the coarse ones, the error in cm), judged over the open mouth's poses by the
    skin's tolerances; each part's borders and the rings next to them kept whole."""
    from render.scan_look import ScanLook, _static_layout
    from sim.face.scan.data import N_VERTICES, PARTS, scan_data

    lay = _static_layout()
    mouth = lay["mouth"].astype(np.int64)
    lo, hi = PARTS[INSIDE_PARTS[0]][0], PARTS[INSIDE_PARTS[-1]][1]
    tri = mouth[(mouth >= lo).all(axis=1) & (mouth < hi).all(axis=1)]
    pos, rows = _open_poses()
    occ = ScanLook(scan_data().neutral).material[:, 2].astype(np.float64)
    attr = np.concatenate([rows, np.broadcast_to(occ[None, :, None], (len(rows), N_VERTICES, 1))], axis=2)
    keep = np.ones(N_VERTICES, bool)
    keep[np.unique(tri)] = False
    keep |= _border_rings(tri, N_VERTICES)
    col = _collapse(_Collapser(tri, pos, attr, ~keep), keep, len(tri), 500 if verbose else 0)
    coarse = col.tri[col.alive]
    return tri.astype(np.int32), coarse.astype(np.int32), deviation(coarse, tri, pos, every=True)


def main() -> None:
    """Builds the lists; `python -m render.scan_lod inside` builds the mouth's inside alone and keeps
    the shipped plain skin, `ears` the ears' collapses alone over the shipped plain skin before them."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m render.scan_lod",
                                 description=f"Rebuild the scanned head's coarse lists and rewrite {DATA.name}.")
    ap.add_argument("part", nargs="?", choices=["all", "inside", "ears", "eyes"], default="all",
                    help="inside: the mouth's inside alone; ears: the ears' collapses alone (the rest of the "
                         "shipped lists kept); all: everything (default)")
    part = ap.parse_args().part
    with np.load(DATA, allow_pickle=False) as d:
        shipped = {k: d[k] for k in d.files}
    if part == "all":
        skin, err = build(verbose=True)
        print(f"{len(skin)} triangles, largest deviation over the poses {err * 10:.3f} mm")
    else:
        skin = shipped.get("skin_plain", shipped["plain"]).astype(np.int32)
    if part in ("inside", "eyes"):
        coarse, err = coarse_plain()
    else:
        coarse, err, ear_err = build_ears(skin, verbose=True)
        print(f"ears: {len(skin)} -> {len(coarse)} triangles; largest deviation of the full plain skin "
              f"{err * 10:.3f} mm, of the ears {ear_err * 10:.3f} mm")
    if part in ("ears", "eyes"):
        inside, inside_err = shipped["inside"], float(shipped["inside_error_cm"])
    else:
        full, inside, inside_err = build_inside(verbose=True)
        print(f"the mouth's inside {len(full)} -> {len(inside)} triangles, largest deviation {inside_err * 10:.3f} mm")
    if part in ("all", "eyes"):
        eyes, eyes_err = build_eyes(verbose=True)
        print(f"the eyeballs' shells -> {len(eyes)} triangles, largest deviation {eyes_err * 10:.3f} mm")
    else:
        eyes = shipped["eyes"]
    fd, tmp = tempfile.mkstemp(dir=DATA.parent, suffix=".npz")
    os.close(fd)
    try:
        np.savez_compressed(tmp, plain=coarse.astype(np.uint16), error_cm=np.float64(err),
                            skin_plain=skin.astype(np.uint16), eyes=eyes.astype(np.uint16),
                            inside=inside.astype(np.uint16),
                            inside_error_cm=np.float64(inside_err))
        os.replace(tmp, DATA)
    except BaseException:
        os.unlink(tmp)
        raise
    print(f"wrote {DATA}", file=sys.stderr)


if __name__ == "__main__":
    main()
