"""Fit the ARKit map's entry of each scanned shape on the simulator's settled poses (run by hand).

Per shape, the parameters are its span on its own channel(s) and a share of each of the `--candidates`
muscle channels whose settled response at rest points most along the scan's motion (cosine over the
skin; a channel named without its side drives the shape's side, both sides for an unsided shape:
left and right stay twins), plus the shipped shares. Each share carries an L1 cost (`--sparsity`:
a share at 1 must take that much off the squared relative error), so the entry keeps the few
channels that matter, and is bounded so that a pose exported and streamed back returns as itself
(`share_limits`). `sim.fit.settled.fit_settled` fits them by Levenberg-Marquardt whose Jacobian is
taken from settled poses about the current settled pose (Broyden's update between full Jacobians).
Then the entry is made readable: shares below `--min-share` are dropped, the rest rounded to 0.05,
the span rounded and tried 0.05 either way; each entry is settled from rest exactly as
`scan_match.py` measures it, and marked KEEP when it beats the shipped entry by more than 0.01. A
sided shape is fitted on its left side; its right twin is settled with the same entry and reported
(held out). Prints per shape the shipped and fitted errors and the entry as `SHAPE_SPAN` /
`SHAPE_SHARES` (puppet/export/arkit.py) write it; those and `puppet/maps/arkit.toml` are edited by
hand from it (a test holds the map and the import to the same channels). `--min-span 1` holds the
span at 1 and fits the shares alone.

    nice .venv/bin/python benchmarks/map_fit.py [--shapes MouthClose,MouthDimpleLeft,...] [--rounds 8]
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

#: Shapes the map's entries are fitted for (left or unsided): the jaw shapes are the jaw's own
#: motion and the eyes' looks are the gaze's (`GAZE_LIDS`), neither a muscle mix.
SHAPES = ("BrowDownLeft", "BrowInnerUp", "BrowOuterUpLeft", "CheekPuff", "CheekSquintLeft", "EyeBlinkLeft",
          "EyeSquintLeft", "EyeWideLeft", "MouthClose", "MouthDimpleLeft", "MouthFrownLeft", "MouthFunnel",
          "MouthLeft", "MouthLowerDownLeft", "MouthPressLeft", "MouthPucker", "MouthRollLower", "MouthRollUpper",
          "MouthShrugLower", "MouthShrugUpper", "MouthSmileLeft", "MouthStretchLeft", "MouthUpperUpLeft",
          "NoseSneerLeft")
#: never a share: the jaw's motions and the mouth's shift are shapes of their own (JawOpen, JawForward,
#: MouthLeft ...), not a muscle a shape brings with it
NOT_SHARED = ("jaw", "jaw_forward", "jaw_sideways", "mouth_shift_l", "mouth_shift_r")


#: Shares a shape may not take, and why: the incisivi carry the lips forward and part them, so
#: "m" (MouthClose 0.1 with MouthPress 0.35, tests/fit/test_fit_speech.py) no longer closes the lips
#: (2.3 mm apart with the incisivus at 1.0 of MouthClose; the test allows 1 mm over rest)
WITHOUT = {"MouthClose": ("incisivus",)}


def share_limits(shape: str) -> dict[str, float]:
    """The largest share of each channel a shape may take so that a pose exported and streamed back
    returns as itself: at most the span of the shape that writes that channel back (the export
    divides by it and clips at 1; of two such shapes the larger span, as the import takes the
    larger), and none of a pair an unsided shape reads as the mean of both
    sides (BrowInnerUp's frontalis_inner) for a sided shape, which would move the other side."""
    from puppet.capture.arkit_in import shape_targets
    from puppet.export.arkit import ARKIT_SHAPES, SHAPE_SPAN

    out: dict[str, float] = {}
    never: set[str] = set()
    sided = shape.endswith(("Left", "Right"))
    for other in ARKIT_SHAPES:
        own = shape_targets(other)
        if len(own) == 2 and not own[0].endswith("_l"):  # MouthFunnel writes back from its first only
            own = own[:1]
        span = SHAPE_SPAN.get(other.removesuffix("Left").removesuffix("Right"), 1.0)
        pair = len(own) == 2 and own[0].endswith("_l") and own[1].endswith("_r")
        for ch in own:
            name = ch.removesuffix("_l").removesuffix("_r")
            out[name] = max(out.get(name, 0.0), span)
            if pair and sided and not other.endswith(("Left", "Right")):
                never.add(name)
    return {c: 0.0 if c in never else v for c, v in out.items()}


def share_names() -> tuple[str, ...]:
    from sim.fit.basis import fit_channels

    return tuple(dict.fromkeys(c.removesuffix("_l").removesuffix("_r") for c in fit_channels()
                               if c not in NOT_SHARED))


def entry_values(shape: str, span: float, shares: dict[str, float]) -> np.ndarray:
    """The channel values the shape at 1 gives with this entry (the import's rule)."""
    from puppet.capture import arkit_in

    spans, table = arkit_in.SHAPE_SPAN, arkit_in.SHAPE_SHARES
    base = shape.removesuffix("Left").removesuffix("Right")
    old_span, old_shares = spans.get(base), table.get(base)
    spans[base] = span
    table[base] = tuple((c, w) for c, w in shares.items() if w > 0.0)
    try:
        return arkit_in.shape_channels({shape: np.ones(1)}, 1)[0]
    finally:
        spans.pop(base, None)
        table.pop(base, None)
        if old_span is not None:
            spans[base] = old_span
        if old_shares is not None:
            table[base] = old_shares


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shapes", help="comma-separated ARKit names (default: SHAPES)")
    ap.add_argument("--rounds", type=int, default=8, help="Levenberg-Marquardt steps per shape")
    ap.add_argument("--min-share", type=float, default=0.1, help="shares below this are dropped")
    ap.add_argument("--min-span", type=float, default=0.2, help="the own channel at least this (the export divides by it; 1 keeps the span at 1)")
    ap.add_argument("--candidates", type=int, default=8, help="share channels per shape (by cosine at rest)")
    ap.add_argument("--sparsity", type=float, default=0.01, help="L1 cost of a share, relative to the scan's energy")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args()

    from puppet.capture import arkit_in
    from puppet.face_cache import scan_model
    from sim.fit.basis import Settler, build_basis, fit_channels
    from sim.fit.settled import fit_settled

    t0 = time.monotonic()
    settler = Settler(scan_model())
    targets = {shape: t for _, (shape, t) in scan_targets(None).items()}
    names = share_names()
    basis = build_basis(settler, [c for c in fit_channels() if c not in NOT_SHARED])
    column = dict(zip(basis.channels, basis.columns))
    print(f"settled rest and {len(basis.channels)} channels' responses in {time.monotonic() - t0:.0f} s", flush=True)

    def response(shape: str, pair: str) -> np.ndarray:
        """The rest response of a share channel as the shape drives it."""
        from puppet.capture.arkit_in import share_targets
        from sim.channels import CHANNEL_INDEX

        return sum(column[c] for c in share_targets(shape, pair, CHANNEL_INDEX))  # type: ignore[return-value]

    def measured(shape: str, span: float, shares: dict[str, float]) -> float:
        """Settled from rest under the simulator's own settling, as scan_match.py measures."""
        target = targets[shape]
        return rms(settler.pose(entry_values(shape, span, shares)) - settler.rest - target) / rms(target)

    for shape in (args.shapes.split(",") if args.shapes else SHAPES):
        t1 = time.monotonic()
        base = shape.removesuffix("Left").removesuffix("Right")
        own = {c.removesuffix("_l").removesuffix("_r") for c in arkit_in.shape_targets(shape)}
        span0 = arkit_in.SHAPE_SPAN.get(base, 1.0)
        shipped = dict(arkit_in.SHAPE_SHARES.get(base, ()))
        t = targets[shape]
        limits = share_limits(shape)
        cosine = {c: float(np.sum(response(shape, c) * t)) / (np.linalg.norm(response(shape, c)) * np.linalg.norm(t) + 1e-12)
                  for c in names if c not in own and c not in WITHOUT.get(shape, ()) and limits.get(c, 1.0) > 0.0}
        best = sorted(cosine, key=lambda c: -cosine[c])[: args.candidates]
        cands = list(dict.fromkeys([*shipped, *(c for c in best if cosine[c] > 0.0)]))
        e0 = measured(shape, span0, shipped)

        def values(x: np.ndarray, cands: list[str] = cands) -> np.ndarray:
            return entry_values(shape, float(x[0]), dict(zip(cands, (float(v) for v in x[1:]))))

        x0 = np.array([span0] + [shipped.get(c, 0.0) for c in cands])
        lo = np.array([min(args.min_span, 1.0 - 1e-6)] + [0.0] * len(cands))  # --min-span 1 holds the span at 1
        hi = np.array([1.0] + [limits.get(c, 1.0) for c in cands])
        x0 = np.minimum(x0, hi)
        log = print if args.verbose else None
        l1 = np.array([0.0] + [args.sparsity] * len(cands))
        if log:
            log("  candidates: " + " ".join(f"{c} {cosine.get(c, float('nan')):.2f}" for c in cands))  # (a shipped share
            # such as the jaw's thrust is not a candidate: no cosine)
        fit = fit_settled(settler, values, targets[shape], x0, lo, hi, rounds=args.rounds, sparsity=l1, log=log)
        kept = {c: round(float(v) * 20) / 20 for c, v in zip(cands, fit.x[1:]) if v >= args.min_share}
        kept = {c: v for c, v in kept.items() if v > 0.0}
        span = round(float(fit.x[0]) * 20) / 20
        e1 = measured(shape, span, kept)
        for s in (span - 0.05, span + 0.05):  # the span again about the rounded entry
            if args.min_span <= s <= 1.0 and (e := measured(shape, s, kept)) < e1:
                span, e1 = round(s, 2), e
        better = e1 < e0 - 0.01
        line = (f"{shape:20s} shipped {e0:.3f}  fit {fit.error:.3f}  entry {e1:.3f} "
                f"{'KEEP' if better else 'no'}  span {span:.2f} shares {kept}")
        if shape.endswith("Left"):
            twin = shape.removesuffix("Left") + "Right"
            line += f"  held-out {twin}: {measured(twin, span0, shipped):.3f} -> {measured(twin, span, kept):.3f}"
        print(line + f"  [{time.monotonic() - t1:.0f} s, {fit.settles} settles]", flush=True)
    print(f"total {time.monotonic() - t0:.0f} s, {settler.settles} settles")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
