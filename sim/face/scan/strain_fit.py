"""Active strain of the scanned head's muscles, fitted to its scanned expressions.

A muscle lies inside the soft tissue; when it contracts, the tissue it runs through shortens along
its fibres and bulges across them: the tissue's rest state changes (active strain, as in FEM faces
driven by muscle activations: Sifakis, Neverov & Fedkiw 2005, "Automatic determination of facial
muscle activations from sparse motion capture marker data"; Ichim et al. 2017, "Phace"). In the
mass-spring skin that is a change of its springs' rest lengths inside the muscle's zone, in
proportion to the channel's value:

    L_e = L0_e (1 + sum_c v_c s_ce),   s_ce = d_e^T (E_c(i) + E_c(j)) / 2 d_e

with d_e the spring's rest direction and E_c(x) a symmetric 3x3 strain field per zone vertex (six
parameters a vertex; the right side's field is the left's mirrored, M E M with M = diag(-1, 1, 1)).
The forces such a field makes are internal (each spring pushes its two ends apart or together) and
local: what the muscles' smooth pulls cannot make (docs/scan-face.md, "What limits the match").

Linear statics about the rest shape, as the other fits (`sim.face.scan.insertion_fit`): a rest
length change L0 s_e at rest is a force k_e L0_e s_e along d_e on one end and its opposite on the
other, so the settled displacement is u = K^-1 sum_c v_c T_c p_c, K the skin's stiffness at rest
with the implicit step's bending terms (margin and skin bending: they are elastic energies of the
step, and the strain's local forces excite exactly the ripples they resist). The fields are fitted
on top of the pulls (the pulls stay as the rig has them): the target of each shape is the scan less
the shape's settled pose on the simulator. L-BFGS-B with the adjoint gradient; a graph-Laplacian
smoothness over the zone's edges and a small ridge keep the fields tissue-like; each component is
bounded (BOUND).
"""

from __future__ import annotations

from typing import Any

import numpy as np

SMOOTH = 1e-3  # Laplacian weight per edge and component, relative to one shape's own size
RIDGE = 1e-4  # pull of each component towards 0
BOUND = 0.4  # |E_ab| at most this (a spring shortens or lengthens at most 40 % at full value)
_MIRROR_SIGN = np.array([1.0, 1.0, 1.0, -1.0, -1.0, 1.0])  # M E M, M = diag(-1, 1, 1)


