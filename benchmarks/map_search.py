"""Search the ARKit map's entry of each scanned shape on the simulator itself (run by hand).

The map's entry of a shape: its span on its own channel(s) (`SHAPE_SPAN`, 0..1 of the channel's
range) and other channels by shares (`SHAPE_SHARES`); this searches one share (the shipped first
one), `map_fit.py` fits several by Levenberg-Marquardt on settled poses. The linear statics the
earlier fits used do not predict the settled poses well, so this settles every candidate as
`scan_match.py` does (the shape at 1 through `puppet.capture.arkit_in.shape_channels`) and keeps the
lowest relative error: a coordinate search, span first, then each anatomically plausible share
channel (`CANDIDATES`) on a grid, then the span again with the best share, then the share refined.
A sided shape is searched on its left side; its right twin is settled with the left's entry as a
held-out check.

    nice .venv/bin/python benchmarks/map_search.py [--shapes MouthClose,MouthDimpleLeft,...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from scan_match import rms, scan_targets  # noqa: E402

#: Per shape (left or unsided), the channels it may plausibly share (a channel named without its
#: side is the shape's side, both sides for an unsided shape), and why.
CANDIDATES: dict[str, tuple[str, ...]] = {
    # lips meeting over a still jaw: the sphincter and its marginal parts close them, the mentalis
    # lifts the lower lip, the incisivi carry the lips forward
    "MouthClose": ("orbicularis_oris", "orbicularis_oris_marginalis_upper", "orbicularis_oris_marginalis_lower",
                   "mentalis", "incisivus"),
    # the lower lip pushed up by the chin's muscle: with the lower lip's sphincter and its eversion
    "MouthShrugLower": ("orbicularis_oris", "orbicularis_oris_peripheralis_lower", "orbicularis_oris_marginalis_lower",
                        "incisivus", "lip_closure"),
    # the upper lip's shrug: with the chin pushing up (the lips pressed) or the sphincter
    "MouthShrugUpper": ("mentalis", "orbicularis_oris", "incisivus", "orbicularis_oris_marginalis_upper", "lip_closure",
                        "levator_labii", "orbicularis_oris_peripheralis_lower"),
    # the lips pressed: the sphincter with the chin (shipped), the marginal parts, the lips' closure
    "MouthPressLeft": ("mentalis", "orbicularis_oris_marginalis_upper", "orbicularis_oris_marginalis_lower",
                       "lip_closure", "buccinator"),
    # the corner drawn back into the cheek: the buccinator with the corner's other retractors
    "MouthDimpleLeft": ("risorius", "zygomaticus_major", "orbicularis_oris", "depressor_anguli_oris",
                        "levator_anguli_oris"),
    # the lower lip drawn down: with the corner's depressor, the platysma's pull (risorius), the chin
    "MouthLowerDownLeft": ("depressor_anguli_oris", "mentalis", "risorius", "orbicularis_oris_peripheralis_lower"),
    "MouthFunnel": ("incisivus", "orbicularis_oris", "orbicularis_oris_marginalis_upper", "orbicularis_oris_marginalis_lower"),
    "MouthRollLower": ("orbicularis_oris", "mentalis", "orbicularis_oris_marginalis_upper", "lip_closure"),
    # the puff holds air behind closed lips: pursed (shipped) or pressed or closed
    "CheekPuff": ("incisivus", "orbicularis_oris", "lip_closure", "buccinator"),
    # the upper lid raised: the brows' raisers often come with it (the scan's shape moves the brow)
    "EyeWideLeft": ("frontalis_outer", "frontalis_inner"),
    # the inner brows raised: the outer part of the frontalis, the corrugator drawing them in
    "BrowInnerUp": ("frontalis_outer", "corrugator", "procerus"),
    "BrowDownLeft": ("procerus", "orbicularis_oculi", "levator_labii_alaeque_nasi", "frontalis_inner"),
    # the squints: the cheek pushed up under the lid (zygomaticus, the upper lip's raisers)
    "EyeSquintLeft": ("zygomaticus_major", "levator_labii", "zygomaticus_minor", "levator_palpebrae"),
    "CheekSquintLeft": ("zygomaticus_major", "levator_labii", "zygomaticus_minor", "levator_palpebrae"),
    "NoseSneerLeft": ("levator_labii", "procerus", "corrugator", "orbicularis_oculi"),
}
SPANS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
SHARES = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", help="comma-separated ARKit names (default: every one in CANDIDATES)")
    ap.add_argument("--any", action="store_true",
                    help="try every muscle channel as the share (a coarser grid), not only CANDIDATES")
    args = ap.parse_args()

    from puppet.capture import arkit_in
    from puppet.face_cache import scan_model
    from sim.fit.basis import Settler, fit_channels

    t0 = time.monotonic()
    settler = Settler(scan_model())
    targets = {shape: (label, t) for label, (shape, t) in scan_targets(None).items()}
    spans, shares = arkit_in.SHAPE_SPAN, arkit_in.SHAPE_SHARES
    todo = args.shapes.split(",") if args.shapes else list(CANDIDATES)
    print(f"settled rest in {time.monotonic() - t0:.0f} s", flush=True)

    def error(shape: str, span: float, share: tuple[str, float] | None) -> float:
        base = shape.removesuffix("Left").removesuffix("Right")
        old_span, old_share = spans.get(base), shares.get(base)
        spans[base] = span
        if share is None:
            shares.pop(base, None)
        else:
            shares[base] = (share,)
        try:
            values = arkit_in.shape_channels({shape: np.ones(1)}, 1)[0]
        finally:
            spans.pop(base, None)
            shares.pop(base, None)
            if old_span is not None:
                spans[base] = old_span
            if old_share is not None:
                shares[base] = old_share
        _, target = targets[shape]
        return rms(settler.pose(values) - settler.rest - target) / rms(target)

    for shape in todo:
        t1 = time.monotonic()
        base = shape.removesuffix("Left").removesuffix("Right")
        span0, share0 = spans.get(base, 1.0), next(iter(shares.get(base, ())), None)  # its first share
        e0 = error(shape, span0, share0)
        best = (e0, span0, share0)
        for s in SPANS:  # the span with the shipped share, then without any
            for sh in {share0, None} if share0 else (None,):
                e = error(shape, s, sh)
                if e < best[0]:
                    best = (e, s, sh)
        every = tuple(dict.fromkeys(c.removesuffix("_l").removesuffix("_r") for c in fit_channels()))
        for ch in every if args.any else CANDIDATES.get(shape, ()):
            for w in (0.15, 0.4, 0.8) if args.any else SHARES:
                e = error(shape, best[1], (ch, w))
                if e < best[0]:
                    best = (e, best[1], (ch, w))
        if best[2] is not None:  # the span again with the chosen share, then the share refined
            for s in SPANS:
                e = error(shape, s, best[2])
                if e < best[0]:
                    best = (e, s, best[2])
            ch, w = best[2]
            for dw in (-0.1, -0.05, 0.05, 0.1) if args.any else (-0.05, 0.05):
                w2 = round(min(1.0, max(0.05, w + dw)), 2)
                e = error(shape, best[1], (ch, w2))
                if e < best[0]:
                    best = (e, best[1], (ch, w2))
        line = (f"{shape:20s} shipped {e0:.3f} (span {span0}, share {share0})  best {best[0]:.3f} "
                f"(span {best[1]}, share {best[2]})")
        if shape.endswith("Left"):
            twin = shape.removesuffix("Left") + "Right"
            line += f"  held-out {twin}: {error(twin, span0, share0):.3f} -> {error(twin, best[1], best[2]):.3f}"
        print(line + f"  [{time.monotonic() - t1:.0f} s]", flush=True)
    print(f"total {time.monotonic() - t0:.0f} s, {settler.settles} settles")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
