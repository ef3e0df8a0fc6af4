"""How far active strain could bring the scanned face to the scans, in the linear statics (run by hand).

Every scanned ARKit shape (left and right apart, `scan_match.scan_targets`) is driven with the
channels the shipped ARKit map gives it (`shape_channels`) and settled on the shipped rig, as
`scan_match.py --no-fit` does. On top of that settled pose, each muscle channel gets an active
strain field (`sim.face.scan.strain_fit`: a change of the skin's spring rest lengths over the
muscle's zone, scaled by the channel's value, the sides mirrored), fitted in the linear statics of
the shipped skin (bending included) to what the settled pose misses, on the left and unsided
shapes; the right ones are held out. Prints per shape the settled relative error (0 = the scan,
1 = as wrong as not moving) and the linear model's prediction with the fitted fields.

`--settle` writes the fitted fields into the rig (`FaceRig.strain`) and settles every shape on the
simulator with them (`--write RIG` keeps that rig); `--free SHAPES` instead fits, per named shape, a
strain free over the whole skin for that shape alone (no zone, no sharing); `--no-bending` leaves
the step's bending terms out of the statics; `--settled FILE` caches the shipped rig's settled poses.
docs/scan-face.md ("Active strain") has the figures.

    nice .venv/bin/python benchmarks/strain_limits.py [--smooth 1e-3] [--ridge 1e-4] [--bound 0.4] [--iters 300]
        [--settle [--write RIG]] [--free SHAPES] [--no-bending] [--all] [--settled FILE]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

STILL_MM = 0.3


def rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def free_strain(model, b: np.ndarray, smooth: float, bound: float, iters: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The linear displacement of a strain free over the whole skin for one shape alone (its
    residual b (N, 3)), smooth as the channels' (same weights), fitted by L-BFGS-B."""
    import scipy.sparse as sp
    from scipy.optimize import minimize

    from sim.face.scan.strain_fit import spring_strain_matrix, step_stiffness

    rest = np.asarray(model.rest)
    n = len(rest)
    springs = np.asarray(model.spring_indices, np.int64)
    lu, free = step_stiffness(model)
    par = np.arange(n)
    s_mat = spring_strain_matrix(rest, springs, np.arange(len(springs)), par, n, False)
    i, j = springs[:, 0], springs[:, 1]
    d = rest[i] - rest[j]
    d /= np.linalg.norm(d, axis=1)[:, None]
    kl0 = np.asarray(model.spring_k_low) * np.asarray(model.spring_rest_length)
    m = len(springs)
    g = sp.csr_matrix((np.concatenate([(d * kl0[:, None]).ravel(), (-d * kl0[:, None]).ravel()]),
                       (np.concatenate([(3 * i[:, None] + np.arange(3)).ravel(), (3 * j[:, None] + np.arange(3)).ravel()]),
                        np.concatenate([np.repeat(np.arange(m), 3)] * 2))), shape=(3 * n, m))
    t = (g @ s_mat).tocsr()
    tri = np.asarray(model.triangles, np.int64)
    e = np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1), axis=0)
    d1 = (sp.csr_matrix((np.ones(len(e)), (np.arange(len(e)), e[:, 0])), shape=(len(e), n))
          - sp.csr_matrix((np.ones(len(e)), (np.arange(len(e)), e[:, 1])), shape=(len(e), n)))
    diff = sp.kron(d1, sp.eye(6)).tocsr()
    w = 1.0 / float(np.sum(b**2))

    def solve(f: np.ndarray) -> np.ndarray:
        out = np.zeros_like(f)
        out[free] = lu.solve(np.ascontiguousarray(f[free]))
        return out

    def obj(p: np.ndarray) -> tuple[float, np.ndarray]:
        r = solve(t @ p) - b.ravel()
        lam = 2.0 * w * solve(r)
        dp = diff @ p
        return (w * float(r @ r) + smooth * float(dp @ dp) + 1e-4 * float(p @ p),
                t.T @ lam + 2.0 * smooth * (diff.T @ dp) + 2e-4 * p)

    res = minimize(obj, np.zeros(6 * n), jac=True, method="L-BFGS-B", bounds=[(-bound, bound)] * (6 * n),
                   options={"maxiter": iters, "ftol": 1e-12, "gtol": 1e-10})
    return solve(t @ res.x).reshape(n, 3)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smooth", type=float, default=1e-3, help="Laplacian weight per edge and component")
    ap.add_argument("--ridge", type=float, default=1e-4, help="pull of each strain component towards 0")
    ap.add_argument("--bound", type=float, default=0.4, help="bound of each strain component")
    ap.add_argument("--iters", type=int, default=300, help="L-BFGS-B iterations at most")
    ap.add_argument("--settled", type=Path, help="cache of the shipped rig's settled poses (read if present, else written)")
    ap.add_argument("--no-bending", action="store_true", help="the linear statics without the step's bending terms")
    ap.add_argument("--settle", action="store_true", help="also settle every shape on the simulator with the fitted fields")
    ap.add_argument("--write", type=Path, help="with --settle: write the rig with the fitted fields here")
    ap.add_argument("--free", metavar="SHAPES",
                    help="instead: per named shape, a strain free over the whole skin for that shape alone")
    ap.add_argument("--all", action="store_true", help="fit on all shapes (no held-out right ones)")
    args = ap.parse_args()
    from scan_match import scan_targets

    from puppet.capture.arkit_in import shape_channels
    from puppet.face_cache import scan_model
    from sim.face.scan.strain_fit import StrainCalibration
    from sim.fit.basis import Settler

    t0 = time.monotonic()
    model = scan_model()
    settler = Settler(model)
    cache = dict(np.load(args.settled)) if args.settled and args.settled.exists() else None
    labels, vals, targets, real = [], [], [], []
    for label, (shape, target) in scan_targets(None).items():
        if rms(target) * 10 < STILL_MM:
            continue
        v = shape_channels({shape: np.ones(1)}, 1)[0]
        labels.append(label)
        vals.append(v)
        targets.append(target)
        real.append(settler.pose(v) - settler.rest if cache is None else cache[label])
    vals_a = np.array(vals)
    if args.settled and cache is None:
        np.savez(args.settled, **dict(zip(labels, real)))
    print(f"{len(labels)} shapes settled in {time.monotonic() - t0:.0f} s", flush=True)
    if args.free:
        for name in args.free.split(","):
            k = labels.index(name)
            u = free_strain(model, targets[k] - real[k], args.smooth, args.bound, args.iters)
            print(f"{name:22s} settled {rms(real[k] - targets[k]) / rms(targets[k]):.3f}  "
                  f"+ a free strain over the whole skin (linear) {rms(real[k] + u - targets[k]) / rms(targets[k]):.3f}",
                  flush=True)
        return 0
    cal = StrainCalibration(model, smooth=args.smooth, ridge=args.ridge, bound=args.bound, bending=not args.no_bending)
    print(f"strain fields: {cal.n_params} parameters over {len(cal.groups)} muscles "
          f"({time.monotonic() - t0:.0f} s)", flush=True)
    train = [k for k, lab in enumerate(labels) if args.all or not lab.endswith("_R")]
    b = np.stack([(targets[k] - real[k]).ravel() for k in train], axis=1)
    w = np.array([1.0 / float(np.sum(targets[k] ** 2)) for k in train])
    res = cal.fit(vals_a[train], b, w, iters=args.iters)
    print(f"fitted in {time.monotonic() - t0:.0f} s: {res.nit} iterations, {res.message}", flush=True)
    add = cal.predict_all(vals_a)
    before, after = [], []
    print(f"{'shape':22s} {'settled':>8s} {'+strain':>8s}")
    for k, lab in enumerate(labels):
        r0 = rms(real[k] - targets[k]) / rms(targets[k])
        r1 = rms(real[k] + add[k] - targets[k]) / rms(targets[k])
        before.append(r0)
        after.append(r1)
        print(f"{lab:22s} {r0:8.3f} {r1:8.3f}{'' if k in train else '  (held out)'}")
    before_a, after_a = np.array(before), np.array(after)
    held = np.array([k not in train for k in range(len(labels))])
    for what, m in (("all", np.ones(len(labels), bool)), ("fitted", ~held), ("held out", held)):
        if m.any():
            print(f"{what} ({m.sum()}): settled median {np.median(before_a[m]):.3f} max {before_a[m].max():.3f}; "
                  f"with strain (linear) median {np.median(after_a[m]):.3f} max {after_a[m].max():.3f}, "
                  f"{int(np.sum(after_a[m] > 0.6))} above 0.6")
    if args.settle:  # the fitted fields written into the rig, compiled, each shape settled on the simulator
        from dataclasses import replace

        from sim.build import compile_model

        strained = compile_model(replace(model.rig, strain=cal.strain()), model.params)
        st = Settler(strained)
        sim_rel = np.array([rms(st.pose(vals[k]) - st.rest - targets[k]) / rms(targets[k]) for k in range(len(labels))])
        for k, lab in enumerate(labels):
            print(f"  settled with strain {lab:22s} {sim_rel[k]:.3f}")
        for what, m in (("all", np.ones(len(labels), bool)), ("fitted", ~held), ("held out", held)):
            if m.any():
                print(f"{what} ({m.sum()}): settled with strain on the simulator median {np.median(sim_rel[m]):.3f} "
                      f"max {sim_rel[m].max():.3f}, {int(np.sum(sim_rel[m] > 0.6))} above 0.6")
        if args.write:
            from sim.rig import save_rig

            save_rig(strained.rig, args.write)
            print(f"wrote {args.write}")
    strains = np.concatenate([s[s != 0] for s in cal.spring_strain().values()])
    print(f"spring strains at full value: |s| median {np.median(np.abs(strains)):.3f}, "
          f"95th percentile {np.percentile(np.abs(strains), 95):.3f}, max {np.abs(strains).max():.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
