"""``can://INTERFACE/CHANNEL?dbc=FILE[&bitrate=N]`` — a control panel on a CAN bus.

Any python-can interface works (``socketcan/can0``, ``slcan//dev/ttyACM0``, ``virtual/panel``...).
Frames are decoded with cantools; every DBC signal becomes a control named after it. The kind comes
from a ``kind=button|dial|axis|ignore`` token in the signal's DBC comment, else 1-bit signals are
buttons and the rest axes. Dials are wrapping counters (``counts_per_turn=N`` in the comment); an
axis may carry ``negative_if=SIGNAL`` (J1939 joysticks send a magnitude plus a direction status).
Error frames and undecodable frames are counted and logged, never fatal; a bus that fails is
reopened like any lost device. Extended frames that match no DBC ID exactly are matched by their
J1939 PGN, so any source address works (and, for PDU1 messages, any destination address).
"""

from __future__ import annotations

import re
import time
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from devices.base import ControlInfo, Device
from devices.controlsets import DIAL_HI, DIAL_LO
from devices.errors import DeviceSpecError
from devices.events import ControlEvent
from devices.spec import DeviceSpec
from devices.warn import WarningCounter
from safefile import file_kind, not_a_file, quote

MAX_DBC_BYTES = 16 * 1024 * 1024

ERROR_CLASSES = {
    0x001: "TX timeout", 0x002: "lost arbitration", 0x004: "controller problem", 0x008: "protocol violation",
    0x010: "transceiver status", 0x020: "no ACK on transmission", 0x040: "bus off", 0x080: "bus error",
    0x100: "controller restarted",
}


def describe_error_frame(arbitration_id: int, data: bytes) -> str:
    """Linux can/error.h error classes of an error frame, in words."""
    names = [text for bit, text in ERROR_CLASSES.items() if arbitration_id & bit]
    if arbitration_id & 0x004 and len(data) > 1:
        flags = {0x01: "RX overflow", 0x02: "TX overflow", 0x04: "RX warning", 0x08: "TX warning",
                 0x10: "RX passive", 0x20: "TX passive"}
        names += [v for k, v in flags.items() if data[1] & k]
    return ", ".join(names) or f"error frame 0x{arbitration_id:x}"


def j1939_pgn(frame_id: int) -> int:
    """The J1939 parameter group number of a 29-bit ID. In the PDU1 format (PDU format byte below
    240) the PDU specific byte is the destination address, not part of the PGN: a panel sending to
    this host's address matched no DBC message written for the global address (0xFF), or for another."""
    pgn = (frame_id >> 8) & 0x3FFFF
    return pgn & 0x3FF00 if (pgn >> 8) & 0xFF < 240 else pgn


@dataclass
class _Sig:
    name: str
    kind: str
    signal: Any
    length: int
    counts_per_turn: int = 24
    lo: float = 0.0
    hi: float = 1.0
    minimum: float | None = None
    maximum: float | None = None
    negative_if: str | None = None


def _hints(comment: str | None) -> dict[str, str]:
    return dict(re.findall(r"(\w+)=([\w.]+)", comment or ""))


