"""Contact between the two lids of each eye and between the two lips: a closing margin stops where
it meets the other one instead of passing through it (explicit RK2 only, see below).

Each margin vertex (corners excluded) is paired at rest with the point of the opposite margin at
the same frontal-plane x (linear between the two vertices that bracket it), both ways (upper
vertices against the lower margin and lower ones against the upper). After every substep a pair
that has crossed is projected back apart along the vertical, the correction shared by inverse
mass (a position-based constraint, Mueller et al. 2007, one Gauss-Seidel sweep), and the part of
the pair's relative velocity that drives them further into each other is removed, as the eyeball
contact does. A lower lid yields only LOWER_LID_GIVE as much as the upper one (the upper lid does
the closing). The constraint is one-sided and never acts at rest: a pair that overlaps at rest
(lips drawn closed on some meshes) may keep that overlap, no more; closed lids may overlap by
LID_OVERLAP. Cost: a few dozen pairs per
face, nothing next to the springs.

Why not in the implicit integrator (`sim.implicit`, the 3k and 12k faces): a projection after its
global solve has a false fixed point (the solve spreads the held vertices' push over their
neighbours; at 3k vertices closed lids stopped 5 mm down instead of 8); the contact as a
projective-dynamics term in the matrix made every margin vertex heavier (AU9 reached its lip lift
seconds later), and as an explicit penalty it left the closed lids 1.5 mm open and folded.
"""

from __future__ import annotations

import numba
import numpy as np

from sim.model import FaceMesh
from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start

KERNEL = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")


LID_OVERLAP = 0.03  # cm the closed lids may overlap: edge to edge, a hairline of the eyeball showed
# between them in renders (the lids meet at an angle in depth)
LOWER_LID_GIVE = 0.1  # how far a lower lid yields to the upper one, relative to an equal mass:
# the upper lid does the closing; a lower margin pushed down as far folded its first ring of skin


def _pairs(rest: np.ndarray, a_row: np.ndarray, b_row: np.ndarray, sign: float,
           give: tuple[float, float], overlap: float) -> list[tuple]:  # type: ignore[type-arg]
    order = np.argsort(rest[b_row, 0], kind="stable")
    bx, b = rest[b_row[order], 0], b_row[order]
    out = []
    for i in a_row[1:-1]:
        x = rest[i, 0]
        k = int(np.clip(np.searchsorted(bx, x) - 1, 0, len(b) - 2))
        span = bx[k + 1] - bx[k]
        w = float(np.clip((x - bx[k]) / span, 0.0, 1.0)) if span > 0 else 0.0
        y = (1.0 - w) * rest[b[k], 1] + w * rest[b[k + 1], 1]
        out.append((int(i), int(b[k]), int(b[k + 1]), w, sign, min(0.0, sign * (rest[i, 1] - y)) - overlap, *give))
    return out


def margin_pairs(mesh: FaceMesh, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The contact pairs of the lids and lips: (idx (P,3) int64 vertex a and the two vertices b0, b1
    of the opposite margin, w (P,) float the weight of b1, sign_gap (P,2) float: +1 when a is on the
    upper margin else -1, the least allowed signed gap (cm, <= 0: the overlap at rest), and how much
    a and the opposite margin yield (factors on their inverse masses)).
    Empty arrays for a mesh without eye and mouth loops."""
    from sim.smoothness import margin_rows

    rows: list[tuple] = []  # type: ignore[type-arg]
    try:
        m = margin_rows(mesh)
    except (AttributeError, KeyError, IndexError, ValueError):
        m = {}
    for up, low, g in (("eye_l_upper", "eye_l_lower", LOWER_LID_GIVE), ("eye_r_upper", "eye_r_lower", LOWER_LID_GIVE),
                       ("lip_upper", "lip_lower", 1.0)):
        if up in m and low in m and len(m[up]) > 2 and len(m[low]) > 2:
            ov = LID_OVERLAP if up.startswith("eye") else 0.0
            rows += _pairs(rest, m[up], m[low], 1.0, (1.0, g), ov) + _pairs(rest, m[low], m[up], -1.0, (g, 1.0), ov)
    if not rows:
        return np.zeros((0, 3), np.int64), np.zeros(0), np.zeros((0, 4))
    idx = np.array([r[:3] for r in rows], dtype=np.int64)
    w = np.array([r[3] for r in rows], dtype=np.float64)
    sg = np.array([r[4:] for r in rows], dtype=np.float64)
    return idx, w, sg


@numba.njit(**KERNEL)
def margin_contact(x, v, idx, w, sg, inv_mass):  # type: ignore[no-untyped-def]
    """Projects crossed margin pairs apart along y and removes their closing relative velocity."""
    for k in range(idx.shape[0]):
        a, b0, b1 = idx[k, 0], idx[k, 1], idx[k, 2]
        wb = w[k]
        s = sg[k, 0]
        ma, m0, m1 = inv_mass[a] * sg[k, 2], inv_mass[b0] * sg[k, 3], inv_mass[b1] * sg[k, 3]
        denom = ma + (1.0 - wb) * (1.0 - wb) * m0 + wb * wb * m1
        if denom <= 0.0:
            continue
        c = s * (x[a, 1] - (1.0 - wb) * x[b0, 1] - wb * x[b1, 1]) - sg[k, 1]
        if c < 0.0:
            lam = -c / denom
            x[a, 1] += lam * s * ma
            x[b0, 1] -= lam * s * (1.0 - wb) * m0
            x[b1, 1] -= lam * s * wb * m1
            cv = s * (v[a, 1] - (1.0 - wb) * v[b0, 1] - wb * v[b1, 1])
            if cv < 0.0:
                lam = -cv / denom
                v[a, 1] += lam * s * ma
                v[b0, 1] -= lam * s * (1.0 - wb) * m0
                v[b1, 1] -= lam * s * wb * m1
