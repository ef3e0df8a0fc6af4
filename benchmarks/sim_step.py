"""How fast the face simulates: for resolutions 0, 1, 2 and both integrators, microseconds per step,
substeps per 60 Hz frame, and the share of a 60 Hz frame on one core.

    .venv/bin/python benchmarks/sim_step.py [--resolutions 0 1 2] [--frames 30] [--no-scan]

Method: the default face (gravity on) under the happiness preset, wrinkles off (their layer's cost is
printed on its own line), numba kernels warmed up first; times are the CPU time of this thread
(time.thread_time: one core's work, not inflated when other processes share the machine), best of 3
runs of --frames frames. A
"step" is one RK2 substep (two force evaluations) or one implicit substep (one spring pass and one
prefactored solve). The scanned head (sim.face.scan, the default face of the application) is
timed the same way after the procedural resolutions, with its build time (rig transfer, compile), the
posing of all its 26,719 vertices (`ScanDressing.pose`, the renderer's side of a frame) and its cost
as a ratio to resolution 0's in the same run, and at the live loop's faster ticks (120 and 240 Hz:
one substep a tick, so 2 and 4 solves per 60 Hz frame; `puppet live` headless ticks at 240 Hz). The last block compares the two integrators' transients on the default face:
time for the left mouth corner to reach 90 % of its settled AU12 displacement.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

FRAME = 1.0 / 60.0


def _frame_ms(sim: object, model: object, control: object, frames: int) -> float:
    state = model.rest_state()  # type: ignore[attr-defined]
    for _ in range(2):
        sim.step(state, control)  # type: ignore[attr-defined]
    best = float("inf")
    for _ in range(3):
        t0 = time.thread_time()
        for _ in range(frames):
            sim.step(state, control)  # type: ignore[attr-defined]
        best = min(best, (time.thread_time() - t0) / frames)
    return best * 1e3


def _rise_time(model: object, method: str) -> float:
    from sim.integrator import Simulator
    from sim.state import FaceControl

    c = FaceControl()
    c.set("zygomaticus_major_l", 1.0)
    sim = Simulator(model, wrinkles=False, method=method)  # type: ignore[arg-type]
    state = model.rest_state()  # type: ignore[attr-defined]
    i = model.mesh.landmarks["mouth_corner_l"]  # type: ignore[attr-defined]
    track = []
    for _ in range(120):
        sim.step(state, c)
        track.append(np.linalg.norm(state.positions[i] - model.rest[i]))  # type: ignore[attr-defined]
    final = track[-1]
    k = next(n for n, d in enumerate(track) if d >= 0.9 * final)
    return (k + 1) * FRAME


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--no-scan", action="store_true", help="leave out the scanned head")
    args = parser.parse_args()

    from sim import facs
    from sim.build import compile_model
    from sim.integrator import Simulator
    from sim.face import default_rig
    from sim.state import FaceControl

    control = FaceControl()
    facs.apply_expression(control, "happiness")
    print(f"{'res':>3} {'verts':>6} {'springs':>7} {'method':>8} {'auto':>4} {'substeps':>8} "
          f"{'us/step':>8} {'ms/frame':>8} {'% of 60Hz':>9}")
    models = {}
    for res in args.resolutions:
        t0 = time.perf_counter()
        model = compile_model(default_rig(res))
        models[res] = model
        compile_s = time.perf_counter() - t0
        auto = Simulator(model, wrinkles=False).method
        for method in ("rk2", "implicit"):
            sim = Simulator(model, wrinkles=False, method=method)
            frames = args.frames if sim.substeps * len(model.spring_indices) < 3e6 else 3
            ms = _frame_ms(sim, model, control, frames)
            mark = "*" if method == auto else ""
            print(f"{res:>3} {model.n_vertices:>6} {len(model.spring_indices):>7} {method:>8} {mark:>4} "
                  f"{sim.substeps:>8} {1e3 * ms / sim.substeps:>8.1f} {ms:>8.2f} {100 * ms / (1e3 * FRAME):>8.1f}%")
        print(f"    compile_model: {compile_s:.2f} s")
    auto_ms = {}
    for res, model in models.items():
        sim = Simulator(model, wrinkles=False)
        auto_ms[res] = _frame_ms(sim, model, control, args.frames)
    if not args.no_scan:
        _scan(control, args.frames, auto_ms)
    if 0 in models:
        from sim.wrinkles.layer import apply_wrinkles

        m = models[0]
        state = m.rest_state()
        state.age = 70.0
        apply_wrinkles(m, state)
        t0 = time.thread_time()
        for _ in range(30):
            apply_wrinkles(m, state)
        print(f"wrinkle layer (res 0, age 70): {(time.thread_time() - t0) / 30 * 1e3:.2f} ms/frame")
        for method in ("rk2", "implicit"):
            print(f"AU12 rise to 90 % (res 0, {method}): {_rise_time(m, method) * 1e3:.0f} ms")


def _scan(control: object, frames: int, auto_ms: dict[int, float]) -> None:
    """The scanned head: build, simulate (auto method), pose the whole scan; ratios to the
    procedural faces timed in this run."""
    from sim.build import compile_model
    from sim.face.scan.dressing import build_dressing
    from sim.face.scan.rig import SCAN_PARAMS, scan_rig
    from sim.integrator import Simulator

    t0 = time.perf_counter()
    rig = scan_rig()
    t1 = time.perf_counter()
    model = compile_model(rig, SCAN_PARAMS)
    t2 = time.perf_counter()
    sim = Simulator(model, wrinkles=False)
    ms = _frame_ms(sim, model, control, frames)
    print(f"scan {model.n_vertices:>6} {len(model.spring_indices):>7} {sim.method:>8} {'*':>4} {sim.substeps:>8} "
          f"{1e3 * ms / sim.substeps:>8.1f} {ms:>8.2f} {100 * ms / (1e3 * FRAME):>8.1f}%")
    print(f"    scan_rig (the shipped rig): {t1 - t0:.2f} s, compile_model: {t2 - t1:.2f} s")
    for res, base in auto_ms.items():
        print(f"    scan / resolution {res} (each with its auto method): {ms / base:.2f}x")
    # `puppet live` headless ticks at 240 Hz (puppet.live.LIVE_TICK_RATE; a window at 60 Hz): one
    # implicit substep a tick, four ticks per 60 Hz frame
    for rate in (120.0, 240.0):
        fast = Simulator(model, 1.0 / rate, wrinkles=False)
        ticks = int(rate / 60.0)
        tick_ms = _frame_ms(fast, model, control, frames * ticks)
        print(f"    at {rate:.0f} Hz ticks: {tick_ms:.2f} ms a tick, {ticks * tick_ms:.2f} ms per 60 Hz frame "
              f"({100 * ticks * tick_ms / (1e3 * FRAME):.1f}% of a 60 Hz frame)")
    t0 = time.thread_time()
    Simulator(model, 1.0 / 50.0, wrinkles=False)  # a substep no other simulator here used
    print(f"    a simulator's set-up (its matrix factored, nothing kept): {time.thread_time() - t0:.2f} s; "
          f"the same face and substep again: ", end="")
    t0 = time.thread_time()
    Simulator(model, 1.0 / 50.0, wrinkles=False)
    print(f"{time.thread_time() - t0:.3f} s")
    dressing = build_dressing(model)
    state = model.rest_state()
    sim.settle(state, control, max_seconds=1.0)  # type: ignore[arg-type]
    best = float("inf")
    for _ in range(3):
        t0 = time.thread_time()
        for _ in range(frames):
            dressing.pose(state.surface, control)
        best = min(best, (time.thread_time() - t0) / frames)
    print(f"    pose all 26719 vertices: {best * 1e3:.2f} ms ({100 * best / FRAME:.1f}% of a 60 Hz frame)")


if __name__ == "__main__":
    main()
