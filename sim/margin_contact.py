"""Contact between the two lids of each eye and between the two lips: a closing margin stops where
it meets the other one instead of passing through it. Two forms, one per integrator.

Explicit RK2 (`margin_contact`, the coarse default face and transferred heads): each margin vertex
(corners excluded) is paired at rest with the point of the opposite margin at the same frontal-plane
x (linear between the two vertices that bracket it), both ways (upper vertices against the lower
margin and lower ones against the upper). After every substep a pair that has crossed is projected
back apart along the vertical, the correction shared by inverse mass (a position-based constraint,
Mueller et al. 2007, one Gauss-Seidel sweep), and the part of the pair's relative velocity that
drives them further into each other is removed, as the eyeball contact does. A lower lid yields
only LOWER_LID_GIVE as much as the upper one (the upper lid does the closing). The constraint is
one-sided and never acts at rest: a pair that overlaps at rest (lips drawn closed on some meshes)
may keep that overlap, no more; closed lids may overlap by LID_OVERLAP. Cost: a few dozen pairs per
face, nothing next to the springs.

Implicit integrator (`SolvedContact`, `sim.implicit`, the 3k and 12k faces): the same pairs, but
solved with the step as forces of unknown size (a linear complementarity problem on the Schur
complement of the step's fixed matrix, warm-started; see the class), re-paired along the opposite
margin at the current x every substep, plus two kinds of constraint the finer meshes need: each
margin row keeps its order along x, and the first ring of skin outside a margin (or a corner) stays
on its side of it, re-paired along its own margin (`margin_order`, `margin_rings`; both keep
ORDER_FRACTION of the rest spacing). With the margin rows' bending term
(`margin_bending`) that is what keeps closed lids and pressed lips clean there. What failed before:
a projection after the global solve has a false fixed point (the solve spreads the projected
vertices' push over their neighbours, which never see it; at 3k vertices closed lids stopped 5 mm
down instead of 8); the contact as a projective-dynamics term in the matrix made every margin
vertex heavier (AU9 reached its lip lift seconds later); as an explicit penalty it left the closed
lids 1.5 mm open and folded. With the contact alone (pairs fixed at rest) the lids still crossed by
0.7 mm at 12k vertices (they slide along each other by up to 2 mm as they close), the skin behind
a stopped margin rolled past it (upper lid, 12k: 34 folded triangles) and the upper margin next to
the inner canthus stepped past its neighbours; with the first ring paired at rest, a ring vertex
sliding past its segment folded the outer upper lid when AU45 was dialled in over 10 frames; pressed
lips buckled into an alternating zig-zag of ~1 mm at 3k vertices, with RK2 as well, which no contact
removes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numba
import numpy as np

from sim.model import FaceMesh
from sim.numba_start import prepare_blas_check

if TYPE_CHECKING:
    import scipy.sparse as sp

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start

KERNEL = dict(cache=True, fastmath=False, nogil=True, error_model="numpy")


LID_OVERLAP = 0.03  # cm the closed lids may overlap: edge to edge, a hairline of the eyeball showed
# between them in renders (the lids meet at an angle in depth)
LOWER_LID_GIVE = 0.1  # how far a lower lid yields to the upper one, relative to an equal mass:
# the upper lid does the closing; a lower margin pushed down as far folded its first ring of skin


def _rows(mesh: FaceMesh) -> dict[str, np.ndarray]:
    """sim.smoothness.margin_rows, or none for a mesh without eye and mouth loops."""
    from sim.smoothness import margin_rows

    try:
        return margin_rows(mesh)
    except (AttributeError, KeyError, IndexError, ValueError):
        return {}


def _pairs(rest: np.ndarray, a_row: np.ndarray, b_row: np.ndarray, sign: float,
           give: tuple[float, float], overlap: float, ends: bool = False) -> list[tuple]:  # type: ignore[type-arg]
    """Each vertex of a_row (its two ends too only if `ends`) against the point of b_row at its rest
    x: (a, b0, b1, w, sign, least gap, give of a, give of b)."""
    order = np.argsort(rest[b_row, 0], kind="stable")
    bx, b = rest[b_row[order], 0], b_row[order]
    out = []
    for i in (a_row if ends else a_row[1:-1]):
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
    rows: list[tuple] = []  # type: ignore[type-arg]
    m = _rows(mesh)
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


ORDER_FRACTION = 0.5  # the implicit solve's row order and first rings: a margin vertex keeps at
# least this share of its rest spacing (along x) from the next one, a first-ring vertex this share
# of its rest height off its margin


def margin_order(mesh: FaceMesh, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Order constraints along each margin row, as margin_pairs gives its pairs but on x: vertex a
    = row[k + 1] stays at least ORDER_FRACTION of its rest spacing beyond b0 = b1 = row[k] in the
    row's direction (sign +-1)."""
    m = _rows(mesh)
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
    m = _rows(mesh)
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
        for a, b0, b1, w, _, _, _, _ in _pairs(rest, ring, row, sign, (1.0, 1.0), 0.0, ends=True):
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


