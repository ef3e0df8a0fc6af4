"""How close to the scans the face could come with the lips' contacts or a sliding skin (run by hand).

`scan_limits.py`'s "gains free per shape" measure (in the linear statics of the shipped skin, every
muscle's insertion gain free per skin vertex and per shape, non-negative, Laplacian-smoothed, each
vertex pulled along the muscles' fixed lines of action; the map's settled pose minus its linear
prediction kept as an offset), with one mechanism added at a time:

- lips: the lips pressing on each other. Where the simulated mouth opening's upper and lower
  edges face each other, a pair of equal and opposite forces pushes them apart along the line
  between them, its pressure free per shape, non-negative (a contact pushes, never pulls) and
  smooth along the lip line (the same Laplacian weight as the gains);
- teeth: the same, plus the teeth and gums pushing the skin near them (within `--reach` cm of the
  scanned teeth and gums, the inside of the lips being no part of the simulated skin) outwards,
  along the direction from the nearest tooth or gum point, free, non-negative, smooth over the
  skin's edges: what any contact with the lips' bed could add;
- split: the lips' red part (vermilion) free from the skin above and below it, and each lip's two
  sides free from each other (every muscle's smoothness cut there): the orbicularis oris' marginal
  part per lip and side, which may curl the red lip apart from the skin;
- unheld: the skin below the lower lip that the step holds (under the chin, moved by the jaw's
  weights alone, and the mask's border rows there) free like the rest: what the held skin costs
  the chin's shapes;
- slide:S: the skin's tether to the tissue beneath resisting a tangential slide S times as
  strongly, its normal resistance kept (retinacula cutis lax over fat);
- slide-lig:A:B: the same with the tangential tether A times over fat and B times on the retaining
  ligaments (`sim.face.scan.layers.ligaments`).

A contact variant's bound is loose: the pressure may act wherever the lips might touch, whether or
not they do in the settled pose. Each sliding variant's compliance is scaled so that the placed
muscles move the skin as far as on the shipped sheet (as `layered_limits.py`). Relative RMS error
over the simulated skin (0 = the scan, 1 = as wrong as not moving).

    nice .venv/bin/python benchmarks/contact_limits.py [--shapes mouthPress_L,...]
        [--variants lips,teeth,split,unheld,slide:0.1,slide-lig:0.05:1] [--maxiter 100] [--reach 0.8] [--smooth 1e-3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import scan_limits  # noqa: E402
from scan_limits import Free  # noqa: E402

SHAPES = ("mouthPress_L,mouthClose,mouthShrugLower,mouthDimple_L,mouthRollLower,mouthRollUpper,mouthFunnel,"
          "BrowInnerUp,mouthSmile_L")


def lip_pairs(model) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """The simulated mouth opening's upper edge vertices (K,) in order from corner to corner and
    each one's nearest vertex of the lower edge (K,)."""
    from sim.springs import boundary_loops

    rest = np.asarray(model.rest)
    tri = np.asarray(model.rig.mesh.triangles, np.int64)
    loops = [np.asarray(lp) for lp in boundary_loops(tri)]
    mouth = min((lp for lp in loops if len(lp) < 400), key=lambda lp: rest[lp, 1].mean())
    x = rest[mouth, 0]
    a, b = sorted((int(np.argmin(x)), int(np.argmax(x))))
    arcs = [mouth[a:b + 1], np.concatenate([mouth[b:], mouth[:a + 1]])]
    upper, lower = sorted(arcs, key=lambda arc: -rest[arc, 1].mean())
    upper = upper[1:-1]  # the corners belong to both
    upper = upper[np.argsort(rest[upper, 0])]
    d = np.linalg.norm(rest[upper, None] - rest[None, lower], axis=2)
    return upper, lower[np.argmin(d, axis=1)]


