"""Where on the face, and on what scale, the settled scanned head misses the scans (run by hand).

Every scanned ARKit shape is settled on the shipped rig as `scan_match.py --no-fit` settles it (or
read from `anchor_limits.py --settled FILE`'s cache), and its error against the scan is cut up two
ways: by region of the face (`face_regions.REGIONS`: the lips' inside edge, the red lips, the lids,
the nasolabial band, the nose, the upper lip's skin, the chin, the brows, the forehead, the cheeks,
the rest), each region's share of the squared relative error; and by scale, the share of the
squared relative error in the part of the error finer than 2, 4 and 8 mm (what is left once the
error is diffused over the mesh on that scale), beside the same share of the scan's own motion.
A summary sums the regions over the shapes near the median.

    nice .venv/bin/python benchmarks/scan_residuals.py [--settled FILE] [--band 0.40,0.60]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

STILL_MM = 0.3


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--settled", type=Path, help="cache of the settled poses (anchor_limits.py --settled)")
    ap.add_argument("--band", default="0.40,0.60", help="the relative errors counted as near the median")
    ap.add_argument("--rig", type=Path, help="a rig file of the scanned head instead of the shipped one")
    args = ap.parse_args()
    from anchor_limits import AnchoredSettler, rms
    from face_regions import REGIONS, face_regions, print_scales, print_where, where
    from scan_match import scan_targets

    from puppet.capture.arkit_in import shape_channels
    from puppet.face_cache import scan_model

    if args.rig:
        from sim.build import compile_model
        from sim.face.scan.rig import scan_params
        from sim.rig import load_rig

        model = compile_model(load_rig(args.rig), scan_params())
    else:
        model = scan_model()
    cache = dict(np.load(args.settled)) if args.settled and args.settled.exists() else None
    settler = AnchoredSettler(model) if cache is None else None
    labels, targets, poses = [], [], []
    for label, (shape, target) in scan_targets(None).items():
        if rms(target) * 10 < STILL_MM:
            continue
        labels.append(label)
        targets.append(target)
        if cache is None:
            poses.append(settler.displacement(shape_channels({shape: np.ones(1)}, 1)[0]))  # type: ignore[union-attr]
        else:
            poses.append(cache[label])
    if args.settled and cache is None:
        np.savez(args.settled, **dict(zip(labels, poses)))
    print_where(model, labels, targets, poses, "settled")
    print_scales(model, labels, targets, poses, "settled")
    lo, hi = (float(x) for x in args.band.split(","))
    regions = face_regions(model)
    print(f"vertices per region: " + ", ".join(f"{r} {int(np.sum(regions == k))}" for k, r in enumerate(REGIONS)))
    rel = np.array([rms(p - t) / rms(t) for p, t in zip(poses, targets)])
    near = [k for k in range(len(labels)) if lo <= rel[k] <= hi]
    print(f"median {np.median(rel):.3f}; {len(near)} shapes between {lo} and {hi}: "
          + ", ".join(labels[k] for k in near))
    tot = {r: 0.0 for r in REGIONS}
    mot = {r: 0.0 for r in REGIONS}
    for k in near:
        w = where(model, targets[k], poses[k], regions)
        t2 = np.sum(targets[k] ** 2, axis=1)
        for j, r in enumerate(REGIONS):
            tot[r] += w[r] / len(near)
            mot[r] += float(t2[regions == j].sum() / t2.sum()) / len(near)
    s = sum(tot.values())
    print(f"mean over them: rel^2 {s:.3f} (rel {np.sqrt(s):.3f}); per region its share of rel^2 "
          f"(and of the scan's motion):")
    for r in sorted(REGIONS, key=lambda r: -tot[r]):
        print(f"  {r:15s} {tot[r]:.3f} ({tot[r] / s:.0%} of the error; {mot[r]:.0%} of the motion)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
