"""How close any pose of the skin could come to a scanned shape (run by hand): a bound on the pose,
not on forces.

Each free vertex's displacement is free (the held skin stays), and L-BFGS-B minimises the squared
error to the scan plus penalties for
- the mouth's lower half (below the lips' meeting line, as wide as the mouth) rising above the
  upper lip's margin at its rest x: the lips' contact's topology, lips that do not pass through
  each other (`sim.margin_contact` keeps the lower margin below the upper one along y);
- an edge stretched beyond S times its rest length, for each S in `--stretch` (each run starts from
  the one before);
- with `--area A`, a triangle whose area projected on its rest normal falls below A times its rest
  area (A 0.25: no triangle turned over).
Prints per S the relative RMS error (as `scan_match.py`), the largest stretch and the largest
crossing left. docs/scan-face.md ("None above 0.6") has the figures for mouthClose.

    nice .venv/bin/python benchmarks/pose_limits.py [--shape mouthClose] [--stretch 100,2,1.5,1.3] [--area 0.25]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

WEIGHT = 1e4  # the penalties' weight against the squared error (cm^2)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="mouthClose")
    ap.add_argument("--stretch", default="100,2,1.5,1.3", help="the largest edge stretches S, run in turn")
    ap.add_argument("--area", type=float, default=0.0, help="the least projected area of a triangle (0: off)")
    ap.add_argument("--iters", type=int, default=3000)
    args = ap.parse_args()
    from scipy.optimize import minimize

    from puppet.face_cache import scan_model
    from scan_match import scan_targets
    from sim.smoothness import margin_rows

    model = scan_model()
    rest = np.asarray(model.rest)
    n = len(rest)
    (_, (_, t)), = scan_targets([args.shape]).items()
    tot = float(np.sum(t * t))
    free = np.flatnonzero(~np.asarray(model.held, bool))
    tri = np.asarray(model.triangles)
    e = np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1), axis=0)
    l0 = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    n0 = np.cross(rest[tri[:, 1]] - rest[tri[:, 0]], rest[tri[:, 2]] - rest[tri[:, 0]])
    a0 = np.sum(n0 * n0, axis=1)
    w_area = WEIGHT * float(np.mean(l0**2)) * 1e2 / np.maximum(a0, 1e-16) ** 2
    up = np.asarray(margin_rows(model.mesh)["lip_upper"])
    up = up[np.argsort(rest[up, 0])]

    def lm(name: str) -> np.ndarray:
        return rest[model.landmark_index(name)]

    centre = 0.5 * (lm("upper_lip_center") + lm("lower_lip_center"))
    low = np.flatnonzero((rest[:, 1] <= centre[1]) & (np.abs(rest[:, 0]) < abs(lm("mouth_corner_l")[0]))
                         & ~np.isin(np.arange(n), up))
    k = np.clip(np.searchsorted(rest[up, 0], rest[low, 0]) - 1, 0, len(up) - 2)
    w = np.clip((rest[low, 0] - rest[up[k], 0]) / (rest[up[k + 1], 0] - rest[up[k], 0]), 0.0, 1.0)
    b0, b1 = up[k], up[k + 1]
    slack = np.maximum(0.0, rest[low, 1] - ((1 - w) * rest[b0, 1] + w * rest[b1, 1]))  # overlap at rest kept

    def parts(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = rest[e[:, 0]] + u[e[:, 0]] - rest[e[:, 1]] - u[e[:, 1]]
        cross = (rest[low, 1] + u[low, 1] - (1 - w) * (rest[b0, 1] + u[b0, 1]) - w * (rest[b1, 1] + u[b1, 1])
                 - slack)
        p = rest[tri] + u[tri]
        c = np.sum(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) * n0, axis=1)
        return d, cross, c

    x = t[free].ravel().copy()
    for s in (float(v) for v in args.stretch.split(",")):
        def f(xv: np.ndarray, s: float = s) -> tuple[float, np.ndarray]:
            u = np.zeros((n, 3))
            u[free] = xv.reshape(-1, 3)
            r = u - t
            g = 2 * r
            d, cross, c = parts(u)
            length = np.linalg.norm(d, axis=1)
            over = np.maximum(0.0, length / l0 - s)
            ge = (2 * WEIGHT * l0 * over / np.maximum(length, 1e-12))[:, None] * d
            np.add.at(g, e[:, 0], ge)
            np.add.at(g, e[:, 1], -ge)
            v = np.maximum(0.0, cross)
            gv = 2 * WEIGHT * v
            np.add.at(g[:, 1], low, gv)
            np.add.at(g[:, 1], b0, -(1 - w) * gv)
            np.add.at(g[:, 1], b1, -w * gv)
            energy = float(np.sum(r * r) + WEIGHT * np.sum(l0 * l0 * over * over) + WEIGHT * np.sum(v * v))
            if args.area > 0.0:
                p = rest[tri] + u[tri]
                ea, eb = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
                short = np.maximum(0.0, args.area * a0 - c)
                energy += float(np.sum(w_area * short * short))
                gc = -2 * w_area * short
                ga, gb = gc[:, None] * np.cross(eb, n0), gc[:, None] * np.cross(n0, ea)
                np.add.at(g, tri[:, 1], ga)
                np.add.at(g, tri[:, 2], gb)
                np.add.at(g, tri[:, 0], -ga - gb)
            return energy / tot, (g[free] / tot).ravel()

        res = minimize(f, x, jac=True, method="L-BFGS-B", options=dict(maxiter=args.iters, maxcor=20))
        x = res.x
        u = np.zeros((n, 3))
        u[free] = x.reshape(-1, 3)
        d, cross, c = parts(u)
        print(f"{args.shape}: edges at most {s:g} x: relative error {np.sqrt(np.sum((u - t) ** 2) / tot):.3f} "
              f"(largest stretch {np.max(np.linalg.norm(d, axis=1) / l0):.2f}, crossing {max(0.0, cross.max()) * 10:.2f} mm, "
              f"{int(np.sum(c < 0))} triangles turned over; {res.nit} iterations)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
