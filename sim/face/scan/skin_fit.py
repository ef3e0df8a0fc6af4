"""The scanned head's skin material, fitted to its scanned expressions jointly with the insertions.

Uniform skin, attached uniformly to the tissue beneath, spreads every muscle's pull broadly; real
facial skin is held by retaining ligaments at some places (the orbital rim, the zygoma, the
mandible) and slides over fat pads at others (the malar and nasolabial fat, the lids). This fits,
on top of `sim.face.scan.insertion_fit`'s per-vertex insertion gains, three smooth non-negative
fields over the skin: multipliers of its tether to the tissue beneath (`SkinParams.tether`), of its
support against indentation along the normal (`SkinParams.support`) and of its springs' modulus
(`SkinParams.sheet_modulus`, bending included; a spring takes the mean of its ends'). Each field
is exp(sum_b theta_b phi_b(x)) over smooth bumps phi_b (a partition of unity over the skin, the
right side's bumps mirroring the left's and sharing their parameters), so it is positive, smooth
and symmetric; theta is bounded (the multipliers stay within LOW..HIGH) and pulled weakly to 0.

The statics are linear in the forces but not in the fields: u = K(theta)^-1 F(g). The gradient in
the gains is one adjoint solve per shape (`insertion_fit`); in a field, with lambda = K^-1 dE/du
(K symmetric), dE/dk = -lambda^T (dK/dk) u, which for a vertex's tether is -k_t lambda_i . u_i,
for its support -k_n (lambda_i . n_i)(u_i . n_i), for a spring's modulus
-k_s (d . (lambda_j - lambda_i))(d . (u_j - u_i)). K is refactorised once an iteration.
The rig stores the fields per vertex (`FaceRig.skin`); identities carry them unchanged.
"""

from __future__ import annotations

import numpy as np

from sim.face.scan.calibrate import MAX_GAIN, Shape, _bumps
from sim.face.scan.insertion_fit import VertexCalibration

FIELDS = ("tether", "support", "modulus")
BUMPS = 40  # bumps on one side (and the midline) per field
LOW, HIGH = 0.4, 2.5  # bounds of each multiplier (0.1..10 fitted laxer skin that read worse)
PULL_FIELD = 1e-3  # weight of the pull of theta towards 0 (multiplier 1), per parameter
MIDLINE = 0.4  # cm: bump centres closer than this to x = 0 have no mirror image


