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
