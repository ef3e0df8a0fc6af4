"""Reading a recording back, checked at the boundary (the format is described in puppet.session).

The header is checked field by field (types, ranges, finiteness, sizes): a header that cannot be
trusted is one ConfigError naming file:1. Records after it are checked the same way; the first one
that is damaged ends the take there, with a warning, like a file cut by a crash. Nothing is
allocated by what a file claims without a bound: a take's ticks times its channels stays under
`MAX_CELLS`."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from puppet.errors import ConfigError
from puppet.session import FORMAT, VERSION, Session
from safefile import BadFile, bounded_lines, number, open_to_read, quote, sequence, string, table

MAX_CHANNELS = 4096
MIN_RATE = 1.0
MAX_RATE = 10_000.0
MAX_TICKS = 100_000_000
#: ticks x channels of a take's value array (8 bytes each): 400 MB
MAX_CELLS = 50_000_000
MAX_BYTES = 2 * 1024 * 1024 * 1024
#: a header line's bytes (4096 channel names of 100 characters are 0.4 MB): a file whose first line
#: runs on past this (/dev/zero, a video, one line of gigabytes) is refused after reading this much
MAX_HEADER_BYTES = 4 * 1024 * 1024
#: a record line's bytes (a tick of 4096 channels with long names and long numbers is under 0.6 MB)
MAX_RECORD_BYTES = 4 * 1024 * 1024
#: event records ("ev", "st") one take holds (a dial box sends at most a few hundred a second: an
#: hour is about a million): a file of endless events stops here instead of filling the memory
MAX_EVENTS = 20_000_000
#: blank lines looked at after a damaged record to tell a file cut by a crash from damage inside
LOOK_AHEAD = 64
MAX_LABEL = 200
RESOLUTIONS = (0, 1, 2)


class _Damaged(ValueError):
    """One record cannot be used."""


#: the header's keys that say how the recording program's step was made (puppet.replay reads them)
STEP_KEYS = ("muscles", "lids", "jaw", "bending", "jaw bending", "solve", "responses", "jaw constants",
             "lid coupling", "gaze tissue")


def _finite(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError("number out of range")
    return x


def _no_constant(name: str) -> float:
    raise ValueError(f"non-finite {name}")


def _json_line(raw: bytes) -> Any:
    return json.loads(raw, parse_constant=_no_constant, parse_float=_finite)


def _header(p: Path, line: bytes) -> dict[str, Any]:
    where = f"{p}:1"
    if line.startswith((b"\xff\xfe", b"\xfe\xff", b"\0\0\xfe\xff", b"{\0", b"\0{")):
        # json reads a UTF-16/32 header line by itself, and every record after it would be damage
        raise ConfigError(f"{where}: not a facepuppet recording in UTF-8 (it looks like UTF-16 or UTF-32: "
                          "save it as UTF-8)")
    try:
        header = _json_line(line)
    except (ValueError, UnicodeDecodeError, RecursionError) as err:
        raise ConfigError(f"{where}: not a facepuppet recording (no readable header)") from err
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise ConfigError(f"{where}: not a facepuppet recording (header format is not {FORMAT!r})")
    if header.get("version") != VERSION or isinstance(header.get("version"), bool):
        raise ConfigError(f"{where}: recording format version {quote(header.get('version'))} is not supported "
                          f"(expected {VERSION})")
    try:
        if "channels" not in header:
            raise BadFile(f"{where}: recording header lacks channels")
        header.setdefault("tick_rate", 60.0)  # takes from before the tick rate was a choice ticked at 60 Hz
        chans = sequence(header["channels"], f"{where}: channels", MAX_CHANNELS, 1)
        channels = [string(c, f"{where}: channel name", 100) for c in chans]
        if len(set(channels)) != len(channels):
            raise BadFile(f"{where}: the header names a channel twice")
        header["tick_rate"] = number(header["tick_rate"], f"{where}: tick_rate", MIN_RATE, MAX_RATE)
        header["rig"] = _rig(header.get("rig"), where)
        for key in STEP_KEYS:  # how the step was made: words, each read by puppet.replay
            if header.get(key) is not None:
                header[key] = string(header[key], f"{where}: {key}", 80)
    except BadFile as err:
        raise ConfigError(f"{err} (the recording header is damaged)") from err
    header["channels"] = channels
    return header


def _rig(rig: Any, where: str) -> dict[str, Any]:
    """The header's rig identity: {name, hash, path, resolution}, each of the right type or absent."""
    if rig is None:
        return {}
    rig = table(rig, f"{where}: rig", 64)
    out: dict[str, Any] = {}
    for key in ("name", "hash", "path"):
        if rig.get(key) is not None:
            out[key] = string(rig[key], f"{where}: rig {key}", 4096)
    if rig.get("resolution") is not None:
        out["resolution"] = number(rig["resolution"], f"{where}: rig resolution", 0, 2, integer=True)
    for key in ("face", "identity_hash"):  # the face it was made with (puppet.faces)
        if rig.get(key) is not None:
            out[key] = string(rig[key], f"{where}: rig {key}", 200)
    if rig.get("identity") is not None:
        vals = sequence(rig["identity"], f"{where}: rig identity", 100, 1)
        out["identity"] = [number(v, f"{where}: rig identity weight", -10, 10) for v in vals]
    return out


def _tick(rec: dict[str, Any], key: str = "tick") -> int:
    v = rec[key]
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= MAX_TICKS:
        raise _Damaged(f"{key} {quote(v)}")
    return v


