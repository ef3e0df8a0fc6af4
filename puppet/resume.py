"""Continuing a take after a crash: `puppet live --resume --record FILE` (what `--supervise` runs
after a crash, and what a systemd unit can run) appends a new segment to FILE instead of starting
a new recording.

The new segment begins with a `seg` record at the first tick not in the file, then a marker. The
face restarts from rest there (replay does the same, so a replay of the whole take stays
bit-identical) with the channel values it had when the show stopped: `HeldValues` keeps each
channel at that value until a control that drives it is touched (a dial nudges on from it, a
fader picks it up when it meets it) or the performer panics."""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from puppet.errors import ConfigError

RESTART_LABEL = "restarted after a crash"
_TAIL_BYTES = 1 << 16  # how far back from the end to look for where the file may be cut


@dataclass
class ResumePoint:
    """Where a take goes on: after `ticks` complete ticks, at byte `offset`, with `values`."""

    path: Path
    ticks: int
    offset: int
    values: np.ndarray
    header: dict[str, Any]


def _keep(line: bytes, ticks: int) -> bool:
    """A line stays in the take: a complete record, not the end record, not of a tick >= ticks."""
    if not line.endswith(b"\n"):
        return False
    try:
        rec = json.loads(line)
    except (ValueError, RecursionError):  # cut, or damaged (nested thousands deep): it goes
        return False
    if not isinstance(rec, dict) or rec.get("t") == "end":
        return False
    tick = rec.get("tick")
    return not (rec.get("t") in ("ev", "st", "v", "mark", "seg") and isinstance(tick, int) and tick >= ticks)


def _cut_offset(path: Path, ticks: int) -> int:
    """The byte offset just after the last record that stays in the take: a line cut by the
    crash, an end record and the records of the tick in progress go (looked for in the tail)."""
    size = path.stat().st_size
    start = max(0, size - _TAIL_BYTES)
    with open(path, "rb") as fh:
        fh.seek(start)
        tail = fh.read()
    parts = tail.split(b"\n")
    lines = [x + b"\n" for x in parts[:-1]] + ([parts[-1]] if parts[-1] else [])
    ends = np.cumsum([len(x) for x in lines]).tolist() if lines else [0]
    first = 1 if start > 0 else 0  # the tail's first line may be a part of one: left as it is
    for i in range(len(lines) - 1, first - 1, -1):
        if _keep(lines[i], ticks):
            return start + ends[i]
    return start + (ends[0] if first else 0)


class TakeFollower:
    """Follows a recording while another process writes it (what a standby does while it waits),
    so that at a crash only the last few records are left to read: the tick count and the last
    channel values as `read_session` would give them. Any surprise (a damaged line, another face,
    a file cut back or replaced) makes `point()` return None: the caller then reads the file whole."""

    def __init__(self, path: str | Path, face: Any) -> None:
        self.path = Path(path)
        self.names = [c.name for c in face.vocab.channels]
        self.index = {n: i for i, n in enumerate(self.names)}
        self.rig_hash = face.rig.get("hash")
        self.defaults = np.array(face.vocab.defaults(), dtype=np.float64)
        self._reset()

    def _reset(self) -> None:
        self.pos, self.buf, self.ok = 0, b"", True
        self.header: dict[str, Any] | None = None
        self.values = self.defaults.copy()
        self.sync, self.last, self.end = 0, -1, None

    def poll(self) -> None:
        """Read what was written since the last call."""
        try:
            with open(self.path, "rb") as fh:
                if os.fstat(fh.fileno()).st_size < self.pos:
                    self._reset()  # cut back (a restart) or replaced: start again
                fh.seek(self.pos)
                data = fh.read()
        except OSError:
            return
        self.pos += len(data)
        lines = (self.buf + data).split(b"\n")
        self.buf = lines.pop()
        for line in lines:
            if self.ok and line.strip():
                self._line(line)

    def _line(self, line: bytes) -> None:
        try:
            rec = json.loads(line)
            kind = rec["t"]
            if self.header is None:
                if kind != "header" or rec.get("channels") != self.names or \
                        (rec.get("rig") or {}).get("hash") != self.rig_hash:
                    self.ok = False
                self.header = rec
            elif kind == "end":
                self.end = int(rec["ticks"])
            elif kind == "v":
                tick = int(rec["tick"])
                for n, v in rec["v"].items():
                    i = self.index.get(n)
                    if i is not None:
                        x = float(v)
                        if not np.isfinite(x):
                            raise ValueError("non-finite value")
                        self.values[i] = x
                self.last = max(self.last, tick)
            elif kind == "sync":
                self.sync = max(self.sync, int(rec["tick"]))
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError):
            self.ok = False

    def point(self) -> ResumePoint | None:
        self.poll()
        if not self.ok or self.header is None or self.end is not None:
            return None
        ticks = max(self.sync, self.last + 1)
        return ResumePoint(self.path, ticks, _cut_offset(self.path, ticks), self.values.copy(), self.header)


