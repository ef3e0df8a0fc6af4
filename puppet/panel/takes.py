"""The page's take list: the take library searched from the browser, a take opened in the editor
or exported, each in a process of its own (the show's process only reads the library).

Routes (behind the page server's guard like every other route):
  GET  /api/takes?q=QUERY              takes matching the query (as `puppet takes search`), newest first
  GET  /api/takes/{id}/thumbnail       the take's PNG thumbnail
  POST /api/takes/{id}/edit            `puppet edit TAKE` started; answers its URL
  POST /api/takes/{id}/export?to=KIND  `puppet replay TAKE --out STEM.KIND` beside the take (mp4, pc2, csv)
  GET  /api/takes/exports              the exports started from this page, waiting, running or ended

Edit starts one editor per take (pressed again: the same one), at most MAX_EDITORS. Exports run one
at a time (each renders on every core already), up to MAX_WAITING more wait their turn, and past
that a request is answered busy (429). An export never replaces a file: when STEM.KIND (or a PC2's
STEM.obj) exists, it is written as STEM-2.KIND, STEM-3.KIND, ..."""

from __future__ import annotations

import asyncio
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aiohttp import web

from puppet.batch.plan import output_stem
from puppet.errors import PuppetError
from puppet.library.store import recording_alive

MAX_RESULTS = 200
MAX_WAITING = 4  # exports waiting behind the running one; past that a request is answered busy (429)
MAX_KEPT = 100  # exports remembered (the list the page polls shows the last 20)
MAX_EDITORS = 4  # `puppet edit` processes the page starts (each holds a face); past that: busy (429)
EXPORT_SUFFIXES = {"mp4": ".mp4", "pc2": ".pc2", "csv": ".csv"}


