"""Input-to-frame latency of the live loop at 60 Hz: event timestamp (taken by the device reader
right after the read) -> the frame that shows it is ready (headless: the tick's simulation step is
done; with --render WxH, also drawn offscreen and read back, as a window would before swapping).

Two sources:
1. `mock://` playing a dense dial script in real time (the device thread stamps each event);
2. the SGI dial-and-button box emulator on a pseudo-terminal (tests/devices/emulators.py), in a
   process of its own (as a box is), turned at random moments, read by the real `sgi://` backend.
The loop records to a temporary file, as `puppet live` does (--no-record: it does not).
The fixed tick bounds the wait for the next tick boundary by one tick (16.7 ms); the target is
p99 <= one frame + 2 ms = 18.7 ms. The floor printed is that of frames on a fixed 60 Hz schedule (a
uniform wait for the next frame plus the work); the loop draws a tick that took events at once when
the last frame is half a frame old, so it can beat that floor. "work after the boundary" is drain + tick (+ render and readback):
an event that just missed a boundary waits ~16.5 ms (the 99th percentile of a uniform wait) plus that,
which is the floor printed for p99. The breakdown below each line times the parts (perf_counter,
p50 / p99 over the ticks): how late the loop woke after the boundary, the drain, applying the events,
the mapping (filters, combine, values into the FaceControl), the simulator step (RK2 frame, forces,
wrinkle surface), the tick's tail (digest copy, lights), the render; "recording (after frame)" is
the JSON and flush, done after the frame is ready and so not part of the latency. The step's CPU
time (this thread's) is printed beside its wall time: equal, the step was not kept waiting (by other
threads holding the interpreter, or other programs holding the core) but did more or slower work.
On the implicit integrator the loop solves the next step's all-but-the-muscles between ticks, then
drains the input (`Simulator.prepare`, printed as "computed between ticks"); a tick then only adds the
muscles' responses and the jaw's (the step starts from the last step's jaw opening and skin age,
`sim.Simulator.jaw_responses`) and solves the contact ("sim step"). `--jaw whole,responses` runs
each row also as takes recorded before were stepped (the jaw and the age taken whole at each step),
interleaved in the same run: the SGI box's default map turns the jaw and the age on two of its
eight dials, which made those ticks whole steps. `--solve idle,always` runs each row also as the loop
did before (the solve between ticks only when no input waits, a tick finding one doing the whole step)
beside now (the solve at every pass, the input drained after it).

"runnable, no CPU" is the loop thread's time on the run queue without a CPU (the kernel's
`/proc/thread-self/schedstat`, its second field) from the previous tick's end to the end of an
event's tick: what of that event's latency other programs took, the rest being the loop's own work
and its sleeps. Beside it, the share of a core the loop's thread used over the row. The SGI box
emulator runs in a session of its own, so that it is not in the show's autogroup (the fair scheduler
shares the CPU between sessions first, then between the threads of one): a box outside the machine
takes nothing of the show's share. `--repeat N` runs every row N times, interleaved.

Run:  .venv/bin/python benchmarks/live_latency.py [--seconds 10] [--render 640x360] [--no-record]
      [--rates 60,auto,240] [--wake off,on] [--realtime off,on] [--jaw whole,responses] [--solve idle,always]
      [--repeat N] [--json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import random
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "devices")]

import numpy as np  # noqa: E402

import devices  # noqa: E402
from puppet import live  # noqa: E402
from puppet.mapping import Mapper  # noqa: E402
from puppet.tick_rate import TICK_BUDGET, choose_tick_rate  # noqa: E402

MOCK = """
impersonate = "sgi"
speed = 1
duration = {seconds}
[[sine]]
control = "dial1"
start = 0.0
duration = {seconds}
freq = 0.5
amplitude = 0.4
offset = 0.5
rate = 97
"""


def run_loop(face: live.Face, devs: list[Any], seconds: float, render: tuple[int, int] | None,
             drive: Any = None, record: Path | None = None, rate: float = 60.0, wake: bool = False,
             realtime: bool = False, jaw: bool = True, solve: str = "always") -> dict[str, Any]:
    spec = live.build_mapping(face.vocab, None, [d.spec for d in devs])
    mapper = Mapper(spec, face.vocab)
    writer = None
    if record is not None:
        from puppet.session import SessionWriter

        header = live.session_header(face, spec, rate, [d.spec for d in devs])
        if not jaw:  # as a take recorded before the jaw's responses says
            del header["jaw"]
        writer = SessionWriter(record, header)
    core = live.LiveCore(face, mapper, writer=writer, rate=rate)
    core.sim.jaw_responses = jaw  # off: the jaw and the age taken whole at each step, as before
    core.latency.keep_all = True
    core.state_latency.keep_all = True
    spans = live.Spans() if hasattr(live, "Spans") else None
    core.spans = spans
    queue = devices.EventQueue()
    renderer = None
    if render is not None:
        from render.offscreen import OffscreenRenderer

        renderer = OffscreenRenderer(face.model, render)
    # the work after each boundary: drain -> tick -> (render + readback); the wait for the boundary
    # itself is the rest of the latency
    starts: list[float] = []
    work: list[float] = []
    # per event: where its event -> state time went (busy: a tick in progress when it arrived;
    # schedule: the loop waiting for the schedule or waking up; tick: its own tick's work)
    where: dict[str, list[float]] = {"busy": [], "schedule": [], "tick": [], "runnable, no CPU": []}
    ends: list[float] = []  # each tick's simulation step done (time.monotonic)
    batches: list[list[float]] = []

    def drain() -> list[Any]:
        now = time.monotonic()
        starts.append(now)
        t = time.perf_counter()
        out = queue.drain()
        if spans is not None:
            spans.add("drain", time.perf_counter() - t)
        batches.append([e.t for e in out if hasattr(e, "control")])
        return out

    def on_frame(c: live.LiveCore) -> None:
        if renderer is not None:
            t = time.perf_counter()
            renderer.render_frame(c.state)  # reads the pixels back: the frame is finished
            if spans is not None:
                spans.add("render + readback", time.perf_counter() - t)
        work.append(time.monotonic() - starts[-1])
    tick = core.tick

    delays: list[float] = []  # the loop thread's time runnable but not running (schedstat), at each tick's end

    def run_delay() -> float:
        try:
            with open("/proc/thread-self/schedstat") as f:
                return int(f.read().split()[1]) / 1e9
        except OSError:
            return 0.0

    def timed_tick(events: Any) -> None:
        tick(events)
        ends.append(time.monotonic())
        delays.append(run_delay())

    core.tick = timed_tick  # type: ignore[method-assign]
    step = core.sim.step

    def cpu_timed_step(state: Any, control: Any, **kw: Any) -> Any:
        # the step's CPU time (this thread's): equal to its wall time when nothing took the core or
        # the interpreter from it, so a step slower here than in benchmarks/sim_step.py is slower work
        c0 = time.thread_time()
        out = step(state, control, **kw)
        if spans is not None:
            spans.add("sim step CPU", time.thread_time() - c0)
            impl = core.sim._implicit
            if impl is not None and not impl.last_predicted:  # the step did its input-free part itself
                spans.add("sim step CPU, nothing made ahead", time.thread_time() - c0)
        return out

    core.sim.step = cpu_timed_step  # type: ignore[method-assign]
    if solve == "never":  # the whole step at each tick, as replay does
        core.prepare_next = lambda: None  # type: ignore[method-assign]
    live.prepare_show()  # as `puppet live` does before it starts the devices
    os.environ["PUPPET_REALTIME_DEVICES"] = "1" if realtime else "0"  # as `puppet live --realtime`
    for d in devs:
        d.add_listener(queue)
        d.start()
    stop = threading.Event()
    th = None
    if drive is not None:
        th = threading.Thread(target=drive, args=(stop,), daemon=True)
        th.start()
    if realtime and live.realtime_priority() is not None:
        print("--realtime: SCHED_FIFO not permitted here: the row runs at the ordinary priority", file=sys.stderr)
    cpu_start, wall_start = time.thread_time(), time.monotonic()
    try:
        live.run_realtime(core, drain, seconds, on_frame=on_frame, frame_rate=live.DISPLAY_RATE,
                          wake=queue.wait_arrival if wake else None, ahead_when_idle=solve == "idle")
    finally:
        cpu_end, wall_end = time.thread_time(), time.monotonic()
        live.ordinary_priority()
        if writer is not None:
            writer.close(core.tick_count)
        stop.set()
        if th is not None:
            th.join(2)
        for d in devs:
            d.close()
        if renderer is not None:
            renderer.release()
    for k in range(1, min(len(ends), len(starts))):
        for te in batches[k]:
            busy = max(0.0, ends[k - 1] - max(te, starts[k - 1]))
            where["busy"].append(busy)
            where["schedule"].append(max(0.0, starts[k] - max(te, ends[k - 1])))
            where["tick"].append(ends[k] - starts[k])
            # what of it the loop spent waiting for a CPU (the last tick's end -> its own tick's end)
            where["runnable, no CPU"].append(delays[k] - delays[k - 1])
    loop_cpu = (cpu_end - cpu_start) / max(1e-9, wall_end - wall_start)  # the loop thread's share of a core
    lat = np.array(core.latency.all) * 1000
    st = np.array(core.state_latency.all) * 1000
    wk = np.array(work) * 1000
    return {"rate": rate, "wake": wake, "loop_cpu": loop_cpu, "state_p50_ms": float(np.percentile(st, 50)),
            "state_p99_ms": float(np.percentile(st, 99)),
            "events": int(lat.size), "p50_ms": float(np.percentile(lat, 50)), "p99_ms": float(np.percentile(lat, 99)),
            "max_ms": float(lat.max()), "ticks": core.tick_count, "target_ms": 1000 / 60 + 2,
            "work_p50_ms": float(np.percentile(wk, 50)), "work_p99_ms": float(np.percentile(wk, 99)),
            # the floor: a uniform wait for the next boundary (events arrive at random phase) plus
            # this run's measured work after a boundary, combined as independent
            "floor_p99_ms": float(np.percentile(np.add.outer(np.linspace(0, 1000 / 60, 400), wk), 99)),
            "where_ms": {k: [float(np.percentile(np.array(v) * 1000, 50)), float(np.percentile(np.array(v) * 1000, 99))]
                         for k, v in where.items() if v},
            "counts": {} if spans is None else {k: len(v) for k, v in spans.data.items()},
            "spans_ms": {} if spans is None else {
                k: [float(np.percentile(np.array(v) * 1000, 50)), float(np.percentile(np.array(v) * 1000, 99))]
                for k, v in spans.data.items()}}


def mock_source(face: live.Face, seconds: float, render: tuple[int, int] | None, tmp: Path,
                record: bool = True, rate: float = 60.0, wake: bool = False, realtime: bool = False,
                jaw: bool = True, solve: str = "always") -> dict[str, Any]:
    script = tmp / "dense.toml"
    script.write_text(MOCK.format(seconds=seconds + 1))
    dev = devices.open_device(f"mock://{script}")
    return run_loop(face, [dev], seconds, render, record=tmp / "mock.jsonl" if record else None, rate=rate, wake=wake,
                    realtime=realtime, jaw=jaw, solve=solve)


def _box_process(link: str, conn: Any) -> None:
    """The SGI box emulator in a process of its own, as a real box is outside the show's process (in
    the show's, its thread would hold the interpreter's lock against the loop): turned at random
    moments until told to stop."""
    sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "devices")]
    from emulators import SgiBoxEmulator

    os.setsid()  # a session of its own: not in the show's autogroup, whose share of the CPU a box does not take

    box = SgiBoxEmulator(Path(link))
    try:
        conn.send("ready")
        box.wait_ready(20)
        rng = random.Random(7)
        while not conn.poll(rng.uniform(0.005, 0.025)):  # random phase against the tick
            box.turn(rng.randrange(8), rng.choice((-2, -1, 1, 2)))
    finally:
        box.port.close()


def sgi_source(face: live.Face, seconds: float, render: tuple[int, int] | None, tmp: Path,
               record: bool = True, rate: float = 60.0, wake: bool = False, realtime: bool = False,
               jaw: bool = True, solve: str = "always") -> dict[str, Any]:
    import multiprocessing

    link = tmp / f"sgi-{time.monotonic_ns()}"
    here, there = multiprocessing.Pipe()
    proc = multiprocessing.get_context("spawn").Process(target=_box_process, args=(str(link), there), daemon=True)
    proc.start()
    try:
        if not here.poll(30):
            raise RuntimeError("the SGI box emulator did not start")
        here.recv()
        dev = devices.open_device(f"sgi://{link}")
        return run_loop(face, [dev], seconds, render, record=tmp / "sgi.jsonl" if record else None,
                        rate=rate, wake=wake, realtime=realtime, jaw=jaw, solve=solve)
    finally:
        here.send("stop")
        proc.join(5)
        if proc.is_alive():
            proc.kill()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--render", default=None, help="also render each frame offscreen at WxH")
    ap.add_argument("--no-record", action="store_true", help="do not record the session (live records)")
    ap.add_argument("--rates", default="60,auto,240",
                    help="tick rates to compare, e.g. 60,120,240 (frames at 60 Hz); auto: the face's chosen rate")
    ap.add_argument("--wake", default="off,on", help="waking the loop on an event: off, on, or both (off,on)")
    ap.add_argument("--realtime", default="off", help="as `puppet live --realtime` (the loop's thread and the devices' "
                    "readers under SCHED_FIFO): off, on, or both (off,on: interleaved in one run)")
    ap.add_argument("--jaw", default="responses", help="how the step moves the jaw and ages the skin: responses "
                    "(from the last step's pose, sim.Simulator.jaw_responses), whole (at each step, as takes recorded "
                    "before), or both (whole,responses: interleaved in one run)")
    ap.add_argument("--solve", default="always", help="when the loop makes the next step's input-free solve "
                    "between ticks: always (also with an input waiting, which is drained after it), idle (only when "
                    "no input waits, the tick then doing the whole step, as before), never (the whole step at "
                    "every tick, as replay does), or several (idle,always: interleaved in one run)")
    ap.add_argument("--repeat", type=int, default=1, help="run every row this many times, interleaved")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    render = tuple(int(x) for x in a.render.split("x")) if a.render else None
    wakes = [w == "on" for w in a.wake.split(",")]
    realtimes = [w == "on" for w in a.realtime.split(",")]
    jaws = [w == "responses" for w in a.jaw.split(",")]
    solves = a.solve.split(",")
    face = live.load_face()
    chosen, cost = choose_tick_rate(face.model)  # what `puppet live` picks for this face (auto)
    print(f"the face's step: {', '.join(f'{r:g} Hz {c * 1000:.2f} ms' for r, c in cost.items())} (CPU); "
          f"auto picks {chosen:g} Hz (budget {TICK_BUDGET:.0%} of a core); load {os.getloadavg()[0]:.2f}")
    rates = list(dict.fromkeys(chosen if x == "auto" else float(x) for x in a.rates.split(",")))
    res: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory() as d:
        for rep in range(a.repeat):  # every row again, interleaved, so each repetition shares the load
            for name, source in (("mock", mock_source), ("sgi_pty", sgi_source)):
                for rate, wake, rt, jaw, when in itertools.product(rates, wakes, realtimes, jaws, solves):
                    key = (f"{name} {rate:g} Hz wake {'on' if wake else 'off'}{' rt' if rt else ''}"
                           f"{'' if jaw else ' jaw whole'}{' ahead ' + when if len(solves) > 1 else ''}"
                           f"{f' #{rep + 1}' if a.repeat > 1 else ''}")
                    res[key] = source(face, a.seconds, render, Path(d), not a.no_record, rate, wake, rt, jaw, when)
                    print(f"{key}: state p99 {res[key]['state_p99_ms']:.1f} ms (runnable, no CPU p99 "
                          f"{res[key]['where_ms']['runnable, no CPU'][1]:.1f} ms; the loop's thread "
                          f"{res[key]['loop_cpu']:.0%} of a core), load {os.getloadavg()[0]:.2f}",
                          file=sys.stderr, flush=True)
    if a.json:
        print(json.dumps(res, indent=2))
        return 0
    base: dict[str, dict[str, Any]] = {}
    for key, r in res.items():
        src = key.split()[0]
        base.setdefault(src, r)
        b = base[src]
        print(f"{key:36s} events {r['events']:5d}  event->state p50 {r['state_p50_ms']:5.1f} p99 {r['state_p99_ms']:5.1f} ms"
              f" (x{r['state_p99_ms'] / b['state_p99_ms']:.2f})  event->frame p50 {r['p50_ms']:5.1f} p99 {r['p99_ms']:5.1f} ms"
              f" (x{r['p99_ms'] / b['p99_ms']:.2f}; target <= {r['target_ms']:.1f}, floor ~{r['floor_p99_ms']:.1f})")
        late = r["spans_ms"].get("woke late", [0.0, 0.0])
        print(f"{'':36s} work after the boundary (drain + tick) p50 {r['work_p50_ms']:.1f} p99 {r['work_p99_ms']:.1f} ms, "
              f"woke late p99 {late[1]:.1f} ms, {r['ticks']} ticks; the loop's thread used {r['loop_cpu']:.0%} of a core")
        wh = r.get("where_ms", {})
        print(f"{'':36s} an event's wait: for a tick in progress p50/p99 {wh['busy'][0]:.1f}/{wh['busy'][1]:.1f} ms, "
              f"for the schedule or the wake-up {wh['schedule'][0]:.1f}/{wh['schedule'][1]:.1f} ms; its tick "
              f"{wh['tick'][0]:.1f}/{wh['tick'][1]:.1f} ms; sim step {r['spans_ms']['sim step'][0]:.1f}/"
              f"{r['spans_ms']['sim step'][1]:.1f} ms (CPU {r['spans_ms']['sim step CPU'][0]:.1f}/"
              f"{r['spans_ms']['sim step CPU'][1]:.1f})")
        if "runnable, no CPU" in wh:
            print(f"{'':36s} the loop runnable but given no CPU from the previous tick's end to its tick's end "
                  f"p50/p99 {wh['runnable, no CPU'][0]:.1f}/{wh['runnable, no CPU'][1]:.1f} ms")
        whole = r["counts"].get("sim step CPU, nothing made ahead", 0)
        if whole:
            w = r["spans_ms"]["sim step CPU, nothing made ahead"]
            print(f"{'':36s} {whole} of {r['ticks']} steps found nothing made ahead (an input waiting, or the "
                  f"step's pose not the one prepared): CPU p50/p99 {w[0]:.1f}/{w[1]:.1f} ms")
        ahead = r["spans_ms"].get("prepared between ticks")
        if ahead:
            print(f"{'':36s} computed between ticks (the solve of all but the muscles) p50/p99 {ahead[0]:.1f}/{ahead[1]:.1f} ms")
    print("ratios are against the first row of the same source in this run; goals: event->state p99 <= 6 ms, "
          f"event->frame p99 <= 18.7 ms; load average at the end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
