"""Where a live tick's simulation spends its time: the CPU time of each part of the simulator's
step, its prepare between ticks and the wrinkle surface, for several tick scenarios built in one
process and run in alternating batches (so all see the same load).

    .venv/bin/python benchmarks/tick_parts.py [--scenarios sim,dials,dials-still:jaw] [--batches 12]
        [--ticks 120] [--rate 120] [--lean] [--tree DIR]

Scenarios: `sim` is live_tick_pair.py's sim scenario (the happiness preset's muscles moving every
tick, the jaw at rest); `dials` its dials scenario (8 SGI dials from the mock device through the
default map: the age, six dials of 15 muscle channels and the jaw, with the events, mapping and
recording of the live loop); `dials-still:jaw` (or `:age`, `:muscles`, joined by +) the same with
those dials left where they start (a relative dial still: the jaw shut, the age where it starts).
Each call of the compiled kernels the simulator calls from Python, and (without --lean) of its
Python methods, is wrapped and timed with time.thread_time; a part's time is exclusive of the
timed calls inside it (a method's own Python, with the dispatch of what it calls; a kernel's
time includes numba's dispatch). The wrappers cost ~0.5-1 us a call, charged to the caller:
--lean times the kernels and the three top methods only (step, prepare, surface: their Python is
then all the Python of the simulation). Printed: each part's median over the batches in us a tick,
the simulation (step + prepare + surface) and the loop's total, and a digest of each scenario's
final positions (the same digest from two trees: the same bits). --tree: the checkout to measure
(default this one), e.g. to profile the code before a change.
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = 'impersonate = "sgi"\nspeed = 0\nduration = {seconds}\n{dials}\n'
DIAL = ('[[sine]]\ncontrol = "dial{n}"\nduration = {seconds}\nfreq = {freq}\namplitude = {amp}\noffset = 0.5\n'
        'rate = 120\n')
KERNELS = {  # the kernels the simulator calls from Python (a module without one of them: skipped)
    "sim.implicit": ["_predict", "_held_rhs", "_held_rhs_turned", "_sym_sweeps", "_sn_sweeps", "_inputs", "_advance",
                     "_unchanged", "_remember", "_bend_turned_add", "_bend_turned", "_csr_times_flat"],
    "sim.integrator": ["_jaw_pose", "_open_pose", "_grid_pose", "_place", "_active", "_save_hold", "_held_deviation",
                       "_fixed_forces", "_hold", "_max_deviation"],
    "sim.margin_contact": ["_memory", "_recall"],
    "sim.wrinkles.layer": ["frame_displacement"],
}
METHODS = {  # (module, class): methods
    ("sim.integrator", "Simulator"): ["_set_jaw", "_set_opening", "_age_skin", "_jaw_motion", "_muscles",
                                      "_start_pose", "_constants", "_place_held", "_surface", "_judge",
                                      "_recall_contact"],
    ("sim.implicit", "ImplicitStepper"): ["frame", "predict", "_solve_free", "_is_predicted", "_with_bending"],
    ("sim.margin_contact", "SolvedContact"): ["memory", "recall"],
    ("puppet.live", "LiveCore"): ["tick", "prepare_next", "finish_surface", "after_frame"],
}
FUNCTIONS = {"sim.integrator": ["jaw_motion", "jaw_rotation"], "sim.wrinkles.aging": ["skin_params_for_age"],
             "sim.wrinkles.layer": ["compiled_displacement", "apply_wrinkles"]}
TOP = ["step", "prepare", "surface"]


class Timer:
    """Exclusive CPU time per name: each wrapped call's time minus that of the wrapped calls inside it."""

    def __init__(self) -> None:
        self.own: dict[str, float] = defaultdict(float)
        self.whole: dict[str, float] = defaultdict(float)
        self._inner: list[float] = []

    def wrap(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        clock, inner, own, whole = time.thread_time, self._inner, self.own, self.whole

        def timed(*args: Any, **kw: Any) -> Any:
            t = clock()
            inner.append(0.0)
            try:
                return fn(*args, **kw)
            finally:
                spent = clock() - t
                own[name] += spent - inner.pop()
                whole[name] += spent
                if inner:
                    inner[-1] += spent
        return timed

    def clear(self) -> None:
        self.own.clear()
        self.whole.clear()


def _instrument(timer: Timer, lean: bool) -> None:
    import importlib

    def short(module: str, name: str) -> str:
        return f"{module.rsplit('.', 1)[-1]}.{name}"

    for module, names in KERNELS.items():
        mod = importlib.import_module(module)
        for name in names:
            if hasattr(mod, name):
                setattr(mod, name, timer.wrap(short(module, name), getattr(mod, name)))
    sim_cls = importlib.import_module("sim.integrator").Simulator
    for name in TOP:
        setattr(sim_cls, name, timer.wrap(f"Simulator.{name}", getattr(sim_cls, name)))
    if lean:
        return
    for (module, cls_name), names in METHODS.items():
        cls = getattr(importlib.import_module(module), cls_name)
        for name in names:
            if hasattr(cls, name):
                setattr(cls, name, timer.wrap(f"{cls_name}.{name}", getattr(cls, name)))
    for module, names in FUNCTIONS.items():
        mod = importlib.import_module(module)
        for name in names:
            if hasattr(mod, name):
                setattr(mod, name, timer.wrap(short(module, name), getattr(mod, name)))


def _dials(face: Any, still: set[str], rate: float, seconds: float) -> tuple[Callable[[int], None], Callable[[], Any]]:
    """The dials scenario's loop (live_tick_pair.py's worker), with the `still` dials not turned."""

    def amp(n: int) -> float:
        held = (n == 0 and "age" in still) or (n == 7 and "jaw" in still) or (1 <= n <= 6 and "muscles" in still)
        return 0.0 if held else 0.4

    from live_tick_pair import dial_core  # this folder: the core live_tick_pair.py times

    dials = "".join(DIAL.format(n=n, seconds=seconds, freq=0.3 + 0.17 * n, amp=amp(n)) for n in range(8))
    core, events = dial_core(face, SCRIPT.format(seconds=seconds, dials=dials), rate, "tick-parts-")
    later = core.surface_later
    per_frame = max(1, int(round(rate / 60.0)))
    at = [0]

    from live_tick_pair import run_ticks  # this folder: the loop live_tick_pair.py times

    def run(n: int) -> None:
        at[0] = run_ticks(core, events, at[0], n, per_frame, later)
    return run, lambda: core.state


def _sim(face: Any, rate: float) -> tuple[Callable[[int], None], Callable[[], Any]]:
    """live_tick_pair.py's sim scenario: the happiness preset's muscles moving every tick."""
    import numpy as np

    from sim import facs
    from sim.integrator import Simulator
    from sim.state import FaceControl

    control = FaceControl()
    facs.apply_expression(control, "happiness")
    sim = Simulator(face.model, 1.0 / rate, wrinkles=True)
    state = face.model.rest_state()
    base = np.array(control.values)
    muscle = sim._is_muscle
    per_frame = max(1, int(round(rate / 60.0)))
    k = [0]

    def run(n: int) -> None:
        for _ in range(n):
            control.values[muscle] = base[muscle] * (0.8 + 0.2 * np.sin(k[0] / 10.0))
            sim.step(state, control, surface=False)
            k[0] += 1
            if k[0] % per_frame == 0:
                sim.surface(state)
            sim.prepare(state)
    return run, lambda: state


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="sim,dials,dials-still:jaw,dials-still:age")
    ap.add_argument("--batches", type=int, default=12)
    ap.add_argument("--ticks", type=int, default=120, help="ticks a batch")
    ap.add_argument("--warm", type=int, default=60, help="ticks each scenario runs first, untimed")
    ap.add_argument("--rate", type=float, default=120.0)
    ap.add_argument("--lean", action="store_true", help="time the kernels and step, prepare, surface only")
    ap.add_argument("--tree", default=str(ROOT), help="the checkout to measure")
    a = ap.parse_args()
    sys.path.insert(0, str(Path(a.tree).resolve()))
    from puppet import live

    face = live.load_face()  # (before the wrappers: a kernel compiled now sees the kernels it calls)
    from sim.integrator import Simulator, warm_up

    warm_up()
    Simulator(face.model, 1.0 / a.rate)
    timer = Timer()
    _instrument(timer, a.lean)
    seconds = (a.warm + a.ticks * a.batches) / a.rate + 1.0
    scenarios = {}
    for name in a.scenarios.split(","):
        if name == "sim":
            scenarios[name] = _sim(face, a.rate)
        elif name == "dials" or name.startswith("dials-still:"):
            still = set(name.split(":", 1)[1].split("+")) if ":" in name else set()
            scenarios[name] = _dials(face, still, a.rate, seconds)
        else:
            ap.error(f"unknown scenario {name!r}: sim, dials, dials-still:jaw[+age+muscles]")
    for run, _ in scenarios.values():
        run(a.warm)
    names = list(scenarios)
    parts: dict[str, list[dict[str, float]]] = {n: [] for n in names}
    totals: dict[str, list[tuple[float, float]]] = {n: [] for n in names}
    for b in range(a.batches):
        for name in names if b % 2 == 0 else names[::-1]:
            timer.clear()
            t0 = time.thread_time()
            scenarios[name][0](a.ticks)
            total = time.thread_time() - t0
            simulated = sum(timer.whole[f"Simulator.{m}"] for m in TOP)
            parts[name].append(dict(timer.own))
            totals[name].append((simulated, total))
    us = 1e6 / a.ticks

    def median(name: str, part: str) -> float:
        return statistics.median(p.get(part, 0.0) for p in parts[name]) * us

    every = sorted({k for n in names for p in parts[n] for k in p}, key=lambda k: -max(median(n, k) for n in names))
    print(f"{Path(live.__file__).parents[1]}: {a.batches} batches of {a.ticks} ticks at {a.rate:.0f} Hz a scenario, alternating; "
          f"us a tick, median of the batches")
    print(f"{'part':32s}" + "".join(f"{n[:16]:>17s}" for n in names))
    for k in every:
        print(f"{k:32s}" + "".join(f"{median(n, k):17.1f}" for n in names))
    for label, i in (("simulation (step+prepare+surface)", 0), ("the loop", 1)):
        print(f"{label:32s}" + "".join(f"{statistics.median(t[i] for t in totals[n]) * us:17.1f}" for n in names))
    print(f"{'simulation, best batch':32s}" + "".join(f"{min(t[0] for t in totals[n]) * us:17.1f}" for n in names))
    for name, (_, state) in scenarios.items():
        print(f"  {name}: positions {hashlib.sha256(state().positions.tobytes()).hexdigest()[:16]}")


if __name__ == "__main__":
    main()
