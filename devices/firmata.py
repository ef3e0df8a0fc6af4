"""``firmata://PORT`` — an Arduino running StandardFirmata as a DIY control box.

Analog inputs become axes (``axis0`` = A0, normalised by the ADC resolution), digital pins become
buttons (``button2`` = D2, pull-ups on, pressed = low), and FirmataEncoder reports become dials.

Why our own parser rather than pyfirmata2: pyfirmata2 sleeps a fixed 5 s on every open, runs its own
polling iterator thread over its own ``serial.Serial``, hands out values without read timestamps, has no notion of a lost and
reopened port, and knows nothing of encoders. The protocol subset a control box needs is small
(MIDI-style framing, three message types, a few sysex replies), so it is parsed here in the one
reader thread, with the same latency, hot-plug and bad-input behaviour as the other serial boxes.
"""

from __future__ import annotations

import time
from typing import Any

from devices.base import ControlInfo
from devices.controlsets import DIAL_HI, DIAL_LO
from devices.errors import DeviceSpecError
from devices.events import ControlEvent
from devices.serialport import SerialPortDevice
from devices.spec import DeviceSpec
from devices.warn import WarningCounter

ANALOG, DIGITAL, VERSION = 0xE0, 0x90, 0xF9
SYSEX_START, SYSEX_END = 0xF0, 0xF7
REPORT_FIRMWARE, SAMPLING_INTERVAL, STRING_DATA, ENCODER = 0x79, 0x7A, 0x71, 0x61
SET_PIN_MODE, REPORT_ANALOG, REPORT_DIGITAL = 0xF4, 0xC0, 0xD0
MODE_INPUT, MODE_PULLUP = 0x00, 0x0B
MAX_SYSEX = 1024


def parse_pins(text: str, spec: str, key: str) -> list[int]:
    """``"0-5"`` or ``"2,3,7"`` (or empty) -> pin numbers."""
    pins: list[int] = []
    try:
        for part in filter(None, text.split(",")):
            lo, _, hi = part.partition("-")
            pins.extend(range(int(lo), int(hi or lo) + 1))
    except ValueError as err:
        raise DeviceSpecError(f"{spec}: option {key}={text!r} must look like 0-5 or 2,3,7") from err
    if any(not 0 <= p < 128 for p in pins):
        raise DeviceSpecError(f"{spec}: option {key}: pins are 0..127")
    return sorted(set(pins))


def seven_bit(value: int) -> bytes:
    """A 14-bit value as Firmata's (lsb7, msb7) pair."""
    return bytes([value & 0x7F, (value >> 7) & 0x7F])