def margin_bending(mesh: FaceMesh, rest: np.ndarray, springs: np.ndarray, k: np.ndarray,
                   lids: float, lips: float) -> sp.csr_matrix:
    """(N, N) the bending term of the margin rows for the implicit integrator's matrix: the energy
    sum_k k_b |u_{k-1} - 2 u_k + u_{k+1}|^2 / 2 of the displacements u from the (jaw-turned) rest
    shape along each lid and lip row, k_b = lids or lips (SkinParams.lid_bending, lip_bending)
    times the mean stiffness k of the row's edge springs. It is zero for a translation and for the turn with the
    jaw, small for a displacement smooth along the row, and stiffest against the alternating one: a margin
    pressed along its length (the lips in AU24, a closing lid) buckled into that zig-zag at 3k
    vertices, a mode the mesh has and the tissue has not (the lips' and lids' fibres run along the
    margin). RK2 (the coarse default face, whose rows do not buckle) goes without it: at resolution
    0 it would raise the stable step's omega_max by a third."""
    import scipy.sparse as sp  # here, not at the top: the RK2 live path must not import it (start-up)

    rows = _rows(mesh)
    n = len(rest)
    edge_k = {(int(min(a, b)), int(max(a, b))): float(kk) for (a, b), kk in zip(springs, k)}
    ri, ci, vals = [], [], []
    for name, row in rows.items():
        ks = [edge_k.get((int(min(a, b)), int(max(a, b))), 0.0) for a, b in zip(row[:-1], row[1:])]
        kb = (lips if name.startswith("lip") else lids) * float(np.mean(ks)) if ks else 0.0
        for j in range(1, len(row) - 1):
            trip = (row[j - 1], row[j], row[j + 1])
            for a, ca in zip(trip, (1.0, -2.0, 1.0)):
                for b, cb in zip(trip, (1.0, -2.0, 1.0)):
                    ri.append(int(a))
                    ci.append(int(b))
                    vals.append(kb * ca * cb)
    return sp.coo_matrix((vals, (ri, ci)), shape=(n, n)).tocsr()


CORRECTION_CUTOFF = 0.05  # a contact's position correction moves the vertices whose response to it is
# at least this fraction of the largest (the rest get the change through the next solve, see below)
ROUNDS = 3  # complementarity solves per substep at most (a correction may close other gaps)
SWEEPS = 12  # projected Gauss-Seidel sweeps over the constraints in contact per substep (warm-started)


