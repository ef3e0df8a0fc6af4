"""Session recordings: JSON Lines, one record per line, written as the performance happens.

Line 1 is the header (format, version, program, rig identity and hash, channel list, tick rate,
mapping text, start time). Then, in tick order:
  {"t": "ev",  "tick": k, "dev", "ctl", "kind", "value", "delta", "raw", "time"}  raw device events
  {"t": "st",  "tick": k, "dev", "status", "detail"}                            device came/went
  {"t": "v",   "tick": k, "v": {channel: value, ...}}  channel values applied to sim step k, changes only
  {"t": "mark","tick": k, "label"}                                                a marker
  {"t": "chk", "tick": k, "sha"}  digest of the positions after k ticks (replay verifies it)
  {"t": "sync","tick": k}     ticks < k are complete (after a tick that wrote no "v" record)
  {"t": "seg", "tick": k, "reason"}  the program restarted here (a crash): the face restarts from
                              rest at tick k, the channel values carry on; the take goes on
  {"t": "end", "ticks": n}    clean end: n ticks were simulated
Floats are written with repr (what `json` does), the shortest text that reads back to the same
double, so a replay feeds the simulator bit-identical values. No pickle, nothing executable.
A writer is a context manager. Every tick's records reach the operating system when the tick is done
(one write: a killed process loses at most the tick in progress) and a small thread makes them
durable about once a second (fsync: a power cut loses at most the last second); neither is on the
tick's critical path. A reader accepts a file cut by a crash and returns everything up to the last
complete record, with a warning."""

from __future__ import annotations

import fcntl
import json
import math
import os
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from devices.events import ControlEvent, StatusEvent
from puppet.errors import ConfigError

FORMAT = "facepuppet-session"
VERSION = 1
#: the recording is made durable (fsync) this often, by a thread of its own: with the fsync itself
#: and the tick in progress, a power cut then loses less than a second
FSYNC_SECONDS = 0.9


def _json(obj: dict[str, Any]) -> str:
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def _number(x: object) -> str | None:
    """`_json`'s text for a plain int, a finite float or None; None for anything else (which
    `_json` then encodes, or refuses as it always did)."""
    t = type(x)
    if t is float:
        return float.__repr__(x) if math.isfinite(x) else None  # type: ignore[arg-type]
    if t is int:
        return int.__repr__(x)  # type: ignore[arg-type]
    return "null" if x is None else None


class _Syncer:
    """Makes a recording durable about every `interval` seconds (os.fsync releases the GIL, so the
    loop thread never waits for the disk). `log` keeps (time the fsync returned, bytes it covers,
    ticks those bytes hold) for the last hour, to measure what a power cut would lose."""

    def __init__(self, writer: SessionWriter, interval: float) -> None:
        from collections import deque

        self.writer, self.interval = writer, interval
        self.log: deque[tuple[float, int, int]] = deque(maxlen=4000)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="recording-fsync", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            self.sync_now()

    def sync_now(self) -> None:
        w = self.writer
        with w._lock:
            if w._file is None:
                return
            ticks = w._on_os_ticks  # read before the size: the bytes hold at least these ticks
            try:
                fd = w._file.fileno()
                size = os.fstat(fd).st_size
                os.fsync(fd)
            except (OSError, ValueError):
                return  # a failing disk is reported by the writes themselves
        self.log.append((time.monotonic(), size, ticks))

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=10)


def lock_probe(path: Path) -> str | None:
    """What the recording lock on `path` says: "held" (a show records to it), "free", "unsupported"
    (a file system where flock does nothing), or None when the file cannot be opened. Probed with a
    shared lock, released at once, so two probes never see each other."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return "held"
    except OSError:
        return "unsupported"
    finally:
        os.close(fd)  # releases the lock just taken
    return "free"


def _being_recorded(path: Path) -> bool:
    """Whether a show holds the recording lock on `path` (SessionWriter takes it for the show)."""
    return lock_probe(path) == "held"


def _open_locked(path: Path, append_to: int | None) -> IO[str]:
    """The take opened for writing under an exclusive lock held until it closes, so that a second
    show given the same file is refused before it truncates or moves the first one's take."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise ConfigError(f"{path}: another show is recording to it; choose another --record name") from None
    except OSError:
        pass  # a file system without locks: written as before
    try:
        os.ftruncate(fd, 0 if append_to is None else append_to)
        fh = os.fdopen(fd, "r+", encoding="utf-8", newline="\n")
    except BaseException:
        os.close(fd)
        raise
    fh.seek(0 if append_to is None else append_to)
    return fh


