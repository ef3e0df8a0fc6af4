"""Fits the scanned head's muscle insertions to its scanned expressions (run by hand).

Each scanned ARKit shape (left and right apart; `scan_match.scan_targets`) is driven with the channels
the ARKit import gives it at 1 (`puppet.capture.arkit_in.shape_channels`, without the gaze's share
of the lids, which is fitted here); `sim.face.scan.calibrate` fits the insertion gains and the gaze
shares over all of them at once, re-linearised on the simulator, and prints the settled relative
errors. `--holdout` fits on the left and unsided shapes and also reports the right ones, held out.
Without --no-write it rewrites `sim/face/scan/ict_rig.npz` (the shipped part of the fit).

`--skin` also fits the skin's material per region (its tether to the tissue beneath, its normal
support, its springs' modulus: `sim.face.scan.skin_fit`) with the per-vertex gains.

    nice .venv/bin/python benchmarks/calibrate_scan.py [--rounds 2] [--holdout] [--per-vertex | --skin] [--no-write]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from sim.face.scan.calibrate import STILL_CM, Shape, rms, run, shipped  # noqa: E402


def shapes(names: list[str] | None = None) -> list[Shape]:
    """The scanned ARKit shapes with the channel values the ARKit import gives each at 1."""
    from scan_match import scan_targets

    from puppet.capture.arkit_in import shape_channels

    out = []
    for label, (arkit, target) in scan_targets(names).items():
        values = shape_channels({arkit: np.ones(1)}, 1, couple=False)[0]
        coupling = None
        side = "_l" if arkit.endswith("Left") else "_r"
        if arkit.startswith("EyeLookUp"):
            coupling = ("levator_palpebrae" + side, "EyeLookUp")
        elif arkit.startswith("EyeLookDown"):
            coupling = ("orbicularis_oculi_lid" + side, "EyeLookDown")
        out.append(Shape(label, arkit, target, values, coupling))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2, help="re-linearisations on the simulator (default 2)")
    ap.add_argument("--holdout", action="store_true", help="fit on the left and unsided shapes only")
    ap.add_argument("--per-vertex", action="store_true",
                    help="fit a gain per skin vertex of each muscle's zone (smooth), not a dozen bumps")
    ap.add_argument("--skin", action="store_true",
                    help="also fit the skin's tether, support and modulus per region (with per-vertex gains)")
    ap.add_argument("--no-write", action="store_true", help="do not rewrite the shipped rig")
    args = ap.parse_args()
    items = [s for s in shapes() if rms(s.target) >= STILL_CM]
    if args.holdout:
        train = [s for s in items if not s.label.endswith("_R")]
        test = [s for s in items if s.label.endswith("_R")]
    else:
        train, test = items, []
    cal, model, _ = run(args.rounds, train, test, per_vertex=args.per_vertex, skin=args.skin)
    if not args.no_write:
        from sim.face.scan.rig import RIG_FILE
        from sim.rig import save_rig

        from sim.face.scan.lids import with_lids

        save_rig(with_lids(replace(model.rig, insertion=shipped(model.rig.insertion))), RIG_FILE)
        print(f"wrote {RIG_FILE}")
    print("gaze shares: " + ", ".join(f"{k} {v:.3f}" for k, v in cal.shares.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