class CanDecoder:
    """Frames -> events for one DBC; emits changes only (panels re-send their whole state)."""

    def __init__(self, device: str, db: Any, warnings: WarningCounter | None = None) -> None:
        self.device = device
        self.db = db
        self.warnings = warnings or WarningCounter(device)
        self.bus_errors: Counter[str] = Counter()
        self.unknown_frames = 0
        self._by_id: dict[tuple[int, bool], Any] = {}
        self._by_pgn: dict[int, Any] = {}
        self._sigs: dict[str, list[_Sig]] = {}
        self._last: dict[str, float] = {}
        self._raw_last: dict[str, int] = {}
        self.controls: list[ControlInfo] = []
        self._plan()

    def _plan(self) -> None:
        taken: set[str] = set()
        for msg in self.db.messages:
            self._by_id[(msg.frame_id, bool(msg.is_extended_frame))] = msg
            if msg.is_extended_frame:
                self._by_pgn.setdefault(j1939_pgn(msg.frame_id), msg)
            sigs: list[_Sig] = []
            for sig in msg.signals:
                hints = _hints(sig.comment)
                kind = hints.get("kind") or ("button" if sig.length == 1 else "axis")
                if kind == "ignore":
                    continue
                if kind not in ("button", "dial", "axis"):
                    raise DeviceSpecError(f"{self.device}: signal {sig.name}: unknown kind={kind}")
                name = sig.name if sig.name not in taken else f"{msg.name}.{sig.name}"
                taken.add(name)
                s = _Sig(name, kind, sig, sig.length)
                if kind == "dial":
                    s.counts_per_turn = int(hints.get("counts_per_turn", 24))
                    s.lo, s.hi = DIAL_LO, DIAL_HI
                elif kind == "axis":
                    lo_raw, hi_raw = (-(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1) if sig.is_signed \
                        else (0, (1 << sig.length) - 1)
                    a, b = sig.offset + sig.scale * lo_raw, sig.offset + sig.scale * hi_raw
                    s.minimum = sig.minimum if sig.minimum is not None else min(a, b)
                    s.maximum = sig.maximum if sig.maximum is not None else max(a, b)
                    s.negative_if = hints.get("negative_if")
                    s.lo = -1.0 if (s.minimum < 0 or s.negative_if) else 0.0
                sigs.append(s)
                self.controls.append(ControlInfo(name, kind, s.lo, s.hi))  # type: ignore[arg-type]
            self._sigs[msg.name] = sigs

    def _message(self, frame_id: int, extended: bool) -> Any:
        msg = self._by_id.get((frame_id, extended))
        if msg is None and extended:
            msg = self._by_pgn.get(j1939_pgn(frame_id))
        return msg

    def decode(self, frame: Any, t: float) -> list[ControlEvent]:
        """One python-can Message."""
        if frame.is_error_frame:
            text = describe_error_frame(frame.arbitration_id, bytes(frame.data))
            self.bus_errors[text] += 1
            self.warnings.warn("bus-error", f"CAN {text}")
            return []
        if frame.is_remote_frame:
            return []
        msg = self._message(frame.arbitration_id, frame.is_extended_id)
        if msg is None:
            self.unknown_frames += 1
            return []
        try:
            raw = msg.decode(bytes(frame.data), decode_choices=False, scaling=False)
        except Exception as err:  # cantools DecodeError, short frames: a DBC that does not match
            self.warnings.warn("decode", f"frame 0x{frame.arbitration_id:x} ({msg.name}) does not match the DBC: {err}")
            return []
        out: list[ControlEvent] = []
        for s in self._sigs[msg.name]:
            value = raw.get(s.signal.name)
            if isinstance(value, (int, float)):
                self._signal(s, value, raw, t, out)
        return out

    def _signal(self, s: _Sig, value: float, raw: dict[str, Any], t: float, out: list[ControlEvent]) -> None:
        if s.kind == "button":
            if value in (0, 1):
                self._emit(s.name, "button", float(value), None, value, t, out)
            elif s.length == 2 and value == 3:
                pass  # J1939 "not available"
            else:
                self.warnings.warn("range", f"{s.name}={value} is not a button state (J1939 2 = error)")
        elif s.kind == "dial":
            iv = int(value)
            last, self._raw_last[s.name] = self._raw_last.get(s.name), iv
            if last is None or iv == last:
                return
            half, full = 1 << (s.length - 1), 1 << s.length
            delta = ((iv - last + half) % full) - half
            if abs(delta) > s.counts_per_turn:
                self.warnings.warn("range", f"{s.name} jumped {delta} counts; resynchronised")
                return
            out.append(ControlEvent(self.device, s.name, "dial", delta / s.counts_per_turn, float(delta), iv, t))
        else:
            phys = s.signal.offset + s.signal.scale * value
            assert s.minimum is not None and s.maximum is not None
            if not s.minimum <= phys <= s.maximum:
                self.warnings.warn("range", f"{s.name}={phys:g} outside {s.minimum:g}..{s.maximum:g}")
                return
            span = (s.maximum - s.minimum) or 1.0
            unit = (phys - s.minimum) / span
            norm = 2 * unit - 1 if s.minimum < 0 else unit
            if s.negative_if and raw.get(s.negative_if) == 1:
                norm = -norm
            self._emit(s.name, "axis", max(s.lo, min(s.hi, norm)), None, value, t, out)

    def _emit(self, name: str, kind: str, value: float, delta: float | None, raw: float, t: float,
              out: list[ControlEvent]) -> None:
        if self._last.get(name, 0.0 if kind == "button" else None) == value:
            return
        self._last[name] = value
        out.append(ControlEvent(self.device, name, kind, value, delta, raw, t))  # type: ignore[arg-type]


def load_dbc(path: str, spec: str) -> Any:
    """cantools database from a DBC (or KCD/SYM/ARXML) file, with a one-line error."""
    import cantools

    if not path:
        raise DeviceSpecError(f"{spec}: a DBC file is needed: can://INTERFACE/CHANNEL?dbc=FILE")
    if file_kind(path) in ("folder", "other"):  # a device such as /dev/zero was read until memory ran out
        raise DeviceSpecError(f"{spec}: {not_a_file(path, 'DBC file')}")
    try:
        if Path(path).is_file() and Path(path).stat().st_size > MAX_DBC_BYTES:
            raise DeviceSpecError(f"{spec}: DBC file {Path(path).name} is larger than "
                                  f"{MAX_DBC_BYTES // (1024 * 1024)} MB; is it the right file?")
        return cantools.database.load_file(path)
    except DeviceSpecError:
        raise
    except FileNotFoundError as err:
        raise DeviceSpecError(f"{spec}: DBC file {path} not found") from err
    except Exception as err:  # cantools raises many types for a damaged file: one short line
        msg = str(err)
        m = re.search(r"line (\d+), column (\d+)", msg)
        where = f"{Path(path).name}:{m.group(1)}:{m.group(2)}: syntax error" if m else \
            f"{Path(path).name}: {quote(msg.splitlines()[0] if msg else type(err).__name__, 100)}"
        raise DeviceSpecError(f"{spec}: cannot load DBC file {where}") from err


class CanDevice(Device):
    """A CAN panel. Options: ``dbc`` (required), ``bitrate``; other python-can settings come from
    python-can's own configuration files."""

    scheme = "can"
    FORM = "can://INTERFACE/CHANNEL?dbc=FILE[&bitrate=N]"
    OPTIONS = frozenset({"dbc", "bitrate"})

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        interface, sep, channel = spec.location.partition("/")
        if not interface or not sep or not channel:
            raise DeviceSpecError(f"{spec.text}: expected {self.FORM}, e.g. can://socketcan/can0?dbc=panel.dbc")
        self.interface, self.channel = interface, channel
        self.bitrate = spec.get_int("bitrate", 0, lo=0) or None
        self.decoder = CanDecoder(self.spec, load_dbc(spec.query.get("dbc", ""), spec.text), self.warnings)
        self.controls = list(self.decoder.controls)
        self.description = f"CAN panel on {interface} {channel} ({Path(spec.query['dbc']).name})"
        self._bus: Any = None

    @property
    def bus_errors(self) -> Counter[str]:
        """Error frames seen so far, by kind."""
        return self.decoder.bus_errors

    def _open(self) -> None:
        import can

        kwargs: dict[str, Any] = {"interface": self.interface, "channel": self.channel}
        if self.bitrate:
            kwargs["bitrate"] = self.bitrate
        self._close_handle()
        self._bus = can.Bus(**kwargs)

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        bus = self._bus
        if bus is None:
            raise OSError("bus not open")
        frame = bus.recv(timeout)
        t = time.monotonic()
        if frame is None:
            return ()
        return self.decoder.decode(frame, t)

    def _close_handle(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            bus.shutdown()