def _aside(p: Path, n: int) -> Path:
    """`NAME.n.jsonl` beside `p`, NAME cut (in bytes, on a character boundary) when the name would
    pass the file system's limit: a take named near 255 bytes is kept aside like any other."""
    from safefile import fitting_stem

    tail = f".{n}{p.suffix}"
    return p.with_name(fitting_stem(p.parent, p.stem, len(os.fsencode(tail))) + tail)


#: what a show writes beside its take `NAME.jsonl`, named after it: the sound of its first audio
#: input, the last frame of a show without a display, the demo's video
COMPANIONS = (".wav", ".png", ".mp4")


def _companions(p: Path) -> list[str]:
    """The suffixes of the files beside the take `p` that belong to it (`NAME.wav`, ...): the
    first sound and the show's pictures, and every further sound its header names (`NAME.2.wav`)."""
    found = [c for c in COMPANIONS if p.with_suffix(c).is_file()]
    try:
        with open(p, "rb") as fh:
            head = json.loads(fh.readline(1 << 20))
        for entry in head.get("audio", [])[1:]:
            name = entry.get("file") if isinstance(entry, dict) else None
            if isinstance(name, str) and name.startswith(p.stem + ".") and name.endswith(".wav") \
                    and "/" not in name and (p.parent / name).is_file():
                found.append(name[len(p.stem):])
    except (OSError, ValueError, AttributeError, TypeError):
        pass  # a damaged take: its first sound and pictures still go with it
    return found


def keep_previous(path: str | Path, companions: bool = False) -> Path | None:
    """Before a new take is written to `path`, move a take already there aside (to the first free
    `NAME.1.jsonl`, `NAME.2.jsonl`, ...) so that starting a show never destroys an earlier one;
    returns where it went, or None when there was nothing to keep. `companions`: the files the
    take's show wrote beside it (`NAME.wav`, `NAME.png`, `NAME.mp4`) go with it (`NAME.1.wav`...),
    so the new show's do not take their place: the kept take's sound was the new take's."""
    p = Path(path)
    try:
        if p.stat().st_size == 0:
            return None
    except OSError:
        return None
    if _being_recorded(p):
        raise ConfigError(f"{p}: another show is recording to it; choose another --record name")
    tails = _companions(p) if companions else []
    for n in range(1, 10_000):
        kept = _aside(p, n)
        beside = [(p.with_name(p.stem + t), kept.with_name(kept.stem + t)) for t in tails]
        if not os.path.lexists(kept) and not any(os.path.lexists(b) for _, b in beside):
            try:
                os.link(p, kept)  # never replaces a file that appeared meanwhile
            except FileExistsError:
                continue
            except OSError as err:
                raise ConfigError(f"{p}: a take is already there and cannot be kept aside "
                                  f"({err.strerror}); choose another --record name") from err
            p.unlink()
            for a, b in beside:
                try:
                    os.link(a, b)
                    a.unlink()
                except OSError:
                    pass  # left where it was: the new show's file of that name is written beside it
            return kept
    raise ConfigError(f"{p}: a take is already there and {p.stem}.1..9999{p.suffix} are all taken; "
                      "choose another --record name")


