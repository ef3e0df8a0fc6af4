"""Muscle models of seed 000 section 3, one function per equation, and the muscle force fields.

All equations are evaluated on the *rest* geometry once, in `muscle_field`, giving for every
channel an (N,3) force per unit activation; a step then only scales and sums these fields. Why rest
geometry: the paper's fields are defined there (Fig. 3-5 show them on the neutral face), the skin
moves a few mm against muscle lengths of 3-6 cm, so directions change by a few degrees, and a fixed
field makes the muscle term free per substep. The force stays attached to the skin point it was
computed for (a material, not a spatial, field). docs/simulation.md measures how far eq 10's
direction at the settled pose is from the precomputed one (a few degrees for the linear muscles,
checked by `tests/sim/test_muscles.py`) and why the sphincters should not be re-evaluated (a pull to a
point that skin can reach flips; zone edges are discontinuous).

Force scale reading: the paper's alpha is a per-node force, which would make a finer mesh pull harder.
We read alpha as a force per unit skin area (dyn/cm^2) and multiply it by each node's lumped area.

Placement (`place_muscles`) is in `sim.face.placement`.
"""

from __future__ import annotations

import numpy as np

from sim.model import LinearMuscle, Muscle, PatchMuscle, SheetMuscle, SphincterMuscle
from sim.rowmath import dot3

HALF_PI = 0.5 * np.pi


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", v, v))


# ---------------------------------------------------------------- linear muscle, eqs 6-13


