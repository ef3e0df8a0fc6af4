"""`puppet edit TAKE.jsonl`: the force-graph editor's server side.

The page edits curves layered over the take (puppet.curves, version 2); the take is only read.
Every file the page names is a plain name inside the take's folder (`safe_child`): curves are
saved there (written beside and renamed into place), exports go there. The preview is the edited
performance re-simulated (puppet.replay.Replayer, checkpoints every second, so scrubbing back is
cheap) and drawn offscreen in one render thread that owns the GL context."""

from __future__ import annotations

import asyncio
import hashlib
import json
import math
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from puppet.curves import INTERPS, MODES, Curve, CurveLayer, CurveSet, format_curves, load_curves, parse_curves, save_text
from puppet.errors import ConfigError, PuppetError

PREVIEW_SIZE = (480, 360)
EXPORT_SUFFIXES = (".mp4", ".pc2", ".csv")
MAX_BODY_KEYS = 500_000


def take_digest(path: Path) -> str:
    return hashlib.sha1(path.read_bytes()).hexdigest()[:16]


def _finite(x: int | float) -> bool:
    """A finite number; an integer past floats (309+ digits) is not one (math.isfinite raised
    OverflowError: the page's save answered 500 with a traceback on the editor's terminal)."""
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def curves_from_json(data: Any, take: tuple[str, str] | None) -> CurveSet:
    """The page's curves (`[{target, interp, mode, keys: [[t, v, seg?], ...]}, ...]`), checked
    like a file: ValueError with what is wrong."""
    if not isinstance(data, list) or len(data) > 5000:
        raise ValueError("expected a list of at most 5000 curves")
    out, total = [], 0
    for i, c in enumerate(data):
        if not isinstance(c, dict):
            raise ValueError(f"curve {i}: expected an object")
        target, interp, mode, keys = c.get("target"), c.get("interp", "linear"), c.get("mode", "replace"), c.get("keys")
        if not isinstance(target, str) or not target or len(target) > 80 or any(ch.isspace() or ch == "#" for ch in target):
            raise ValueError(f"curve {i}: expected a target name")
        if interp not in INTERPS or mode not in MODES:
            raise ValueError(f"curve {i}: interp must be one of {INTERPS}, mode one of {MODES}")
        if not isinstance(keys, list) or not keys:
            raise ValueError(f"curve {i} ({target}): expected a non-empty list of keys")
        total += len(keys)
        if total > MAX_BODY_KEYS:
            raise ValueError(f"more than {MAX_BODY_KEYS} keys")
        ts, vs, segs = [], [], []
        for k in keys:
            if not isinstance(k, list) or len(k) not in (2, 3):
                raise ValueError(f"curve {i} ({target}): a key is [time, value] or [time, value, segment]")
            t, v = k[0], k[1]
            if isinstance(t, bool) or isinstance(v, bool) or not isinstance(t, (int, float)) or not isinstance(v, (int, float)):
                raise ValueError(f"curve {i} ({target}): key times and values are numbers")
            if not (_finite(t) and _finite(v)) or t < 0 or t > 1e6:
                raise ValueError(f"curve {i} ({target}): key times are finite seconds >= 0, values finite")
            seg = k[2] if len(k) == 3 else interp
            if seg not in INTERPS:
                raise ValueError(f"curve {i} ({target}): segment must be one of {INTERPS}")
            ts.append(round(float(t), 6))
            vs.append(float(v))
            segs.append(seg)
        if any(b < a for a, b in zip(ts, ts[1:])):
            raise ValueError(f"curve {i} ({target}): keys must be in time order")
        out.append(Curve(target, interp, mode, np.array(ts), np.array(vs), i + 1,
                         None if all(s == interp for s in segs) else segs))
    return CurveSet(out, "<page>", 2, take)


def curves_to_json(cs: CurveSet) -> list[dict[str, Any]]:
    return [{"target": c.target, "interp": c.interp, "mode": c.mode,
             "keys": [[float(t), float(v), c.segs[k] if c.segs else c.interp]
                      for k, (t, v) in enumerate(zip(c.times, c.values))]} for c in cs.curves]


