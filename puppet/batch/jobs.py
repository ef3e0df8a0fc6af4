"""What a Dask worker runs: one function per kind of task. Each gets the input file's bytes (and
sidecars), writes them under a private temporary folder with the input's own file name, calls the
very function the single command calls (`puppet.export.runner.export`, `puppet fit`'s and `puppet
recognize`'s own functions) and returns the outputs as {file name: bytes}; the client writes them.
So a worker needs no shared folder, and an output equals the single command's byte for byte.

A long video is split: `mp4_checkpoints` simulates the take once and keeps the face's state at the
first frame of each chunk, `mp4_chunk` re-simulates from that state and renders its frames (the
renderer's raw rows, zlib-compressed), `mp4_join` feeds every frame in order to one encoder with
the single export's settings. Rendering runs in parallel; encoding once keeps the file identical
to a single export (independently encoded segments would start new groups of pictures)."""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import tempfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

#: compression of raw frames travelling from a chunk to the join (fast; the face's flat background
#: packs well)
ZLIB_LEVEL = 1
#: what a task returns for an output file it wrote in the client's own folder (not its bytes)
IN_PLACE = "in place"


class JobFailed(Exception):
    """A task's input could not be processed; the message names the user's file."""


#: the key of a task's result that holds the warnings the single command would have printed
WARNINGS = "warnings"


@contextlib.contextmanager
def _staged(files: dict[str, bytes], origin: str, notes: list[str] | None = None) -> Iterator[Path]:
    """The input files in a private folder; errors inside name `origin` instead of the copy, and
    the warnings printed inside go into `notes` (naming `origin` too)."""
    from puppet.batch import worker

    worker.install()  # faces and simulators kept between this process's tasks (idempotent)
    quiet = io.StringIO()  # one progress bar, the client's: the single commands' bars and lines go here
    with tempfile.TemporaryDirectory(prefix="puppet-batch-") as tmp, contextlib.redirect_stderr(quiet):
        first = None
        for name, data in files.items():
            p = Path(tmp) / name
            p.write_bytes(data)
            first = first or p
        assert first is not None
        try:
            yield first
            if notes is not None:
                notes += [line.replace(str(first), origin) for line in quiet.getvalue().splitlines()
                          if line.startswith("puppet: warning: ")]
        except JobFailed as err:
            raise JobFailed(str(err).replace(str(first), origin).replace(tmp + os.sep, "")) from None
        except Exception as err:
            from puppet.errors import PuppetError
            from safefile import BadFile

            text = str(err).replace(str(first), origin).replace(tmp + os.sep, "")
            if not isinstance(err, (PuppetError, BadFile, ValueError, OSError)):
                text = f"{type(err).__name__}: {text}"
            raise JobFailed(text) from None


def _performance(take: Path) -> Any:
    import sys

    from puppet.replay import build_performance
    from puppet.session import read_session

    session = read_session(take)
    perf = build_performance(session, None)
    if perf.ticks == 0:
        raise JobFailed(f"{take} holds no performance (its header only)")
    if session.warnings:
        print(f"puppet: warning: {session.warnings[0]}", file=sys.stderr)
    return perf


def _options(perf: Any, kind: str, opts: dict[str, Any]) -> Any:
    from puppet.export.runner import ExportOptions

    fps = opts.get("fps")
    if fps is None:
        fps = 30.0 if kind == "mp4" else perf.rate
    return ExportOptions(fps=fps, view=opts.get("view", "shaded"), size=tuple(opts.get("size", (1280, 720))),
                         supersample=opts.get("supersample", 1), crf=opts.get("crf"), parallel=False)


def export_take(files: dict[str, bytes], origin: str, outname: str, opts: dict[str, Any]) -> dict[str, bytes]:
    """One export of one take, as `puppet replay TAKE --out OUTNAME` writes it (render in this
    process: the cluster already keeps every core busy)."""
    return export_outputs(files, origin, [(outname, opts)])[outname]


def export_outputs(files: dict[str, bytes], origin: str, outputs: list[tuple[str, dict[str, Any]]],
                   dest: dict[str, str] | None = None) -> dict[str, dict[str, bytes | str]]:
    """Several exports of one take ({output name: {file name: bytes}}), each as `puppet replay TAKE
    --out NAME` writes it, the take simulated once for all of them (`export_together`), and under
    `WARNINGS` the warnings it would print (a take cut off by a crash). When this
    process sees the client's output folder (`plan.reachable(dest)`), the files are written in place
    (as `puppet replay --out` writes them) and only their names travel back (`IN_PLACE`)."""
    from puppet.batch.plan import reachable
    from puppet.export.runner import export_together, kind_of

    direct = reachable(dest)
    notes: list[str] = []
    with _staged(files, origin, notes) as take:
        perf = _performance(take)
        todo = []
        for outname, opts in outputs:
            if direct is not None:
                out = direct / outname
            else:
                folder = take.parent / "out" / str(len(todo))
                folder.mkdir(parents=True)
                out = folder / outname
            todo.append((out, _options(perf, kind_of(out), opts)))
        with contextlib.redirect_stdout(io.StringIO()):
            export_together(perf, todo)
        result: dict[str, dict[str, bytes | str]] = {}
        for out, _ in todo:
            made = [out] + ([out.with_suffix(".obj")] if kind_of(out) == "pc2" else [])
            if direct is None:
                result[out.name] = {p.name: p.read_bytes() for p in made}
            else:  # the client sees the same files
                result[out.name] = {p.name: IN_PLACE for p in made}
    if notes:
        result[WARNINGS] = notes  # type: ignore[assignment]  # no output's name (those have suffixes)
    return result


