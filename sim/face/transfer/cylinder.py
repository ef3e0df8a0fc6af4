"""Seed 003 section 3.1: the cylinder a face mask is projected on before it is flattened.

A cylinder is (origin G, direction d, radius r). Following the paper, one coordinate of d is held
fixed (`Z0` in the paper) so the direction cannot collapse to zero; the other two are the free
unknowns alpha, beta. The paper fixes z; in this project's frame the face's natural axis is +Y
(up), so we fix the Y component to 1 and let alpha, beta be the X and Z components. The energy
(eq 1) and its gradient (eqs 2-7) are written for any fixed axis.

Parameter vector everywhere: x = (Gx, Gy, Gz, alpha, beta, r).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

FloatArray = np.ndarray

_BASIS = np.eye(3)


@dataclass(frozen=True)
class Cylinder:
    """A fitted cylinder. origin (3,) lies on the axis; axis (3,) is unit; radius in the input's
    units. `residual_rms` is the RMS distance of the fitted points from the surface and
    `iterations` the conjugate-gradient iterations used (both for the user's report)."""

    origin: FloatArray
    axis: FloatArray
    radius: float
    residual_rms: float = 0.0
    iterations: int = 0

    def distances(self, points: FloatArray) -> FloatArray:
        """Signed distance of each point from the cylinder surface (positive outside)."""
        w = np.asarray(points, float) - self.origin
        radial = w - np.outer(w @ self.axis, self.axis)
        return np.linalg.norm(radial, axis=1) - self.radius


def _free_axes(fixed: int) -> tuple[int, int]:
    free = [k for k in range(3) if k != fixed]
    return free[0], free[1]


def direction(alpha: float, beta: float, fixed: int = 1, z0: float = 1.0) -> FloatArray:
    """The (unnormalised) direction d with coordinate `fixed` = Z0 and the others alpha, beta."""
    a, b = _free_axes(fixed)
    d = np.empty(3)
    d[a], d[b], d[fixed] = alpha, beta, z0
    return d


def _residuals(
    x: FloatArray, points: FloatArray, fixed: int, z0: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """GP_i, d, GP_i ^ d and f_i = |GP_i ^ d|^2 - r^2 |d|^2, shared by eq 1 and eqs 2-7."""
    g, r = x[:3], x[5]
    d = direction(x[3], x[4], fixed, z0)
    gp = points - g
    c = np.cross(gp, d)
    f = np.einsum("ij,ij->i", c, c) - r * r * (d @ d)
    return gp, d, c, f


def cylinder_energy(x: FloatArray, points: FloatArray, fixed: int = 1, z0: float = 1.0) -> float:
    """Seed 003 eq 1: E = sum_i (|GP_i ^ d|^2 - r^2 |d|^2)^2.

    |GP ^ d| / |d| is the distance of P from the axis, so each term is |d|^4 (dist^2 - r^2)^2: zero
    when P lies on the cylinder. Read literally: no normalisation of d is applied (the fixed
    coordinate keeps |d| >= |Z0|)."""
    _, _, _, f = _residuals(np.asarray(x, float), points, fixed, z0)
    return float(f @ f)


def cylinder_gradient(
    x: FloatArray, points: FloatArray, fixed: int = 1, z0: float = 1.0
) -> FloatArray:
    """Seed 003 eqs 2-7, the analytic gradient of eq 1 with respect to (x, y, z, alpha, beta, r).

    eqs 2-4:  dE/dG_k   = -4 sum f_i <GP_i ^ d | e_k ^ d>
    eqs 5-6:  dE/dalpha =  4 sum f_i (<GP_i ^ d | GP_i ^ e_a> - r^2 <d | e_a>), e_a the axis alpha
              moves (same for beta); the scan doubles the parentheses around f_i, read as one.
    eq 7:     dE/dr     = -4 sum |d|^2 r f_i
    with f_i = |GP_i ^ d|^2 - r^2 |d|^2."""
    x = np.asarray(x, float)
    gp, d, c, f = _residuals(x, points, fixed, z0)
    r = x[5]
    grad = np.empty(6)
    for k in range(3):
        grad[k] = -4.0 * f @ (c @ np.cross(_BASIS[k], d))
    for slot, k in zip((3, 4), _free_axes(fixed)):
        e = _BASIS[k]
        grad[slot] = 4.0 * f @ (np.einsum("ij,ij->i", c, np.cross(gp, e)) - r * r * (d @ e))
    grad[5] = -4.0 * (d @ d) * r * f.sum()
    return grad


def _initial_circle(points: FloatArray, axis: FloatArray) -> tuple[FloatArray, float]:
    """Algebraic (Kasa) circle fit of the points seen along `axis`: a starting cylinder that is not
    orthogonal to the answer, as the paper asks of its user."""
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    p = np.stack([points @ e1, points @ e2], axis=1)
    a = np.column_stack([2 * p, np.ones(len(p))])
    b = (p * p).sum(axis=1)
    (cx, cy, c0), *_ = np.linalg.lstsq(a, b, rcond=None)
    radius = float(np.sqrt(max(c0 + cx * cx + cy * cy, 1e-12)))
    centre = cx * e1 + cy * e2 + (points.mean(axis=0) @ axis) * axis
    return centre, radius


def fit_cylinder(points: FloatArray, fixed: int = 1, max_iter: int = 2000) -> Cylinder:
    """Fit a cylinder to `points` (n, 3) by minimising eq 1 with conjugate gradients (eqs 2-7).

    The points are centred and scaled to unit RMS first so one tolerance serves every mesh unit;
    alpha and beta are unchanged by that, G and r are mapped back afterwards."""
    points = np.asarray(points, float)
    if len(points) < 6:
        raise ValueError(f"need at least 6 points to fit a cylinder, got {len(points)}")
    centre = points.mean(axis=0)
    scale = float(np.sqrt(((points - centre) ** 2).sum(axis=1).mean()))
    if scale <= 0:
        raise ValueError("cannot fit a cylinder to coincident points")
    q = (points - centre) / scale
    g0, r0 = _initial_circle(q, _BASIS[fixed])
    x0 = np.array([*g0, 0.0, 0.0, r0])
    res = minimize(
        cylinder_energy, x0, args=(q, fixed), jac=cylinder_gradient, method="CG",
        options={"maxiter": max_iter, "gtol": 1e-9},
    )
    x = res.x
    d = direction(x[3], x[4], fixed)
    axis = d / np.linalg.norm(d)
    g = x[:3]
    g = g + ((q.mean(axis=0) - g) @ axis) * axis  # slide G along the axis to the points' level
    cyl = Cylinder(centre + scale * g, axis, abs(float(x[5])) * scale)
    rms = float(np.sqrt(np.mean(cyl.distances(points) ** 2)))
    return Cylinder(cyl.origin, cyl.axis, cyl.radius, rms, int(res.nit))