def solved_constraints(mesh: FaceMesh, rest: np.ndarray) -> dict[str, np.ndarray]:
    """Every constraint of the implicit integrator's contact (SolvedContact), as margin_pairs gives
    its pairs: the margin pairs and the first rings (margin_rings), both on y and re-paired every
    substep with the segment of their row (the opposite margin, or the ring's own) at their current
    x, and the row order (margin_order, on x). Keys: idx, w, sg as in margin_pairs, dim (P,) the
    coordinate, opp (P,) the row a constraint is re-paired along (-1: fixed), row_ptr, row_v the
    rows (concatenated)."""
    pairs, rings, order = margin_pairs(mesh, rest), margin_rings(mesh, rest), margin_order(mesh, rest)
    idx, w, sg = (np.concatenate([pairs[i], rings[i], order[i]]) for i in range(3))
    n_pairs, n_y = len(pairs[0]), len(pairs[0]) + len(rings[0])
    dim = np.concatenate([np.ones(n_y, np.int64), np.zeros(len(order[0]), np.int64)])
    rows = list(_rows(mesh).values())
    opp = np.full(len(idx), -1, dtype=np.int64)
    for k in range(n_y):
        a, b0, b1 = idx[k]
        opp[k] = next(r for r, row in enumerate(rows) if a not in row and b0 in row and b1 in row)
    row_ptr = np.cumsum([0] + [len(r) for r in rows]).astype(np.int64)
    row_v = np.concatenate(rows).astype(np.int64) if rows else np.zeros(0, np.int64)

    def gap(i: np.ndarray, ww: np.ndarray) -> np.ndarray:
        y = rest[:, 1]
        return sg[:n_y, 0] * (y[i[:n_y, 0]] - (1.0 - ww[:n_y]) * y[i[:n_y, 1]] - ww[:n_y] * y[i[:n_y, 2]])

    # the least gaps again for the pairing the substeps use (along the row, not sorted by x), so
    # that the rest pose satisfies every constraint whatever the row's shape
    overlap = np.minimum(gap(idx, w), 0.0)[:n_pairs] - sg[:n_pairs, 1]
    idx, w, sg = idx.copy(), w.copy(), sg.copy()
    _repair(np.ascontiguousarray(rest, dtype=np.float64), idx, w, opp, row_ptr, row_v)
    g = gap(idx, w)
    sg[:n_pairs, 1] = np.minimum(g[:n_pairs], 0.0) - overlap
    sg[n_pairs:n_y, 1] = ORDER_FRACTION * np.maximum(g[n_pairs:], 0.0)
    return dict(idx=idx, w=w, sg=sg, dim=dim, opp=opp, row_ptr=row_ptr, row_v=row_v)


