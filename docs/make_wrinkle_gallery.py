"""Render the wrinkle gallery of docs/wrinkles.md: the same expressions at ages 25, 45, 65, 85.

The expressions are those of the render gallery (docs/make_gallery.py, sim.facs.EXPRESSIONS) plus
a frown (AU4 alone). Each pose is simulated from rest to a standstill with the age channel set,
then drawn by render.offscreen.render_to_file. Writes one strip per expression,
docs/images/wrinkles_<expression>.png (ages left to right), and a close-up strip of the region it
creases most, docs/images/wrinkles_<expression>_closeup.png; with --frames DIR also the frames.

    .venv/bin/python docs/make_wrinkle_gallery.py [--resolution 2] [--size 480x560] [--frames DIR]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from render.offscreen import render_to_file  # noqa: E402
from sim.build import compile_model  # noqa: E402
from sim.facs import EXPRESSIONS, apply_au, apply_expression  # noqa: E402
from sim.integrator import Simulator  # noqa: E402
from sim.face import default_rig  # noqa: E402
from sim.state import FaceControl  # noqa: E402

AGES = (25, 45, 65, 85)
# close-up boxes (fractions of the image: left, top, right, bottom) of the region each creases most
BROWS = (0.2, 0.02, 0.8, 0.42)
GLABELLA = (0.28, 0.2, 0.72, 0.46)
MOUTH = (0.15, 0.3, 0.85, 0.85)
MIDFACE = (0.2, 0.2, 0.8, 0.8)
CLOSEUP = {"frown": GLABELLA, "surprise": BROWS, "fear": BROWS, "sadness": BROWS, "anger": GLABELLA,
           "happiness": MOUTH, "contempt": MOUTH, "disgust": MIDFACE}


def _pose(name: str):  # type: ignore[no-untyped-def]
    if name == "frown":
        return lambda c: apply_au(c, "AU4", 1.0)
    return lambda c: apply_expression(c, name, 1.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=2)
    ap.add_argument("--size", default="480x560")
    ap.add_argument("--out", default=str(HERE / "images"))
    ap.add_argument("--frames", default=None, help="also keep every frame in this directory")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    frames = Path(args.frames) if args.frames else Path(tempfile.mkdtemp(prefix="wrinkle-frames-"))
    model = compile_model(default_rig(args.resolution))
    sim = Simulator(model)
    for name in ("frown", *EXPRESSIONS):
        pose, box = _pose(name), CLOSEUP.get(name, MIDFACE)
        panels, crops = [], []
        for age in AGES:
            state = model.rest_state()
            control = FaceControl(model)
            pose(control)
            control.set("age", float(age))
            sim.settle(state, control, max_seconds=4.0)
            path = render_to_file(model, state, frames / f"{name}_{age}.png", size=(w, h))
            img = Image.open(path).convert("RGB")
            panels.append(np.asarray(img))
            crop = img.crop((int(box[0] * w), int(box[1] * h), int(box[2] * w), int(box[3] * h)))
            if crop.width < w // 2:  # small close-ups are shown at twice the size
                crop = crop.resize((2 * crop.width, 2 * crop.height), Image.LANCZOS)
            crops.append(np.asarray(crop))
            bulge = float(np.abs(state.surface - state.positions).max())
            print(f"{name} at {age}: largest bulge {10 * bulge:.2f} mm -> {path}")
        Image.fromarray(np.concatenate(panels, axis=1)).save(out / f"wrinkles_{name}.png")
        Image.fromarray(np.concatenate(crops, axis=1)).save(out / f"wrinkles_{name}_closeup.png")
    if sim.guard_events:
        print(f"warning: {len(sim.guard_events)} simulation guard events", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