class SkinCalibration(VertexCalibration):
    """The linear model of one compiled face with per-vertex insertion gains and the skin's fields."""

    def __init__(self, model, bumps: int = BUMPS, fields: tuple[str, ...] = FIELDS,  # type: ignore[no-untyped-def]
                 low: float = LOW, high: float = HIGH, pull_field: float = PULL_FIELD,
                 fixed: frozenset[str] = frozenset()) -> None:
        import scipy.sparse as sp

        super().__init__(model, fixed=fixed)
        rest, n = self.rest, self.n
        held = np.asarray(model.held, bool)
        self.fields = fields
        self.k_tether = np.asarray(model.rest_stiffness, float)
        self.k_support = np.asarray(model.support_stiffness, float)
        self.normal = np.asarray(model.rest_normal, float)
        springs = np.asarray(model.spring_indices, np.int64)
        self.si, self.sj = springs[:, 0], springs[:, 1]
        d = rest[self.sj] - rest[self.si]
        self.sdir = d / np.linalg.norm(d, axis=1)[:, None]
        self.k_spring = np.asarray(model.spring_k_low, float)
        left, centres = _bumps(rest, ~held & (rest[:, 0] >= -0.05), bumps)
        del left
        mirrored = centres[:, 0] > MIDLINE
        every = np.concatenate([centres, centres[mirrored] * np.array([-1.0, 1.0, 1.0])])
        owner = np.concatenate([np.arange(len(centres)), np.flatnonzero(mirrored)])
        phi, _ = _bumps(rest, np.ones(n, bool), 0, every)
        share = sp.csr_matrix((np.ones(len(owner)), (np.arange(len(owner)), owner)), shape=(len(owner), len(centres)))
        self.basis = (sp.csr_matrix(phi.T) @ share).tocsr()  # (N, B): each vertex's weight per parameter
        self.n_bumps = len(centres)
        self.bounds = (float(np.log(low)), float(np.log(high)))
        self.pull_field = pull_field
        self.theta = np.zeros(self.n_bumps * len(fields))
        # the stiffness' entries as fixed patterns times the fields' values
        a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        uu = self.sdir[:, :, None] * self.sdir[:, None, :]
        rows, cols, vals = [], [], []
        for p, q, sign in ((self.si, self.si, 1.0), (self.sj, self.sj, 1.0), (self.si, self.sj, -1.0), (self.sj, self.si, -1.0)):
            rows.append((3 * p[:, None, None] + a).ravel())
            cols.append((3 * q[:, None, None] + b).ravel())
            vals.append((sign * uu).ravel())
        vr = (3 * np.arange(n)[:, None, None] + a[None]).ravel()
        vc = (3 * np.arange(n)[:, None, None] + b[None]).ravel()
        self._rows = np.concatenate(rows + [vr, vr])
        self._cols = np.concatenate(cols + [vc, vc])
        self._spring_pattern = np.concatenate(vals)
        self._spring_of = np.tile(np.repeat(np.arange(len(self.k_spring)), 9), 4)
        self._eye = np.broadcast_to(np.eye(3), (n, 3, 3)).ravel()
        self._nn = (self.normal[:, :, None] * self.normal[:, None, :]).ravel()
        self._vertex_of = np.repeat(np.arange(n), 9)
        self._factored: bytes | None = None
        self.factor(self.theta)

    def multipliers(self, theta: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Per field the (N,) multiplier at theta (1 for a field not fitted)."""
        t = self.theta if theta is None else theta
        out = {f: np.ones(self.n) for f in FIELDS}
        for i, f in enumerate(self.fields):
            out[f] = np.exp(self.basis @ t[i * self.n_bumps:(i + 1) * self.n_bumps])
        return out

    def factor(self, theta: np.ndarray) -> dict[str, np.ndarray]:
        """Factorises K at theta (once per theta); returns the multipliers."""
        import scipy.sparse as sp
        from scipy.sparse.linalg import splu

        mu = self.multipliers(theta)
        if self._factored != theta.tobytes():
            ks = self.k_spring * 0.5 * (mu["modulus"][self.si] + mu["modulus"][self.sj])
            vals = np.concatenate([self._spring_pattern * ks[self._spring_of],
                                   self._eye * (self.k_tether * mu["tether"])[self._vertex_of],
                                   self._nn * (self.k_support * mu["support"])[self._vertex_of]])
            k = sp.csr_matrix((vals, (self._rows, self._cols)), shape=(3 * self.n, 3 * self.n))
            self.lu = splu(k[self.free][:, self.free].tocsc())
            self._factored = theta.tobytes()
        return mu

    def joint_objective(self, x: np.ndarray, vals: np.ndarray, b: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray]:
        """The weighted squared misfit of every shape plus the penalties, and its gradient in the
        gains and the fields' parameters x = [gains, theta]."""
        g, theta = x[:self.n_params], x[self.n_params:]
        mu = self.factor(theta)
        u = self._solve(self._forces(g, vals))
        r = u - b
        lam = self._solve(2.0 * r * w[None])
        s = len(w)
        uu = u.T.reshape(s, self.n, 3)
        ll = lam.T.reshape(s, self.n, 3)
        penalty, grad_g = self._penalty(g)
        grad_g += self._gain_gradient(g, vals, ll)
        val = float(np.sum(w * np.sum(r * r, axis=0))) + penalty + self.pull_field * float(theta @ theta)
        grads = [grad_g]
        for f in self.fields:
            if f == "tether":
                dm = -self.k_tether * np.einsum("svk,svk->v", ll, uu)
            elif f == "support":
                dm = -self.k_support * np.sum(np.einsum("svk,vk->sv", ll, self.normal)
                                              * np.einsum("svk,vk->sv", uu, self.normal), axis=0)
            else:
                du = np.einsum("sek,ek->se", uu[:, self.sj] - uu[:, self.si], self.sdir)
                dl = np.einsum("sek,ek->se", ll[:, self.sj] - ll[:, self.si], self.sdir)
                de = -0.5 * self.k_spring * np.sum(dl * du, axis=0)
                dm = np.zeros(self.n)
                np.add.at(dm, self.si, de)
                np.add.at(dm, self.sj, de)
            grads.append(self.basis.T @ (dm * mu[f]))
        out = np.concatenate(grads)
        out[self.n_params:] += 2.0 * self.pull_field * theta
        return val, out

    def fit(self, items: list[Shape], offsets: dict[str, np.ndarray], iters: int = 150) -> None:
        """Gains and fields by L-BFGS-B over `items` (offsets: what the linear model misses)."""
        from scipy.optimize import minimize

        vals = np.array([self.shape_values(s) for s in items])
        b = np.stack([(s.target - offsets[s.label]).ravel() for s in items], axis=1)
        w = np.array([1.0 / float(np.sum(s.target**2)) for s in items])
        x0 = np.concatenate([np.clip(self.gains, 0.0, MAX_GAIN), self.theta])
        bounds = [(0.0, MAX_GAIN)] * self.n_params + [self.bounds] * len(self.theta)
        res = minimize(self.joint_objective, x0, args=(vals, b, w), jac=True, method="L-BFGS-B",
                       bounds=bounds, options={"maxiter": iters})
        self.gains, self.theta = res.x[:self.n_params], res.x[self.n_params:]
        self.factor(self.theta)
        self._fit_shares(items, offsets)

    def skin(self) -> dict[str, np.ndarray]:
        """Per fitted field the (N,) multiplier the rig stores (`FaceRig.skin`)."""
        mu = self.multipliers()
        return {f: np.round(mu[f], 4) for f in self.fields}
