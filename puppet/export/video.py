"""Rendered exports (MP4, PNG frames, a still) and a second process that renders and encodes while
this one simulates: the simulation of every tick and the software rasterizer each take a core,
so overlapping them is what makes long exports faster than real time on a CPU-only machine."""

from __future__ import annotations

import queue as _queue
import struct
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from puppet.errors import PuppetError

PARALLEL_MIN_FRAMES = 90
AHEAD_FRAMES = 600  # states buffered for the render process (~20 KB each at the default face)  # below this the second process's start-up costs more than it saves


class FrameSink:
    """An offscreen renderer plus the file writer for one export."""

    def __init__(self, model: Any, out: Path, kind: str, fps: float, size: tuple[int, int], view: str) -> None:
        try:
            from render.offscreen import OffscreenRenderer, save_image
        except ImportError as err:
            raise PuppetError(f"video and image export need the renderer: {err}") from err
        self._save = save_image
        try:
            self.renderer = OffscreenRenderer(model, size, view=view)
        except ValueError as err:
            raise PuppetError(str(err)) from err
        except Exception as err:  # no EGL / GL: one clear line, not a traceback
            raise PuppetError(f"cannot create an offscreen OpenGL context: {err}") from err
        self.out, self.kind = out, kind
        self.writer: Any = None
        try:
            if kind == "mp4":
                import imageio.v2 as imageio

                self.writer = imageio.get_writer(str(out), fps=fps, codec="libx264", quality=7,
                                                 pixelformat="yuv420p", macro_block_size=2,
                                                 ffmpeg_params=["-preset", "veryfast"], ffmpeg_log_level="error")
            elif kind == "frames":
                out.mkdir(parents=True, exist_ok=True)
        except Exception as err:
            self.renderer.release()
            raise PuppetError(f"{out}: cannot write: {err}") from err

    def add(self, j: int, state: Any) -> None:
        img = self.renderer.render_frame(state)
        if self.kind == "mp4":
            self.writer.append_data(img)
        elif self.kind == "png":
            self._save(img, self.out)
        else:
            self._save(img, self.out / f"frame_{j:06d}.png")

    def close(self) -> None:
        try:
            if self.writer is not None:
                self.writer.close()
                self.writer = None
        finally:
            self.renderer.release()


FRAME_HEAD = struct.Struct("<iI")  # frame number (-1 ends), payload bytes


def _pack(j: int, state: Any) -> bytes:
    body = np.ascontiguousarray(state.surface, dtype="<f8").tobytes() + struct.pack(
        "<4d", state.time, state.eye_yaw, state.eye_pitch, state.age)
    return FRAME_HEAD.pack(j, len(body)) + body


def worker_main() -> int:
    """The render process (`python -c ...worker_main()`): a fresh interpreter, so it never shares
    an OpenGL context with its parent nor re-runs the parent's command. Reads frames on stdin,
    reports `ready`, `done J`, `closed` or `error MESSAGE` lines on stdout."""
    import json
    import sys

    cfg = json.loads(sys.argv[1])
    out = sys.stdout
    inp = sys.stdin.buffer
    try:
        import pickle

        from sim.state import FaceState

        (n,) = struct.unpack("<Q", inp.read(8))
        model = pickle.loads(inp.read(n))  # our own parent's compiled face, over a private pipe
        sink = FrameSink(model, Path(cfg["out"]), cfg["kind"], cfg["fps"], tuple(cfg["size"]), cfg["view"])
    except Exception as err:  # reported to the parent as one line
        print("error " + str(err).replace("\n", " "), file=out, flush=True)
        return 1
    print("ready", file=out, flush=True)
    try:
        while True:
            head = inp.read(FRAME_HEAD.size)
            if len(head) < FRAME_HEAD.size:
                break
            j, n = FRAME_HEAD.unpack(head)
            if j < 0:
                break
            body = inp.read(n)
            pts = np.frombuffer(body[:-32], dtype="<f8").reshape(-1, 3)
            t, yaw, pitch, age = struct.unpack("<4d", body[-32:])
            sink.add(j, FaceState(pts, np.zeros_like(pts), pts, t, yaw, pitch, age))
            print(f"done {j}", file=out, flush=True)
        sink.close()
        print("closed", file=out, flush=True)
        return 0
    except Exception as err:
        print(f"error {type(err).__name__}: {err}".replace("\n", " "), file=out, flush=True)
        return 1


def render_serial(model: Any, out: Path, kind: str, fps: float, size: tuple[int, int], view: str,
                  frames: Iterable[tuple[int, Any]], progress: Callable[[int], None]) -> None:
    sink = FrameSink(model, out, kind, fps, size, view)
    try:
        for j, state in frames:
            sink.add(j, state)
            progress(1)
    finally:
        sink.close()


def render_parallel(model: Any, out: Path, kind: str, fps: float, size: tuple[int, int], view: str,
                    frames: Iterable[tuple[int, Any]], progress: Callable[[int], None]) -> None:
    """Simulate here, render and encode in a second process; the compiled face is handed over
    pickled on the private pipe (compiling it again would cost seconds), then one state per frame."""
    import json
    import pickle
    import subprocess
    import sys
    import threading

    cfg = json.dumps({"out": str(out), "kind": kind, "fps": fps, "size": list(size), "view": view})
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from puppet.export.video import worker_main; "
                             "sys.exit(worker_main())", cfg], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL)
    msgs: _queue.Queue[str] = _queue.Queue()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            msgs.put(line.decode("utf-8", "replace").strip())
        msgs.put("eof")

    reader = threading.Thread(target=read, name="render-progress", daemon=True)
    reader.start()

    def collect(block: bool) -> str:
        while True:
            try:
                m = msgs.get(timeout=120 if block else 0)
            except _queue.Empty:
                if block:
                    raise PuppetError("the render process stopped answering") from None
                return ""
            if m.startswith("error"):
                raise PuppetError(f"rendering failed: {m[6:]}")
            if m == "eof":
                raise PuppetError("the render process ended early")
            if m.startswith("done"):
                progress(1)
                if not block:
                    continue
            if m == "closed" or not block:
                return m

    assert proc.stdin is not None
    stdin = proc.stdin
    # a writer thread with a deep buffer lets the simulation run ahead while the renderer starts
    outbox: _queue.Queue[bytes | None] = _queue.Queue(maxsize=AHEAD_FRAMES)

    def write() -> None:
        try:
            while (chunk := outbox.get()) is not None:
                stdin.write(chunk)
            stdin.write(FRAME_HEAD.pack(-1, 0))
            stdin.close()
        except (BrokenPipeError, OSError):
            pass  # the worker died; its reason arrives on stdout

    writer = threading.Thread(target=write, name="render-feed", daemon=True)
    try:
        blob = pickle.dumps(model, protocol=pickle.HIGHEST_PROTOCOL)
        outbox.put(struct.pack("<Q", len(blob)) + blob)
        writer.start()
        for j, state in frames:
            while True:
                try:
                    outbox.put(_pack(j, state), timeout=0.2)
                    break
                except _queue.Full:
                    collect(False)
                    if proc.poll() is not None:
                        collect(True)
            collect(False)
        outbox.put(None)
        while collect(True) != "closed":
            pass
        proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
