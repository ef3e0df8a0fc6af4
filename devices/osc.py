"""``osc://HOST:PORT[?profile=generic|touchosc|openstage]`` — phones, tablets and other programs
sending Open Sound Control over UDP.

python-osc is the codec only: its message parser decodes each message, while bundles are walked
here (depth and count bounded), on the device's own socket and reader thread. So a future time tag
never delays anything (messages are dispatched when they arrive; the tag is only counted), nothing
sleeps, no thread is started per datagram, nothing is ever sent back, and an address *pattern*
from a sender (``/face/*``) is refused instead of fanned out to every matching control.

Every address is a control named by the address itself (``/face/channel/jaw``, ``/1/fader1``).
A message with one number is that control's value; one with several numbers (an XY pad) gives
``ADDRESS:0``, ``ADDRESS:1``...; ``T``/``F`` are button presses and releases. A profile declares
the controls of a known layout (kinds, ranges) and which addresses are buttons.
"""

from __future__ import annotations

import fnmatch
import math
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from devices.base import ControlInfo
from devices.errors import DeviceSpecError
from devices.events import ControlEvent
from devices.spec import DeviceSpec
from devices.udp import UdpListenerDevice
from devices.warn import WarningCounter

BUNDLE = b"#bundle\x00"
#: Nesting of bundles in bundles, messages in one datagram, characters of an address: at most.
MAX_DEPTH = 8
MAX_MESSAGES = 1024
MAX_ADDRESS = 256
#: Distinct button addresses remembered (a sender spraying addresses must not grow memory).
MAX_BUTTONS = 4096
PATTERN_CHARS = frozenset("*?[]{}")
#: Seconds between 1900 (OSC time tags) and 1970 (time.time()).
NTP_EPOCH = 2208988800
#: Values of a declared axis this far beyond its range (as a fraction of it) are counted.
SLACK = 0.05
#: Values this large are not a control position but garbage.
HUGE = 1e9


class OscDecodeError(ValueError):
    """A datagram that is not OSC (or is damaged)."""


class OscMessage(NamedTuple):
    """One decoded message: its address, its arguments, and the time tag of the bundle that
    carried it (``None`` outside a bundle; 1 means "immediately")."""

    address: str
    args: tuple[Any, ...]
    timetag: int | None = None


#: Argument type tags python-osc decodes; anything else is refused before it is asked (it would
#: log a warning per datagram on the root logger).
TYPE_TAGS = frozenset(",ihfdsbrmtTFN[]")
_py_message: Any = None


def decode_packet(data: bytes) -> list[OscMessage]:
    """Every message of one datagram, bundles flattened in order; OscDecodeError when damaged.
    Bundles are walked iteratively with bounded depth and count, never recursively."""
    out: list[OscMessage] = []
    if not data.startswith(BUNDLE):
        _message(data, None, out)
        return out
    stack: list[tuple[bytes, int]] = [(data, 0)]
    while stack:
        chunk, depth = stack.pop()
        if depth >= MAX_DEPTH:
            raise OscDecodeError(f"bundles nested deeper than {MAX_DEPTH}")
        if len(chunk) < 16:
            raise OscDecodeError("bundle shorter than its header")
        (tag,) = struct.unpack_from(">Q", chunk, 8)
        nested = []
        for el in _elements(chunk):
            if el.startswith(BUNDLE):
                nested.append((el, depth + 1))
            else:
                _message(el, tag, out)
        stack.extend(reversed(nested))
    return out


def _message(chunk: bytes, tag: int | None, out: list[OscMessage]) -> None:
    global _py_message
    if _py_message is None:
        from pythonosc.osc_message import OscMessage as _py_message  # noqa: N813 (lazy: devices imports fast)
    if not chunk.startswith(b"/"):
        raise OscDecodeError("not an OSC message or bundle")
    if len(out) >= MAX_MESSAGES:
        raise OscDecodeError(f"more than {MAX_MESSAGES} messages in one datagram")
    end = chunk.find(b"\0")
    start = (end + 4) & ~3
    if end < 0:
        raise OscDecodeError("address not terminated")
    if start < len(chunk):
        stop = chunk.find(b"\0", start)
        tags = chunk[start:stop if stop >= 0 else len(chunk)]
        # a second comma passes the set test but python-osc logs it per datagram on the root logger
        if not tags.startswith(b",") or b"," in tags[1:] or not TYPE_TAGS.issuperset(tags.decode("latin-1")):
            raise OscDecodeError(f"unknown argument types {tags[:16]!r}")
    try:
        msg = _py_message(chunk)
        out.append(OscMessage(msg._address_regexp, tuple(msg._parameters), tag))
    except Exception as err:  # python-osc raises ParseError, but damaged input finds others
        # python-osc's messages can quote the whole type-tag string (thousands of '[' in one line)
        raise OscDecodeError(f"damaged message: {str(err)[:100]}") from err


