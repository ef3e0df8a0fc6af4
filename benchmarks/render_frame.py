"""Milliseconds per rendered frame on this machine's OpenGL (Mesa llvmpipe where there is no GPU),
for the default face at resolutions 0 (~700 nodes) and 2 (~12k nodes), every view, with and
without the HUD, as a share of a 60 Hz frame (16.7 ms), and as a ratio to the rasterizer's floor
measured in the same run: one full-screen textured quad drawn and read back at the same size
(absolute GL times differ 1.5-2.5x between machines; the ratios compare across them).

Each frame uploads a new surface (the live loop's work), offers the HUD a new fps reading (shown
at most every 0.25 s, as live) and ends with ctx.finish(), so the time
is real rendering work, not queued commands. Two figures: wall-clock time, and the CPU time of the
whole process (llvmpipe's rasterizer threads included), which is what the frame costs a machine
and stays meaningful when other programs compete for the cores.
llvmpipe rasterises on LP_NUM_THREADS threads (default: one per core); the run prints the value
used. `--lp-threads 1,2` reruns the benchmark once per value in a fresh process (the variable is
read when the driver loads).
`--scan N` times the scanned head (the default face) shaded + HUD against the floor in N
alternating batches, whole frames (posing, rows, drawing; the whole frame's CPU split by thread:
the calling thread, the listing helper, llvmpipe's rasterizer threads); also with the full lashes
drawn with the coarse skin (render.scan_look.coarse_lashes not used), with the full skin and lashes
at any size, with every triangle handed to OpenGL (render.scan_draw's cull_on_cpu off), with the
triangles that cover no pixel or lie hidden inside the head kept (cull_unseen off), and with the
eyes' and the mouth's insides hidden by their openings' boxes on screen alone, not their convex
hulls (render.scan_rows's use_hulls off), and with the small triangles judged by their boxes
alone and no eyeball hiding its socket (render.scan_rows's small_box 0, use_balls off), and with
the teeth and gums hidden only behind the mouth's opening, not beside it (render.scan_rows's
use_walls off), and with the full lining, gums and tongue drawn with the coarse skin
(render.scan_draw's lod_inside off), and with the HUD composited last, not with the clear
(render.renderer.FaceRenderer's hud_first off), and with llvmpipe's rasterizer threads left to the
OS, not steered off the drawing thread's CPU while it draws and onto a CPU each after
(FaceRenderer's steer off: render.pipeline.steer_rasterizer); and the drawing alone (rows made beforehand: every
triangle; also with the whole skin in its full shader, split_skin off), for comparison.
`--scan N --stream` times the scanned head (shaded + HUD) and the floor as streams of frames, each
frame's pixels read back (the floor's too), serial and pipelined (render.pipeline: the next frame's
CPU half made while llvmpipe rasterises the frame before; the floor's frames flushed and read at
the next one the same way), in alternating 20-frame batches, and prints per pose the serial
ratio and the stream ratio to the floor side by side, wall and CPU, with the CPU by thread.
`--scan N --window` does the same in a window on $DISPLAY (run it under `xvfb-run -s "-screen 0
1920x1080x24"` without a display): each step a new state shown, serial and pipelined
(render.window.FaceWindow.pipelined), with the swap's own time.
`--scan-parts N` times where the scanned head's frame goes beyond the floor: the whole frame (shaded +
HUD) against the same frame with one part left out (the HUD; the lashes; the mouth's inside; the
eyeballs; the eye sockets; the skin's brows and lips; its plain rest; every group; the posing and
rows alone, no drawing), in N alternating batches with the floor, with the CPU of each kind of
thread: what a part costs is the whole frame's figure less the figure without it.
`--scan-areas` says where the scanned head's drawn triangles lie on screen, group by group: their
summed area, the part of the eyes', sockets' and mouth's outside their openings' boxes on screen,
and the pixels each group shows.
`--head-vs-mask N` times the default face with its held head against the mask alone in N
alternating batches instead (both see the same load: the issue-11 budget, head at most 1.2x).
Run: .venv/bin/python benchmarks/render_frame.py [--lp-threads 1,2] [--resolutions 0,1] [--mask]
     .venv/bin/python benchmarks/render_frame.py --scan 10 --stream
     .venv/bin/python benchmarks/render_frame.py --head-vs-mask 30 --resolutions 0,2
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

FRAME_60HZ_MS = 1000.0 / 60.0


def _states(model: object, n: int, expression: str = "happiness") -> list[object]:
    """A short expression onset (happiness), so surfaces (and trails) change every frame; "jaw_open"
    is the jaw dropped fully (AU27), "neutral" the face held at rest."""
    from sim.facs import apply_au, apply_expression
    from sim.integrator import Simulator
    from sim.state import FaceControl

    sim = Simulator(model)
    state = model.rest_state()  # type: ignore[attr-defined]
    out = []
    for k in range(n):
        control = FaceControl(model)
        w = min(1.0, (k + 1) / n)
        if expression == "jaw_open":
            apply_au(control, "AU27", w)
        elif expression != "neutral":
            apply_expression(control, expression, w)
        sim.step(state, control)
        out.append(state.copy())
    return out


Row = tuple[str, bool, float, float]


def _thread_cpu() -> dict[str, int]:
    """ns of CPU each kind of this process's threads has run: "main" (Python: posing, rows, and
    OpenGL's vertex shading, set-up and binning, which llvmpipe does on the calling thread),
    "raster" (llvmpipe's rasterizer threads: pixels), "other" (the scan's listing helper). Linux
    only (/proc/self/task/*/schedstat); empty elsewhere."""
    out: dict[str, int] = {}
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return out
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/comm") as f:
                comm = f.read().strip()
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                ns = int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            continue
        kind = "main" if int(tid) == os.getpid() else "raster" if comm.startswith("llvmpipe") else "other"
        out[kind] = out.get(kind, 0) + ns
    return out


def _timed(fn: object, frames: int) -> tuple[float, float]:
    """(wall ms, cpu ms) per call of fn(i)."""
    w, c = time.perf_counter(), time.process_time()
    for i in range(frames):
        fn(i)  # type: ignore[operator]
    return ((time.perf_counter() - w) / frames * 1000.0, (time.process_time() - c) / frames * 1000.0)


FLOOR_VS = """
#version 330
in vec2 pos;
out vec2 uv;
void main() { uv = 0.5 * pos + 0.5; gl_Position = vec4(pos, 0.0, 1.0); }
"""
FLOOR_FS = """
#version 330
uniform sampler2D tex;
in vec2 uv;
out vec4 color;
void main() { color = texture(tex, uv); }
"""


def floor_ms(ctx: object, size: tuple[int, int], frames: int) -> tuple[float, float]:
    """(wall ms, cpu ms) of the rasterizer's floor at `size`: a full-screen quad sampling a texture
    of that size into a colour + depth framebuffer, read back to memory, each frame finished."""
    import numpy as np

    previous = ctx.fbo  # type: ignore[attr-defined]
    rng = np.random.default_rng(0)
    tex = ctx.texture(size, 4, rng.integers(0, 255, (size[1], size[0], 4), dtype=np.uint8).tobytes())  # type: ignore[attr-defined]
    prog = ctx.program(vertex_shader=FLOOR_VS, fragment_shader=FLOOR_FS)  # type: ignore[attr-defined]
    quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4").tobytes())  # type: ignore[attr-defined]
    vao = ctx.vertex_array(prog, [(quad, "2f", "pos")])  # type: ignore[attr-defined]
    fbo = ctx.framebuffer([ctx.renderbuffer(size, 4)], ctx.depth_renderbuffer(size))  # type: ignore[attr-defined]

    def frame(i: int) -> None:
        fbo.use()
        fbo.clear(0.2, 0.2, 0.2, 1.0)
        tex.use(0)
        vao.render(mode=5)  # triangle strip
        fbo.read(components=3)
        ctx.finish()  # type: ignore[attr-defined]

    for i in range(5):
        frame(i)
    out = _timed(frame, frames)
    (previous if previous is not None else ctx.detect_framebuffer(0)).use()  # type: ignore[attr-defined]
    for obj in (vao, quad, prog, tex, fbo):
        obj.release()
    return out


def bench(resolution: int, size: tuple[int, int], frames: int, ctx: object, head: bool = True) -> list[Row]:
    import dataclasses

    from render.hud import HudInfo
    from render.offscreen import OffscreenRenderer
    from render.renderer import VIEWS
    from sim.face import default_model
    from sim.build import compile_model

    model = default_model(resolution)
    if not head:  # the mask alone, as the default face was drawn before it had a head
        model = compile_model(dataclasses.replace(model.rig, name="mask"))
    states = _states(model, 30)
    hud = HudInfo(channels=[("zygomaticus_major_l", 0.8, 0, 1), ("jaw", 0.3, 0, 1)], age=30,
                  devices=[("sgi:///dev/ttyS0", True), ("keyboard://", True)], fps=60.0,
                  latency_ms=12.0, lines=["? help"])
    # the fps reading changes every frame, as it does live; the HUD shows a new reading at most
    # every render.hud.NUMBER_PERIOD s of real time (as live), redrawing its cached layer then
    huds = [HudInfo(**{**hud.__dict__, "fps": 58.0 + 0.1 * k}) for k in range(len(states))]
    rows = []
    with OffscreenRenderer(model, size, ctx=ctx) as off:  # type: ignore[arg-type]
        for view in VIEWS:
            off.view = view
            for with_hud in (False, True):
                off.fbo.use()
                for s in states[:5]:  # warm-up: shader compilation, buffer allocation
                    off.renderer.draw(s, hud if with_hud else None)
                off.ctx.finish()

                def frame(i: int, h: bool = with_hud) -> None:
                    off.fbo.use()
                    off.renderer.draw(states[i % len(states)], huds[i % len(huds)] if h else None)
                    off.ctx.finish()

                rows.append((view, with_hud, *_timed(frame, frames)))
        off.view = "shaded"

        def exported(i: int) -> None:
            off.render_frame(states[i % len(states)], huds[i % len(huds)])

        rows.append(("shaded+read", True, *_timed(exported, frames)))
        off.renderer.antialias = "fxaa"
        rows.append(("shaded+fxaa", True, *_timed(exported, frames)))
        off.renderer.antialias = "none"
        off.renderer.supersample = 2
        rows.append(("shaded+ss2", True, *_timed(exported, frames)))
    return rows


def head_vs_mask(resolution: int, size: tuple[int, int], batches: int, ctx: object) -> list[str]:
    """The default face with its held head against the mask alone, shaded with and without the
    HUD, in alternating 10-frame batches on one context (so both see the same load), with the floor
    measured between them: median ms per frame and each as a ratio to the floor, and head / mask."""
    import dataclasses

    import numpy as np

    from render.hud import HudInfo
    from render.offscreen import OffscreenRenderer
    from sim.face import default_model
    from sim.build import compile_model

    head = default_model(resolution)
    models = {"head": head, "mask": compile_model(dataclasses.replace(head.rig, name="mask"))}
    hud = HudInfo(channels=[("zygomaticus_major_l", 0.8, 0, 1), ("jaw", 0.3, 0, 1)], age=30,
                  devices=[("sgi:///dev/ttyS0", True), ("keyboard://", True)], fps=60.0,
                  latency_ms=12.0, lines=["? help"])
    offs = {k: OffscreenRenderer(m, size, ctx=ctx) for k, m in models.items()}  # type: ignore[arg-type]
    states = {k: _states(m, 30) for k, m in models.items()}
    out = []
    try:
        for with_hud in (False, True):
            times: dict[str, list[tuple[float, float]]] = {"head": [], "mask": [], "floor": []}
            for b in range(batches):
                for k, off in offs.items():
                    def frame(i: int, off: OffscreenRenderer = off, k: str = k) -> None:
                        off.fbo.use()
                        off.renderer.draw(states[k][(b * 10 + i) % 30], hud if with_hud else None)
                        off.ctx.finish()

                    times[k].append(_timed(frame, 10))
                if b % 5 == 0:
                    times["floor"].append(floor_ms(ctx, size, 10))
            med = {k: np.median(np.array(v), axis=0) for k, v in times.items()}
            f = med["floor"]
            h, m = med["head"], med["mask"]
            out.append(f"{'shaded+HUD' if with_hud else 'shaded':<12}{h[0]:>8.2f}{h[1]:>8.2f}{m[0]:>8.2f}{m[1]:>8.2f}"
                       f"{f[0]:>8.2f}{f[1]:>8.2f}{h[0] / f[0]:>9.2f}{h[1] / f[1]:>9.2f}{m[0] / f[0]:>9.2f}"
                       f"{m[1] / f[1]:>9.2f}{h[0] / m[0]:>9.2f}{h[1] / m[1]:>9.2f}")
    finally:
        for off in offs.values():
            off.release()
    return out


def _scan_and_hud() -> tuple[object, object]:
    """The scanned head's model (the default face) and the HUD a show draws over it."""
    from puppet.face_cache import scan_model
    from render.hud import HudInfo

    hud = HudInfo(channels=[("zygomaticus_major_l", 0.8, 0, 1), ("jaw", 0.3, 0, 1)], age=30,
                  devices=[("sgi:///dev/ttyS0", True), ("keyboard://", True)], fps=60.0,
                  latency_ms=12.0, lines=["? help"])
    return scan_model(None), hud


def scan_vs_floor(size: tuple[int, int], batches: int, ctx: object) -> list[str]:
    """The scanned head (the default face, sim.face.scan) shaded + HUD, in alternating 10-frame
    batches with the floor: each frame poses the whole scan from the simulated surface, makes its
    rows (normals, fold term) and draws; also with the full skin at any size (render.scan_lod's
    coarse plain skin not used), with the full lining, gums and tongue (render.scan_lod's coarse
    inside not used), the drawing alone (rows made beforehand), and in one pass (the frame cleared
    just before the draw calls and no flush between them: FaceRenderer.clear_first,
    ScanDraw.flush_at), for a happiness onset, a surprise onset, the jaw dropped (AU27) and the face at rest (lips closed:
    the mouth's inside left out)."""
    import statistics

    from render.offscreen import OffscreenRenderer
    from render.pipeline import free_rasterizer
    from render.scan_rows import SMALL_BOX

    model, hud = _scan_and_hud()
    out = []
    with OffscreenRenderer(model, size, ctx=ctx) as off:  # type: ignore[arg-type]
        r = off.renderer
        parts = (r.clear_first, r.scan.flush_at)  # the frame in parts, as drawn (none with LP_NUM_THREADS=0)
        for expression in ("happiness", "surprise", "jaw_open", "neutral"):
            states = _states(model, 30, expression)
            rows = [r.scan.rows(s).copy() for s in states]
            drawn = []
            for s, rw in zip(states, rows):
                s.scan_rows = rw  # type: ignore[attr-defined]
                drawn.append(r.scan.look.mouth_open(rw[:, :3]))
            times: dict[str, list[tuple[float, float]]] = {"whole": [], "full_skin": [], "all_tris": [], "unseen": [],
                                                           "boxes": [], "full_lashes": [], "loose": [], "plane": [],
                                                           "full_inside": [], "draw": [],
                                                           "unsplit": [], "one_pass": [], "hud_last": [],
                                                           "unsteered": [], "floor": []}
            threads: dict[str, dict[str, list[float]]] = {k: {"main": [], "other": [], "raster": []}
                                                          for k in ("whole", "full_skin", "loose", "plane",
                                                                    "full_inside", "one_pass", "hud_last",
                                                                    "unsteered")}
            for b in range(batches + 1):
                for key, use_rows in (("whole", False), ("full_skin", False), ("all_tris", False), ("unseen", False),
                                      ("boxes", False), ("full_lashes", False), ("loose", False), ("plane", False),
                                      ("full_inside", False), ("draw", True),
                                      ("unsplit", True), ("one_pass", False), ("hud_last", False),
                                      ("unsteered", False)):
                    def frame(i: int, use: bool = use_rows, split: bool = key != "unsplit",
                              cull: bool = key != "all_tris", unseen: bool = key != "unseen",
                              lod: bool = key != "full_skin") -> None:
                        s = states[i % len(states)]
                        if not use:
                            del s.scan_rows  # type: ignore[attr-defined]
                        r.scan.lod = lod
                        r.clear_first = key != "one_pass" and parts[0]
                        r.hud_first = key != "hud_last"
                        r.steer = key != "unsteered"
                        r.scan.flush_at = () if key == "one_pass" else parts[1]
                        r.scan.lod_inside = key != "full_inside"
                        r.scan.split_skin = split
                        r.scan.cull_on_cpu = cull
                        r.scan.cull_unseen = unseen
                        r.scan.maker.use_hulls = key != "boxes"
                        r.scan.maker.small_box = 0.0 if key == "loose" else SMALL_BOX
                        r.scan.maker.use_balls = key != "loose"
                        r.scan.maker.use_walls = key != "plane"
                        few = r.scan.coarse_lash_vao
                        if key == "full_lashes":
                            r.scan.coarse_lash_vao = r.scan.lash_vao
                        off.fbo.use()
                        r.draw(s, hud)
                        off.ctx.finish()  # type: ignore[attr-defined]
                        r.scan.coarse_lash_vao = few
                        s.scan_rows = rows[i % len(states)]  # type: ignore[attr-defined]
                    if key == "unsteered":
                        free_rasterizer()  # as the OS left them
                    before = _thread_cpu()
                    t = _timed(frame, 10)
                    after = _thread_cpu()
                    if b:  # the first batch warms up
                        times[key].append(t)
                        if key in threads:
                            for kind, v in threads[key].items():
                                v.append((after.get(kind, 0) - before.get(kind, 0)) / 1e7)  # ms per frame
                t = floor_ms(ctx, size, 10)
                if b:
                    times["floor"].append(t)
            med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
                   for k, v in times.items()}
            f, whole, draw, unsplit = med["floor"], med["whole"], med["draw"], med["unsplit"]
            every, unseen, full, boxes = med["all_tris"], med["unseen"], med["full_skin"], med["boxes"]
            lashes, loose, plane, inside = med["full_lashes"], med["loose"], med["plane"], med["full_inside"]
            one, last, free = med["one_pass"], med["hud_last"], med["unsteered"]
            quicker = sum(a[0] < b[0] for a, b in zip(times["whole"], times["one_pass"]))
            steered = sum(a[0] < b[0] for a, b in zip(times["whole"], times["unsteered"]))
            first = sum(a[0] < b[0] for a, b in zip(times["whole"], times["hud_last"]))
            out.append(f"{expression:<10} mouth's inside drawn in {sum(drawn)}/{len(drawn)} frames; "
                       f"floor {f[0]:.2f} ms (cpu {f[1]:.2f}); whole frame {whole[0]:.2f} ms = "
                       f"{whole[0] / f[0]:.2f}x floor (cpu {whole[1] / f[1]:.2f}x; coarse skin drawn: "
                       f"{r.scan.coarse}), with the full lashes (the coarse skin) {lashes[0] / f[0]:.2f}x "
                       f"(cpu {lashes[1] / f[1]:.2f}x), with the full skin and lashes at any size "
                       f"{full[0] / f[0]:.2f}x (cpu {full[1] / f[1]:.2f}x), with every triangle handed to "
                       f"OpenGL {every[0] / f[0]:.2f}x (cpu {every[1] / f[1]:.2f}x), with the triangles that cover "
                       f"no pixel or lie hidden kept {unseen[0] / f[0]:.2f}x (cpu {unseen[1] / f[1]:.2f}x), with the "
                       f"insides hidden by their openings' boxes alone (not their hulls) {boxes[0] / f[0]:.2f}x "
                       f"(cpu {boxes[1] / f[1]:.2f}x), with the small triangles' boxes alone and no eyeball hiding "
                       f"the sockets {loose[0] / f[0]:.2f}x (cpu {loose[1] / f[1]:.2f}x), with the teeth and gums "
                       f"hidden only behind the mouth's opening {plane[0] / f[0]:.2f}x (cpu {plane[1] / f[1]:.2f}x), "
                       f"with "
                       f"the full lining, gums and tongue (the coarse skin) {inside[0] / f[0]:.2f}x "
                       f"(cpu {inside[1] / f[1]:.2f}x); "
                       f"drawing alone "
                       f"{draw[0]:.2f} ms = {draw[0] / f[0]:.2f}x (cpu {draw[1] / f[1]:.2f}x); the same with "
                       f"the skin in one shader {unsplit[0] / f[0]:.2f}x (cpu {unsplit[1] / f[1]:.2f}x); the whole "
                       f"frame in one pass (cleared just before the draw calls, no flush between them) "
                       f"{one[0] / f[0]:.2f}x (cpu {one[1] / f[1]:.2f}x), the whole frame quicker in "
                       f"{quicker}/{len(times['whole'])} batches; with the HUD composited last (not with the "
                       f"clear) {last[0] / f[0]:.2f}x (cpu {last[1] / f[1]:.2f}x), the whole frame quicker in "
                       f"{first}/{len(times['whole'])} batches; with llvmpipe's threads left to the OS (not "
                       f"steered) {free[0] / f[0]:.2f}x (cpu {free[1] / f[1]:.2f}x), the whole frame quicker in "
                       f"{steered}/{len(times['whole'])} batches")
            for key, label in (("whole", "whole frame's"), ("full_skin", "with the full skin,"),
                               ("loose", "with the small triangles' boxes alone and no eyeball hiding,"),
                               ("plane", "with the teeth and gums hidden only behind the mouth's opening,"),
                               ("full_inside", "with the full lining, gums and tongue,"),
                               ("one_pass", "in one pass,"), ("hud_last", "with the HUD composited last,"),
                               ("unsteered", "with llvmpipe's threads left to the OS,")):
                if threads[key]["main"]:
                    out.append(f"{'':<10} {label} CPU by thread, ms: " + ", ".join(
                        f"{kind} {statistics.median(v):.2f}" for kind, v in threads[key].items()))
    return out


class _FloorStream:
    """The floor (floor_ms's frame: a full-screen textured quad into a colour + depth framebuffer)
    as a stream of frames read back, with render.pipeline.FrameStream's push/finish: serial, each
    frame drawn and read back; pipelined, each frame drawn and flushed and read back at the next
    push (the floor has no CPU half, so it gains only what the flush overlaps)."""

    def __init__(self, ctx: object, size: tuple[int, int]) -> None:
        import numpy as np

        self.ctx, self.size = ctx, size
        rng = np.random.default_rng(0)
        self.tex = ctx.texture(size, 4, rng.integers(0, 255, (size[1], size[0], 4), dtype=np.uint8).tobytes())  # type: ignore[attr-defined]
        self.prog = ctx.program(vertex_shader=FLOOR_VS, fragment_shader=FLOOR_FS)  # type: ignore[attr-defined]
        self.quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4").tobytes())  # type: ignore[attr-defined]
        self.vao = ctx.vertex_array(self.prog, [(self.quad, "2f", "pos")])  # type: ignore[attr-defined]
        self.fbo = ctx.framebuffer([ctx.renderbuffer(size, 4)], ctx.depth_renderbuffer(size))  # type: ignore[attr-defined]
        self.pipelined = True
        self._pending: list[object] = []
        self.read_at = 0.0

    def _draw(self) -> None:
        self.fbo.use()
        self.fbo.clear(0.2, 0.2, 0.2, 1.0)
        self.tex.use(0)
        self.vao.render(mode=5)  # triangle strip

    def push(self, state: object = None, hud: object = None, tag: object = None) -> list[tuple[object, bytes]]:
        from render.pipeline import flush

        if not self.pipelined:
            self._draw()
            raw = self.fbo.read(components=3, alignment=1)
            self.read_at = time.perf_counter()
            return [(tag, raw)]
        done = self.finish()
        self._draw()
        flush()
        self._pending = [tag]
        return done

    def finish(self) -> list[tuple[object, bytes]]:
        if not self._pending:
            return []
        tag, self._pending = self._pending[0], []
        raw = self.fbo.read(components=3, alignment=1)
        self.read_at = time.perf_counter()
        return [(tag, raw)]

    def release(self) -> None:
        for obj in (self.vao, self.quad, self.prog, self.tex, self.fbo):
            obj.release()


STREAM_BATCH = 20  # frames per timed batch of a stream: each batch fills and drains the pipeline once


def scan_stream(size: tuple[int, int], batches: int, ctx: object) -> list[str]:
    """The scanned head shaded + HUD and the floor, each as a stream of frames read back (every
    frame's pixels, the floor's too), serial (each frame drawn, then read back) and pipelined
    (render.pipeline: the next frame's CPU half made while llvmpipe rasterises the frame before; the
    floor's frames flushed and read back at the next one the same way), in alternating
    STREAM_BATCH-frame batches (the onset's 30 frames in turn, the order of the four rotated each
    batch): per pose the serial ratio and the stream ratio side by side, wall and CPU, each kind
    of thread's CPU a frame, and the latency: from the push of a state to its pixels read back."""
    import statistics

    from render.offscreen import OffscreenRenderer

    model, hud = _scan_and_hud()
    floor = _FloorStream(ctx, size)
    out = []
    keys = ("floor serial", "floor stream", "scan serial", "scan stream")
    try:
        with OffscreenRenderer(model, size, ctx=ctx) as off:  # type: ignore[arg-type]
            streams = {"scan serial": off.stream(False), "scan stream": off.stream(True)}
            for expression in ("happiness", "surprise", "jaw_open", "neutral"):
                states = _states(model, 30, expression)
                times: dict[str, list[tuple[float, float]]] = {k: [] for k in keys}
                threads: dict[str, list[tuple[float, ...]]] = {k: [] for k in keys}
                latency: dict[str, list[float]] = {k: [] for k in keys}  # push of a state -> its pixels back
                loads = []
                for b in range(batches + 1):
                    order = keys[b % 4:] + keys[:b % 4]
                    for key in order:
                        if key.startswith("floor"):
                            floor.pipelined = key == "floor stream"
                            st: object = floor
                        else:
                            st = streams[key]
                        got = 0
                        pushed: dict[int, float] = {}

                        def frame(i: int, st: object = st, key: str = key) -> None:
                            nonlocal got
                            k = b * STREAM_BATCH + i
                            pushed[k] = time.perf_counter()
                            done = st.push(states[k % len(states)], hud, k)  # type: ignore[attr-defined]
                            if done and b:  # a frame's pixels are ready when read back (before the push draws)
                                latency[key] += [(st.read_at - pushed[j]) * 1e3 for j, _ in done]  # type: ignore[attr-defined]
                            if i == STREAM_BATCH - 1:
                                done += st.finish()  # type: ignore[attr-defined]
                            got += len(done)

                        before = _thread_cpu()
                        t = _timed(frame, STREAM_BATCH)
                        after = _thread_cpu()
                        assert got == STREAM_BATCH, (key, got)
                        if b:  # the first batch warms up
                            times[key].append(t)
                            threads[key].append(tuple((after.get(k, 0) - before.get(k, 0)) / 1e6 / STREAM_BATCH
                                                      for k in ("main", "other", "raster")))
                    loads.append(os.getloadavg()[0])
                med = {k: (statistics.median(x for x, _ in v), statistics.median(c for _, c in v))
                       for k, v in times.items()}
                fs, fp, ss, sp = (med[k] for k in keys)
                out.append(f"{expression:<10} load {min(loads):.1f}-{max(loads):.1f}; floor serial {fs[0]:.2f} ms "
                           f"(cpu {fs[1]:.2f}), stream {fp[0]:.2f} ms (cpu {fp[1]:.2f}); scan serial {ss[0]:.2f} ms "
                           f"(cpu {ss[1]:.2f}), stream {sp[0]:.2f} ms (cpu {sp[1]:.2f})")
                quicker = sum(p[0] < q[0] for p, q in zip(times["scan stream"], times["scan serial"]))
                floor_quicker = sum(p[0] < q[0] for p, q in zip(times["floor stream"], times["floor serial"]))
                out.append(f"{'':<10} x floor, wall: serial {ss[0] / fs[0]:.2f}x, stream {sp[0] / fp[0]:.2f}x; "
                           f"cpu: serial {ss[1] / fs[1]:.2f}x, stream {sp[1] / fp[1]:.2f}x; the stream quicker than "
                           f"serial in {quicker}/{batches} batches (the floor's: {floor_quicker}/{batches}), the scan's "
                           f"wall time stream / serial {sp[0] / ss[0]:.2f}")
                for key in keys:
                    th = [statistics.median(x[j] for x in threads[key]) for j in range(3)]
                    out.append(f"{'':<10} {key:<13} CPU a frame by thread, ms: main {th[0]:.2f}, "
                               f"helper {th[1]:.2f}, raster {th[2]:.2f}; a state's push to its pixels read back "
                               f"{statistics.median(latency[key]):.2f} ms (median)")
    finally:
        floor.release()
    return out


def scan_window(size: tuple[int, int], batches: int) -> list[str]:
    """The scanned head shaded + HUD in a FaceWindow on $DISPLAY (no vsync), each step showing a new
    state, serial and pipelined (FaceWindow.pipelined) in alternating STREAM_BATCH-step batches: per
    pose the median step (wall, CPU) and swap (wall: serially it waits for the rasterisation and
    copies the frame to the X server; pipelined the rasterisation is mostly done by then)."""
    import statistics

    import glfw

    from render.window import FaceWindow

    model, hud = _scan_and_hud()
    out = []
    with FaceWindow(model, size=size, title="render_frame", vsync=False) as win:  # type: ignore[arg-type]
        win.hud = hud  # type: ignore[assignment]
        swaps: list[float] = []
        swap = glfw.swap_buffers

        def timed_swap(w: object) -> None:
            t = time.perf_counter()
            swap(w)
            swaps.append(time.perf_counter() - t)

        glfw.swap_buffers = timed_swap
        try:
            for expression in ("happiness", "surprise", "jaw_open", "neutral"):
                states = _states(model, 30, expression)
                n = [0]

                def feed(w: FaceWindow, t: float, states: list[object] = states) -> None:
                    w.state = states[n[0] % len(states)]
                    n[0] += 1

                win.add_frame_callback(feed)
                times: dict[bool, list[tuple[float, float, float]]] = {False: [], True: []}
                loads = []
                for b in range(batches + 1):
                    for pipelined in ((False, True) if b % 2 else (True, False)):
                        win.pipelined = pipelined
                        swaps.clear()
                        w0, c0 = time.perf_counter(), time.process_time()
                        for _ in range(STREAM_BATCH):
                            win.step()
                        win.present()  # the last frame drawn, pipelined
                        if b:
                            times[pipelined].append(((time.perf_counter() - w0) / STREAM_BATCH * 1e3,
                                                     (time.process_time() - c0) / STREAM_BATCH * 1e3,
                                                     statistics.median(swaps) * 1e3))
                    loads.append(os.getloadavg()[0])
                win._frame_callbacks.remove(feed)
                med = {k: [statistics.median(x[j] for x in v) for j in range(3)] for k, v in times.items()}
                quicker = sum(p[0] < q[0] for p, q in zip(times[True], times[False]))
                out.append(f"{expression:<10} load {min(loads):.1f}-{max(loads):.1f}; a step serial {med[False][0]:.2f} ms "
                           f"(cpu {med[False][1]:.2f}, swap {med[False][2]:.2f}), pipelined {med[True][0]:.2f} ms "
                           f"(cpu {med[True][1]:.2f}, swap {med[True][2]:.2f}); pipelined quicker in "
                           f"{quicker}/{batches} batches")
        finally:
            glfw.swap_buffers = swap
    return out


SCAN_PARTS = {"HUD": (), "lashes": ("lashes",), "mouth's inside": ("mouth",), "eyeballs": ("eyes",),
              "eye sockets": ("sockets",), "brows and lips": ("features",), "plain skin": ("plain",),
              "every group": ("plain", "features", "eyes", "sockets", "mouth", "lashes")}


def scan_parts(size: tuple[int, int], batches: int, ctx: object) -> list[str]:
    """The scanned head shaded + HUD (as scan_vs_floor's whole frame) against the same frame with
    one part left out (render.scan_draw.ScanDraw.left_out; the HUD not drawn; or the posing and
    rows alone), in alternating 10-frame batches with the floor: per pose, median ms per frame as
    a ratio to the floor, wall and CPU, and each kind of thread's CPU (ms per frame)."""
    import statistics

    import numpy as np

    from render.offscreen import OffscreenRenderer

    model, hud = _scan_and_hud()
    out = []
    with OffscreenRenderer(model, size, ctx=ctx) as off:  # type: ignore[arg-type]
        r = off.renderer
        w, h = size
        for expression in ("happiness", "surprise", "jaw_open", "neutral"):
            states = _states(model, 30, expression)
            keys = ["whole", *SCAN_PARTS, "rows alone"]
            times: dict[str, list[tuple[float, float]]] = {k: [] for k in [*keys, "floor"]}
            threads: dict[str, list[tuple[float, float, float]]] = {k: [] for k in keys}
            for b in range(batches + 1):
                for key in keys:
                    def frame(i: int, key: str = key) -> None:
                        s = states[i % len(states)]
                        if key == "rows alone":
                            view_m, mvp = r._matrices(w / h)
                            r.scan.choose_level(mvp, size)
                            r.scan.rows(s, np.linalg.inv(view_m)[:3, 3], mvp, size)
                            return
                        r.scan.left_out = set(SCAN_PARTS.get(key, ()))
                        off.fbo.use()
                        r.draw(s, None if key == "HUD" else hud)
                        off.ctx.finish()  # type: ignore[attr-defined]
                        r.scan.left_out = set()
                    before = _thread_cpu()
                    t = _timed(frame, 10)
                    after = _thread_cpu()
                    if b:  # the first batch warms up
                        times[key].append(t)
                        threads[key].append(tuple((after.get(k, 0) - before.get(k, 0)) / 1e7
                                                  for k in ("main", "other", "raster")))  # type: ignore[arg-type]
                t = floor_ms(ctx, size, 10)
                if b:
                    times["floor"].append(t)
            med = {k: (statistics.median(x for x, _ in v), statistics.median(c for _, c in v))
                   for k, v in times.items()}
            f = med["floor"]
            out.append(f"{expression}: floor {f[0]:.2f} ms (cpu {f[1]:.2f}), load {os.getloadavg()[0]:.1f}")
            out.append(f"  {'':<22}{'x floor':>9}{'cpu x':>8}{'main':>8}{'helper':>8}{'raster':>8}  (ms a frame)")
            for k in keys:
                th = [statistics.median(x[j] for x in threads[k]) for j in range(3)]
                label = k if k in ("whole", "rows alone") else f"without {k}"
                out.append(f"  {label:<22}{med[k][0] / f[0]:>9.2f}{med[k][1] / f[1]:>8.2f}"
                           + "".join(f"{v:>8.2f}" for v in th))
    return out


def _clipped_area(tri: object, box: object) -> float:
    """px²: the area of the triangle `tri` ((3, 2) pixels) within `box` (x0, x1, y0, y1), by clipping
    it to each side in turn (Sutherland and Hodgman)."""
    import numpy as np

    poly = [tuple(float(v) for v in q) for q in tri]  # type: ignore[attr-defined]
    for axis, edge, keep_above in ((0, box[0], True), (0, box[1], False), (1, box[2], True),  # type: ignore[index]
                                   (1, box[3], False)):  # type: ignore[index]
        out = []
        for a, b in zip(poly, poly[1:] + poly[:1]):
            a_in = a[axis] >= edge if keep_above else a[axis] <= edge
            b_in = b[axis] >= edge if keep_above else b[axis] <= edge
            if a_in:
                out.append(a)
            if a_in != b_in:
                t = (edge - a[axis]) / (b[axis] - a[axis])
                out.append((a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])))
        poly = out
        if len(poly) < 3:
            return 0.0
    q = np.array(poly)
    return 0.5 * abs(float(q[:, 0] @ np.roll(q[:, 1], -1) - q[:, 1] @ np.roll(q[:, 0], -1)))


def scan_areas(size: tuple[int, int], ctx: object) -> list[str]:
    """Where the scanned head's drawn triangles lie on screen (shaded + HUD, the last frame of each
    30-frame onset): per group drawn, the triangles listed, their summed area on screen, their median
    and largest area, for the eyes', sockets' and mouth's the part of that area outside their
    openings' boxes on screen (what a scissor rectangle over the boxes would keep llvmpipe from
    rasterising), and the pixels the group shows (the picture with and without it)."""
    import numpy as np

    from render.offscreen import OffscreenRenderer
    from render.scan_draw import CULLED

    model, hud = _scan_and_hud()
    out = []
    w, h = size
    with OffscreenRenderer(model, size, ctx=ctx) as off:  # type: ignore[arg-type]
        scan = off.renderer.scan
        look = scan.look
        mouth = look.mouth_opening
        for expression in ("happiness", "surprise", "jaw_open", "fear", "neutral"):
            state = _states(model, 30, expression)[-1]
            picture = off.render_frame(state, hud, record=False)
            xy = scan.maker.xy.astype(np.float64)
            b = scan.maker.boxes  # normalised device x0 x1 y0 y1 of each opening
            boxes = np.stack([(b[:, 0] + 1) * w / 2, (b[:, 1] + 1) * w / 2, (b[:, 2] + 1) * h / 2,
                              (b[:, 3] + 1) * h / 2], axis=1)
            eyes = [k for k in range(len(boxes)) if k != mouth and boxes[k, 3] > 0.1 * h]  # not the neck's cut
            kept, counts = scan.kept.copy(), scan.counts.copy()
            out.append(f"{expression}: the mouth's inside drawn {scan.mouth_drawn}; the mouth's box on screen "
                       f"{boxes[mouth, 1] - boxes[mouth, 0]:.0f} x {boxes[mouth, 3] - boxes[mouth, 2]:.0f} px")
            for g, group in enumerate(CULLED):
                n = int(counts[g])
                if n == 0:
                    continue
                p = xy[kept[scan.starts[g]:scan.starts[g] + n]]
                area = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                                    - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
                line = (f"  {group:<9}{n:>6} triangles, {area.sum():>8.0f} px² (median {np.median(area):5.1f}, "
                        f"largest {area.max():5.0f})")
                if group in ("eyes", "sockets", "mouth"):
                    own = [mouth] if group == "mouth" else eyes
                    inside = sum(max(_clipped_area(t, boxes[k]) for k in own) for t in p)
                    line += f", {area.sum() - inside:>6.0f} px² outside the opening's box"
                scan.left_out = {group}
                without = off.render_frame(state, hud, record=False)
                scan.left_out = set()
                line += f"; shows {int((picture != without).any(axis=2).sum()):>6} px"
                out.append(line)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--resolutions", default="0,2")
    ap.add_argument("--lp-threads", default="", help="comma-separated LP_NUM_THREADS values to compare")
    ap.add_argument("--mask", action="store_true", help="also time each resolution as the mask alone (no head)")
    ap.add_argument("--head-vs-mask", type=int, default=0, metavar="BATCHES",
                    help="instead: the head against the mask alone (shaded, +HUD) in BATCHES alternating "
                         "10-frame batches each, with the floor between them")
    ap.add_argument("--scan-parts", type=int, default=0, metavar="BATCHES",
                    help="instead: the scanned head's frame against the same frame with one part left out in turn, "
                         "in BATCHES alternating 10-frame batches with the floor")
    ap.add_argument("--scan-areas", action="store_true",
                    help="instead: where the scanned head's drawn triangles lie on screen, group by group")
    ap.add_argument("--scan", type=int, default=0, metavar="BATCHES",
                    help="instead: the scanned head (the default face) shaded + HUD against the floor in "
                         "BATCHES alternating 10-frame batches")
    ap.add_argument("--stream", action="store_true",
                    help="with --scan: the scanned head and the floor as streams of frames read back, serial "
                         "and pipelined (render.pipeline), in alternating batches")
    ap.add_argument("--window", action="store_true",
                    help="with --scan: the scanned head in a window on $DISPLAY (e.g. under xvfb-run), serial and "
                         "pipelined steps in alternating batches")
    args = ap.parse_args()
    if args.lp_threads:
        for n in args.lp_threads.split(","):
            argv = [a for a in sys.argv[1:] if not a.startswith("--lp-threads")]
            if "--lp-threads" in sys.argv:  # the "--lp-threads VALUE" form
                i = sys.argv.index("--lp-threads")
                argv = sys.argv[1:i] + sys.argv[i + 2:]
            print(f"\n=== LP_NUM_THREADS={n} ===", flush=True)
            subprocess.run([sys.executable, __file__, *argv], env={**os.environ, "LP_NUM_THREADS": n},
                           check=True)
        return
    size = tuple(int(v) for v in args.size.lower().split("x"))
    if args.scan and args.window:  # the window's own context (GLX), no EGL one
        print(f"{size[0]}x{size[1]}, LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}, load average "
              f"{os.getloadavg()[0]:.1f}\nthe scanned head, shaded + HUD, in a window on $DISPLAY, serial and "
              f"pipelined: median per {STREAM_BATCH}-step batch over {args.scan} batches")
        for line in scan_window(size, args.scan):  # type: ignore[arg-type]
            print(line)
        return
    from render.offscreen import create_context

    ctx = create_context()
    threads = os.environ.get("LP_NUM_THREADS", f"unset (llvmpipe default: {os.cpu_count()} cores)")
    print(f"renderer: {ctx.info['GL_RENDERER']}, {size[0]}x{size[1]}, {args.frames} frames each, "
          f"LP_NUM_THREADS={threads}, load average {os.getloadavg()[0]:.1f}")
    from sim.face import default_model

    if args.scan_parts:
        print(f"\nthe scanned head, shaded + HUD, and with one part left out: median per 10-frame batch over "
              f"{args.scan_parts} batches")
        for line in scan_parts(size, args.scan_parts, ctx):  # type: ignore[arg-type]
            print(line)
        return
    if args.scan_areas:
        print("\nthe scanned head, shaded + HUD, the last frame of each onset: the triangles drawn, group by group")
        for line in scan_areas(size, ctx):  # type: ignore[arg-type]
            print(line)
        return
    if args.scan and args.stream:
        print(f"\nthe scanned head, shaded + HUD, and the floor as streams of frames read back, serial and "
              f"pipelined: median ms per {STREAM_BATCH}-frame batch over {args.scan} batches")
        for line in scan_stream(size, args.scan, ctx):  # type: ignore[arg-type]
            print(line)
        return
    if args.scan:
        print(f"\nthe scanned head, shaded + HUD, median ms per 10-frame batch over {args.scan} batches")
        for line in scan_vs_floor(size, args.scan, ctx):  # type: ignore[arg-type]
            print(line)
        return
    if args.head_vs_mask:
        for res in (int(r) for r in args.resolutions.split(",")):
            print(f"\nresolution {res}: median ms per frame over {args.head_vs_mask} alternating batches")
            print(f"{'view':<12}{'head':>8}{'cpu':>8}{'mask':>8}{'cpu':>8}{'floor':>8}{'cpu':>8}"
                  f"{'head x':>9}{'cpu x':>9}{'mask x':>9}{'cpu x':>9}{'h/m':>9}{'cpu h/m':>9}")
            for line in head_vs_mask(res, size, args.head_vs_mask, ctx):  # type: ignore[arg-type]
                print(line)
        return
    floors = [floor_ms(ctx, size, args.frames)]
    print(f"floor (textured full-screen quad + readback): {floors[0][0]:.2f} ms wall, {floors[0][1]:.2f} ms cpu")
    runs = [(int(r), head) for r in args.resolutions.split(",") for head in ((True, False) if args.mask else (True,))]
    for res, head in runs:
        n = len(default_model(res).rest)
        print(f"\nresolution {res} ({n} nodes), {'with the head' if head else 'the mask alone'}")
        print(f"{'view':<14}{'HUD':<5}{'wall ms':>9}{'cpu ms':>9}{'wall % of 60 Hz':>17}{'x floor':>9}{'cpu x floor':>13}")
        rows = bench(res, size, args.frames, ctx, head)  # type: ignore[arg-type]
        floors.append(floor_ms(ctx, size, args.frames))  # again after each face: drift shows
        floor = sum(f[0] for f in floors) / len(floors)
        floor_cpu = sum(f[1] for f in floors) / len(floors)
        for view, with_hud, wall, cpu in rows:
            print(f"{view:<14}{'yes' if with_hud else 'no':<5}{wall:>9.2f}{cpu:>9.2f}"
                  f"{wall / FRAME_60HZ_MS * 100:>16.0f}%{wall / floor:>9.2f}{cpu / floor_cpu:>13.2f}")
    print(f"\nfloor over the run: {', '.join(f'{f[0]:.2f}/{f[1]:.2f}' for f in floors)} ms wall/cpu "
          "(ratios use their means)")


if __name__ == "__main__":
    main()
