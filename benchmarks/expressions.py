"""How far every landmark moves per AU and preset at full activation, in mm, next to real faces.

For each face (the default face at each resolution, and the default rig transferred onto a coarse
437-vertex head), gravity on: the rest drift (the largest |x - rest| after 1 s with no activation),
then for every AU of sim.facs and every preset the settled displacement of every landmark that
moves at least --min-mm (up / out / forward / total, in mm of a 90 mm outer-canthal-width adult;
"out" is away from the midline), and the stated targets of sim.face.targets with the real
range and its source. Ends with one table of the targets per face (the README's face section).

Usage: .venv/bin/python benchmarks/expressions.py [--res 0 1 2] [--no-head] [--min-mm 0.5]
       [--summary-only]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sim.face import targets as et
from sim.build import FaceModel, compile_model
from sim.face import default_model
from sim.integrator import Simulator
from sim.state import FaceControl


def settle(model: FaceModel, control: FaceControl) -> tuple[np.ndarray, int]:
    sim = Simulator(model, wrinkles=False)
    state = model.rest_state()
    sim.settle(state, control, max_seconds=3.0)
    return state.positions.copy(), len(sim.guard_events)


def rest_drift(model: FaceModel) -> float:
    sim = Simulator(model, wrinkles=False)
    state = model.rest_state()
    for _ in range(60):
        sim.step(state, FaceControl())
    return 10.0 * float(np.abs(state.positions - model.rest).max())


def face_report(label: str, model: FaceModel, min_mm: float, detail: bool) -> dict[tuple, float]:
    lm = model.mesh.landmarks
    k = 10.0 * et.face_scale_mm(lm, model.rest)
    t0 = time.perf_counter()
    print(f"\n## {label}: {model.n_vertices} vertices; rest drift with gravity {rest_drift(model):.4f} mm")
    values: dict[tuple, float] = {}
    for pose in et.poses():
        pos, guards = settle(model, et.pose_control(pose))
        if detail:
            print(f"\n{pose}" + (f"  ({guards} guard events)" if guards else ""))
            print(f"  {'landmark':18s} {'up':>6s} {'out':>6s} {'fwd':>6s} {'total':>6s}")
            for name, i in sorted(lm.items(), key=lambda kv: kv[0]):
                c = et.components(name, k * (pos[i] - model.rest[i]))
                if c["total"] >= min_mm:
                    print(f"  {name:18s} {c['up']:6.1f} {c['out']:6.1f} {c['forward']:6.1f} {c['total']:6.1f}")
        for t in et.TARGETS:
            if t.pose != pose:
                continue
            v = et.measure(t, lm, model.rest, pos)
            values[(t.pose, t.landmark, t.component)] = v
            if detail:
                flag = "ok" if t.lo <= v <= t.hi else "OUT"
                print(f"  target {t.landmark} {t.component}: {v:.2f} (want {t.lo:g}-{t.hi:g}; {t.source}) {flag}")
    print(f"({time.perf_counter() - t0:.1f} s)")
    return values


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, nargs="*", default=[0, 1, 2])
    ap.add_argument("--no-head", action="store_true", help="skip the transferred coarse head")
    ap.add_argument("--min-mm", type=float, default=0.5, help="print landmarks moving at least this")
    ap.add_argument("--summary-only", action="store_true")
    args = ap.parse_args()
    faces: list[tuple[str, FaceModel]] = [(f"default face, resolution {r}", default_model(r)) for r in args.res]
    if not args.no_head:
        from sim.face.transfer.synthetic import coarse_transferred_head

        faces.append(("transferred coarse head", compile_model(coarse_transferred_head())))
    results = [face_report(label, m, args.min_mm, not args.summary_only) for label, m in faces]
    cols = [f"res {r}" for r in args.res] + ([] if args.no_head else ["head"])
    print("\n| pose | landmark | motion (mm) | " + " | ".join(cols) + " | target | source |")
    print("|---" * (5 + len(cols)) + "|")
    for t in et.TARGETS:
        key = (t.pose, t.landmark, t.component)
        cells = []
        for r in results:
            v = r[key]
            cells.append(f"{v:.1f}" if t.lo <= v <= t.hi else f"**{v:.1f}**")
        comp = t.component.replace("ratio:up:", "up / up of ")
        print(f"| {t.pose} | {t.landmark} | {comp} | " + " | ".join(cells) + f" | {t.lo:g} to {t.hi:g} | {t.source} |")
    print("\n(bold: outside the target)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
