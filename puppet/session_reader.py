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
from safefile import BadFile, number, quote, read_bytes, sequence, string, table

MAX_CHANNELS = 4096
MIN_RATE = 1.0
MAX_RATE = 10_000.0
MAX_TICKS = 100_000_000
#: ticks x channels of a take's value array (8 bytes each): 400 MB
MAX_CELLS = 50_000_000
MAX_BYTES = 2 * 1024 * 1024 * 1024
MAX_LABEL = 200
RESOLUTIONS = (0, 1, 2)


class _Damaged(ValueError):
    """One record cannot be used."""


#: the header's keys that say how the recording program's step was made (puppet.replay reads them)
STEP_KEYS = ("muscles", "lids", "jaw", "bending", "jaw bending", "solve", "responses", "jaw constants",
             "lid coupling")


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


def read_session(path: str | Path) -> Session:
    """Read a recording. A file cut short (crash, SIGKILL) reads up to its last complete record
    and gets a warning in `session.warnings`; a file that is not a recording, or whose header is
    damaged, is a ConfigError naming file:line."""
    p = Path(path)
    try:
        data = read_bytes(p, "recording", MAX_BYTES)
    except BadFile as err:
        raise ConfigError(str(err)) from err
    lines = data.split(b"\n")
    header = _header(p, lines[0])
    channels: list[str] = header["channels"]
    index = {n: i for i, n in enumerate(channels)}
    s = Session(p, header, channels, header["tick_rate"], 0, complete=False)
    last_tick = -1
    sync = 0
    for lineno, raw in enumerate(lines[1:], start=2):
        if not raw.strip():
            continue
        try:
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
                s.values[tick] = _values(rec, index)
                last_tick = max(last_tick, tick)
            elif kind in ("ev", "st"):
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
            cut = lineno == len(lines) or all(not x.strip() for x in lines[lineno:])
            why = "was cut off (crash or kill)" if cut else f"has a damaged record at line {lineno}"
            s.warnings.append(f"{p}: recording {why}; reading it up to its last complete record")
            break
    if not s.complete:
        s.ticks = max(sync, last_tick + 1)
        if not s.warnings:
            s.warnings.append(f"{p}: recording has no end record (the program was stopped); "
                              f"reading its {s.ticks} complete ticks")
    if s.ticks * len(channels) > MAX_CELLS:
        hours = s.ticks / s.tick_rate / 3600
        raise ConfigError(f"{p}: the recording claims {s.ticks} ticks ({hours:.3g} h at {s.tick_rate:g} Hz) of "
                          f"{len(channels)} channels, more than one replay holds ({MAX_CELLS} values); "
                          "is the file damaged?")
    for k in [k for k in s.values if k >= s.ticks]:
        del s.values[k]
    s.markers = [(k, label) for k, label in s.markers if k <= s.ticks]
    s.checks = {k: v for k, v in s.checks.items() if k <= s.ticks}
    s.segments = [k for k in s.segments if 0 < k < s.ticks]
    return s