class TakeRoutes:
    """`library()` answers the library's path (or None: the library is off)."""

    def __init__(self, library: Callable[[], Path | None]) -> None:
        self.library = library
        self.exports: list[dict[str, Any]] = []  # newest last; state waiting, running, done or failed
        self._worker: asyncio.Task | None = None
        self._proc: subprocess.Popen | None = None
        self.editors: dict[str, tuple[subprocess.Popen, str]] = {}  # take's path -> its editor and URL
        self._starting: set[str] = set()

    def add(self, app: web.Application) -> None:
        app.router.add_get("/api/takes", self._list)
        app.router.add_get("/api/takes/exports", self._exports)
        app.router.add_get("/api/takes/{id:\\d+}/thumbnail", self._thumbnail)
        app.router.add_post("/api/takes/{id:\\d+}/edit", self._edit)
        app.router.add_post("/api/takes/{id:\\d+}/export", self._export)
        app.on_cleanup.append(self._cleanup)

    def _open(self) -> Any:
        from puppet.library.store import Library

        path = self.library()
        if path is None:
            raise web.HTTPNotFound(text="the take library is off\n")
        return Library(path, warn=lambda s: None)

    async def _run(self, fn: Callable[[], Any]) -> Any:
        return await asyncio.get_running_loop().run_in_executor(None, fn)

    def _take(self, take_id: int) -> dict[str, Any]:
        from puppet.errors import PuppetError

        with self._open() as lib:
            try:
                return lib.get(take_id)
            except PuppetError as err:
                raise web.HTTPNotFound(text=f"{err}\n") from err

    async def _list(self, request: web.Request) -> web.Response:
        from puppet.errors import PuppetError

        q = request.query.get("q", "")[:500]

        def find() -> list[dict[str, Any]]:
            from puppet.library import complete_died

            with self._open() as lib:
                complete_died(lib)
                rows = lib.search(q)
            rows.reverse()
            return [{"id": t["id"], "name": Path(t["path"]).name, "path": t["path"], "recorded": t["recorded"],
                     "duration": t["duration"], "performer": t["performer"], "tags": t["tags"], "notes": t["notes"],
                     "expressions": sorted({e["expression"] for e in t["expressions"]} - {"neutral"}),
                     "thumbnail": bool(t["thumbnail"]), "missing": bool(t["missing"]),
                     "state": t.get("state", "complete")} for t in rows[:MAX_RESULTS]]

        try:
            return web.json_response({"ok": True, "takes": await self._run(find)})
        except PuppetError as err:
            return web.json_response({"ok": False, "error": str(err)})

    async def _thumbnail(self, request: web.Request) -> web.Response:
        t = await self._run(lambda: self._take(int(request.match_info["id"])))
        if not t["thumbnail"]:
            raise web.HTTPNotFound(text="no thumbnail yet (puppet takes check makes them)\n")
        return web.Response(body=t["thumbnail"], content_type="image/png")

    async def _edit(self, request: web.Request) -> web.Response:
        from puppet.panel.device import _start_editor

        t = await self._run(lambda: self._take(int(request.match_info["id"])))
        if t["missing"] or not Path(t["path"]).is_file():
            return web.json_response({"ok": False, "error": f"{t['path']} is missing"})
        key = str(Path(t["path"]).resolve())
        self.editors = {k: v for k, v in self.editors.items() if v[0].poll() is None}
        if key in self.editors:  # the same take again: its editor, not a second one
            return web.json_response({"ok": True, "url": self.editors[key][1]})
        if key in self._starting:
            return web.json_response({"ok": False, "busy": True, "error": f"the editor for {Path(key).name} is "
                                      "starting; press edit again in a moment"}, status=429)
        if len(self.editors) + len(self._starting) >= MAX_EDITORS:
            return web.json_response({"ok": False, "busy": True, "error": f"{MAX_EDITORS} editors are open from "
                                      "this page already (they close when the show ends); edit one of their "
                                      "takes, or run `puppet edit TAKE` in a terminal"}, status=429)
        self._starting.add(key)
        try:
            proc, url = await self._run(lambda: _start_editor(t["path"]))
        except Exception as err:
            return web.json_response({"ok": False, "error": str(err)})
        finally:
            self._starting.discard(key)
        self.editors[key] = (proc, url)
        return web.json_response({"ok": True, "url": url})

    def argv(self, take: Path, out: Path) -> list[str]:
        """The command of one export: the single command's, in a process of its own."""
        return [sys.executable, "-m", "puppet", "replay", str(take), "--out", str(out)]

    def _pending(self) -> list[dict[str, Any]]:
        return [j for j in self.exports if j["state"] in ("waiting", "running")]

    async def _export(self, request: web.Request) -> web.Response:
        kind = request.query.get("to", "mp4")
        if kind not in EXPORT_SUFFIXES:
            return web.json_response({"ok": False, "error": f"export to one of {', '.join(EXPORT_SUFFIXES)}"})
        t = await self._run(lambda: self._take(int(request.match_info["id"])))
        take = Path(t["path"])
        if t["missing"] or not take.is_file():
            return web.json_response({"ok": False, "error": f"{take} is missing"})
        if t.get("state") == "recording" and await self._run(lambda: recording_alive(take, t.get("recorder"))):
            return web.json_response({"ok": False, "error": f"{take.name} is being recorded by a show; "
                                      "export it when the show ends"})
        pending = self._pending()
        same = next((j for j in pending if j["take"] == str(take) and j["kind"] == kind), None)
        if same is not None:  # a second click on the same button: the export already under way
            return web.json_response({"ok": True, "out": same["out"], "state": same["state"],
                                      "ahead": self._ahead(same)})
        if len(pending) > MAX_WAITING:
            return web.json_response({"ok": False, "busy": True,
                                      "error": f"{len(pending)} exports are running or waiting already (one runs at "
                                      "a time); try again when one has ended"}, status=429)
        from puppet.export.runner import unused_output

        try:
            out = unused_output(take.with_name(output_stem(take) + EXPORT_SUFFIXES[kind]),
                                [Path(j["out"]) for j in pending])
        except PuppetError as err:
            return web.json_response({"ok": False, "error": str(err)})
        job = {"id": t["id"], "take": str(take), "kind": kind, "out": str(out), "state": "waiting", "error": ""}
        self.exports.append(job)
        del self.exports[:-MAX_KEPT]
        if self._worker is None or self._worker.done():
            self._worker = asyncio.get_running_loop().create_task(self._work())
        ahead = self._ahead(job)  # none: the worker starts it now
        return web.json_response({"ok": True, "out": str(out), "state": "waiting" if ahead else "running",
                                  "ahead": ahead})

    def _ahead(self, job: dict[str, Any]) -> int:
        pending = self._pending()
        return pending.index(job) if job in pending else 0

    async def _work(self) -> None:
        """Runs the waiting exports one after the other (each renders on every core already)."""
        import tempfile

        from puppet.export.runner import unused_output

        while True:
            job = next((j for j in self.exports if j["state"] == "waiting"), None)
            if job is None:
                return
            take, out = Path(job["take"]), Path(job["out"])
            others = [Path(j["out"]) for j in self._pending() if j is not job]
            try:  # a file of that name may have appeared while the job waited
                out = unused_output(out, others)
            except PuppetError as err:
                job.update(state="failed", error=str(err))
                continue
            job.update(out=str(out), state="running")
            with tempfile.TemporaryFile("w+") as log:  # not a pipe: nothing blocks or breaks on it
                try:
                    proc = subprocess.Popen(self.argv(take, out), stdin=subprocess.DEVNULL,
                                            stdout=subprocess.DEVNULL, stderr=log, text=True)
                except OSError as err:
                    job.update(state="failed", error=f"cannot start the export: {err}")
                    continue
                self._proc = proc
                while proc.poll() is None:  # polled: no thread is left waiting on it at the show's end
                    await asyncio.sleep(0.1)
                self._proc = None
                log.seek(0)
                lines = log.read().strip().splitlines()
            ok = proc.returncode == 0
            job.update(state="done" if ok else "failed", error="" if ok else (lines or ["exit"])[-1][:300])

    async def _exports(self, request: web.Request) -> web.Response:
        return web.json_response({"ok": True, "exports": self.exports[-20:]})

    async def _cleanup(self, app: web.Application) -> None:
        """The running export goes on in its own process and writes its file when done; exports
        still waiting are not started (the show's terminal names them)."""
        if self._worker is not None:
            self._worker.cancel()
        dropped = [Path(j["out"]).name for j in self.exports if j["state"] == "waiting"]
        if dropped:
            print(f"puppet: the page's exports still waiting were not started: {', '.join(dropped)}", file=sys.stderr)
        for p, _ in self.editors.values():
            if p.poll() is None:
                p.terminate()
