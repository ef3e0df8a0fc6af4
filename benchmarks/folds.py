"""How much skin turns over on the scanned head under each preset, each channel at full value and
each ARKit shape that shares a second channel (cm2 of triangles whose normal points against their rest normal), the figure tests/sim/
test_scan_face.py holds to 0.1 cm2 (run by hand):

    nice .venv/bin/python benchmarks/folds.py [--only anger,corrugator_l,...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def turned_over_area(model, x: np.ndarray) -> float:  # type: ignore[no-untyped-def]
    """cm2 of skin triangles whose normal points against their rest normal (sim.antifold)."""
    from sim.antifold import turned_over_area as area

    return area(model.triangles, model.rest, x)


def main(argv: list[str] | None = None) -> int:
    from puppet.face_cache import scan_model
    from sim.facs import EXPRESSIONS, apply_expression, preset_face
    from sim.integrator import Simulator
    from sim.state import FaceControl

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="")
    args = ap.parse_args(argv)
    only = {n for n in args.only.split(",") if n}
    model = scan_model(None)
    sim = Simulator(model, wrinkles=False)
    poses: dict[str, FaceControl] = {}
    for name in EXPRESSIONS:
        c = FaceControl()
        apply_expression(c, name, face=preset_face(model.rig))
        poses[name] = c
    for spec in model.channels:
        if spec.name == "age" or spec.name.endswith("_r"):
            continue
        for value in (spec.hi, spec.lo) if spec.kind == "eyes" else (spec.hi,):  # the lids follow the gaze
            c = FaceControl()
            c.set(spec.name, value)
            poses[spec.name if value == spec.hi else f"{spec.name} {value:+g}"] = c
    c = FaceControl()  # a blink looking aside: the lids closing on an eye that carries them sideways
    for name, value in (("eyes_yaw", 1.0), ("orbicularis_oculi_lid_l", 1.0), ("orbicularis_oculi_lid_r", 1.0)):
        c.set(name, value)
    poses["blink looking aside"] = c
    from puppet.capture.arkit_in import shape_channels
    from puppet.export.arkit import ARKIT_SHAPES, SHAPE_SHARES

    for shape in ARKIT_SHAPES:  # the ARKit shapes that drive a second channel by a share, at 1
        if shape.removesuffix("Left").removesuffix("Right") in SHAPE_SHARES and not shape.endswith("Right"):
            c = FaceControl()
            c.values[...] = shape_channels({shape: np.ones(1)}, 1)[0]
            poses[f"ARKit {shape}"] = c
    total = 0.0
    for name, c in poses.items():
        if only and name not in only:
            continue
        state = model.rest_state()
        t0 = time.perf_counter()
        sim.settle(state, c, max_seconds=2.0 if name in EXPRESSIONS else 1.5)
        a = turned_over_area(model, state.positions)
        total += a
        flag = "  over" if a > 0.1 else ""
        print(f"{name:40s} {a:6.3f} cm2  ({time.perf_counter() - t0:.1f} s){flag}", flush=True)
    print(f"total {total:.2f} cm2")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
