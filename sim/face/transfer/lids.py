"""Open the closed eyes of a head whose lids were cut along the lid line (a scan taken with the
eyes shut). The rig's rest shape is the relaxed face with the eyes open: the reference's lids
part there, its lid channels close them (AU43/45) and its expressions widen or narrow them. A head
whose lids meet at rest would look asleep in every expression, so after the cut its upper lid is
raised and its lower lid lowered until the lids part by the reference's opening, measured against
the eye's width (about a third on an adult), with the skin around them following smoothly."""

from __future__ import annotations

import numpy as np

FloatArray = np.ndarray
IntArray = np.ndarray

UPPER_SHARE = 0.75  # of the opening made by the upper lid (it moves most in a real blink)
REACH_UP = 0.55  # how far above the lid line (of the eye's width) the skin follows the upper lid
REACH_DOWN = 0.3  # and below it, the lower lid
DEPTH = 0.5  # skin further than this (of the eye's width) in front of or behind the lid line stays


def slit_sides(loop: IntArray) -> tuple[IntArray, IntArray]:
    """(upper path corner to corner, its lower copies in the same order) of a loop made by
    `openings.cut_slit` (the path, then the copies of its inner vertices in reverse)."""
    loop = np.asarray(loop, dtype=np.int64)
    n = (len(loop) + 2) // 2
    path = loop[:n]
    lower = np.r_[path[0], loop[n:][::-1], path[-1]]
    return path, lower


def open_lids(vertices: FloatArray, loop: IntArray, ratio: float, up: FloatArray) -> FloatArray:
    """The vertices with the lids of one cut eye parted by `ratio` x the eye's width at the
    middle, tapering to nothing at the corners (a sine along the lid line). Only the skin within
    REACH_UP / REACH_DOWN of the line, between the corners and near the line in depth, moves."""
    v = np.asarray(vertices, float).copy()
    path, lower = slit_sides(loop)
    a, b = v[path[0]], v[path[-1]]
    axis = b - a
    width = float(np.linalg.norm(axis))
    if width <= 0 or ratio <= 0:
        return v
    up = np.asarray(up, float) - (np.asarray(up, float) @ axis) * axis / width ** 2
    up /= np.linalg.norm(up)
    forward = np.cross(axis / width, up)
    opening = ratio * width
    t_path = (v[path] - a) @ axis / width ** 2
    order = np.argsort(t_path)
    height_path = (v[path] - a) @ up
    depth_path = (v[path] - a) @ forward
    t = (v - a) @ axis / width ** 2
    inside = (t > 0.0) & (t < 1.0)
    line_h = np.interp(t, t_path[order], height_path[order])
    line_d = np.interp(t, t_path[order], depth_path[order])
    h = (v - a) @ up - line_h
    near = inside & (np.abs((v - a) @ forward - line_d) < DEPTH * width)
    taper = np.sin(np.pi * np.clip(t, 0.0, 1.0))
    lift = np.zeros(len(v))
    above = near & (h >= 0) & (h < REACH_UP * width)
    below = near & (h < 0) & (-h < REACH_DOWN * width)
    lift[above] = UPPER_SHARE * opening * (1.0 - h[above] / (REACH_UP * width)) ** 2
    lift[below] = -(1.0 - UPPER_SHARE) * opening * (1.0 + h[below] / (REACH_DOWN * width)) ** 2
    # the lid line itself: both copies sit on it, the path takes the upper lid, the copies the lower
    lift[path] = UPPER_SHARE * opening
    lift[lower[1:-1]] = -(1.0 - UPPER_SHARE) * opening
    lift[[path[0], path[-1]]] = 0.0
    return v + (lift * taper)[:, None] * up
