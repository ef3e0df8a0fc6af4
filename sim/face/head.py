"""The rest of the default face's head: cranium, ears and neck, held (not simulated), stitched to
the simulated mask.

The simulated mask (sim.face.builder) ends at the hairline, in front of the ears and under the
chin and jaw. `head_shell(mesh)` builds the rest of the head around it, in the mask's frame (cm, +Y
up, +Z forward), as one surface whose first ring of vertices *is* the mask's outer boundary loop:
rows of vertices sweep from that loop back over the cranium and down the neck to a widening base,
so the join is closed by construction. Each row continues the mask's surface (its outward tangent
at the border) and blends over a few centimetres into an implicit head (smooth union of a cranium,
a skull base, a neck leaning forward, a submandibular floor and a rounded rim laid just inside the
mask's jaw border) of adult proportions: head breadth ~15 cm, vertex ~22-24 cm above the chin, back
of the head ~19 cm behind the glabella, a neck ~11 cm wide and ~11 cm deep widening into the
trapezius. Two ears (helix rim, scapha, antihelix, concha, tragus, lobe) from brow to nose-base
level just behind the jaw hinge, leaning back 15 degrees.

The shell is held, but its vertices near the join follow the mask (`HeadShell.pose`): each takes its
column's share of the mask border's displacement, fading with the distance from the border over a
few centimetres, and under the chin and jaw down the throat, so an open mouth pulls the
submandibular skin with the jaw and the neck's base stays.
Each vertex carries hairline coordinates (cm above the hairline, cm from the join) and the hair
weight they give (1 on the scalp, 0 on skin); the renderer takes the weight per pixel. Only the
default face gets a head (`shell_for`): an imported head brings its own.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from sim.build import vertex_normals
from sim.model import FaceMesh, FaceRig
from sim.springs import boundary_loops

FloatArray = np.ndarray

# Implicit head (cm, the mask's frame). Pieces are ellipsoids / an elliptic cylinder, smoothly unioned.
CRANIUM_CENTRE = np.array([0.0, 1.7, -9.3])
CRANIUM_AXES = np.array([7.45, 9.1, 9.45])  # half breadth, centre to vertex, centre to back
SKULL_BASE_CENTRE = np.array([0.0, -3.6, -10.6])
SKULL_BASE_AXES = np.array([6.5, 5.2, 6.6])  # behind the jaw hinge: mastoids and the occiput's base
JAW_CENTRE = np.array([0.0, -10.4, -5.6])
JAW_AXES = np.array([4.4, 3.1, 4.6])  # under the mandible: the submandibular floor
NECK_TOP = np.array([0.0, -8.0, -9.7])  # neck axis at y = -8 ...
NECK_SLOPE = 0.21  # ... moving back 0.21 cm per cm down (the neck leans forward ~12 degrees going up)
NECK_HALF = (5.35, 5.75)  # half width, half depth (cm) of the neck at mid-neck
TRAPEZIUS_Y = -17.5  # below this the neck widens towards the shoulders
NECK_END_Y = -24.0
BLEND = 1.6  # cm: smooth-union width
JAW_RIM = 1.1  # cm: radius of the rounded rim under the mask's jaw border
# Sweep from the mask's border to the neck base.
COLUMNS = 36
ROWS = 15
FIRST_ROW = 0.6  # cm from the border to the first row (rows further apart further on)
ROW_GROWTH = 1.15
MASK_CONTINUE = 3.0  # cm over which a column turns from the mask's tangent into the implicit head
FOLLOW = 4.0  # cm from the border over which the border's own displacement fades
JAW_FOLLOW = 8.5  # cm under the chin and jaw: the chin's motion fades to held down the throat
# Ears (the left one; the right one mirrors it).
EAR_TOP_Y, EAR_BOTTOM_Y = 2.25, -4.9  # brow level .. nose-base level
EAR_FRONT_Z = -8.3  # the tragus, just behind the jaw hinge (z = -7.8)
EAR_TILT = np.radians(17.0)  # the long axis leans back
EAR_FLARE = np.radians(16.0)  # the rim stands out from the head towards the back


@dataclass(frozen=True)
class HeadShell:
    """The head around a mask. vertices (M,3) cm at rest; triangles (K,3) int32 into vertices,
    counter-clockwise seen from outside; hair (M,) 0..1 = hair_weight(hair_coords), hair_coords
    (M,2) cm above the hairline and cm from the join (near linear over a triangle: a renderer
    interpolates them and takes hair_weight per pixel).

    ring (R,) shell indices of the join's vertices and ring_mask (R,) the mask vertex each one is
    (same place, every frame); `joined_triangles(n)` gives the triangles with those replaced by the
    mask's indices (for normals shared across the join). Posing: moving (P,) shell indices, the two
    mask border vertices col_mask (P,2) either side of each one's column, their rest places
    col_rest (P,2,3) and weights col_w (P,2): the share of their displacement the vertex takes
    (fading from 1 at the border to 0, further under the jaw than elsewhere). The first
    head_triangles triangles are the cranium and neck, the ears' follow."""

    vertices: FloatArray
    triangles: np.ndarray
    hair: FloatArray
    hair_coords: FloatArray
    ring: np.ndarray
    ring_mask: np.ndarray
    moving: np.ndarray
    col_mask: np.ndarray
    col_rest: FloatArray
    col_w: FloatArray
    head_triangles: int

    def joined_triangles(self, n_mask: int) -> np.ndarray:
        """The shell's triangles indexing [mask vertices (n_mask), shell vertices]: the join's
        vertices are the mask's own, so normals computed over both meshes match across it."""
        remap = np.arange(len(self.vertices)) + n_mask
        remap[self.ring] = self.ring_mask
        return remap[self.triangles].astype(np.int32)

    def pose(self, surface: FloatArray) -> FloatArray:
        """(M,3) shell positions for the mask's current surface (N,3): the join's vertices on the
        mask's border exactly, the moving ones displaced by their share of the border's motion,
        the rest held."""
        out = self.vertices.copy()
        surface = np.asarray(surface, np.float64)
        out[self.ring] = surface[self.ring_mask]
        if len(self.moving):
            moved = np.take(surface, self.col_mask, axis=0) - self.col_rest  # (P,2,3)
            out[self.moving] += np.einsum("pk,pkd->pd", self.col_w, moved)
        return out


