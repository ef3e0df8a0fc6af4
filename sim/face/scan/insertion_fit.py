"""Per-vertex insertion densities of the scanned head's muscles, fitted to its scanned expressions.

`sim.face.scan.calibrate` fits a dozen smooth bumps per muscle; this fits the insertion gain of
every skin vertex in each muscle's zone (the skin a muscle's fibres reach: where its placed field is
not zero), so a muscle may insert densely in one part of its zone and barely in another, as real
fibres do. The pull at each vertex keeps the muscle's own direction (towards its origin, the
sphincter's centre, along the sheet); only how hard it pulls there is fitted. The gains are
non-negative, at most MAX_GAIN, and smooth: a graph-Laplacian penalty over the skin's edges inside
the zone. The two sides share their gains through the mirror map of the skin (x -> -x, nearest
vertex), so a fit on the left shapes also predicts the right ones.

Linear statics: the settled displacement of shape s is u_s = K^-1 sum_c v_sc diag(f_c) g_c, K the
skin's stiffness at rest (`calibrate._stiffness`), f_c channel c's placed field, v_sc the channel
values the ARKit map gives s, g_c its per-vertex gains. The objective, each shape weighted by its own
size, is minimised by L-BFGS-B; the gradient is one adjoint solve per shape (K is symmetric), so all
shapes cost two multi-right-hand-side solves an iteration, whatever the number of gains.
"""

from __future__ import annotations

import numpy as np

from sim.face.scan.calibrate import MAX_GAIN, Shape, _stiffness, coupled_values

SMOOTH = 1e-3  # weight of the Laplacian penalty, per edge, relative to one shape's own size
PULL = 1e-4  # weight of the pull towards gain 1 (per vertex)


