"""The tick rate of a show on the wall clock, chosen from the face's measured simulation step: the
fastest rate that leaves the simulation under a budget of one core (puppet.live's loop wakes on
events, so a faster tick shortens how long an event waits for the simulation, but a step too slow
for its tick makes the loop fall behind)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from puppet.live import LIVE_TICK_RATE, TICK_RATES, Face

#: the share of one core the simulation may take when the tick rate is chosen from the face's cost.
#: The rest of a tick (events, mapping, recording) and the drawing need the remainder: with the
#: scanned head's step at 1.4-1.9 ms, 240 Hz (a third to half a core) fell behind on the shared
#: development machine (event->state p99 133-155 ms at load 6, `benchmarks/live_latency.py`) where
#: 120 Hz held 33-35 ms; the procedural face's RK2 step still affords 240 Hz. With the faster
#: solve the scanned head's step timed here is 1.12-1.16 ms (27-28 % of a core at 240 Hz), but in
#: the live loop, where the factors are out of the caches by the next tick, it costs 1.3-2.2 ms:
#: a quarter of a core kept this machine's scanned head at 120 Hz. With the faster live tick
#: (`docs/simulation.md`, "The live tick on the scanned head") the step timed here is 0.97-1.07 ms at
#: load 4-5 (the code before: 1.04-1.07), 23-26 % of a core at 240 Hz: a quarter no longer kept 240 Hz
#: out, where four ticks a frame cost 27-30 % of a frame. A fifth of a core keeps 120 Hz (240 Hz
#: needs a step of 0.83 ms or less, 120 Hz 1.67 ms: the procedural face's RK2 step, 0.27 ms at
#: 240 Hz, still affords 240). The step is the fastest of a few (`choose_tick_rate`): at load 4-5
#: their median here was 1.0-2.1 ms, which would have put a busy machine's choice at 60 Hz.
TICK_BUDGET = 0.2


def choose_tick_rate(model: Any, rates: Sequence[float] = TICK_RATES, budget: float = TICK_BUDGET,
                     steps: int = 7) -> tuple[float, dict[float, float]]:
    """The highest of `rates` whose simulation step, timed here on this face (CPU time of this
    thread, the fastest of `steps` steps of a throw-away simulator after one warm step: what the
    machine's core does, the least touched by other programs sharing its caches), keeps the
    simulation under `budget` of a core; the lowest rate when none does. Returns the rate and the
    seconds per step measured at each rate tried. The scanned head's implicit step costs about the
    same at any dt, so 240 Hz would take a third to half a core where 120 Hz leaves room for
    the rest of the tick and for drawing; the procedural face's RK2 step shrinks with dt and
    affords 240 Hz."""
    import sim

    cost: dict[float, float] = {}
    for rate in sorted(rates, reverse=True):
        s = sim.Simulator(model, 1.0 / rate, wrinkles=False)
        state, control = model.rest_state(), sim.FaceControl(model)
        s.step(state, control)
        times = []
        for _ in range(steps):
            c0 = time.thread_time()
            s.step(state, control)
            times.append(time.thread_time() - c0)
        cost[rate] = float(np.min(times))
        if cost[rate] * rate <= budget:
            return rate, cost
    return min(rates), cost


def live_tick_rate(face: Face, announce: Callable[[str], None] | None = None) -> float:
    """The tick rate of a show on the wall clock for this face: `choose_tick_rate`, measured once
    per face, program version and machine and kept in the face cache (a small JSON file), so later
    shows start without the measurement; LIVE_TICK_RATE when the face cache is off and the
    measurement fails."""
    import json

    from puppet import face_cache

    directory = face_cache.cache_dir()
    path = None
    if directory is not None:
        what = json.dumps({"rig": face.rig, "budget": TICK_BUDGET, "rates": TICK_RATES}, sort_keys=True, default=str)
        path = directory / f"tick-rate-{face_cache.entry_key(what.encode())}.json"
        try:
            rate = float(json.loads(path.read_text())["rate"])
            if rate in TICK_RATES:
                return rate
        except (OSError, ValueError, KeyError, TypeError, RecursionError):  # damaged: measured again
            pass
    if announce is not None:
        announce("measuring the face's tick cost (once for this face)")
    try:
        rate, cost = choose_tick_rate(face.model)
    except Exception:
        return LIVE_TICK_RATE
    if path is not None:
        try:
            from safefile import atomic_write

            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_write(path) as fh:
                json.dump({"rate": rate, "step_ms": {f"{r:g}": c * 1000 for r, c in cost.items()}}, fh)
        except (OSError, ValueError):  # a cache that cannot be written (full, read-only: safefile's BadFile)
            pass
    return rate
