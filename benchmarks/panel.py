"""The performer's page: input-to-frame latency against a serial box, server CPU per page, and the
face's frame time with pages connected.

1. Latency. Pages are a separate process (as a browser is), on the loopback, sending slider moves
   at random moments (5-25 ms apart, random phase against the 60 Hz tick). For each move:
   page send -> the server stamps it (the WebSocket hop) + that stamp -> the frame that shows it
   is ready (the live loop's own latency meter, as for every box). The SGI box emulator on a
   pseudo-terminal (benchmarks/live_latency.py's source) is run the same way for reference.
   Target: the page's p50/p99 within 2 ms of the serial box's.
2. Server CPU per page: the server thread's CPU time (/proc/self/task/TID/stat) while 0, 1 and 4
   pages each send 60 updates a second and receive the 30 Hz state, divided by the pages.
3. Frame time: the loop's work after a tick boundary (drain + tick + offscreen render 640x360 and
   readback) with 0, 1 and 4 pages connected and sending, p50/p99.

Run:  .venv/bin/python benchmarks/panel.py [--seconds 5] [--json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import os
import random
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks"), str(ROOT / "tests" / "devices")]

import numpy as np  # noqa: E402

import devices  # noqa: E402
from puppet import live  # noqa: E402
from puppet.mapping import Mapper  # noqa: E402
from puppet.panel.layout import panel_map  # noqa: E402


def pages_process(url: str, n: int, seconds: float, rate: float | None, conn: Any) -> None:
    """n pages: each sends `slider:jaw` moves (value = a sequence number / 1e6) at `rate` per
    second, or at random 5-25 ms gaps when rate is None; reports each send's monotonic time."""
    import aiohttp

    async def page(i: int, sent: dict[int, float]) -> None:
        rng = random.Random(i)
        async with aiohttp.ClientSession() as s, s.ws_connect(url + f"ws?name=bench{i}") as ws:
            await ws.receive(timeout=10)  # hello
            async def drain_state() -> None:
                async for _ in ws:
                    pass
            reader = asyncio.get_running_loop().create_task(drain_state())
            seq, end = i * 100000, time.monotonic() + seconds
            while time.monotonic() < end:
                seq += 1
                sent[seq] = time.monotonic()
                await ws.send_str(json.dumps({"t": "in", "c": "slider:jaw", "v": seq / 1e6}))
                await asyncio.sleep(1 / rate if rate else rng.uniform(0.005, 0.025))
            reader.cancel()

    async def main() -> dict[int, float]:
        sent: dict[int, float] = {}
        await asyncio.gather(*(page(i, sent) for i in range(n)))
        return sent

    conn.send("ready")
    conn.recv()
    conn.send(asyncio.run(main()) if n else {})


