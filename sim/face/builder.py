"""The procedural default face mesh (no third-party mesh): `build_face_mesh(resolution)`.

Lays out the left half on the flat chart (sim.face.chart), triangulates it there (Delaunay, with
the triangles in the eye and mouth holes and outside the border removed), maps it to 3D
(sim.face.shape) and mirrors it, so the mesh is exactly symmetric about x = 0. Then fills in the
rig's facts: landmarks, held border, jaw weights and hinge, eyeballs, regions. See docs/face-mesh.md.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial import Delaunay, cKDTree

from sim.face import chart as fc
from sim.face import shape as fs
from sim.face.constrain import recover_edges
from sim.face.regions import face_regions, jaw_weights
from sim.model import FaceMesh

FloatArray = np.ndarray
SEED = 20261121
FILL_SCALE = {0: 1.0, 1: 0.87, 2: 0.76}
"""Extra refinement of the fill per resolution: the explicit rows grow only linearly with it."""
JAW_PIVOT = np.array([0.0, -4.6, -7.8])
"""cm: on the hinge through both temporomandibular joints (in front of the ears, nose-base level)."""
JAW_AXIS = np.array([1.0, 0.0, 0.0])
"""+X: a positive (right-handed) rotation swings the chin down and back, opening the mouth."""


def _in_polygon(pts: FloatArray, poly: FloatArray) -> np.ndarray:
    """Even-odd point-in-polygon test, vectorised over pts (one pass per polygon edge)."""
    x, y = pts[:, 0], pts[:, 1]
    inside = np.zeros(len(pts), bool)
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    box = (x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1])
    xb, yb = x[box], y[box]
    acc = np.zeros(len(xb), bool)
    for (x0, y0), (x1, y1) in zip(poly, np.roll(poly, -1, axis=0)):
        if y0 == y1:
            continue
        crosses = (y0 > yb) != (y1 > yb)
        acc ^= crosses & (xb < x0 + (yb - y0) * (x1 - x0) / (y1 - y0))
    inside[box] = acc
    return inside


def _border(s: float) -> tuple[FloatArray, int]:
    """Left-half border from the top of the midline round to the bottom of it; returns the points
    and how many of them (from the start) are held (hairline and sides)."""
    spacing = 0.95 * s
    u = np.linspace(0.0, fc.U_SIDE, 200)
    top = fc.resample(np.stack([u, fc.V_TOP - 1.2 * (u / fc.U_SIDE) ** 2], axis=1), spacing)
    side = fc.resample(np.array([top[-1], [fc.U_SIDE, fc.V_EAR]]), spacing)
    jb = fc.JAW_BORDER
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(jb, axis=0), axis=1))])
    t = np.linspace(0.0, chord[-1], 300)
    jaw = fc.resample(CubicSpline(chord, jb, bc_type="natural")(t), spacing)
    held = len(top) + len(side) - 1
    return np.vstack([top, side[1:], jaw[1:]]), held


def _landmark_chart() -> dict[str, tuple[float, float]]:
    """Chart places of the landmarks that are not on the eye or mouth loops (left side only)."""
    xy = {
        "forehead_center": (0.0, fc.FOREHEAD_LINES[1]),
        "glabella": (0.0, 1.3),
        "nose_bridge": (0.0, 0.6),
        "nose_tip": (0.0, -4.2),
        "subnasale": (0.0, -5.05),
        "upper_lip_top": (0.0, -6.35),
        "lower_lip_bottom": (0.0, -8.2),
        "chin": (0.0, -11.6),
        "brow_inner_l": (1.3, 1.62),
        "brow_mid_l": (2.9, 2.05),
        "brow_outer_l": (4.65, 1.75),
        "nose_wing_l": (1.75, -4.55),
        "cheek_l": (4.2, -2.3),
    }
    out = {k: (float(fs.chart_u(x, y)), y) for k, (x, y) in xy.items()}
    out["jaw_angle_l"] = (8.2, -9.1)
    return out


def _layout(resolution: int) -> tuple[fc.ChartLayout, FloatArray, FloatArray]:
    """Left-half chart points; also the border polygon (with the midline) and the holes."""
    s = 0.5**resolution
    lay = fc.ChartLayout()
    n_eye = 10 * 2**resolution
    lay.eye_loop = lay.add(fc.eye_loop_chart(n_eye))
    up, low = fc.mouth_half_loop(8 * 2**resolution)
    lay.mouth_upper = lay.add(up)
    lay.mouth_lower = lay.add(low)
    border, n_held = _border(s)
    lay.border = lay.add(border)
    lay.held = lay.border[:n_held]
    lm = _landmark_chart()
    idx = lay.add(np.array(list(lm.values())))
    lay.landmarks = dict(zip(lm.keys(), (int(i) for i in idx)))
    e = lay.eye_loop
    lay.landmarks.update(
        eye_inner_l=int(e[0]), upper_lid_l=int(e[n_eye // 2]), eye_outer_l=int(e[n_eye]),
        lower_lid_l=int(e[n_eye + n_eye // 2]), upper_lip_center=int(lay.mouth_upper[0]),
        lower_lip_center=int(lay.mouth_lower[0]), mouth_corner_l=int(lay.mouth_upper[-1]),
    )
    pts = np.vstack(_rows(resolution))
    pts[np.abs(pts[:, 0]) < 0.15 * s, 0] = 0.0
    pts = pts[pts[:, 0] >= 0.0]
    poly = np.vstack([border, [[0.0, fc.V_TOP]]])
    pts = pts[_in_polygon(pts, border) & ~_in_holes(pts, lay)]
    lay.add(pts, min_dist=0.17 * s)
    _midline(lay, s)
    n_fixed = len(lay.array())
    _fill(lay, s * FILL_SCALE[resolution], border)
    _relax(lay, n_fixed, poly)
    return lay, poly, border


def _rows(resolution: int) -> list[FloatArray]:
    """Lid and lip rings, then the wrinkle lines, then their flank rows (earlier rows win where
    two come closer than the thinning distance). Row steps and flank distances are per line
    (`fc.ROW_STEP`, `fc.FLANK`), halved at each resolution step."""
    s = 0.5**resolution
    n_eye = 10 * 2**resolution
    rings = [fc.eye_loop_chart(int(round(n_eye * (1.0 + 0.05 * k))), g * s) for k, g in enumerate((0.22, 0.47, 0.8))]
    for grow in (0.25, 0.55):
        rings += list(fc.mouth_half_loop(8 * 2**resolution + 1, grow * s))
    lines, flanks = [], []
    for name, line in fc.wrinkle_lines().items():
        if name.startswith("crows"):
            (flanks if "flank" in name else lines).append(fc.resample(line, 0.42 * s))
            continue
        step = next((h for k, h in fc.ROW_STEP.items() if name.startswith(k)), 0.55)
        gap = next((h for k, h in fc.FLANK.items() if name.startswith(k)), 0.3)
        base = fc.resample(line, step * s)
        lines.append(base)
        sides = (-1.0,) if name in fc.ONE_SIDED else (1.0, -1.0)
        flanks += [fc.offset(base, side * gap * s) for side in sides]
    return rings + lines + flanks


def _in_holes(pts: FloatArray, lay: fc.ChartLayout) -> np.ndarray:
    """Points inside (or just outside) the left eye opening or the left half of the mouth slit:
    the holes are grown a little so that nothing is placed on top of their loops."""
    allp = lay.array()
    eye = allp[lay.eye_loop]
    mouth = np.vstack([allp[lay.mouth_upper], allp[lay.mouth_lower][::-1]])
    c_e = eye.mean(axis=0)
    eye_g = c_e + (eye - c_e) * 1.06
    mouth_g = mouth.copy()
    mouth_g[:, 1] = fs.MOUTH_V + (mouth[:, 1] - fs.MOUTH_V) * 1.2
    mouth_g[mouth_g[:, 0] > 0, 0] += 0.05
    return _in_polygon(pts, eye_g) | _in_polygon(pts, mouth_g)


def _midline(lay: fc.ChartLayout, s: float) -> None:
    """Fill the u = 0 line between the points already on it, skipping the mouth slit."""
    allp = lay.array()
    v = np.sort(allp[allp[:, 0] == 0.0, 1])
    gap_lo = allp[lay.mouth_lower[0], 1]
    gap_hi = allp[lay.mouth_upper[0], 1]
    new = []
    for a, b in zip(v[:-1], v[1:]):
        if a >= gap_lo - 1e-9 and b <= gap_hi + 1e-9:
            continue
        h = float(fc.sizing(np.array([0.0]), np.array([(a + b) / 2]))[0]) * s
        n = int(round((b - a) / h))
        new += [a + (b - a) * k / n for k in range(1, n)]
    if new:
        lay.add(np.stack([np.zeros(len(new)), new], axis=1))


def _fill(lay: fc.ChartLayout, s: float, border: FloatArray) -> None:
    """Graded Poisson-disc fill: deterministic dart throwing over dense jittered candidates."""
    rng = np.random.default_rng(SEED)
    c = 0.3 * fc.H_MIN * s
    gu, gv = np.meshgrid(np.arange(0.0, fc.U_SIDE + c, c), np.arange(border[:, 1].min(), fc.V_TOP + c, c))
    cand = np.stack([gu.ravel(), gv.ravel()], axis=1) + rng.uniform(-0.45 * c, 0.45 * c, (gu.size, 2))
    h = fc.sizing(cand[:, 0], cand[:, 1]) * s
    keep = rng.uniform(size=len(cand)) < (fc.H_MIN * s / h) ** 2 * 2.0
    cand, h = cand[keep], h[keep]
    ok = (cand[:, 0] > 0.45 * h) & _in_polygon(cand, border) & ~_in_holes(cand, lay)
    cand, h = cand[ok], h[ok]
    d, _ = cKDTree(lay.array()).query(cand)
    ok = d > 0.8 * h
    cand, h = cand[ok], h[ok]
    tree = cKDTree(cand)
    alive = np.ones(len(cand), bool)
    chosen = []
    for i in rng.permutation(len(cand)):
        if alive[i]:
            chosen.append(i)
            alive[tree.query_ball_point(cand[i], 0.8 * h[i])] = False
    lay.add(cand[np.sort(chosen)])


def _relax(lay: fc.ChartLayout, n_fixed: int, poly: FloatArray, rounds: int = 3) -> None:
    """A few damped Laplacian steps on the fill points (rows stay put): evens out the triangles
    where the fill meets the ends of the rows."""
    pts = lay.array()
    for _ in range(rounds):
        tri = Delaunay(pts).simplices
        e = np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        e = np.vstack([e, e[:, ::-1]])
        total = np.zeros_like(pts)
        np.add.at(total, e[:, 0], pts[e[:, 1]])
        deg = np.bincount(e[:, 0], minlength=len(pts))[:, None]
        target = 0.5 * pts + 0.5 * total / np.maximum(deg, 1)
        move = np.zeros(len(pts), bool)
        move[n_fixed:] = True
        ok = _in_polygon(target, poly) & ~_in_holes(target, lay) & (target[:, 0] > 0.0)
        move &= ok
        pts[move] = target[move]
    lay.points = [pts]


def _triangulate(pts: FloatArray, poly: FloatArray, lay: fc.ChartLayout) -> np.ndarray:
    """Delaunay of the half chart, keeping triangles inside the border and outside the holes,
    counter-clockwise in the chart (so outward in 3D)."""
    tri = Delaunay(pts).simplices
    loops = [lay.eye_loop, np.concatenate([lay.mouth_upper, lay.mouth_lower[::-1]])]
    need = [(int(a), int(b)) for loop in loops for a, b in zip(loop, np.roll(loop, -1))]
    need += [(int(a), int(b)) for a, b in zip(lay.border[:-1], lay.border[1:])]
    tri = recover_edges(pts, tri, need)
    cen = pts[tri].mean(axis=1)
    keep = _in_polygon(cen, poly) & ~_in_polygon(cen, pts[lay.eye_loop])
    mouth = np.vstack([pts[lay.mouth_upper], pts[lay.mouth_lower][::-1]])
    keep &= ~_in_polygon(cen, mouth)
    tri = tri[keep]
    a, b, c = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    tri = tri[np.abs(area) > 1e-10]
    flip = area[np.abs(area) > 1e-10] < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    return tri


@lru_cache(maxsize=4)
def _build(resolution: int) -> FaceMesh:
    lay, poly, _ = _layout(resolution)
    return _mirrored_mesh(lay, poly)


def _mirrored_mesh(lay: fc.ChartLayout, poly: FloatArray) -> FaceMesh:
    """The whole face from a left-half layout: triangulated, mirrored, mapped to 3D, rigged."""
    half = lay.array()
    tri = _triangulate(half, poly, lay)
    # Mirror: midline points once, the rest twice (left = +x first, then the right copies).
    n = len(half)
    mid = half[:, 0] == 0.0
    mirror_of = np.arange(n)
    side = np.flatnonzero(~mid)
    mirror_of[side] = n + np.arange(len(side))
    uv = np.vstack([half, half[side] * [-1.0, 1.0]])
    triangles = np.vstack([tri, mirror_of[tri][:, [0, 2, 1]]]).astype(np.int32)
    verts = fs.surface(uv[:, 0], uv[:, 1])
    verts[n:] = verts[side] * [-1.0, 1.0, 1.0]  # exact mirror, whatever rounding did

    lm: dict[str, int] = {}
    for k, i in lay.landmarks.items():
        lm[k] = int(i)
        if k.endswith("_l"):
            lm[k[:-2] + "_r"] = int(mirror_of[i])
    held = np.zeros(len(uv), bool)
    held[lay.held] = True
    held[mirror_of[lay.held]] = True
    eye_l = lay.eye_loop
    eye_r = mirror_of[eye_l][::-1]  # clockwise seen from the front, like the left one
    mu, ml = lay.mouth_upper, lay.mouth_lower
    mouth = np.concatenate([mu, ml[1:][::-1], ml[:1], mirror_of[ml[1:]], mirror_of[mu[1:]][::-1]])
    # Clockwise from the front: upper middle -> face's left corner -> lower -> right corner.
    ec = fs.eye_center()
    jaw = jaw_weights(uv)
    return FaceMesh(
        vertices=verts,
        triangles=triangles,
        landmarks=lm,
        held=held,
        jaw_weight=jaw,
        jaw_pivot=JAW_PIVOT.copy(),
        jaw_axis=JAW_AXIS.copy(),
        eye_centers=np.array([ec, ec * [-1.0, 1.0, 1.0]]),
        eye_radius=fs.EYE_RADIUS,
        eye_loops=(eye_l.astype(np.int64), eye_r.astype(np.int64)),
        mouth_loop=mouth.astype(np.int64),
        regions=face_regions(verts, uv, jaw),
        uv=uv,
    )


def _coarse_layout() -> tuple[fc.ChartLayout, FloatArray]:
    """A low-polygon sampling of the same surface, as a third-party game or tracker mesh has: 8
    points per lid, 6 per half lip, one ring round each opening, no wrinkle rows, the fill of resolution 0."""
    lay = fc.ChartLayout()
    n_eye = 8
    lay.eye_loop = lay.add(fc.eye_loop_chart(n_eye))
    up, low = fc.mouth_half_loop(5)
    lay.mouth_upper, lay.mouth_lower = lay.add(up), lay.add(low)
    border, n_held = _border(1.2)
    lay.border = lay.add(border)
    lay.held = lay.border[:n_held]
    lm = _landmark_chart()
    idx = lay.add(np.array(list(lm.values())), min_dist=0.0)
    lay.landmarks = dict(zip(lm.keys(), (int(i) for i in idx)))
    e = lay.eye_loop
    lay.landmarks.update(
        eye_inner_l=int(e[0]), upper_lid_l=int(e[n_eye // 2]), eye_outer_l=int(e[n_eye]),
        lower_lid_l=int(e[n_eye + n_eye // 2]), upper_lip_center=int(lay.mouth_upper[0]),
        lower_lip_center=int(lay.mouth_lower[0]), mouth_corner_l=int(lay.mouth_upper[-1]),
    )
    rings = [fc.eye_loop_chart(n_eye, 0.45), *fc.mouth_half_loop(6, 0.5)]
    pts = np.vstack(rings)
    pts[np.abs(pts[:, 0]) < 0.15, 0] = 0.0
    pts = pts[(pts[:, 0] >= 0.0) & _in_polygon(pts, border) & ~_in_holes(pts, lay)]
    lay.add(pts, min_dist=0.3)
    _midline(lay, 1.0)
    n_fixed = len(lay.array())
    _fill(lay, 1.0, border)
    poly = np.vstack([border, [[0.0, fc.V_TOP]]])
    _relax(lay, n_fixed, poly)
    return lay, poly


@lru_cache(maxsize=1)
def build_coarse_face_mesh() -> FaceMesh:
    """The default face's surface sampled coarsely (437 vertices; `_coarse_layout`): a test
    and benchmark subject for rig transfer onto a low-polygon head. The same object every call."""
    lay, poly = _coarse_layout()
    return _mirrored_mesh(lay, poly)


def build_face_mesh(resolution: int = 0) -> FaceMesh:
    """The default face at resolution 0 (~700 vertices), 1 (~3k) or 2 (~12k); deterministic.
    Returns a fresh copy each call (callers may modify it)."""
    if resolution not in (0, 1, 2):
        raise ValueError(f"resolution must be 0, 1 or 2, not {resolution!r}")
    m = _build(resolution)
    return FaceMesh(
        vertices=m.vertices.copy(), triangles=m.triangles.copy(), landmarks=dict(m.landmarks),
        held=m.held.copy(), jaw_weight=m.jaw_weight.copy(), jaw_pivot=m.jaw_pivot.copy(),
        jaw_axis=m.jaw_axis.copy(), eye_centers=m.eye_centers.copy(), eye_radius=m.eye_radius,
        eye_loops=(m.eye_loops[0].copy(), m.eye_loops[1].copy()), mouth_loop=m.mouth_loop.copy(),
        regions={k: r.copy() for k, r in m.regions.items()}, uv=None if m.uv is None else m.uv.copy(),
    )
