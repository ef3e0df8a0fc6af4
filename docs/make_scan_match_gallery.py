"""Writes docs/images/scan_match_<group>.png: for each shape group (brows, eyes and lids, the gaze
sideways, cheeks and nose, mouth, jaw) a few ARKit shapes, each as a row: the scanned face (the default face) driven by
the channels the ARKit import gives that shape at 1 (ramped up, then settled), beside the scan's own
shape (same camera, same light, same renderer). What `benchmarks/scan_match.py` measures, shown.
`blink` is a close-up of the left eye: at rest, ours closed by EyeBlinkLeft, the scan's eyeBlink_L.
Run: .venv/bin/python docs/make_scan_match_gallery.py [--size 320x320] [--only brows,jaw,blink]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
sys.path.insert(0, str(ROOT))

from make_scan_gallery import OUT, StillScan, _save  # noqa: E402

RAMP_FRAMES = 40
HOLD_FRAMES = 20

#: group -> (ARKit shape, the scan's shapes standing for it)
GROUPS: dict[str, list[tuple[str, tuple[str, ...]]]] = {
    "brows": [("BrowDownLeft", ("browDown_L",)), ("BrowInnerUp", ("browInnerUp_L", "browInnerUp_R")),
              ("BrowOuterUpLeft", ("browOuterUp_L",))],
    "lids": [("EyeBlinkLeft", ("eyeBlink_L",)), ("EyeWideLeft", ("eyeWide_L",)), ("EyeLookUpLeft", ("eyeLookUp_L",)),
             ("EyeLookDownLeft", ("eyeLookDown_L",))],
    "gaze": [("EyeLookOutLeft", ("eyeLookOut_L",)), ("EyeLookInLeft", ("eyeLookIn_L",))],
    "cheeks": [("CheekSquintLeft", ("cheekSquint_L",)), ("NoseSneerLeft", ("noseSneer_L",)),
               ("CheekPuff", ("cheekPuff_L", "cheekPuff_R"))],
    "mouth": [("MouthSmileLeft", ("mouthSmile_L",)), ("MouthPucker", ("mouthPucker",)),
              ("MouthFunnel", ("mouthFunnel",)), ("MouthFrownLeft", ("mouthFrown_L",))],
    "jaw": [("JawOpen", ("jawOpen",)), ("JawLeft", ("jawLeft",)), ("JawForward", ("jawForward",))],
}


CLOSEUP = ("EyeBlinkLeft", "eyeBlink_L")  # the `blink` group: one row, rest | ours | the scan


def perform(model: Any, values: Any) -> Any:
    """Ramp the channel values up from rest over RAMP_FRAMES, hold, settle; the final state."""
    from sim.integrator import Simulator
    from sim.state import FaceControl

    sim = Simulator(model)
    state = model.rest_state()
    control = FaceControl(model)
    rest = control.values.copy()
    for k in range(RAMP_FRAMES + HOLD_FRAMES):
        control.values[...] = rest + min(1.0, (k + 1) / RAMP_FRAMES) * (values - rest)
        sim.step(state, control)
    sim.settle(state, control)
    return state


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="320x320", help="each picture's size WxH (default 320x320)")
    ap.add_argument("--only", default="", help="comma-separated groups (default: all)")
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    import numpy as np

    from puppet.capture.arkit_in import shape_channels
    from puppet.face_cache import scan_model
    from render.offscreen import OffscreenRenderer
    from sim.face.scan.blendshapes import ScanShapes

    OUT.mkdir(parents=True, exist_ok=True)
    model = scan_model(None)

    def shot(m: Any, state: Any) -> np.ndarray:
        with OffscreenRenderer(m, size, supersample=2) as off:  # type: ignore[arg-type]
            cam = off.renderer.camera
            cam.scale = 0.62  # the face, from the brows to the chin
            cam.lo, cam.hi = cam.lo - [0.0, 3.0, 0.0], cam.hi - [0.0, 3.0, 0.0]
            return off.render_frame(state, record=False)

    def eye(m: Any, state: Any) -> np.ndarray:
        with OffscreenRenderer(m, (360, 300), supersample=2) as off:  # type: ignore[arg-type]
            cam = off.renderer.camera
            cam.scale = 0.25  # the left eye and its brow
            shift = (model.mesh.eye_centers[0] - 0.5 * (cam.lo + cam.hi)) * [1.0, 1.0, 0.0] + [0.0, 0.3, 0.0]
            cam.lo, cam.hi = cam.lo + shift, cam.hi + shift
            return off.render_frame(state, record=False)

    chosen = [g for g in args.only.split(",") if g] or [*GROUPS, "blink"]
    if "blink" in chosen:
        arkit, scan = CLOSEUP
        row = [eye(model, model.rest_state()), eye(model, perform(model, shape_channels({arkit: np.ones(1)}, 1)[0])),
               eye(StillScan(model, ScanShapes(None, {scan: 1.0})), model.rest_state())]
        _save(np.concatenate(row, axis=1), "scan_match_blink.png")
    for group in [g for g in chosen if g != "blink"]:
        rows = []
        for arkit, scans in GROUPS[group]:
            ours = shot(model, perform(model, shape_channels({arkit: np.ones(1)}, 1)[0]))
            theirs = shot(StillScan(model, ScanShapes(None, {s: 1.0 for s in scans})), model.rest_state())
            rows.append(np.concatenate([ours, theirs], axis=1))
            print(f"  {group}: {arkit} (ours, left) beside {' + '.join(scans)} (the scan, right)")
        _save(np.concatenate(rows, axis=0), f"scan_match_{group}.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