class SolvedContact:
    """The lid and lip contact of the implicit integrator: forces in the global solve whose sizes are
    solved for on the constraints in contact (a Schur complement), not a projection after it.

    One implicit substep solves A x' = b with A fixed, the same matrix for x, y and z. Each
    constraint is linear in one coordinate of at most three vertices, c = J x' - g >= 0 (a margin
    pair: +-1 at vertex a, -+(1 - w), -+w at b0, b1 of the opposite margin). A force F^T lam added
    to b changes the gaps by S lam, S = J A^-1 F^T; A^-1 between the constrained vertices (G) is
    computed once. Each substep
      1. adds the last substep's contact forces F^T lam to the right-hand side and solves;
      2. pairs each margin vertex again with the segment of the opposite margin at its current x
         (the lids slide along each other as they close), and each first-ring vertex with its own
         margin, and builds S on the constraints in contact (violated, or pressed in the last
         substep) from G;
      3. finds lam >= 0 with c + S dlam >= 0 and lam (c + S dlam) = 0 (a linear complementarity
         problem, projected Gauss-Seidel from the last lam);
      4. moves the vertices by A^-1 F^T dlam, keeping of each constrained vertex's column of A^-1
         only the entries of at least CORRECTION_CUTOFF of its largest (the vertices near it; the far
         ones get the change through step 1 of the next substep).
    The velocity is then (x' - x) / h, so contact is inelastic. At rest in contact dlam = 0 and the
    pose is the constrained equilibrium of the global equation: the contact force reaches every
    vertex through the solve, unlike the projection, whose neighbours never saw it. F is J with the
    give factors (the lower lid takes LOWER_LID_GIVE of the force, as in the projection)."""

    #: the arrays a SolvedContact is made of (`arrays`, `from_arrays`: the face cache keeps them)
    KEYS = ("idx", "w", "sg", "dim", "opp", "row_ptr", "row_v", "loc", "green", "gptr", "gvert", "gval")

    def __init__(self, cons: dict[str, np.ndarray], free: np.ndarray, n: int,
                 solve: Callable[[np.ndarray, np.ndarray], np.ndarray] | None) -> None:
        if solve is None:  # from_arrays: cons holds every array of KEYS
            self._restore(cons)
            return
        self.idx = np.array(cons["idx"], dtype=np.int64)
        self.w = np.array(cons["w"], dtype=np.float64)
        self.sg = np.ascontiguousarray(cons["sg"], dtype=np.float64)
        self.dim, self.opp = np.asarray(cons["dim"], np.int64), np.asarray(cons["opp"], np.int64)
        self.row_ptr, self.row_v = np.asarray(cons["row_ptr"], np.int64), np.asarray(cons["row_v"], np.int64)
        p = len(self.idx)
        is_free = np.zeros(n, bool)
        is_free[free] = True
        verts = np.unique(self.idx)
        verts = verts[is_free[verts]]  # held vertices never move
        self.loc = np.full(n, -1, dtype=np.int64)
        self.loc[verts] = np.arange(len(verts))
        pos = np.full(n, -1, dtype=np.int64)
        pos[free] = np.arange(len(free))
        g = np.zeros((len(verts), len(verts)))
        ptr, vert, val = [0], [], []
        out = np.zeros((len(free), 3))
        for k in range(0, len(verts), 3):  # three unit loads per solve, as the solver takes them
            cols = min(3, len(verts) - k)
            b = np.zeros((len(free), 3))
            b[pos[verts[k:k + cols]], np.arange(cols)] = 1.0
            solve(b, out)
            for c in range(cols):
                col = out[:, c]
                g[:, k + c] = col[pos[verts]]
                keep = np.flatnonzero(np.abs(col) >= CORRECTION_CUTOFF * np.abs(col).max())
                vert.append(free[keep])
                val.append(col[keep].copy())
                ptr.append(ptr[-1] + len(keep))
        self.green = g
        self.gptr = np.array(ptr, dtype=np.int64)
        self.gvert = np.concatenate(vert).astype(np.int64) if vert else np.zeros(0, np.int64)
        self.gval = np.concatenate(val) if val else np.zeros(0)
        self._buffers()

    def _buffers(self) -> None:
        p = len(self.idx)
        self._rest_idx, self._rest_w = self.idx.copy(), self.w.copy()  # the steps re-pair idx and w
        self.lam = np.zeros(p)
        self._work = np.zeros((3, p))
        self._cand = np.zeros(p, dtype=np.int64)
        self._schur = np.zeros((p, p))
        self._df = np.zeros((self.green.shape[0], 3))

    def arrays(self) -> dict[str, np.ndarray]:
        """The constant arrays this contact is made of, as at construction (the pairing at rest)."""
        return {k: np.array(getattr(self, "_rest_" + k, getattr(self, k))) for k in self.KEYS}

    def _restore(self, arrays: dict[str, np.ndarray]) -> None:
        types = dict(w=np.float64, sg=np.float64, green=np.float64, gval=np.float64)
        for k in self.KEYS:
            setattr(self, k, np.array(arrays[k], dtype=types.get(k, np.int64), order="C"))
        self._buffers()

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "SolvedContact":
        """A contact made from `arrays()` of another: the same bits from the first substep on."""
        return cls(arrays, np.zeros(0, np.int64), 0, None)

    def memory(self) -> np.ndarray:
        """What the next substep starts from besides x and v, as one float array: the impulses
        (warm start) and each pair's segment on the opposite row (its force is applied before the
        pairs are found again). A state carries it so a restored checkpoint steps on the same bits."""
        out = np.empty(4 * len(self.lam))
        _memory(self.lam, self.w, self.idx, out)  # (numpy's concatenate took 13 us a step)
        return out

    def recall(self, mem: np.ndarray | None) -> None:
        """Restore `memory()`'s values; None (a state at rest, before any step): no contact force."""
        p = len(self.lam)
        if mem is None or mem.shape != (4 * p,):
            self.lam[...] = 0.0
            return
        _recall(mem, self.lam, self.w, self.idx)

    def add_force(self, rhs: np.ndarray) -> None:
        """rhs += F^T lam: the contact forces of the last substep (step 1)."""
        _contact_force(rhs, self.idx, self.w, self.sg, self.dim, self.lam)

    def resolve(self, x: np.ndarray) -> None:
        """Steps 2 to 4 on the solved positions x (all vertices, in place)."""
        _repair(x, self.idx, self.w, self.opp, self.row_ptr, self.row_v)
        for _ in range(ROUNDS):  # again while the correction pushed other pairs into contact
            if not _contact_resolve(x, self.idx, self.w, self.sg, self.dim, self.lam, self.loc, self.green,
                                    self.gptr, self.gvert, self.gval, self._work, self._cand, self._schur,
                                    self._df, SWEEPS):
                break


