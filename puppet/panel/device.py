"""``panel://[HOST][:PORT][?lan=1]`` — the performer's page as a control box.

Opening the device starts the web server (puppet.panel.server); each browser page that connects is
its own device in the event stream, ``panel://HOST:PORT/NAME``, announced with a ``connected``
status event and gone with ``lost`` (held pads are released then). A page sends control events
(``slider:CHANNEL`` axes in 0..1, ``pad:expr:NAME`` / ``pad:AUn`` / ``button:panic`` /
``button:marker`` buttons); they are stamped with ``time.monotonic()`` when the message arrives and
handed to the listeners like any box's, so they are mapped, combined, recorded and replayed like
them and ``puppet learn`` can bind them. The live loop does not know a browser exists: the server
only reads the loop's public state (`watch`) to show every page the applied values, the devices,
fps and latency.

With ``serve_later=True`` opening only prepares the controls; `serve_in_background` starts the
server (importing aiohttp, ~0.3 s) in a thread, so `puppet live` does not wait for it before its
first tick when the user did not ask for the page."""

from __future__ import annotations

import json
import math
import re
import threading
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from devices.base import ControlInfo, Device
from devices.errors import DeviceError
from devices.events import ControlEvent, StatusEvent
from devices.spec import DeviceSpec

if TYPE_CHECKING:  # asyncio is imported where the server thread runs: opening the device stays cheap
    import asyncio

STATE_HZ = 30.0
#: the longest a state waits for its cycle's picture (then it goes out alone)
FACE_WAIT_S = 0.1
MAX_MESSAGE = 4096
NAME_RE = re.compile(r"[A-Za-z0-9_-]{1,24}")


@dataclass
class Client:
    name: str
    device: str
    ws: Any
    allowed: set[str]
    only: list[str]
    role: str | None
    own: dict[str, float] = field(default_factory=dict)
    bad: int = 0
    face: bool = False  # the page watches the face


def parse_roles(items: Sequence[str], vocab: Any = None) -> dict[str, list[str]]:
    """`NAME=PAT,PAT` items (the --panel-role option) -> {name: patterns}; ValueError if malformed
    or, given the face's `vocab`, if a pattern matches no control (a typo served an empty page)."""
    roles: dict[str, list[str]] = {}
    for item in items:
        name, sep, pats = item.partition("=")
        if not sep or not NAME_RE.fullmatch(name) or not pats.strip():
            raise ValueError(f"expected --panel-role NAME=PATTERN[,PATTERN...] (e.g. mouth=jaw,orbicularis_oris), got {item!r}")
        roles[name] = [p.strip() for p in pats.split(",") if p.strip()]
        if vocab is not None:
            from puppet.panel.layout import MARKER, PANIC, allowed_controls

            for pat in roles[name]:
                if not allowed_controls(vocab, [pat]) - {PANIC, MARKER}:
                    raise ValueError(f"--panel-role {name}: {pat!r} matches no channel, pair, action unit or "
                                     "expression of this face (`puppet channels` lists them)")
    return roles


def decode_input(text: str, allowed: set[str]) -> tuple[str, float] | None:
    """One page message `{"t":"in","c":CONTROL,"v":VALUE}` -> (control, value in 0..1), or None
    when it is malformed, not an input, or names a control this page may not send."""
    if len(text) > MAX_MESSAGE:
        return None
    try:
        msg = json.loads(text)
    except (ValueError, RecursionError):  # 4096 bytes nest 2048 deep, past json's recursion limit
        return None
    if not isinstance(msg, dict) or msg.get("t") != "in":
        return None
    ctl, val = msg.get("c"), msg.get("v")
    if not isinstance(ctl, str) or ctl not in allowed or isinstance(val, bool) or not isinstance(val, (int, float)):
        return None
    try:
        v = float(val)
    except OverflowError:  # an integer of 309+ digits: it ended the page's connection with a traceback
        return None
    if not math.isfinite(v):
        return None
    return ctl, min(1.0, max(0.0, v))


