"""The face on the page: the server's side of the live view (render.stream encodes, the page's
face.js shows it).

Two ways (`FaceFeed.mode`): "picture" (the default) sends a JPEG of the face as the show renders it:
the frame the show itself drew when the show hands it over (`offer`), else one rendered at
render.stream.PICTURE_SIZE in a process of its own (puppet.panel.pictures: the renderer would
stall the live loop's thread); a page only decodes a small image. "mesh"
streams the vertex positions and the page draws them with WebGL 2. Measured with four pages on two
cores (benchmarks/panel_face.py, docs/panel.md): a page drawing the scanned head's 26,719 vertices
costs its browser ~22 ms of CPU a frame in software WebGL, a picture ~1-2 ms; so pictures are the
default, and the mesh is there for pages on machines with a GPU and a server short of CPU.

`FaceFeed` keeps the pages that watch the face. Each frame is encoded once and the same bytes go to
every page. A page says which frames it has drawn (`{"t":"drawn"}`); one with AHEAD frames sent and
not yet drawn, or whose last send is still under way, skips this frame: a slow phone (or a browser
starved of CPU) gets fewer frames, never a queue of old ones, so the lag behind the show stays about
one frame's encode, send and draw whatever the number of pages. On the live page the feed reads the loop's public state from the server's thread
with the state it sends every page (30 times a second; nothing runs in the live loop); the state is read while the loop may be stepping, so a
frame may mix two consecutive ticks (16 ms apart: nothing a viewer can see)."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # asyncio is imported where the server thread runs: opening the page device stays cheap
    import asyncio


AHEAD = 2  # frames a page may have received and not yet drawn
MODES = ("picture", "mesh")
DEFAULT_MODE = "picture"
OFFER_FRESH_S = 0.25  # a frame the show offered is used while this recent; older, the feed renders


@dataclass
class FeedStats:
    """What the feed cost: frames encoded, their bytes, the encode time; sends done and skipped."""

    frames: int = 0
    bytes: int = 0
    encode_s: float = 0.0
    sent: int = 0
    skipped: int = 0
    sizes: list[int] = field(default_factory=list)


class FaceFeed:
    """The pages watching one face: `add(ws)` sends the scene, `publish(state, tick)` one frame."""

    def __init__(self, mode: str = DEFAULT_MODE) -> None:
        if mode not in MODES:
            raise ValueError(f"face mode {mode!r}: expected one of {', '.join(MODES)}")
        self.mode = mode
        self.stream: Any = None
        self.model: Any = None
        self.pages: dict[Any, asyncio.Task[None] | None] = {}
        self.ahead: dict[Any, int] = {}  # per page: frames sent, not yet reported drawn
        self.stats = FeedStats()
        self.last_tick = -1
        self.offered: tuple[int, float, Any] | None = None  # (tick, time drawn, pixels) from the show
        self.wanted = False  # pages watch: a show that draws frames may offer them
        self._pool: Any = None  # one thread: the pictures' renderer (its GL context) and the encoding
        self._renderer: Any = None
        self._renderer_model: Any = None
        self._process: Any = None  # the picture process (a headless show's pictures)
        self._in_process = False  # that process could not run: pictures are drawn here
        self.thread_id: int | None = None  # that thread (the benchmark reads its CPU time)

    def offer(self, pixels: Any, tick: int, t: float | None = None) -> None:
        """The show's own frame of `tick` ((H, W, 3) uint8, top row first), for the pictures: called
        from the thread that drew it, after it is shown; costs nothing but keeping the reference."""
        self.offered = (int(tick), time.monotonic() if t is None else t, pixels)

    def _render(self, model: Any, state: Any, tick: int, t: float) -> bytes:
        """A picture of `state` drawn in the picture process (puppet.panel.pictures); drawn here
        only if that process cannot run."""
        from render.stream import PICTURE_SIZE, picture

        face_id = f"face{id(model):x}"
        if not self._in_process:
            try:
                if self._process is None or self._process.model is not model:
                    self._close_process()
                    from puppet.panel.pictures import PictureProcess

                    self._process = PictureProcess(model, PICTURE_SIZE)
                return self._process.picture(state, face_id, tick, t)
            except Exception:
                self._close_process()
                self._in_process = True
        from render.offscreen import OffscreenRenderer

        if self._renderer is None or self._renderer_model is not model:
            if self._renderer is not None:
                self._renderer.release()
            self._renderer, self._renderer_model = OffscreenRenderer(model, PICTURE_SIZE), model
        return picture(self._renderer.render_frame(state), face_id, tick, t)

    def _close_process(self) -> None:
        proc, self._process = self._process, None
        if proc is not None:
            proc.close()

    def _picture(self, model: Any, state: Any, offered: Any, tick: int, t: float) -> bytes:
        from render.stream import picture

        self.thread_id = threading.get_native_id()
        c0 = time.perf_counter()
        if offered is None:
            msg = self._render(model, state, tick, t)
        else:
            tick, t, pixels = offered
            msg = picture(pixels, f"face{id(model):x}", tick, t)
        self.stats.encode_s += time.perf_counter() - c0
        return msg

    async def make_picture(self, model: Any, state: Any, tick: int) -> bytes | None:
        """The next picture: the show's offered frame if it is newer than the last one sent and
        fresh, else (no frame offered lately) one rendered here from `state`; None when there is
        nothing new. Runs in the feed's own thread."""
        import asyncio
        from concurrent.futures import ThreadPoolExecutor

        off = self.offered
        now = time.monotonic()
        if off is not None and now - off[1] < OFFER_FRESH_S:
            if off[0] == self.last_tick:
                return None
            tick = off[0]
        else:
            off = None
            if tick == self.last_tick:
                return None
        if self._pool is None:
            self._pool = ThreadPoolExecutor(1, thread_name_prefix="face-picture")
        self.last_tick = tick
        return await asyncio.get_running_loop().run_in_executor(self._pool, self._picture, model, state, off, tick, now)

    def close(self) -> None:
        """Release the pictures' renderer and thread."""
        pool, self._pool = self._pool, None
        if pool is None:
            return

        def release() -> None:
            self._close_process()
            if self._renderer is not None:
                self._renderer.release()
                self._renderer = None

        try:
            pool.submit(release).result(10)
        except Exception:
            pass
        pool.shutdown(wait=False)

    async def use(self, model: Any) -> bool:
        """Stream `model` (built in a worker thread: a large mesh takes a while); True when it is
        a new face, whose scene has then been sent to every page watching."""
        if model is self.model:
            return False
        import asyncio

        if self.mode == "picture":  # no scene: every picture is whole
            self.model, self.last_tick, self.offered = model, -1, None
            return True

        from render.stream import FaceStream

        loop = asyncio.get_running_loop()
        self.stream = await loop.run_in_executor(None, FaceStream, model, f"face{id(model):x}")
        self.model, self.last_tick = model, -1
        scene = self.stream.scene()
        for ws in list(self.pages):
            await self._send_now(ws, scene)
        return True

    async def add(self, ws: Any, model: Any) -> None:
        """A page starts watching: the scene, then frames."""
        await self.use(model)
        if self.mode == "mesh":
            await self._send_now(ws, self.stream.scene())
        self.pages[ws] = None
        self.ahead[ws] = 0

    def drawn(self, ws: Any) -> None:
        """The page drew a frame: it may be sent another."""
        if ws in self.ahead:
            self.ahead[ws] = max(0, self.ahead[ws] - 1)

    def remove(self, ws: Any) -> None:
        self.ahead.pop(ws, None)
        task = self.pages.pop(ws, None)
        if task is not None:
            task.cancel()

    async def _send_now(self, ws: Any, data: bytes) -> None:
        import asyncio

        try:
            await asyncio.wait_for(ws.send_bytes(data), 5.0)
        except Exception:  # a page gone or stalled: its WebSocket handler removes it
            pass

    def publish(self, state: Any, tick: int, t: float | None = None) -> int:
        """Encode `state` once (mesh mode) and start sending it to every page not still busy with
        the last frame; the number of pages it goes to."""
        if self.stream is None or not self.pages:
            return 0
        c0 = time.perf_counter()
        msg = self.stream.frame(state, tick, time.monotonic() if t is None else t)
        self.stats.encode_s += time.perf_counter() - c0
        return self.send(msg, tick)

    def send(self, msg: bytes, tick: int) -> int:
        """One encoded frame (or picture) to every page not still busy with the last one."""
        import asyncio

        st = self.stats
        st.frames += 1
        st.bytes += len(msg)
        if len(st.sizes) < 10000:
            st.sizes.append(len(msg))
        self.last_tick = tick
        n = 0
        for ws, task in list(self.pages.items()):
            if (task is not None and not task.done()) or self.ahead.get(ws, 0) >= AHEAD:
                st.skipped += 1
                continue
            self.ahead[ws] = self.ahead.get(ws, 0) + 1
            self.pages[ws] = asyncio.get_running_loop().create_task(self._send_now(ws, msg))
            st.sent += 1
            n += 1
        return n


def parse_face_message(text: str) -> dict[str, Any] | None:
    """A page's face message (`{"t":"face","on":bool}`, `{"t":"drawn"}` or the editor's
    `{"t":"at","time":s}`), or None when the text is none of them or malformed."""
    import json
    import math

    if len(text) > 256:
        return None
    try:
        msg = json.loads(text)
    except ValueError:
        return None
    if not isinstance(msg, dict):
        return None
    if msg.get("t") == "face" and isinstance(msg.get("on"), bool):
        return msg
    if msg.get("t") == "drawn":
        return {"t": "drawn"}
    if msg.get("t") == "at":
        v = msg.get("time")
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            return {"t": "at", "time": float(v)}
    return None
