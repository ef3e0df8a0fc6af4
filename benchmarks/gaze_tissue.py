"""The tissue round the globe carried by the turning eye, fitted to the scan's look shapes (run by hand).

Tenon's capsule wraps the globe and is joined to the lids' retractors, the check ligaments tie it
to the orbit's rims, and the orbital fat fills round it: as the eye turns, that tissue, and the
lids' and the brows' skin tethered over it, moves with the turn. Modelled as the skin's tether
anchors displaced per eye and per look (`FaceRig.gaze`: in, out, up, down with that eye turned
fully, the right eye's the left's mirrored; `sim.gaze_lids.tissue_fields` carries them by the
gaze's angle), fitted as the muscles' anchor fields are (`sim.face.scan.anchor_fit`): in the
linear statics of the shipped skin, to what the settled eyeLook shapes (left and right, the
channels the shipped ARKit map gives them) miss of the scan, smooth over the free skin within
`--reach` cm of the eye's sphere. Each round settles the looks on the rig with the fields so far
and adds the fit of what they still miss (the step damped by `--damp`).

The shipped rig's fields, one command on top of the rig the commands of
`benchmarks/anchor_limits.py`'s docstring made (docs/scan-face.md, "The tissue round the globe
carried by the turning eye"):

    nice .venv/bin/python benchmarks/gaze_tissue.py --write-rig sim/face/scan/ict_rig.npz

    nice .venv/bin/python benchmarks/gaze_tissue.py [--rig RIG] [--reach 3] [--smooth 1e-4] [--bound 10]
        [--rounds 2] [--damp 1] [--left] [--write-rig RIG]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: the scan's look shapes and the field each drives
LOOKS = {f"eyeLook{look.capitalize()}_{side.upper()}": f"{look}_{side}"
         for side in ("l", "r") for look in ("in", "out", "up", "down")}
REACH = 3.0  # cm outside the eye's sphere: the orbit's rim and the brow's tail, not the cheek below


def rel(d: np.ndarray, t: np.ndarray) -> float:
    return float(np.sqrt(np.sum((d - t) ** 2) / np.sum(t * t)))


class _Fields:
    """The compiled model seen with one pseudo-channel per look field (its `channel_index`)."""

    def __init__(self, model, names: list[str]) -> None:  # type: ignore[no-untyped-def]
        self._model = model
        self.channel_index = {n: k for k, n in enumerate(names)}

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self._model, name)


def zones(model, reach: float) -> dict[str, np.ndarray]:  # type: ignore[no-untyped-def]
    """Per look field its zone: the free skin within `reach` cm of its eye's sphere."""
    rest = np.asarray(model.rest)
    free = (np.asarray(model.rest_stiffness) > 0) & ~np.asarray(model.held, bool)
    c = np.asarray(model.mesh.eye_centers)
    r = float(model.eye_contact_radius)
    near = [free & (np.linalg.norm(rest - c[e], axis=1) - r < reach) for e in range(2)]
    return {name: near[name.endswith("_r")] for name in LOOKS.values()}


def look_values(label: str) -> np.ndarray:
    """The ARKit map's channel values of a scanned look."""
    from puppet.capture.arkit_in import shape_channels
    from scan_match import arkit_shape

    return shape_channels({arkit_shape(label): np.ones(1)}, 1)[0]


def field_values(label: str, names: list[str]) -> np.ndarray:
    """How much of each look field the scanned look's gaze carries (`sim.gaze_lids.look_coefficients`:
    the map turns one eye fully aside, but both eyes half way up or down)."""
    from sim.channels import CHANNEL_INDEX
    from sim.gaze_lids import look_coefficients

    v = look_values(label)
    coef = look_coefficients(*(float(v[CHANNEL_INDEX[c]]) for c in ("eyes_yaw", "eyes_pitch", "eyes_vergence")))
    return np.array([coef[n] for n in names])


