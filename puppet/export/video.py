"""Rendered exports (MP4, PNG frames, a still) and a second process that renders and encodes while
this one simulates: the simulation of every tick and the software rasterizer each take a core,
so overlapping them is what makes long exports faster than real time on a CPU-only machine."""

from __future__ import annotations

import os
import queue as _queue
import struct
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from puppet.errors import PuppetError

PARALLEL_MIN_FRAMES = 90  # below this the render processes' start-up costs more than they save
AHEAD_FRAMES = 16  # states queued per render process (~20 KB each at the default face)
#: H.264 settings: x264's fastest preset; CRF 20 looks clean on the face at 720p (a 20 s take is a
#: few MB) and costs a third less encoding time than `veryfast` at CRF 15 did
DEFAULT_PRESET = "ultrafast"
DEFAULT_CRF = 20


def render_workers() -> int:
    """Render processes for a long export: one per core (the software rasterizer is the slow part;
    the simulation in this process and the encoder fill the gaps), at least 1, at most 4."""
    return max(1, min(4, os.cpu_count() or 1))


class Encoder:
    """H.264 by ffmpeg (imageio-ffmpeg's binary), fed the renderer's raw rows bottom-up (ffmpeg
    flips them, so no copy is made here). ffmpeg's log goes to a scratch file and its exit status
    is checked: a video ffmpeg could not finish (a full disk at the trailer, ffmpeg killed) is an
    error, never a cut file renamed over the user's old one."""

    def __init__(self, out: Path, fps: float, size: tuple[int, int], preset: str = DEFAULT_PRESET,
                 crf: int = DEFAULT_CRF) -> None:
        import subprocess
        import tempfile
        from fractions import Fraction

        import imageio_ffmpeg

        vf = "vflip" if size[0] % 2 == 0 and size[1] % 2 == 0 else "vflip,pad=ceil(iw/2)*2:ceil(ih/2)*2"
        cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-f", "rawvideo", "-vcodec", "rawvideo",
               "-s", f"{int(size[0]):d}x{int(size[1]):d}", "-pix_fmt", "rgb24",
               "-r", str(Fraction(float(fps)).limit_denominator()), "-i", "-", "-an",
               "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-v", "error",
               "-preset", preset, "-crf", str(int(crf)), "-vf", vf, str(out)]
        self.out = out
        self._log = tempfile.TemporaryFile()
        # its own session: a Ctrl-C reaches this process, which closes the encoder
        self._proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self._log,
                                      start_new_session=True)
        self._failed = False

    def add(self, raw: bytes | memoryview) -> None:
        assert self._proc.stdin is not None
        try:
            self._proc.stdin.write(raw)
        except OSError as err:
            self._failed = True
            raise PuppetError(self._failure(err)) from err

    def close(self) -> None:
        """Ends the video; raises if ffmpeg did not finish it (unless the failure was raised already)."""
        proc = self._proc
        if proc.stdin is not None and not proc.stdin.closed:
            try:
                proc.stdin.close()
            except OSError:
                self._failed = True
        code = proc.wait()
        failed, self._failed = self._failed, True  # a second close reports nothing
        if code != 0 and not failed:
            raise PuppetError(self._failure(None))

    def abort(self) -> None:
        """Ends the encoder without a video (an export interrupted or failed: its file is thrown
        away): ffmpeg is killed, not waited for. Waiting let a Ctrl-C or SIGTERM hang for as long
        as ffmpeg took to take in frames it had not read, forever if it had stopped reading."""
        self._failed = True
        proc = self._proc
        try:
            proc.kill()
        except OSError:
            pass
        proc.wait()
        if proc.stdin is not None:
            try:
                proc.stdin.close()
            except (OSError, ValueError):  # the frame half written when the export stopped
                pass

    def _failure(self, err: BaseException | None) -> str:
        """One line: ffmpeg's last words, or what stopped it."""
        import signal

        try:
            code = self._proc.wait(timeout=10)
        except Exception:  # noqa: BLE001 - still running: its pipe broke for another reason
            code = None
        self._log.seek(0)
        said = [ln.strip() for ln in self._log.read()[-4096:].decode("utf-8", "replace").splitlines() if ln.strip()]
        reason = said[-1] if said else (str(err).splitlines()[0] if err is not None else f"ffmpeg ended with {code}")
        if code is not None and code < 0:
            reason = (os.strerror(27) if -code == getattr(signal, "SIGXFSZ", -1)  # EFBIG: the file size limit
                      else f"the encoder was stopped by signal {-code}")
        return encoder_failure(self.out, reason)


