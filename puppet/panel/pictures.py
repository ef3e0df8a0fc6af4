"""Pictures of the face rendered in a child process, for the performer's pages of a show that draws
no frames of its own (headless).

The renderer (moderngl on Mesa's llvmpipe) holds Python's global lock for the whole of a draw and a
read-back: 10-20 ms for the scanned head. In the show's own process that stalls the live loop's
ticks (measured: event -> state p50 4.4-4.8 -> 6.9 ms, p99 9.8 -> 30-118 ms at 120 Hz with a
picture 30 times a second), so the pictures are drawn in a process of their own, fed the model once
and then a state and the sizes the pages ask for per picture, answering with the finished picture
messages (render.stream.pictures): drawn once at the largest size, scaled down for the others.
The child ends when its pipe closes, so it never outlives the show.

Its rasterizer works in the child's one thread (LP_NUM_THREADS=0, unless the user set it): a
picture's cost is mostly the scanned head's vertices, the same at every size (the pixels of a
640x480 picture are a third of it), and llvmpipe's raster threads only add hand-overs: measured
(benchmarks/panel_face.py --pictures, a shared machine at load 6-9, two runs) 0.7-2.8 ms less CPU
a picture up to 400x300, the same at 640x480; and a picture is one runnable thread, not three, on
cores the show and the pages' browsers share."""

from __future__ import annotations

from typing import Any


def _serve(conn: Any, size: tuple[int, int]) -> None:
    """The child: the model, then (state, face id, tick, time, sizes) per picture until None or EOF;
    the renderer is made again only when the largest size asked for changes."""
    import os

    os.environ.setdefault("LP_NUM_THREADS", "0")  # before the first GL context: see the module's note
    from render.offscreen import OffscreenRenderer
    from render.stream import pictures

    off: Any = None
    try:
        model = conn.recv()
        while True:
            job = conn.recv()
            if job is None:
                break
            state, face_id, tick, t, sizes = job
            big = max(sizes) if sizes else tuple(size)
            if off is None or off.size != big:
                if off is not None:
                    off.release()
                off = OffscreenRenderer(model, big)
            conn.send(pictures(off.render_frame(state), face_id, tick, t, sizes or (big,)))
    except (EOFError, OSError, KeyboardInterrupt):
        pass
    finally:
        if off is not None:
            off.release()


def drawn_part(state: Any) -> Any:
    """What the renderer reads of a face state: its surface and its scalars (eyes, jaw, head, age,
    ...), without the simulation's positions and velocities: a third of the bytes pickled through
    the pipe per picture. A state without attributes of its own goes whole."""
    import types

    import numpy as np

    try:
        fields = vars(state)
    except TypeError:
        return state
    return types.SimpleNamespace(**{k: v for k, v in fields.items()
                                    if k == "surface" or not isinstance(v, np.ndarray)})


class PictureProcess:
    """A child process drawing pictures of one model; `picture(state, ...)` blocks until it is done
    (call it from a worker thread: waiting on the pipe does not hold the global lock)."""

    def __init__(self, model: Any, size: tuple[int, int]) -> None:
        import multiprocessing

        ctx = multiprocessing.get_context("spawn")  # no fork of a process with GL and threads in it
        self.model = model
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_serve, args=(child, tuple(size)), name="face-pictures", daemon=True)
        self.proc.start()
        child.close()
        self.conn.send(model)

    @property
    def pid(self) -> int | None:
        return self.proc.pid

    def pictures(self, state: Any, face_id: str, tick: int, t: float, sizes: Any,
                 timeout: float = 60.0) -> dict[tuple[int, int], bytes]:
        """The picture messages of `state` at `sizes` (render.stream.pictures); RuntimeError if the
        child is gone or does not answer within `timeout` seconds (the first waits for its start)."""
        try:
            self.conn.send((drawn_part(state), face_id, int(tick), float(t), tuple(sizes)))
            if not self.conn.poll(timeout):
                raise RuntimeError("the picture process did not answer")
            return dict(self.conn.recv())
        except (EOFError, OSError, BrokenPipeError) as err:
            raise RuntimeError(f"the picture process is gone ({err})") from err

    def close(self) -> None:
        try:
            self.conn.send(None)
        except (OSError, BrokenPipeError):
            pass
        self.conn.close()
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join(5)
