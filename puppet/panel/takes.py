"""The page's take list: the take library searched from the browser, a take opened in the editor
or exported, each in a process of its own (the show's process only reads the library).

Routes (behind the page server's guard like every other route):
  GET  /api/takes?q=QUERY              takes matching the query (as `puppet takes search`), newest first
  GET  /api/takes/{id}/thumbnail       the take's PNG thumbnail
  POST /api/takes/{id}/edit            `puppet edit TAKE` started; answers its URL
  POST /api/takes/{id}/export?to=KIND  `puppet replay TAKE --out STEM.KIND` beside the take (mp4, pc2, csv)
  GET  /api/takes/exports              the exports started from this page and how they ended"""

from __future__ import annotations

import asyncio
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aiohttp import web

from puppet.batch.plan import output_stem
from puppet.library.store import recording_alive

MAX_RESULTS = 200
EXPORT_SUFFIXES = {"mp4": ".mp4", "pc2": ".pc2", "csv": ".csv"}


class TakeRoutes:
    """`library()` answers the library's path (or None: the library is off)."""

    def __init__(self, library: Callable[[], Path | None]) -> None:
        self.library = library
        self.exports: list[dict[str, Any]] = []
        self._procs: list[tuple[dict[str, Any], subprocess.Popen]] = []
        self.editors: list[subprocess.Popen] = []

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
        try:
            proc, url = await self._run(lambda: _start_editor(t["path"]))
        except Exception as err:
            return web.json_response({"ok": False, "error": str(err)})
        self.editors.append(proc)
        return web.json_response({"ok": True, "url": url})

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
        out = take.with_name(output_stem(take) + EXPORT_SUFFIXES[kind])
        job = {"id": t["id"], "out": str(out), "state": "running", "error": ""}
        proc = subprocess.Popen([sys.executable, "-m", "puppet", "replay", str(take), "--out", str(out)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.exports.append(job)
        self._procs.append((job, proc))
        return web.json_response({"ok": True, "out": str(out)})

    async def _exports(self, request: web.Request) -> web.Response:
        for job, proc in list(self._procs):
            if proc.poll() is None:
                continue
            err = proc.stderr.read() if proc.stderr else ""
            job["state"] = "done" if proc.returncode == 0 else "failed"
            job["error"] = "" if proc.returncode == 0 else (err.strip().splitlines() or ["exit"])[-1][:300]
            self._procs.remove((job, proc))
        return web.json_response({"ok": True, "exports": self.exports[-20:]})

    async def _cleanup(self, app: web.Application) -> None:
        for p in self.editors:
            if p.poll() is None:
                p.terminate()
