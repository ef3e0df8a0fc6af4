"""The scanned head's muscles' lines of action, fitted to its scanned expressions with their insertions.

`sim.face.scan.insertion_fit` fits how densely each muscle inserts into the skin, each vertex still
pulled along the line the transfer placed: towards a linear muscle's attachment on the skull, the
sphincter's centre, along a sheet's direction or a patch's. This also fits where those lines run:
each linear muscle's attachment point, each sphincter's centre, each sheet's attachment line and
each patch's direction is moved by a fitted offset (cm; for a direction, a unitless one added
before it is normalised again), the right side's the mirror image of the left's (an unsided
muscle's part with its mirror partner among the channel's parts; a part that is its own mirror
image moves in the midline plane only). The offsets are bounded (BOUND) and pulled weakly to 0
(PULL_OFFSET): a muscle keeps its anatomy, its fibres turn.

The statics stay linear in the forces, u = K^-1 F(g, d), so the adjoint of `insertion_fit` gives
dE/dF, lambda per shape; a field's derivative in an offset is taken by central differences of the
muscle's own force law (`sim.muscles`, cheap: no solve). A channel inserts only into the zone its
placed field reached (gain 0 outside it, where the moved field might otherwise reach), so the rig's
`insertion_<channel>` arrays hold the gains over that zone and 0 elsewhere, and the moved muscles
are the rig's own muscles: the simulator and every identity use them unchanged. (`make_rig`
remakes the muscles from the transfer: a rig whose lines of action were fitted is remade by
`benchmarks/calibrate_scan.py --fibres`, which starts from that transfer.)
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.face.scan.calibrate import MAX_GAIN, Shape
from sim.face.scan.insertion_fit import VertexCalibration
from sim.model import LinearMuscle, Muscle, PatchMuscle, SheetMuscle, SphincterMuscle

BOUND = 1.5  # cm (or unitless for a patch's direction): the largest offset along each axis
PULL_OFFSET = 1e-2  # weight of the pull of each offset to 0, per cm^2, relative to one shape's own size
STEP = 1e-3  # cm: central-difference step of a field in an offset
MIRROR = np.array([-1.0, 1.0, 1.0])


def _point(m: Muscle) -> np.ndarray | None:
    """The point (or direction) of a muscle part that its offset moves, None for a part with none
    (a pressure patch pushes along the skin's normal)."""
    if isinstance(m, LinearMuscle):
        return np.asarray(m.attachment, float)
    if isinstance(m, SphincterMuscle):
        return np.asarray(m.center, float)
    if isinstance(m, SheetMuscle):
        return 0.5 * (np.asarray(m.attach1, float) + np.asarray(m.attach2, float))
    if isinstance(m, PatchMuscle) and np.any(m.direction):
        return np.asarray(m.direction, float)
    return None


def moved(m: Muscle, d: np.ndarray) -> Muscle:
    """Muscle part m with its line of action moved by offset d (3,)."""
    if isinstance(m, LinearMuscle):
        return replace(m, attachment=np.asarray(m.attachment, float) + d)
    if isinstance(m, SphincterMuscle):
        return replace(m, center=np.asarray(m.center, float) + d)
    if isinstance(m, SheetMuscle):
        return replace(m, attach1=np.asarray(m.attach1, float) + d, attach2=np.asarray(m.attach2, float) + d)
    if isinstance(m, PatchMuscle) and np.any(m.direction):
        v = np.asarray(m.direction, float) + d
        return replace(m, direction=v / max(float(np.linalg.norm(v)), 1e-9))
    return m


class FibreCalibration(VertexCalibration):
    """Per-vertex insertion gains and the lines of action of every fitted muscle part."""

    def __init__(self, model, fixed: frozenset[str] = frozenset(), pull_offset: float = PULL_OFFSET,  # type: ignore[no-untyped-def]
                 bound: float = BOUND) -> None:
        from sim.build import vertex_normals

        super().__init__(model, fixed=fixed)
        rig = model.rig
        self.normal = vertex_normals(self.rest, np.asarray(rig.mesh.triangles, np.int32))
        self.area = np.asarray(model.area, float)
        self.parts: dict[str, tuple[Muscle, ...]] = {c: tuple(rig.muscles[c]) for c in self.channels}
        # per part: its offset = sign * theta[index] (sign (3,): the mirror's -1 on x, 0 for a part
        # that is its own mirror image)
        self.index: dict[tuple[str, int], np.ndarray] = {}
        self.sign: dict[tuple[str, int], np.ndarray] = {}
        k = 0
        for c in self.channels:
            if c.endswith("_r") and c[:-2] + "_l" in self.parts:
                continue
            own = self.parts[c]
            pts = [_point(m) for m in own]
            taken: dict[int, int] = {}
            for i, (m, p) in enumerate(zip(own, pts)):
                if p is None or i in taken:
                    continue
                mate = i
                if not c.endswith("_l") and not isinstance(m, PatchMuscle):  # unsided: its mirror partner
                    cand = [j for j, q in enumerate(pts) if q is not None and type(own[j]) is type(m) and j not in taken]
                    mate = min(cand, key=lambda j: float(np.linalg.norm(pts[j] - p * MIRROR)))
                    if float(np.linalg.norm(pts[mate] - p * MIRROR)) > 0.3:
                        mate = i
                idx = k + np.arange(3)
                k += 3
                self.index[(c, i)] = idx
                taken[i] = i
                if mate == i:
                    midline = not c.endswith("_l") and abs(p[0]) < 0.3  # moves in the midline plane only
                    self.sign[(c, i)] = np.array([0.0, 1.0, 1.0]) if midline else np.ones(3)
                else:
                    self.sign[(c, i)] = np.ones(3)
                    self.index[(c, mate)] = idx
                    self.sign[(c, mate)] = MIRROR.copy()
                    taken[mate] = i
                if c.endswith("_l"):
                    self.index[(c[:-2] + "_r", i)] = idx
                    self.sign[(c[:-2] + "_r", i)] = MIRROR.copy()
        self.n_offsets = k
        self.theta = np.zeros(k)
        self.pull_offset, self.bound = pull_offset, bound
        self._fields_at(self.theta)

    def _part_field(self, c: str, i: int, d: np.ndarray) -> np.ndarray:
        from sim.muscles import muscle_force

        z = self.vert[c]
        return muscle_force(moved(self.parts[c][i], d), self.rest[z], self.normal[z]) * self.area[z, None]

    def offset(self, c: str, i: int, theta: np.ndarray) -> np.ndarray:
        key = (c, i)
        if key not in self.index:
            return np.zeros(3)
        return self.sign[key] * theta[self.index[key]]

    def _fields_at(self, theta: np.ndarray) -> None:
        """Each fitted channel's nodal force over its zone (self.field) at offsets theta."""
        for c in self.channels:
            self.field[c] = sum(self._part_field(c, i, self.offset(c, i, theta)) for i in range(len(self.parts[c])))

    def joint_objective(self, x: np.ndarray, vals: np.ndarray, b: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray]:
        """The weighted misfit plus penalties, and its gradient in x = [gains, offsets]."""
        g, theta = x[:self.n_params], x[self.n_params:]
        self._fields_at(theta)
        r = self._solve(self._forces(g, vals)) - b
        lam = 2.0 * self._solve(r * w[None]).T.reshape(len(w), self.n, 3)  # dE/dF per shape
        ci = self.model.channel_index
        penalty, grad_g = self._penalty(g)
        grad_g += self._gain_gradient(g, vals, lam)
        val = float(np.sum(w * np.sum(r * r, axis=0))) + penalty
        grad_t = 2.0 * self.pull_offset * theta
        val += self.pull_offset * float(theta @ theta)
        for c in self.channels:
            v = vals[:, ci[c]]
            if not np.any(v):
                continue
            z = self.vert[c]
            a = np.einsum("s,svk->vk", v, lam[:, z]) * g[self.par[c]][:, None]  # dE/d(field) over the zone
            for i in range(len(self.parts[c])):
                if (c, i) not in self.index:
                    continue
                d0 = self.offset(c, i, theta)
                sign, idx = self.sign[(c, i)], self.index[(c, i)]
                for k in range(3):
                    if sign[k] == 0.0:
                        continue
                    e = np.zeros(3)
                    e[k] = STEP
                    df = (self._part_field(c, i, d0 + e) - self._part_field(c, i, d0 - e)) / (2 * STEP)
                    grad_t[idx[k]] += sign[k] * float(np.sum(a * df))
        return val, np.concatenate([grad_g, grad_t])

    def fit(self, items: list[Shape], offsets: dict[str, np.ndarray], iters: int = 150) -> None:
        """Gains and offsets by L-BFGS-B over `items` (offsets: what the linear model misses)."""
        from scipy.optimize import minimize

        vals = np.array([self.shape_values(s) for s in items])
        b = np.stack([(s.target - offsets[s.label]).ravel() for s in items], axis=1)
        w = np.array([1.0 / float(np.sum(s.target**2)) for s in items])
        x0 = np.concatenate([np.clip(self.gains, 0.0, MAX_GAIN), self.theta])
        bounds = [(0.0, MAX_GAIN)] * self.n_params + [(-self.bound, self.bound)] * self.n_offsets
        res = minimize(self.joint_objective, x0, args=(vals, b, w), jac=True, method="L-BFGS-B",
                       bounds=bounds, options={"maxiter": iters})
        self.gains, self.theta = res.x[:self.n_params], res.x[self.n_params:]
        self._fields_at(self.theta)
        self._fit_shares(items, offsets)

    def muscles(self) -> dict[str, tuple[Muscle, ...]]:
        """Every channel's muscle parts with the fitted offsets (the rig's muscles)."""
        out = dict(self.model.rig.muscles)
        for c in self.channels:
            out[c] = tuple(_rounded(moved(m, self.offset(c, i, self.theta))) for i, m in enumerate(self.parts[c]))
        return out

    def insertion(self) -> dict[str, np.ndarray]:
        """Per fitted channel the (N,) gain: the fitted gains over its placed zone, 0 elsewhere."""
        out = {}
        for c in self.channels:
            g = np.zeros(self.n)
            g[self.vert[c]] = self.gains[self.par[c]]
            out[c] = np.round(np.maximum(g, 0.0), 4)
        return out


def _rounded(m: Muscle) -> Muscle:
    """A muscle part with its moved point or direction rounded to 1e-6 (the rig file's digits)."""
    if isinstance(m, LinearMuscle):
        return replace(m, attachment=np.round(m.attachment, 6))
    if isinstance(m, SphincterMuscle):
        return replace(m, center=np.round(m.center, 6))
    if isinstance(m, SheetMuscle):
        return replace(m, attach1=np.round(m.attach1, 6), attach2=np.round(m.attach2, 6))
    if isinstance(m, PatchMuscle):
        return replace(m, direction=np.round(m.direction, 6))
    return m
