"""The face on the page: the server's side of the live view (render.stream encodes, the page's
face.js shows it).

Two ways (`FaceFeed.mode`): "picture" (the default) sends a JPEG of the face as the show renders it:
the frame the show itself drew when the show hands it over (`offer`), else one rendered in a
process of its own (puppet.panel.pictures: the renderer would stall the live loop's thread); a
page only decodes a small image, of the size it shows the face at (it says its width; the sizes
are render.stream.PICTURE_SIZES, each made once a frame for every page of that size). "mesh"
streams the vertex positions and the page draws them with WebGL 2. Measured with four pages on two
cores (benchmarks/panel_face.py, docs/panel.md): a page drawing the scanned head's 26,719 vertices
costs its browser ~22 ms of CPU a frame in software WebGL, a picture ~1-2 ms; so pictures are the
default, and the mesh is there for pages on machines with a GPU and a server short of CPU.

`FaceFeed` keeps the pages that watch the face. Each frame is encoded once and the same bytes go to
every page (of one size). A still face is sent nothing (`moved`): a page keeps its last picture, and
one that missed the last frame, or is new, is sent it once (`catch_up`). A page says which frames it has drawn (`{"t":"drawn"}`); one with AHEAD frames sent and
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
STILL_CM = 0.002  # a face whose skin moved less than this since the last frame sent is still (a 50th of a pixel)
STATE_SCALARS = ("eye_yaw", "eye_pitch", "eye_vergence", "age", "jaw", "head_yaw", "head_pitch", "head_roll", "tongue_out")


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
        self.sizes: dict[Any, tuple[int, int]] = {}  # per page: the picture size it asked for
        self.serial = 0  # frames made so far (the mesh's, or one set of pictures)
        self.sent_serial: dict[Any, int] = {}  # per page: the serial of the last frame sent to it
        self.latest: dict[Any, bytes] = {}  # the last frame made, per picture size (None: the mesh's)
        self._ref: Any = None  # what the last frame showed: (surface, scalars) of its state
        self._ref_pixels: Any = None  # or the show's frame it was made of
        self._made: set[tuple[int, int]] = set()  # the picture sizes made of it
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

    def ask(self, ws: Any, width: Any) -> None:
        """The page `ws` shows the face `width` device pixels wide: it gets pictures of the size
        render.stream.picture_size gives (at once, with the next picture made for that size)."""
        from render.stream import picture_size

        self.sizes[ws] = picture_size(width)

    def wanted_sizes(self) -> set[tuple[int, int]]:
        """The picture sizes the pages watching ask for (each made once a frame for all of them)."""
        from render.stream import PICTURE_SIZE

        return {self.sizes.get(ws, PICTURE_SIZE) for ws in self.pages} or {PICTURE_SIZE}

    def _key(self, ws: Any) -> tuple[int, int] | None:
        """Which of the latest messages is the page's: its picture size, or None (the mesh's frame)."""
        if self.mode != "picture":
            return None
        from render.stream import PICTURE_SIZE

        return self.sizes.get(ws, PICTURE_SIZE)

    def moved(self, state: Any) -> bool:
        """Whether `state` looks different from the last one sent (a skin vertex moved more than
        STILL_CM, or the eyes, jaw, head, age or tongue changed); records it when it does. A still
        face is sent nothing: a page keeps showing the last picture."""
        import numpy as np

        sig = tuple(float(getattr(state, k, 0.0)) for k in STATE_SCALARS)
        surf = np.asarray(state.surface)
        ref = self._ref
        if (ref is not None and ref[1] == sig and ref[0].shape == surf.shape
                and float(np.abs(surf - ref[0]).max(initial=0.0)) <= STILL_CM):
            return False
        self._ref = (surf.copy(), sig)
        return True

    def _render(self, model: Any, state: Any, tick: int, t: float,
                sizes: Any) -> dict[tuple[int, int], bytes]:
        """Pictures of `state` at `sizes`, drawn in the picture process (puppet.panel.pictures) once
        at the largest; drawn here only if that process cannot run."""
        from render.stream import PICTURE_SIZE, pictures

        face_id = f"face{id(model):x}"
        if not self._in_process:
            try:
                if self._process is None or self._process.model is not model:
                    self._close_process()
                    from puppet.panel.pictures import PictureProcess

                    self._process = PictureProcess(model, PICTURE_SIZE)
                return self._process.pictures(state, face_id, tick, t, sizes)
            except Exception:
                self._close_process()
                self._in_process = True
        from render.offscreen import OffscreenRenderer

        big = max(sizes)
        if self._renderer is None or self._renderer_model is not model or self._renderer.size != big:
            if self._renderer is not None:
                self._renderer.release()
            self._renderer, self._renderer_model = OffscreenRenderer(model, big), model
        return pictures(self._renderer.render_frame(state), face_id, tick, t, sizes)

    def _close_process(self) -> None:
        proc, self._process = self._process, None
        if proc is not None:
            proc.close()

    def _picture(self, model: Any, state: Any, offered: Any, tick: int, t: float,
                 sizes: Any) -> dict[tuple[int, int], bytes]:
        from render.stream import pictures

        self.thread_id = threading.get_native_id()
        c0 = time.perf_counter()
        if offered is None:
            msgs = self._render(model, state, tick, t, sizes)
        else:
            tick, t, pixels = offered
            msgs = pictures(pixels, f"face{id(model):x}", tick, t, sizes)
        self.stats.encode_s += time.perf_counter() - c0
        return msgs

    async def make_picture(self, model: Any, state: Any, tick: int) -> dict[tuple[int, int], bytes] | None:
        """The next pictures, one per size the pages ask for: of the show's offered frame if it is
        fresh, else (no frame offered lately) rendered from `state`; None when there is nothing
        new: no newer tick, or the face has not moved (a still face costs nothing), and every size
        asked for has its picture. Made in the feed's own thread."""
        import asyncio
        from concurrent.futures import ThreadPoolExecutor

        import numpy as np

        sizes = self.wanted_sizes()
        missing = bool(sizes - self._made)
        off = self.offered
        now = time.monotonic()
        if off is not None and now - off[1] < OFFER_FRESH_S:
            if not missing and (off[0] == self.last_tick or (
                    self._ref_pixels is not None and np.array_equal(off[2], self._ref_pixels))):
                return None
            self._ref_pixels = off[2]
            tick = off[0]
        else:
            off = None
            if not self.moved(state) and not missing:
                return None
        if self._pool is None:
            self._pool = ThreadPoolExecutor(1, thread_name_prefix="face-picture")
        self.last_tick, self._made = tick, set(sizes)
        try:
            return await asyncio.get_running_loop().run_in_executor(
                self._pool, self._picture, model, state, off, tick, now, sorted(sizes))
        except BaseException:  # not made after all: the next step makes it again
            self._made, self._ref, self._ref_pixels = set(), None, None
            raise

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

        self.latest, self._ref, self._ref_pixels, self._made = {}, None, None, set()
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
        self.sizes.pop(ws, None)
        self.sent_serial.pop(ws, None)
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
        if not self.moved(state):  # a still face: pages that missed the last frame get it, nothing new
            return self.catch_up()
        c0 = time.perf_counter()
        msg = self.stream.frame(state, tick, time.monotonic() if t is None else t)
        self.stats.encode_s += time.perf_counter() - c0
        return self.send(msg, tick)

    def send(self, msg: bytes | dict[tuple[int, int], bytes], tick: int) -> int:
        """One encoded frame (the mesh's), or the pictures of one frame by size, to every page not
        still busy with the last one (each page its size's picture); the number of pages sent to."""
        st = self.stats
        msgs: dict[Any, bytes] = msg if isinstance(msg, dict) else {None: msg}
        for m in msgs.values():
            st.frames += 1
            st.bytes += len(m)
            if len(st.sizes) < 10000:
                st.sizes.append(len(m))
        self.last_tick = tick
        self.serial += 1
        self.latest = dict(msgs)
        return self.catch_up(count=True)

    def catch_up(self, count: bool = False) -> int:
        """The latest frame to every page that has not had it and is not busy (a page that was busy
        when it was made, or new, or that asked for another size); the number of pages sent to."""
        import asyncio

        n = 0
        for ws, task in list(self.pages.items()):
            if self.sent_serial.get(ws) == self.serial:
                continue
            m = self.latest.get(self._key(ws))
            if m is None:
                continue
            if (task is not None and not task.done()) or self.ahead.get(ws, 0) >= AHEAD:
                if count:
                    self.stats.skipped += 1
                continue
            self.ahead[ws] = self.ahead.get(ws, 0) + 1
            self.sent_serial[ws] = self.serial
            self.pages[ws] = asyncio.get_running_loop().create_task(self._send_now(ws, m))
            self.stats.sent += 1
            n += 1
        return n


def parse_face_message(text: str) -> dict[str, Any] | None:
    """A page's face message (`{"t":"face","on":bool}` with the width it shows the face at in
    device pixels, `"w":n`, if it says; `{"t":"drawn"}`; or the editor's `{"t":"at","time":s}`,
    with `"w"` too), or None when the text is none of them or malformed."""
    import json
    import math

    if len(text) > 256:
        return None
    try:
        msg = json.loads(text)
    except (ValueError, RecursionError):
        return None
    if not isinstance(msg, dict):
        return None
    w = msg.get("w")
    w = float(w) if isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and w > 0 else None
    if msg.get("t") == "face" and isinstance(msg.get("on"), bool):
        return {"t": "face", "on": msg["on"], "w": w}
    if msg.get("t") == "drawn":
        return {"t": "drawn"}
    if msg.get("t") == "at":
        v = msg.get("time")
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            return {"t": "at", "time": float(v), "w": w}
    return None