def _elements(bundle: bytes) -> Iterator[bytes]:
    i, n = 16, len(bundle)
    while i < n:
        if i + 4 > n:
            raise OscDecodeError("bundle element size cut short")
        (size,) = struct.unpack_from(">i", bundle, i)
        i += 4
        if size <= 0 or size % 4 or i + size > n:
            raise OscDecodeError(f"bundle element of {size} bytes does not fit the bundle")
        yield bundle[i:i + size]
        i += size


def is_future(timetag: int | None, now: float | None = None) -> bool:
    """Whether a bundle's time tag lies in the future (it is dispatched now all the same)."""
    if timetag is None or timetag <= 1:
        return False
    seconds = (timetag >> 32) - NTP_EPOCH + (timetag & 0xFFFFFFFF) / 2**32
    return seconds > (time.time() if now is None else now)


def numbers(args: tuple[Any, ...]) -> list[float | bool]:
    """The numeric and boolean arguments of a message (strings, blobs, nil are skipped)."""
    out: list[float | bool] = []
    for a in args:
        if isinstance(a, bool):
            out.append(a)
        elif isinstance(a, (int, float)):
            out.append(float(a))
    return out


# ----------------------------------------------------------------------------------- profiles
@dataclass(frozen=True)
class OscProfile:
    """A sender's layout: declared controls, and which addresses are buttons (glob patterns)."""

    name: str
    description: str
    controls: tuple[ControlInfo, ...] = ()
    buttons: tuple[str, ...] = ()
    _index: dict[str, ControlInfo] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        self._index.update({c.name: c for c in self.controls})

    def declared(self, name: str) -> ControlInfo | None:
        return self._index.get(name)

    def is_button(self, address: str) -> bool:
        info = self._index.get(address)
        if info is not None:
            return info.kind == "button"
        return any(fnmatch.fnmatchcase(address, p) for p in self.buttons)


def _axes(names: list[str], lo: float = 0.0, hi: float = 1.0) -> list[ControlInfo]:
    return [ControlInfo(n, "axis", lo, hi) for n in names]


def _buttons(names: list[str]) -> list[ControlInfo]:
    return [ControlInfo(n, "button") for n in names]


def _touchosc() -> OscProfile:
    """TouchOSC's "Simple" layout (the one it opens with): page 1 five faders and four toggles,
    page 2 sixteen pushes and four toggles, page 3 an XY pad and four toggles, page 4 an 8x8
    multi-toggle and four toggles. Other layouts work too: push, toggle and button addresses (the
    current TouchOSC names a control ``/button1``) are buttons."""
    controls = _axes([f"/1/fader{i}" for i in range(1, 6)] + ["/3/xy:0", "/3/xy:1"])
    controls += _buttons([f"/{p}/toggle{i}" for p in range(1, 5) for i in range(1, 5)])
    controls += _buttons([f"/2/push{i}" for i in range(1, 17)])
    controls += _buttons([f"/4/multitoggle/{r}/{c}" for r in range(1, 9) for c in range(1, 9)])
    return OscProfile("touchosc", "TouchOSC (Simple layout)", tuple(controls),
                      ("*/push*", "*/toggle*", "*/multitoggle*", "*/multipush*", "*/button*", "*/z"))


def _openstage() -> OscProfile:
    """Open Stage Control widgets under their default addresses (``/`` + the widget id, ids
    numbered per type: ``/fader_1``, ``/knob_1``, ``/button_1``, ``/xy_1``)."""
    controls = _axes([f"/fader_{i}" for i in range(1, 9)] + [f"/knob_{i}" for i in range(1, 9)]
                     + ["/xy_1:0", "/xy_1:1"])
    controls += _buttons([f"/button_{i}" for i in range(1, 17)] + [f"/toggle_{i}" for i in range(1, 9)])
    return OscProfile("openstage", "Open Stage Control", tuple(controls), ("/button_*", "/toggle_*", "/switch_*"))


