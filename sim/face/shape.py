"""The default face's shape: a map from the flat (u, v) chart to the skin surface in 3D.

The chart is a cylinder unrolled: u = R0 * angle around the vertical axis (cm at the front), v =
height (cm, eye line at 0). A point of the chart lands on a generalised cylinder whose horizontal
slices are half-ellipses (half width W(v), depth D(v)) hung from a midline profile Zm(v); smooth
analytic bumps and dips (brow ridge, sockets, nose, lips, chin, cheekbones) push it along the
slice's normal. Around the eye openings the skin is laid on the eyeball (the lids), around the
mouth slit the lips roll inwards and close up. Everything here is a pure function of the chart
point, so every resolution of the mesh samples the same surface (same landmarks, same regions).

Frontal coordinates (X, Y) are the base surface's x and height; anatomical places are given in
them (cm, from face-proportions.md) and turned into chart points with `chart_u`.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline


def _spline(xs: list[float], ys: list[float]) -> CubicSpline:
    """Natural cubic spline through knots given top to bottom."""
    return CubicSpline(xs[::-1], ys[::-1], bc_type="natural")

FloatArray = np.ndarray

R0 = 7.0
"""cm: chart u per radian around the head's vertical axis."""

# Midline base profile z (before features), half width and half depth of the slices, per height.
_ZM = _spline(
    [8.0, 7.0, 5.5, 4.0, 2.5, 1.2, 0.0, -2.0, -4.0, -5.5, -7.2, -9.0, -10.5, -11.9, -13.0],
    [-2.0, -1.35, -0.6, -0.2, 0.05, 0.1, -0.1, -0.2, -0.3, -0.3, -0.5, -0.9, -0.95, -1.3, -1.6],
)
_W = _spline(
    [8.0, 5.0, 2.0, -1.5, -4.0, -6.0, -8.0, -9.5, -11.0, -12.5, -14.0],
    [6.7, 6.9, 7.0, 7.05, 6.75, 6.2, 5.6, 5.2, 4.8, 4.5, 4.4],
)
_D = _spline(
    [8.0, 2.0, -2.0, -6.0, -9.5, -12.0, -14.0],
    [8.3, 7.8, 7.6, 7.3, 7.0, 6.2, 5.6],
)

SLICE_POWER = 0.8
"""Slices are (1 - cos)^p in depth: p < 1 narrows the front (nose ahead, eyes set back)."""

V_CURL = -11.9
"""Chart height below which the midline turns back under the chin (arc of radius R_CURL)."""
R_CURL = 1.6

# Eyes (frontal coordinates of the left eye; the right one mirrors it).
EYE_INNER = (1.65, -0.05)
EYE_OUTER = (4.55, 0.2)
EYE_UPPER = 0.62
"""cm: how far the upper lid margin rises above the inner-outer corner line (opening 1.1 cm)."""
EYE_LOWER = 0.46
EYE_CENTER_XY = (3.1, 0.12)
EYE_RADIUS = 1.2
LID_RADIUS = EYE_RADIUS + 0.07
"""cm: the lid margin lies on this sphere, just over the eyeball."""

EYE_PROTRUSION = 0.8
LID_SOFTNESS = 0.3
"""cm: width of the rounded fold where the lids meet the socket (the lid creases)."""

# Mouth slit (chart): centre height, corner u, half-height of the slit at the middle.
MOUTH_V = -7.2
MOUTH_X = 2.75
MOUTH_HALF_HEIGHT = 0.3
MOUTH_SQUEEZE = 0.93
"""fraction by which the lips close the chart's slit vertically in 3D."""


def half_width(v: FloatArray | float) -> FloatArray:
    """W(v): half width (cm) of the head's horizontal slice at chart height v."""
    return np.asarray(_W(v))


def chart_u(x: FloatArray | float, v: FloatArray | float) -> FloatArray:
    """The chart u whose base-surface point has frontal x = x at height v."""
    return R0 * np.arcsin(np.clip(np.asarray(x) / half_width(v), -1.0, 1.0))