def resume_point(path: str | Path, face: Any, follower: TakeFollower | None = None) -> ResumePoint | None:
    """Where the recording at `path` goes on, or None if there is none yet (start a new one).
    A file of another face, or not a recording, is a ConfigError (one line). With a `follower`
    that kept up with the file, only its last records are read."""
    from puppet.session import read_session

    p = Path(path)
    if not p.exists() or p.stat().st_size == 0:
        return None
    if follower is not None:
        point = follower.point()
        if point is not None:
            return point
    s = read_session(p)
    names = [c.name for c in face.vocab.channels]
    if s.channels != names or (s.header.get("rig") or {}).get("hash") != face.rig.get("hash"):
        raise ConfigError(f"{p}: cannot continue this recording: it was made with another face "
                          f"(rig or channels differ); record to a new file")
    defaults = np.array(face.vocab.defaults(), dtype=np.float64)
    values = last_values(s, defaults)
    return ResumePoint(p, s.ticks, _cut_offset(p, s.ticks), values, s.header)


def last_values(session: Any, defaults: np.ndarray) -> np.ndarray:
    """The channel values of a recording's last tick (changes applied in tick order)."""
    cur = np.array(defaults, dtype=np.float64, copy=True)
    for k in sorted(session.values):
        for i, v in session.values[k].items():
            cur[i] = v
    return cur


class HeldValues:
    """Keeps restored channel values until the performer takes each channel over (see module)."""

    def __init__(self, mapper: Any, values: np.ndarray) -> None:
        self.mapper = mapper
        self.values = np.array(values, dtype=np.float64, copy=True)
        self.held = self.values != mapper.defaults
        mapper.values = self.values.copy()  # relative dials and pickup continue from here

    def apply(self, values: np.ndarray) -> np.ndarray:
        """The tick's values with the channels still held replaced by their restored value."""
        held = self.held
        if not held.any():
            return values
        mapper = self.mapper
        if mapper.panic_left > 0.0:  # a panic eases everything to neutral: nothing is held
            held[:] = False
            return values
        for b in mapper.bindings:
            if b.active and b.target is not None:
                for ch, _ in b.target.channels:
                    held[ch] = False
        out = np.where(held, self.values, values)
        mapper.values = out.copy()
        return out


def open_resumed(point: ResumePoint, writer_cls: Any, header: dict[str, Any]) -> Any:
    """A writer that appends to the recording at `point` (header kept), positioned after it."""
    w = writer_cls(point.path, header, append_to=point.offset)
    w.resume_at(point.ticks, point.values)
    return w


def start_segment(core: Any, point: ResumePoint) -> None:
    """Put a fresh LiveCore where the take stopped: tick count, held values, seg + marker."""
    core.tick_count = point.ticks
    from puppet.live import (GAZE_TISSUE_AS, JAW_AS, JAW_BENDING_AS, JAW_CONSTANTS_AS, LIDS_APART_AS, LIDS_AS,
                             MUSCLES_AS, RESPONSES_AS, SOLVE_AS)

    # the new segment is stepped as the take's header says its steps were (puppet.replay reads it)
    core.sim.muscles_summed = point.header.get("muscles") != MUSCLES_AS
    core.sim.jaw_responses = point.header.get("jaw") == JAW_AS
    core.sim.bending_turned = point.header.get("jaw bending") == JAW_BENDING_AS
    core.sim.symmetric_solve = point.header.get("solve") == SOLVE_AS
    core.sim.single_responses = point.header.get("responses") == RESPONSES_AS
    core.sim.constants_from_grid = point.header.get("jaw constants") == JAW_CONSTANTS_AS
    core.sim.lids_follow_gaze = point.header.get("lids") == LIDS_AS
    core.sim.lids_apart = point.header.get("lid coupling") == LIDS_APART_AS
    core.sim.gaze_tissue = point.header.get("gaze tissue") == GAZE_TISSUE_AS
    if core._crash_at <= point.ticks:  # the test hook's crash happened in the segment before
        core._crash_at = -1
    core.hold = HeldValues(core.mapper, point.values)
    core.values = point.values.copy()
    if core.writer is not None:
        core.writer.segment(point.ticks, RESTART_LABEL)
    core.mark(RESTART_LABEL)
    print(f"puppet: continuing {point.path} at tick {point.ticks} ({point.ticks / core.rate:.2f} s) "
          f"with the face's last channel values", file=sys.stderr)
