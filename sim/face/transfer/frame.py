"""Bring a head of any scale and orientation into the project frame (cm, +Y up, looking along +Z,
+X = the face's own left), using its landmarks only."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.face.transfer.landmarks import SIDE_PAIRS

FloatArray = np.ndarray


@dataclass(frozen=True)
class Similarity:
    """x_project = scale * rotation @ (x - source_centre) + target_centre."""

    rotation: FloatArray
    scale: float
    source_centre: FloatArray
    target_centre: FloatArray

    def apply(self, points: FloatArray) -> FloatArray:
        return self.scale * (np.asarray(points, float) - self.source_centre) @ self.rotation.T + self.target_centre

    def invert(self, points: FloatArray) -> FloatArray:
        return (np.asarray(points, float) - self.target_centre) @ self.rotation / self.scale + self.source_centre


def landmark_axes(points: dict[str, FloatArray]) -> FloatArray:
    """Rows (left, up, forward) of the face in the points' own coordinates: up from the chin to
    the forehead centre, left from the mean of the _r -> _l pairs (made orthogonal to up), forward
    = left x up so the frame is right-handed like the project's (X left, Y up, Z forward)."""
    up = points["forehead_center"] - points["chin"]
    up = up / np.linalg.norm(up)
    pairs = [points[a] - points[b] for a, b in SIDE_PAIRS if a in points and b in points]
    left = np.mean(pairs, axis=0)
    left = left - (left @ up) * up
    left = left / np.linalg.norm(left)
    return np.stack([left, up, np.cross(left, up)])


def fit_similarity(
    source: FloatArray, target: FloatArray, initial_rotation: FloatArray | None = None
) -> Similarity:
    """Least-squares rotation + uniform scale + translation taking source points onto target
    points (Umeyama's closed form, proper rotations only)."""
    cs, ct = source.mean(axis=0), target.mean(axis=0)
    a, b = source - cs, target - ct
    u, sv, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    fix = np.diag([1.0, 1.0, d])
    rotation = u @ fix @ vt
    scale = float((sv * np.diag(fix)).sum() / (a * a).sum())
    return Similarity(rotation, scale, cs, ct)


def rotation_angle(a: FloatArray, b: FloatArray) -> float:
    """Angle in degrees of the rotation a^T b (how different two orientations are)."""
    c = (np.trace(a.T @ b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