def mirror_map(points: np.ndarray) -> np.ndarray:
    """(N,) index of each vertex's mirror image across x = 0 (nearest vertex)."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(points).query(points * np.array([-1.0, 1.0, 1.0]))
    return np.asarray(idx, np.int64)


class VertexCalibration:
    """The linear model of one compiled face with a gain per zone vertex per muscle (sides shared)."""

    def __init__(self, model, smooth: float = SMOOTH, pull: float = PULL,  # type: ignore[no-untyped-def]
                 fixed: frozenset[str] = frozenset()) -> None:
        import scipy.sparse as sp

        from sim.build import vertex_normals
        from sim.muscles import muscle_field

        self.model = model
        rig = model.rig
        rest = np.asarray(model.rest)
        self.rest = rest
        n = len(rest)
        self.n = n
        self.lu, self.free = _stiffness(model)
        normal = vertex_normals(rest, np.asarray(rig.mesh.triangles, np.int32))
        mirror = mirror_map(rest)
        # channels in `fixed` keep the model's insertion gains: out of the linear model, their
        # settled motion is part of each shape's offset (what the linear model does not fit)
        self.channels = [c for c in rig.muscles if c in model.channel_index and c not in fixed]
        self.field: dict[str, np.ndarray] = {}
        self.vert: dict[str, np.ndarray] = {}  # channel -> zone vertices (in its own side)
        self.par: dict[str, np.ndarray] = {}  # channel -> parameter index of each zone vertex
        groups: dict[str, list[str]] = {}
        for c in self.channels:
            groups.setdefault(c[:-2] if c.endswith(("_l", "_r")) else c, []).append(c)
        k = 0
        edges_all = np.asarray(model.spring_indices, np.int64)
        tri = np.asarray(rig.mesh.triangles, np.int64)
        e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        e = e[(e < n).all(axis=1)] if len(e) else edges_all
        e = np.unique(np.sort(e, axis=1), axis=0)
        lap_rows, lap_cols = [], []
        for g, chans in sorted(groups.items()):
            fields = {c: muscle_field(rig.muscles[c], rest, np.asarray(model.area), normal) for c in chans}
            # the group's parameters live on the left side's vertices (unsided: its own)
            zone = np.zeros(n, bool)
            for c, f in fields.items():
                mag = np.linalg.norm(f, axis=1)
                z = np.flatnonzero(mag > 1e-3 * mag.max())
                zone[z if c != g + "_r" else mirror[z]] = True
            ids = np.flatnonzero(zone)
            lookup = -np.ones(n, np.int64)
            lookup[ids] = k + np.arange(len(ids))
            for c, f in fields.items():
                mag = np.linalg.norm(f, axis=1)
                z = np.flatnonzero(mag > 1e-3 * mag.max())
                self.vert[c] = z
                self.par[c] = lookup[z if c != g + "_r" else mirror[z]]
                self.field[c] = f[z]
            inner = e[zone[e].all(axis=1)]
            lap_rows.append(lookup[inner[:, 0]])
            lap_cols.append(lookup[inner[:, 1]])
            k += len(ids)
        self.n_params = k
        self.groups = sorted(groups)
        r, c = np.concatenate(lap_rows), np.concatenate(lap_cols)
        d = sp.csr_matrix((np.ones(len(r)), (np.arange(len(r)), r)), shape=(len(r), k)) - \
            sp.csr_matrix((np.ones(len(r)), (np.arange(len(r)), c)), shape=(len(r), k))
        self.diff = d.tocsr()  # (E, P) edge differences inside each zone
        self.smooth, self.pull = smooth, pull
        self.gains = np.ones(k)
        self.shares = {"EyeLookUp": 0.0, "EyeLookDown": 0.0}
        self.fit_shares = True  # False: the shares stay as set (the ARKit map's)

    def shape_values(self, s: Shape) -> np.ndarray:
        return coupled_values(self.model, self.shares, s)

    def _forces(self, gains: np.ndarray, values: np.ndarray) -> np.ndarray:
        """(3N, S) nodal force of each shape at those gains."""
        f = np.zeros((len(values), self.n, 3))
        ci = self.model.channel_index
        for c in self.channels:
            v = values[:, ci[c]]
            if not np.any(v):
                continue
            fc = self.field[c] * gains[self.par[c]][:, None]
            f[:, self.vert[c]] += v[:, None, None] * fc[None]
        return f.reshape(len(values), -1).T

    def _solve(self, rhs: np.ndarray) -> np.ndarray:
        out = np.zeros_like(rhs)
        out[self.free] = self.lu.solve(np.ascontiguousarray(rhs[self.free]))
        return out

    def predict(self, s: Shape) -> np.ndarray:
        """(N, 3) linear displacement of one shape."""
        return self.predict_all([s])[0]

    def predict_all(self, items: list[Shape], gains: np.ndarray | None = None) -> np.ndarray:
        """(S, N, 3) linear displacement of each shape."""
        vals = np.array([self.shape_values(s) for s in items])
        u = self._solve(self._forces(self.gains if gains is None else gains, vals))
        return u.T.reshape(len(items), self.n, 3)

    def fit(self, items: list[Shape], offsets: dict[str, np.ndarray], iters: int = 400) -> None:
        """The gains by L-BFGS-B over `items` (offsets: what the linear model misses)."""
        from scipy.optimize import minimize

        vals = np.array([self.shape_values(s) for s in items])
        b = np.stack([(s.target - offsets[s.label]).ravel() for s in items], axis=1)
        w = np.array([1.0 / float(np.sum(s.target**2)) for s in items])

        def objective(g: np.ndarray) -> tuple[float, np.ndarray]:
            return self.objective(g, vals, b, w)

        res = minimize(objective, np.clip(self.gains, 0.0, MAX_GAIN), jac=True, method="L-BFGS-B",
                       bounds=[(0.0, MAX_GAIN)] * self.n_params, options={"maxiter": iters})
        self.gains = res.x
        self._fit_shares(items, offsets)

    def objective(self, g: np.ndarray, vals: np.ndarray, b: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray]:
        """The weighted squared misfit of every shape (values (S,C), targets b (3N,S), weights (S,))
        plus the smoothness and the pull, and its gradient in the gains (one adjoint solve a shape)."""
        r = self._solve(self._forces(g, vals)) - b
        lam = 2.0 * self._solve(r * w[None]).T.reshape(len(w), self.n, 3)  # dE/dF per shape
        penalty, grad = self._penalty(g)
        return float(np.sum(w * np.sum(r * r, axis=0))) + penalty, self._gain_gradient(g, vals, lam) + grad

    def _gain_gradient(self, g: np.ndarray, vals: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """The misfit's gradient in the gains, given dE/dF per shape `lam` (S,N,3): each channel's
        field over its zone, times its value in each shape."""
        grad = np.zeros_like(g)
        ci = self.model.channel_index
        for c in self.channels:
            v = vals[:, ci[c]]
            if np.any(v):
                np.add.at(grad, self.par[c], np.einsum("s,svk,vk->v", v, lam[:, self.vert[c]], self.field[c]))
        return grad

    def _penalty(self, g: np.ndarray) -> tuple[float, np.ndarray]:
        """The gains' smoothness and pull towards 1, and their gradient."""
        dg = self.diff @ g
        val = self.smooth * float(dg @ dg) + self.pull * float(np.sum((g - 1.0) ** 2))
        return val, 2.0 * self.smooth * (self.diff.T @ dg) + 2.0 * self.pull * (g - 1.0)

    def _fit_shares(self, items: list[Shape], offsets: dict[str, np.ndarray]) -> None:
        """The gaze's share of the lids, one per gaze direction, with the gains fixed."""
        if not self.fit_shares:
            return
        for name in self.shares:
            chosen = [s for s in items if s.coupling and s.coupling[1] == name]
            if not chosen:
                continue
            v0 = np.array([s.values for s in chosen])
            v1 = v0.copy()
            for i, s in enumerate(chosen):
                v1[i, self.model.channel_index[s.coupling[0]]] = 1.0  # type: ignore[index]
            base = self._solve(self._forces(self.gains, v0))
            col = self._solve(self._forces(self.gains, v1)) - base
            r = np.stack([(s.target - offsets[s.label]).ravel() for s in chosen], axis=1) - base
            den = float(np.sum(col * col))
            if den > 0:
                self.shares[name] = float(np.clip(np.sum(col * r) / den, 0.0, 1.0))

    def insertion(self) -> dict[str, np.ndarray]:
        """Per channel the (N,) insertion gain the rig stores (1 outside the zone: the field is 0 there)."""
        out = {}
        for c in self.channels:
            g = np.ones(self.n)
            g[self.vert[c]] = self.gains[self.par[c]]
            out[c] = np.round(np.maximum(g, 0.0), 4)
        return out
