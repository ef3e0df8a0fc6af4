"""The live loop's simulation on the default face, this tree against another checkout of the
program (the code before a change), measured paired: two worker processes, one per tree, run
batches of ticks in turn (A, B, A, B, ...), so both see the same load.

    .venv/bin/python benchmarks/live_tick_pair.py --base DIR [--rate 120] [--batches 16] [--ticks 120]

DIR: a checkout of the code to compare with (e.g. `git worktree add /tmp/before main`; its numba
kernels compile on the first run). Each worker builds the default face (`puppet.live.load_face`), a
dense scripted dial take from the mock device through the default map (a channel moves on most
ticks), a `LiveCore` at --rate recording to a temporary file, and runs the live loop's work per
tick as `run_realtime` does headless with 60 Hz frames: the next step's input-free part between
ticks (`prepare_next`), the tick (events, mapping, the simulator step, the wrinkle surface where the
tree makes it every tick), and on every tick that ends a 60 Hz frame the surface (where the tree
leaves it for the frame) and the recording's JSON (`after_frame`); no drawing. Timed: this thread's
CPU time (time.thread_time, one core's work), per batch; printed: the median and the best batch of
each tree as milliseconds a tick and as the share of a 60 Hz frame (ticks per frame x tick), their
ratio, and whether both trees reached the very same positions after each batch (the replay's bits;
when not, how far apart they came at most: a change of the step's bits that a take header names).
With --scenario dials also the simulation's part of the loop alone: the CPU time inside the
simulator's step, its prepare between ticks and the surface (each call timed; the mapping, the
events and the recording are the rest).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
impersonate = "sgi"
speed = 0
duration = {seconds}
{dials}
"""
DIAL = """
[[sine]]
control = "dial{n}"
duration = {seconds}
freq = {freq}
amplitude = 0.4
offset = 0.5
rate = 120
"""


def _sim_ticks(tree: str, rate: float) -> None:
    """sim_step.py's live ticks (`_live_ticks`): the happiness preset with the muscles' activations
    moving every tick, the step, the wrinkle surface (every tick, or once a 60 Hz frame where the
    tree's live loop leaves it for the frame), the next step's input-free part between ticks."""
    sys.path.insert(0, tree)
    import numpy as np

    from puppet import live
    from sim import facs
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = live.load_face().model
    control = FaceControl()
    facs.apply_expression(control, "happiness")
    sim = Simulator(model, 1.0 / rate, wrinkles=True)
    state = model.rest_state()
    base = np.array(control.values)
    muscle = sim._is_muscle
    later = hasattr(live.LiveCore, "finish_surface")
    per_frame = max(1, int(round(rate / 60.0)))
    k = 0
    print(json.dumps({"ready": live.__file__, "surface_later": later}), flush=True)
    for line in sys.stdin:
        n = int(line)
        t0 = time.thread_time()
        for _ in range(n):
            control.values[muscle] = base[muscle] * (0.8 + 0.2 * np.sin(k / 10.0))
            sim.step(state, control, surface=False)
            k += 1
            if not later or k % per_frame == 0:
                sim.surface(state)
            sim.prepare(state)
        cpu = time.thread_time() - t0
        digest = hashlib.sha256(state.positions.tobytes()).hexdigest()[:16]
        print(json.dumps({"cpu": cpu, "sim": cpu, "digest": digest, "events": k, "x": state.positions.ravel().tolist()}),
              flush=True)


def dial_core(face, script: str, rate: float, prefix: str):  # type: ignore[no-untyped-def]
    """A `LiveCore` on `face` at `rate` recording to a temporary folder, mapped from the mock
    device of `script` (a mock:// TOML script), with the script's events; the surface left for the
    frame where the tree's loop can (as run_realtime sets it headless with frames slower than ticks)."""
    import devices
    from puppet import live
    from puppet.mapping import Mapper
    from puppet.session import SessionWriter

    tmp = Path(tempfile.mkdtemp(prefix=prefix))
    (tmp / "s.toml").write_text(script)
    dev = devices.open_device(f"mock://{tmp / 's.toml'}")
    spec = live.build_mapping(face.vocab, None, [dev.spec])
    events = live.scripted_events([dev])
    dev.close()
    writer = SessionWriter(tmp / "take.jsonl", live.session_header(face, spec, rate, [dev.spec]), fsync_seconds=None)
    core = live.LiveCore(face, Mapper(spec, face.vocab), rate=rate, writer=writer)
    core.surface_later = hasattr(core, "finish_surface")
    return core, events


def run_ticks(core, events: list, i: int, n: int, per_frame: int, later: bool) -> int:  # type: ignore[no-untyped-def]
    """`n` ticks of the live loop headless as `run_realtime` runs them (the events due by each
    tick's end from `events[i:]`, the next step's input-free part, the tick, and on every tick that
    ends a 60 Hz frame the surface where the loop leaves it for the frame and the recording's
    frame); returns the index of the next event."""
    for _ in range(n):
        boundary = core.tick_count * core.dt + 1e-12
        batch = []
        while i < len(events) and events[i].t <= boundary:
            batch.append(events[i])
            i += 1
        core.prepare_next()
        core.tick(batch)
        if core.tick_count % per_frame == 0:
            if later:
                core.finish_surface()
            core.after_frame()
    return i