def settle(rig, params):  # type: ignore[no-untyped-def]
    """(model, {label: settled displacement (N, 3) cm}) of the look shapes on `rig`."""
    from sim.build import compile_model
    from sim.fit.basis import Settler

    model = compile_model(rig, params)
    settler = Settler(model)
    out = {}
    for label in LOOKS:
        out[label] = settler.pose(look_values(label)) - settler.rest
    return model, out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig", type=Path, help="start from this rig file of the scanned head (default: the shipped one)")
    ap.add_argument("--reach", type=float, default=REACH, help="cm outside the eye's sphere the fields reach")
    ap.add_argument("--smooth", type=float, default=1e-4, help="Laplacian weight per edge and component (per mm^2)")
    ap.add_argument("--ridge", type=float, default=1e-5, help="pull of each component towards 0 (per mm^2)")
    ap.add_argument("--bound", type=float, default=10.0, help="bound of each component, mm")
    ap.add_argument("--iters", type=int, default=300, help="L-BFGS-B iterations at most")
    ap.add_argument("--rounds", type=int, default=2, help="fits, each about the poses the fields so far settle")
    ap.add_argument("--damp", type=float, default=1.0, help="the share of each round's fitted change taken")
    ap.add_argument("--left", action="store_true", help="fit on the left looks only (the right ones held out)")
    ap.add_argument("--write-rig", type=Path, help="write the rig with the fitted fields (FaceRig.gaze) here")
    args = ap.parse_args()

    from scan_match import scan_targets

    from sim.face.scan.anchor_fit import AnchorCalibration
    from sim.face.scan.rig import RIG_FILE, scan_params
    from sim.rig import load_rig, save_rig

    t0 = time.monotonic()
    params = scan_params()
    rig = load_rig(args.rig or RIG_FILE)
    targets = {label: t for label, (_, t) in scan_targets(list(LOOKS)).items()}
    names = sorted(LOOKS.values())
    cal = None
    for r in range(args.rounds + 1):
        model, real = settle(rig, params)
        errs = {label: rel(real[label], targets[label]) for label in LOOKS}
        print(f"round {r} settled ({time.monotonic() - t0:.0f} s): "
              + ", ".join(f"{label} {e:.3f}" for label, e in errs.items()), flush=True)
        if r == args.rounds:
            break
        if cal is None:
            cal = AnchorCalibration(model, smooth=args.smooth, ridge=args.ridge, bound=args.bound,
                                    zones=zones(model, args.reach))
            cal.model = _Fields(model, names)
            print(f"{cal.n_params} parameters ({time.monotonic() - t0:.0f} s)", flush=True)
        train = [label for label in LOOKS if not (args.left and label.endswith("_R"))]
        vals = np.array([field_values(label, names) for label in train])
        b = np.stack([(targets[label] - real[label]).ravel() for label in train], axis=1)
        w = np.array([1.0 / float(np.sum(targets[label] ** 2)) for label in train])
        cal.params = np.zeros(cal.n_params)
        res = cal.fit(vals, b, w, iters=args.iters)
        lin = cal.predict_all(vals)
        print(f"  fitted ({res.nit} iterations, {time.monotonic() - t0:.0f} s), linear: "
              + ", ".join(f"{label} {rel(real[label] + lin[k], targets[label]):.3f}" for k, label in enumerate(train)),
              flush=True)
        mag = np.linalg.norm(cal.params.reshape(-1, 3), axis=1)
        print(f"  anchor displacement mm: median {np.median(mag):.2f}, 95th {np.percentile(mag, 95):.2f}, "
              f"max {mag.max():.2f}", flush=True)
        zero = np.zeros((len(model.rest), 3))
        gaze = {n: np.round(np.clip(np.asarray(rig.gaze.get(n, zero)) + args.damp * cal.field(n), -2.0, 2.0), 6)
                for n in names}
        rig = replace(rig, gaze={n: d for n, d in gaze.items() if np.abs(d).max() > 1e-5})
    if args.write_rig:
        save_rig(rig, args.write_rig)
        print(f"wrote {args.write_rig} ({len(rig.gaze)} look fields)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