@numba.njit(**KERNEL)
def _memory(lam, w, idx, out):  # type: ignore[no-untyped-def]
    """out = lam, w, idx[:, 1], idx[:, 2] one after the other, as floats (SolvedContact.memory)."""
    p = lam.shape[0]
    for k in range(p):
        out[k] = lam[k]
        out[p + k] = w[k]
        out[2 * p + k] = float(idx[k, 1])
        out[3 * p + k] = float(idx[k, 2])


@numba.njit(**KERNEL)
def _recall(mem, lam, w, idx):  # type: ignore[no-untyped-def]
    """The inverse of `_memory` (SolvedContact.recall; the indices truncated, as astype does)."""
    p = lam.shape[0]
    for k in range(p):
        lam[k] = mem[k]
        w[k] = mem[p + k]
        idx[k, 1] = int(mem[2 * p + k])
        idx[k, 2] = int(mem[3 * p + k])


def warm_up_solved() -> None:
    """Compile (or load from numba's cache) SolvedContact's kernels on a three-vertex system."""
    cons = dict(idx=np.array([[0, 1, 2]]), w=np.array([0.5]), sg=np.array([[1.0, 0.0, 1.0, 1.0]]),
                dim=np.array([1]), opp=np.array([0]), row_ptr=np.array([0, 2]), row_v=np.array([1, 2]))
    contact = SolvedContact(cons, np.arange(3), 3, lambda b, out: np.copyto(out, b))
    contact.add_force(np.zeros((3, 3)))
    contact.resolve(np.array([[0.0, -0.1, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    contact.recall(contact.memory())


@numba.njit(**KERNEL)
def _contact_force(rhs, idx, w, sg, dim, lam):  # type: ignore[no-untyped-def]
    """rhs += F^T lam (held vertices get a force too; the solve never reads their rows)."""
    for k in range(idx.shape[0]):
        f = lam[k] * sg[k, 0]
        d = dim[k]
        if f != 0.0:
            rhs[idx[k, 0], d] += f * sg[k, 2]
            rhs[idx[k, 1], d] -= f * (1.0 - w[k]) * sg[k, 3]
            rhs[idx[k, 2], d] -= f * w[k] * sg[k, 3]


@numba.njit(**KERNEL)
def _repair(x, idx, w, opp, row_ptr, row_v):  # type: ignore[no-untyped-def]
    """Each margin pair's b0, b1, w: the segment of its opposite row that spans vertex a's x (the
    nearer end segment when none does)."""
    for k in range(idx.shape[0]):
        r = opp[k]
        if r < 0:
            continue
        xa = x[idx[k, 0], 0]
        s0, s1 = row_ptr[r], row_ptr[r + 1]
        best, bw = -1, 0.0
        for j in range(s0, s1 - 1):
            x0 = x[row_v[j], 0]
            x1 = x[row_v[j + 1], 0]
            if (x0 <= xa <= x1) or (x1 <= xa <= x0):
                best = j
                bw = (xa - x0) / (x1 - x0) if x1 != x0 else 0.0
                break
        if best < 0:
            if abs(xa - x[row_v[s0], 0]) <= abs(xa - x[row_v[s1 - 1], 0]):
                best, bw = s0, 0.0
            else:
                best, bw = s1 - 2, 1.0
        idx[k, 1] = row_v[best]
        idx[k, 2] = row_v[best + 1]
        w[k] = bw


@numba.njit(**KERNEL)
def _contact_resolve(x, idx, w, sg, dim, lam, loc, green, gptr, gvert, gval, work, cand, schur, df, sweeps):  # type: ignore[no-untyped-def]
    """Steps 2 to 4 of SolvedContact: the gaps, the Schur complement on the constraints in contact
    (violated, or pressed last substep) from the Green's function, projected Gauss-Seidel for the
    change of lam, and x += A^-1 F^T dlam (truncated columns). Returns how many constraints out of
    contact the correction violated."""
    p = idx.shape[0]
    c, dl = work[0], work[1]
    for k in range(p):
        d = dim[k]
        c[k] = sg[k, 0] * (x[idx[k, 0], d] - (1.0 - w[k]) * x[idx[k, 1], d] - w[k] * x[idx[k, 2], d]) - sg[k, 1]
    nc = 0
    for k in range(p):
        if lam[k] > 0.0 or c[k] < 0.0:
            cand[nc] = k
            nc += 1
    if nc == 0:
        return 0
    # each candidate's three vertices (their rows of the Green's function, -1: held), its row of J
    # and its column of F^T, gathered once (the same expressions as the sums below used inline)
    rows = np.empty((nc, 3), dtype=np.int64)
    jcoef = np.empty((nc, 3))
    fcoef = np.empty((nc, 3))
    for ii in range(nc):
        k = cand[ii]
        for pk in range(3):
            rows[ii, pk] = loc[idx[k, pk]]
        jcoef[ii, 0] = sg[k, 0]
        jcoef[ii, 1] = -sg[k, 0] * (1.0 - w[k])
        jcoef[ii, 2] = -sg[k, 0] * w[k]
        fcoef[ii, 0] = sg[k, 0] * sg[k, 2]
        fcoef[ii, 1] = -sg[k, 0] * (1.0 - w[k]) * sg[k, 3]
        fcoef[ii, 2] = -sg[k, 0] * w[k] * sg[k, 3]
    for ii in range(nc):  # S = J G F^T on the candidates, each entry summed in the same order
        dk = dim[cand[ii]]
        for jj in range(nc):
            acc = 0.0
            if dim[cand[jj]] == dk:
                for pk in range(3):
                    u = rows[ii, pk]
                    if u < 0:
                        continue
                    jc = jcoef[ii, pk]
                    for pm in range(3):
                        v = rows[jj, pm]
                        if v >= 0:
                            acc += jc * green[u, v] * fcoef[jj, pm]
            schur[ii, jj] = acc
    dlc = np.zeros(nc)  # the candidates' change of lam, in candidate order
    for _ in range(sweeps):
        for ii in range(nc):
            k = cand[ii]
            if schur[ii, ii] <= 0.0:
                continue
            res = c[k]
            srow = schur[ii]
            for jj in range(nc):
                res += srow[jj] * dlc[jj]
            new = lam[k] + dlc[ii] - res / schur[ii, ii]
            dlc[ii] = (new if new > 0.0 else 0.0) - lam[k]
    for ii in range(nc):
        dl[cand[ii]] = dlc[ii]
    for ii in range(nc):
        k = cand[ii]
        d = dl[k]
        if d == 0.0:
            continue
        lam[k] += d
        f = d * sg[k, 0]
        e = dim[k]
        for pk in range(3):
            u = loc[idx[k, pk]]
            if u >= 0:
                cf = sg[k, 2] if pk == 0 else (-(1.0 - w[k]) * sg[k, 3] if pk == 1 else -w[k] * sg[k, 3])
                df[u, e] += f * cf
    for u in range(df.shape[0]):
        for e in range(3):
            g = df[u, e]
            if g != 0.0:
                for q in range(gptr[u], gptr[u + 1]):
                    x[gvert[q], e] += gval[q] * g
                df[u, e] = 0.0
    late = 0  # constraints out of contact before that the correction violated
    for k in range(p):
        if lam[k] == 0.0:
            d = dim[k]
            if sg[k, 0] * (x[idx[k, 0], d] - (1.0 - w[k]) * x[idx[k, 1], d] - w[k] * x[idx[k, 2], d]) < sg[k, 1]:
                late += 1
    return late
