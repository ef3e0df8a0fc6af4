"""MIDI controller profiles: data files (``devices/midi/profiles/*.toml``) saying which message each
physical control sends, how to read it, and how to light it.

A profile file::

    name = "Korg nanoKONTROL2"
    match = ["nanokontrol2"]       # port-name substrings that pick this profile by itself
    channel = 1                    # default MIDI channel (1-16) of every control
    note = "..."                   # shown by `puppet devices` (e.g. a mode the box must be in)

    [[control]]
    name = "fader{n}"              # {n} = 1..count
    count = 8
    message = "cc"                 # cc | cc14 | note | pitchbend | nrpn | rpn
    number = 0                     # first number (or a list, one per control); step = 1
    kind = "axis"                  # axis (absolute) | dial (relative encoder) | button
    dead_band = 1                  # counts a reversal must exceed (jittering pots)
    light = true                   # or {message, number, channel, on, off}: the button's LED
    ring = true                    # or {message, number, channel, lo, hi}: an encoder's ring

``encoding`` (twos_complement | offset64 | sign_magnitude) and ``counts_per_turn`` describe a
relative encoder; ``order`` (msb_lsb | lsb_msb | msb) how a 14-bit value arrives; ``lo``/``hi`` the
axis range (``lo = -1`` for a centred pitch-bend wheel). Every file is checked when loaded: any
content gives a profile or one ``ProfileError`` line naming the file, the line and what to fix.
"""

from __future__ import annotations

import functools
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from devices.errors import DeviceSpecError
from safefile import BadFile, file_kind, quote, read_text

MESSAGES = ("cc", "cc14", "note", "pitchbend", "nrpn", "rpn")
KINDS = ("axis", "dial", "button")
ENCODINGS = ("twos_complement", "offset64", "sign_magnitude")
ORDERS = ("msb_lsb", "lsb_msb", "msb")
LIGHT_MESSAGES = ("cc", "note")
MAX_FILE = 256 * 1024
#: Read no more than this of a profile file (parse_profile then refuses what passes MAX_FILE).
MAX_PROFILE_BYTES = 1024 * 1024
MAX_CONTROLS = 1024
TOP_KEYS = {"name", "match", "channel", "note", "control", "dead_band", "port"}
CONTROL_KEYS = {"name", "count", "message", "number", "step", "channel", "kind", "encoding", "counts_per_turn",
                "order", "dead_band", "lo", "hi", "light", "ring"}
LIGHT_KEYS = {"message", "number", "channel", "on", "off", "lo", "hi", "step"}


class ProfileError(DeviceSpecError):
    """A profile file that cannot be used; the message is one line: file:line: what to fix."""


@dataclass(frozen=True)
class LightDef:
    """How the host drives one LED or ring: a CC or note-on on ``channel`` (0-15) and ``number``;
    a light sends ``on``/``off`` values, a ring ``lo + level * (hi - lo)``."""

    message: str
    channel: int
    number: int
    on: int = 127
    off: int = 0
    lo: int = 0
    hi: int = 127

    def button(self, level: float) -> tuple[int, ...]:
        return self._msg(self.on if level >= 0.5 else self.off)

    def ring_value(self, level: float) -> tuple[int, ...]:
        return self._msg(int(round(self.lo + max(0.0, min(1.0, level)) * (self.hi - self.lo))))

    def _msg(self, value: int) -> tuple[int, ...]:
        status = (0xB0 if self.message == "cc" else 0x90) | self.channel
        return (status, self.number, value & 0x7F)


@dataclass(frozen=True)
class ControlDef:
    """One physical control. ``channel`` is 0-15; ``number`` a CC/note number, or the 14-bit
    parameter number of an NRPN/RPN (MSB * 128 + LSB)."""

    name: str
    message: str
    channel: int
    number: int
    kind: str
    lo: float = 0.0
    hi: float = 1.0
    encoding: str = "twos_complement"
    counts_per_turn: float = 24.0
    order: str = "msb_lsb"
    dead_band: int = 0
    light: LightDef | None = None
    ring: LightDef | None = None

    @property
    def max_raw(self) -> int:
        return 127 if self.message in ("cc", "note") or (self.message in ("nrpn", "rpn") and self.order == "msb") \
            else 16383


@dataclass
class MidiProfile:
    """A controller: its controls, the port names that select it, a note for the user."""

    name: str
    title: str
    match: list[str] = field(default_factory=list)
    controls: list[ControlDef] = field(default_factory=list)
    note: str = ""
    port: str = ""
    source: str = "<profile>"

    def control(self, name: str) -> ControlDef | None:
        return next((c for c in self.controls if c.name == name), None)