def encoder_failure(out: Path, reason: str | BaseException) -> str:
    """One line for an encoder that stopped. A full disk shows there as a broken pipe or a muxer's
    complaint: the free room of the output's disk is checked and named instead."""
    text = (str(reason).strip().splitlines() or [type(reason).__name__])[0]
    try:
        st = os.statvfs(Path(out).parent if str(Path(out).parent) else ".")
        if st.f_bavail * st.f_frsize < 4 * 1024 * 1024:
            text = os.strerror(28)  # ENOSPC
    except OSError:
        pass
    return f"{out}: cannot write: {text}"


class FrameSink:
    """An offscreen renderer plus the file writer for one export."""

    def __init__(self, model: Any, out: Path, kind: str, fps: float, size: tuple[int, int], view: str,
                 supersample: int = 1, preset: str = DEFAULT_PRESET, crf: int = DEFAULT_CRF,
                 encode: bool = True, pipelined: bool = True) -> None:
        try:
            from render.offscreen import OffscreenRenderer, save_image
        except ImportError as err:
            raise PuppetError(f"video and image export need the renderer: {err}") from err
        self._save = save_image
        try:
            self.renderer = OffscreenRenderer(model, size, view=view, supersample=supersample)
        except ValueError as err:
            raise PuppetError(str(err)) from err
        except Exception as err:  # no EGL / GL: one clear line, not a traceback
            raise PuppetError(f"cannot create an offscreen OpenGL context: {err}") from err
        self.out, self.kind, self.size = out, kind, size
        # pipelined (render.pipeline): a frame is written at the next `add` (or `finish`), its CPU
        # half and the writing of the frame before it made while llvmpipe rasterises it
        self.frames = self.renderer.stream(pipelined)
        self.writer: Encoder | None = None
        try:
            if kind == "mp4" and encode:
                self.writer = Encoder(out, fps, size, preset, crf)
            elif kind == "frames":
                out.mkdir(parents=True, exist_ok=True)
        except Exception as err:
            self.renderer.release()
            raise PuppetError(f"{out}: cannot write: {err}") from err

    def raw(self, state: Any) -> bytes:
        """The frame's RGB rows as the renderer left them (bottom row first), read back."""
        off = self.renderer
        off.fbo.use()
        off.fbo.viewport = (0, 0, *off.size)
        off.renderer.draw(state, hud=None, record=True)
        return off.fbo.read(components=3, alignment=1)

    def add(self, j: int, state: Any) -> None:
        """Draw frame `j`; write it (pipelined: write the frame added before it)."""
        for k, raw in self.frames.push(state, None, j):
            self._write(k, raw)

    def finish(self) -> None:
        """Write the frame still being drawn (after the last `add`)."""
        for k, raw in self.frames.finish():
            self._write(k, raw)

    def _write(self, j: int, raw: bytes) -> None:
        if self.kind == "mp4":
            assert self.writer is not None
            self.writer.add(raw)
            return
        from render.pipeline import image

        img = image(raw, self.renderer.size)
        self._save(img, self.out if self.kind == "png" else self.out / f"frame_{j:06d}.png")

    def close(self, abort: bool = False) -> None:
        """Release the renderer and close the file (a frame still drawn and not `finish`ed is dropped);
        `abort`: the export stopped, its video is thrown away (the encoder killed, not waited for)."""
        try:
            if self.writer is not None:
                writer, self.writer = self.writer, None
                if abort:
                    writer.abort()
                else:
                    writer.close()
        finally:
            self.renderer.release()

    def exit(self, exc_type: Any, exc: Any, tb: Any) -> None:
        """`close` as an ExitStack exit callback: aborted when the stack unwinds with an exception."""
        self.close(abort=exc_type is not None)


FRAME_HEAD = struct.Struct("<iI")  # frame number (-1 ends), payload bytes


class RenderModel:
    """What the renderer reads of a face model (its rig, mesh, rest positions and triangles), rebuilt
    in a render process from the face's rig file (sim.rig: npz + JSON, read without pickle)."""

    def __init__(self, rig: Any, scan_rest: str | None = None) -> None:
        self.rig = rig
        self.scan_dressing: Any = None
        if scan_rest:  # the scanned head at rest: each frame brings the posed scan (RenderFrame)
            self.scan_dressing = _ScanRest(np.load(scan_rest, allow_pickle=False))
        self.mesh = rig.mesh
        self.rest = np.asarray(rig.mesh.vertices, np.float64)
        self.triangles = np.asarray(rig.mesh.triangles, np.int32)


