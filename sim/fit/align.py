"""Procrustes: the similarity (scale, rotation, translation) that best maps one point set onto
another in the least-squares sense (Umeyama 1991, IEEE PAMI 13(4), eqs 40-42: the SVD of the
cross-covariance, with the sign fix that keeps it a rotation, never a reflection)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Similarity:
    """x -> scale * R @ x + t. rotation (3, 3) proper; scale > 0; translation (3,) in the
    target's units."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        return self.scale * np.asarray(points, float) @ self.rotation.T + self.translation

    @property
    def angle_degrees(self) -> float:
        """The rotation's angle about its axis."""
        c = (np.trace(self.rotation) - 1.0) / 2.0
        return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def similarity(source: np.ndarray, target: np.ndarray, scale: bool = True,
               weights: np.ndarray | None = None) -> Similarity:
    """The similarity (or, with scale=False, the rigid motion) minimising
    sum_i w_i |s R source_i + t - target_i|^2. source, target: (P, 3), P >= 3 not collinear."""
    x = np.asarray(source, float)
    y = np.asarray(target, float)
    w = np.ones(len(x)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    mx, my = w @ x, w @ y
    xc, yc = x - mx, y - my
    cov = (yc * w[:, None]).T @ xc
    u, sv, vt = np.linalg.svd(cov)
    fix = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        fix[2] = -1.0
    rot = u @ np.diag(fix) @ vt
    var_x = float(w @ np.sum(xc * xc, axis=1))
    s = float(np.sum(sv * fix) / var_x) if scale and var_x > 0 else 1.0
    return Similarity(s, rot, my - s * rot @ mx)


def rms(a: np.ndarray, b: np.ndarray) -> float:
    """Root mean square distance between corresponding points (P, 3)."""
    return float(np.sqrt(np.mean(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=1))))