def eye_curve(t: FloatArray, grow: float = 0.0) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Left eye's almond in frontal coordinates: (x, y_upper, y_lower) at t in [0, 1] from the
    inner to the outer corner. `grow` (cm) offsets it outwards, for rings of lid rows."""
    t = np.asarray(t, dtype=float)
    x = EYE_INNER[0] - 0.8 * grow + t * (EYE_OUTER[0] - EYE_INNER[0] + 1.6 * grow)
    base = EYE_INNER[1] + t * (EYE_OUTER[1] - EYE_INNER[1])
    up = np.sin(np.pi * np.clip(t, 0, 1) ** 0.85) ** 0.9
    low = np.sin(np.pi * np.clip(t, 0, 1) ** 1.15)
    return x, base + (EYE_UPPER + grow) * up + 0.25 * grow, base - (EYE_LOWER + grow) * low - 0.25 * grow


def mouth_half_height(u: FloatArray, grow: float = 0.0) -> FloatArray:
    """Chart half-height of the mouth lens at chart u (0 beyond the corners)."""
    a = chart_u(MOUTH_X, MOUTH_V) + 0.8 * grow
    s = np.clip(1.0 - (np.asarray(u) / a) ** 2, 0.0, 1.0)
    return (MOUTH_HALF_HEIGHT + grow) * np.sqrt(s)


def _g(x: FloatArray, y: FloatArray, cx: float, cy: float, sx: float, sy: float) -> FloatArray:
    return np.exp(-(((x - cx) / sx) ** 2) - ((y - cy) / sy) ** 2)


def _nose_profile(y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Nose ridge height above the base (cm) and its half-width scale, along the midline."""
    ys = np.array([1.4, 0.6, -0.5, -2.0, -3.3, -4.2, -4.75, -5.05, -5.4])
    hs = np.array([0.0, 0.12, 0.5, 1.05, 1.6, 2.05, 1.25, 0.25, 0.0])
    ws = np.array([0.7, 0.6, 0.55, 0.6, 0.75, 0.85, 0.9, 0.9, 0.9])
    order = np.argsort(ys)
    h = np.interp(y, ys[order], hs[order])
    w = np.interp(y, ys[order], ws[order])
    return h, w


def features(x: FloatArray, y: FloatArray) -> FloatArray:
    """Displacement (cm, along the base normal) of the facial relief at frontal (x, y)."""
    ax = np.abs(x)
    f = np.zeros_like(x)
    f += 0.6 * _g(ax, y, 2.7, 1.75, 1.9, 0.5)  # brow ridge
    f += 0.25 * _g(ax, y, 0.0, 1.3, 0.9, 0.7)  # glabella
    f -= 0.45 * _g(ax, y, 0.0, 0.6, 0.9, 0.5)  # nasion
    f -= 0.9 * _g(ax, y, 3.0, 0.2, 1.7, 1.0)  # eye socket
    f -= 0.45 * _g(ax, y, 1.75, 0.0, 0.55, 0.55)  # inner eye corner
    f -= 0.35 * _g(ax, y, 5.7, 2.4, 1.1, 1.4)  # temple
    f += 0.7 * _g(ax, y, 4.5, -1.7, 1.4, 0.9)  # cheekbone
    f += 0.35 * _g(ax, y, 3.4, -4.2, 1.4, 1.4)  # cheek fat
    f -= 0.2 * _g(ax, y, 2.3, -2.6, 0.8, 0.9)  # tear trough / nose-cheek junction
    # The nose's underside rises towards the wings, so it is lowest at the columella.
    h, w = _nose_profile(y + 0.3 * np.minimum(ax / 1.3, 1.2) ** 2)
    f += h * np.exp(-((ax / w) ** 2) * (1.0 + 0.3 * (ax / w) ** 2))  # bridge and tip
    f += 0.3 * _g(ax, y, 0.0, -4.05, 0.5, 0.5)  # tip lobule
    f += 0.8 * _g(ax, y, 1.3, -4.5, 0.5, 0.42)  # alar wing
    f -= 0.28 * _g(ax, y, 1.9, -4.35, 0.28, 0.5)  # alar groove (the crease round the wing)
    f += 0.2 * _g(ax, y, 0.75, -4.8, 0.45, 0.25)  # nostril sill
    f += 0.55 * _g(ax, y, 0.0, -6.2, 2.3, 0.9)  # upper lip body
    f -= 0.12 * _g(ax, y, 0.0, -5.7, 0.35, 0.5)  # philtrum groove
    f += 0.08 * _g(ax, y, 0.45, -5.8, 0.18, 0.6)  # philtral ridges
    f += 0.42 * _g(ax, y, 0.0, -6.9, 1.8, 0.3)  # upper vermilion
    f += 0.64 * _g(ax, y, 0.0, -7.65, 1.6, 0.45)  # lower lip
    f -= 0.35 * _g(ax, y, 2.8, -7.2, 0.5, 0.45)  # mouth corner dimple
    f -= 0.35 * _g(ax, y, 0.0, -8.75, 1.7, 0.4)  # chin crease (mentolabial sulcus)
    f += 0.75 * _g(ax, y, 0.0, -10.5, 1.6, 1.0)  # chin
    return f