PROFILES: dict[str, OscProfile] = {
    "generic": OscProfile("generic", "OSC (generic addresses)"),
    "touchosc": _touchosc(),
    "openstage": _openstage(),
}


# ----------------------------------------------------------------------------------- parser
class OscParser:
    """Datagrams -> control events for one profile. Pure: fed bytes and a time."""

    def __init__(self, device: str, profile: OscProfile, warnings: WarningCounter | None = None) -> None:
        self.device = device
        self.profile = profile
        self.warnings = warnings or WarningCounter(device)
        self.future_bundles = 0
        self.last_address = ""
        self._down: dict[str, bool] = {}

    def feed(self, data: bytes, t: float) -> list[ControlEvent]:
        """Decode one datagram received at ``t``."""
        try:
            messages = decode_packet(data)
        except OscDecodeError as err:
            self.warnings.warn("garbage", f"not OSC ({err}): {data[:24]!r}")
            return []
        out: list[ControlEvent] = []
        future = False
        for m in messages:
            future |= is_future(m.timetag)
            self.message(m.address, m.args, t, out)
        self.future_bundles += future
        return out

    def message(self, address: str, args: tuple[Any, ...], t: float, out: list[ControlEvent]) -> None:
        """One message -> events appended to ``out``."""
        if len(address) > MAX_ADDRESS or not address.isprintable():
            self.warnings.warn("garbage", f"address too long or not printable: {address[:40]!r}")
            return
        if PATTERN_CHARS.intersection(address):
            self.warnings.warn("pattern", f"address pattern {address!r} refused: send plain addresses")
            return
        self.last_address = address
        nums = numbers(args)
        if not nums:
            if not args and self.profile.is_button(address):  # a "momentary" tap without a value
                self._button(address, True, t, out)
                self._button(address, False, t, out)
            return
        single = len(nums) == 1
        for i, v in enumerate(nums):
            name = address if single else f"{address}:{i}"
            if isinstance(v, bool) or self.profile.is_button(name):
                self._button(name, bool(v) if isinstance(v, bool) else v >= 0.5, t, out)
            else:
                self._axis(name, v, t, out)

    def _button(self, name: str, down: bool, t: float, out: list[ControlEvent]) -> None:
        if self._down.get(name, False) == down:
            return
        if name not in self._down and len(self._down) >= MAX_BUTTONS:
            self.warnings.warn("range", f"more than {MAX_BUTTONS} button addresses; {name!r} ignored")
            return
        self._down[name] = down
        out.append(ControlEvent(self.device, name, "button", 1.0 if down else 0.0, None, int(down), t))

    def _axis(self, name: str, v: float, t: float, out: list[ControlEvent]) -> None:
        if not math.isfinite(v) or abs(v) > HUGE:
            self.warnings.warn("range", f"{name} = {v!r} is not a usable number")
            return
        info = self.profile.declared(name)
        value = v
        if info is not None:
            span = info.hi - info.lo
            if not info.lo - SLACK * span <= v <= info.hi + SLACK * span:
                self.warnings.warn("range", f"{name} = {v:g} outside {info.lo:g}..{info.hi:g}; clamped")
            value = min(info.hi, max(info.lo, v))
        out.append(ControlEvent(self.device, name, "axis", value, None, v, t))


class OscDevice(UdpListenerDevice):
    """An OSC server. Options: ``profile`` (generic), ``lan``/``allow``/``max_size``/``max_rate``
    (see devices.udp)."""

    scheme = "osc"
    FORM = "osc://127.0.0.1:9000[?profile=generic|touchosc|openstage&lan=1&allow=ADDR,...]"
    OPTIONS = UdpListenerDevice.NET_OPTIONS | {"profile"}
    DEFAULT_PORT = 9000
    WHAT = "OSC"

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        name = spec.query.get("profile", "generic").lower()
        if name not in PROFILES:
            self.close()
            raise DeviceSpecError(f"{spec.text}: unknown profile {name!r}; expected one of {', '.join(PROFILES)}")
        self.profile = PROFILES[name]
        self.controls = list(self.profile.controls)
        self.parser = OscParser(self.spec, self.profile, self.warnings)
        self.description = f"{self.profile.description} on udp {self.host}:{self.port}"

    def _datagram(self, data: bytes, t: float, sender: str) -> list[ControlEvent]:
        return self.parser.feed(data, t)