def teeth_contacts(model, reach: float) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """Skin vertices within `reach` cm of the scanned teeth and gums (the sim's numbering) and the
    unit direction each is pushed (from its nearest tooth or gum point)."""
    from scipy.spatial import cKDTree

    from sim.face.scan.anatomy import skin_layout
    from sim.face.scan.data import PARTS, scan_data

    data = scan_data()
    bed = data.neutral[np.concatenate([np.arange(*PARTS[p]) for p in ("teeth", "gums_tongue")])]
    skin = data.neutral[skin_layout().vertices]
    d, j = cKDTree(bed).query(skin)
    near = np.flatnonzero((d < reach) & ~np.asarray(model.held, bool))
    out = skin[near] - bed[j[near]]
    return near, out / np.linalg.norm(out, axis=1, keepdims=True)


class Contact(Free):
    """scan_limits' gains free per shape plus non-negative contact pressures along fixed
    directions: each pressure p_k gives the force p_k * unit * pattern_k, smooth over `links`."""

    def __init__(self, model, teeth_reach: float | None) -> None:  # type: ignore[no-untyped-def]
        import scipy.sparse as sp

        super().__init__(model)
        n = self.n
        upper, lower = lip_pairs(model)
        d = np.asarray(model.rest)[upper] - np.asarray(model.rest)[lower]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        rows, cols, vals = [], [], []  # the (3n, k) pattern matrix
        for k, (i, j) in enumerate(zip(upper, lower, strict=True)):
            for c in range(3):
                rows += [3 * i + c, 3 * j + c]
                cols += [k, k]
                vals += [d[k, c], -d[k, c]]
        links = [(k, k + 1) for k in range(len(upper) - 1)]
        n_c = len(upper)
        self.n_lips = n_c
        self.n_teeth = 0
        if teeth_reach is not None:
            near, out = teeth_contacts(model, teeth_reach)
            look = -np.ones(n, np.int64)
            look[near] = n_c + np.arange(len(near))
            for k, i in enumerate(near):
                for c in range(3):
                    rows.append(3 * i + c)
                    cols.append(n_c + k)
                    vals.append(out[k, c])
            inner = self.edges[(look[self.edges] >= 0).all(axis=1)]
            links += [(int(a), int(b)) for a, b in look[inner]]
            n_c += len(near)
            self.n_teeth = len(near)
        self.pattern = sp.csr_matrix((vals, (rows, cols)), shape=(3 * n, n_c))
        la = np.array(links, np.int64).reshape(-1, 2)
        m = len(la)
        diff_c = (sp.csr_matrix((np.ones(m), (np.arange(m), la[:, 0])), shape=(m, n_c))
                  - sp.csr_matrix((np.ones(m), (np.arange(m), la[:, 1])), shape=(m, n_c)))
        self.n_c = n_c
        self.diff_all = sp.block_diag([self.diff_g, diff_c]).tocsr()

    def best_with_contact(self, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The best displacement and the contact pressures (in units of a typical muscle's nodal force)."""
        ng = self.n_gains

        def force(x: np.ndarray) -> np.ndarray:
            f = np.zeros((self.n, 3))
            g = x[:ng]
            for c, z in self.zone.items():
                f[z] += g[self.offs[c]:self.offs[c] + len(z), None] * self.field[c][z]
            return f + self.unit * (self.pattern @ x[ng:]).reshape(-1, 3)

        def grad_of(lam: np.ndarray) -> np.ndarray:
            out = np.zeros(ng + self.n_c)
            for c, z in self.zone.items():
                out[self.offs[c]:self.offs[c] + len(z)] = np.sum(lam[z] * self.field[c][z], axis=1)
            out[ng:] = self.unit * (self.pattern.T @ lam.ravel())
            return out

        def fit() -> np.ndarray:
            from scipy.optimize import minimize

            w = 1.0 / float(np.sum(b * b))
            diff = self.diff_all

            def obj(x: np.ndarray) -> tuple[float, np.ndarray]:
                r = self.solve(force(x)) - b
                lam = self.adjoint(2.0 * w * r)
                dx = diff @ x
                smooth = scan_limits.SMOOTH
                return (w * float(np.sum(r * r)) + smooth * float(dx @ dx),
                        grad_of(lam) + 2.0 * smooth * (diff.T @ dx))

            x0 = np.zeros(ng + self.n_c)
            return minimize(obj, x0, jac=True, method="L-BFGS-B", bounds=[(0.0, None)] * len(x0),
                            options={"maxiter": self.MAXITER}).x

        x = fit()
        return self.solve(force(x)), x[ng:]


def lip_parts(model) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(N,) int: 0 off the lips, else 1 + (upper lip) * 2 + (the face's left side), each lip's red
    part (vermilion) being the rings of the skin's mesh from the mouth opening up to labrale
    superius (down to labrale inferius); a ring is a vertex's edge count from the opening."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    from sim.springs import boundary_loops

    rest = np.asarray(model.rest)
    tri = np.asarray(model.rig.mesh.triangles, np.int64)
    n = len(rest)
    loops = [np.asarray(lp) for lp in boundary_loops(tri)]
    mouth = min((lp for lp in loops if len(lp) < 400), key=lambda lp: rest[lp, 1].mean())
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    ring = dijkstra(g + g.T, unweighted=True, indices=mouth, min_only=True)
    top, bottom = model.landmark_index("upper_lip_top"), model.landmark_index("lower_lip_bottom")
    centre = 0.5 * (rest[model.landmark_index("upper_lip_center")] + rest[model.landmark_index("lower_lip_center")])
    upper = rest[:, 1] > centre[1]
    red = np.where(upper, ring <= ring[top], ring <= ring[bottom])
    return np.where(red, 1 + 2 * upper + (rest[:, 0] > 0), 0)


class Split(Free):
    """scan_limits' gains free per shape with every muscle's smoothness cut where the lips' red
    part meets the skin and at the lips' midline: the orbicularis oris' marginal part per lip and
    side free apart from the skin above and below it (and from the other side)."""

    def __init__(self, model) -> None:  # type: ignore[no-untyped-def]
        import scipy.sparse as sp

        super().__init__(model)
        part = lip_parts(model)
        keep = part[self.edges[:, 0]] == part[self.edges[:, 1]]
        self.cut = int((~keep).sum())
        edges = self.edges[keep]
        rows, cols = [], []
        for c, z in self.zone.items():
            look = -np.ones(self.n, np.int64)
            look[z] = self.offs[c] + np.arange(len(z))
            inner = edges[(look[edges] >= 0).all(axis=1)]
            rows.append(look[inner[:, 0]])
            cols.append(look[inner[:, 1]])
        r, c2 = np.concatenate(rows), np.concatenate(cols)
        m, k = len(r), self.n_gains
        self.diff_g = (sp.csr_matrix((np.ones(m), (np.arange(m), r)), shape=(m, k))
                       - sp.csr_matrix((np.ones(m), (np.arange(m), c2)), shape=(m, k))).tocsr()


class Unheld(Free):
    """scan_limits' gains free per shape with the held skin below the lower lip (under the chin,
    which the step moves with the jaw alone, and the mask's border rows there) free, tethered as
    the rest of the skin."""

    def __init__(self, model) -> None:  # type: ignore[no-untyped-def]
        from dataclasses import replace

        from sim.face.scan.calibrate import _stiffness

        super().__init__(model)
        rest = np.asarray(model.rest)
        held = np.asarray(model.held, bool)
        below = rest[:, 1] < rest[model.landmark_index("lower_lip_bottom"), 1]
        self.freed = int((held & below).sum())
        self.lu, self.free = _stiffness(replace(model, held=held & ~below))


class Sliding(Free):
    """The shipped sheet with its tether's tangential part scaled by `tangential` (per vertex),
    the normal part kept (moved into the support along the rest normal)."""

    def __init__(self, model, tangential: np.ndarray) -> None:  # type: ignore[no-untyped-def]
        from dataclasses import replace

        from sim.face.scan.calibrate import _stiffness

        super().__init__(model)
        rk = np.asarray(model.rest_stiffness)
        slid = replace(model, rest_stiffness=rk * tangential,
                       support_stiffness=np.asarray(model.support_stiffness) + (1.0 - tangential) * rk)
        self.lu, self.free = _stiffness(slid)
        self.scale = 1.0

    def solve(self, f: np.ndarray) -> np.ndarray:
        return self.scale * super().solve(f)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", default=SHAPES, help="comma-separated scan or ARKit names (BrowInnerUp: both halves)")
    ap.add_argument("--variants", default="lips,teeth,slide:0.1,slide-lig:0.1:1",
                    help="of lips, teeth, split, unheld, slide:S, slide-lig:A:B")
    ap.add_argument("--maxiter", type=int, default=100, help="L-BFGS-B iterations a fit")
    ap.add_argument("--reach", type=float, default=0.8, help="cm from the teeth and gums a contact may act")
    ap.add_argument("--smooth", type=float, default=scan_limits.SMOOTH,
                    help="Laplacian weight per edge of every fit, relative to one shape's own size")
    args = ap.parse_args()
    from sim.face.scan.layers import ligaments

    Free.MAXITER = args.maxiter
    scan_limits.SMOOTH = args.smooth
    t0 = time.monotonic()
    model, targets, values, real, sheet = scan_limits.settled_shapes(args.shapes)
    models: dict[str, Free] = {"sheet": sheet}
    for name in filter(None, args.variants.split(",")):
        if name == "split":
            m = Split(model)
            print(f"split: {m.cut} of the skin's edges cut", flush=True)
        elif name == "unheld":
            m = Unheld(model)
            print(f"unheld: {m.freed} held skin vertices below the lower lip set free", flush=True)
        elif name in ("lips", "teeth"):
            m = Contact(model, args.reach if name == "teeth" else None)
            print(f"{name}: {m.n_lips} lip pairs, {m.n_teeth} skin vertices over the teeth and gums", flush=True)
        else:
            part = name.split(":")
            if part[0] == "slide":
                tang = np.full(model.n_vertices, float(part[1]))
            else:
                lax, tight = float(part[1]), float(part[2])
                tang = lax + (tight - lax) * ligaments(model)
            m = Sliding(model, tang)
            scan_limits.scale_like(name, m, sheet, values)
        models[name] = m
    print(f"settled and built in {time.monotonic() - t0:.0f} s")
    print(f"{'shape':20s} {'map':>5s} " + " ".join(f"{k:>16s}" for k in models))
    red = lip_parts(model) > 0
    mouth = np.linalg.norm(np.asarray(model.rest) - 0.5 * (np.asarray(model.rest)[model.landmark_index("upper_lip_center")]
                                                            + np.asarray(model.rest)[model.landmark_index("lower_lip_center")]),
                           axis=1) < 3.0
    print(f"(where: the share of the sheet's remaining error on the lips' red part ({red.sum()} vertices) and within 3 cm "
          f"of the mouth's centre ({mouth.sum()}))")
    def fit(name: str, m, wanted: np.ndarray) -> tuple[np.ndarray, str | None]:
        if isinstance(m, Contact):
            u, p = m.best_with_contact(wanted)
            return u, f"{name} pressure lips {p[:m.n_lips].sum():.1f} teeth {p[m.n_lips:].sum():.1f}"
        u = m.best_gains(wanted)
        if m is not sheet:
            return u, None
        e = np.sum((u - wanted) ** 2, axis=1)
        return u, f"where: red {e[red].sum() / e.sum():.2f}, mouth {e[mouth].sum() / e.sum():.2f}"

    scan_limits.ceiling_table(targets, real, values, models, fit, 16, t0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