def step_stiffness(model: Any, bending: bool = True) -> tuple[Any, np.ndarray]:
    """The skin's stiffness at rest (`calibrate.rest_stiffness`) plus the implicit step's bending,
    factorised over the free degrees of freedom, and their indices."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    from sim.antifold import bending_of
    from sim.face.scan.calibrate import rest_stiffness

    k = rest_stiffness(model)
    if not bending:
        free = np.flatnonzero(np.repeat(~np.asarray(model.held, bool), 3))
        return splu(k.tocsr()[free][:, free].tocsc()), free
    k = k + sp.kron(bending_of(model), sp.eye(3))
    free = np.flatnonzero(np.repeat(~np.asarray(model.held, bool), 3))
    return splu(k.tocsr()[free][:, free].tocsc()), free


def spring_strain_matrix(rest: np.ndarray, springs: np.ndarray, sel: np.ndarray, par: np.ndarray,
                         n_params: int, mirrored: bool) -> Any:
    """(len(sel), 6 P) sparse: each selected spring's strain s_e from the strain parameters (six per
    zone vertex; par (N,) the parameter vertex of each skin vertex, -1 outside the zone)."""
    import scipy.sparse as sp

    from sim.active_strain import fibre_terms

    i, j = springs[sel, 0], springs[sel, 1]
    a = fibre_terms(rest, springs[sel])
    if mirrored:
        a = a * _MIRROR_SIGN
    m = len(sel)
    r = np.repeat(np.arange(m), 12)
    c = np.concatenate([6 * par[i][:, None] + np.arange(6), 6 * par[j][:, None] + np.arange(6)], axis=1).ravel()
    v = 0.5 * np.concatenate([a, a], axis=1).ravel()
    return sp.csr_matrix((v, (r, c)), shape=(m, 6 * n_params))


class FieldCalibration:
    """What the fits of a field per channel in the linear statics share (`StrainCalibration`,
    `sim.face.scan.anchor_fit.AnchorCalibration`): a subclass sets `model`, `n`, the factored
    stiffness `lu` over the `free` rows, `force_of` (channel -> sparse (3N, n_params) force per
    parameter), `diff` (the smoothness's edge differences), `smooth`, `ridge`, `bound` and `params`."""

    FTOL = 1e-12  # L-BFGS-B's relative tolerance on the objective

    model: Any
    n: int
    lu: Any
    free: np.ndarray
    force_of: dict[str, Any]
    diff: Any
    smooth: float
    ridge: float
    bound: float
    params: np.ndarray
    n_params: int

    @staticmethod
    def _group_zone(g: str, chans: list[str], zones: dict[str, np.ndarray], mirror: np.ndarray, e: np.ndarray,
                    k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """One group's zone (its channels' zones, a right channel's mirrored onto the left), its
        vertices, each vertex's parameter index (k on; -1 outside) and its inner edges' two indices."""
        n = len(mirror)
        zone = np.zeros(n, bool)
        for c in chans:
            z = np.flatnonzero(zones[c])
            zone[z if c != g + "_r" else mirror[z]] = True
        ids = np.flatnonzero(zone)
        look = -np.ones(n, np.int64)
        look[ids] = k + np.arange(len(ids))
        inner = e[zone[e].all(axis=1)]
        return zone, ids, look, (look[inner[:, 0]], look[inner[:, 1]])

    def _edge_differences(self, lap: list[tuple[np.ndarray, np.ndarray]], k: int, width: int) -> None:
        """`diff`: one row per zone edge and component, the difference of its two ends' parameters
        (`lap`: per group the edges' two parameter indices; `k` parameters of `width` components)."""
        import scipy.sparse as sp

        r = np.concatenate([i for i, _ in lap])
        c2 = np.concatenate([j for _, j in lap])
        m = len(r)
        d1 = (sp.csr_matrix((np.ones(m), (np.arange(m), r)), shape=(m, k))
              - sp.csr_matrix((np.ones(m), (np.arange(m), c2)), shape=(m, k)))
        self.diff = sp.kron(d1, sp.eye(width)).tocsr()

    def _solve(self, rhs: np.ndarray) -> np.ndarray:
        out = np.zeros_like(rhs)
        out[self.free] = self.lu.solve(np.ascontiguousarray(rhs[self.free]))
        return out

    def forces(self, p: np.ndarray, vals: np.ndarray) -> np.ndarray:
        """(3N, S) nodal force of each shape (vals (S, C) channel values)."""
        ci = self.model.channel_index
        f = np.zeros((3 * self.n, len(vals)))
        for c, t in self.force_of.items():
            v = vals[:, ci[c]]
            if np.any(v):
                f += (t @ p)[:, None] * v[None]
        return f

    def predict_all(self, vals: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """(S, N, 3) linear displacement the fields add to each shape."""
        u = self._solve(self.forces(self.params if p is None else p, vals))
        return u.T.reshape(len(vals), self.n, 3)

    def objective(self, p: np.ndarray, vals: np.ndarray, b: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray]:
        """Weighted squared misfit (targets b (3N, S), weights w (S,)) plus smoothness and ridge, and
        its gradient (one adjoint solve a shape: K is symmetric)."""
        r = self._solve(self.forces(p, vals)) - b
        lam = 2.0 * self._solve(r * w[None])
        ci = self.model.channel_index
        grad = np.zeros_like(p)
        for c, t in self.force_of.items():
            v = vals[:, ci[c]]
            if np.any(v):
                grad += t.T @ (lam @ v)
        dp = self.diff @ p
        val = float(np.sum(w * np.sum(r * r, axis=0))) + self.smooth * float(dp @ dp) + self.ridge * float(p @ p)
        grad += 2.0 * self.smooth * (self.diff.T @ dp) + 2.0 * self.ridge * p
        return val, grad

    def fit(self, vals: np.ndarray, b: np.ndarray, w: np.ndarray, iters: int = 300) -> Any:
        """The fields by L-BFGS-B (vals (S, C), targets b (3N, S), weights w (S,))."""
        from scipy.optimize import minimize

        res = minimize(lambda p: self.objective(p, vals, b, w), self.params, jac=True, method="L-BFGS-B",
                       bounds=[(-self.bound, self.bound)] * self.n_params,
                       options={"maxiter": iters, "ftol": self.FTOL, "gtol": 1e-10})
        self.params = res.x
        return res


class StrainCalibration(FieldCalibration):
    """The linear model of one compiled face with an active strain field per muscle (sides shared)."""

    def __init__(self, model: Any, smooth: float = SMOOTH, ridge: float = RIDGE, bound: float = BOUND,
                 bending: bool = True) -> None:
        import scipy.sparse as sp

        from sim.build import vertex_normals
        from sim.face.scan.insertion_fit import mirror_map
        from sim.muscles import muscle_field

        self.model = model
        rig = model.rig
        rest = np.asarray(model.rest)
        n = self.n = len(rest)
        self.lu, self.free = step_stiffness(model, bending)
        normal = vertex_normals(rest, np.asarray(rig.mesh.triangles, np.int32))
        mirror = mirror_map(rest)
        springs = np.asarray(model.spring_indices, np.int64)
        kl0 = np.asarray(model.spring_k_low) * np.asarray(model.spring_rest_length)
        tri = np.asarray(rig.mesh.triangles, np.int64)
        e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        e = np.unique(np.sort(e[(e < n).all(axis=1)], axis=1), axis=0)
        self.channels = [c for c in rig.muscles if c in model.channel_index]
        groups: dict[str, list[str]] = {}
        for c in self.channels:
            groups.setdefault(c[:-2] if c.endswith(("_l", "_r")) else c, []).append(c)
        self.groups = sorted(groups)
        zones: dict[str, np.ndarray] = {}
        for c in self.channels:
            f = muscle_field(rig.muscles[c], rest, np.asarray(model.area), normal)
            mag = np.linalg.norm(f, axis=1)
            zones[c] = mag > 1e-3 * mag.max() if mag.max() > 0 else np.zeros(n, bool)
        self.zone_vertices: dict[str, np.ndarray] = {}
        parts, lap, k = {}, [], 0
        self.spring_sel: dict[str, np.ndarray] = {}
        self.strain_of: dict[str, Any] = {}  # channel -> (E_c, 6P) spring strains from the parameters
        for g in self.groups:
            chans = groups[g]
            zone, ids, look, edges = self._group_zone(g, chans, zones, mirror, e, k)
            lap.append(edges)
            parts[g] = (k, len(ids))
            for c in chans:
                right = c == g + "_r"
                par = look[mirror] if right else look
                par = np.where(zones[c], par, -1)
                sel = np.flatnonzero((par[springs] >= 0).all(axis=1))
                self.spring_sel[c] = sel
                self.zone_vertices[c] = np.flatnonzero(zones[c])
                self.strain_of[c] = (sel, par, right)
            k += len(ids)
        self.n_params = 6 * k
        self.parts = parts
        self.force_of: dict[str, Any] = {}  # channel -> (3N, 6P) nodal force per parameter at value 1
        self.strain_mat: dict[str, Any] = {}
        for c, (sel, par, right) in self.strain_of.items():
            s = spring_strain_matrix(rest, springs, sel, par, k, right)
            i, j = springs[sel, 0], springs[sel, 1]
            d = rest[i] - rest[j]
            d /= np.linalg.norm(d, axis=1)[:, None]
            m = len(sel)
            rr = np.concatenate([(3 * i[:, None] + np.arange(3)).ravel(), (3 * j[:, None] + np.arange(3)).ravel()])
            cc = np.concatenate([np.repeat(np.arange(m), 3), np.repeat(np.arange(m), 3)])
            vv = np.concatenate([(d * kl0[sel][:, None]).ravel(), (-d * kl0[sel][:, None]).ravel()])
            g_mat = sp.csr_matrix((vv, (rr, cc)), shape=(3 * n, m))
            self.strain_mat[c] = s
            self.force_of[c] = (g_mat @ s).tocsr()
        self._edge_differences(lap, k, 6)
        self.smooth, self.ridge, self.bound = smooth, ridge, bound
        self.params = np.zeros(self.n_params)

    def spring_strain(self) -> dict[str, np.ndarray]:
        """Per channel the (S,) strain of every spring at full value (0 outside the zone)."""
        out = {}
        n_springs = len(np.asarray(self.model.spring_indices))
        for c, s in self.strain_mat.items():
            full = np.zeros(n_springs)
            full[self.spring_sel[c]] = s @ self.params
            out[c] = full
        return out

    def strain(self, tol: float = 1e-6) -> dict[str, np.ndarray]:
        """Per channel the (N, 6) strain the rig stores (`FaceRig.strain`; zero outside the zone),
        for the channels whose fitted field is not negligible."""
        out = {}
        p = self.params.reshape(-1, 6)
        for c, (_, par, right) in self.strain_of.items():
            e = np.zeros((self.n, 6))
            z = par >= 0
            e[z] = p[par[z]] * (_MIRROR_SIGN if right else 1.0)
            if np.abs(e).max() > tol:
                out[c] = np.round(e, 6)
        return out

