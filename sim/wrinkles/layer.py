"""The wrinkle mask compiled onto a mesh, and the per-frame bulges (seed 003 sections 5.2-5.3).

At rig-build time everything that depends only on rest geometry is precomputed: each line is cut
into stations every STATION_STEP cm; each station has a point on the line and, per side with a
roll, a point across the wrinkle at the roll's width (P1 and P0 of section 5, stored as barycentric
points of the mesh); the vertices in each roll get their station pair, side and Bezier parameter.
Per frame: gather the current P0 and P1 and their triangles' normals, solve every cross-section at
once (eq 10 and the tables of eqs 11-14), scatter the heights to the vertices.

Reading of section 5.2 chosen: the cross-section's plane contains the chord P0P1 and the mean of the
two end normals; alpha is measured from the chord, and the natural skin between P0 and P1 is the
cubic at the tangent-plane angle alpha_min (mean of both ends, clipped to [0, pi/2]) with a = d/3.
The bulge is the height of the solved cubic minus that natural one, applied along the plane's
normal; the in-plane slide of the material is neglected (at most a few tenths of a millimetre).
"""

from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from sim.wrinkles.arclength import lookup, table
from sim.wrinkles.arclength import ASYM_RATIO
from sim.wrinkles.bulge import (
    _A_SAMPLES,
    AGE_0,
    AGE_MAX,
    A_CAP_RATIO,
    DIL_MAX,
    FULL_RELEASE_STRAIN,
    INPLANE_LOSS_AT_MAX,
    Segment,
    dilatation,
    bezier_height,
    control_heights,
    released_surplus,
)
from sim.wrinkles.kernels import frame_displacement, solve_rolls
from sim.wrinkles.mask import WrinkleLine

FloatArray = np.ndarray
IntArray = np.ndarray

STATION_STEP = 0.25  # cm between stations along a line (heights are interpolated between)
TAPER = 0.5  # cm over which a wrinkle fades in at each end of its line
FURROW_HALF_WIDTH = 0.12  # cm, half width of the microfurrow groove
SMOOTH_PASSES = 2  # [1, 2, 1] / 4 passes over the crest heights along each line
FURROW_MAX_DEPTH = 0.06  # cm: a microfurrow, however tall its rolls, stays a fine groove


@dataclass(eq=False)
class WrinkleLayer:
    """Compiled wrinkles of one mesh. A = anchors, R = rolls (station x side), V = roll entries,
    F = furrow entries, S = stations.

    anchor_tri (A, 3) int, anchor_bary (A, 3): barycentric surface points.
    roll_far, roll_line (R,) int: anchors of P0 (across) and P1 (on the line) of each roll;
    roll_asym (R,) bool; roll_emphasis (R,); roll_d_init (R,) cm: the natural arc at rest.
    roll_prev, roll_next (R,) int: the neighbouring roll along the same line and side (itself at
    the ends).
    entry_vertex (V,) int; entry_roll0/1 (V,) int and entry_lam (V,): the two stations' rolls and the
    weight of the second; entry_b1, entry_b2 (V,): Bezier weights of P'0, P'1 at the vertex's t;
    entry_taper (V,).
    station_line (S,) int anchor on the line; station_rolls (S, 2) int roll per side (-1: none);
    station_furrow (S,): the line's furrow ratio.
    furrow_vertex (F,) int; furrow_station0/1 (F,) int; furrow_lam (F,); furrow_weight (F,).
    """

    n_vertices: int
    anchor_tri: IntArray
    anchor_bary: FloatArray
    roll_far: IntArray
    roll_line: IntArray
    roll_asym: np.ndarray
    roll_emphasis: FloatArray
    roll_d_init: FloatArray
    roll_prev: IntArray
    roll_next: IntArray
    entry_vertex: IntArray
    entry_roll0: IntArray
    entry_roll1: IntArray
    entry_lam: FloatArray
    entry_b1: FloatArray
    entry_b2: FloatArray
    entry_taper: FloatArray
    station_line: IntArray
    station_rolls: IntArray
    station_furrow: FloatArray
    furrow_vertex: IntArray
    furrow_station0: IntArray
    furrow_station1: IntArray
    furrow_lam: FloatArray
    furrow_weight: FloatArray
    line_names: tuple[str, ...]
    line_vertices: tuple[IntArray, ...]

    def displacement(self, positions: FloatArray, age: float) -> FloatArray:
        """(N, 3) cm to add to `positions` for the wrinkles at `age` years (compiled kernel; the
        numpy `wrinkle_displacement` is its reference)."""
        return compiled_displacement(self, positions, age)


