"""A second integrator for big meshes: implicit Euler by one projective-dynamics iteration.

Explicit RK2 (the paper's method, `sim.integrator`) needs a step below ~2/omega_max, and omega_max
grows as 1/edge length: at 12k vertices that is ~80 substeps of ~80k springs per frame, far beyond a
real-time budget. Here each substep is one local/global iteration of projective dynamics
(Bouaziz et al. 2014) for implicit Euler:

- local: each spring s, at the predicted positions y = x + h v, gets a target vector d_s along its
  current direction whose length l_s makes k_h (r - l_s) equal the true biphasic tension T(r)
  (eqs 1-3): l_s = r - T(r) / k_h. The spring's term k_h |x_j - x_i - d_s|^2 then has exactly the
  true force at y and a Hessian that never changes.
- global: (M / h^2 + C / h + L(k_h) + diag(k_r)) x' = M / h^2 y + C / h x + sum_s k_h (e_j - e_i) d_s
  + k_r target + f_muscle + f_gravity, with L(k_h) the springs' graph Laplacian. The matrix is
  constant and the same for x, y and z, so it is factored once (sparse LU, scipy SuperLU) and a
  substep costs one spring pass and two triangular solves with 3 right-hand sides.
- the lid and lip contact is solved with the global step (forces of unknown size on the margin
  pairs, `sim.margin_contact.SolvedContact`), then v' = (x' - x) / h; the eyeball contact is a
  projection after it.

The matrix also carries a bending term along the lid and lip rows (`sim.margin_contact.
margin_bending`, K_b (x' - rest shape) with the rest shape turned with the jaw): a fine mesh's
pressed margin buckles into an alternating zig-zag without it; and the skin's own bending and its
guard against turning over (`sim.antifold`: the first in the matrix, the second on the right-hand
side, zero unless a triangle nears folding flat). RK2 has no such terms, so apart from them
(and from contact) the global equation at rest (x' = x = y) is exactly the force balance RK2 settles
to, and a settled pose is the same equilibrium; only the transient differs (implicit Euler damps fast
modes; the axial spring damping is left out, implicit Euler's own dissipation replaces it).

Substeps: accuracy, not stability, sets h: the slowest physically meaningful motion is the skin
swinging on its eq 9 tethers, omega_r = sqrt(tether / areal density) (~100 rad/s, and damped at
zeta ~ 0.6 by the mass damping); we take omega_r h <= OMEGA_H, which gives one substep per 60 Hz
frame. The price is a slower rise (benchmarks/sim_step.py measures it against RK2).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from sim.antifold import FoldGuard, skin_bending, thin_skin
from sim.antifold import warm_up as warm_up_folds
from sim.build import FaceModel
from sim.margin_contact import SolvedContact, margin_bending, solved_constraints, warm_up_solved
from sim.numba_start import prepare_blas_check

prepare_blas_check()  # before this module's first kernel runs: see sim.numba_start


def laplacian(n: int, springs: np.ndarray, w: np.ndarray) -> sp.csr_matrix:
    """Graph Laplacian (n, n) of the springs weighted by w: sum_s w_s (e_i - e_j)(e_i - e_j)^T."""
    i, j = springs[:, 0].astype(np.int64), springs[:, 1].astype(np.int64)
    off = sp.coo_matrix((np.concatenate([-w, -w]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                        shape=(n, n)).tocsr()
    diag = np.zeros(n)
    np.add.at(diag, i, w)
    np.add.at(diag, j, w)
    return (off + sp.diags(diag)).tocsr()


OMEGA_H = 2.0


def implicit_substeps(model: FaceModel, frame_dt: float) -> int:
    """Substeps per frame so that omega_r h <= OMEGA_H for the tether mode (module docstring)."""
    p = model.params
    omega_r = math.sqrt(p.tether / p.areal_density)
    return max(1, math.ceil(frame_dt * omega_r / OMEGA_H))


@numba.njit(cache=True, nogil=True)
def _lu_solve(b, perm_r, perm_c, l_ptr, l_idx, l_val, u_ptr, u_idx, u_val, u_diag, y, out):  # type: ignore[no-untyped-def]
    """x = Pc U^-1 L^-1 Pr b for 3 right-hand sides; L unit lower, U upper, both CSC."""
    n = b.shape[0]
    for i in range(n):
        r = perm_r[i]
        for k in range(3):
            y[r, k] = b[i, k]
    for j in range(n):  # forward: L has a unit diagonal
        y0 = y[j, 0]
        y1 = y[j, 1]
        y2 = y[j, 2]
        for p in range(l_ptr[j], l_ptr[j + 1]):
            r = l_idx[p]
            if r > j:
                a = l_val[p]
                y[r, 0] -= a * y0
                y[r, 1] -= a * y1
                y[r, 2] -= a * y2
    for j in range(n - 1, -1, -1):  # backward
        d = u_val[u_diag[j]]
        y0 = y[j, 0] / d
        y1 = y[j, 1] / d
        y2 = y[j, 2] / d
        y[j, 0] = y0
        y[j, 1] = y1
        y[j, 2] = y2
        for p in range(u_ptr[j], u_ptr[j + 1]):
            r = u_idx[p]
            if r < j:
                a = u_val[p]
                y[r, 0] -= a * y0
                y[r, 1] -= a * y1
                y[r, 2] -= a * y2
    for i in range(n):
        c = perm_c[i]
        for k in range(3):
            out[i, k] = y[c, k]


class PrefactoredSolver:
    """A sparse LU of a fixed matrix with a compiled solve for (n, 3) right-hand sides."""

    def __init__(self, a: sp.spmatrix) -> None:
        lu = splu(sp.csc_matrix(a), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                  options={"SymmetricMode": True})
        lower, upper = sp.csc_matrix(lu.L), sp.csc_matrix(lu.U)
        self.n = a.shape[0]
        self.perm_r = np.ascontiguousarray(lu.perm_r, dtype=np.int64)
        self.perm_c = np.ascontiguousarray(lu.perm_c, dtype=np.int64)
        # int32 indices: the solve streams the factors from memory, so their size is its cost
        self.l = (lower.indptr.astype(np.int64), lower.indices.astype(np.int32), lower.data.copy())
        self.u = (upper.indptr.astype(np.int64), upper.indices.astype(np.int32), upper.data.copy())
        u_diag = np.empty(self.n, dtype=np.int64)
        for j in range(self.n):
            rows = upper.indices[upper.indptr[j]:upper.indptr[j + 1]]
            u_diag[j] = upper.indptr[j] + int(np.flatnonzero(rows == j)[0])
        self.u_diag = u_diag
        self.fill = int(lower.nnz + upper.nnz)
        self._y = np.zeros((self.n, 3))

    def solve(self, b: np.ndarray, out: np.ndarray) -> np.ndarray:
        """out = A^-1 b for b (n, 3)."""
        _lu_solve(b, self.perm_r, self.perm_c, *self.l, *self.u, self.u_diag, self._y, out)
        return out


@numba.njit(cache=True, nogil=True)
def _pd_springs(y, springs, rest_len, k_low, k_high, thr, out):  # type: ignore[no-untyped-def]
    """Adds sum_s k_h (e_j - e_i) d_s to out (the local step; see the module docstring)."""
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        dx = y[j, 0] - y[i, 0]
        dy = y[j, 1] - y[i, 1]
        dz = y[j, 2] - y[i, 2]
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        stretch = r - rest_len[s]
        knee = thr * rest_len[s]
        if stretch <= knee:
            t = k_low[s] * stretch
        else:
            t = k_low[s] * knee + k_high[s] * (stretch - knee)
        scale = (k_high[s] * r - t) / r  # k_h * l_s / r: d_s = l_s u_s
        out[j, 0] += scale * dx
        out[j, 1] += scale * dy
        out[j, 2] += scale * dz
        out[i, 0] -= scale * dx
        out[i, 1] -= scale * dy
        out[i, 2] -= scale * dz


def warm_up() -> None:
    """Compile (or load from numba's cache) this module's kernels on a tiny system."""
    a = sp.csc_matrix(np.array([[2.0, -1.0], [-1.0, 2.0]]))
    PrefactoredSolver(a).solve(np.ones((2, 3)), np.zeros((2, 3)))
    y = np.array([[0.0, 0.0, 0.0], [1.1, 0.0, 0.0]])
    one = np.ones(1)
    _pd_springs(y, np.array([[0, 1]], dtype=np.int32), one, one, one, 0.1, np.zeros_like(y))
    warm_up_solved()
    warm_up_folds()


class ImplicitStepper:
    """Runs the substeps of one frame for a Simulator (method "implicit")."""

    def __init__(self, model: FaceModel, h: float) -> None:
        n = model.n_vertices
        springs = np.asarray(model.spring_indices)
        self.h = h
        held = np.asarray(model.held)
        self.free = np.flatnonzero(~held)
        self.held = np.flatnonzero(held)
        mass = np.asarray(model.mass)
        self.mass_h2 = mass / h**2
        self.damp_h = np.asarray(model.damping) / h
        self.kn = np.asarray(model.support_stiffness)
        self.rest = np.asarray(model.rest)
        self._shape: np.ndarray | None = None
        self._bend_rhs = np.zeros((n, 3))
        self.bend = margin_bending(model.mesh, model.rest, springs, np.asarray(model.spring_k_high),
                                   model.params.lid_bending, model.params.lip_bending)
        if model.params.skin_bending:
            self.bend = self.bend + skin_bending(n, model.triangles, np.asarray(model.spring_k_high),
                                                 model.params.skin_bending, thin_skin(model.mesh.regions, n))
        a = (laplacian(n, springs, np.asarray(model.spring_k_high)) + self.bend
             + sp.diags(self.mass_h2 + self.damp_h + np.asarray(model.rest_stiffness) + self.kn)).tocsr()
        self.a_fh = a[self.free][:, self.held].tocsr()
        self.solver = PrefactoredSolver(a[self.free][:, self.free])
        cons = solved_constraints(model.mesh, model.rest)  # the lid and lip contact (sim.margin_contact)
        self.margins = SolvedContact(cons, self.free, n, self.solver.solve) if len(cons["idx"]) else None
        # the skin's thickness against folding over (sim.antifold), on its predicted positions
        self.folds = FoldGuard(self.rest, model.triangles, springs, np.asarray(model.spring_k_high))
        self._rhs = np.zeros((n, 3))
        self._y = np.zeros((n, 3))
        self._xf = np.zeros((len(self.free), 3))

    def frame(self, x: np.ndarray, v: np.ndarray, n_sub: int, ext: np.ndarray, springs: tuple,  # type: ignore[type-arg]
              normal: np.ndarray, contact: Callable[[np.ndarray, np.ndarray], None],
              shape: np.ndarray | None = None) -> None:
        """n_sub substeps in place. ext: the frame-constant forces (muscles, gravity, the target terms
        of the tether and of the normal support); springs: (indices, rest lengths, k_low, k_high,
        threshold) as the kernel takes them; normal (N,3): the support's normals this frame. The
        support k_n n n^T enters like a spring: k_n I in the matrix, k_n (y - n (n . y)) on the right.
        contact(x, v) is applied after each substep (the eyeballs); shape (N,3): the rest shape of
        the margin bending term this frame (turned with the jaw; None: the model's rest)."""
        h, f = self.h, self.free
        idx, rest_len, k_low, k_high, thr = springs
        held_term = self.a_fh @ x[self.held]  # held nodes do not move within a frame
        if self.bend.nnz:  # the margin bending term's rest side (the shape changes with the jaw)
            shape = self.rest if shape is None else shape
            if shape is not self._shape:
                self._shape, self._bend_rhs = shape, self.bend @ shape
            ext = ext + self._bend_rhs
        for _ in range(n_sub):
            np.multiply(v, h, out=self._y)
            self._y += x
            np.multiply(self.mass_h2[:, None], self._y, out=self._rhs)
            self._rhs += ext
            self._rhs += self.damp_h[:, None] * x
            _pd_springs(self._y, idx, rest_len, k_low, k_high, thr, self._rhs)
            self.folds.add_forces(self._y, self._rhs)
            ny = np.einsum("ij,ij->i", normal, self._y)
            self._rhs += self.kn[:, None] * (self._y - ny[:, None] * normal)
            if self.margins is not None:
                self.margins.add_force(self._rhs)
            rhs_f = np.take(self._rhs, f, axis=0)
            rhs_f -= held_term
            self.solver.solve(rhs_f, self._xf)
            xf_old = np.take(x, f, axis=0)
            x[f] = self._xf
            if self.margins is not None:
                self.margins.resolve(x)
            v[f] = (np.take(x, f, axis=0) - xf_old) * (1.0 / h)
            contact(x, v)