def _line_of(text: str, path: tuple[Any, ...]) -> int:
    """The line of a top-level key, or of the k-th [[control]] table (and a key inside it)."""
    lines = text.splitlines()
    if not path:
        return 1
    if path[0] == "control" and len(path) > 1 and isinstance(path[1], int):
        seen = -1
        for i, line in enumerate(lines):
            if re.match(r"\s*\[\[\s*control\s*\]\]", line):
                seen += 1
                if seen == path[1]:
                    if len(path) > 2:
                        for j in range(i + 1, len(lines)):
                            if re.match(r"\s*\[", lines[j]):
                                break
                            if re.match(rf"\s*{re.escape(str(path[2]))}\s*=", lines[j]):
                                return j + 1
                    return i + 1
        return 1
    for i, line in enumerate(lines):
        if re.match(rf"\s*{re.escape(str(path[0]))}\s*=", line):
            return i + 1
    return 1


class _Check:
    def __init__(self, text: str, source: str) -> None:
        self.text, self.source = text, source

    def fail(self, path: tuple[Any, ...], msg: str) -> ProfileError:
        return ProfileError(f"{self.source}:{_line_of(self.text, path)}: {msg}")

    def int_(self, v: Any, path: tuple[Any, ...], lo: int, hi: int) -> int:
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise self.fail(path, f"expected a whole number {lo}..{hi} for {path[-1]}, got {quote(v)}")
        return v

    def num(self, v: Any, path: tuple[Any, ...], lo: float, hi: float) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo <= v <= hi):
            raise self.fail(path, f"expected a number {lo:g}..{hi:g} for {path[-1]}, got {quote(v)}")
        return float(v)

    def str_(self, v: Any, path: tuple[Any, ...], choices: tuple[str, ...] | None = None) -> str:
        if not isinstance(v, str) or not v or len(v) > 200 or (choices is not None and v not in choices):
            want = f"one of {', '.join(choices)}" if choices else "a non-empty string (at most 200 characters)"
            raise self.fail(path, f"expected {want} for {path[-1]}, got {quote(v)}")
        return v

    def ints(self, v: Any, path: tuple[Any, ...], count: int, lo: int, hi: int) -> list[int]:
        if isinstance(v, list):
            if len(v) != count:
                raise self.fail(path, f"expected {count} numbers in {path[-1]} (one per control), got {len(v)}")
            return [self.int_(x, path, lo, hi) for x in v]
        return [self.int_(v, path, lo, hi)] * count


def parse_profile(text: str, source: str = "<profile>", name: str | None = None,
                  channel: int | None = None) -> MidiProfile:
    """Parse and check a profile file's text; raises ProfileError naming file:line. ``channel``
    (1-16) replaces the file's default channel (a box set to another global channel)."""
    if len(text) > MAX_FILE:
        raise ProfileError(f"{source}:1: profile larger than {MAX_FILE // 1024} KiB; is this the right file?")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        from safefile import toml_end

        m = re.search(r"\(at line (\d+)", str(err))
        line = m.group(1) if m else toml_end(text).split(":")[0] if "end of document" in str(err) else 1
        raise ProfileError(f"{source}:{line}: TOML syntax error: "
                           f"{re.sub(r' [(]at line.*', '', str(err))}") from err
    except RecursionError as err:  # an array nested thousands deep
        raise ProfileError(f"{source}:1: the profile is nested too deep; a profile is flat tables") from err
    except ValueError as err:  # an integer of thousands of digits
        raise ProfileError(f"{source}:1: the profile holds an unusable number ({str(err)[:60]})") from err
    c = _Check(text, source)
    for key in data:
        if key not in TOP_KEYS:
            raise c.fail((key,), f"unknown key {quote(key)}; expected one of {', '.join(sorted(TOP_KEYS))}")
    title = c.str_(data.get("name", Path(source).stem), ("name",))
    match = data.get("match", [])
    if not isinstance(match, list) or len(match) > 32:
        raise c.fail(("match",), "expected match = [\"port name part\", ...]")
    match = [c.str_(m, ("match",)).lower() for m in match]
    default_channel = c.int_(data.get("channel", 1), ("channel",), 1, 16) - 1
    if channel is not None:
        default_channel = channel - 1
    note = data.get("note", "")
    if not isinstance(note, str) or len(note) > 1000:
        raise c.fail(("note",), "expected a short note string")
    port = data.get("port", "")
    if not isinstance(port, str) or len(port) > 200:
        raise c.fail(("port",), "expected port = \"port name part\" (which of the box's ports to use)")
    dead_band = c.int_(data.get("dead_band", 0), ("dead_band",), 0, 64)
    raw = data.get("control", [])
    if not isinstance(raw, list):
        raise c.fail(("control",), "expected [[control]] tables")
    controls: list[ControlDef] = []
    for i, item in enumerate(raw):
        controls += _controls(c, i, item, default_channel, dead_band)
        if len(controls) > MAX_CONTROLS:
            raise c.fail(("control", i), f"more than {MAX_CONTROLS} controls")
    seen: dict[str, int] = {}
    keys: dict[tuple[str, int, int], str] = {}
    for i, cd in enumerate(controls):
        if cd.name in seen:
            raise ProfileError(f"{source}:1: control name {cd.name!r} used twice; names must be unique")
        seen[cd.name] = i
        for key in _input_keys(cd):
            if key in keys:
                raise ProfileError(f"{source}:1: controls {keys[key]!r} and {cd.name!r} read the same message")
            keys[key] = cd.name
    return MidiProfile(name or Path(source).stem, title, match, controls, note, port, source)


