"""Writes the scanned head's gallery to docs/images/: each of the seven presets simulated on the
scanned head (the default face) beside the scan's own expression shapes combined by FACS (same
camera, same light, same renderer), the neutral pair, and three identities.

The scan's shapes stand for the presets' action units at the shared intensities (sim.facs.EXPRESSIONS;
the simulated head plays some presets at its own, `sim.facs.FACE_EXPRESSIONS`):
AU1 browInnerUp, AU2 browOuterUp, AU4 browDown, AU5 eyeWide, AU6 cheekRaiser, AU7 eyeSquint,
AU9 noseSneer, AU10 mouthUpperUp, AU12 mouthSmile, AU14 mouthDimple, AU15 mouthFrown,
AU17 mouthShrugLower, AU20 mouthStretch, AU23 mouthPress, AU43 eyeBlink, AU26 jawOpen at half the AU's intensity
(the shape is the jaw wide open, AU27); both sides unless the AU names one (AU12_R: the _R shape).
Run: .venv/bin/python docs/make_scan_gallery.py [--size 480x480]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images"
RAMP_FRAMES = 40
HOLD_FRAMES = 20
IDENTITY_SEEDS = (1, 2, 3)

AU_SHAPES = {
    "AU1": "browInnerUp", "AU2": "browOuterUp", "AU4": "browDown", "AU5": "eyeWide", "AU6": "cheekRaiser",
    "AU7": "eyeSquint", "AU9": "noseSneer", "AU10": "mouthUpperUp", "AU12": "mouthSmile", "AU14": "mouthDimple",
    "AU15": "mouthFrown", "AU16": "mouthLowerDown", "AU17": "mouthShrugLower", "AU20": "mouthStretch",
    "AU23": "mouthPress", "AU24": "mouthPress", "AU26": "jawOpen", "AU43": "eyeBlink",
}


UNPAIRED = ("jawOpen", "mouthShrugLower")  # shapes the scan has once, not per side


def scan_weights(aus: dict[str, float]) -> dict[str, float]:
    """The scan's expression shapes and weights standing for a preset's action units."""
    out: dict[str, float] = {}
    for au, w in aus.items():
        base, _, side = au.partition("_")
        shape = AU_SHAPES[base]
        if shape in UNPAIRED:
            out[shape] = max(out.get(shape, 0.0), (0.5 if shape == "jawOpen" else 1.0) * w)
            continue
        for s in ("L", "R") if not side else (side.upper(),):
            out[f"{shape}_{s}"] = max(out.get(f"{shape}_{s}", 0.0), w)
    return out


class StillScan:
    """A face model drawn as a still pose of the scan's own shapes (its dressing replaced)."""

    def __init__(self, model: Any, shapes: Any) -> None:
        self._model = model
        self.scan_dressing = shapes

    def __getattr__(self, name: str) -> Any:
        return getattr(self._model, name)


def perform(model: Any, expression: str | None) -> Any:
    """Dial `expression` up from rest over RAMP_FRAMES, hold, settle; the final state."""
    from sim.facs import apply_expression, preset_face
    from sim.integrator import Simulator
    from sim.state import FaceControl

    sim = Simulator(model)
    state = model.rest_state()
    control = FaceControl(model)
    for k in range(RAMP_FRAMES + HOLD_FRAMES):
        control = FaceControl(model)
        if expression:
            apply_expression(control, expression, min(1.0, (k + 1) / RAMP_FRAMES), preset_face(model.rig))
        sim.step(state, control)
    sim.settle(state, control)
    return state


def _save(img: Any, name: str) -> None:
    from PIL import Image

    path = OUT / name
    Image.fromarray(img).save(path, "PNG", optimize=True)
    print(f"wrote {path.relative_to(ROOT)} ({path.stat().st_size // 1024} KB)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="480x480", help="each picture's size WxH (default 480x480)")
    ap.add_argument("--supersample", type=int, default=2, help="samples per pixel per axis (default 2)")
    ap.add_argument("--only", default="", help="comma-separated presets (default: all seven and neutral)")
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    sys.path.insert(0, str(ROOT))
    import numpy as np

    from puppet.face_cache import scan_model
    from puppet.faces import parse_face
    from render.offscreen import OffscreenRenderer
    from sim.face.scan.blendshapes import ScanShapes
    from sim.facs import EXPRESSIONS

    OUT.mkdir(parents=True, exist_ok=True)
    model = scan_model(None)
    names = [n for n in args.only.split(",") if n] or ["neutral", *EXPRESSIONS]

    def shot(m: Any, state: Any) -> np.ndarray:
        with OffscreenRenderer(m, size, supersample=args.supersample) as off:  # type: ignore[arg-type]
            off.renderer.camera.scale = 0.78  # the face and the top of the head
            return off.render_frame(state, record=False)

    for name in names:
        sim_state = perform(model, None if name == "neutral" else name)
        weights = {} if name == "neutral" else scan_weights(EXPRESSIONS[name])
        left = shot(model, sim_state)
        right = shot(StillScan(model, ScanShapes(None, weights)), model.rest_state())
        _save(np.concatenate([left, right], axis=1), f"scan_{name}.png")
        print(f"  {name}: the scan's shapes {', '.join(f'{k} {v:g}' for k, v in sorted(weights.items())) or 'none'}")
    row = []
    for seed in IDENTITY_SEEDS:
        m = scan_model(parse_face(f"ict?identity={seed}").weights)
        row.append(shot(m, perform(m, "happiness" if seed == 2 else None)))
    _save(np.concatenate(row, axis=1), "scan_identities.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
