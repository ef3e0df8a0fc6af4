"""The head turning on the neck: what the channels head_yaw, head_pitch and head_roll do.

The simulation runs in the head's own frame (the skin's dynamics do not care which way the head
faces), so the turn is applied afterwards to what is drawn or exported: every point of the head and
face turns rigidly about a pivot at the top of the cervical spine (the atlanto-occipital joints,
behind and below the jaw hinge), and the neck takes a share of the turn that fades from all of it
under the jaw to none at the shoulders, the way the cervical vertebrae share a real turn between
them. The same function poses the procedural face with its held head and a scanned head.

Units: a channel value of 1 is a quarter turn (90 degrees), as Live Link Face sends head rotations.
Signs, in the head's frame (+X the face's left, +Y up, +Z forward): yaw + turns the nose towards the
face's left, pitch + lifts the chin, roll + tips the top of the head towards the face's left shoulder.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

#: A channel value of 1: a quarter turn.
QUARTER_TURN = 0.5 * math.pi
#: cm, head frame: the pivot of the turn (occipital condyles on the atlas), behind and below the
#: jaw hinge (0, -4.6, -7.8) of the default face.
NECK_PIVOT = np.array([0.0, -5.5, -9.5])
#: cm: rest points at or above this height turn fully (the whole face and head lie above it) ...
FULL_TURN_Y = -13.5
#: ... and points at or below this one not at all (the neck's base, at the shoulders).
NO_TURN_Y = -22.5


def turn_weights(rest: np.ndarray, full_y: float = FULL_TURN_Y, none_y: float = NO_TURN_Y) -> np.ndarray:
    """(N,) share of the turn each rest point (N,3) takes: 1 above `full_y`, 0 below `none_y`,
    a smoothstep between (a function of the rest height only, so a seam's two sides agree)."""
    t = np.clip((np.asarray(rest, np.float64)[:, 1] - none_y) / (full_y - none_y), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def head_rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """3x3 rotation of the head for channel values (1 = a quarter turn): roll, then pitch, then yaw
    (yaw about the vertical, last, so a nod stays a nod whichever way the head faces)."""
    return Rotation.from_euler("YXZ", [yaw * QUARTER_TURN, -pitch * QUARTER_TURN,
                                       -roll * QUARTER_TURN]).as_matrix()


def state_turn(state: object) -> tuple[float, float, float]:
    """A face state's head turn (yaw, pitch, roll channel values; zeros for one without)."""
    return (float(getattr(state, "head_yaw", 0.0)), float(getattr(state, "head_pitch", 0.0)),
            float(getattr(state, "head_roll", 0.0)))


def is_turned(yaw: float, pitch: float, roll: float) -> bool:
    """Whether the angles turn the head at all (most frames do not: nothing to compute)."""
    return bool(yaw or pitch or roll)


def turn_head(points: np.ndarray, weights: np.ndarray, yaw: float, pitch: float, roll: float,
              pivot: np.ndarray = NECK_PIVOT) -> np.ndarray:
    """(N,3) points turned with the head: each point by its weight's share of the rotation (the
    rotation vector scaled by the weight) about `pivot`. A new array, same dtype; the points
    themselves when the head is not turned."""
    if not is_turned(yaw, pitch, roll):
        return points
    p = np.asarray(points)
    rel = p.astype(np.float64) - pivot
    full = head_rotation(yaw, pitch, roll)
    w = np.asarray(weights, np.float64)
    out = np.empty_like(rel)
    whole = w >= 1.0
    out[whole] = rel[whole] @ full.T
    part = ~whole
    if part.any():
        rotvec = Rotation.from_matrix(full).as_rotvec()
        out[part] = Rotation.from_rotvec(w[part, None] * rotvec[None, :]).apply(rel[part])
    return (out + pivot).astype(p.dtype, copy=False)


def turn_eye(center: np.ndarray, rotation: np.ndarray, yaw: float, pitch: float, roll: float,
             pivot: np.ndarray = NECK_PIVOT) -> tuple[np.ndarray, np.ndarray]:
    """An eyeball's centre (3,) and gaze rotation (3,3) carried by the head's turn."""
    r = head_rotation(yaw, pitch, roll)
    return (np.asarray(center, np.float64) - pivot) @ r.T + pivot, r @ rotation
