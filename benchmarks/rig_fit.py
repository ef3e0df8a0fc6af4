"""Fit the scanned face's own muscles to the scans on settled poses (run by hand).

The parameters are insertion gains on `--bumps` smooth bumps over each of `--groups`' zones (both
sides sharing them, mirrored; gains 1 = the shipped rig), multiplying the shipped insertions
(`sim.fit.rig_settled`). Levenberg-Marquardt whose Jacobian columns are settled poses about the
current settled poses (`sim.fit.settled.levenberg_settled`), over every fitted shape at once: the
left and unsided ARKit shapes (as `scan_match.py` drives them through the shipped map) that drive
any fitted muscle. The right twins are held out. Prints per shape the shipped and fitted relative
error settled from rest as `scan_match.py` measures it (fitted shapes, held-out twins, and with
`--all` every other shape too, which the fitted muscles may move), and the median and max over
every measured shape. `--write PATH` writes a rig file with the fitted insertions (for
`puppet replay --rig`, `observer.py`, `folds.py` to judge before anything ships).

`--hold-presets W` also keeps the presets that drive a fitted muscle where they settle now;
`--skin` fits the skin's tether and modulus about the lips, chin and corners instead (`SKIN_AT`).
Figures and what they showed: docs/scan-face.md, "The rig's own muscles fitted on the settled poses".

    nice .venv/bin/python benchmarks/rig_fit.py [--groups mentalis,orbicularis_oris,...] [--bumps 4] [--all]
    nice .venv/bin/python benchmarks/rig_fit.py --skin [--shapes mouthPress_L,mouthClose,...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from scan_match import STILL_MM, rms, scan_targets  # noqa: E402

#: the muscles the worst-matched shapes drive (mouthPress, mouthClose, mouthShrugLower,
#: mouthDimple, browInnerUp)
GROUPS = ("orbicularis_oris", "mentalis", "levator_anguli_oris", "buccinator", "frontalis_inner")
#: `--skin`: the skin's bumps, about these landmarks (a pair shares its parameter)
SKIN_AT = (("upper_lip_center",), ("lower_lip_center",), ("chin",), ("mouth_corner_l", "mouth_corner_r"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--groups", default=",".join(GROUPS), help="muscles (without side) whose gains are fitted")
    ap.add_argument("--bumps", type=int, default=4, help="bumps per muscle")
    ap.add_argument("--rounds", type=int, default=6, help="Levenberg-Marquardt steps")
    ap.add_argument("--lo", type=float, default=0.25, help="lowest gain")
    ap.add_argument("--hi", type=float, default=3.0, help="highest gain")
    ap.add_argument("--shapes", help="comma-separated ARKit shapes to fit (default: every left or unsided "
                                     "shape driving a fitted muscle)")
    ap.add_argument("--all", action="store_true", help="also measure every other shape")
    ap.add_argument("--hold-presets", type=float, default=0.0, metavar="W",
                    help="also hold the seven presets where they settle now (each a pose whose target is its "
                         "shipped settled displacement, weighted W against a scan shape)")
    ap.add_argument("--skin", action="store_true",
                    help="instead: fit the skin's tether and modulus about the lips and chin (SKIN_AT), each "
                         "parameter vector a rig compiled again, on the mouth's left and unsided shapes")
    ap.add_argument("--write", type=Path, help="write a rig file with the fitted insertions here")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args()

    from puppet.capture.arkit_in import shape_channels
    from puppet.face_cache import scan_model
    from sim.fit.basis import Settler
    from sim.fit.rig_settled import InsertionBumps, Pose, fit_rig_settled, relative_errors

    t0 = time.monotonic()
    model = scan_model()
    settler = Settler(model)
    if args.skin:
        return fit_skin(args, model)
    groups = args.groups.split(",")
    rig = InsertionBumps(settler, groups, args.bumps)
    fitted_ch = [model.channel_index[c] for c in rig.channels]
    poses = {}
    for label, (shape, target) in scan_targets(None).items():
        if rms(target) * 10 >= STILL_MM:
            poses[label] = Pose(label, shape_channels({shape: np.ones(1)}, 1)[0], target)
    shape_of = {label: shape for label, (shape, _) in scan_targets(None).items()}
    wanted = set(args.shapes.split(",")) if args.shapes else None
    fit = [p for p in poses.values() if not shape_of[p.label].endswith("Right")
           and (shape_of[p.label] in wanted if wanted else np.any(p.values[fitted_ch] != 0.0))]
    held = [poses[p.label.replace("_L", "_R")] for p in fit if p.label.endswith("_L")]
    others = [p for p in poses.values() if p not in fit and p not in held] if args.all else []
    print(f"{len(rig.channels)} channels, {rig.n_params} gains; fitting {len(fit)} shapes "
          f"({', '.join(p.label for p in fit)}), {len(held)} held out; ready in {time.monotonic() - t0:.0f} s",
          flush=True)

    x0 = np.ones(rig.n_params)
    kept = []
    if args.hold_presets > 0.0:  # the presets drive the same muscles: their settled poses as they are now
        from sim.facs import EXPRESSIONS, apply_expression, preset_face
        from sim.state import FaceControl

        for name in EXPRESSIONS:
            c = FaceControl()
            apply_expression(c, name, face=preset_face(model.rig))
            if np.any(c.values[fitted_ch] != 0.0):
                v = np.asarray(c.values, float)
                kept.append(Pose(f"preset {name}", v, settler.pose(v) - settler.rest))
        print(f"holding {len(kept)} presets ({', '.join(p.label for p in kept)}) at weight {args.hold_presets}")
    before = relative_errors(settler, rig, fit + held + others, x0)
    res = fit_rig_settled(settler, rig, fit + kept, x0, np.full(rig.n_params, args.lo), np.full(rig.n_params, args.hi),
                          rounds=args.rounds, log=print if args.verbose else None,
                          weights=[1.0] * len(fit) + [args.hold_presets] * len(kept))
    after = relative_errors(settler, rig, fit + held + others, res.x)
    for p, e in relative_errors(settler, rig, kept, res.x).items():
        print(f"  {p:20s} moved {e:.3f} of its own motion")
    print(f"fit: {res.settles} settles, rms relative error {res.history[0][1]:.3f} -> {res.error:.3f}")
    print("gains: " + " ".join(f"{n}={v:.2f}" for n, v in zip(rig.names, res.x)))
    for what, group in (("fitted", fit), ("held out", held), ("others", others)):
        for p in group:
            flag = "  WORSE" if after[p.label] > before[p.label] + 0.01 else ""
            print(f"  {what:8s} {p.label:20s} {before[p.label]:.3f} -> {after[p.label]:.3f}{flag}")
    if args.all:
        b = np.array(list(before.values()))
        a = np.array(list(after.values()))
        print(f"all {len(b)} shapes: median {np.median(b):.3f} -> {np.median(a):.3f}, max {b.max():.3f} -> "
              f"{a.max():.3f} ({list(after)[int(np.argmax(a))]}), above 0.6: {int(np.sum(b > 0.6))} -> {int(np.sum(a > 0.6))}")
    if args.write:
        from dataclasses import replace

        from sim.rig import save_rig

        insertion = dict(model.rig.insertion)
        insertion.update(rig.insertion(res.x, model.rig.insertion))
        save_rig(replace(model.rig, insertion=insertion), args.write)
        print(f"wrote {args.write}")
    print(f"total {time.monotonic() - t0:.0f} s")
    return 0


def fit_skin(args: argparse.Namespace, model: object) -> int:
    """`--skin`: the skin's fields about the mouth on the mouth's shapes (left and unsided fitted,
    right twins held out), measured settled from rest on the rig compiled with them."""
    import json

    from puppet.capture.arkit_in import shape_channels
    from sim.face.scan.anatomy import skin_layout
    from sim.fit.rig_settled import Pose, SkinBumps, fit_skin_settled
    from sim.prepared import use_store

    use_store(None)  # the trial faces are not written to the face cache
    t0 = time.monotonic()
    marks = json.loads((Path(__file__).resolve().parents[1] / "sim/face/scan/landmarks.json").read_text())
    where = {int(v): k for k, v in enumerate(skin_layout().vertices)}
    rest = np.asarray(model.rest)  # type: ignore[attr-defined]
    skin = SkinBumps(model, [np.array([rest[where[marks[n]]] for n in pair]) for pair in SKIN_AT])
    poses = {label: Pose(label, shape_channels({shape: np.ones(1)}, 1)[0], target)
             for label, (shape, target) in scan_targets(None).items()
             if rms(target) * 10 >= STILL_MM and shape.startswith(("Mouth", "Jaw", "CheekPuff"))}
    wanted = set(args.shapes.split(",")) if args.shapes else None  # here scan names: mouthPress_L, ...
    fit = [p for p in poses.values() if not p.label.endswith("_R") and p.label not in ("mouthRight", "jawRight")
           and (wanted is None or p.label in wanted)]
    held = [poses[p.label.replace("_L", "_R")] for p in fit if p.label.endswith("_L")]
    print(f"{skin.n_params} skin parameters; fitting {len(fit)} shapes, {len(held)} held out", flush=True)

    def measured(x: np.ndarray) -> dict[str, float]:
        s = skin.settler(x)
        out = {}
        for p in fit + held:
            d = s.pose(p.values) - s.rest - p.target
            out[p.label] = float(np.sqrt(np.sum(d * d) / np.sum(p.target * p.target)))
        return out

    x0 = np.zeros(skin.n_params)
    before = measured(x0)
    lim = np.log(2.5)
    res = fit_skin_settled(skin, fit, x0, np.full(skin.n_params, -lim), np.full(skin.n_params, lim),
                           rounds=args.rounds, h=0.15, log=print if args.verbose else None)
    after = measured(res.x)
    print(f"fit: rms relative error {res.history[0][1]:.3f} -> {res.error:.3f}")
    print("multipliers at the centres: " + " ".join(f"{n}={np.exp(v):.2f}" for n, v in zip(skin.names, res.x)))
    for what, group in (("fitted", fit), ("held out", held)):
        for p in group:
            flag = "  WORSE" if after[p.label] > before[p.label] + 0.01 else ""
            print(f"  {what:8s} {p.label:20s} {before[p.label]:.3f} -> {after[p.label]:.3f}{flag}")
    print(f"total {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