# ---------------------------------------------------------------- rest geometry helpers


def vertex_normals(positions: FloatArray, triangles: IntArray) -> FloatArray:
    """Area-weighted unit vertex normals (N, 3)."""
    a, b, c = (positions[triangles[:, k]] for k in range(3))
    fn = np.cross(b - a, c - a)
    n = np.zeros_like(positions)
    for k in range(3):
        np.add.at(n, triangles[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def project_frontal(
    xy: FloatArray, rest: FloatArray, triangles: IntArray, tree: cKDTree
) -> tuple[IntArray, FloatArray]:
    """Front-most skin point under each frontal (x, y): (triangle (P,), barycentric (P, 3)).
    Points off the mesh fall back to the nearest triangle, with clamped weights."""
    k = min(48, len(triangles))
    _, cand = tree.query(xy, k=k)
    cand = np.atleast_2d(cand)
    a, b, c = (rest[triangles[cand, i]] for i in range(3))  # (P, k, 3)
    v0, v1 = b[..., :2] - a[..., :2], c[..., :2] - a[..., :2]
    v2 = xy[:, None, :] - a[..., :2]
    den = v0[..., 0] * v1[..., 1] - v0[..., 1] * v1[..., 0]
    safe = np.where(np.abs(den) > 1e-14, den, 1.0)
    w1 = (v2[..., 0] * v1[..., 1] - v2[..., 1] * v1[..., 0]) / safe
    w2 = (v0[..., 0] * v2[..., 1] - v0[..., 1] * v2[..., 0]) / safe
    w0 = 1.0 - w1 - w2
    bary = np.stack([w0, w1, w2], axis=-1)
    inside = np.all(bary >= -1e-9, axis=-1) & (np.abs(den) > 1e-14)
    z = np.einsum("pki,pkij->pkj", bary, np.stack([a, b, c], axis=2))[..., 2]
    score = np.where(inside, z, -np.inf)
    best = np.argmax(score, axis=1)
    rows = np.arange(len(xy))
    hit = np.isfinite(score[rows, best])
    best = np.where(hit, best, 0)  # nearest centroid when nothing contains the point
    out_bary = bary[rows, best]
    out_bary = np.clip(out_bary, 0.0, None)
    out_bary /= out_bary.sum(axis=1, keepdims=True)
    return cand[rows, best].astype(np.int64), out_bary


def _resample(points: FloatArray, step: float) -> FloatArray:
    """The polyline resampled at even arc-length spacing (at least 3 points)."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(3, int(np.ceil(s[-1] / step)) + 1)
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, points[:, i]) for i in range(points.shape[1])], axis=1)


def _smoothstep(x: FloatArray) -> FloatArray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


# ---------------------------------------------------------------- compile


class _Builder:
    """Collects anchors, rolls and entries line by line, then freezes them into a WrinkleLayer."""

    def __init__(self, rest: FloatArray, triangles: IntArray) -> None:
        self.rest = rest
        self.tris = np.asarray(triangles, dtype=np.int64)
        self.normals = vertex_normals(rest, self.tris)
        cent = rest[self.tris].mean(axis=1)
        self.tri_tree = cKDTree(cent[:, :2])
        self.vert_tree = cKDTree(rest)
        self.anchor_tri: list[IntArray] = []
        self.anchor_bary: list[FloatArray] = []
        self.n_anchor = 0
        self.rolls: dict[str, list] = {k: [] for k in ("far", "line", "asym", "emph", "prev", "next")}
        self.entries: dict[str, list] = {
            k: [] for k in ("v", "r0", "r1", "lam", "b1", "b2", "taper")
        }
        self.stations: dict[str, list] = {k: [] for k in ("line", "rolls", "furrow")}
        self.furrows: dict[str, list] = {k: [] for k in ("v", "s0", "s1", "lam", "w")}
        self.names: list[str] = []
        self.line_vertices: list[IntArray] = []

    def anchors(self, xy: FloatArray) -> tuple[IntArray, FloatArray, FloatArray]:
        tri, bary = project_frontal(xy, self.rest, self.tris, self.tri_tree)
        pts = np.einsum("pi,pij->pj", bary, self.rest[self.tris[tri]])
        nrm = np.einsum("pi,pij->pj", bary, self.normals[self.tris[tri]])
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        idx = np.arange(self.n_anchor, self.n_anchor + len(xy))
        self.n_anchor += len(xy)
        self.anchor_tri.append(self.tris[tri])
        self.anchor_bary.append(bary)
        return idx, pts, nrm

    def add_line(self, line: WrinkleLine) -> None:
        xy = _resample(np.asarray(line.points, dtype=np.float64), STATION_STEP)
        s_idx, p, n = self.anchors(xy)
        tang = np.gradient(p, axis=0)
        tang /= np.linalg.norm(tang, axis=1, keepdims=True)
        across = np.cross(n, tang)
        across /= np.linalg.norm(across, axis=1, keepdims=True)
        n_st = len(xy)
        first_station = len(self.stations["line"])
        widths = (line.width_minus, line.width_plus)
        asyms = (line.asym_minus, line.asym_plus)
        roll_ids = np.full((n_st, 2), -1, dtype=np.int64)
        for side, sign in ((0, -1.0), (1, 1.0)):
            w = widths[side]
            if w <= 0:
                continue
            far_idx, _, _ = self.anchors((p + sign * w * across)[:, :2])
            first_roll = len(self.rolls["far"])
            roll_ids[:, side] = first_roll + np.arange(n_st)
            self.rolls["prev"].extend(first_roll + np.maximum(np.arange(n_st) - 1, 0))
            self.rolls["next"].extend(first_roll + np.minimum(np.arange(n_st) + 1, n_st - 1))
            self.rolls["far"].extend(far_idx)
            self.rolls["line"].extend(s_idx)
            self.rolls["asym"].extend([asyms[side]] * n_st)
            self.rolls["emph"].extend([line.emphasis] * n_st)
        self.stations["line"].extend(s_idx)
        self.stations["rolls"].extend(roll_ids)
        self.stations["furrow"].extend([line.furrow] * n_st)
        self._add_vertices(line, p, n, across, roll_ids, first_station)

    def _add_vertices(
        self,
        line: WrinkleLine,
        p: FloatArray,
        n: FloatArray,
        across: FloatArray,
        roll_ids: IntArray,
        first_station: int,
    ) -> None:
        reach = max(line.width_minus, line.width_plus, FURROW_HALF_WIDTH)
        cand = np.unique(np.concatenate(self.vert_tree.query_ball_point(p, reach * 1.5 + 0.1)))
        cand = cand.astype(np.int64)
        if len(cand) == 0:
            self.names.append(line.name)
            self.line_vertices.append(cand)
            return
        x = self.rest[cand]
        a, b = p[:-1], p[1:]
        ab = b - a
        L2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
        f = np.einsum("vij,ij->vi", x[:, None, :] - a[None], ab) / L2
        fc = np.clip(f, 0.0, 1.0)
        foot = a[None] + fc[..., None] * ab[None]
        dist = np.linalg.norm(x[:, None, :] - foot, axis=2)
        k = np.argmin(dist, axis=1)
        rows = np.arange(len(cand))
        lam = fc[rows, k]
        inside = (f[rows, k] >= -1e-6) & (f[rows, k] <= 1 + 1e-6)
        foot_k = foot[rows, k]
        acr = (1 - lam)[:, None] * across[k] + lam[:, None] * across[k + 1]
        nrm = (1 - lam)[:, None] * n[k] + lam[:, None] * n[k + 1]
        c = np.einsum("ij,ij->i", x - foot_k, acr)
        h = np.einsum("ij,ij->i", x - foot_k, nrm)
        seglen = np.sqrt(L2)
        along = np.concatenate([[0.0], np.cumsum(seglen)])
        s_along = along[k] + lam * seglen[k]
        taper_len = min(TAPER, along[-1] / 3.0)
        taper = _smoothstep(np.minimum(s_along, along[-1] - s_along) / taper_len)
        ok = inside & (np.abs(h) < 0.5 * reach + 0.15) & (taper > 0)
        side = (c > 0).astype(np.int64)
        width = np.where(side == 1, line.width_plus, line.width_minus)
        in_roll = ok & (np.abs(c) < width)
        r0 = roll_ids[k, side]
        r1 = roll_ids[k + 1, side]
        in_roll &= (r0 >= 0) & (r1 >= 0)
        t = 1.0 - np.abs(c) / np.where(width > 0, width, 1.0)
        sel = np.flatnonzero(in_roll)
        e = self.entries
        e["v"].extend(cand[sel])
        e["r0"].extend(r0[sel])
        e["r1"].extend(r1[sel])
        e["lam"].extend(lam[sel])
        e["b1"].extend(3.0 * (1 - t[sel]) ** 2 * t[sel])
        e["b2"].extend(3.0 * (1 - t[sel]) * t[sel] ** 2)
        e["taper"].extend(taper[sel])
        fw = ok & (np.abs(c) < FURROW_HALF_WIDTH)
        sel = np.flatnonzero(fw)
        g = self.furrows
        g["v"].extend(cand[sel])
        g["s0"].extend(first_station + k[sel])
        g["s1"].extend(first_station + k[sel] + 1)
        g["lam"].extend(lam[sel])
        g["w"].extend(taper[sel] * (1.0 - (c[sel] / FURROW_HALF_WIDTH) ** 2) ** 2)
        self.names.append(line.name)
        self.line_vertices.append(np.unique(cand[in_roll | fw]))

    def freeze(self) -> WrinkleLayer:
        def arr(x: list, dtype: type = np.float64) -> np.ndarray:
            return np.asarray(x, dtype=dtype)

        e, g, r, s = self.entries, self.furrows, self.rolls, self.stations
        layer = WrinkleLayer(
            n_vertices=len(self.rest),
            anchor_tri=np.concatenate(self.anchor_tri) if self.anchor_tri else np.zeros((0, 3), np.int64),
            anchor_bary=np.concatenate(self.anchor_bary) if self.anchor_bary else np.zeros((0, 3)),
            roll_far=arr(r["far"], np.int64),
            roll_line=arr(r["line"], np.int64),
            roll_asym=arr(r["asym"], bool),
            roll_emphasis=arr(r["emph"]),
            roll_d_init=np.zeros(len(r["far"])),
            roll_prev=arr(r["prev"], np.int64),
            roll_next=arr(r["next"], np.int64),
            entry_vertex=arr(e["v"], np.int64),
            entry_roll0=arr(e["r0"], np.int64),
            entry_roll1=arr(e["r1"], np.int64),
            entry_lam=arr(e["lam"]),
            entry_b1=arr(e["b1"]),
            entry_b2=arr(e["b2"]),
            entry_taper=arr(e["taper"]),
            station_line=arr(s["line"], np.int64),
            station_rolls=arr(s["rolls"], np.int64).reshape(-1, 2),
            station_furrow=arr(s["furrow"]),
            furrow_vertex=arr(g["v"], np.int64),
            furrow_station0=arr(g["s0"], np.int64),
            furrow_station1=arr(g["s1"], np.int64),
            furrow_lam=arr(g["lam"]),
            furrow_weight=arr(g["w"]),
            line_names=tuple(self.names),
            line_vertices=tuple(self.line_vertices),
        )
        layer.roll_d_init = cross_sections(layer, self.rest)[4]
        return layer


def compile_wrinkles(
    rest: FloatArray, triangles: IntArray, lines: tuple[WrinkleLine, ...]
) -> WrinkleLayer:
    """Precompute everything the per-frame bulge needs from the rest geometry."""
    b = _Builder(np.asarray(rest, dtype=np.float64), triangles)
    for line in lines:
        b.add_line(line)
    return b.freeze()


# ---------------------------------------------------------------- per frame


@lru_cache(maxsize=1)
def _stacked_tables() -> FloatArray:
    """The symmetric and asymmetric tables as one (2, 21, 11, 21) array for the kernel."""
    return np.ascontiguousarray(np.stack([table(False).values, table(True).values]))


def _anchor_points(layer: WrinkleLayer, positions: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Current anchor positions (A, 3) and their triangles' unit normals (A, 3)."""
    corners = np.take(positions, layer.anchor_tri, axis=0)  # (A, 3, 3)
    pts = np.einsum("ai,aij->aj", layer.anchor_bary, corners)
    nrm = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    return pts, nrm


def cross_sections(
    layer: WrinkleLayer, positions: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per roll: chord d (cm), its unit direction, the plane's unit normal `up`, alpha_min, the
    natural arc S(d, d/3, alpha_min) (cm), and the line anchor's normal."""
    pts, nrm = _anchor_points(layer, positions)
    p0, p1 = pts[layer.roll_far], pts[layer.roll_line]
    n0, n1 = nrm[layer.roll_far], nrm[layer.roll_line]
    chord = p1 - p0
    d = np.maximum(np.linalg.norm(chord, axis=1), 1e-9)
    e = chord / d[:, None]
    nbar = n0 + n1
    up = nbar - np.einsum("ij,ij->i", nbar, e)[:, None] * e
    up /= np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-12)
    a0 = np.arctan2(-np.einsum("ij,ij->i", n0, e), np.einsum("ij,ij->i", n0, up))
    a1 = np.arctan2(np.einsum("ij,ij->i", n1, e), np.einsum("ij,ij->i", n1, up))
    alpha_min = np.clip(0.5 * (a0 + a1), 0.0, np.pi / 2)
    s_nat = lookup(table(False), d, d / 3.0, alpha_min)
    return d, e, up, alpha_min, s_nat, n1


def roll_heights(
    layer: WrinkleLayer, positions: FloatArray, age: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per roll: the extra control heights (dh0, dh1) of the bulged cubic over the natural one
    (cm), the plane normal `up` (R, 3) and the line anchor's normal (R, 3)."""
    d, _, up, alpha_min, s_nat, n_line = cross_sections(layer, positions)
    surplus = released_surplus(layer.roll_d_init, s_nat, age, layer.roll_emphasis)
    dh0 = np.zeros_like(d)
    dh1 = np.zeros_like(d)
    sel = np.flatnonzero(surplus > 1e-7)
    if len(sel):
        a = np.empty(len(sel))
        alpha = np.empty(len(sel))
        asym = layer.roll_asym[sel]
        solve_rolls(_stacked_tables(), asym.astype(np.int64), d[sel], s_nat[sel] + surplus[sel],
                    alpha_min[sel], a, alpha, A_CAP_RATIO, _A_SAMPLES)
        h0, h1 = control_heights(Segment(a=a, alpha=alpha), asym)
        nat = d[sel] / 3.0 * np.sin(alpha_min[sel])
        dh0[sel] = h0 - nat
        dh1[sel] = h1 - nat
    return dh0, dh1, up, n_line


def _smooth_along(layer: WrinkleLayer, h: FloatArray, passes: int | None = None) -> FloatArray:
    """Heights smoothed along each line ([1, 2, 1] / 4 over neighbouring stations): a crest follows
    its wrinkle evenly instead of copying every local ripple of the dynamics' compression."""
    for _ in range(SMOOTH_PASSES if passes is None else passes):
        h = 0.25 * np.take(h, layer.roll_prev) + 0.5 * h + 0.25 * np.take(h, layer.roll_next)
    return h


def wrinkle_displacement(layer: WrinkleLayer, positions: FloatArray, age: float) -> FloatArray:
    """(N, 3) cm: the rolls' heights along their planes' normals plus the microfurrow groove."""
    out = np.zeros((layer.n_vertices, 3))
    if len(layer.roll_far) == 0:
        return out
    dh0, dh1, up, n_line = roll_heights(layer, positions, age)
    dh0, dh1 = _smooth_along(layer, dh0), _smooth_along(layer, dh1)
    lam = layer.entry_lam
    r0, r1 = layer.entry_roll0, layer.entry_roll1
    h0 = (1 - lam) * np.take(dh0, r0) + lam * np.take(dh0, r1)
    h1 = (1 - lam) * np.take(dh1, r0) + lam * np.take(dh1, r1)
    height = np.maximum(layer.entry_b1 * h0 + layer.entry_b2 * h1, 0.0) * layer.entry_taper
    direction = (1 - lam)[:, None] * np.take(up, r0, axis=0) + lam[:, None] * np.take(up, r1, axis=0)
    disp = height[:, None] * direction
    # microfurrow: each station's groove depth is a fraction of its taller roll's crest
    crest = np.maximum(bezier_height(0.5, dh0, dh1), 0.0)
    sr = layer.station_rolls
    st_crest = np.maximum(
        np.where(sr[:, 0] >= 0, crest[np.maximum(sr[:, 0], 0)], 0.0),
        np.where(sr[:, 1] >= 0, crest[np.maximum(sr[:, 1], 0)], 0.0),
    )
    st_depth = np.minimum(st_crest * layer.station_furrow, FURROW_MAX_DEPTH)
    st_roll = np.where(sr[:, 1] >= 0, sr[:, 1], sr[:, 0])
    st_normal = n_line[st_roll]
    fl = layer.furrow_lam
    s0, s1 = layer.furrow_station0, layer.furrow_station1
    depth = ((1 - fl) * st_depth[s0] + fl * st_depth[s1]) * layer.furrow_weight
    fdir = (1 - fl)[:, None] * st_normal[s0] + fl[:, None] * st_normal[s1]
    fdisp = -depth[:, None] * fdir
    for c in range(3):
        out[:, c] = np.bincount(layer.entry_vertex, disp[:, c], layer.n_vertices)
        out[:, c] += np.bincount(layer.furrow_vertex, fdisp[:, c], layer.n_vertices)
    return out


def compiled_displacement(layer: WrinkleLayer, positions: FloatArray, age: float,
                          out: FloatArray | None = None) -> FloatArray:
    """wrinkle_displacement through kernels.frame_displacement: same numbers, one compiled pass.
    out: an (N, 3) float64 array to fill and return (a new one when None)."""
    if out is None:
        out = np.zeros((layer.n_vertices, 3))
    else:
        out.fill(0.0)
    if len(layer.roll_far) == 0:
        return out
    arrays, scratch = _kernel_args(layer)
    frame_displacement(np.ascontiguousarray(positions, dtype=np.float64), *arrays, _age_params(age),
                       _A_SAMPLES, out, scratch)
    return out


def _age_params(age: float) -> FloatArray:
    """The kernel's params for `age` (see kernels.frame_displacement); the last one is kept, since
    the age channel rarely moves."""
    global _LAST_PARAMS
    if _LAST_PARAMS is None or _LAST_PARAMS[0] != age:
        extra = _unit_dilatation(age) - 1.0
        params = np.array([extra, INPLANE_LOSS_AT_MAX * extra / DIL_MAX, FULL_RELEASE_STRAIN,
                           A_CAP_RATIO, ASYM_RATIO, FURROW_MAX_DEPTH, float(SMOOTH_PASSES)])
        _LAST_PARAMS = (age, params)
    return _LAST_PARAMS[1]


_LAST_PARAMS: tuple[float, FloatArray] | None = None


def _unit_dilatation(age: float) -> float:
    """`dilatation(1.0, age)` on Python floats: the same operations in the same order, so the
    same bits, NaN kept (numpy's on one value took 3 us, made every frame the age dial moves)."""
    t = AGE_MAX if age > AGE_MAX else age  # np.minimum(age, AGE_MAX)
    g = 1.0 + (t - AGE_0) * DIL_MAX / (AGE_MAX - AGE_0)
    return 1.0 if g < 1.0 else g  # np.maximum(1.0, g) (times d_init = 1.0: the same value)


def _kernel_args(layer: WrinkleLayer) -> tuple[tuple, tuple]:
    """The layer's arrays grouped as the kernel takes them, and its work arrays for this thread;
    built once per layer (and thread), not every frame."""
    arrays = _ARGS.get(layer)
    if arrays is None:
        arrays = (
            layer.anchor_tri,
            layer.anchor_bary,
            (layer.roll_far, layer.roll_line, layer.roll_asym, layer.roll_emphasis, layer.roll_d_init,
             layer.roll_prev, layer.roll_next),
            (layer.entry_vertex, layer.entry_roll0, layer.entry_roll1, layer.entry_lam, layer.entry_b1,
             layer.entry_b2, layer.entry_taper),
            (layer.station_rolls, layer.station_furrow),
            (layer.furrow_vertex, layer.furrow_station0, layer.furrow_station1, layer.furrow_lam,
             layer.furrow_weight),
            _stacked_tables(),
        )
        _ARGS[layer] = arrays
    per_thread = _SCRATCH.setdefault(layer, {})
    scratch = per_thread.get(threading.get_ident())
    if scratch is None:
        n_a, n_r, n_s = len(layer.anchor_tri), len(layer.roll_far), len(layer.station_rolls)
        scratch = (np.zeros((n_a, 3)), np.zeros((n_a, 3)), np.zeros((n_r, 3)), np.zeros((n_r, 3)), np.zeros(n_r),
                   np.zeros(n_r), np.zeros(n_r), np.zeros(n_r), np.zeros(n_s), np.zeros((n_s, 3)))
        per_thread[threading.get_ident()] = scratch
    return arrays, scratch


_ARGS: "weakref.WeakKeyDictionary[WrinkleLayer, tuple]" = weakref.WeakKeyDictionary()
_SCRATCH: "weakref.WeakKeyDictionary[WrinkleLayer, dict[int, tuple]]" = weakref.WeakKeyDictionary()


# ---------------------------------------------------------------- model glue

_LAYERS: "weakref.WeakKeyDictionary[object, WrinkleLayer]" = weakref.WeakKeyDictionary()


def layer_for(model: object) -> WrinkleLayer:
    """The compiled wrinkles of a FaceModel (`rest`, `triangles`, `rig.wrinkles`), cached per model."""
    layer = _LAYERS.get(model)
    if layer is None:
        layer = compile_wrinkles(model.rest, model.triangles, tuple(model.rig.wrinkles))  # type: ignore[attr-defined]
        _LAYERS[model] = layer
    return layer


def warm_up(model: object) -> None:
    """Compile the model's wrinkle layer and run its kernel once (numba compiles it, or loads it
    from its on-disk cache), so the first live frame does not stall. The positions are a writable
    copy: the simulator's are writable, and numba compiles a read-only array (the model's rest)
    as another signature, which the first wrinkled frame would then compile on the live path."""
    compiled_displacement(layer_for(model), np.array(model.rest, dtype=np.float64), 30.0)  # type: ignore[attr-defined]



def apply_wrinkles(model: object, state: object) -> None:
    """Set state.surface = state.positions displaced by the model's wrinkles at state.age."""
    pos = state.positions  # type: ignore[attr-defined]
    if not getattr(model, "rig").wrinkles:
        state.surface[...] = pos  # type: ignore[attr-defined]
        return
    layer = layer_for(model)
    age = float(state.age)  # type: ignore[attr-defined]
    disp = compiled_displacement(layer, pos, age, _displacement_buffer(layer))
    np.add(pos, disp, out=state.surface)  # type: ignore[attr-defined]


def _displacement_buffer(layer: WrinkleLayer) -> FloatArray:
    """An (N, 3) array for this thread's displacements of `layer` (`apply_wrinkles`: the live loop
    surfaces every frame; an array of its own each time took 2-3x the Python around the kernel)."""
    per_thread = _OUT.setdefault(layer, {})
    out = per_thread.get(threading.get_ident())
    if out is None:
        out = per_thread[threading.get_ident()] = np.zeros((layer.n_vertices, 3))
    return out


_OUT: "weakref.WeakKeyDictionary[WrinkleLayer, dict[int, FloatArray]]" = weakref.WeakKeyDictionary()
