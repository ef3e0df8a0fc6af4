"""The page's web server: aiohttp (HTTP and WebSocket in one well-kept dependency) on its own
asyncio loop in a thread, so the live loop never waits for a browser.

Security, for every request before any handler runs:
- bound to 127.0.0.1 unless told otherwise; the Host header must then name the loopback (a page on
  another site cannot reach us through a DNS name that resolves to 127.0.0.1);
- bound to anything else (the LAN), every request needs the random token, as `?token=` (the first
  page load; it is then kept in a same-site cookie) or that cookie; without it: 403, nothing served;
- a WebSocket or a POST whose Origin is not this server's own is refused (403), and so is any
  request a browser marks `Sec-Fetch-Site: cross-site` (another site embedding our images, scripts
  or API) except a plain navigation to the page;
- static files come from a fixed list of names shipped in the package (no path is ever joined);
  file parameters of the editor are checked by `safe_child`."""

from __future__ import annotations

import asyncio
import hmac
import os
import secrets
import threading
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import web

from puppet.errors import PuppetError
from puppet.panel.address import DEFAULT_PORT, is_loopback

COOKIE = "puppet_token"
STATIC_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css", ".svg": "image/svg+xml"}
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")


def static_files() -> dict[str, tuple[bytes, str]]:
    """Name -> (content, type) of every file in puppet/panel/static (read once)."""
    out = {}
    for p in resources.files("puppet.panel").joinpath("static").iterdir():
        suffix = Path(p.name).suffix
        if suffix in STATIC_TYPES:
            out[p.name] = (p.read_bytes(), STATIC_TYPES[suffix])
    return out


def safe_child(folder: Path, name: str, suffixes: tuple[str, ...]) -> Path:
    """`folder/name` for a plain file name with one of `suffixes`; ValueError for anything that
    could leave the folder (separators, `..`, absolute paths, NUL, a symlink pointing out)."""
    if (not isinstance(name, str) or not name or len(name) > 200 or "/" in name or "\\" in name
            or "\0" in name or name.startswith(".") or not name.endswith(suffixes)):
        raise ValueError(f"expected a plain file name ending in {' or '.join(suffixes)}, got {name!r}")
    folder = folder.resolve()
    path = (folder / name).resolve()
    if path.parent != folder:
        raise ValueError(f"{name!r} is outside the take folder")
    return path