def _input_keys(cd: ControlDef) -> list[tuple[str, int, int]]:
    if cd.message == "cc14":
        return [("cc", cd.channel, cd.number), ("cc", cd.channel, cd.number + 32)]
    return [(cd.message, cd.channel, cd.number)]


def _controls(c: _Check, i: int, item: Any, channel: int, dead_band: int) -> list[ControlDef]:
    p: tuple[Any, ...] = ("control", i)
    if not isinstance(item, dict):
        raise c.fail(p, "expected a [[control]] table")
    for key in item:
        if key not in CONTROL_KEYS:
            raise c.fail(p + (key,), f"unknown control key {quote(key)}; "
                         f"expected one of {', '.join(sorted(CONTROL_KEYS))}")
    if "name" not in item or "message" not in item or "number" not in item and item.get("message") != "pitchbend":
        raise c.fail(p, "expected name, message and number in every [[control]]")
    count = c.int_(item.get("count", 1), p + ("count",), 1, 128)
    name = c.str_(item["name"], p + ("name",))
    if count > 1 and "{n}" not in name:
        raise c.fail(p + ("name",), "expected {n} in the name of a control with a count (e.g. fader{n})")
    message = c.str_(item["message"], p + ("message",), MESSAGES)
    top = {"cc": 127, "note": 127, "cc14": 31, "pitchbend": 0, "nrpn": 16383, "rpn": 16383}[message]
    step = c.int_(item.get("step", 1), p + ("step",), 0, 127)
    if message == "pitchbend":  # one per channel: the number is not part of the message
        numbers = [0] * count
    else:
        numbers = _numbers(c, item.get("number", 0), p + ("number",), count, step, top)
    channels = _channels(c, item.get("channel"), p + ("channel",), count, channel)
    default_kind = "button" if message == "note" else "axis"
    kind = c.str_(item.get("kind", default_kind), p + ("kind",), KINDS)
    if kind == "dial" and message not in ("cc", "nrpn", "rpn"):
        raise c.fail(p + ("kind",), "a relative encoder (kind = \"dial\") must send cc, nrpn or rpn")
    encoding = c.str_(item.get("encoding", "twos_complement"), p + ("encoding",), ENCODINGS)
    cpt = c.num(item.get("counts_per_turn", 24), p + ("counts_per_turn",), 1, 100000)
    order = c.str_(item.get("order", "msb_lsb"), p + ("order",), ORDERS)
    db = c.int_(item.get("dead_band", dead_band), p + ("dead_band",), 0, 1024)
    lo = c.num(item.get("lo", 0.0), p + ("lo",), -1.0, 1.0)
    hi = c.num(item.get("hi", 1.0), p + ("hi",), -1.0, 1.0)
    if hi <= lo:
        raise c.fail(p + ("hi",), "expected hi > lo")
    if kind == "button":
        lo, hi = 0.0, 1.0
    elif kind == "dial":
        lo, hi = -1.0, 1.0
    lights = _lights(c, item.get("light"), p + ("light",), count, message, numbers, channels, "light")
    rings = _lights(c, item.get("ring"), p + ("ring",), count, message, numbers, channels, "ring")
    if lights[0] is not None and kind != "button":
        raise c.fail(p + ("light",), "light is for buttons; an encoder's or fader's LEDs are a ring")
    if rings[0] is not None and kind == "button":
        raise c.fail(p + ("ring",), "ring is for encoders and faders; a button's LED is a light")
    out = []
    for k in range(count):
        out.append(ControlDef(name.replace("{n}", str(k + 1)), message, channels[k], numbers[k], kind, lo, hi,
                              encoding, cpt, order, db, lights[k], rings[k]))
    return out