class _ScanRest:
    """A render process's stand-in for the scan dressing: the rest scan the look is baked from;
    the posed scan arrives with every frame (`RenderFrame.scan_rows`)."""

    def __init__(self, rest: np.ndarray) -> None:
        self.rest = rest

    def pose(self, surface: np.ndarray, control: Any) -> np.ndarray:
        raise RuntimeError("a render process draws the scan rows it is sent")


class RenderFrame:
    """What a render process draws: the surface as the renderer's float32 rows x y z nx ny nz
    (`interleaved`: the mask's rows, then the held head's if the face has one; made by the
    simulating process with the renderer's own rows (render.meshdata.SurfaceRows), so the
    frames equal a serial export's bit for bit and the render process never loads numba), plus the
    state's scalars."""

    def __init__(self, interleaved: np.ndarray, time: float, eye_yaw: float, eye_pitch: float,
                 age: float, jaw: float = 0.0, scan_rows: np.ndarray | None = None,
                 head: tuple[float, float, float] = (0.0, 0.0, 0.0), eye_vergence: float = 0.0) -> None:
        self.interleaved = interleaved
        self.surface = interleaved[:, :3]
        self.positions = self.surface
        self.time, self.eye_yaw, self.eye_pitch, self.age = time, eye_yaw, eye_pitch, age
        self.jaw = jaw
        self.scan_rows = scan_rows  # the scanned head posed, as render.scan_look.ScanRows makes them
        self.head_yaw, self.head_pitch, self.head_roll = head
        self.eye_vergence = eye_vergence


_SCALARS = struct.Struct("<9d")  # time, eye yaw, eye pitch, age, jaw, head yaw, pitch, roll, eye vergence


def _pack(j: int, state: Any, normals: Any, scan: Any = None) -> bytes:
    """One frame for a render process: its number, then the interleaved rows (the head turned on
    the neck; and the scanned head's rows, posed here by `scan`, a render.scan_draw.ScanPoser) and
    the scalars."""
    from render.meshdata import head_turn

    turn = head_turn(state)
    rows = normals.interleaved(np.ascontiguousarray(state.surface, dtype=np.float32), turn)
    extra = b"" if scan is None else scan.rows(state).astype("<f4", copy=False).tobytes()
    body = rows.astype("<f4", copy=False).tobytes() + extra + _SCALARS.pack(
        state.time, state.eye_yaw, state.eye_pitch, state.age, getattr(state, "jaw", 0.0), *turn,
        getattr(state, "eye_vergence", 0.0))
    return FRAME_HEAD.pack(j, len(body)) + body


def _unpack_state(body: bytes, n_scan: int = 0) -> RenderFrame:
    data = np.frombuffer(body[:-_SCALARS.size], dtype="<f4")
    scan = data[len(data) - 7 * n_scan:].reshape(-1, 7) if n_scan else None
    rows = data[:len(data) - 7 * n_scan].reshape(-1, 6)
    t, yaw, pitch, age, jaw, *head, verge = _SCALARS.unpack(body[-_SCALARS.size:])
    return RenderFrame(rows, t, yaw, pitch, age, jaw, scan, (head[0], head[1], head[2]), verge)