class FirmataParser:
    """Bytes -> events. Command bytes have bit 7 set, so a truncated message is noticed when the
    next command starts; stray data bytes are counted and skipped."""

    def __init__(self, device: str, analog: list[int], digital: list[int], pullup: bool = True,
                 bits: int = 10, counts_per_turn: int = 96, warnings: WarningCounter | None = None) -> None:
        self.device = device
        self.analog = set(analog)
        self.digital = set(digital)
        self.pullup = pullup
        self.max_analog = (1 << bits) - 1
        self.counts_per_turn = counts_per_turn
        self.warnings = warnings or WarningCounter(device)
        self.version: tuple[int, int] | None = None
        self.firmware = ""
        self._cmd = -1
        self._data = bytearray()
        self.reset_state()

    def reset_state(self) -> None:
        """Forget the last values: after a reconnect the board reports everything again."""
        self._analog_last: dict[int, int] = {}
        self._pressed: dict[int, bool] = {}
        self._enc_last: dict[int, int] = {}
        self._cmd = -1
        self._data.clear()

    def feed(self, data: bytes, t: float) -> list[ControlEvent]:
        out: list[ControlEvent] = []
        for b in data:
            if b & 0x80:
                if self._cmd == SYSEX_START and b == SYSEX_END:
                    self._sysex(bytes(self._data), t, out)
                    self._cmd = -1
                    continue
                if self._cmd >= 0:
                    self.warnings.warn("truncated", f"message 0x{self._cmd:02x} cut short by 0x{b:02x}")
                self._cmd = b
                self._data.clear()
                if b not in (SYSEX_START, VERSION) and (b & 0xF0) not in (ANALOG, DIGITAL):
                    self.warnings.warn("garbage", f"unexpected command byte 0x{b:02x}")
                    self._cmd = -1
                continue
            if self._cmd < 0:
                self.warnings.warn("garbage", f"stray data byte 0x{b:02x} (wrong baud rate?)")
                continue
            self._data.append(b)
            if self._cmd == SYSEX_START:
                if len(self._data) > MAX_SYSEX:
                    self.warnings.warn("garbage", "over-long sysex dropped")
                    self._cmd = -1
                continue
            if len(self._data) == 2:
                self._message(self._cmd, self._data[0] | self._data[1] << 7, t, out)
                self._cmd = -1
        return out

    def _message(self, cmd: int, value: int, t: float, out: list[ControlEvent]) -> None:
        if cmd == VERSION:
            self.version = (value & 0x7F, value >> 7)
            return
        channel = cmd & 0x0F
        if cmd & 0xF0 == ANALOG:
            if channel not in self.analog:
                return
            if value > self.max_analog:
                self.warnings.warn("range", f"A{channel}={value} exceeds {self.max_analog} (set ?bits=)")
                return
            if self._analog_last.get(channel) != value:
                self._analog_last[channel] = value
                out.append(ControlEvent(self.device, f"axis{channel}", "axis", value / self.max_analog, None, value, t))
            return
        for bit in range(8):  # a digital port message: pins 8*port .. 8*port+7
            pin = channel * 8 + bit
            if pin not in self.digital:
                continue
            level = (value >> bit) & 1
            pressed = (level == 0) if self.pullup else (level == 1)
            if self._pressed.get(pin, False) != pressed:
                self._pressed[pin] = pressed
                out.append(ControlEvent(self.device, f"button{pin}", "button", float(pressed), None, level, t))

    def _sysex(self, payload: bytes, t: float, out: list[ControlEvent]) -> None:
        if not payload:
            return
        kind, body = payload[0], payload[1:]
        if kind == REPORT_FIRMWARE and len(body) >= 2:
            self.version = (body[0], body[1])
            chars = body[2:]
            self.firmware = "".join(chr(chars[i] | (chars[i + 1] << 7)) for i in range(0, len(chars) - 1, 2))
        elif kind == ENCODER:
            if len(body) % 5:
                self.warnings.warn("truncated", f"encoder report of {len(body)} bytes")
                return
            for i in range(0, len(body), 5):
                head, mag = body[i], body[i + 1] | body[i + 2] << 7 | body[i + 3] << 14 | body[i + 4] << 21
                self._encoder(head & 0x3F, -mag if head & 0x40 else mag, t, out)

    def _encoder(self, n: int, pos: int, t: float, out: list[ControlEvent]) -> None:
        last = self._enc_last.get(n)
        self._enc_last[n] = pos
        if last is None or pos == last:
            return
        delta = pos - last
        if abs(delta) > self.counts_per_turn:
            self.warnings.warn("range", f"encoder {n} jumped {delta} counts; resynchronised")
            return
        out.append(ControlEvent(self.device, f"dial{n}", "dial", delta / self.counts_per_turn, float(delta), pos, t))