def linear_distance(attachment: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Eq 6: l_ji = |m^A - x_i|, distance from the skull attachment to each skin point (cm)."""
    return _norm(attachment - x)


def linear_length_ratio(distance: np.ndarray, attachment: np.ndarray, insertion: np.ndarray) -> np.ndarray:
    """Eq 7: lambda_ji = l_ji / |m^A - m^I| (0 at the attachment, 1 at the insertion distance)."""
    return distance / _norm(attachment - insertion)


def linear_angle_ratio(
    x: np.ndarray, attachment: np.ndarray, insertion: np.ndarray, max_angle: float
) -> np.ndarray:
    """Eq 8: gamma_ji = phi_ji / phi_j, phi_ji the angle at m^A between the muscle vector m^A->m^I and
    m^A->x_i."""
    axis = (insertion - attachment) / _norm(insertion - attachment)
    to_x = x - attachment
    cos = np.einsum("...i,i->...", to_x, axis) / np.maximum(_norm(to_x), 1e-12)
    return np.arccos(np.clip(cos, -1.0, 1.0)) / max_angle


def linear_direction(attachment: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Eq 10: nu_ji = (m^A - x_i) / |m^A - x_i|, unit pull towards the attachment."""
    d = attachment - x
    return d / np.maximum(_norm(d), 1e-12)[..., None]


def linear_radius_ratio(radius: float, attachment: np.ndarray, insertion: np.ndarray) -> float:
    """Eq 11: delta_j = R_j / |m^A - m^I| (how far past the insertion the influence reaches, > 1)."""
    return float(radius / _norm(attachment - insertion))


def length_falloff(lam: np.ndarray, eta: float, delta: float) -> np.ndarray:
    """Eq 12 (and eq 20, its sheet twin): Theta_1(lambda).

    Branch 1, 0 <= lambda <= 1: cos((1 - lambda^eta) pi/2), rising from 0 at the attachment to 1 at
    the insertion. Branch 2, 1 < lambda <= delta: reading chosen for the scanned formula,
    cos((lambda^eta - 1) / (delta^eta - 1) * pi/2), the exponent applied to both lambda and delta so
    the fall-off reaches exactly 0 at lambda = delta. Outside [0, delta]: 0 (no influence).
    """
    lam = np.asarray(lam, dtype=np.float64)
    le = np.power(np.maximum(lam, 0.0), eta)
    inner = np.cos((1.0 - le) * HALF_PI)
    outer = np.cos((le - 1.0) / (delta**eta - 1.0) * HALF_PI)
    out = np.where(lam <= 1.0, inner, outer)
    return np.where((lam >= 0.0) & (lam <= delta), out, 0.0)


def angle_falloff(gamma: np.ndarray, max_angle: float) -> np.ndarray:
    """Eq 13: Theta_2(gamma) = cos(phi_j gamma) cos(gamma pi/2) for 0 <= gamma <= 1, else 0.

    Reading chosen: phi_j * gamma_ji is the actual angle phi_ji, so the first factor is the cosine of
    the point's angle off the muscle axis (the share of the pull along the fibres) and the second
    tapers the influence to 0 at the cone's edge."""
    g = np.asarray(gamma, dtype=np.float64)
    out = np.cos(max_angle * g) * np.cos(g * HALF_PI)
    return np.where((g >= 0.0) & (g <= 1.0), out, 0.0)


def linear_force(m: LinearMuscle, x: np.ndarray) -> np.ndarray:
    """Eq 9: f_ji = alpha_L Theta_1(lambda_ji) Theta_2(gamma_ji) nu_ji, (N,3) for skin points x (N,3);
    alpha_L is m.scale."""
    lam = linear_length_ratio(linear_distance(m.attachment, x), m.attachment, m.insertion)
    delta = linear_radius_ratio(m.radius, m.attachment, m.insertion)
    gamma = linear_angle_ratio(x, m.attachment, m.insertion, m.angle)
    w = m.scale * length_falloff(lam, m.eta, delta) * angle_falloff(gamma, m.angle)
    return w[:, None] * linear_direction(m.attachment, x)


# ---------------------------------------------------------------- sphincter muscle, eqs 14-17


def sphincter_radius(m: SphincterMuscle, x: np.ndarray) -> np.ndarray:
    """Eq 17: d_i = sqrt(y_i^2 a^2 + x_i^2 b^2) / (a b), i.e. sqrt((x/a)^2 + (y/b)^2).

    Reading chosen for the frame: x_i, y_i are the coordinates of x_i - o along the ellipse's major and
    minor unit axes (the component along their normal, into the face, is ignored), so d_i is 1 on the
    ellipse and 0 at its centre."""
    rel = x - m.center
    xi = dot3(rel, m.major_axis)
    yi = dot3(rel, m.minor_axis)
    return np.sqrt(yi**2 * m.a**2 + xi**2 * m.b**2) / (m.a * m.b)


def sphincter_falloff(d: np.ndarray) -> np.ndarray:
    """Eq 16: Theta = cos((1 - d_i) pi/2) for 0 <= d_i <= 1, else 0.

    Reading chosen: the r_i of the equation's range is d_i of eq 17 (the normalised elliptic radius),
    so the pull is strongest at the ring of fibres (d = 1) and vanishes at the centre."""
    d = np.asarray(d, dtype=np.float64)
    return np.where(d <= 1.0, np.cos((1.0 - d) * HALF_PI), 0.0)


def sphincter_direction(center: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Eq 15: nu_i = (o - x_i) / |o - x_i|, unit pull towards the centre."""
    d = center - x
    return d / np.maximum(_norm(d), 1e-12)[..., None]


def sphincter_force(m: SphincterMuscle, x: np.ndarray) -> np.ndarray:
    """Eq 14: f_i = alpha_S Theta(d_i) nu_i, (N,3); alpha_S is m.scale. With m.protrude = p (not in
    the paper) the ring also pushes out of the face: f_i = alpha_S Theta(d_i) (nu_i + p n), n the
    ellipse's normal major x minor (out of the face for a major axis towards the face's left and a
    minor axis up), so the push, like the pull, is strongest at the ring and nothing at the centre."""
    w = m.scale * sphincter_falloff(sphincter_radius(m, x))
    nu = sphincter_direction(m.center, x)
    if m.protrude:
        n = np.cross(m.major_axis, m.minor_axis)
        nu = nu + (m.protrude / float(np.linalg.norm(n))) * n[None, :]
    return w[:, None] * nu


# ---------------------------------------------------------------- sheet muscle, eqs 18-22


def sheet_direction(m: SheetMuscle) -> np.ndarray:
    """Eq 19: m_j = (m^Ac - m^Ic) / |m^Ac - m^Ic|, one pull direction for the whole sheet."""
    d = 0.5 * (m.attach1 + m.attach2) - 0.5 * (m.insert1 + m.insert2)
    return d / _norm(d)


def sheet_length_ratio(m: SheetMuscle, x: np.ndarray) -> np.ndarray:
    """Eq 21: lambda_ji = l_ji / |m^Ac - m^Ic|, l_ji the distance from x_i to the attachment line
    (the infinite line through m^A1, m^A2)."""
    a1 = m.attach1
    t = (m.attach2 - a1) / _norm(m.attach2 - a1)
    rel = x - a1
    perp = rel - np.outer(dot3(rel, t), t)
    span = _norm(0.5 * (m.attach1 + m.attach2) - 0.5 * (m.insert1 + m.insert2))
    return _norm(perp) / span


def sheet_length_ratio_limit(m: SheetMuscle) -> float:
    """Eq 22: delta_j = L_j / |m^Ac - m^Ic|."""
    span = _norm(0.5 * (m.attach1 + m.attach2) - 0.5 * (m.insert1 + m.insert2))
    return float(m.length / span)


def sheet_zone(m: SheetMuscle, x: np.ndarray) -> np.ndarray:
    """The rectangle of Fig. 5 (not numbered): a point is inside when it lies on the insertion side of
    the attachment line and within W_j/2 of the sheet's centre line, measured along the attachment
    line. 1.0 inside, 0.0 outside."""
    ac = 0.5 * (m.attach1 + m.attach2)
    ic = 0.5 * (m.insert1 + m.insert2)
    t = (m.attach2 - m.attach1) / _norm(m.attach2 - m.attach1)
    rel = x - ac
    lateral = np.abs(dot3(rel, t))
    forward = dot3(rel, ic - ac)
    return ((lateral <= 0.5 * m.width) & (forward >= 0.0)).astype(np.float64)


def sheet_falloff(lam: np.ndarray, eta: float, delta: float) -> np.ndarray:
    """Eq 20: Theta(lambda_ji), the same two-branch fall-off as eq 12 (same reading of the second
    branch), with the sheet's lambda (eq 21) and delta (eq 22)."""
    return length_falloff(lam, eta, delta)


def sheet_force(m: SheetMuscle, x: np.ndarray) -> np.ndarray:
    """Eq 18: f_ji = alpha_st Theta(lambda_ji) m_j, Theta from eq 20, restricted to the sheet's
    rectangle; alpha_st is m.scale."""
    lam = sheet_length_ratio(m, x)
    w = m.scale * sheet_falloff(lam, m.eta, sheet_length_ratio_limit(m)) * sheet_zone(m, x)
    return w[:, None] * sheet_direction(m)[None, :]


# ---------------------------------------------------------------- patch (not in seed 000)


def patch_falloff(m: PatchMuscle, x: np.ndarray) -> np.ndarray:
    """cos(d pi/2) inside the patch's ellipsoid, d = |(x - c) / semi_axes| (1 at its centre, 0 on
    and outside its surface): the same cosine taper as the sphincter's eq 16, here from the centre."""
    d = np.sqrt(np.sum(((x - m.center) / m.semi_axes) ** 2, axis=-1))
    return np.where(d < 1.0, np.cos(d * HALF_PI), 0.0)


def patch_force(m: PatchMuscle, x: np.ndarray, normal: np.ndarray | None = None) -> np.ndarray:
    """f_i = alpha_P Theta(d_i) u_i, (N,3): u the patch's fixed direction, or the skin's outward unit
    normal n_i when the direction is zero (a pressure p = alpha_P on the skin inside, so a node of
    area A_i feels p A_i n_i: a cheek puffed by the air in the mouth)."""
    w = m.scale * patch_falloff(m, x)
    if not np.any(m.direction):
        if normal is None:
            raise ValueError(f"{m.name}: a pressure patch needs the skin's normals")
        return w[:, None] * normal
    return w[:, None] * np.asarray(m.direction)[None, :]


# ---------------------------------------------------------------- fields


def muscle_force(m: Muscle, x: np.ndarray, normal: np.ndarray | None = None) -> np.ndarray:
    """Force density (dyn/cm^2, (N,3)) of one muscle part at full activation on skin points x
    (normal (N,3): the skin's outward unit normals, which pressure patches push along)."""
    if isinstance(m, LinearMuscle):
        return linear_force(m, x)
    if isinstance(m, SphincterMuscle):
        return sphincter_force(m, x)
    if isinstance(m, SheetMuscle):
        return sheet_force(m, x)
    if isinstance(m, PatchMuscle):
        return patch_force(m, x, normal)
    raise TypeError(f"not a muscle: {m!r}")


def muscle_field(parts: tuple[Muscle, ...], x: np.ndarray, area: np.ndarray,
                 normal: np.ndarray | None = None) -> np.ndarray:
    """Nodal force (dyn, (N,3)) of one channel at activation 1: the sum of its parts' force densities
    times each node's lumped area (cm^2)."""
    out = np.zeros_like(x)
    for m in parts:
        out += muscle_force(m, x, normal)
    return out * area[:, None]