class Editor:
    """One take open for editing: its recorded values, the current curves, the preview."""

    def __init__(self, take: str | Path, curves: str | Path | None = None, rig: str | None = None,
                 boxes: Any = None) -> None:
        from puppet.replay import build_performance
        from puppet.session import read_session

        self.take = Path(take).resolve()
        self.folder = self.take.parent
        self.session = read_session(self.take)
        if self.session.ticks < 1:  # its export was an IndexError traceback (a 500 on the page)
            raise ConfigError(f"{self.take} holds no performance (its header only: the show stopped before its "
                              "first tick, or has not written one yet); nothing to edit: record it again, or "
                              "edit it once the show has run a moment")
        self.digest = take_digest(self.take)
        self.base = build_performance(self.session, None, rig)
        self.face = self.base.face
        self.names = [c.name for c in self.face.vocab.channels]
        self.curves_name = (Path(curves).name if curves else self.take.stem + ".curves")
        self.curves = CurveSet([], "<none>", 2, (self.take.name, self.digest))
        path = self.folder / self.curves_name
        if curves is not None or path.exists():
            self.curves = load_curves(Path(curves) if curves else path)
            CurveLayer(self.curves, self.face.vocab)  # unknown targets: the file's line
        self.boxes = boxes  # a puppet.panel.boxes.BoxFeed, or None
        self._perf: Any = None
        self._replayer: Any = None
        self._renderer: Any = None
        self._pic_renderer: Any = None  # the preview's pictures, at the size the page shows them
        self._stream: Any = None  # render.stream.FaceStream of the preview (the page draws it)
        # the preview as the mesh (the page draws it) unless set to "picture" (rendered here): the
        # preview's thread also owns the performance and the saves, and a render there (the first one
        # seconds, with its context) would hold a save or a scrub behind it; one page, frames on demand
        self.face_mode = "mesh"
        self.render_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="preview")
        self.work_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="export")
        self.exporting: Path | None = None  # the export under way (the page's export runs one at a time)

    # --- state -----------------------------------------------------------------------------------
    def take_json(self) -> dict[str, Any]:
        v = self.base.values
        vocab = self.face.vocab
        moving = {n: [round(float(x), 6) for x in v[:, j]] for j, n in enumerate(self.names)
                  if v.shape[0] and not np.all(v[:, j] == v[0, j])}
        return {"take": self.take.name, "digest": self.digest, "rate": self.base.rate, "ticks": self.base.ticks,
                "channels": [{"name": c.name, "lo": c.lo, "hi": c.hi, "default": c.default} for c in vocab.channels],
                "first": [float(x) for x in (v[0] if v.shape[0] else vocab.defaults())],
                "values": moving, "markers": [[k / self.base.rate, label] for k, label in self.base.markers],
                "aus": sorted(a for a in vocab.aus if a[2:].isdigit()), "expressions": sorted(vocab.expressions),
                "targets": {t: [[i, w] for i, w in vocab.resolve(t).channels] for t in
                            [*sorted(a for a in vocab.aus if a[2:].isdigit()), *(f"expr:{e}" for e in sorted(vocab.expressions))]},
                "curves": curves_to_json(self.curves), "curves_name": self.curves_name,
                "boxes": [] if self.boxes is None else [d.spec for d in self.boxes.devs]}

    def set_curves(self, data: Any) -> None:
        cs = curves_from_json(data, (self.take.name, self.digest))
        text = format_curves(cs)
        parsed = parse_curves(text, "<page>")  # the same checks as a file, on the text that is saved
        try:
            CurveLayer(parsed, self.face.vocab)
        except ConfigError as err:
            raise ValueError(str(err).replace("<page>:", "curve ")) from err
        self.curves = parsed
        self._perf = None

    def performance(self) -> Any:
        if self._perf is None:
            from puppet.replay import Performance, Replayer

            p = self.base
            values = p.values
            if self.curves.curves:
                layer = CurveLayer(self.curves, self.face.vocab)
                values = np.array([layer.apply(values[k], k / p.rate) for k in range(values.shape[0])])
            old, old_rp = getattr(self, "_last_perf", None), self._replayer
            self._perf = Performance(self.face, values, p.rate, p.markers, p.checks if not self.curves.curves else {},
                                     restarts=p.restarts, muscles_summed=p.muscles_summed,
                                     lids_follow_gaze=p.lids_follow_gaze, lids_apart=p.lids_apart,
                                     jaw_responses=p.jaw_responses,
                                     bending_turned=p.bending_turned, symmetric_solve=p.symmetric_solve,
                                     single_responses=p.single_responses,
                                     constants_from_grid=p.constants_from_grid, gaze_tissue=p.gaze_tissue)
            self._replayer = Replayer(self._perf)
            if old is not None and old_rp is not None and old.values.shape == values.shape:
                # states before the first tick the edit changed are still right: keep their checkpoints
                differs = np.flatnonzero(np.any(old.values != values, axis=1))
                first = int(differs[0]) if len(differs) else values.shape[0]
                self._replayer.checkpoints.update({k: st for k, st in old_rp.checkpoints.items() if k <= first})
            self._last_perf = self._perf
        return self._perf

    def _seek(self, k: int) -> Any:
        """The replayer at tick k, starting from the latest checkpoint at or before k."""
        rp = self._replayer
        base = max(t for t in rp.checkpoints if t <= k)
        if base > rp.tick or k < rp.tick:
            rp.state.assign(rp.checkpoints[base])
            rp.tick = base
        rp.seek(k)
        return rp

    def save(self, name: str | None = None) -> Path:
        from puppet.panel.server import safe_child

        path = safe_child(self.folder, name or self.curves_name, (".curves",))
        note = (f"layered over {self.take.name} by puppet edit; play with:\n"
                f"puppet replay {self.take.name} --curves {path.name}")
        save_text(path, format_curves(self.curves, note))
        self.curves_name = path.name
        return path

    # --- preview and export (worker threads) -----------------------------------------------------
    def _frame(self, t: float, view: str) -> bytes:
        import io

        from PIL import Image

        perf = self.performance()
        if self._renderer is None:
            from render.offscreen import OffscreenRenderer

            self._renderer = OffscreenRenderer(self.face.model, PREVIEW_SIZE)
        rp = self._seek(int(round(min(max(t, 0.0), perf.duration) * perf.rate)))
        self._renderer.view = view
        img = self._renderer.render_frame(rp.state)
        buf = io.BytesIO()
        Image.fromarray(img).save(buf, format="PNG", compress_level=1)
        return buf.getvalue()

    def face_scene(self) -> bytes:
        """The preview's scene for the page's face view (render.stream), made once; none (b"") when
        the preview goes as pictures."""
        if self.face_mode == "picture":
            return b""
        if self._stream is None:
            from render.stream import FaceStream

            self._stream = FaceStream(self.face.model, "preview")
        return bytes(self._stream.scene())

    def face_frame(self, t: float, width: float | None = None) -> bytes:
        """The edited performance at `t` seconds as a frame of the page's face view (as a picture:
        of the size for a view `width` device pixels wide, render.stream.picture_size)."""
        import time

        perf = self.performance()
        k = int(round(min(max(t, 0.0), perf.duration) * perf.rate))
        if self.face_mode == "picture":
            from render.stream import picture, picture_size

            size = PREVIEW_SIZE if width is None else picture_size(width)
            if self._pic_renderer is None or self._pic_renderer.size != size:
                from render.offscreen import OffscreenRenderer

                if self._pic_renderer is not None:
                    self._pic_renderer.release()
                self._pic_renderer = OffscreenRenderer(self.face.model, size)
            state = self._seek(k).state
            return picture(self._pic_renderer.render_frame(state), "preview", k, time.monotonic(), size)
        rp = self._seek(k)
        self.face_scene()
        return bytes(self._stream.frame(rp.state, k, time.monotonic()))

    def export_path(self, name: Any) -> Path:
        """Where an export asked for as `name` goes: a plain name in the take's folder, never a file
        that exists (`NAME-2.mp4`, `NAME-3.mp4`, ... instead)."""
        from puppet.export.runner import unused_output
        from puppet.panel.server import safe_child

        path = safe_child(self.folder, name, EXPORT_SUFFIXES)
        if path == self.take:
            raise ValueError("the take itself is never written")
        return unused_output(path)

    def _export(self, path: Path, perf: Any) -> str:
        from puppet.export.runner import ExportOptions, export

        kind_video = path.suffix == ".mp4"
        return export(perf, path, ExportOptions(fps=30.0 if kind_video else self.base.rate))

    def close(self) -> None:
        def release() -> None:
            for name in ("_renderer", "_pic_renderer"):
                r = getattr(self, name)
                if r is not None:
                    r.release()
                    setattr(self, name, None)

        try:
            self.render_pool.submit(release).result(10)
        except Exception:
            pass
        self.render_pool.shutdown(wait=False)
        self.work_pool.shutdown(wait=False)

    # --- routes ----------------------------------------------------------------------------------
    def routes(self, app: Any, prefix: str = "") -> None:
        from aiohttp import web

        async def take(request: web.Request) -> web.Response:
            return web.json_response(self.take_json())

        async def post_curves(request: web.Request) -> web.Response:
            try:
                body = await _json_body(request)
                if not isinstance(body, dict):
                    raise ValueError("expected an object")
                await asyncio.get_running_loop().run_in_executor(self.render_pool, self.set_curves, body.get("curves"))
                saved = None
                if body.get("save"):
                    saved = self.save(body.get("name")).name
            except (ValueError, TypeError, ConfigError) as err:
                return web.json_response({"ok": False, "error": str(err)}, status=400)
            return web.json_response({"ok": True, "saved": saved})

        async def frame(request: web.Request) -> web.Response:
            try:
                t = float(request.query.get("t", "0"))
                if not math.isfinite(t):
                    raise ValueError
            except ValueError:
                return web.Response(status=400, text="t must be seconds\n")
            view = request.query.get("view", "shaded")
            if view not in ("shaded", "wireframe", "muscles", "heat"):
                view = "shaded"
            png = await asyncio.get_running_loop().run_in_executor(self.render_pool, self._frame, t, view)
            return web.Response(body=png, content_type="image/png")

        async def do_export(request: web.Request) -> web.Response:
            # one export at a time (it renders on every core); another is answered busy, not queued
            # behind it where a script's requests would pile up
            if self.exporting is not None:
                return web.json_response({"ok": False, "busy": True, "error": f"{self.exporting.name} is being "
                                          "exported; export again when it is done"}, status=429)
            try:
                body = await _json_body(request)
                path = self.export_path(body.get("name") if isinstance(body, dict) else None)
                self.exporting = path
                loop = asyncio.get_running_loop()
                perf = await loop.run_in_executor(self.render_pool, self.performance)  # the pool that owns it
                msg = await loop.run_in_executor(self.work_pool, self._export, path, perf)
            except (ValueError, TypeError, PuppetError) as err:
                return web.json_response({"ok": False, "error": str(err)}, status=400)
            finally:
                self.exporting = None
            return web.json_response({"ok": True, "message": msg, "out": path.name})

        async def box_ws(request: web.Request) -> web.WebSocketResponse:
            ws = web.WebSocketResponse(max_msg_size=4096, heartbeat=10.0)
            await ws.prepare(request)
            try:
                while not ws.closed and self.boxes is not None:
                    await ws.send_str(json.dumps(self.boxes.state(), separators=(",", ":")))
                    await asyncio.sleep(1 / 60)
            except (ConnectionError, RuntimeError):
                pass
            return ws

        async def face_ws(request: web.Request) -> web.WebSocketResponse:
            """The preview as the live page's face view: the scene once, then a frame for each time
            the page asks for (`{"t":"at","time":s}`); only the latest wish is served, so scrubbing
            never queues up behind the re-simulation."""
            from puppet.panel.face import parse_face_message

            ws = web.WebSocketResponse(max_msg_size=4096, heartbeat=10.0, compress=False)
            await ws.prepare(request)
            loop = asyncio.get_running_loop()
            wish: dict[str, float | None] = {"time": None, "w": None}
            wake = asyncio.Event()

            async def serve() -> None:
                scene = await loop.run_in_executor(self.render_pool, self.face_scene)
                if scene:
                    await ws.send_bytes(scene)
                while not ws.closed:
                    await wake.wait()
                    wake.clear()
                    t, wish["time"] = wish["time"], None
                    if t is not None:
                        await ws.send_bytes(await loop.run_in_executor(self.render_pool, self.face_frame, t, wish["w"]))

            task = loop.create_task(serve())
            try:
                async for msg in ws:
                    want = parse_face_message(msg.data) if msg.type == web.WSMsgType.TEXT else None
                    if want is not None and want["t"] == "at":
                        wish["time"], wish["w"] = want["time"], want["w"]
                        wake.set()
            finally:
                task.cancel()
            return ws

        app.router.add_get(prefix + "/ws", box_ws)
        app.router.add_get(prefix + "/ws/face", face_ws)
        app.router.add_get(prefix + "/api/take", take)
        app.router.add_post(prefix + "/api/curves", post_curves)
        app.router.add_get(prefix + "/api/frame", frame)
        app.router.add_post(prefix + "/api/export", do_export)
        async def no_icon(request: web.Request) -> web.Response:
            return web.Response(status=204)

        app.router.add_get(prefix + "/favicon.ico", no_icon)


async def _json_body(request: Any) -> Any:
    """A request's JSON body with bounded nesting (safefile.load_json); a body nested thousands
    deep was json's RecursionError: a 500 and a traceback on the editor's terminal. Every way a
    body is unusable is a ValueError (the routes answer 400 with it)."""
    from safefile import load_json

    return load_json(await request.text(), "the request", "request")