class FirmataDevice(SerialPortDevice):
    """StandardFirmata board. Options: ``baud`` (57600), ``analog`` (0-5), ``digital`` (2-12),
    ``pullup`` (1), ``bits`` (10; 12 or 14 for boards with wider ADCs), ``interval`` (ms, 10),
    ``encoders`` (``2:3,4:5`` = pin pairs of FirmataEncoder dials), ``counts_per_turn`` (96),
    ``boot_wait`` (s to wait for the board after the open resets it, 4)."""

    scheme = "firmata"
    FORM = "firmata://PORT[?baud=57600&analog=0-5&digital=2-12&pullup=1&bits=10&interval=10&encoders=2:3]"
    OPTIONS = frozenset({"baud", "analog", "digital", "pullup", "bits", "interval", "encoders",
                         "counts_per_turn", "boot_wait"})
    BAUDRATE = 57600

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        q = spec.query
        self.analog = parse_pins(q.get("analog", "0-5"), spec.text, "analog")
        self.digital = parse_pins(q.get("digital", "2-12"), spec.text, "digital")
        self.pullup = spec.get_bool("pullup", True)
        bits = spec.get_int("bits", 10, lo=1, hi=14)
        self.interval = spec.get_int("interval", 10, lo=1, hi=16383)
        self.boot_wait = spec.get_float("boot_wait", 4.0, lo=0.1)
        self.encoders: list[tuple[int, int]] = []
        for pair in filter(None, q.get("encoders", "").split(",")):
            a, _, b = pair.partition(":")
            try:
                self.encoders.append((int(a), int(b)))
            except ValueError as err:
                raise DeviceSpecError(f"{spec.text}: encoders={q['encoders']!r} must look like 2:3,4:5") from err
        cpt = spec.get_int("counts_per_turn", 96, lo=1)
        self.parser = FirmataParser(self.spec, self.analog, self.digital, self.pullup, bits, cpt, self.warnings)
        self.controls = (
            [ControlInfo(f"axis{n}", "axis", 0.0, 1.0) for n in self.analog]
            + [ControlInfo(f"button{p}", "button", 0.0, 1.0) for p in self.digital]
            + [ControlInfo(f"dial{i}", "dial", DIAL_LO, DIAL_HI) for i in range(len(self.encoders))]
        )
        self.description = f"Firmata board on {self.path}"

    def _handshake(self) -> None:
        """Ask for the version until the board (just reset by the open) answers, then configure."""
        self.parser.version = None
        deadline = time.monotonic() + self.boot_wait
        next_query = 0.0
        while self.parser.version is None:
            now = time.monotonic()
            if self.closing:
                raise OSError("device is closing")
            if now >= deadline:
                raise OSError(f"{self.path}: no Firmata board answered the version query")
            if now >= next_query:
                self.write(bytes([VERSION, SYSEX_START, REPORT_FIRMWARE, SYSEX_END]))
                next_query = now + 0.5
            data, t = self.read_raw(min(0.05, deadline - now))
            self.parser.feed(data, t)
        time.sleep(0.02)  # let the firmware-name reply finish before the stream starts
        data, t = self.read_raw(0.001)
        self.parser.feed(data, t)
        if self.parser.firmware:
            self.description = f"{self.parser.firmware} {self.parser.version[0]}.{self.parser.version[1]} on {self.path}"
        self.parser.reset_state()
        out = bytearray([SYSEX_START, SAMPLING_INTERVAL, *seven_bit(self.interval), SYSEX_END])
        for pin in self.digital:
            out += bytes([SET_PIN_MODE, pin, MODE_PULLUP if self.pullup else MODE_INPUT])
        for port in sorted({p // 8 for p in self.digital}):
            out += bytes([REPORT_DIGITAL | port, 1])
        for n in self.analog:
            out += bytes([REPORT_ANALOG | n, 1])
        for i, (a, b) in enumerate(self.encoders):
            out += bytes([SYSEX_START, ENCODER, 0x00, i, a, b, SYSEX_END])
        if self.encoders:
            out += bytes([SYSEX_START, ENCODER, 0x04, 0x01, SYSEX_END])
        self.write(bytes(out))

    def _parse(self, data: bytes, t: float) -> list[ControlEvent]:
        return self.parser.feed(data, t)
