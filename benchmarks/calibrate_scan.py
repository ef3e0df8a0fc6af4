"""Fits the scanned head's muscle insertions to its scanned expressions (run by hand).

Each scanned ARKit shape (left and right apart; `scan_match.scan_targets`) is driven with the channels
the ARKit import gives it at 1 (`puppet.capture.arkit_in.shape_channels`, without the gaze's share
of the lids, which is fitted here); `sim.face.scan.calibrate` fits the insertion gains and the gaze
shares over all of them at once, re-linearised on the simulator, and prints the settled relative
errors. `--holdout` fits on the left and unsided shapes and also reports the right ones, held out.
Without --no-write it rewrites `sim/face/scan/ict_rig.npz` (the shipped part of the fit).

`--skin` also fits the skin's material per region (its tether to the tissue beneath, its normal
support, its springs' modulus: `sim.face.scan.skin_fit`) with the per-vertex gains. `--keep-skin`
fits the per-vertex gains on the shipped rig's skin instead, `--keep` holds named muscles at the
shipped rig's gains, `--map-shares` holds the gaze's share of the lids at the ARKit map's
(`GAZE_LIDS`), `--without` leaves shapes out of the fit (still reported) and `--ship-all` writes
every fitted gain (without it the bump fit's `NOT_SHIPPED` muscles keep gain 1).

The shipped rig (docs/scan-face.md) is regenerated, bit for bit, by

    nice .venv/bin/python benchmarks/calibrate_scan.py --rounds 1 --keep-skin --map-shares --ship-all \
        --keep orbicularis_oculi,orbicularis_oculi_lid,levator_palpebrae \
        --without eyeBlink,eyeSquint,eyeWide,cheekSquint,eyeLook

(the skin's material and the eye region's gains are read from the file it rewrites and written back
unchanged, so running it again on its own output writes the same file).

    nice .venv/bin/python benchmarks/calibrate_scan.py [--rounds 2] [--holdout] [--per-vertex | --skin | --keep-skin]
        [--keep MUSCLES] [--map-shares] [--without SHAPES] [--ship-all] [--no-write]
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

EYE_REGION = ("eyeBlink", "eyeSquint", "eyeWide", "cheekSquint", "eyeLook")


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
    ap.add_argument("--fibres", action="store_true",
                    help="also fit the muscles' lines of action (attachments, centres, directions) with per-vertex gains")
    ap.add_argument("--keep-skin", action="store_true",
                    help="fit per-vertex gains on the shipped rig's skin material (not fitted, written back)")
    ap.add_argument("--keep", default="", metavar="MUSCLES",
                    help="comma-separated muscles (both sides) held at the shipped rig's gains, not fitted")
    ap.add_argument("--map-shares", action="store_true",
                    help="hold the gaze's share of the lids at the ARKit map's (GAZE_LIDS), not fitted")
    ap.add_argument("--without", default="", metavar="SHAPES",
                    help="comma-separated scan shape names or prefixes left out of the fit (still reported)")
    ap.add_argument("--ship-all", action="store_true",
                    help="write every fitted gain (else the NOT_SHIPPED muscles keep gain 1)")
    ap.add_argument("--no-write", action="store_true", help="do not rewrite the shipped rig")
    args = ap.parse_args()
    items = [s for s in shapes() if rms(s.target) >= STILL_CM]
    left_out = tuple(p for p in args.without.split(",") if p)
    fitted = [s for s in items if not s.label.startswith(left_out)] if left_out else items
    if args.holdout:
        train = [s for s in fitted if not s.label.endswith("_R")]
    else:
        train = fitted
    test = [s for s in items if s not in train]
    shares = None
    if args.map_shares:
        from puppet.export.arkit import GAZE_LIDS

        shares = {k: v for k, (_, v) in GAZE_LIDS.items()}
    keep = tuple(m for m in args.keep.split(",") if m)
    cal, model, real = run(args.rounds, train, test, per_vertex=args.per_vertex, skin=args.skin, keep=keep,
                           keep_skin=args.keep_skin, shares=shares, fibres=args.fibres)
    rel = {s.label: rms(real[s.label] - s.target) / rms(s.target) for s in items}
    print("settled, every shape: median relative error "
          f"{np.median(list(rel.values())):.3f}; without the left-out shapes "
          f"{np.median([rel[s.label] for s in fitted]):.3f}")
    for s in items:
        print(f"  {s.label:22s} {rel[s.label]:.3f}{'' if s in train else '  (not fitted)'}")
    if not args.no_write:
        from sim.face.scan.rig import RIG_FILE
        from sim.rig import save_rig

        gains = model.rig.insertion
        ship = {c: np.round(g, 6) for c, g in gains.items()} if args.ship_all else shipped(gains)
        save_rig(replace(model.rig, insertion=ship), RIG_FILE)
        print(f"wrote {RIG_FILE}")
    print("gaze shares: " + ", ".join(f"{k} {v:.3f}" for k, v in cal.shares.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