def _worker(tree: str, rate: float, seconds: float) -> None:
    """One tree's live loop, driven by batch requests on stdin ("N" ticks), answering one JSON line
    per batch: CPU seconds and the positions' digest."""
    sys.path.insert(0, tree)
    from puppet import live

    face = live.load_face()
    dials = "".join(DIAL.format(n=n, seconds=seconds, freq=0.3 + 0.17 * n) for n in range(8))
    core, events = dial_core(face, SCRIPT.format(seconds=seconds, dials=dials), rate, "tick-pair-")
    later = core.surface_later
    per_frame = max(1, int(round(rate / 60.0)))
    i = 0
    clock = time.thread_time
    spent = [0.0]  # this batch's CPU time in the simulator's own calls (step, prepare, surface)
    simulator = core.sim

    def timed(fn):  # type: ignore[no-untyped-def]
        def run(*args, **kw):  # type: ignore[no-untyped-def]
            t = clock()
            out = fn(*args, **kw)
            spent[0] += clock() - t
            return out
        return run

    for name in ("step", "prepare", "surface"):  # the instance's attributes: the class is untouched
        setattr(simulator, name, timed(getattr(simulator, name)))
    print(json.dumps({"ready": live.__file__, "surface_later": later}), flush=True)
    for line in sys.stdin:
        n = int(line)
        spent[0] = 0.0
        t0 = clock()
        i = run_ticks(core, events, i, n, per_frame, later)
        cpu = clock() - t0
        digest = hashlib.sha256(core.state.positions.tobytes()).hexdigest()[:16]
        print(json.dumps({"cpu": cpu, "sim": spent[0], "digest": digest, "events": i,
                          "x": core.state.positions.ravel().tolist()}), flush=True)
    core.writer.close(core.tick_count)


def _start(tree: str, rate: float, seconds: float, scenario: str) -> subprocess.Popen:  # type: ignore[type-arg]
    env = dict(os.environ, PYTHONPATH=tree)
    p = subprocess.Popen([sys.executable, __file__, "--worker", tree, "--rate", str(rate), "--seconds", str(seconds),
                          "--scenario", scenario],
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env, cwd=tree)
    assert p.stdout is not None
    hello = json.loads(p.stdout.readline())
    print(f"  {tree}: {hello['ready']} (surface for the frame only: {hello['surface_later']})")
    return p


def _batch(p: subprocess.Popen, n: int) -> dict:  # type: ignore[type-arg]
    assert p.stdin is not None and p.stdout is not None
    p.stdin.write(f"{n}\n")
    p.stdin.flush()
    return json.loads(p.stdout.readline())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", help="a checkout of the code to compare with")
    ap.add_argument("--rate", type=float, default=120.0)
    ap.add_argument("--batches", type=int, default=16)
    ap.add_argument("--ticks", type=int, default=120, help="ticks a batch")
    ap.add_argument("--warm", type=int, default=60, help="ticks run first, untimed")
    ap.add_argument("--scenario", choices=("dials", "sim"), default="dials",
                    help="dials: the whole live loop on a scripted dial take; sim: sim_step.py's live ticks")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--seconds", type=float, default=0.0, help=argparse.SUPPRESS)
    a = ap.parse_args()
    seconds = a.seconds or (a.warm + a.batches * a.ticks) / a.rate + 1.0
    if a.worker:
        if a.scenario == "sim":
            _sim_ticks(a.worker, a.rate)
        else:
            _worker(a.worker, a.rate, seconds)
        return
    if not a.base:
        ap.error("--base DIR is needed (a checkout of the code to compare with)")
    print(f"load before: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")
    trees = {"before": str(Path(a.base).resolve()), "now": str(ROOT)}
    procs = {k: _start(t, a.rate, seconds, a.scenario) for k, t in trees.items()}
    for p in procs.values():
        _batch(p, a.warm)
    cpu: dict[str, list[float]] = {k: [] for k in trees}
    simulated: dict[str, list[float]] = {k: [] for k in trees}
    same = True
    apart = 0.0  # the largest distance between the two trees' positions after a batch, cm
    for b in range(a.batches):
        order = list(trees) if b % 2 == 0 else list(reversed(trees))
        out = {k: _batch(procs[k], a.ticks) for k in order}
        same = same and out["before"]["digest"] == out["now"]["digest"]
        apart = max(apart, max(abs(p - q) for p, q in zip(out["before"]["x"], out["now"]["x"])))
        for k in trees:
            cpu[k].append(out[k]["cpu"] / a.ticks * 1e3)
            simulated[k].append(out[k].get("sim", out[k]["cpu"]) / a.ticks * 1e3)
    for p in procs.values():
        assert p.stdin is not None
        p.stdin.close()
        p.wait()
    per_frame = a.rate / 60.0
    print(f"{a.scenario}: {a.rate:.0f} Hz ticks, {a.batches} batches of {a.ticks} ticks each tree, alternating")

    def medians(times: dict[str, list[float]]) -> None:
        for k in trees:
            med, best = statistics.median(times[k]), min(times[k])
            print(f"  {k:6s}: {med:.3f} ms a tick median ({100 * per_frame * med / (1e3 / 60):.1f} % of a 60 Hz "
                  f"frame), best batch {best:.3f} ms ({100 * per_frame * best / (1e3 / 60):.1f} %)")

    medians(cpu)
    ratios = [b / n for b, n in zip(cpu["before"], cpu["now"])]
    print(f"  before / now: median of the paired batches {statistics.median(ratios):.2f}x "
          f"(range {min(ratios):.2f}-{max(ratios):.2f}); the same positions after every batch: {same}"
          + ("" if same else f" (at most {apart:.3g} cm apart)"))
    if a.scenario == "dials":
        print("  of which the simulation (the simulator's step, its prepare between ticks and the surface):")
        medians(simulated)
        ratios = [b / n for b, n in zip(simulated["before"], simulated["now"])]
        print(f"  before / now (simulation): median of the paired batches {statistics.median(ratios):.2f}x "
              f"(range {min(ratios):.2f}-{max(ratios):.2f})")
    print(f"load after: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}")


if __name__ == "__main__":
    main()