class PanelDevice(Device):
    """The page server as a device; see the module docstring."""

    scheme = "panel"
    OPTIONS = frozenset({"lan", "face"})
    FORM = "panel://[HOST][:PORT][?lan=1][&face=picture|mesh]"

    def __init__(self, spec: DeviceSpec, vocab: Any = None, roles: dict[str, list[str]] | None = None,
                 serve_later: bool = False, **options: Any) -> None:
        super().__init__(spec, **options)
        self.serve_later = serve_later
        self._serve_lock = threading.Lock()  # a server started late and close() do not cross
        loc = spec.location.strip("/")
        host, _, port = loc.rpartition(":") if ":" in loc else (loc, "", "")
        self.explicit_port = bool(port)
        try:
            self.port = int(port) if port else None
        except ValueError as err:
            raise DeviceError(f"{spec.text}: port {port!r} is not a number; expected {self.FORM}") from err
        if self.port is not None and not 0 <= self.port <= 65535:
            raise DeviceError(f"{spec.text}: port {self.port} is outside 0..65535")
        self.lan = spec.get_bool("lan", False)
        self.host = host or ("0.0.0.0" if self.lan else "127.0.0.1")
        from puppet.panel.address import DEFAULT_PORT, is_loopback

        if not self.lan and not is_loopback(self.host):
            # served beyond the loopback without the LAN mode's token, the page's only guard would be
            # the Host header, which any machine on the network can write as 127.0.0.1
            raise DeviceError(f"{spec.text}: {self.host} would serve the page beyond this machine; say so with "
                              f"lan=1 (panel://{self.host}:{port or DEFAULT_PORT}?lan=1: the printed URL then "
                              "holds a token), or use 127.0.0.1")
        self.vocab = vocab
        self.roles = dict(roles or {})
        self.description = "browser panel"
        self.clients: dict[str, Client] = {}
        self.core: Any = None
        self.devs: Sequence[Any] = ()
        self.server: Any = None
        self.layout: dict[str, Any] = {}
        self._every: set[str] = set()
        self._rates = {"t": time.monotonic(), "frames": 0, "ticks": 0, "fps": 0.0, "tps": 0.0}
        self._count = 0
        self.received = 0
        self._task: asyncio.Task[None] | None = None
        self.record: str | None = None
        self.editor: Any = None  # the `puppet edit` process the editor button started
        from puppet.panel.face import DEFAULT_MODE, MODES, FaceFeed

        mode = spec.query.get("face", DEFAULT_MODE)
        if mode not in MODES:
            raise DeviceError(f"{spec.text}: face={mode!r} is not one of {', '.join(MODES)}; expected {self.FORM}")
        self.face_feed = FaceFeed(mode)  # the pages watching the face

    # --- device hooks ----------------------------------------------------------------------------
    def _open(self) -> None:
        from puppet.panel import layout as L

        if self.server is not None:
            return
        if self.vocab is None:
            from puppet.live import load_face

            self.vocab = load_face().vocab
        self.layout = L.build_layout(self.vocab)
        self._every = L.allowed_controls(self.vocab, None)
        self.controls = [ControlInfo(c, "axis" if c.startswith("slider:") else "button", 0.0, 1.0)
                         for c in L.controls_of(self.vocab)]
        if not self.serve_later:
            self._serve()

    def _serve(self) -> None:
        from puppet.errors import PuppetError
        from puppet.panel.server import DEFAULT_PORT, PanelServer

        port = DEFAULT_PORT if self.port is None else self.port
        srv = PanelServer(self.host, port, "panel.html", self._routes, try_ports=0 if self.explicit_port else 20,
                          lan=self.lan)
        try:
            srv.start()
        except PuppetError as err:
            raise DeviceError(f"{self.spec}: {err}") from err
        self.server = srv
        self.description = f"browser panel at {srv.url}"

    def serve_in_background(self, ready: Any, failed: Any) -> threading.Thread:
        """Start the server of a device opened with serve_later in a thread; then `ready(self)`,
        or `failed(message)` if it cannot serve (the show goes on without the page)."""

        def run() -> None:
            with self._serve_lock:
                if self._closed or self.server is not None:
                    return
                try:
                    self._serve()
                except Exception as err:  # noqa: BLE001 - a page that cannot start never stops the show
                    failed(f"no performer's page ({err})")
                    return
            if not self._closed:
                ready(self)

        thread = threading.Thread(target=run, name="panel start", daemon=True)
        thread.start()
        return thread

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        self._stop.wait(timeout)
        return ()

    def _wake(self) -> None:
        self._stop.set()

    def _close_handle(self) -> None:
        with self._serve_lock:
            if self.server is not None and self._stop.is_set():
                self.server.stop()
                self.server = None
        self.face_feed.close()
        ed, self.editor = self.editor, None
        if ed is not None and ed.poll() is None:
            ed.terminate()
            try:
                ed.wait(5)
            except Exception:
                ed.kill()

    @property
    def url(self) -> str:
        return self.server.url if self.server is not None else ""

    def add_listener(self, fn: Any) -> None:
        """Also tell a new listener about the pages already open (they may connect before the
        live loop listens)."""
        super().add_listener(fn)
        for c in list(self.clients.values()):
            try:
                fn(StatusEvent(c.device, "connected", time.monotonic(), "page open"))
            except Exception:
                pass

    # --- the loop's public state ----------------------------------------------------------------
    def watch(self, core: Any, devs: Sequence[Any], record: str | None = None) -> None:
        """Show pages this live core's state (read from the server thread; nothing runs in the
        loop); `record` is the take being recorded, which the page's editor button opens."""
        self.core, self.devs = core, devs
        self.record = record

    def _state(self) -> dict[str, Any]:
        core = self.core
        st: dict[str, Any] = {"t": "state", "clients": [
            {"name": c.name, "role": c.role, "only": c.only, "own": c.own} for c in list(self.clients.values())]}
        if core is None:
            return st
        vals = core.values
        st["tick"] = int(core.tick_count)
        st["values"] = [round(float(x), 5) for x in vals]
        now = time.monotonic()
        r = self._rates
        if now - r["t"] >= 1.0:
            frames, ticks = getattr(core, "frames", 0), core.tick_count
            r["fps"] = (frames - r["frames"]) / (now - r["t"])
            r["tps"] = (ticks - r["ticks"]) / (now - r["t"])
            r["t"], r["frames"], r["ticks"] = now, frames, ticks
        st["fps"], st["tps"] = round(r["fps"], 1), round(r["tps"], 1)
        lat = _copy(core.latency.samples)
        if lat:
            lat.sort()
            st["latency"] = [round(lat[len(lat) // 2] * 1e3, 2), round(lat[min(len(lat) - 1, int(len(lat) * 0.99))] * 1e3, 2)]
        status = dict(_copy_items(core.mapper.status))
        # [spec, connected, drops, level]: drops counts input a network listener lost to bursts (else
        # null); a microphone adds how loud it hears
        devices = [[self._base() if d is self else d.spec, bool(status.get(d.spec, d.connected)),
                    getattr(d, "drops", None)] for d in self.devs]
        for row, d in zip(devices, self.devs, strict=False):
            level = getattr(d, "level", None)
            if isinstance(level, float):
                row.append(round(level, 3))
        devices += [[c.device, True] for c in list(self.clients.values())]
        st["devices"] = devices
        st["markers"] = [[round(k / core.rate, 2), label] for k, label in core.markers[-8:]]
        return st

    # --- web routes ------------------------------------------------------------------------------
    def _routes(self, app: Any) -> None:
        from aiohttp import web

        async def layout(request: Any) -> Any:
            return web.json_response(self.layout)

        app.router.add_post("/api/edit", self._open_editor)
        app.router.add_get("/ws", self._ws)
        app.router.add_get("/favicon.ico", _no_icon)
        app.router.add_get("/api/layout", layout)
        from puppet.panel.takes import TakeRoutes

        TakeRoutes(self._library_path).add(app)  # the take list (its own panel, takes.js)
        app.on_startup.append(self._start_broadcast)
        app.on_cleanup.append(self._stop_broadcast)

    def _library_path(self) -> Any:
        from puppet.library import library_path

        return library_path(getattr(self, "library", None))  # `puppet live --library` sets it

    async def _start_broadcast(self, app: Any) -> None:
        import asyncio

        self._task = asyncio.get_running_loop().create_task(self._broadcast())

    async def _stop_broadcast(self, app: Any) -> None:
        import asyncio

        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            try:
                await task
            except (asyncio.CancelledError, Exception):
                pass

    async def _broadcast(self) -> None:
        """The loop's state to every page, and the face to the pages watching it, STATE_HZ times a
        second on an absolute schedule. Each cycle starts the picture of the loop's state at once
        and sends it as soon as it is made, then the state (read then): a page gets both together
        and redraws once per cycle (a software-composited browser pays for every redraw of the
        whole page), and the picture is only its own making old when it leaves. A picture slower
        than FACE_WAIT_S (a loaded machine) lets the state go out alone; it goes with a later state
        when done, and no other picture is started meanwhile, so the pages get max(period, picture
        time) cycles."""
        import asyncio

        period = 1.0 / STATE_HZ
        due = time.monotonic()
        face_task: asyncio.Task[tuple[dict[tuple[int, int], bytes], int] | None] | None = None
        try:
            while True:
                due += period
                now = time.monotonic()
                if due < now - period:  # the machine stalled: re-anchor rather than burst
                    due = now
                await asyncio.sleep(max(0.0, due - now))
                if not self.clients:
                    continue
                # the face in its own task: a picture being rendered holds up the state FACE_WAIT_S at most
                if face_task is None:
                    face_task = asyncio.get_running_loop().create_task(self._face_step())
                if not face_task.done():
                    try:
                        await asyncio.wait_for(asyncio.shield(face_task), FACE_WAIT_S)
                    except Exception:  # slower than that: the state goes out alone this time
                        pass
                if face_task.done():
                    got = None if face_task.cancelled() or face_task.exception() else face_task.result()
                    face_task = None
                    if got is not None:  # the pictures first: a page decodes one while it reads the state
                        self.face_feed.send(*got)
                    elif self.face_feed.mode == "picture":  # nothing new: pages that missed the last get it
                        self.face_feed.catch_up()
                try:
                    text = json.dumps(self._state(), separators=(",", ":"))
                except Exception:  # the loop's state changed under us: next time
                    continue

                async def send(ws: Any) -> None:
                    try:
                        await asyncio.wait_for(ws.send_str(text), 0.5)
                    except Exception:  # a stalled page must not stall the others
                        pass

                await asyncio.gather(*(send(c.ws) for c in list(self.clients.values()) if not c.ws.closed))
        finally:  # the server is closing: the picture under way is not waited for
            if face_task is not None:
                face_task.cancel()

    async def _face_step(self) -> tuple[dict[tuple[int, int], bytes], int] | None:
        """The face to the pages watching it: the loop's state encoded once per new tick for every
        page (puppet.panel.face); in mesh mode a page that just asked for it gets the scene first and
        the frame is sent at once; in picture mode the picture and its tick are returned, for
        `_broadcast` to send with this cycle's state."""
        core, feed = self.core, self.face_feed
        watching = [c.ws for c in list(self.clients.values()) if c.face and not c.ws.closed]
        feed.wanted = bool(watching)
        if core is None or not watching:
            return None
        try:
            model = core.face.model
            await feed.use(model)
            for ws in watching:
                if ws not in feed.pages:
                    await feed.add(ws, model)
            k = int(core.tick_count)
            if feed.mode == "picture":
                msg = await feed.make_picture(model, core.state, k)
                return None if msg is None else (msg, feed.last_tick)
            if k != feed.last_tick:
                feed.publish(core.state, k)
        except Exception:  # the loop's state changed under us, or a page went: next time
            pass
        return None

    def _base(self) -> str:
        """The spec with the port actually served (the OS's or the fallback's choice)."""
        base = self.spec.split("?", 1)[0].rstrip("/")
        if self.server is not None and (not self.port or self.server.port != self.port):
            base = f"panel://{self.host}:{self.server.port}"
        return base

    async def _open_editor(self, request: Any) -> Any:
        """Start `puppet edit` on the take being recorded, in its own process (the show's process
        stays as lean as it was), and answer its URL."""
        import asyncio

        from aiohttp import web

        if not self.record:
            return web.json_response({"ok": False, "error": "this show is not recorded: start it with --record FILE"})
        if self.editor is not None and self.editor.poll() is None:
            return web.json_response({"ok": True, "url": self._editor_url})
        loop = asyncio.get_running_loop()
        try:
            self.editor, self._editor_url = await loop.run_in_executor(None, _start_editor, self.record)
        except Exception as err:
            return web.json_response({"ok": False, "error": str(err)})
        return web.json_response({"ok": True, "url": self._editor_url})

    def _client_name(self, want: str | None) -> str:
        base = want if want and NAME_RE.fullmatch(want) else None
        if base is None:
            self._count += 1
            base = f"page{self._count}"
        name, n = base, 1
        while name in self.clients:
            n += 1
            name = f"{base}{n}"
        return name

    async def _ws(self, request: Any) -> Any:
        from aiohttp import WSMsgType, web

        from puppet.panel import layout as L

        role = request.query.get("role") or None
        if role is not None and role not in self.roles:
            raise web.HTTPBadRequest(text=f"unknown role {role!r}; known: {', '.join(sorted(self.roles)) or 'none'}\n")
        only = self.roles.get(role, []) if role else [p for p in request.query.get("only", "").split(",") if p.strip()]
        try:
            allowed = L.allowed_controls(self.vocab, only) if only else set(self._every)
        except Exception as err:
            raise web.HTTPBadRequest(text=f"bad channel list: {err}\n") from err
        # no per-message deflate: the face's frames are deflated once for every page already
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE, heartbeat=10.0, compress=False)
        await ws.prepare(request)
        name = self._client_name(request.query.get("name") or role)
        client = Client(name, f"{self._base()}/{name}", ws, allowed, only, role)
        self.clients[name] = client
        await ws.send_str(json.dumps({"t": "hello", "you": name, "device": client.device, "layout": self.layout,
                                      "allowed": sorted(allowed), "roles": sorted(self.roles)}))
        self.emit(StatusEvent(client.device, "connected", time.monotonic(), "page opened"))
        try:
            async for msg in ws:
                t = time.monotonic()
                if msg.type != WSMsgType.TEXT:
                    continue
                if msg.data.startswith('{"t":"ping"'):  # the server's clock too: the page measures its lag
                    await ws.send_str('{"t":"pong","s":%.6f}' % time.monotonic())
                    continue
                got = decode_input(msg.data, allowed)
                if got is None:
                    from puppet.panel.face import parse_face_message

                    want = parse_face_message(msg.data)  # the face shown or hidden on this page
                    if want is not None and want["t"] == "drawn":
                        self.face_feed.drawn(ws)
                    elif want is not None and want["t"] == "face":
                        client.face = want["on"]  # the broadcast sends the scene, then frames
                        if want["w"] is not None:  # the width the page shows the face at
                            self.face_feed.ask(ws, want["w"])
                        if not client.face:
                            self.face_feed.remove(ws)
                    else:
                        client.bad += 1
                    continue
                ctl, v = got
                self.received += 1
                client.own[ctl] = v
                kind = "axis" if ctl.startswith("slider:") else "button"
                self.emit(ControlEvent(client.device, ctl, kind, v if kind == "axis" else float(v > 0.5), None, v, t))
        finally:
            self.face_feed.remove(ws)
            self.clients.pop(name, None)
            self.emit(StatusEvent(client.device, "lost", time.monotonic(), "page closed"))
        return ws


def _start_editor(take: str) -> tuple[Any, str]:
    """`python -m puppet edit TAKE` in a child process; its URL, read from its first line. When it
    ends without serving, its own one-line reason (naming the take and what to do) is raised."""
    import os
    import subprocess
    import sys
    import tempfile

    from puppet.errors import PuppetError

    with tempfile.TemporaryFile("w+") as log:  # a file, not a pipe: a serving editor never blocks on it
        proc = subprocess.Popen([sys.executable, "-m", "puppet", "edit", os.path.abspath(take)],
                                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=log, text=True)
        assert proc.stdout is not None
        end = time.monotonic() + 60
        while time.monotonic() < end:
            line = proc.stdout.readline()
            if not line:
                break
            m = re.search(r"(http://\S+)", line)
            if m:
                return proc, m.group(1)
        proc.kill()
        proc.wait()
        log.seek(0)
        said = [ln[len("puppet: error: "):] for ln in log.read().splitlines() if ln.startswith("puppet: error: ")]
    if said:
        raise PuppetError(said[-1])
    raise PuppetError(f"the editor for {take} did not start (exit {proc.returncode}); "
                      f"run `puppet edit {take}` in a terminal to see why")


async def _no_icon(request: Any) -> Any:
    from aiohttp import web

    return web.Response(status=204)


def _copy(dq: Any) -> list[float]:
    for _ in range(5):
        try:
            return list(dq)
        except RuntimeError:  # appended to while copying
            continue
    return []


def _copy_items(d: dict[str, Any]) -> list[tuple[str, Any]]:
    for _ in range(5):
        try:
            return list(d.items())
        except RuntimeError:
            continue
    return []
