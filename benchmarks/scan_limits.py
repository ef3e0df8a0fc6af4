"""How close to the scans the scanned face's physics could come at best, shape by shape (run by hand).

Three ceilings for each chosen shape (relative RMS error over the simulated skin, as
`scan_match.py`: 0 = the scan, 1 = as wrong as not moving), on the shipped rig:

- map: the channels the shipped ARKit map gives the shape, settled (what `scan_match.py` reports);
- span: the best combination, each within its range, of every channel's settled response at full
  value (each channel settled alone on the simulator; a signed channel, the jaw's sideways and the
  like, at both ends), as a linear sum: what any choice of channel values, the ARKit map's weights
  included, could reach;
- gains: in the linear statics of the rig's skin (`sim.face.scan.calibrate`), every muscle's
  insertion gain free per skin vertex and per shape (non-negative, smooth: the Laplacian penalty of
  `insertion_fit`), each vertex still pulled along each muscle's fixed line of action: what fitting
  the muscles' strengths and insertions could reach at best;
- force: the same with the force free in direction too (a smooth 3-vector per vertex of the
  muscles' zones, same smoothness): what fitting the lines of action could add.

What the linear statics miss (the jaw, the lids on the eyes, the skin's stiffening) is the map's
settled pose minus its linear prediction, kept as an offset in the last two.

    nice .venv/bin/python benchmarks/scan_limits.py [--shapes mouthClose,mouthPress_L,...] [--span-only]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

SHAPES = ("mouthClose,mouthShrugLower,mouthPress_L,mouthDimple_L,mouthShrugUpper,BrowInnerUp,CheekPuff,"
          "mouthLowerDown_L,mouthSmile_L,mouthFunnel,browDown_L")
SMOOTH = 1e-3  # Laplacian weight per edge, relative to one shape's own size (as insertion_fit)


def rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def settled_shapes(shapes: str) -> tuple:
    """The scanned head; its scan targets for `shapes` (comma-separated); each shape's channels by
    the ARKit map; the shipped rig's settled displacement for them; the plain sheet's free fit."""
    from scan_match import scan_targets

    from puppet.capture.arkit_in import shape_channels
    from puppet.face_cache import scan_model
    from sim.fit.basis import Settler

    model = scan_model()
    st = Settler(model)
    targets = scan_targets(shapes.split(","))
    values = {label: shape_channels({arkit: np.ones(1)}, 1)[0] for label, (arkit, _) in targets.items()}
    real = {label: st.pose(v) - st.rest for label, v in values.items()}
    return model, targets, values, real, Free(model)


def scale_like(name: str, m, sheet, values: dict) -> None:
    """Scale model m's compliance so its linear statics move the shapes as much as the sheet's do
    (the median ratio over the shapes): the ceilings then compare shapes of motion, not stiffness."""
    ratio = [rms(sheet.linear(v)) / rms(m.linear(v)) for v in values.values()]
    m.scale = float(np.median(ratio))
    print(f"{name}: compliance scaled by {m.scale:.2f} (per shape {min(ratio):.2f}..{max(ratio):.2f})", flush=True)


def ceiling_table(targets: dict, real: dict, values: dict, models: dict, fit, width: int, t0: float) -> None:
    """Print, shape by shape as each is fitted, the map's relative error and each model's ceiling,
    then their medians. `fit(name, model, wanted)` gives the model's best displacement for `wanted`
    (the scan's displacement less what the model's linear statics leave of the settled pose) and a
    note for the row, or None."""
    rows = []
    for label, (_, target) in targets.items():
        rel = [rms(real[label] - target) / rms(target)]
        notes = []
        for name, m in models.items():
            offset = real[label] - m.linear(values[label])
            u, note = fit(name, m, target - offset)
            if note:
                notes.append(note)
            rel.append(rms(u + offset - target) / rms(target))
        rows.append(rel)
        said = f"; {'; '.join(notes)}" if notes else ""
        print(f"{label:20s} " + f"{rel[0]:5.2f} " + " ".join(f"{r:{width}.3f}" for r in rel[1:]) +
              f"   ({time.monotonic() - t0:.0f} s{said})", flush=True)
    med = np.median(np.array(rows), axis=0)
    print(f"{'median':20s} {med[0]:5.2f} " + " ".join(f"{r:{width}.3f}" for r in med[1:]))


class Free:
    """Per-shape free fits in the rig's linear statics: gains per (muscle, zone vertex) along the
    fixed lines of action, or a free smooth force per zone vertex."""

    MAXITER = 500  # L-BFGS-B iterations of each free fit

    def __init__(self, model) -> None:  # type: ignore[no-untyped-def]
        import scipy.sparse as sp

        from sim.build import vertex_normals
        from sim.face.scan.calibrate import _stiffness
        from sim.muscles import muscle_field

        self.model = model
        rig = model.rig
        rest = np.asarray(model.rest)
        self.n = n = len(rest)
        self.lu, self.free = _stiffness(model)
        normal = vertex_normals(rest, np.asarray(rig.mesh.triangles, np.int32))
        self.field = {}
        for c in rig.muscles:
            if c in model.channel_index:
                f = muscle_field(rig.muscles[c], rest, np.asarray(model.area), normal)
                g = rig.insertion.get(c)
                self.field[c] = f * (np.ones(n) if g is None else np.asarray(g))[:, None]
        tri = np.asarray(rig.mesh.triangles, np.int64)
        e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        self.edges = np.unique(np.sort(e[(e < n).all(axis=1)], axis=1), axis=0)
        # gains: one parameter per (channel, vertex of its zone)
        self.zone, offs, rows, cols = {}, {}, [], []
        k = 0
        for c, f in self.field.items():
            mag = np.linalg.norm(f, axis=1)
            z = np.flatnonzero(mag > 1e-3 * mag.max()) if mag.max() > 0 else np.zeros(0, np.int64)
            self.zone[c] = z
            look = -np.ones(n, np.int64)
            look[z] = k + np.arange(len(z))
            inner = self.edges[(look[self.edges] >= 0).all(axis=1)]
            rows.append(look[inner[:, 0]])
            cols.append(look[inner[:, 1]])
            offs[c] = k
            k += len(z)
        self.offs, self.n_gains = offs, k
        r, c2 = np.concatenate(rows), np.concatenate(cols)
        m = len(r)
        self.diff_g = (sp.csr_matrix((np.ones(m), (np.arange(m), r)), shape=(m, k))
                       - sp.csr_matrix((np.ones(m), (np.arange(m), c2)), shape=(m, k))).tocsr()
        # free force: a 3-vector per vertex of the union of zones, in units of a typical muscle's
        # nodal force (the median over the zones), so its smoothness weighs like the gains'
        union = np.zeros(n, bool)
        for z in self.zone.values():
            union[z] = True
        self.fv = np.flatnonzero(union)
        look = -np.ones(n, np.int64)
        look[self.fv] = np.arange(len(self.fv))
        inner = self.edges[(look[self.edges] >= 0).all(axis=1)]
        m = len(inner)
        d = (sp.csr_matrix((np.ones(m), (np.arange(m), look[inner[:, 0]])), shape=(m, len(self.fv)))
             - sp.csr_matrix((np.ones(m), (np.arange(m), look[inner[:, 1]])), shape=(m, len(self.fv))))
        self.diff_f = sp.kron(d, sp.eye(3)).tocsr()
        self.unit = float(np.median(np.concatenate([np.linalg.norm(self.field[c][z], axis=1)
                                                    for c, z in self.zone.items() if len(z)])))

    def solve(self, f: np.ndarray) -> np.ndarray:
        out = np.zeros(3 * self.n)
        out[self.free] = self.lu.solve(np.ascontiguousarray(f.ravel()[self.free]))
        return out.reshape(self.n, 3)

    def adjoint(self, r: np.ndarray) -> np.ndarray:
        """The transpose of `solve` applied to r (N,3): solve itself, the stiffness being symmetric."""
        return self.solve(r)

    def linear(self, values: np.ndarray) -> np.ndarray:
        f = np.zeros((self.n, 3))
        for c, fc in self.field.items():
            f += values[self.model.channel_index[c]] * fc
        return self.solve(f)

    def _fit(self, b: np.ndarray, x0: np.ndarray, force, grad_of, diff, lo) -> np.ndarray:  # type: ignore[no-untyped-def]
        from scipy.optimize import minimize

        w = 1.0 / float(np.sum(b * b))

        def obj(x: np.ndarray) -> tuple[float, np.ndarray]:
            r = self.solve(force(x)) - b
            lam = self.adjoint(2.0 * w * r)
            dx = diff @ x
            return (w * float(np.sum(r * r)) + SMOOTH * float(dx @ dx),
                    grad_of(lam) + 2.0 * SMOOTH * (diff.T @ dx))

        res = minimize(obj, x0, jac=True, method="L-BFGS-B", bounds=[(lo, None)] * len(x0),
                       options={"maxiter": self.MAXITER})
        return self.solve(force(res.x))

    def best_gains(self, b: np.ndarray) -> np.ndarray:
        def force(g: np.ndarray) -> np.ndarray:
            f = np.zeros((self.n, 3))
            for c, z in self.zone.items():
                f[z] += g[self.offs[c]:self.offs[c] + len(z), None] * self.field[c][z]
            return f

        def grad_of(lam: np.ndarray) -> np.ndarray:
            out = np.zeros(self.n_gains)
            for c, z in self.zone.items():
                out[self.offs[c]:self.offs[c] + len(z)] = np.sum(lam[z] * self.field[c][z], axis=1)
            return out

        return self._fit(b, np.zeros(self.n_gains), force, grad_of, self.diff_g, 0.0)

    def best_force(self, b: np.ndarray) -> np.ndarray:
        def force(q: np.ndarray) -> np.ndarray:
            f = np.zeros((self.n, 3))
            f[self.fv] = self.unit * q.reshape(-1, 3)
            return f

        def grad_of(lam: np.ndarray) -> np.ndarray:
            return self.unit * lam[self.fv].ravel()

        return self._fit(b, np.zeros(3 * len(self.fv)), force, grad_of, self.diff_f, None)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", default=SHAPES,
                    help="comma-separated scan or ARKit names (BrowInnerUp, CheekPuff: both halves; "
                         "default: the worst and a few good)")
    ap.add_argument("--span-only", action="store_true", help="only the map and the channels' span (no free fits)")
    args = ap.parse_args()
    from scipy.optimize import lsq_linear
    from scan_match import scan_targets

    from puppet.capture.arkit_in import shape_channels
    from puppet.face_cache import scan_model
    from sim.channels import CHANNEL_SPECS
    from sim.fit.basis import Settler

    t0 = time.monotonic()
    model = scan_model()
    st = Settler(model)
    targets = scan_targets(args.shapes.split(","))
    cols, names = [], []
    for i, spec in enumerate(CHANNEL_SPECS):
        if spec.kind in ("eyes", "age", "head", "tongue"):
            continue
        for end in (spec.hi, spec.lo):
            if end == spec.default:
                continue
            v = st.defaults.copy()
            v[i] = end
            cols.append((st.pose(v) - st.rest).ravel())
            names.append(f"{spec.name}{'-' if end < spec.default else ''}")
    a = np.array(cols).T
    free = Free(model) if not args.span_only else None
    print(f"{len(names)} channel responses settled, linear model built in {time.monotonic() - t0:.0f} s")
    print(f"{'shape':20s} {'scan mm':>7s} {'map':>5s} {'span':>5s} {'gains':>5s} {'force':>5s}  span's largest channels")
    rows = []
    for label, (arkit, target) in targets.items():
        values = shape_channels({arkit: np.ones(1)}, 1)[0]
        real = st.pose(values) - st.rest
        offset = real - free.linear(values) if free else 0.0
        x = lsq_linear(a, target.ravel(), bounds=(0.0, 1.0)).x
        span = (a @ x).reshape(-1, 3)
        b = target - offset
        poses = [real, span]
        if not args.span_only:
            poses += [free.best_gains(b) + offset, free.best_force(b) + offset]
        rel = [rms(p - target) / rms(target) for p in poses]
        rows.append(rel)
        top = ", ".join(f"{names[i]} {x[i]:.2f}" for i in np.argsort(-x)[:4] if x[i] > 0.02)
        print(f"{label:20s} {10 * rms(target):7.2f} " + " ".join(f"{r:5.2f}" for r in rel) + f"  {top}", flush=True)
    med = np.median(np.array(rows), axis=0)
    print("(gains, force: not run)" if args.span_only else "", end="")
    print(f"{'median':20s} {'':7s} " + " ".join(f"{r:5.2f}" for r in med) + f"   ({time.monotonic() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
