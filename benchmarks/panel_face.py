"""The face on the page: frames per second and lag behind the show in real browsers, the server's
cost per page, bytes per frame.

1. Live. A live core on the wall clock (the show: tick, offscreen render 640x360 and readback, as
   a window would, handed to the pictures; or headless, drawing nothing), the jaw and a smile driven by a slow wave, the page server watching it. N
   headless chromium pages (separate browsers, the machine's software WebGL) open the page and
   show the face. Every page logs each face frame it draws (the tick, its own clock); its clock
   is put on the server's by the quickest ping. Lag = the page's draw time minus the time the show
   presented that tick. Server CPU: the server thread's CPU time (/proc/self/task/TID/stat), with
   the face shown and, same pages, hidden: the difference is what the face costs, per page.
2. Encoding alone (no browser): frames of a moving take of the default face at resolutions 0 and
   2 encoded as the server does: bytes per frame, encode time, the largest position error; and the
   other way, a JPEG of the offscreen render (480x360) per frame: its time and bytes; and the
   scanned head's 26,719 vertices (sim/face/scan) moved by its own expressions.

3. The server alone: 1, 4 and 16 WebSocket clients in another process (no browser competing for
   the CPU) with the face asked for and not: the server thread's CPU, hence the face's cost per
   page, and how far behind the show each frame arrives; with `--still`, the same with the face at
   rest (no input): a still face is sent nothing after its first picture.

4. With `--pictures`: what one picture costs the picture process, part by part (posing the scanned
   head on the CPU, the draw calls, the raster, the read-back, the JPEG), at three sizes, with
   llvmpipe's raster threads (Mesa's default) and without (LP_NUM_THREADS=0, the picture process's
   setting); each way in a process of its own (Mesa reads the setting once).

Run:  .venv/bin/python benchmarks/panel_face.py [--seconds 8] [--pages 1,4] [--clients 1,4,16] [--still] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "panel")]

import numpy as np  # noqa: E402

import devices  # noqa: E402
from devices.events import ControlEvent  # noqa: E402
from puppet import live  # noqa: E402
from puppet.mapping import Mapper  # noqa: E402
from puppet.panel.layout import panel_map  # noqa: E402


def thread_cpu(tid: int) -> float:
    with open(f"/proc/self/task/{tid}/stat") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def feed_cpu(dev: Any, tid: int) -> float:
    """CPU seconds of the page server's thread, the face feed's thread and its picture process."""
    feed = dev.face_feed
    total = thread_cpu(tid) + (thread_cpu(feed.thread_id) if feed.thread_id else 0.0)
    proc = getattr(feed, "_process", None)
    if proc is not None and proc.pid:
        try:
            with open(f"/proc/{proc.pid}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except OSError:
            pass
    return total


def tree_cpu(root: int) -> float:
    """CPU seconds of every live process under `root` (a chromedriver: its browser's processes)."""
    parent, cpu = {}, {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(d)] = int(fields[1])
        cpu[int(d)] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    total = 0.0
    for pid, c in cpu.items():
        p = pid
        while p in parent and p != root:
            p = parent[p]
        if p == root:
            total += c
    return total


def wave(k: int, rate: float) -> list[tuple[str, float]]:
    t = k / rate
    return [("slider:jaw", 0.5 + 0.45 * math.sin(2 * math.pi * 0.4 * t)),
            ("slider:zygomaticus_major_l", 0.5 + 0.4 * math.sin(2 * math.pi * 0.25 * t))]


def open_show(face: live.Face, query: str = "", still: bool = False) -> tuple[Any, live.LiveCore, live.StopFlag, Any]:
    """A page device on 127.0.0.1 driving a live core, and the drain that feeds it the wave's events
    (none when `still`: the face at rest): (device, core, stop flag, drain)."""
    dev = devices.open_device(f"panel://127.0.0.1:0{query}", vocab=face.vocab)
    core = live.LiveCore(face, Mapper(panel_map(face.vocab), face.vocab))
    dev.watch(core, [dev])
    dev.start()
    spec = dev.spec.rstrip("/") + "/wave"

    def drain() -> list[Any]:
        if still:
            return []
        k, t = core.tick_count, time.monotonic()
        return [ControlEvent(spec, c, "axis", v, None, v, t) for c, v in wave(k, core.rate)]

    return dev, core, live.StopFlag(), drain


def live_run(face: live.Face, n_pages: int, seconds: float, mode: str = "picture",
             draws: bool = True) -> dict[str, Any]:
    """One show with n pages watching: per page fps and lag; server CPU shown vs hidden. `mode`:
    the feed's way (pictures or the mesh); `draws`: the show renders each frame (as a window
    does) and hands it to the pictures, else it is headless (the feed's process renders them)."""
    import threading

    from panel_browser import browser, quit_browser, wait_for
    from render.offscreen import OffscreenRenderer

    dev, core, stop, drain = open_show(face, f"?face={mode}")
    rend: list[Any] = []  # made in the show's thread: a GL context is current in the thread that made it
    presented: dict[int, float] = {}

    def on_frame(c: live.LiveCore) -> None:
        if not draws:
            presented[c.tick_count] = time.monotonic()
            return
        if not rend:
            rend.append(OffscreenRenderer(face.model, (640, 360)))
        img = rend[0].render_frame(c.state)
        presented[c.tick_count] = now = time.monotonic()
        if dev.face_feed.wanted:
            dev.face_feed.offer(img, c.tick_count, now)

    def run_show() -> None:
        try:
            live.run_realtime(core, drain, None, on_frame=on_frame, stop=stop)
        finally:
            for r in rend:
                r.release()

    show = threading.Thread(target=run_show, daemon=True)
    show.start()
    pages = [browser() for _ in range(n_pages)]

    def server_cpu() -> float:  # the server's thread, the feed's thread and picture process
        return feed_cpu(dev, tid)

    js = "const f = window.puppetPanel && window.puppetPanel.face; return f ? [f.drawn, f.offset, f.error] : null"
    out: dict[str, Any] = {"pages": n_pages, "mode": mode, "draws": draws}
    try:
        for i, drv in enumerate(pages):
            drv.get(dev.url + f"?name=watch{i}")
        for drv in pages:
            wait_for(lambda drv=drv: (drv.execute_script(js) or [0])[0] > 10, 60, "the face drawn")
        tid = dev.server._thread.native_id
        time.sleep(1.5)  # pings settle the clock offsets
        for drv in pages:
            drv.execute_script("const f = window.puppetPanel.face; f.drawLog = []; f.frames = 0; "
                               "for (const k in f.cost) f.cost[k] = 0")
        feed = dev.face_feed
        f0, b0, e0, s0, k0 = feed.stats.frames, feed.stats.bytes, feed.stats.encode_s, feed.stats.sent, feed.stats.skipped
        roots = [drv.service.process.pid for drv in pages]
        br0 = sum(tree_cpu(r) for r in roots)
        cpu0, t0 = server_cpu(), time.monotonic()
        time.sleep(seconds)
        wall = time.monotonic() - t0
        out["cpu_shown"] = (server_cpu() - cpu0) / wall
        out["browser_cpu_per_page_shown"] = (sum(tree_cpu(r) for r in roots) - br0) / wall / n_pages
        out["show_fps_shown"] = len([t for t in presented.values() if t > t0]) / wall
        st = feed.stats
        frames = st.frames - f0
        out.update(frames_encoded_per_s=frames / wall, bytes_per_frame=(st.bytes - b0) / max(frames, 1),
                   encode_ms=(st.encode_s - e0) / max(frames, 1) * 1000, sends=st.sent - s0, skipped=st.skipped - k0)
        per_page = []
        for drv in pages:
            log, offset, err, cost, got, size = drv.execute_script(
                "const f = window.puppetPanel.face; return [f.drawLog, f.offset, f.error, f.cost, f.frames, f.size]")
            lags = [t_page + offset - presented[k] * 1000 for k, t_page in log if k in presented]
            span = (log[-1][1] - log[0][1]) / 1000 if len(log) > 1 else 1.0
            per_page.append({"fps": (len(log) - 1) / span, "lag_p50_ms": float(np.percentile(lags, 50)),
                             "lag_p99_ms": float(np.percentile(lags, 99)), "lag_max_ms": float(np.max(lags)),
                             "draws": len(log), "error": err, "size": size,
                             "cost_ms": {k: v / max(got, 1) for k, v in cost.items()}})
        out["per_page"] = per_page
        # the same pages with the face hidden: what the rest of the page costs the server
        for drv in pages:
            drv.find_element("id", "facetoggle").click()
        time.sleep(1.0)
        b0 = sum(tree_cpu(r) for r in roots)
        cpu0, t0 = server_cpu(), time.monotonic()
        time.sleep(min(seconds, 4.0))
        out["cpu_hidden"] = (server_cpu() - cpu0) / (time.monotonic() - t0)
        out["browser_cpu_per_page_hidden"] = (sum(tree_cpu(r) for r in roots) - b0) / (time.monotonic() - t0) / n_pages
        out["show_fps"] = len([t for t in presented.values() if t > t0]) / (time.monotonic() - t0)
    finally:
        for drv in pages:
            quit_browser(drv)
        stop.stopped = True
        show.join(10)
        dev.close()
    return out


def clients_process(url: str, n: int, seconds: float, face: bool, conn: Any) -> None:
    """n WebSocket clients (a separate process, as browsers are) asking for the face or not; each
    logs the tick and arrival time (time.monotonic, the show's clock: same machine) of its frames."""
    import asyncio
    import struct

    import aiohttp

    async def page(i: int) -> list[tuple[int, float, int]]:
        got: list[tuple[int, float, int]] = []
        async with aiohttp.ClientSession() as s, s.ws_connect(url + f"ws?name=c{i}") as ws:
            await ws.send_str(json.dumps({"t": "face", "on": face}))
            end = time.monotonic() + seconds
            while time.monotonic() < end and not conn.poll():  # until told to stop (or `seconds`)
                try:
                    msg = await ws.receive(timeout=1.0)
                except asyncio.TimeoutError:
                    continue
                if msg.type == aiohttp.WSMsgType.BINARY:
                    kind, hl = struct.unpack_from("<B3xI", msg.data)
                    if kind in (2, 3):  # a frame of the mesh, or a picture
                        got.append((json.loads(msg.data[8:8 + hl])["tick"], time.monotonic(), len(msg.data)))
                        await ws.send_str('{"t":"drawn"}')  # as a page does once it has drawn the frame
        return got

    async def main() -> list[list[tuple[int, float, int]]]:
        return list(await asyncio.gather(*(page(i) for i in range(n))))

    conn.send(asyncio.run(main()))


def server_run(face: live.Face, n_pages: int, seconds: float, with_face: bool, still: bool = False) -> dict[str, Any]:
    """The server's cost with n client processes watching (or not): thread CPU, lag at arrival;
    `still`: the face at rest (no input), which should cost no more than not watching."""
    import multiprocessing
    import threading

    dev, core, stop, drain = open_show(face, still=still)
    presented: dict[int, float] = {}

    def on_frame(c: live.LiveCore) -> None:
        presented[c.tick_count] = time.monotonic()

    show = threading.Thread(target=live.run_realtime, args=(core, drain, None),
                            kwargs={"on_frame": on_frame, "stop": stop}, daemon=True)
    show.start()
    here, there = multiprocessing.Pipe()
    proc = multiprocessing.get_context("spawn").Process(target=clients_process,
                                                        args=(dev.url, n_pages, seconds + 90, with_face, there))
    try:
        proc.start()
        time.sleep(1.5)  # connected, scenes sent
        end = time.monotonic() + 60  # the picture process's start (seconds on a loaded machine)
        while with_face and dev.face_feed.stats.frames < (1 if still else 3) and time.monotonic() < end:
            time.sleep(0.1)
        tid = dev.server._thread.native_id

        def server_cpu() -> float:  # the server's thread, the feed's thread and picture process
            return feed_cpu(dev, tid)

        cpu0, t0 = server_cpu(), time.monotonic()
        time.sleep(seconds)
        cpu = (server_cpu() - cpu0) / (time.monotonic() - t0)
        here.send("stop")
        logs = here.recv()
    finally:
        proc.join(10)
        stop.stopped = True
        show.join(10)
        dev.close()
    lags = [(t - presented[k]) * 1000 for log in logs for k, t, _ in log if k in presented and t > t0]
    frames = [sum(1 for _, t, _ in log if t > t0) / seconds for log in logs]
    out: dict[str, Any] = {"pages": n_pages, "face": with_face, "server_cpu": cpu,
                           "pictures_per_s": float(np.mean([sum(1 for _, t, _ in log if t > t0) / seconds for log in logs]))}
    if lags:
        out.update(lag_p50_ms=float(np.percentile(lags, 50)), lag_p99_ms=float(np.percentile(lags, 99)),
                   frames_per_s=float(np.mean(frames)))
    return out


def encode_run(resolution: int, seconds: float = 3.0) -> dict[str, Any]:
    """Frames of a moving take encoded as the server does, without a browser."""
    import sim
    from render.stream import FaceStream

    face = live.load_face(resolution=resolution)
    stream = FaceStream(face.model)
    simu = sim.Simulator(face.model, 1 / 60, wrinkles=False)
    state, control = face.model.rest_state(), sim.FaceControl(face.model)
    names = [c.name for c in face.vocab.channels]
    sizes, times, errors = [], [], []
    for k in range(int(seconds * 60)):
        for c, v in wave(k, 60.0):
            control.values[names.index(c.split(":", 1)[1])] = v
        simu.step(state, control)
        if k % 2:
            continue  # the live feed's 30 Hz
        t = time.perf_counter()
        msg = stream.frame(state, k, 0.0)
        times.append(time.perf_counter() - t)
        sizes.append(len(msg))
        errors.append(float(np.abs(stream.decode(msg) - stream.positions(state)).max()))
    # the other way: a JPEG of the offscreen render, per frame, the size of the page's view (480x360)
    import io

    from PIL import Image

    from render.offscreen import OffscreenRenderer

    jpeg_ms, jpeg_bytes = [], []
    with OffscreenRenderer(face.model, (480, 360)) as off:
        for _ in range(5):
            off.render_frame(state)
        for _ in range(20):
            t = time.perf_counter()
            buf = io.BytesIO()
            Image.fromarray(off.render_frame(state)).save(buf, "JPEG", quality=80)
            jpeg_ms.append((time.perf_counter() - t) * 1000)
            jpeg_bytes.append(buf.tell())
    return {"resolution": resolution, "vertices": stream.n_vertices, "scene_bytes": len(stream.scene()),
            "jpeg_ms_p50": float(np.percentile(jpeg_ms, 50)), "jpeg_bytes": float(np.mean(jpeg_bytes)),
            "raw_float32_bytes": stream.n_vertices * 12, "bytes_p50": float(np.percentile(sizes, 50)),
            "bytes_max": int(max(sizes)), "encode_ms_p50": float(np.percentile(times, 50) * 1000),
            "max_error_cm": max(errors)}


def scan_run(seconds: float = 3.0) -> dict[str, Any]:
    """The scanned head's 26,719 vertices (sim/face/scan) moved by its own expressions (jaw open,
    a smile, a blink, in waves), encoded as the face's frames are: bytes and time per frame. The
    simulated head moves every skin vertex a little; blend shapes move only where they act, so
    this is the lower end of what a simulated scanned head will cost."""
    from render.stream import encode_positions
    from sim.face.scan.data import scan_data

    d = scan_data()
    base = d.neutral.astype(np.float32)
    names = [n for n in ("jawOpen", "mouthSmile_L", "mouthSmile_R", "eyeBlink_L", "eyeBlink_R") if n in d.expression_names]
    shapes = [d.expression(n).astype(np.float32) for n in names]
    sizes, times = [], []
    q = np.empty(base.shape, np.int16)
    for k in range(int(seconds * 30)):
        t = k / 30
        pos = base.copy()
        for i, sh in enumerate(shapes):
            pos += sh * np.float32(0.5 + 0.45 * math.sin(2 * math.pi * (0.3 + 0.1 * i) * t))
        c0 = time.perf_counter()
        sizes.append(len(encode_positions(pos, base, q)))
        times.append(time.perf_counter() - c0)
    return {"vertices": len(base), "shapes": names, "bytes_p50": float(np.percentile(sizes, 50)),
            "bytes_max": int(max(sizes)), "encode_ms_p50": float(np.percentile(times, 50) * 1000),
            "raw_float32_bytes": len(base) * 12}


def _picture_parts(conn: Any, threads: str | None) -> None:
    """A child: the parts of one picture at each size, medians of 40 (ms, wall and CPU)."""
    if threads is not None:
        os.environ["LP_NUM_THREADS"] = threads
    from render.offscreen import OffscreenRenderer
    from render.stream import pictures

    face = live.load_face()
    state = face.model.rest_state()
    out = {}
    for size in ((160, 120), (400, 300), (640, 480)):
        off = OffscreenRenderer(face.model, size)
        rend, parts = off.renderer, {k: [] for k in ("pose", "draw", "raster", "read", "jpeg", "cpu", "wall")}
        pose = rend.scan.rows if rend.scan is not None else None

        def timed(*a: Any, **k: Any) -> Any:
            c = time.perf_counter()
            got = pose(*a, **k)
            parts["pose"].append(time.perf_counter() - c)
            return got

        if pose is not None:
            rend.scan.rows = timed
        for i in range(45):
            c0, p0 = time.perf_counter(), time.process_time()
            off.fbo.use()
            off.fbo.viewport = (0, 0, *size)
            rend.draw(state)
            c1 = time.perf_counter()
            off.ctx.finish()
            c2 = time.perf_counter()
            img = np.frombuffer(off.fbo.read(components=3, alignment=1), np.uint8).reshape(size[1], size[0], 3)[::-1]
            c3 = time.perf_counter()
            pictures(img, "f", 0, 0.0, (size,))
            c4, p4 = time.perf_counter(), time.process_time()
            if i < 5:  # warm-up
                for v in parts.values():
                    v.clear()
                continue
            parts["draw"].append(c1 - c0 - (parts["pose"][-1] if parts["pose"] else 0.0))
            for k, v in (("raster", c2 - c1), ("read", c3 - c2), ("jpeg", c4 - c3), ("cpu", p4 - p0), ("wall", c4 - c0)):
                parts[k].append(v)
        off.release()
        out["x".join(map(str, size))] = {k: float(np.median(v) * 1000) if v else 0.0 for k, v in parts.items()}
    conn.send(out)


def picture_run() -> dict[str, Any]:
    """The parts of a picture (_picture_parts) with llvmpipe's threads and without, each in a child."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    res = {}
    for name, threads in (("threads", None), ("one thread", "0")):
        here, there = ctx.Pipe()
        proc = ctx.Process(target=_picture_parts, args=(there, threads))
        proc.start()
        res[name] = here.recv()
        proc.join(30)
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--pages", default="1,4")
    ap.add_argument("--modes", default="picture,mesh,picture-headless,mesh-headless",
                    help="the face's ways with real pages: picture (pictures of the show's frames), mesh "
                         "(WebGL in the page); -headless: the show draws no frames (the pictures are rendered "
                         "by the feed's process)")
    ap.add_argument("--resolutions", default="0,2")
    ap.add_argument("--clients", default="1,4,16", help="page counts for the server-only runs")
    ap.add_argument("--no-scan", dest="scan", action="store_false", help="skip the scanned head's encoding")
    ap.add_argument("--still", action="store_true", help="also the server-only runs with the face at rest")
    ap.add_argument("--pictures", action="store_true", help="also a picture's cost, part by part")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    face = live.load_face()
    res: dict[str, Any] = {"load": os.getloadavg()}
    for n in [int(x) for x in a.clients.split(",") if x]:
        res[f"server_{n}_face"] = server_run(face, n, a.seconds, True)
        res[f"server_{n}_noface"] = server_run(face, n, a.seconds, False)
        if a.still:
            res[f"server_{n}_still"] = server_run(face, n, a.seconds, True, still=True)
    for n in [int(x) for x in a.pages.split(",") if x]:
        for m in [x for x in a.modes.split(",") if x]:  # interleaved: the ratios share the machine's load
            res[f"live_{n}_{m}"] = live_run(face, n, a.seconds, m.split("-")[0], not m.endswith("-headless"))
    for r in [int(x) for x in a.resolutions.split(",") if x]:
        res[f"encode_{r}"] = encode_run(r)
    if a.scan:
        res["scan"] = scan_run()
    if a.pictures:
        res["pictures"] = picture_run()
    res["load_after"] = os.getloadavg()
    if a.json:
        print(json.dumps(res, indent=2))
        return 0
    print(f"machine load average {res['load'][0]:.2f} -> {res['load_after'][0]:.2f} (2 cores, shared)")
    for key, r in res.items():
        if key.startswith("live_"):
            n = r["pages"]
            how = {"mesh": "mesh (WebGL in the page)"}.get(r["mode"], "pictures " + (
                "of the show's own frames" if r["draws"] else "rendered by the feed's process"))
            how += ", the show drawing 640x360 frames" if r["draws"] else ", a headless show"
            fps = [p["fps"] for p in r["per_page"]]
            p50 = [p["lag_p50_ms"] for p in r["per_page"]]
            p99 = [p["lag_p99_ms"] for p in r["per_page"]]
            cost = {k: float(np.mean([p["cost_ms"][k] for p in r["per_page"]])) for k in r["per_page"][0]["cost_ms"]}
            sizes = sorted({"x".join(map(str, p["size"])) for p in r["per_page"] if p.get("size")})
            how += f" (pictures {', '.join(sizes)})" if sizes else ""
            print(f"{n} page(s), {how}: face drawn {min(fps):.1f}-{max(fps):.1f} frames/s per page; behind the show p50 "
                  f"{min(p50):.0f}-{max(p50):.0f} ms, p99 {min(p99):.0f}-{max(p99):.0f} ms (show {r['show_fps']:.0f} frames/s)")
            per = (r["cpu_shown"] - r["cpu_hidden"]) / n
            print(f"   each browser {r['browser_cpu_per_page_shown'] * 100:.0f} % of a core with the face, "
                  f"{r['browser_cpu_per_page_hidden'] * 100:.0f} % without; the show {r['show_fps_shown']:.0f} frames/s "
                  "while the pages watched; in the page per frame " + ", ".join(f"{k} {v:.1f} ms" for k, v in cost.items()))
            print(f"   server thread {r['cpu_shown'] * 100:.1f} % of a core shown, {r['cpu_hidden'] * 100:.1f} % hidden: "
                  f"the face {per * 100:.2f} % per page; {r['frames_encoded_per_s']:.1f} frames encoded/s, "
                  f"{r['encode_ms']:.2f} ms each, {r['bytes_per_frame']:.0f} bytes/frame; sends {r['sends']}, "
                  f"skipped (page busy) {r['skipped']}")
        if key.startswith("server_") and key.endswith("_noface"):
            n, f, nf = r["pages"], res[key.replace("_noface", "_face")], r
            print(f"server alone, {n} client(s) (no browser): thread {f['server_cpu'] * 100:.1f} % of a core with the face, "
                  f"{nf['server_cpu'] * 100:.1f} % without: {(f['server_cpu'] - nf['server_cpu']) / n * 100:.2f} % per page; "
                  f"{f.get('frames_per_s', 0):.1f} frames/s each, at the client p50 {f.get('lag_p50_ms', 0):.0f} ms "
                  f"p99 {f.get('lag_p99_ms', 0):.0f} ms behind the show")
            still = res.get(key.replace("_noface", "_still"))
            if still is not None:
                print(f"   the face at rest (no input): thread {still['server_cpu'] * 100:.1f} % of a core, "
                      f"{still['pictures_per_s']:.2f} pictures/s to each client")
        if key == "pictures":
            for how, sizes in r.items():
                print(f"a picture, llvmpipe with {how} (ms; medians): " + "; ".join(
                    f"{sz}: " + ", ".join(f"{k} {v:.2f}" for k, v in p.items()) for sz, p in sizes.items()))
        if key == "scan":
            print(f"encode, the scanned head ({r['vertices']} vertices, its own {', '.join(r['shapes'])} in waves): "
                  f"{r['bytes_p50']:.0f} bytes/frame p50 (max {r['bytes_max']}; float32 {r['raw_float32_bytes']}), "
                  f"{r['encode_ms_p50']:.2f} ms")
        if key.startswith("encode_"):
            print(f"encode, resolution {r['resolution']} ({r['vertices']} streamed vertices): {r['bytes_p50']:.0f} bytes/frame "
                  f"p50 (max {r['bytes_max']}; float32 would be {r['raw_float32_bytes']}), {r['encode_ms_p50']:.2f} ms, "
                  f"scene {r['scene_bytes']} bytes once, largest error {r['max_error_cm'] * 1e4:.0f} um")
            print(f"   against a JPEG of the offscreen render 480x360 (q80): {r['jpeg_ms_p50']:.1f} ms a frame "
                  f"(render + readback + encode), {r['jpeg_bytes']:.0f} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