def _numbers(c: _Check, v: Any, path: tuple[Any, ...], count: int, step: int, top: int) -> list[int]:
    if isinstance(v, list):
        return c.ints(v, path, count, 0, top)
    first = c.int_(v, path, 0, top)
    nums = [first + k * step for k in range(count)]
    if nums[-1] > top:
        raise c.fail(path, f"numbers {first}..{nums[-1]} run past {top}")
    return nums


def _channels(c: _Check, v: Any, path: tuple[Any, ...], count: int, default: int) -> list[int]:
    if v is None:
        return [default] * count
    if isinstance(v, str) and v == "each":  # one channel per control: 1, 2, ... (Mackie faders)
        if count > 16:
            raise c.fail(path, "channel = \"each\" allows at most 16 controls")
        return list(range(count))
    return [ch - 1 for ch in c.ints(v, path, count, 1, 16)]


def _lights(c: _Check, v: Any, path: tuple[Any, ...], count: int, message: str, numbers: list[int],
            channels: list[int], what: str) -> list[LightDef | None]:
    if v is None or v is False:
        return [None] * count
    if v is True:
        if message not in LIGHT_MESSAGES:
            raise c.fail(path, f"{what} = true needs a cc or note control; give {what} = {{message, number}}")
        return [LightDef(message, ch, n) for ch, n in zip(channels, numbers)]
    if not isinstance(v, dict):
        raise c.fail(path, f"expected {what} = true or {what} = {{message = \"note\", number = N, on = 127, off = 0}}")
    for key in v:
        if key not in LIGHT_KEYS:
            raise c.fail(path, f"unknown {what} key {quote(key)}; expected one of {', '.join(sorted(LIGHT_KEYS))}")
    msg = c.str_(v.get("message", message if message in LIGHT_MESSAGES else "cc"), path, LIGHT_MESSAGES)
    step = c.int_(v.get("step", 1), path, 0, 127)
    nums = _numbers(c, v["number"], path, count, step, 127) if "number" in v else numbers
    if any(n > 127 for n in nums):
        raise c.fail(path, f"expected {what} numbers 0..127")
    chans = _channels(c, v.get("channel"), path, count, channels[0]) if "channel" in v else channels
    on, off = c.int_(v.get("on", 127), path, 0, 127), c.int_(v.get("off", 0), path, 0, 127)
    lo, hi = c.int_(v.get("lo", 0), path, 0, 127), c.int_(v.get("hi", 127), path, 0, 127)
    return [LightDef(msg, ch, n, on, off, lo, hi) for ch, n in zip(chans, nums)]


# ----------------------------------------------------------------------------- the shipped profiles
def profile_names() -> list[str]:
    """The shipped profiles (file stems under devices/midi/profiles/)."""
    root = resources.files("devices.midi") / "profiles"
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_profile(name_or_path: str, channel: int | None = None) -> MidiProfile:
    """A shipped profile by name (``nanokontrol2``) or a profile file by path; ``channel``
    (1-16) replaces its default channel."""
    if name_or_path.endswith(".toml") or "/" in name_or_path:
        p = Path(name_or_path)
        if file_kind(p) == "missing":
            raise ProfileError(f"{p}: MIDI profile file not found")
        try:  # bounded: a wrong name (/dev/zero, a recording) must not read gigabytes into memory
            text = read_text(p, "MIDI profile", MAX_PROFILE_BYTES)
        except BadFile as err:
            raise ProfileError(str(err)) from err
        return parse_profile(text, str(p), channel=channel)
    key = name_or_path.lower()
    if key not in profile_names():
        raise ProfileError(f"unknown MIDI profile {name_or_path!r}; expected one of {', '.join(profile_names())} "
                           "or a path to a profile .toml file")
    text = (resources.files("devices.midi") / "profiles" / f"{key}.toml").read_text(encoding="utf-8")
    return parse_profile(text, f"devices/midi/profiles/{key}.toml", key, channel)


@functools.lru_cache(maxsize=1)
def _matches() -> tuple[tuple[str, str], ...]:
    return tuple((m, name) for name in profile_names() for m in load_profile(name).match)


def profile_for_port(port_name: str) -> str:
    """The shipped profile whose ``match`` names this port (the longest match wins), else
    ``generic``."""
    low = port_name.lower()
    hits = [(len(m), name) for m, name in _matches() if m in low]
    return max(hits)[1] if hits else "generic"
