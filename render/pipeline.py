"""Frames drawn back to back with each frame's CPU half made while llvmpipe rasterises the frame
before it.

llvmpipe shades the vertices and bins the triangles on the calling thread inside the draw calls,
and rasterises the tiles on its own threads once the frame is flushed; a flush returns before they
are done (measured: docs/rendering.md, "Pipelined frames"). So a stream of frames can run
    draw N, flush | make N+1's CPU half (posing, rows, listing: no OpenGL) | read N back | draw N+1 ...
and the CPU half hides behind the rasterisation. The pixels are those of the serial frame (the same
state, camera and size make the same rows and lists; tests/render/test_render_pipeline.py); the
pixels of frame N reach the caller one CPU half later than serially, and the caller's own work on
them (encoding, writing) runs while frame N+1 rasterises."""

from __future__ import annotations

import ctypes
import time
from typing import Any

import numpy as np

from render.hud import HudInfo

_flush: Any = None


def flush() -> None:
    """glFlush on the current context (moderngl has none): hands the frame's binned triangles to
    llvmpipe's rasterizer threads and returns. Through GLVND's libOpenGL (or libGL), which
    dispatches to whichever context, EGL's or GLX's, is current on this thread."""
    global _flush
    if _flush is None:
        for name in ("libOpenGL.so.0", "libGL.so.1"):
            try:
                _flush = ctypes.CDLL(name).glFlush
                break
            except (OSError, AttributeError):
                continue
        else:  # no GL library by these names: the rasterizer then starts at the read, as serially
            _flush = lambda: None  # noqa: E731
    _flush()


def threaded_rasterizer() -> bool:
    """Whether llvmpipe rasterises on threads of its own, so that a flush hands the frame over and
    returns (LP_NUM_THREADS unset or above 0); with LP_NUM_THREADS=0 the calling thread rasterises
    at the flush itself, and a frame handed over in parts only adds passes over its tiles."""
    import os

    return os.environ.get("LP_NUM_THREADS", "").strip() != "0"


def rasterizer_threads() -> list[int]:
    """Thread ids of llvmpipe's rasterizer threads in this process (named "llvmpipe-N", started with
    a context's screen), from Linux's /proc, in their numbering; [] elsewhere or with LP_NUM_THREADS=0."""
    import os

    found = []
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return []
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/comm") as f:
                name = f.read().strip()
        except OSError:
            continue
        if name.startswith("llvmpipe-") and name[9:].isdigit():
            found.append((int(name[9:]), int(tid)))
    return [tid for _, tid in sorted(found)]


class _Steering:
    """llvmpipe's rasterizer threads and the CPUs this process may use, for `steer_rasterizer`;
    `others`: how many threads besides this one were runnable on the machine as frames began
    (smoothed over frames), `steered`: whether the frame being drawn was."""

    threads: list[int] = []
    cpus: list[int] = []
    getcpu: Any = None
    others = 0.0
    steered = False


# the weight of each frame's count of other runnable threads in `_Steering.others`
RUNNABLE_SMOOTHING = 0.2


def runnable_threads() -> int:
    """How many threads are runnable on the machine now, this one included (Linux's
    /proc/loadavg, its fourth field); -1 where unknown."""
    try:
        with open("/proc/loadavg") as f:
            return int(f.read().split()[3].split("/")[0])
    except (OSError, ValueError, IndexError):
        return -1


def find_rasterizer() -> int:
    """List llvmpipe's rasterizer threads and this process's CPUs for `steer_rasterizer`; called
    where a context is made (its screen starts the threads). Returns how many threads were found
    (0 where there is nothing to steer: not Linux, one CPU, no rasterizer threads)."""
    import os

    _Steering.threads, _Steering.cpus = [], []
    if not hasattr(os, "sched_setaffinity"):
        return 0
    try:
        cpus = sorted(os.sched_getaffinity(0))
        getcpu = ctypes.CDLL(None).sched_getcpu
    except (OSError, AttributeError):
        return 0
    if len(cpus) < 2:
        return 0
    _Steering.threads, _Steering.cpus, _Steering.getcpu = rasterizer_threads(), cpus, getcpu
    return len(_Steering.threads)