def _read_exact(f: Any, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = f.read(n - len(buf))
        if not chunk:
            break
        buf += chunk
    return bytes(buf)


def worker_main() -> int:
    """A render process (`python -c ...worker_main()`): a fresh interpreter, so it never shares an
    OpenGL context with its parent nor re-runs the parent's command. Reads the face from the rig
    file named in its configuration (argv[1], JSON), then frames (RenderFrame rows) on stdin;
    answers on stdout with binary records FRAME_HEAD(j, n) + n bytes: the raw frame for a video (the
    parent encodes, in order), nothing for files it saved itself; j = -2 is an error message, j = -1
    the end."""
    import json
    import sys

    cfg = json.loads(sys.argv[1])
    out = sys.stdout.buffer
    inp = sys.stdin.buffer

    def send(j: int, payload: bytes = b"") -> None:
        out.write(FRAME_HEAD.pack(j, len(payload)))
        if payload:
            out.write(payload)
        out.flush()

    try:
        from sim.rig import load_rig

        model = RenderModel(load_rig(cfg["rig"]), cfg.get("scan_rest"))
        sink = FrameSink(model, Path(cfg["out"]), cfg["kind"], cfg["fps"], tuple(cfg["size"]), cfg["view"],
                         supersample=cfg.get("supersample", 1), encode=False, pipelined=False)
    except Exception as err:  # reported to the parent as one message
        send(-2, f"{type(err).__name__}: {err}".encode())
        return 1
    try:
        while True:
            head = _read_exact(inp, FRAME_HEAD.size)
            if len(head) < FRAME_HEAD.size:
                break
            j, n = FRAME_HEAD.unpack(head)
            if j < 0:
                break
            n_scan = 0 if model.scan_dressing is None else len(model.scan_dressing.rest)
            state = _unpack_state(_read_exact(inp, n), n_scan)
            if sink.kind == "mp4":
                send(j, sink.raw(state))
            else:
                sink.add(j, state)
                send(j)
        sink.close()
        send(-1)
        return 0
    except BrokenPipeError:
        return 1
    except OSError as err:  # writing a frame (a full disk): the folder's name, not the exception's
        send(-2, f"{cfg['out']}: cannot write: {err.strerror or err}".encode())
        return 1
    except Exception as err:
        send(-2, f"{type(err).__name__}: {err}".encode())
        return 1


def render_serial(model: Any, out: Path, kind: str, fps: float, size: tuple[int, int], view: str,
                  frames: Iterable[tuple[int, Any]], progress: Callable[[int], None], supersample: int = 1,
                  preset: str = DEFAULT_PRESET, crf: int = DEFAULT_CRF) -> None:
    sink = FrameSink(model, out, kind, fps, size, view, supersample, preset, crf)
    try:
        for j, state in frames:
            sink.add(j, state)
            progress(1)
        sink.finish()
    except BaseException:
        sink.close(abort=True)
        raise
    sink.close()


class _Worker:
    """One render process with a feeding thread (states in) and a reading thread (frames out)."""

    def __init__(self, cfg: str, results: "_queue.Queue[tuple[int, bytes | None]]",
                 env: dict[str, str] | None = None) -> None:
        import subprocess
        import sys
        import threading

        self.proc = subprocess.Popen(
            [sys.executable, "-c", "import sys; from puppet.export.video import worker_main; sys.exit(worker_main())",
             cfg], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)
        self.outbox: _queue.Queue[bytes | None] = _queue.Queue(maxsize=AHEAD_FRAMES)
        self.results = results
        self._feed = threading.Thread(target=self._write, name="render-feed", daemon=True)
        self._read_t = threading.Thread(target=self._read, name="render-read", daemon=True)
        self._feed.start()
        self._read_t.start()

    def _write(self) -> None:
        stdin = self.proc.stdin
        assert stdin is not None
        try:
            while (chunk := self.outbox.get()) is not None:
                stdin.write(chunk)
            stdin.write(FRAME_HEAD.pack(-1, 0))
            stdin.close()
        except (BrokenPipeError, OSError):
            pass  # the worker died; its reason arrives on stdout

    def _read(self) -> None:
        stdout = self.proc.stdout
        assert stdout is not None
        while True:
            head = _read_exact(stdout, FRAME_HEAD.size)
            if len(head) < FRAME_HEAD.size:
                self.results.put((-3, b"the render process ended early"))
                return
            j, n = FRAME_HEAD.unpack(head)
            body = _read_exact(stdout, n) if n else b""
            self.results.put((j, body))
            if j < 0:
                return

    def put(self, chunk: bytes | None, alive: Callable[[], None]) -> None:
        while True:
            try:
                self.outbox.put(chunk, timeout=0.2)
                return
            except _queue.Full:
                alive()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(5)


def render_parallel(model: Any, out: Path, kind: str, fps: float, size: tuple[int, int], view: str,
                    frames: Iterable[tuple[int, Any]], progress: Callable[[int], None], supersample: int = 1,
                    preset: str = DEFAULT_PRESET, crf: int = DEFAULT_CRF, workers: int | None = None) -> None:
    """Simulate here, render in `workers` processes (frame j goes to worker j mod N), encode here in
    frame order (a thread feeds ffmpeg, which runs as its own process). The workers read the face
    from its rig file (written to a private temporary folder: what the renderer needs is the rig's
    mesh and muscles, not the compiled dynamics); after that only the renderer's vertex rows go
    out and raw frames come back."""
    import json
    import tempfile
    import threading

    from sim.rig import save_rig

    n = workers or render_workers()
    if view == "trails":
        n = 1  # the trails are drawn from the frames one renderer has seen: all of them, in order
    if kind == "frames":
        out.mkdir(parents=True, exist_ok=True)
    scratch = tempfile.TemporaryDirectory(prefix="puppet-export-")
    rig_path = Path(scratch.name) / "face.npz"
    from render.scan_draw import dressing_of

    dressing = dressing_of(model)  # the scanned head: frames carry the posed scan's rows
    try:
        save_rig(model.rig, rig_path)
        if dressing is not None:
            np.save(Path(scratch.name) / "scan_rest.npy", np.asarray(dressing.rest, np.float32))
    except OSError as err:
        scratch.cleanup()
        raise PuppetError(f"cannot write the face for the render processes to {rig_path}: {err}") from err
    cfg = json.dumps({"out": str(out), "kind": kind, "fps": fps, "size": list(size), "view": view,
                      "supersample": supersample, "rig": str(rig_path),
                      "scan_rest": str(Path(scratch.name) / "scan_rest.npy") if dressing is not None else None})
    results: _queue.Queue[tuple[int, bytes | None]] = _queue.Queue()
    env = None
    if n > 1 and "LP_NUM_THREADS" not in os.environ:
        # the processes already share the cores: one rasterizer thread each (llvmpipe would start one
        # per core in every process, which only adds hand-offs); a user's LP_NUM_THREADS wins
        env = {**os.environ, "LP_NUM_THREADS": "1"}
    pool: list[_Worker] = []
    try:
        for _ in range(n):
            pool.append(_Worker(cfg, results, env))
    except OSError as err:
        for w in pool:
            w.stop()
        scratch.cleanup()
        raise PuppetError(f"cannot start a render process: {err}") from err
    encoder: Encoder | None = None
    state = {"error": None, "done": 0, "ended": 0}

    def check() -> None:
        if state["error"]:
            raise PuppetError(f"rendering failed: {state['error']}")

    def collect() -> None:
        """Results thread: frames back into order and into the encoder; progress counts."""
        pending: dict[int, bytes] = {}
        nxt = 0
        try:
            while state["ended"] < n:
                j, body = results.get()
                if j == -1:
                    state["ended"] += 1
                    continue
                if j < -1:
                    state["error"] = (body or b"").decode("utf-8", "replace")
                    return
                if encoder is None:
                    state["done"] += 1
                    continue
                pending[j] = body or b""
                while nxt in pending:
                    encoder.add(pending.pop(nxt))
                    nxt += 1
                    state["done"] += 1
        except Exception as err:  # the encoder failed (disk full, ffmpeg gone)
            state["error"] = str(err) if isinstance(err, PuppetError) else encoder_failure(out, err)

    try:
        if kind == "mp4":
            try:
                encoder = Encoder(out, fps, size, preset, crf)
            except Exception as err:
                raise PuppetError(f"{out}: cannot write: {err}") from err
        collector = threading.Thread(target=collect, name="render-collect", daemon=True)
        collector.start()
        shown = 0

        def alive() -> None:
            nonlocal shown
            check()
            if state["done"] > shown:
                progress(state["done"] - shown)
                shown = state["done"]

        from render.meshdata import surface_rows

        normals = surface_rows(model)  # the renderer's, for its rows (the held head's included)
        poser = None
        if dressing is not None:
            from render.scan_draw import ScanPoser

            poser = ScanPoser(dressing)
        for j, st in frames:
            pool[j % n].put(_pack(j, st, normals, poser), alive)
            alive()
        for w in pool:
            w.put(None, alive)
        while collector.is_alive():
            collector.join(0.1)
            alive()
        check()
        alive()
        if encoder is not None:
            encoder.close()
            encoder = None
        for w in pool:
            w.proc.wait(30)
    finally:
        for w in pool:
            w.stop()
        if encoder is not None:  # not closed above: the export stopped (an error, Ctrl-C, SIGTERM)
            try:
                encoder.abort()
            except Exception:  # the real error is already on its way
                pass
        scratch.cleanup()