def mp4_frames(files: dict[str, bytes], origin: str, opts: dict[str, Any]) -> list[int]:
    """The tick shown by each frame of the take's video (what the single export renders)."""
    from puppet.replay import frame_ticks

    with _staged(files, origin) as take:
        perf = _performance(take)
        o = _options(perf, "mp4", opts)
        return frame_ticks(perf, o.fps, o.start, o.end, o.speed)


def mp4_checkpoints(files: dict[str, bytes], origin: str, ticks: list[int], starts: list[int]) -> list[Any]:
    """The face's state (sim.state.FaceState) after ticks[a] ticks for every chunk start a."""
    from puppet.replay import Replayer

    with _staged(files, origin) as take:
        rp = Replayer(_performance(take))
        out = []
        for a in starts:
            rp.seek(ticks[a])
            out.append(rp.state.copy())
        return out


def mp4_chunk(files: dict[str, bytes], origin: str, opts: dict[str, Any], ticks: list[int], a: int, b: int,
              checkpoints: list[Any], index: int) -> list[bytes]:
    """Frames a..b-1 rendered from the checkpoint at frame a: raw rows, zlib-compressed."""
    from puppet.export.video import FrameSink
    from puppet.replay import Replayer

    with _staged(files, origin) as take:
        perf = _performance(take)
        o = _options(perf, "mp4", opts)
        rp = Replayer(perf)
        rp.state.assign(checkpoints[index])
        rp.tick = ticks[a]
        sink = FrameSink(perf.face.model, take.parent / "unused.mp4", "mp4", o.fps, o.size, o.view,
                         supersample=o.supersample, encode=False)
        try:
            frames = []
            for j in range(a, b):
                rp.seek(ticks[j])
                frames.append(zlib.compress(sink.raw(rp.state), ZLIB_LEVEL))
        finally:
            sink.close()
        return frames


def mp4_join(outname: str, origin: str, opts: dict[str, Any], *chunks: list[bytes]) -> dict[str, bytes]:
    """Every chunk's frames, in order, through the single export's encoder and settings."""
    from puppet.export.video import DEFAULT_CRF, DEFAULT_PRESET, Encoder

    with tempfile.TemporaryDirectory(prefix="puppet-batch-") as tmp:
        out = Path(tmp) / outname
        fps = opts.get("fps") or 30.0
        crf = DEFAULT_CRF if opts.get("crf") is None else opts["crf"]
        try:
            enc = Encoder(out, fps, tuple(opts.get("size", (1280, 720))), DEFAULT_PRESET, crf)
        except Exception as err:
            raise JobFailed(f"{origin}: cannot encode the video: {err}") from None
        try:
            for chunk in chunks:
                for raw in chunk:
                    enc.add(zlib.decompress(raw))
        finally:
            enc.close()
        return {outname: out.read_bytes()}


def fit_capture(files: dict[str, bytes], origin: str, outname: str, opts: dict[str, Any]) -> dict[str, bytes]:
    """`puppet fit INPUT --out OUTNAME` (the command's own function), its summary in `.fit.txt`."""
    from puppet import cmd_fit

    with _staged(files, origin) as capture:
        out = capture.parent / "out" / outname
        out.parent.mkdir()
        args = _command_args(cmd_fit, "fit", [str(capture), "--out", str(out)], opts)
        text = io.StringIO()
        with contextlib.redirect_stdout(text):
            cmd_fit.run(args)
        # the take names its capture: the user's path, not this worker's copy
        here, there = (json.dumps(str(p))[1:-1].encode() for p in (capture.resolve(), origin))
        return {outname: out.read_bytes().replace(here, there)}


def _command_args(module: Any, name: str, argv: list[str], opts: dict[str, Any]) -> Any:
    """The arguments the single command would get from `puppet NAME ARGV` with the batch's options
    (--rig, --map, --fps, --face where given): its own parser, so its defaults are the same."""
    import argparse

    parser = argparse.ArgumentParser(prog="puppet")
    sub = parser.add_subparsers(dest="command")
    module.register(sub)
    known = {a.dest for a in sub.choices[name]._actions}
    for key in ("rig", "map", "fps", "face"):
        if opts.get(key) is not None and key in known:
            argv += [f"--{key}", str(opts[key])]
    return parser.parse_args([name, *argv])


def recognize_input(files: dict[str, bytes], origin: str, outname: str, opts: dict[str, Any]) -> dict[str, bytes]:
    """`puppet recognize INPUT --json`'s output, as a file."""
    from puppet import cmd_recognize

    with _staged(files, origin) as src:
        args = _command_args(cmd_recognize, "recognize", [str(src), "--json"], opts)
        text = io.StringIO()
        with contextlib.redirect_stdout(text):
            cmd_recognize.run(args)
        return {outname: text.getvalue().encode()}


@functools.lru_cache(maxsize=1)
def identity() -> tuple[str, str]:
    """(package version, digest of its sources): a farm must run the same program everywhere.
    Computed once per process: the program a process runs is the one it loaded."""
    import hashlib

    import puppet

    root = Path(puppet.__file__).resolve().parent.parent
    h = hashlib.sha256()
    for pkg in ("puppet", "sim", "render", "devices", "safefile"):
        for p in sorted((root / pkg).rglob("*.py")):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return puppet.__version__, h.hexdigest()[:16]
