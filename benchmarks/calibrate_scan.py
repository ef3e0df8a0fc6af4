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
shipped rig's gains (and, with `--fibres`, their placed lines of action), `--map-shares` holds the
gaze's share of the lids at the ARKit map's (`GAZE_LIDS`), `--without` leaves shapes out of the fit
(still reported) and `--not-shipped` names the muscles written at gain 1 whatever their fit
(default `calibrate.NOT_SHIPPED`, measured with the bumps on the uniform skin; "" writes every
fitted gain). `--fibres` also fits the muscles' lines of action (`sim.face.scan.fibre_fit`),
starting from where the transfer placed them (`sim.face.scan.make_rig.transferred_rig`, the same
bits as the file's muscles today).

The shipped rig's fit (docs/scan-face.md) was made as

    nice .venv/bin/python benchmarks/calibrate_scan.py --skin --rounds 1 --map-shares --not-shipped orbicularis_oculi_lid

but on the simulator of then: the gaze's pull on the lids was retuned after it (sim.gaze_lids), so
the eyeLook shapes settle otherwise and this command now writes a rig a little different from the
shipped one (not re-measured). A fit that leaves the eye region to its own work reads the skin's
material and the eye muscles' gains from the file it rewrites and writes them back unchanged:

    nice .venv/bin/python benchmarks/calibrate_scan.py --rounds 1 --fibres --keep-skin --map-shares --not-shipped "" \
        --keep orbicularis_oculi,orbicularis_oculi_lid,levator_palpebrae,lip_closure \
        --without eyeBlink,eyeSquint,eyeWide,cheekSquint,eyeLook

Its inputs are then the transfer's placed muscles, the scans, the ARKit map's gaze shares and what
it keeps from the file: run again on its own output it starts from the same inputs.

    nice .venv/bin/python benchmarks/calibrate_scan.py [--rounds 2] [--holdout] [--per-vertex | --skin | --keep-skin]
        [--fibres] [--keep MUSCLES] [--map-shares] [--without SHAPES] [--not-shipped MUSCLES] [--no-write | --out RIG]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from sim.face.scan.calibrate import NOT_SHIPPED, STILL_CM, Shape, rms, run, shipped  # noqa: E402

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
    ap.add_argument("--not-shipped", default=",".join(NOT_SHIPPED), metavar="MUSCLES",
                    help="comma-separated muscles written at gain 1 whatever their fit (default: NOT_SHIPPED; \"\": none)")
    ap.add_argument("--no-write", action="store_true", help="do not rewrite the shipped rig")
    ap.add_argument("--out", type=Path, help="write the rig here instead of the shipped rig file")
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

        from sim.face.scan.lids import with_lids

        gains = model.rig.insertion
        ship = shipped(gains, tuple(m for m in args.not_shipped.split(",") if m))
        out = args.out or RIG_FILE
        save_rig(with_lids(replace(model.rig, insertion=ship)), out)
        print(f"wrote {out}")
    print("gaze shares: " + ", ".join(f"{k} {v:.3f}" for k, v in cal.shares.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