# -- the implicit head ---------------------------------------------------------------------------
def _ellipsoid(p: FloatArray, c: FloatArray, a: FloatArray) -> FloatArray:
    """Approximate signed distance to an ellipsoid (exact on its surface, cm near it)."""
    q = (p - c) / a
    k0 = np.linalg.norm(q, axis=-1)
    k1 = np.linalg.norm(q / a, axis=-1)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-9)


def neck_axis(y: FloatArray) -> FloatArray:
    """z of the neck's axis at height y (it leans forward going up)."""
    return NECK_TOP[2] + NECK_SLOPE * (np.asarray(y) - NECK_TOP[1])


def neck_half(y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Half width and half depth of the neck at height y: slimmest at mid-neck, widening into the
    trapezius and towards the shoulders below TRAPEZIUS_Y."""
    y = np.asarray(y, float)
    below = np.clip((TRAPEZIUS_Y - y) / (TRAPEZIUS_Y - NECK_END_Y), 0.0, None)
    top = _smoothstep(-14.0, -7.0, y)  # wider under the skull: the sternocleidomastoids' origins
    return NECK_HALF[0] + 0.7 * top + 4.5 * below**1.6, NECK_HALF[1] + 0.9 * below**1.5


def _neck(p: FloatArray) -> FloatArray:
    y = p[..., 1]
    wx, wz = neck_half(y)
    qx, qz = p[..., 0] / wx, (p[..., 2] - neck_axis(y)) / wz
    r = np.sqrt(qx * qx + qz * qz)
    d = (r - 1.0) * np.minimum(wx, wz)
    return np.maximum(d, y - 2.0)  # capped inside the cranium


def _smin(a: FloatArray, b: FloatArray, k: float) -> FloatArray:
    h = np.maximum(k - np.abs(a - b), 0.0) / k
    return np.minimum(a, b) - h * h * k / 4.0


def _tube(p: FloatArray, rim: tuple[FloatArray, float]) -> FloatArray:
    """Signed distance to a tube of radius r round a polyline (points (S,3))."""
    pts, r = rim
    a, b = pts[:-1], pts[1:]
    ab = b - a
    q = p[..., None, :] - a
    t = np.clip(np.sum(q * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-12), 0.0, 1.0)
    d = np.linalg.norm(q - t[..., None] * ab, axis=-1)
    return d.min(axis=-1) - r


def head_field(p: FloatArray, rim: tuple[FloatArray, float] | None = None) -> FloatArray:
    """< 0 inside the implicit head, > 0 outside, ~ cm from its surface. rim: the jaw's rim, a
    tube laid just inside the mask's free border (so the head meets the mask there tangentially)."""
    f = _smin(_ellipsoid(p, CRANIUM_CENTRE, CRANIUM_AXES), _ellipsoid(p, SKULL_BASE_CENTRE, SKULL_BASE_AXES),
              BLEND)
    f = _smin(f, _neck(p), BLEND)
    f = _smin(f, _ellipsoid(p, JAW_CENTRE, JAW_AXES), BLEND)
    return f if rim is None else _smin(f, _tube(p, rim), 0.8 * BLEND)


def _cast(origin: FloatArray, dirs: FloatArray, far: float = 40.0, step: float = 0.35) -> FloatArray:
    """First exits of rays origin + t dirs (origins (R,3) inside the head, dirs (R,S,3) unit) from
    the implicit head: marched, then bisected. (R,S,3)."""
    ts = np.arange(step, far, step)
    o = origin[:, None, None, :]
    pts = o + dirs[:, :, None, :] * ts[None, None, :, None]
    out = head_field(pts) > 0.0
    first = np.argmax(out, axis=2)  # index of the first outside sample
    lo = ts[np.maximum(first - 1, 0)] * (first > 0)
    hi = ts[first]
    for _ in range(22):
        mid = 0.5 * (lo + hi)
        inside = head_field(origin[:, None, :] + dirs * mid[..., None]) <= 0.0
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    return origin[:, None, :] + dirs * (0.5 * (lo + hi))[..., None]


# -- the mask's border ---------------------------------------------------------------------------
def _outer_loop(mesh: FaceMesh) -> np.ndarray:
    """The mask's outer boundary loop (the longest one), starting at its top on the midline and
    going first towards +X (the face's left)."""
    loop = max(boundary_loops(np.asarray(mesh.triangles)), key=len)
    v = mesh.vertices[loop]
    top = int(np.argmax(v[:, 1] - 10.0 * np.abs(v[:, 0])))
    loop = np.roll(loop, -top)
    if mesh.vertices[loop[1], 0] < mesh.vertices[loop[-1], 0]:
        loop = np.r_[loop[:1], loop[1:][::-1]]
    return loop


def _smoothstep(e0: float, e1: float, x: FloatArray) -> FloatArray:
    s = np.clip((np.asarray(x, float) - e0) / (e1 - e0), 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _periodic_interp(s: FloatArray, knots: FloatArray, values: FloatArray) -> FloatArray:
    """Linear interpolation of values (K, ...) given at increasing knots in [0, 1), periodic."""
    k = np.r_[knots, knots[0] + 1.0]
    vals = np.concatenate([values, values[:1]])
    j = np.clip(np.searchsorted(k, s, side="right") - 1, 0, len(knots) - 1)
    a = ((s - k[j]) / (k[j + 1] - k[j])).reshape((-1,) + (1,) * (values.ndim - 1))
    return vals[j] * (1.0 - a) + vals[j + 1] * a


# -- the sweep -----------------------------------------------------------------------------------
def _neck_angle(sigma: FloatArray, keys: tuple[float, float]) -> FloatArray:
    """Where round the neck base (0 = front, pi = back, + towards +X) column sigma ends: the
    hairline goes to the back, the sides in front of the ears to the neck's sides, the chin to the
    front. keys: the loop parameters of the hairline's corner and of the side border's lower end."""
    corner, ear = keys
    s = np.where(sigma <= 0.5, sigma, 1.0 - sigma)
    psi = np.interp(s, [0.0, corner, ear, 0.5], [np.pi, 0.66 * np.pi, 0.44 * np.pi, 0.0])
    return np.where(sigma <= 0.5, psi, -psi)


# Guides for the columns' paths (left half; the right mirrors it): for key places along the mask's
# border (loop parameter keys: top of the hairline, its corner, in front of the ear, the ear lobe's
# level where the jaw border starts, the jaw's angle, under the chin), waypoints (cm) the path
# passes near on its way to the neck base, before it is laid on the implicit head.
_GUIDES = np.array([
    [(0.0, 11.0, -6.0), (0.0, 10.6, -11.5), (0.0, 6.5, -17.5), (0.0, -1.0, -18.6),
     (0.0, -7.5, -16.2), (0.0, -13.0, -15.6), (0.0, -19.0, -16.6)],
    [(6.9, 6.8, -9.6), (6.7, 5.9, -13.3), (5.6, 1.0, -16.5), (4.6, -5.5, -15.6),
     (4.0, -9.5, -15.0), (4.0, -13.5, -14.8), (4.2, -19.0, -16.0)],
    [(7.3, 0.6, -9.0), (7.4, -0.5, -11.8), (6.9, -3.0, -13.6), (6.2, -6.5, -13.6),
     (5.7, -9.5, -13.2), (5.5, -13.5, -13.2), (6.2, -19.0, -14.5)],
    [(6.5, -6.3, -7.7), (6.4, -7.0, -9.0), (6.2, -8.2, -10.1), (5.9, -9.8, -10.9),
     (5.6, -11.5, -11.4), (5.4, -14.0, -12.0), (6.6, -19.0, -13.0)],
    [(5.3, -10.0, -7.6), (5.3, -11.0, -8.4), (5.3, -12.0, -9.0), (5.3, -13.3, -9.5),
     (5.3, -14.8, -10.0), (5.4, -16.5, -10.5), (6.4, -19.0, -11.0)],
    [(0.0, -14.0, -3.5), (0.0, -14.4, -4.6), (0.0, -15.4, -5.2), (0.0, -16.8, -5.5),
     (0.0, -18.2, -5.8), (0.0, -19.6, -6.0), (0.0, -21.0, -6.2)],
])


def _project(p: FloatArray, rim: tuple[FloatArray, float] | None = None, iterations: int = 10) -> FloatArray:
    """Points moved onto the implicit head along its gradient (Newton steps)."""
    h = 1e-3
    for _ in range(iterations):
        f = head_field(p, rim)
        g = np.stack([(head_field(p + e, rim) - f) / h for e in np.eye(3) * h], axis=-1)
        p = p - (f / np.maximum(np.sum(g * g, axis=-1), 1e-9))[..., None] * g
    return p


def _catmull_rom(pts: FloatArray, samples: int) -> FloatArray:
    """A uniform Catmull-Rom curve through pts (P,3), its ends extended by reflection: (S,3)."""
    p = np.vstack([2 * pts[0] - pts[1], pts, 2 * pts[-1] - pts[-2]])
    n = len(pts) - 1
    t = np.linspace(0.0, n, samples)
    i = np.minimum(t.astype(int), n - 1)
    u = (t - i)[:, None]
    p0, p1, p2, p3 = p[i], p[i + 1], p[i + 2], p[i + 3]
    return 0.5 * ((2 * p1) + (-p0 + p2) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u**2
                  + (-p0 + 3 * p1 - 3 * p2 + p3) * u**3)


def _column_paths(F: FloatArray, T: FloatArray, sigma: FloatArray, keys: tuple[float, float, float],
                  rim: tuple[FloatArray, float], sig_border: FloatArray, F_border: FloatArray,
                  samples: int = 120) -> list[FloatArray]:
    """For each column (its border point F, outward tangent T at loop parameter sigma): a polyline
    from F over the head to the neck base, through the guides laid on the implicit head, leaving
    the border along the mask's own surface."""
    psi = _neck_angle(sigma, keys[:2])
    wx, wz = neck_half(NECK_END_Y)
    end = np.stack([wx * np.sin(psi), np.full_like(psi, NECK_END_Y), neck_axis(NECK_END_Y) + wz * np.cos(psi)], 1)
    half = np.where(sigma <= 0.5, sigma, 1.0 - sigma)
    knots = np.array([0.0, keys[0], 0.5 * (keys[0] + keys[1]), keys[1], keys[2], 0.5])
    guides = np.stack([np.stack([np.interp(half, knots, _GUIDES[:, w, d]) for d in range(3)], 1)
                       for w in range(_GUIDES.shape[1])], 1)  # (C, W, 3)
    guides[sigma > 0.5, :, 0] *= -1.0
    # between key places the border curves away from the straight line the guides interpolate:
    # shift a column's guides by its border point's offset from that line, fading down the path
    key_f = _periodic_interp(knots, sig_border, F_border)
    f_lin = np.stack([np.interp(half, knots, key_f[:, d]) for d in range(3)], 1)
    f_lin[sigma > 0.5, 0] *= -1.0
    fade = 1.0 - np.arange(guides.shape[1]) / guides.shape[1]
    guides += (F - f_lin)[:, None, :] * fade[None, :, None]
    paths = []
    for c in range(len(F)):
        pts = np.vstack([F[c], F[c] + 1.2 * T[c], guides[c], end[c]])
        g = _project(_catmull_rom(pts, samples), rim)
        seg = np.linalg.norm(np.diff(g, axis=0), axis=1)
        s = np.r_[0.0, np.cumsum(seg)]
        b = _smoothstep(0.0, MASK_CONTINUE, s)[:, None]
        straight = F[c] + T[c] * s[:, None]
        p = (1.0 - b) * straight + b * g
        p[0] = F[c]
        paths.append(p)
    return paths


def _even_out(rows: FloatArray, dist: FloatArray, rim: tuple[FloatArray, float], rounds: int = 6) -> FloatArray:
    """Smooth the swept grid round its rings (neighbouring columns meet evenly where the border
    turns a corner), then lay the rows beyond the mask's continuation back on the implicit head."""
    out = rows.copy()
    for _ in range(rounds):
        ring_mean = 0.5 * (np.roll(out, 1, axis=1) + np.roll(out, -1, axis=1))
        out = out + 0.5 * (ring_mean - out)
    far = dist > MASK_CONTINUE
    out[far] = _project(out[far], rim)
    w = _smoothstep(0.8, 2.5, dist)[..., None]  # the first rows stay near the border's own
    return rows * (1.0 - w) + out * w


def _resample(path: FloatArray, fractions: FloatArray) -> tuple[FloatArray, FloatArray]:
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    target = fractions * s[-1]
    return np.stack([np.interp(target, s, path[:, d]) for d in range(3)], 1), target


def _zipper(pa: FloatArray, pb: FloatArray, a0: int, b0: int) -> list[tuple[int, int, int]]:
    """Triangles between two closed rings of points pa (A,3), pb (B,3), both starting at the same
    place and running the same way (vertex indices a0 + i, b0 + j): each step takes the shorter
    of the two diagonals it could add (a fan never reaches across a corner of the other ring)."""
    na, nb = len(pa), len(pb)
    i = j = 0
    tris = []
    while i < na or j < nb:
        ia, jb = (i + 1) % na, (j + 1) % nb
        take_a = j >= nb or (i < na and np.sum((pa[ia] - pb[j % nb]) ** 2) <= np.sum((pa[i % na] - pb[jb]) ** 2))
        if take_a:
            tris.append((a0 + i % na, b0 + j % nb, a0 + ia))
            i += 1
        else:
            tris.append((a0 + i % na, b0 + j % nb, b0 + jb))
            j += 1
    return tris


def _hair_line(theta: FloatArray) -> FloatArray:
    """Height (cm) of the hairline round the head at angle theta from the front (about the neck's
    vertical axis): at the forehead's top in front (where the mask's border sits below it), down to the
    sideburns at the temples, over the ears, down behind them to the nape."""
    a = np.degrees(np.abs(theta))
    return np.interp(a, [0, 50, 66, 82, 98, 110, 128, 150, 180],
                     [6.0, 5.0, 0.8, 2.9, 3.1, 2.2, -2.5, -6.5, -7.4])


HAIR_EDGE = (1.0, 0.2, 1.6)
"""cm: the hairline's soft half width; the distance from the join where hair starts and is full."""


def hair_weight(coords: FloatArray) -> FloatArray:
    """Hair (0 skin .. 1 hair) from hairline coordinates (..., 2): cm above the hairline, cm from
    the join. The renderer evaluates the same per pixel (its SCALP shader), so the hairline is
    smooth however coarse the mesh."""
    soft, start, full = HAIR_EDGE
    return _smoothstep(-soft, soft, coords[..., 0]) * _smoothstep(start, full, coords[..., 1])


def _hair_coords(p: FloatArray, from_border: FloatArray) -> FloatArray:
    theta = np.arctan2(p[:, 0], p[:, 2] - neck_axis(0.0))
    return np.stack([p[:, 1] - _hair_line(theta), from_border], 1)


def _sweep(mesh: FaceMesh) -> tuple[FloatArray, np.ndarray, FloatArray, np.ndarray, dict]:
    loop = _outer_loop(mesh)
    v = np.asarray(mesh.vertices, float)
    F0 = v[loop]
    seg = np.linalg.norm(np.diff(np.vstack([F0, F0[:1]]), axis=0), axis=1)
    sig0 = np.r_[0.0, np.cumsum(seg)[:-1]] / seg.sum()
    n = vertex_normals(v, np.asarray(mesh.triangles))[loop]
    along = np.roll(F0, -1, axis=0) - np.roll(F0, 1, axis=0)
    T0 = np.cross(along, n)
    T0 /= np.linalg.norm(T0, axis=1, keepdims=True)
    inner = v.mean(axis=0)
    if np.sum(np.sum(T0 * (F0 - inner), axis=1) > 0) < len(T0) / 2:
        T0 = -T0
    held = np.asarray(mesh.held, bool)[loop]
    left = sig0 <= 0.5
    free_left = np.flatnonzero(left & ~held)
    ear_key = float(sig0[free_left.min()]) if len(free_left) else 0.3
    # the hairline's corner: where the border turns from running sideways to running down
    dy = np.abs(np.diff(np.r_[F0[:, 1], F0[:1, 1]]))
    dx = np.abs(np.diff(np.r_[F0[:, 0], F0[:1, 0]]))
    steep = np.flatnonzero(left & (dy > dx) & (sig0 < ear_key))
    corner_key = float(sig0[steep.min()]) if len(steep) else 0.5 * ear_key
    # the jaw's angle: the free border's point furthest from the chin and the ear lobe's level line
    jaw_pts = np.flatnonzero(left & ~held)
    chin = F0[np.argmin(np.abs(sig0 - 0.5))]
    ear_pt = F0[jaw_pts.min()] if len(jaw_pts) else chin
    d_line = np.linalg.norm(np.cross(F0[jaw_pts] - chin, ear_pt - chin), axis=1) if len(jaw_pts) else np.zeros(1)
    angle_key = float(sig0[jaw_pts[np.argmax(d_line)]]) if len(jaw_pts) else 0.4
    keys = (corner_key, ear_key, angle_key)
    # the columns leave the border along its outward tangent smoothed over ~1 cm (the mask's
    # border kinks where the hairline meets the side, and a fine mesh resolves the kink)
    arc = sig0 * seg.sum()
    gap = np.abs(arc[:, None] - arc[None, :])
    gap = np.minimum(gap, seg.sum() - gap)
    kern = np.exp(-0.5 * (gap / 0.8) ** 2)
    kern /= kern.sum(axis=1, keepdims=True)
    Ts = kern @ T0
    Ts /= np.linalg.norm(Ts, axis=1, keepdims=True)
    # columns evenly spaced along the border offset by 1.5 cm: more of them round its corners
    off = F0 + 1.5 * Ts
    off_seg = np.linalg.norm(np.diff(np.vstack([off, off[:1]]), axis=0), axis=1)
    sig_off = np.r_[0.0, np.cumsum(off_seg)] / off_seg.sum()
    sigma = np.interp(np.arange(COLUMNS) / COLUMNS, sig_off, np.r_[sig0, 1.0])
    F = _periodic_interp(sigma, sig0, F0)
    T = _periodic_interp(sigma, sig0, Ts)
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    # the jaw's rim: the free border (ear lobe level, round the jaw, under the chin), moved in
    # along the mask's normal by the tube's radius, so the tube touches the border tangentially
    free = np.flatnonzero(~held)
    free = free[np.argsort(sig0[free])]
    if len(free) > 40:
        free = free[np.linspace(0, len(free) - 1, 40).astype(int)]
    rim = (F0[free] - JAW_RIM * n[free], JAW_RIM)
    paths = _column_paths(F, T, sigma, keys, rim, sig0, F0)
    i = np.arange(1, ROWS + 1)
    rows = np.zeros((ROWS, COLUMNS, 3))
    dist = np.zeros((ROWS, COLUMNS))
    for c, path in enumerate(paths):
        # the first row ~FIRST_ROW from the border (a short column's rows closer), then growing
        length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
        first = min(FIRST_ROW, length / ROWS)
        s = first * i + (length - first * ROWS) * ((i - 1) / (ROWS - 1)) ** ROW_GROWTH
        rows[:, c], dist[:, c] = _resample(path, s / length)
    rows = _even_out(rows, dist, rim)
    K = len(loop)
    # which two border vertices each swept vertex follows (and how far between them)
    j0 = np.clip(np.searchsorted(sig0, sigma, side="right") - 1, 0, K - 1)
    j1 = (j0 + 1) % K
    t = (sigma - sig0[j0]) / (np.where(j1 == 0, 1.0, sig0[j1]) - sig0[j0])
    tris = _zipper(F0, rows[0], 0, K)
    for r in range(ROWS - 1):
        a0, b0 = K + r * COLUMNS, K + (r + 1) * COLUMNS
        for c in range(COLUMNS):
            d = (c + 1) % COLUMNS
            tris += [(a0 + c, b0 + c, a0 + d), (a0 + d, b0 + c, b0 + d)]
    verts = np.vstack([F0, rows.reshape(-1, 3)])
    # distance from the border in space (where columns bunch up at a corner, their arc lengths
    # overstate it): what the hair and the share of the border's motion fade with
    swept = verts[K:]
    near = np.min(np.linalg.norm(swept[:, None, :] - F0[None, :, :], axis=2), axis=1)
    from_border = np.r_[np.zeros(K), np.minimum(near, dist.ravel())]
    tri = np.array(tris, np.int32)
    # counter-clockwise from outside: compare with the direction from the head's inside
    cen = verts[tri].mean(axis=1)
    nrm = np.cross(verts[tri[:, 1]] - verts[tri[:, 0]], verts[tri[:, 2]] - verts[tri[:, 0]])
    inside = np.stack([np.zeros(len(cen)), np.where(cen[:, 1] > -6.0, 0.0, cen[:, 1]),
                       neck_axis(np.minimum(cen[:, 1], 0.0))], 1)
    if np.mean(np.sum(nrm * (cen - inside), axis=1) > 0) < 0.5:
        tri = tri[:, [0, 2, 1]]
    info = dict(loop=loop, K=K, follow=np.tile(np.stack([j0, j1], 1), (ROWS, 1)), between=np.tile(t, ROWS),
                jaw=np.tile(_periodic_interp(sigma, sig0, np.asarray(mesh.jaw_weight, float)[loop]), ROWS))
    return verts, tri, from_border, loop, info


# -- the ears ------------------------------------------------------------------------------------
# The ear's rim round the concha's centre, (up, back) in cm of a 6.8 cm ear: the helix arching
# over a broad top and down a nearly straight back edge into the lobe, the intertragic notch and
# the tragus in front, the helix's root above them.
_EAR_RIM = np.array([
    (3.95, 0.7), (3.55, 1.9), (2.5, 2.5), (0.9, 2.45), (-0.7, 2.05), (-1.9, 1.5), (-2.85, 0.65),
    (-2.55, -0.2), (-1.3, -0.5), (-0.3, -0.95), (1.0, -0.9), (2.6, -0.55), (3.6, -0.05),
])


def _ear_outline(a: FloatArray) -> FloatArray:
    """Distance (cm) from the concha's centre to the ear's rim at angle a (0 = up, pi/2 = back,
    pi = down to the lobe, 3pi/2 = forward to the tragus), for a 6.8 cm ear."""
    ang = np.mod(np.arctan2(_EAR_RIM[:, 1], _EAR_RIM[:, 0]), 2 * np.pi)
    rad = np.hypot(_EAR_RIM[:, 0], _EAR_RIM[:, 1])
    order = np.argsort(ang)
    ang, rad = ang[order], rad[order]
    ang = np.r_[ang[-1] - 2 * np.pi, ang, ang[0] + 2 * np.pi]
    rad = np.r_[rad[-1], rad, rad[0]]
    return np.interp(np.mod(a, 2 * np.pi), ang, rad)


def _ear_relief(r: FloatArray, a: FloatArray) -> FloatArray:
    """Height (cm, out of the ear's plane) of the front of the ear at fraction r of the way from the
    concha's centre to the rim, angle a: the rolled helix rim, the scapha groove inside it, the
    antihelix ridge round the concha, the concha's hollow, the soft lobe, the tragus."""
    a = np.mod(a, 2 * np.pi)
    helix_on = 1.0 - _smoothstep(2.55, 2.95, a) * (1.0 - _smoothstep(4.2, 4.5, a))  # not round the lobe
    helix_on *= 1.0 - 0.7 * np.exp(-(((a - 4.7) / 0.35) ** 2))  # fades into the crus at the front
    rim = np.exp(-(((r - 0.9) / 0.075) ** 2)) * 0.42 * helix_on
    scapha = -0.22 * np.exp(-(((r - 0.74) / 0.07) ** 2)) * helix_on * _smoothstep(0.3, 1.0, a) * (1 - _smoothstep(2.3, 2.7, a))
    anti = 0.30 * np.exp(-(((r - 0.56) / 0.09) ** 2)) * _smoothstep(-0.2, 0.4, np.minimum(a, 2 * np.pi - a) * 0 + a) \
        * (1.0 - _smoothstep(2.2, 2.6, a))
    concha = -1.0 * (1.0 - _smoothstep(0.12, 0.5, r)) * (1.0 - 0.5 * _smoothstep(-0.5, 0.5, np.cos(a)))
    lobe_w = _smoothstep(2.6, 3.0, a) * (1.0 - _smoothstep(3.7, 4.1, a))
    lobe = 0.18 * lobe_w * np.exp(-(((r - 0.7) / 0.25) ** 2))
    tragus = 0.35 * np.exp(-(((r - 0.95) / 0.12) ** 2)) * np.exp(-(((a - 4.45) / 0.3) ** 2))
    edge = -0.25 * _smoothstep(0.93, 1.0, r)  # rolled over at the very edge
    return rim + scapha + anti + concha + lobe + tragus + edge


def ear_frame(side: float = 1.0) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(origin, up, back, out) of an ear: origin at the concha's centre (cm), unit axes of its
    plane (up leaning back EAR_TILT, back) and out of the head. side +1 = left (+X)."""
    up = np.array([0.0, np.cos(EAR_TILT), -np.sin(EAR_TILT)])
    back = np.array([0.0, -np.sin(EAR_TILT), -np.cos(EAR_TILT)])
    out = np.array([side, 0.0, 0.0])
    # the concha's centre: 42 % of the way up the ear, ~1.3 cm behind the tragus
    cy = EAR_BOTTOM_Y + 0.42 * (EAR_TOP_Y - EAR_BOTTOM_Y)
    cz = EAR_FRONT_Z - 1.1
    p = np.array([side * 6.0, cy, cz])
    # on the head's side surface at that height: march out along +-X to the implicit head
    hit = _cast(p[None, :] * [0, 1, 1], out[None, None, :])[0, 0]
    return hit, up, back, out


def _ear(side: float) -> tuple[FloatArray, np.ndarray]:
    origin, up, back, out = ear_frame(side)
    n_a, n_r, n_back = 20, 6, 1
    a = np.linspace(0.0, 2 * np.pi, n_a, endpoint=False)
    r = np.array([0.22, 0.45, 0.57, 0.74, 0.89, 0.98])[:n_r]  # on the relief: concha, antihelix, scapha, rim
    scale = (EAR_TOP_Y - EAR_BOTTOM_Y) / (_EAR_RIM[:, 0].max() - _EAR_RIM[:, 0].min())
    rr, aa = np.meshgrid(r, a, indexing="ij")
    R = _ear_outline(aa) * scale * rr
    u, w = R * np.cos(aa), R * np.sin(aa)  # up, back (cm)
    # the flap stands out from the head towards its back and top edge; the relief on its front
    stand = np.tan(EAR_FLARE) * np.maximum(w + 1.0, 0.0) + 0.1 + 0.06 * np.maximum(u, 0.0)
    h = stand + _ear_relief(rr, aa)
    front = origin + u[..., None] * up + w[..., None] * back + h[..., None] * out
    # the back of the ear: from the rim curling behind and into the head
    rim_u, rim_w, rim_h = u[-1], w[-1], h[-1]
    backs = []
    for k, f in enumerate(np.linspace(0.15, 1.0, n_back)):
        shrink = 1.0 - 0.35 * f
        depth = rim_h - (0.35 + 2.0 * f**1.5) * (0.6 + 0.4 * np.maximum(rim_w + 1.0, 0.0) / 3.0)
        backs.append(origin + (rim_u * shrink)[:, None] * up + (rim_w * shrink)[:, None] * back
                     + depth[:, None] * out)
    centre = origin + (stand[0].mean() + _ear_relief(np.array([0.0]), np.array([0.0]))[0]) * out
    verts = np.vstack([centre[None, :], front.reshape(-1, 3), np.vstack(backs)])
    rings = n_r + n_back
    tris = [(0, 1 + (k + 1) % n_a, 1 + k) for k in range(n_a)]
    for i in range(rings - 1):
        b0, b1 = 1 + i * n_a, 1 + (i + 1) * n_a
        for k in range(n_a):
            j = (k + 1) % n_a
            tris += [(b0 + k, b1 + j, b1 + k), (b0 + k, b0 + j, b1 + j)]
    tri = np.array(tris, np.int32)
    cen = verts[tri].mean(axis=1)
    nrm = np.cross(verts[tri[:, 1]] - verts[tri[:, 0]], verts[tri[:, 2]] - verts[tri[:, 0]])
    # the front faces out of the head
    if np.mean(np.sum(nrm[:n_a * 4] * out, axis=1) > 0) < 0.5:
        tri = tri[:, [0, 2, 1]]
    return verts, tri


# -- the whole shell -----------------------------------------------------------------------------
def head_shell(mesh: FaceMesh) -> HeadShell:
    """Cranium, neck and both ears around a default-face mask, joined to its outer border."""
    verts, tri, from_border, loop, info = _sweep(mesh)
    K = info["K"]
    parts_v, parts_t, parts_h = [verts], [tri], [_hair_coords(verts, from_border)]
    base = len(verts)
    for side in (1.0, -1.0):
        v, t = _ear(side)
        parts_v.append(v)
        parts_t.append(t + base)
        parts_h.append(np.tile([-100.0, 0.0], (len(v), 1)))  # no hair on the ears
        base += len(v)
    all_v = np.vstack(parts_v)
    # who moves: the sweep's vertices near the border, each with its share of the displacement of
    # the two border vertices its column starts between; under the jaw the share fades over a
    # longer way, down the throat, so the chin's travel when the mouth opens shears the neck's
    # skin instead of folding it
    reach = FOLLOW + (JAW_FOLLOW - FOLLOW) * info["jaw"]
    share = 1.0 - _smoothstep(0.0, 1.0, from_border[K:] / reach)
    moving = np.flatnonzero(share > 1e-6)
    col_mask = loop[info["follow"][moving]]
    t = info["between"][moving]
    sh = share[moving]
    return HeadShell(
        vertices=all_v.astype(np.float64),
        triangles=np.vstack(parts_t).astype(np.int32),
        hair=hair_weight(np.vstack(parts_h)),
        hair_coords=np.vstack(parts_h).astype(np.float64),
        ring=np.arange(K),
        ring_mask=loop.astype(np.int64),
        moving=(moving + K).astype(np.int64),
        col_mask=col_mask.astype(np.int64),
        col_rest=np.asarray(mesh.vertices, float)[col_mask],
        col_w=np.stack([(1.0 - t) * sh, t * sh], 1),
        head_triangles=len(tri),
    )


_SHELLS: dict[bytes, HeadShell] = {}


class ShellStore(Protocol):
    """Where built shells are kept between processes (`use_store`; puppet.face_cache keeps them on
    disk beside the compiled faces). `load` returns None for anything it cannot vouch for."""

    def load(self, key: bytes) -> HeadShell | None: ...

    def save(self, key: bytes, shell: HeadShell) -> None: ...


_STORE: ShellStore | None = None


def use_store(store: ShellStore | None) -> None:
    """Keep built shells in `store` too (None: in this process only). Building one takes ~0.4 s,
    which a window's or an export's start would otherwise pay every time."""
    global _STORE
    _STORE = store


def check_shell(shell: HeadShell, mask: FaceMesh) -> None:
    """ValueError unless `shell` is consistent in itself and with `mask` (shapes, finiteness,
    every index in range): what a shell read back from a file must pass before it is drawn."""
    n, m = len(mask.vertices), len(shell.vertices)
    v, t = np.asarray(shell.vertices), np.asarray(shell.triangles)
    p = len(shell.moving)
    shapes = {"vertices": (m, 3), "hair": (m,), "hair_coords": (m, 2), "ring_mask": (len(shell.ring),),
              "col_mask": (p, 2), "col_rest": (p, 2, 3), "col_w": (p, 2)}
    for name, want in shapes.items():
        if np.asarray(getattr(shell, name)).shape != want:
            raise ValueError(f"head shell: {name} has the wrong shape")
    for name in ("vertices", "hair", "hair_coords", "col_rest", "col_w"):
        a = np.asarray(getattr(shell, name))
        if a.dtype.kind != "f" or not np.all(np.isfinite(a)):
            raise ValueError(f"head shell: {name} is not finite")
    for name, arr, hi in (("triangles", t, m), ("ring", shell.ring, m), ("moving", shell.moving, m),
                          ("ring_mask", shell.ring_mask, n), ("col_mask", shell.col_mask, n)):
        a = np.asarray(arr)
        if a.dtype.kind not in "iu" or (a.size and (a.min() < 0 or a.max() >= hi)):
            raise ValueError(f"head shell: {name} indexes out of range")
    if t.ndim != 2 or t.shape[1] != 3 or v.size == 0 or not 0 <= int(shell.head_triangles) <= len(t):
        raise ValueError("head shell: triangles are malformed")


def shell_for(rig: FaceRig) -> HeadShell | None:
    """The head around the default face (a rig named default-N), or None for any other rig. Built
    once per mask (kept by a digest of its geometry: a renderer and an export's frames share it),
    and read from the store (`use_store`) when one holds it."""
    if not str(rig.name).startswith("default-"):
        return None
    m = rig.mesh
    h = hashlib.sha1()
    for a in (m.vertices, m.triangles, m.jaw_weight, m.held):
        h.update(np.ascontiguousarray(a).tobytes())
    key = h.digest()
    if key not in _SHELLS:
        if len(_SHELLS) >= 4:
            _SHELLS.pop(next(iter(_SHELLS)))
        shell = _STORE.load(key) if _STORE is not None else None
        if shell is not None:
            try:
                check_shell(shell, m)
            except ValueError:
                shell = None
        if shell is None:
            shell = head_shell(m)
            if _STORE is not None:
                try:
                    _STORE.save(key, shell)
                except OSError:  # an unwritable store: built again next time
                    pass
        for a in vars(shell).values():
            if isinstance(a, np.ndarray):
                a.setflags(write=False)  # shared by every caller
        _SHELLS[key] = shell
    return _SHELLS[key]