def steer_rasterizer(drawing: bool) -> None:
    """Where llvmpipe's rasterizer threads may run while this thread draws a frame, when the machine
    has a core to spare. `drawing` True (FaceRenderer.draw begins): on every CPU but the one this
    thread is on, so the parts of the frame flushed while this thread sets up the rest rasterise beside
    it. False (draw ends): each moved to a CPU of its own, then free to run anywhere again, so the
    rasterisation left when the caller waits (finish, a read, a swap) starts on every core. Left to
    themselves the two threads, busy on one core while this thread set up the frame, stayed on it when
    this thread went to wait: the frame's last 3-4 ms rasterised at one core's rate (docs/rendering.md,
    "Steering llvmpipe's threads"). Only while fewer other threads are runnable on the machine than
    there are other CPUs (counted as each frame begins, `runnable_threads`, smoothed over frames):
    where other programs load the cores, the steered threads waited for their CPU while others ran
    there (frames 1.2-2.7x slower at load 19-25), so they are left to the OS. One system call a thread
    at the start, two at the end, and a read of /proc/loadavg; if the OS refuses, the threads are left
    free and no longer steered (the same pixels either way); the threads of a context released since
    they were listed are dropped from the list."""
    import os

    threads, cpus = _Steering.threads, _Steering.cpus
    if not threads:
        return
    try:
        if drawing:
            _Steering.steered = False
            now = runnable_threads()
            if now < 0:
                return
            _Steering.others += RUNNABLE_SMOOTHING * (now - 1 - _Steering.others)
            here = int(_Steering.getcpu())
            others = {c for c in cpus if c != here}
            if _Steering.others >= len(others) or here not in cpus or not others:
                return  # no core idles while this thread draws: left to the OS
            for tid in threads:
                os.sched_setaffinity(tid, others)
            _Steering.steered = True
        elif _Steering.steered:
            _Steering.steered = False
            for k, tid in enumerate(threads):  # moved now, each to a CPU of its own ...
                os.sched_setaffinity(tid, {cpus[k % len(cpus)]})
            every = set(cpus)
            for tid in threads:  # ... and free to move on, where other programs load a CPU
                os.sched_setaffinity(tid, every)
    except ProcessLookupError:  # a thread gone (its context released): list the ones left
        free_rasterizer()
        find_rasterizer()
    except OSError:  # the OS refuses: stop steering
        free_rasterizer()
        _Steering.threads = []


def free_rasterizer() -> None:
    """llvmpipe's rasterizer threads free to run on any of the process's CPUs again (as the OS left
    them before `steer_rasterizer`): for a renderer that stops steering them."""
    import os

    for tid in _Steering.threads:
        try:
            os.sched_setaffinity(tid, set(_Steering.cpus))
        except OSError:
            continue


class FrameStream:
    """Frames of one `render.offscreen.OffscreenRenderer` drawn in a stream and read back.
    `push(state, hud, tag)` returns the frames read back by then as (tag, raw) pairs, raw being the
    RGB rows bottom row first (`OffscreenRenderer.image` turns them into a picture): pipelined, the
    frame pushed before this one (drawn while this one's CPU half was made); serial
    (`pipelined=False`), this one. `finish()` returns the last one still in flight. `read_at`: when
    the last frame returned was read back (its pixels were ready then, before this push's drawing)."""

    def __init__(self, off: Any, pipelined: bool = True) -> None:
        self.off = off
        self.pipelined = pipelined
        self._pending: list[Any] = []  # the tag of the frame drawn and flushed, not yet read
        self.read_at = 0.0  # time.perf_counter() when the last frame's pixels were read back

    def push(self, state: Any, hud: HudInfo | None = None, tag: Any = None,
             record: bool = True) -> list[tuple[Any, bytes]]:
        off = self.off
        if not self.pipelined:
            self._draw(state, hud, record, None)
            return [(tag, self._read())]
        prepared = off.renderer.prepare(state, off.size)  # while the frame before rasterises
        done = self.finish()
        self._draw(state, hud, record, prepared)
        flush()
        self._pending.append(tag)
        return done

    def finish(self) -> list[tuple[Any, bytes]]:
        """The frame still in flight, read back (waits for its rasterisation); [] if none."""
        if not self._pending:
            return []
        return [(self._pending.pop(), self._read())]

    def _draw(self, state: Any, hud: HudInfo | None, record: bool, prepared: Any) -> None:
        off = self.off
        off.fbo.use()
        off.fbo.viewport = (0, 0, *off.size)
        off.renderer.draw(state, hud=hud, record=record, prepared=prepared)

    def _read(self) -> bytes:
        raw = self.off.fbo.read(components=3, alignment=1)
        self.read_at = time.perf_counter()
        return raw


def image(raw: bytes, size: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) uint8 picture, top row first, of the rows `FrameStream` read back (bottom first)."""
    img = np.frombuffer(raw, np.uint8).reshape(size[1], size[0], 3)
    return np.ascontiguousarray(img[::-1])
