"""How far active strain could bring the scanned face to the scans, in the linear statics (run by hand).

Every scanned ARKit shape (left and right apart, `scan_match.scan_targets`) is driven with the
channels the shipped ARKit map gives it (`shape_channels`) and settled on the shipped rig, as
`scan_match.py --no-fit` does. On top of that settled pose, each muscle channel gets an active
strain field (`sim.face.scan.strain_fit`: a change of the skin's spring rest lengths over the
muscle's zone, scaled by the channel's value, the sides mirrored), fitted in the linear statics of
the shipped skin (bending included) to what the settled pose misses, on the left and unsided
shapes; the right ones are held out. Prints per shape the settled relative error (0 = the scan,
1 = as wrong as not moving) and the linear model's prediction with the fitted fields.

    nice .venv/bin/python benchmarks/strain_limits.py [--smooth 3e-3] [--ridge 1e-4] [--bound 0.4] [--iters 300]
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smooth", type=float, default=3e-3)
    ap.add_argument("--ridge", type=float, default=1e-4)
    ap.add_argument("--bound", type=float, default=0.4)
    ap.add_argument("--iters", type=int, default=300)
    ap.add_argument("--settled", type=Path, help="cache of the shipped rig's settled poses (read if present, else written)")
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
    cal = StrainCalibration(model, smooth=args.smooth, ridge=args.ridge, bound=args.bound)
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
    strains = np.concatenate([s[s != 0] for s in cal.spring_strain().values()])
    print(f"spring strains at full value: |s| median {np.median(np.abs(strains)):.3f}, "
          f"95th percentile {np.percentile(np.abs(strains), 95):.3f}, max {np.abs(strains).max():.3f}")
    np.savez(Path("/tmp") / "strain_fit_params.npz", params=cal.params)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
