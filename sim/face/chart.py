"""Where the default face's vertices go on the flat (u, v) chart, before the 3D map.

Explicit rows come first (eye and mouth loops with rings of lid and lip rows around them, the
outer border, the midline, the landmarks, and rows along the expressive wrinkle lines with a flank
row on each side); a graded Poisson-disc fill (denser at the eyes, mouth and nose) covers the rest.
Only the face's left half (u >= 0) is laid out; the builder mirrors it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from sim.face import shape as fs

FloatArray = np.ndarray

H_MIN, H_MAX = 0.3, 1.45
"""cm: vertex spacing at resolution 0 next to the eyes and mouth, and on the forehead/cheek sides."""
SIDE_COARSEN = 0.4
"""fraction by which the fill's spacing grows further on the cheek sides, towards the ears."""
U_SIDE = 9.6
"""chart u of the side border (about 78 degrees round the head: in front of the ears)."""
V_TOP = 7.0
V_EAR = -5.0
"""chart height where the held side border gives way to the free border along the jaw."""
JAW_BORDER = np.array(
    [[9.6, -5.0], [9.5, -7.0], [9.15, -8.6], [8.6, -9.7], [7.3, -10.9], [5.1, -12.3], [2.6, -13.4], [0.0, -13.8]]
)
FOREHEAD_LINES = (3.2, 4.2, 5.2)
"""chart heights of the horizontal forehead wrinkle rows (at the midline)."""
NASAL_ROOT_DY = 0.36
"""cm above the eye centres: the nasal-root line, just under the nasion (y = 0.6)."""
GLABELLA_OBLIQUE = ((1.05, 0.95), (1.41, 1.5), (1.75, 2.2))
"""frontal (x, y - eye centre height) of the oblique glabellar line, through the inner brow head."""
LIP_UPPER_X = (0.45, 0.95, 1.45)
LIP_LOWER_X = (0.5, 1.1)
"""frontal x of the perioral lines' ends nearest the lips (the mask's, sim.wrinkles.mask); the upper
lines' flank rows (0.25 cm) are shared between neighbours, the lower ones' (0.3 cm) too."""
FLANK = {"lip_upper": 0.25}
"""cm at resolution 0 between a wrinkle row and its flank rows, by line-name prefix (default 0.3)."""
ONE_SIDED = ("glabella_oblique",)
"""lines with a flank row on their right (lateral) side only: the skin medial to the oblique
glabellar line is the vertical line's roll, which has its own rows."""
ROW_STEP = {
    "forehead": 0.8, "nasolabial": 0.7, "marionette": 0.7, "chin_crease": 0.65, "lip": 0.16, "nasal_root": 0.3,
    "glabella_oblique": 0.55,
}
"""cm at resolution 0 between the vertices along a wrinkle row, by line-name prefix (default 0.55)."""


def sizing(u: FloatArray, v: FloatArray) -> FloatArray:
    """Target vertex spacing (cm) at resolution 0."""
    au = np.abs(u)
    ex, ey = fs.EYE_CENTER_XY
    ecu = float(fs.chart_u(ex, ey))
    rho_e = np.hypot((au - ecu) / 1.9, (v - ey) / 0.85)
    rho_m = np.hypot(au / 3.3, (v - fs.MOUTH_V) / 0.6)
    g = np.maximum(np.exp(-((np.maximum(rho_e - 1.0, 0.0) / 1.0) ** 2)), np.exp(-((np.maximum(rho_m - 1.0, 0.0) / 0.9) ** 2)))
    g = np.maximum(g, 0.8 * np.exp(-((au / 1.5) ** 2) - ((v + 4.5) / 1.1) ** 2))
    g = np.maximum(g, 0.45 * np.exp(-((au / 2.0) ** 2) - ((v + 1.5) / 2.5) ** 2))
    h = H_MAX - (H_MAX - H_MIN) * g
    # Coarser still on the cheek sides, where nothing creases.
    side = np.clip((au - 5.5) / 2.5, 0.0, 1.0)
    return h * (1.0 + SIDE_COARSEN * side**2)