class SessionWriter:
    """Writes one recording. Call `event`, `values`, `marker` as ticks happen and `tick(k)` once
    per tick (the tick's records then go to the operating system in one write); `close(n)` writes
    the end record.

    With `defer = True` (what the live loop sets) those calls only keep what they were given, and
    the JSON is made and written by `service()`, which the loop calls after the frame is published:
    no serialisation on the critical path. The file is the same, record for record; `flush` and
    `close` write whatever is kept first, so a `sync` still covers every record of the ticks before
    it. A `sync` record is written after a tick only when no `v` record already says it is done.

    `fsync_seconds` (None: never, until close) sets how often a thread makes the file durable.
    `append_to` (a byte offset) continues an existing recording cut at that offset instead of
    starting a new one: the header is not written again (see `puppet.resume`)."""

    def __init__(self, path: str | Path, header: dict[str, Any], *, clock: Callable[[], float] = time.monotonic,
                 fsync_seconds: float | None = FSYNC_SECONDS,
                 append_to: int | None = None) -> None:
        self.path = Path(path)
        self._clock = clock
        self.channels: list[str] = list(header["channels"])
        # the records' fixed parts as `_json` writes them: each channel's key in a "v" record, and
        # each (device, control, kind)'s fields of an "ev" record (made once: the live loop writes
        # a record per event and per tick)
        self._keys = [_json({c: 0})[1:-2] for c in self.channels] if len(set(self.channels)) == len(self.channels) else None
        self._ev_fields: dict[tuple[str, str, str], str] = {}
        self._lock = threading.Lock()
        try:
            self._file: IO[str] | None = _open_locked(self.path, append_to)
        except OSError as err:
            raise ConfigError(f"{self.path}: cannot write the recording: {err.strerror}") from err
        full = {"t": "header", "format": FORMAT, "version": VERSION, **header}
        self._last: np.ndarray | None = None
        self.error: OSError | None = None
        self._done_ticks = 0
        self._covered = 0  # ticks < this are known done from `v` records already written
        self._on_os_ticks = 0  # ticks whose records the OS has (written and flushed)
        self.defer = False
        self._kept: list[tuple[Any, ...]] = []
        self._behind: Any = None  # write_behind's queue, once started
        self._behind_thread: threading.Thread | None = None
        self._handed = self._written = 0  # hand-overs to the writer's thread, and those it has written
        self._written_cv = threading.Condition()
        if append_to is None:
            self._write(full)
        self.flush()
        self.syncer = _Syncer(self, fsync_seconds) if fsync_seconds else None

    def resume_at(self, ticks: int, last_values: np.ndarray) -> None:
        """Continue after `ticks` complete ticks whose last channel values were `last_values`."""
        self._done_ticks = self._covered = self._on_os_ticks = ticks
        self._last = np.array(last_values, dtype=np.float64, copy=True)

    def _write(self, rec: dict[str, Any]) -> None:
        self._write_line(_json(rec))

    def _write_line(self, line: str) -> None:
        if self._file is not None:
            try:
                self._file.write(line + "\n")
            except OSError as err:
                self._fail(err)

    def _fail(self, err: OSError) -> None:
        """Disk full or gone: stop recording, keep what is on disk, and let the show go on."""
        import sys

        self.error = err
        print(f"puppet: warning: recording to {self.path} stopped: {err.strerror or err}; "
              f"the part written so far is readable", file=sys.stderr)
        with self._lock:
            try:
                if self._file is not None:
                    self._file.close()
            except OSError:
                pass
            self._file = None

    def event(self, tick: int, ev: ControlEvent | StatusEvent, t0: float = 0.0) -> None:
        """A raw device event applied at tick boundary `tick`; `time` is relative to t0."""
        if self.defer:
            self._kept.append((self._event, tick, ev, t0))
            return
        self._event(tick, ev, t0)

    def _event(self, tick: int, ev: ControlEvent | StatusEvent, t0: float) -> None:
        if isinstance(ev, StatusEvent):
            self._write({"t": "st", "tick": tick, "dev": ev.device, "status": ev.status, "detail": ev.detail})
            return
        raw = ev.raw if isinstance(ev.raw, (int, float, str)) or ev.raw is None else repr(ev.raw)
        value, when = float(ev.value), ev.t - t0
        parts = (_number(tick), _number(value), _number(ev.delta), _number(raw), _number(when))
        key = (ev.device, ev.control, ev.kind)
        fields = self._ev_fields.get(key)
        if None in parts or fields is None or len(self._ev_fields) > 4096:
            # the same text by `_json` (and its errors for what it refuses); the fields kept for later
            rec = {"t": "ev", "tick": tick, "dev": ev.device, "ctl": ev.control, "kind": ev.kind,
                   "value": value, "delta": ev.delta, "raw": raw, "time": when}
            if fields is None and len(self._ev_fields) <= 4096 and all(type(x) is str for x in key):
                self._ev_fields[key] = _json({"dev": ev.device, "ctl": ev.control, "kind": ev.kind})[1:-1]
            self._write(rec)
            return
        k, v, d, r, w = parts
        self._write_line(f'{{"t":"ev","tick":{k},{fields},"value":{v},"delta":{d},"raw":{r},"time":{w}}}')

    def values(self, tick: int, values: np.ndarray) -> None:
        """Channel values applied to sim step `tick`; only the ones that changed are written."""
        if self.defer:
            self._kept.append((self._values, tick, values.copy()))
            return
        self._values(tick, values)

    def _values(self, tick: int, values: np.ndarray) -> None:
        if self._last is None:
            changed = range(len(values))
        else:
            changed = np.flatnonzero(values != self._last).tolist()
        if len(changed):
            keys = self._keys
            floats = [float(values[i]) for i in changed]
            if keys is not None and type(tick) is int and all(map(math.isfinite, floats)):  # `_json`'s text
                self._write_line(f'{{"t":"v","tick":{tick},"v":{{'
                                 + ",".join([keys[i] + float.__repr__(f) for i, f in zip(changed, floats)]) + "}}")
            else:
                self._write({"t": "v", "tick": tick, "v": {self.channels[i]: float(values[i]) for i in changed}})
            self._covered = max(self._covered, tick + 1)
        self._last = values.copy()

    def marker(self, tick: int, label: str) -> None:
        if self.defer:
            self._kept.append((self._marker, tick, label))
            return
        self._marker(tick, label)

    def _marker(self, tick: int, label: str) -> None:
        self._write({"t": "mark", "tick": tick, "label": label})

    def segment(self, tick: int, reason: str) -> None:
        """A new segment of the same take starts at `tick` (the program restarted after a crash):
        replay restarts the face from rest here, as the live loop did."""
        self._write({"t": "seg", "tick": tick, "reason": reason})

    def check(self, tick: int, digest: str | Callable[[], str]) -> None:
        """A digest of the simulated positions after `tick` ticks, for replay to verify (or a
        function that computes it, called when the record is written)."""
        if self.defer:
            self._kept.append((self._check, tick, digest))
            return
        self._check(tick, digest)

    def _check(self, tick: int, digest: str | Callable[[], str]) -> None:
        self._write({"t": "chk", "tick": tick, "sha": digest if isinstance(digest, str) else digest()})

    def tick(self, done_ticks: int) -> None:
        """`done_ticks` ticks are complete; their records go to the OS now (deferred: at the next
        `service()`)."""
        self._done_ticks = done_ticks
        if not self.defer:
            self.service()

    def service(self) -> None:
        """Write what was kept and hand it to the OS (one write per tick, no fsync); after
        `write_behind`, hand it to the writer's thread, which does that."""
        if self._behind is not None:
            self._hand_over(None)
            return
        self.flush()

    def _hand_over(self, written: threading.Event | None) -> None:
        """What was kept, to the writer's thread, once it has written the last hand-over: the
        records it has not written are at most one tick's (a crash loses at most a tick), and the
        loop waits only while the file holds the writer back for longer than a tick."""
        if threading.current_thread() is not self._behind_thread:
            with self._written_cv:
                self._written_cv.wait_for(lambda: self._written >= self._handed)
        kept, self._kept = self._kept, []
        self._handed += 1
        self._behind.put((kept, self._done_ticks, written))

    def write_behind(self) -> None:
        """From now on (defer mode) `service()` hands what was kept to a thread of the writer's own,
        which makes the JSON and writes it, so the calling thread (the live loop) waits on the file
        only when the previous tick's records are not written yet (`_hand_over`): an append to a file waits for the file system's journal, which an fsync of the same
        file (the durability thread) holds for as long as the disk takes (measured: a 51 ms gap
        between ticks, the loop in the write, under other programs' disk load). `flush` and `close`
        wait for the thread. Records, their order and the file are the same."""
        if self._behind is not None or self._file is None:
            return
        import queue

        self._behind = queue.SimpleQueue()
        self._behind_thread = threading.Thread(target=self._write_behind, name="recording-writer", daemon=True)
        self._behind_thread.start()

    def _write_behind(self) -> None:
        while True:
            item = self._behind.get()
            if item is None:
                return
            kept, done, written = item
            try:
                for fn, *args in kept:
                    fn(*args)
                self._to_os(done)
            except Exception as err:  # noqa: BLE001 - the show goes on; the warning says what was not recorded
                import sys

                print(f"puppet: warning: {self.path}: a record could not be written ({err})", file=sys.stderr)
            finally:
                with self._written_cv:
                    self._written += 1
                    self._written_cv.notify_all()
                if written is not None:
                    written.set()

    def _stop_behind(self) -> None:
        if self._behind is None:
            return
        self._hand_over(None)
        self._behind.put(None)
        if self._behind_thread is not None and self._behind_thread is not threading.current_thread():
            self._behind_thread.join()
        self._behind = self._behind_thread = None

    def _write_kept(self) -> None:
        kept, self._kept = self._kept, []
        for fn, *args in kept:
            fn(*args)

    def flush(self) -> None:
        if self._behind is not None:  # the writer's thread writes, in order; wait for it
            written = threading.Event()
            self._hand_over(written)
            written.wait()
            return
        if self._kept:
            self._write_kept()
        self._to_os(self._done_ticks)

    def _to_os(self, done: int) -> None:
        """A `sync` record for `done` ticks unless already covered, then the file's buffer to the OS."""
        if self._file is None:
            return
        if done > self._covered:
            self._write({"t": "sync", "tick": done})
            self._covered = done
        try:
            if self._file is not None:
                self._file.flush()
                self._on_os_ticks = done
        except OSError as err:
            self._fail(err)

    def close(self, ticks: int | None = None) -> None:
        """Write the end record, flush and fsync. Idempotent."""
        if self.syncer is not None:
            self.syncer.stop()
        self._stop_behind()
        if self._kept:
            self._write_kept()
        if self._file is None:
            return
        n = self._done_ticks if ticks is None else ticks
        self._write({"t": "end", "ticks": n})
        if self._file is None:
            return
        try:
            self._file.flush()
            os.fsync(self._file.fileno())
        except OSError:
            pass
        try:
            self._file.close()
        except OSError:
            pass
        self._file = None

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class Session:
    """A recording read back. `values` holds tick -> {channel index: value} (changes only)."""

    path: Path
    header: dict[str, Any]
    channels: list[str]
    tick_rate: float
    ticks: int
    values: dict[int, dict[int, float]] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    markers: list[tuple[int, str]] = field(default_factory=list)
    checks: dict[int, str] = field(default_factory=dict)
    segments: list[int] = field(default_factory=list)  # ticks where a restart began a segment
    complete: bool = True
    warnings: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return self.ticks / self.tick_rate

    def iter_values(self, defaults: np.ndarray, names: list[str] | None = None) -> Iterator[np.ndarray]:
        """Full channel arrays for ticks 0..ticks-1, starting from `defaults`; with `names`
        (the live face's channel order) values are placed by name."""
        order = self._order(names)
        cur = np.array(defaults, dtype=np.float64, copy=True)
        for k in range(self.ticks):
            ch = self.values.get(k)
            if ch:
                for i, v in ch.items():
                    j = order[i]
                    if j >= 0:
                        cur[j] = v
            yield cur.copy()

    def value_array(self, defaults: np.ndarray, names: list[str] | None = None) -> np.ndarray:
        """(ticks, C) array of every tick's channel values."""
        out = np.empty((self.ticks, len(defaults)), dtype=np.float64)
        for k, row in enumerate(self.iter_values(defaults, names)):
            out[k] = row
        return out

    def _order(self, names: list[str] | None) -> list[int]:
        if names is None:
            return list(range(len(self.channels)))
        pos = {n: j for j, n in enumerate(names)}
        return [pos.get(n, -1) for n in self.channels]


def read_session(path: str | Path) -> Session:
    """Read a recording, checked at the boundary (see puppet.session_reader). A file cut short
    (crash, SIGKILL) reads up to its last complete record and gets a warning in
    `session.warnings`; a file that is not a recording is a ConfigError."""
    from puppet.session_reader import read_session as read

    return read(path)