def _values(rec: dict[str, Any], index: dict[str, int]) -> dict[int, float]:
    v = rec["v"]
    if not isinstance(v, dict) or len(v) > len(index):
        raise _Damaged("values")
    out = {}
    for name, x in v.items():
        if isinstance(x, bool) or not isinstance(x, (int, float)) or (isinstance(x, int) and x.bit_length() > 1000):
            raise _Damaged(f"value {quote(x)}")
        x = float(x)
        if not math.isfinite(x):  # finite but out of range is clamped to the channel's range later
            raise _Damaged(f"value {quote(x)}")
        if name in index:
            out[index[name]] = x
    return out


def _too_many(p: Path, ticks: int, channels: int, rate: float) -> ConfigError:
    hours = ticks / rate / 3600
    return ConfigError(f"{p}: the recording claims {ticks} ticks ({hours:.3g} h at {rate:g} Hz) of "
                       f"{channels} channels, more than one replay holds ({MAX_CELLS} values); "
                       "is the file damaged?")


def read_session(path: str | Path) -> Session:
    """Read a recording. A file cut short (crash, SIGKILL) reads up to its last complete record
    and gets a warning in `session.warnings`; a file that is not a recording, or whose header is
    damaged, is a ConfigError naming file:line. The file is read line by line, each line bounded
    (`MAX_HEADER_BYTES`, `MAX_RECORD_BYTES`): what is not a recording (/dev/zero, /dev/urandom, a
    video, a file of one endless line) is refused after reading a few megabytes at most."""
    p = Path(path)
    try:
        with open_to_read(p, "recording") as fh:
            return _read(p, bounded_lines(fh, str(p), "recording", MAX_RECORD_BYTES, MAX_BYTES))
    except BadFile as err:
        raise ConfigError(str(err)) from err


def _read(p: Path, lines: Any) -> Session:
    first = next(lines, b"")
    if len(first) > MAX_HEADER_BYTES:
        raise ConfigError(f"{p}:1: not a facepuppet recording (its first line runs on past "
                          f"{MAX_HEADER_BYTES // (1024 * 1024)} MB; is it the right file?)")
    header = _header(p, first.rstrip(b"\r\n"))
    channels: list[str] = header["channels"]
    index = {n: i for i, n in enumerate(channels)}
    s = Session(p, header, channels, header["tick_rate"], 0, complete=False)
    last_tick = -1
    sync = 0
    most = MAX_CELLS // len(channels)  # ticks one replay holds
    for lineno, raw in enumerate(lines, start=2):
        if not raw.strip():
            continue
        try:
            if len(raw) > MAX_RECORD_BYTES:
                raise _Damaged("a line too long")
            rec = _json_line(raw)
            if not isinstance(rec, dict):
                raise _Damaged("not an object")
            kind = rec["t"]
            if kind == "end":
                s.ticks = _tick(rec, "ticks")
                s.complete = True
                break
            tick = _tick(rec)
            if kind == "v":
                if tick >= most:
                    raise _too_many(p, tick + 1, len(channels), s.tick_rate)
                s.values[tick] = _values(rec, index)
                last_tick = max(last_tick, tick)
            elif kind in ("ev", "st"):
                if len(s.events) >= MAX_EVENTS:
                    raise ConfigError(f"{p}:{lineno}: the recording holds more than {MAX_EVENTS} device events, "
                                      "more than one replay holds; is the file damaged?")
                s.events.append(rec)
            elif kind == "mark":
                s.markers.append((tick, str(rec.get("label", ""))[:MAX_LABEL]))
            elif kind == "chk":
                s.checks[tick] = str(rec.get("sha", ""))[:64]
            elif kind == "sync":
                sync = max(sync, tick)
            elif kind == "seg":
                s.segments.append(tick)
        except (ValueError, KeyError, TypeError, UnicodeDecodeError, RecursionError, OverflowError):
            if len(raw) > MAX_RECORD_BYTES:
                why = (f"has a line longer than {MAX_RECORD_BYTES // (1024 * 1024)} MB at line {lineno} "
                       "(damaged, or not a recording from there on)")
            elif raw.endswith(b"\n") and not _blank_to_end(lines):
                why = f"has a damaged record at line {lineno}"
            else:
                why = "was cut off (crash or kill)"
            s.warnings.append(f"{p}: recording {why}; reading it up to its last complete record")
            break
    if not s.complete:
        s.ticks = max(sync, last_tick + 1)
        if not s.warnings:
            s.warnings.append(f"{p}: recording has no end record (the program was stopped); "
                              f"reading its {s.ticks} complete ticks")
    if s.ticks * len(channels) > MAX_CELLS:
        raise _too_many(p, s.ticks, len(channels), s.tick_rate)
    for k in [k for k in s.values if k >= s.ticks]:
        del s.values[k]
    s.markers = [(k, label) for k, label in s.markers if k <= s.ticks]
    s.checks = {k: v for k, v in s.checks.items() if k <= s.ticks}
    s.segments = [k for k in s.segments if 0 < k < s.ticks]
    return s


def _blank_to_end(lines: Any) -> bool:
    """Whether the lines left are blank (a record cut by a crash is followed by nothing else); at
    most `LOOK_AHEAD` of them are read."""
    for n, raw in enumerate(lines):
        if raw.strip() or n >= LOOK_AHEAD:
            return False
    return True