def resample(poly: FloatArray, spacing: float, closed: bool = False) -> FloatArray:
    """Points at (about) equal arc-length `spacing` along a polyline, keeping both ends."""
    pts = np.vstack([poly, poly[:1]]) if closed else poly
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(int(np.ceil(s[-1] / spacing - 1e-9)), 1)
    t = np.linspace(0.0, s[-1], n + 1)
    out = np.stack([np.interp(t, s, pts[:, 0]), np.interp(t, s, pts[:, 1])], axis=1)
    return out[:-1] if closed else out


def offset(poly: FloatArray, d: float) -> FloatArray:
    """The polyline moved sideways by d (to its left in the chart)."""
    tang = np.gradient(poly, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    return poly + d * np.stack([-tang[:, 1], tang[:, 0]], axis=1)


def to_chart(xy: FloatArray) -> FloatArray:
    """Frontal (x, y) of the left half -> chart (u, v)."""
    return np.stack([fs.chart_u(xy[:, 0], xy[:, 1]), xy[:, 1]], axis=1)


def frontal_to_chart(xy: FloatArray, iters: int = 6) -> FloatArray:
    """Left-half frontal (x, y) of the skin itself (after the relief, the lids and the lips have
    moved it) -> chart (u, v), by Newton steps on `fs.surface` from `to_chart`. For rows that
    must lie exactly under a wrinkle line of the mask, which is given on the skin."""
    xy = np.asarray(xy, dtype=float)
    uv = to_chart(xy)
    eps = 1e-5
    for _ in range(iters):
        p = fs.surface(uv[:, 0], uv[:, 1])[:, :2]
        pu = fs.surface(uv[:, 0] + eps, uv[:, 1])[:, :2]
        pv = fs.surface(uv[:, 0], uv[:, 1] + eps)[:, :2]
        j = np.stack([(pu - p) / eps, (pv - p) / eps], axis=2)  # (N, 2 xy, 2 uv)
        uv = uv + np.linalg.solve(j, (xy - p)[:, :, None])[:, :, 0]
        uv[:, 0] = np.maximum(uv[:, 0], 0.0)
    return uv


def eye_loop_chart(n: int, grow: float = 0.0) -> FloatArray:
    """Left eye loop (or a ring `grow` cm outside it): inner corner, upper lid to the outer corner,
    lower lid back; clockwise seen from the front. 2n points."""
    t = np.linspace(0.0, 1.0, n + 1)
    x, yu, yl = fs.eye_curve(t, grow)
    upper = np.stack([x, yu], axis=1)
    lower = np.stack([x, yl], axis=1)[::-1][1:-1]
    return to_chart(np.vstack([upper, lower]))


def mouth_half_loop(n: int, grow: float = 0.0) -> tuple[FloatArray, FloatArray]:
    """Left half of the mouth loop (or a ring outside it): upper row from the midline to the
    corner (n+1 points, corner last) and lower row from the midline to just before the corner."""
    a = float(fs.chart_u(fs.MOUTH_X, fs.MOUTH_V)) + 0.8 * grow
    t = np.linspace(0.0, 1.0, n + 1)
    u = a * (0.5 * t + 0.5 * np.sin(0.5 * np.pi * t))  # closer together at the corner
    hh = fs.mouth_half_height(u, grow)
    upper = np.stack([u, fs.MOUTH_V + hh], axis=1)
    lower = np.stack([u, fs.MOUTH_V - hh], axis=1)[:-1]
    return upper, lower


def wrinkle_lines() -> dict[str, FloatArray]:
    """Left-half expressive wrinkle lines as chart polylines (frontal layout, seed 003 section 2)."""
    lines: dict[str, FloatArray] = {}
    for k, v0 in enumerate(FOREHEAD_LINES):
        x = np.linspace(0.0, 4.6, 12)
        lines[f"forehead_{k}"] = to_chart(np.stack([x, v0 - 0.35 * (x / 4.6) ** 2], axis=1))
    lines["glabella"] = to_chart(np.array([[0.6, 0.9], [0.62, 1.7], [0.68, 2.5]]))
    ox, oy = fs.EYE_OUTER
    for ang in (-30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0):
        # Crow's feet: the rays at -20, 0, +20 degrees; the ones between and outside flank them.
        a = np.radians(ang)
        wrinkle = ang in (-20.0, 0.0, 20.0)
        r = np.linspace(0.6 if wrinkle else 0.95, 1.9, 5 if wrinkle else 4)
        kind = "crows_feet" if wrinkle else "crows_flank"
        lines[f"{kind}_{int(ang):+d}"] = to_chart(np.stack([ox + r * np.cos(a), oy + r * np.sin(a)], axis=1))
    t = np.linspace(0.0, 1.0, 12)
    bez = ((1 - t) ** 2)[:, None] * [1.95, -4.15] + (2 * t * (1 - t))[:, None] * [3.05, -5.3] + (t**2)[:, None] * [3.35, -7.7]
    lines["nasolabial"] = to_chart(bez)
    lines["marionette"] = to_chart(np.array([[3.05, -7.75], [3.15, -8.8], [3.25, -10.0]]))
    x = np.linspace(0.0, 1.9, 8)
    lines["chin_crease"] = to_chart(np.stack([x, -8.75 + 0.25 * (x / 1.9) ** 2], axis=1))
    # Lines placed on the skin itself (the mask's, sim.wrinkles.mask): the nasal root at the
    # nasion, the oblique glabellar lines above the inner brow heads, and the short perioral lines.
    ey = fs.EYE_CENTER_XY[1]
    x = np.linspace(0.0, 0.8, 5)
    lines["nasal_root"] = frontal_to_chart(np.stack([x, ey + NASAL_ROOT_DY + 0.06 * (x / 0.8) ** 2], axis=1))
    lines["glabella_oblique"] = frontal_to_chart(np.array(GLABELLA_OBLIQUE) + [0.0, ey])
    for i, x0 in enumerate(LIP_UPPER_X, start=1):
        lines[f"lip_upper_{i}"] = frontal_to_chart(np.array([[x0, fs.MOUTH_V + 0.62], [x0 + 0.05, fs.MOUTH_V + 1.15]]))
    for i, x0 in enumerate(LIP_LOWER_X, start=1):
        lines[f"lip_lower_{i}"] = frontal_to_chart(np.array([[x0, fs.MOUTH_V - 0.78], [x0 + 0.05, fs.MOUTH_V - 1.18]]))
    return lines


@dataclass
class ChartLayout:
    """Left-half chart points: fixed rows first, then fill. Index sets refer to `points`."""

    points: list[FloatArray] = field(default_factory=list)
    eye_loop: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    mouth_upper: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    mouth_lower: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    border: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    held: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    landmarks: dict[str, int] = field(default_factory=dict)

    def add(self, pts: FloatArray, min_dist: float | None = None) -> np.ndarray:
        """Append points (optionally dropping those closer than min_dist to any already placed);
        returns the indices of the kept ones (-1 for dropped)."""
        pts = np.atleast_2d(np.asarray(pts, dtype=float)).copy()
        pts[np.abs(pts[:, 0]) < 1e-9, 0] = 0.0  # exactly on the midline, so it is not mirrored
        start = sum(len(p) for p in self.points)
        if min_dist is not None and start:
            tree = cKDTree(np.vstack(self.points))
            d, _ = tree.query(pts)
            keep = d >= min_dist
            # Also thin the new points among themselves.
            for i in range(len(pts)):
                if keep[i]:
                    close = np.linalg.norm(pts[i + 1 :] - pts[i], axis=1) < min_dist
                    keep[i + 1 :] &= ~close
            idx = np.full(len(pts), -1)
            idx[keep] = start + np.arange(keep.sum())
            pts = pts[keep]
        else:
            idx = start + np.arange(len(pts))
        if len(pts):
            self.points.append(pts)
        return idx

    def array(self) -> FloatArray:
        return np.vstack(self.points)
