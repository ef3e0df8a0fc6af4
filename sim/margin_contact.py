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

from collections.abc import Callable

import numba
import numpy as np

from sim.model import FaceMesh

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


ORDER_FRACTION = 0.25  # a margin vertex keeps at least this share of its rest spacing (along x)
# from the next one along the row (the implicit solve only)


def margin_order(mesh: FaceMesh, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Order constraints along each margin row, as margin_pairs gives its pairs but on x: vertex a
    = row[k + 1] stays at least ORDER_FRACTION of its rest spacing beyond b0 = b1 = row[k] in the
    row's direction (sign +-1)."""
    from sim.smoothness import margin_rows

    try:
        m = margin_rows(mesh)
    except (AttributeError, KeyError, IndexError, ValueError):
        m = {}
    out = []
    tri = np.asarray(mesh.triangles)
    for row in m.values():
        s = 1.0 if rest[row[-1], 0] > rest[row[0], 0] else -1.0
        for a, b in zip(row[1:], row[:-1]):
            gap = s * (rest[a, 0] - rest[b, 0])
            if gap > 0.0:
                out.append((int(a), int(b), int(b), 0.0, s, ORDER_FRACTION * gap, 1.0, 1.0))
        for end, side in ((row[0], -s), (row[-1], s)):  # the skin beyond each corner stays beyond it
            touch = np.unique(tri[(tri == end).any(axis=1)].ravel())
            for v in touch:
                gap = side * (rest[v, 0] - rest[end, 0])
                if v != end and gap > 0.0:
                    out.append((int(v), int(end), int(end), 0.0, side, ORDER_FRACTION * gap, 1.0, 1.0))
    if not out:
        return np.zeros((0, 3), np.int64), np.zeros(0), np.zeros((0, 4))
    return (np.array([r[:3] for r in out], dtype=np.int64), np.array([r[3] for r in out]),
            np.array([r[4:] for r in out], dtype=np.float64))


def margin_rings(mesh: FaceMesh, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first ring of skin outside each margin stays on its side of it: a vertex joined by an edge
    to an upper margin (and on neither margin) keeps at least ORDER_FRACTION of its rest height
    above that margin at its x, and one by a lower margin as far below it; as margin_pairs gives its
    pairs, with the vertex's own margin as the opposite one."""
    from sim.smoothness import margin_rows

    try:
        m = margin_rows(mesh)
    except (AttributeError, KeyError, IndexError, ValueError):
        m = {}
    if not m:
        return np.zeros((0, 3), np.int64), np.zeros(0), np.zeros((0, 4))
    on_margin = np.zeros(len(rest), bool)
    on_margin[np.concatenate(list(m.values()))] = True
    tri = np.asarray(mesh.triangles)
    out = []
    for name, row in m.items():
        sign = 1.0 if name.endswith("upper") else -1.0
        mark = np.zeros(len(rest), bool)
        mark[row] = True
        touch = tri[mark[tri].any(axis=1)].ravel()
        ring = np.unique(touch[~on_margin[touch]])
        lo, hi = rest[row, 0].min(), rest[row, 0].max()
        beyond = np.maximum(lo - rest[ring, 0], rest[ring, 0] - hi)  # > 0 past a corner
        y = np.interp(rest[ring, 0], np.sort(rest[row, 0]), rest[row[np.argsort(rest[row, 0])], 1])
        ring = ring[beyond < np.abs(rest[ring, 1] - y)]  # past a corner only if more above or below it
        for a, b0, b1, w, _, _, _, _ in _pairs(rest, np.concatenate([[-1], ring, [-1]]), row, sign, (1.0, 1.0), 0.0) \
                if len(ring) else []:
            y = (1.0 - w) * rest[b0, 1] + w * rest[b1, 1]
            gap = sign * (rest[a, 1] - y)
            if gap > 0.0:
                out.append((a, b0, b1, w, sign, ORDER_FRACTION * gap, 1.0, 1.0))
    if not out:
        return np.zeros((0, 3), np.int64), np.zeros(0), np.zeros((0, 4))
    return (np.array([r[:3] for r in out], dtype=np.int64), np.array([r[3] for r in out]),
            np.array([r[4:] for r in out], dtype=np.float64))


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


CORRECTION_CUTOFF = 0.01  # a pair's position correction keeps the vertices it moves by at least this
# fraction of its largest entry (the rest is carried by the force in the next solve, see below)
SWEEPS = 12  # projected Gauss-Seidel sweeps over the pairs in contact per substep (warm-started)


class SolvedContact:
    """The lid and lip contact of the implicit integrator: a force in the global solve whose size is
    solved for on the pairs in contact (a Schur complement), not a projection after it.

    One implicit substep solves A x' = b with A fixed, the same matrix for x, y and z. A pair's gap is
    linear in the vertical positions, c = J x'_y - g (J: +-1 at vertex a, -+(1 - w), -+w at b0, b1),
    so with a force J^T lam added to b the gaps become c0 + S lam, S = J A^-1 J^T: P x P, computed
    once with Z = A^-1 J^T. Each substep
      1. adds the last substep's contact force J^T lam to the right-hand side and solves;
      2. finds lam >= 0 with c0 + S dlam >= 0 and lam (c0 + S dlam) = 0 (a linear complementarity
         problem on the few dozen pairs, projected Gauss-Seidel from the last lam);
      3. moves the vertices by Z dlam, keeping in each column of Z only the entries of at least
         CORRECTION_CUTOFF of its largest (the vertices near the pair; the far ones get the change
         through step 1 of the next substep).
    The velocity is then (x' - x) / h, so contact is inelastic. At rest in contact dlam = 0 and the
    pose is exactly the constrained equilibrium of the global equation: the contact force reaches
    every vertex through the solve, unlike the projection, whose neighbours never saw it. The force
    is shared between the two margins by the skin's own compliance (the give factors of the
    projection are not used)."""

    def __init__(self, idx: np.ndarray, w: np.ndarray, sg: np.ndarray, dim: np.ndarray, free: np.ndarray,
                 n: int, solve: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        p = len(idx)
        self.idx, self.w, self.sg, self.dim = idx, w, sg, np.asarray(dim, dtype=np.int64)
        self.lam = np.zeros(p)
        pos = np.full(n, -1, dtype=np.int64)
        pos[free] = np.arange(len(free))
        jt = np.zeros((len(free), p))  # J^T on the free vertices (held ones never move)
        ft = np.zeros((len(free), p))  # the force's direction: J^T with the give factors
        for k in range(p):
            s, ga, gb = sg[k, 0], sg[k, 2], sg[k, 3]
            for vert, c, g in ((idx[k, 0], s, ga), (idx[k, 1], -s * (1.0 - w[k]), gb), (idx[k, 2], -s * w[k], gb)):
                if pos[vert] >= 0:
                    jt[pos[vert], k] += c
                    ft[pos[vert], k] += c * g
        z = np.zeros_like(jt)
        out = np.zeros((len(free), 3))
        for k in range(0, p, 3):  # three columns per solve, as the solver takes them
            cols = min(3, p - k)
            b = np.zeros((len(free), 3))
            b[:, :cols] = ft[:, k:k + cols]
            solve(b, out)
            z[:, k:k + cols] = out[:, :cols]
        # x, y and z solve apart: constraints on different coordinates do not see each other
        self.schur = np.ascontiguousarray(np.where(self.dim[:, None] == self.dim[None, :], jt.T @ z, 0.0))
        ptr, vert, val = [0], [], []
        for k in range(p):
            col = z[:, k]
            keep = np.flatnonzero(np.abs(col) >= CORRECTION_CUTOFF * np.abs(col).max()) if p else []
            vert.append(free[keep])
            val.append(col[keep])
            ptr.append(ptr[-1] + len(keep))
        self.ptr = np.array(ptr, dtype=np.int64)
        self.vert = np.concatenate(vert).astype(np.int64) if p else np.zeros(0, np.int64)
        self.val = np.concatenate(val) if p else np.zeros(0)
        self._work = np.zeros((3, p))
        self._cand = np.zeros(p, dtype=np.int64)

    def add_force(self, rhs: np.ndarray) -> None:
        """rhs[:, 1] += J^T lam: the contact force of the last substep (step 1)."""
        _contact_force(rhs, self.idx, self.w, self.sg, self.dim, self.lam)

    def resolve(self, x: np.ndarray) -> None:
        """Steps 2 and 3 on the solved positions x (all vertices, in place)."""
        _contact_resolve(x, self.idx, self.w, self.sg, self.dim, self.lam, self.schur, self.ptr, self.vert, self.val,
                         self._work, self._cand, SWEEPS)


@numba.njit(**KERNEL)
def _contact_force(rhs, idx, w, sg, dim, lam):  # type: ignore[no-untyped-def]
    """rhs += J^T lam (held vertices get a force too; the solve never reads their rows)."""
    for k in range(idx.shape[0]):
        f = lam[k] * sg[k, 0]
        d = dim[k]
        if f != 0.0:
            rhs[idx[k, 0], d] += f * sg[k, 2]
            rhs[idx[k, 1], d] -= f * (1.0 - w[k]) * sg[k, 3]
            rhs[idx[k, 2], d] -= f * w[k] * sg[k, 3]


@numba.njit(**KERNEL)
def _contact_resolve(x, idx, w, sg, dim, lam, schur, ptr, vert, val, work, cand, sweeps):  # type: ignore[no-untyped-def]
    """The complementarity solve for the change of lam on the pairs in contact (violated or pressed
    last substep), projected Gauss-Seidel on the Schur complement; pairs found violated after the
    sweeps join the set and the sweeps run again (at most three rounds); then x += Z dlam."""
    p = idx.shape[0]
    c, dl, r = work[0], work[1], work[2]
    for k in range(p):
        d = dim[k]
        c[k] = sg[k, 0] * (x[idx[k, 0], d] - (1.0 - w[k]) * x[idx[k, 1], d] - w[k] * x[idx[k, 2], d]) - sg[k, 1]
        dl[k] = 0.0
    nc = 0
    for k in range(p):
        if lam[k] > 0.0 or c[k] < 0.0:
            cand[nc] = k
            nc += 1
    for _ in range(3):
        for _ in range(sweeps):
            for ii in range(nc):
                k = cand[ii]
                res = c[k]
                for jj in range(nc):
                    res += schur[k, cand[jj]] * dl[cand[jj]]
                new = lam[k] + dl[k] - res / schur[k, k]
                dl[k] = (new if new > 0.0 else 0.0) - lam[k]
        grown = False
        for k in range(p):
            r[k] = c[k]
            for jj in range(nc):
                r[k] += schur[k, cand[jj]] * dl[cand[jj]]
        for k in range(p):
            if r[k] < 0.0 and lam[k] + dl[k] == 0.0:
                inside = False
                for jj in range(nc):
                    if cand[jj] == k:
                        inside = True
                if not inside:
                    cand[nc] = k
                    nc += 1
                    grown = True
        if not grown:
            break
    for ii in range(nc):
        k = cand[ii]
        d = dl[k]
        if d != 0.0:
            lam[k] += d
            e = dim[k]
            for q in range(ptr[k], ptr[k + 1]):
                x[vert[q], e] += val[q] * d
