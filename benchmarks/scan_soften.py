"""What softening the upper face's buckles (render.scan_soften) adds to the CPU half of a scanned
head's frame: posing the scan and making its rows (render.scan_draw.ScanPoser.rows) with and without
it, in alternating batches in one run, for a few presets settled on the default face; printed as
milliseconds per frame (process CPU time) and as the ratio of the two.
Run: .venv/bin/python benchmarks/scan_soften.py [--batches 20] [--presets fear,anger,neutral]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batches", type=int, default=20)
    ap.add_argument("--frames", type=int, default=20, help="frames per batch")
    ap.add_argument("--presets", default="fear,anger,neutral")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from puppet.face_cache import scan_model
    from render.scan_draw import ScanPoser, dressing_of, posed_scan
    from sim.facs import apply_expression, preset_face
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    poser = ScanPoser(dressing_of(model))
    for name in args.presets.split(","):
        sim = Simulator(model)
        state = model.rest_state()
        for k in range(60):
            control = FaceControl(model)
            if name != "neutral":
                apply_expression(control, name, min(1.0, (k + 1) / 40), preset_face(model.rig))
            sim.step(state, control)
        times: dict[bool, list[float]] = {True: [], False: []}
        for b in range(args.batches + 1):
            for soft in (True, False):
                t = time.process_time()
                for _ in range(args.frames):
                    if soft:
                        poser.rows(state)
                    else:
                        poser.maker.rows(posed_scan(poser.dressing, None, state))
                if b:  # the first batch warms up
                    times[soft].append((time.process_time() - t) / args.frames * 1e3)
        on, off = statistics.median(times[True]), statistics.median(times[False])
        print(f"{name:<9} pose + rows: {off:.3f} ms per frame, with the softening {on:.3f} ms "
              f"({on / off:.2f}x, +{on - off:.3f} ms)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
