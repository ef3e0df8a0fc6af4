"""How far a one-sided lips' sphincter and chin muscle could bring the one-sided scanned shapes (run by hand).

The scan's mouthPress_L presses the left half of the lips (92 % of its motion's energy lies on the
face's left, x > 0; its part that is not mirror-symmetric is 0.60 of it), but the ARKit map drives
it with the orbicularis oris and the mentalis, which are one channel each for both sides: whatever
their strengths, the press they make is symmetric, so no map, insertion or skin field reaches
below that 0.60. Anatomically both are paired muscles (each half its side's facial nerve). This
measures, on the simulator, what a one-sided half would give: the unsided channels' fields are
split by a smooth weight across the midline (0.5 (1 + tanh(x / WIDTH)), the face's left, x > 0),
the half's response written into the running implicit step (`sim.fit.rig_settled` does the same for
its bumps), and the shape's channel values fitted on settled poses (`sim.fit.settled.fit_settled`)
with the whole channels and with their left halves, from the shipped map's entry. Each result is
then settled from rest as `scan_match.py --no-fit` measures it.

    nice .venv/bin/python benchmarks/sided_limits.py [--shapes mouthPress_L,mouthDimple_L] [--split orbicularis_oris,mentalis]
        [--extra depressor_labii_l,...] [--rounds 8]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

WIDTH = 0.3  # cm, the width of the halves' blend across the midline


def rel(d: np.ndarray, t: np.ndarray) -> float:
    return float(np.sqrt(np.sum(d * d) / np.sum(t * t)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", default="mouthPress_L,mouthDimple_L")
    ap.add_argument("--split", default="orbicularis_oris,mentalis", help="unsided channels to split")
    ap.add_argument("--extra", default="", help="more channels the fit may drive (besides the shape's own)")
    ap.add_argument("--rounds", type=int, default=8)
    args = ap.parse_args()
    from scan_match import scan_targets

    from puppet.capture.arkit_in import shape_channels
    from puppet.face_cache import scan_model
    from sim.fit.basis import Settler
    from sim.fit.settled import fit_settled

    t0 = time.monotonic()
    model = scan_model()
    settler = Settler(model)
    stepper = settler.sim._implicit  # type: ignore[attr-defined]
    stepper._resp = np.array(stepper._resp)
    base = stepper._resp.copy()
    free = np.asarray(stepper.prepared["free"])
    rest = np.asarray(model.rest)
    n = len(rest)
    ci = model.channel_index
    left = 0.5 * (1.0 + np.tanh(rest[:, 0] / WIDTH))
    split = [c for c in args.split.split(",") if c]
    half_resp = {}
    for c in split:
        f = np.asarray(model.muscle_matrix[:, ci[c]].todense()).reshape(n, 3)
        out = np.zeros((len(free), 3))
        stepper.solver.solve(np.ascontiguousarray((left[:, None] * f)[free]), out)
        half_resp[c] = out
    targets = scan_targets(None)
    for label in args.shapes.split(","):
        shape, target = targets[label]
        v0 = shape_channels({shape: np.ones(1)}, 1)[0]
        names = [c for c in ci if v0[ci[c]] != 0 and c not in ("age",)]
        names += [c for c in args.extra.split(",") if c and c not in names]
        names += [c for c in split if c not in names]
        idx = np.array([ci[c] for c in names])
        lo = np.zeros(len(names))
        hi = np.ones(len(names))

        def values(x: np.ndarray, v0: np.ndarray = v0, idx: np.ndarray = idx) -> np.ndarray:
            v = v0.copy()
            v[idx] = x
            return v

        def settle_rest(x: np.ndarray) -> float:
            return rel(settler.pose(values(x)) - settler.rest - target, target)

        x0 = v0[idx].copy()
        print(f"{label}: the map's entry {dict(zip(names, np.round(x0, 2)))} settles to {settle_rest(x0):.3f}", flush=True)
        for mode in ("whole", "left half"):
            stepper._resp[...] = base
            if mode == "left half":
                for c in split:
                    stepper._resp[ci[c]] = half_resp[c]
            res = fit_settled(settler, values, target, x0, lo, hi, rounds=args.rounds)
            x = np.round(res.x, 2)
            print(f"  {mode:9s} channels fitted: {dict(zip(names, x))}: along the fit {res.error:.3f}, "
                  f"settled from rest {settle_rest(x):.3f} ({time.monotonic() - t0:.0f} s)", flush=True)
        stepper._resp[...] = base
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