def thread_cpu(tid: int) -> float:
    with open(f"/proc/self/task/{tid}/stat") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run(face: live.Face, n_pages: int, seconds: float, rate: float | None, render: bool) -> dict[str, Any]:
    dev = devices.open_device("panel://127.0.0.1:0", vocab=face.vocab)
    mapper = Mapper(panel_map(face.vocab), face.vocab)
    core = live.LiveCore(face, mapper)
    core.latency.keep_all = True
    dev.watch(core, [dev])
    received: dict[int, float] = {}
    dev.add_listener(lambda ev: received.__setitem__(int(round(ev.raw * 1e6)), ev.t)
                     if getattr(ev, "control", "") == "slider:jaw" else None)
    queue = devices.EventQueue()
    renderer = None
    if render:
        from render.offscreen import OffscreenRenderer

        renderer = OffscreenRenderer(face.model, (640, 360))
        for _ in range(30):  # shaders compiled and caches warm before the timed run
            renderer.render_frame(core.state)
    starts: list[float] = []
    work: list[float] = []

    def drain() -> list[Any]:
        starts.append(time.monotonic())
        return queue.drain()

    def on_frame(c: live.LiveCore) -> None:
        if renderer is not None:
            renderer.render_frame(c.state)
        work.append(time.monotonic() - starts[-1])

    here, there = multiprocessing.Pipe()
    proc = multiprocessing.get_context("spawn").Process(target=pages_process, args=(dev.url, n_pages, seconds, rate, there))
    proc.start()
    here.recv()
    live.prepare_show()
    dev.add_listener(queue)
    dev.start()
    tid = dev.server._thread.native_id
    cpu0, t0 = thread_cpu(tid), time.monotonic()
    here.send("go")
    try:
        live.run_realtime(core, drain, seconds + 0.5, on_frame=on_frame)
        cpu = (thread_cpu(tid) - cpu0) / (time.monotonic() - t0)
        sent = here.recv()
    finally:
        proc.join(10)
        dev.close()
        if renderer is not None:
            renderer.release()
    hop = np.array([received[k] - t for k, t in sent.items() if k in received]) * 1000
    lat = np.array(core.latency.all) * 1000
    out = {"pages": n_pages, "server_cpu": cpu, "work_p50_ms": float(np.percentile(work, 50) * 1000),
           "work_p99_ms": float(np.percentile(work, 99) * 1000), "events": int(lat.size)}
    if n_pages == 1 and len(hop) == len(lat) and len(lat):
        total = hop + lat  # one page, one device: events are presented in the order they were stamped
        out.update(hop_p50_ms=float(np.percentile(hop, 50)), hop_p99_ms=float(np.percentile(hop, 99)),
                   loop_p50_ms=float(np.percentile(lat, 50)), loop_p99_ms=float(np.percentile(lat, 99)),
                   p50_ms=float(np.percentile(total, 50)), p99_ms=float(np.percentile(total, 99)))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    import live_latency

    face = live.load_face()
    res: dict[str, Any] = {"load": os.getloadavg()}
    res["page"] = run(face, 1, a.seconds, None, render=False)
    with tempfile.TemporaryDirectory() as d:
        res["sgi_pty"] = live_latency.sgi_source(face, a.seconds, None, Path(d), record=False)
    for n in (0, 1, 4):
        res[f"cpu_{n}"] = run(face, n, a.seconds, 60.0, render=False)
    for n in (0, 1, 4):
        res[f"frame_{n}"] = run(face, n, a.seconds, 60.0, render=True)
    res["load_after"] = os.getloadavg()
    if a.json:
        print(json.dumps(res, indent=2))
        return 0
    p, s = res["page"], res["sgi_pty"]
    print(f"machine load average {res['load'][0]:.2f} -> {res['load_after'][0]:.2f} (2 cores, shared)")
    print(f"latency  page (loopback)  p50 {p['p50_ms']:5.1f} ms  p99 {p['p99_ms']:5.1f} ms   "
          f"(WebSocket hop p50 {p['hop_p50_ms']:.2f} p99 {p['hop_p99_ms']:.2f}; stamp->frame p50 "
          f"{p['loop_p50_ms']:.1f} p99 {p['loop_p99_ms']:.1f}; {p['events']} moves)")
    print(f"         SGI box (pty)    p50 {s['p50_ms']:5.1f} ms  p99 {s['p99_ms']:5.1f} ms   ({s['events']} events)")
    print(f"         page - box       p50 {p['p50_ms'] - s['p50_ms']:+5.1f} ms  p99 {p['p99_ms'] - s['p99_ms']:+5.1f} ms"
          "   (target: within 2 ms)")
    base = res["cpu_0"]["server_cpu"]
    for n in (1, 4):
        c = res[f"cpu_{n}"]["server_cpu"]
        print(f"server CPU with {n} page(s) at 60 updates/s: {c * 100:5.1f} % of a core "
              f"({(c - base) / n * 100:.1f} % per page over {base * 100:.1f} % idle)")
    f0 = res["frame_0"]
    for n in (0, 1, 4):
        f = res[f"frame_{n}"]
        print(f"frame time (tick + render 640x360) with {n} page(s): p50 {f['work_p50_ms']:5.2f} ms  "
              f"p99 {f['work_p99_ms']:5.2f} ms   (x{f['work_p50_ms'] / f0['work_p50_ms']:.2f} p50 against none)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
