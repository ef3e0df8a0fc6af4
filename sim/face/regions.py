"""The default face's jaw weights and named regions, from chart and rest positions.

Both are functions of where a vertex sits on the face (not of its index), so they name the same
anatomy at every resolution.
"""

from __future__ import annotations

import numpy as np

from sim.face import chart as fc
from sim.face import shape as fs

FloatArray = np.ndarray


def _smoothstep(e0: float, e1: float, x: FloatArray) -> FloatArray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def jaw_weights(uv: FloatArray) -> FloatArray:
    """1 on the lower lip and chin, 0 on the upper lip and above; below the mouth line it ramps
    in more slowly the further out from the mouth, and fades out towards the ears."""
    au, v = np.abs(uv[:, 0]), uv[:, 1]
    a = float(fs.chart_u(fs.MOUTH_X, fs.MOUTH_V))
    below = fs.MOUTH_V - v
    ramp = 0.2 + 1.1 * np.maximum(au - 0.55 * a, 0.0)
    w = _smoothstep(0.0, 1.0, below / ramp)
    w *= 1.0 - _smoothstep(fc.U_SIDE - 3.6, fc.U_SIDE - 0.2, au)
    w[below <= 0.0] = 0.0
    return w


def face_regions(verts: FloatArray, uv: FloatArray, jaw: FloatArray) -> dict[str, np.ndarray]:
    """Named boolean masks (N,): forehead, glabella, brow_l/r, temple_l/r, upper_lid_l/r,
    lower_lid_l/r, nose, upper_lip, lower_lip, cheek_l/r, chin, jaw. Left = +x."""
    x, y = verts[:, 0], verts[:, 1]
    ax, v = np.abs(x), uv[:, 1]
    ex, ey = fs.EYE_CENTER_XY
    (ix, iy), (ox, oy) = fs.EYE_INNER, fs.EYE_OUTER
    rho_e = np.hypot((ax - ex) / 1.5, (y - ey) / 0.62)
    eye_line = iy + (ax - ix) * (oy - iy) / (ox - ix)
    upper_lid = (rho_e < 2.2) & (y >= eye_line) & (y < 1.35)
    lower_lid = (rho_e < 2.0) & (y < eye_line)
    brow = (ax > 0.7) & (ax < 5.5) & (y >= 1.0) & (y < 2.8) & ~upper_lid
    forehead = y >= 2.8
    glabella = (ax <= 0.7) & (y >= 0.9) & (y < 2.8)
    temple = (ax >= 5.0) & (y >= -0.5) & ~forehead & ~brow
    nose_w = np.interp(y, [-5.1, -4.4, -2.5, 0.8], [1.5, 2.1, 1.0, 0.75])
    nose = (ax < nose_w) & (y > -5.1) & (y < 0.8)
    a = float(fs.chart_u(fs.MOUTH_X, fs.MOUTH_V))
    lips_w = np.abs(uv[:, 0]) < a + 0.5
    upper_lip = lips_w & (v >= fs.MOUTH_V) & (y <= -5.0) & ~nose
    lower_lip = lips_w & (v < fs.MOUTH_V) & (y > -8.75)
    chin = (y <= -8.75) & (ax < 2.8)
    cheek = (ax > 1.3) & (ax < 6.3) & (y < eye_line - 0.4) & (y > -8.0) & ~lower_lid & ~nose & ~upper_lip & ~lower_lip
    jaw_r = (jaw > 0.05) & ~lower_lip & ~chin
    left, right = x > 0, x < 0
    return {
        "forehead": forehead, "glabella": glabella,
        "brow_l": brow & left, "brow_r": brow & right,
        "temple_l": temple & left, "temple_r": temple & right,
        "upper_lid_l": upper_lid & left, "upper_lid_r": upper_lid & right,
        "lower_lid_l": lower_lid & left, "lower_lid_r": lower_lid & right,
        "nose": nose, "upper_lip": upper_lip, "lower_lip": lower_lip,
        "cheek_l": cheek & left, "cheek_r": cheek & right,
        "chin": chin, "jaw": jaw_r,
    }