class PanelServer:
    """Serves `index` (a static file name) at `/`, the static files, and the routes `setup(app)`
    adds. `start()` binds (DeviceError-free: a PuppetError naming the address if it cannot)."""

    def __init__(self, host: str, port: int, index: str, setup: Callable[[web.Application], None],
                 token: str | None = None, try_ports: int = 0, lan: bool | None = None) -> None:
        self.host, self.port, self.index, self.setup = host, port, index, setup
        self.lan = (not is_loopback(host)) if lan is None else lan
        self.token = token or (secrets.token_urlsafe(16) if self.lan else None)
        self.try_ports = try_ports
        self.loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._runner: web.AppRunner | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.files = static_files()
        self.refused = 0
        self.on_stop: list[Callable[[], Any]] = []

    # --- lifecycle -------------------------------------------------------------------------------
    def start(self) -> str:
        self._thread = threading.Thread(target=self._serve, name="panel server", daemon=True)
        self._thread.start()
        self._ready.wait(15)
        if self._error is not None:
            err = self._error
            raise PuppetError(f"cannot serve the page on {self.host}:{self.port}: {err}; "
                              "pick another port") from err
        return self.url

    @property
    def url(self) -> str:
        host = self.host.strip("[]")
        if host in ("0.0.0.0", "::"):
            host = _lan_address()
        elif host == "localhost":
            host = "127.0.0.1"
        if ":" in host:  # IPv6: bracketed in a URL
            host = f"[{host}]"
        q = f"?token={self.token}" if self.token else ""
        return f"http://{host}:{self.port}/{q}"

    def _serve(self) -> None:
        loop = asyncio.new_event_loop()
        self.loop = loop
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._bind())
        except BaseException as err:  # noqa: BLE001 - reported to start()
            self._error = err
            try:  # the app's startup tasks (the page's broadcast) end with it, silently
                if self._runner is not None:
                    loop.run_until_complete(self._runner.cleanup())
            except Exception:  # noqa: BLE001 - the bind error is what start() reports
                pass
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.run_until_complete(self._shutdown())
            loop.close()

    async def _bind(self) -> None:
        app = web.Application(middlewares=[self._guard], client_max_size=4 * 1024 * 1024)
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{name}", self._static)
        self.setup(app)
        self._runner = web.AppRunner(app, handle_signals=False, access_log=None)
        await self._runner.setup()
        last: OSError | None = None
        for port in range(self.port, self.port + 1 + self.try_ports):
            # SO_REUSEADDR on POSIX (asyncio's own default there): a show restarted after a crash
            # or a stop binds its port again although the pages' closed connections still hold it
            # in TIME_WAIT for a minute (without it a fixed --panel PORT failed 'address already in
            # use', and the default port moved to the next one, where the open pages never looked);
            # a port another program listens on is still refused on Linux and taken as busy
            # an IPv6 host is bound without the brackets of its spec and URL ('[::1]' was looked
            # up as a name: 'Name or service not known; pick another port')
            site = web.TCPSite(self._runner, self.host.strip("[]"), port, reuse_address=os.name == "posix")
            try:
                await site.start()
            except OSError as err:
                last = err
                continue
            server = getattr(site, "_server", None)
            if server is not None and server.sockets:
                self.port = server.sockets[0].getsockname()[1]
            return
        assert last is not None
        raise OSError(last.errno, last.strerror or str(last))

    async def _shutdown(self) -> None:
        for fn in self.on_stop:
            try:
                res = fn()
                if asyncio.iscoroutine(res):
                    await res
            except Exception:  # closing must not hide the outcome
                pass
        if self._runner is not None:
            await self._runner.cleanup()

    def stop(self) -> None:
        loop = self.loop
        if loop is not None and loop.is_running():
            loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5)
        self._thread = None

    def call(self, coro_fn: Callable[[], Any]) -> None:
        """Run `coro_fn()` on the server's loop from any thread (fire and forget)."""
        loop = self.loop
        if loop is not None and loop.is_running():
            asyncio.run_coroutine_threadsafe(coro_fn(), loop)

    # --- guard -----------------------------------------------------------------------------------
    def _allowed_host(self, host: str) -> bool:
        if self.lan:
            return True
        # the loopback names, and the address the page is served on (panel://127.0.0.2 served a
        # URL whose every request it refused: 'served to the loopback address only')
        served = self.url.split("/")[2]
        return host == served or host in {f"{h}:{self.port}" for h in LOOPBACK_NAMES}

    def _has_token(self, request: web.Request) -> bool:
        if self.token is None:
            return True
        given = request.query.get("token") or request.cookies.get(COOKIE) or ""
        return hmac.compare_digest(given.encode(), self.token.encode())

    @web.middleware
    async def _guard(self, request: web.Request, handler: Callable[[web.Request], Any]) -> web.StreamResponse:
        host = request.headers.get("Host", "")
        if not self._allowed_host(host):
            self.refused += 1
            return web.Response(status=403, text="puppet: this page is served to the loopback address only\n")
        if not self._has_token(request):
            self.refused += 1
            return web.Response(status=403, text="puppet: token required (use the URL printed by puppet)\n")
        if (request.headers.get("Sec-Fetch-Site") == "cross-site"
                and not (request.path == "/" and request.headers.get("Sec-Fetch-Mode") == "navigate")):
            self.refused += 1  # another site's page using ours as an image, script or API (browsers say so)
            return web.Response(status=403, text="puppet: cross-site request refused\n")
        origin = request.headers.get("Origin")
        if origin is not None and origin not in (f"http://{host}", f"https://{host}"):
            if request.headers.get("Upgrade", "").lower() == "websocket" or request.method != "GET":
                self.refused += 1
                return web.Response(status=403, text="puppet: foreign origin refused\n")
        response = await handler(request)
        if self.token is not None and request.query.get("token"):
            response.set_cookie(COOKIE, self.token, httponly=True, samesite="Strict")
        response.headers.setdefault("Cache-Control", "no-store")
        response.headers.setdefault("X-Content-Type-Options", "nosniff")
        response.headers.setdefault("X-Frame-Options", "DENY")
        return response

    async def _index(self, request: web.Request) -> web.StreamResponse:
        body, ctype = self.files[self.index]
        return web.Response(body=body, content_type=ctype, charset="utf-8" if ctype.startswith("text") else None)

    async def _static(self, request: web.Request) -> web.StreamResponse:
        item = self.files.get(request.match_info["name"])
        if item is None:
            raise web.HTTPNotFound(text="no such file\n")
        body, ctype = item
        return web.Response(body=body, content_type=ctype)


def _lan_address() -> str:
    """This machine's address on the LAN (the one a route to the outside would use), for the URL."""
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.connect(("10.255.255.255", 1))  # no packet is sent by a UDP connect
        return str(s.getsockname()[0])
    except OSError:
        return "127.0.0.1"
    finally:
        s.close()


def qr_text(url: str) -> str:
    """The URL as a QR code in terminal characters (segno), or '' when segno is missing."""
    try:
        import io

        import segno
    except ImportError:
        return ""
    buf = io.StringIO()
    segno.make(url, error="l").terminal(out=buf, compact=True)
    return buf.getvalue()