def _ball_height(dx: FloatArray, dy: FloatArray) -> FloatArray:
    """Height (cm) of the lid sphere above the eye centre, continued steeply (C1) past 95 % of its
    radius so that a smooth max with the socket can take over there."""
    r = np.hypot(dx, dy)
    r0 = 0.95 * LID_RADIUS
    h0 = np.sqrt(LID_RADIUS**2 - r0**2)
    inside = np.sqrt(np.clip(LID_RADIUS**2 - np.minimum(r, r0) ** 2, 0.0, None))
    return np.where(r <= r0, inside, h0 - (r0 / h0) * (r - r0))


def _smooth_max(a: FloatArray, b: FloatArray, k: float) -> FloatArray:
    """max(a, b) with the corner rounded over a width k (C1): where the lids fold into the socket."""
    h = np.maximum(k - np.abs(a - b), 0.0) / k
    return np.maximum(a, b) + h * h * k / 4.0


def _smoothstep(e0: float, e1: float, x: FloatArray) -> FloatArray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def eye_weight(x: FloatArray, y: FloatArray) -> FloatArray:
    """How much the skin at frontal (x, y) lies on the eyeball (1 on the lids, 0 off the orbit)."""
    ax = np.abs(x)
    rho = np.hypot((ax - EYE_CENTER_XY[0]) / 1.5, (y - EYE_CENTER_XY[1]) / 0.62)
    return 1.0 - _smoothstep(1.45, 2.6, rho)


def squeeze_v(u: FloatArray, v: FloatArray) -> FloatArray:
    """Chart height after the lips close the slit (monotonic in v for MOUTH_SQUEEZE < 1)."""
    d = v - MOUTH_V
    lat = np.exp(-((np.abs(u) / 3.6) ** 6))
    return v - d * MOUTH_SQUEEZE * lat * np.exp(-((d / 0.9) ** 2))


def base_surface(u: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Base point (N,3), unit horizontal outward normal (N,3), frontal (x, y) (N,2)."""
    vs = squeeze_v(u, v)
    theta = u / R0
    below = vs < V_CURL
    phi = np.where(below, (V_CURL - vs) / R_CURL, 0.0)
    y = np.where(below, V_CURL - R_CURL * np.sin(phi), vs)
    zm = np.where(below, _ZM(V_CURL) - R_CURL * (1.0 - np.cos(phi)), _ZM(vs))
    w, d = _W(vs), _D(vs)
    x = w * np.sin(theta)
    z = zm - d * (1.0 - np.cos(theta)) ** SLICE_POWER
    one_c = np.maximum(1.0 - np.cos(theta), 1e-12)
    dz = d * SLICE_POWER * one_c ** (SLICE_POWER - 1.0) * np.sin(theta)
    n = np.stack([dz, np.zeros_like(x), w * np.cos(theta)], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.stack([x, y, z], axis=1), n, np.stack([x, y], axis=1)


def eye_center() -> FloatArray:
    """Left eyeball centre (3,): the ball's front stands EYE_PROTRUSION out of the socket floor."""
    cx, cy = EYE_CENTER_XY
    u = chart_u(cx, cy)
    p, n, xy = base_surface(np.array([u]), np.array([cy]))
    surf = p[0] + features(xy[:, 0], xy[:, 1])[0] * n[0]
    return np.array([cx, cy, surf[2] - LID_RADIUS + EYE_PROTRUSION])


def surface(u: FloatArray, v: FloatArray) -> FloatArray:
    """3D skin point (N,3) of chart points (u, v); exact mirror: surface(-u) = surface(u) * (-1,1,1)."""
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    sign = np.where(u < 0, -1.0, 1.0)
    au = np.abs(u)
    p, n, xy = base_surface(au, v)
    pts = p + features(xy[:, 0], xy[:, 1])[:, None] * n
    # Lids: the skin wraps over the eyeball where the ball stands out of the socket.
    ec = eye_center()
    w = eye_weight(xy[:, 0], xy[:, 1])
    pts[:, 0] = (1.0 - w) * pts[:, 0] + w * xy[:, 0]
    ball = ec[2] + _ball_height(pts[:, 0] - ec[0], xy[:, 1] - ec[1])
    pts[:, 2] = _smooth_max(pts[:, 2], ball, LID_SOFTNESS)
    # Lips roll inwards at the slit and the corners tuck in.
    gap = np.abs(v - MOUTH_V) - mouth_half_height(au)
    near = np.exp(-np.maximum(gap, 0.0) / 0.18) * np.exp(-((au / 4.0) ** 8))
    pts[:, 2] -= 0.3 * near
    pts[:, 0] *= sign
    return pts
