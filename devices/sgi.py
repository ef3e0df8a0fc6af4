"""``sgi://PORT`` — the SGI dial-and-button box (8 dials, 32 lit buttons) on a 9600 8N1 line.

Protocol (see docs/devices.md; sources: VRPN vrpn_raw_sgibox, XFree86 xf86Dial, IRIX dial.c):
host sends reset ``0x20`` and waits for ``0x20``; then ``0x50 FF FF`` (dials first: enabling dials
disables buttons), ``0x71 FF*4`` + ``0x73 FF*4`` twice (the box sometimes misses the first), and
``0x75`` + 4 LED bytes, one byte per millisecond. The box sends ``0x30+n HI LO`` (int16 absolute
dial counter), ``0xC0+k``/``0xE0+k`` for press/release of button ``k ^ 0x18``, and ``0x20`` when it
was reset.
"""

from __future__ import annotations

import time
from typing import Any

from devices.controlsets import sgi_controls
from devices.events import ControlEvent
from devices.serialport import SerialPortDevice
from devices.spec import DeviceSpec
from devices.warn import WarningCounter

RESET = 0x20
DIAL_BASE = 0x30
PRESS_BASE = 0xC0
RELEASE_BASE = 0xE0
ENABLE_DIALS = bytes([0x50, 0xFF, 0xFF])
ENABLE_BUTTONS = bytes([0x71, 0xFF, 0xFF, 0xFF, 0xFF, 0x73, 0xFF, 0xFF, 0xFF, 0xFF])
SET_LEDS = 0x75
#: Unexpected bytes tolerated before the box is re-initialised (XFree86/IRIX use 5).
MAX_GARBAGE = 5


def button_index(code: int) -> int:
    """Button number (0..31) of a press (0xC0..0xDF) or release (0xE0..0xFF) code."""
    return ((code - PRESS_BASE) & 0x1F) ^ 0x18


def button_code(index: int, pressed: bool) -> int:
    """Inverse of ``button_index``: the byte the box sends for button ``index``."""
    return (PRESS_BASE if pressed else RELEASE_BASE) + (index ^ 0x18)


def led_bytes(mask: int) -> bytes:
    """The ``0x75`` command for a 32-bit LED mask (bit i = button i)."""
    return bytes([SET_LEDS, mask & 0xFF, (mask >> 8) & 0xFF, (mask >> 16) & 0xFF, (mask >> 24) & 0xFF])


class SgiParser:
    """Bytes -> events. A 3-state machine: after ``0x3n`` exactly two value bytes follow, whatever
    they look like. ``needs_reinit`` is raised after garbage or an unexpected reset byte."""

    def __init__(self, device: str, counts_per_turn: int = 200, warnings: WarningCounter | None = None) -> None:
        self.device = device
        self.counts_per_turn = counts_per_turn
        self.warnings = warnings or WarningCounter(device)
        self.needs_reinit = False
        self._dial = -1
        self._hi = -1
        self._garbage = 0
        self.reset_state()

    def reset_state(self, buttons: bool = True) -> None:
        """Forget the dial counters (the box zeroes them on reset) and, on a fresh connection, the
        buttons; a re-init keeps button states so a release after it still arrives."""
        self._last: list[int | None] = [0] * 8
        self._fresh = [True] * 8
        if buttons or not hasattr(self, "_down"):
            self._down = [False] * 32
        self._dial = -1
        self._hi = -1
        self._garbage = 0
        self.needs_reinit = False

    def feed(self, data: bytes, t: float) -> list[ControlEvent]:
        """Decode a chunk; partial packets are kept for the next chunk."""
        out: list[ControlEvent] = []
        for b in data:
            if self._dial >= 0:
                if self._hi < 0:
                    self._hi = b
                    continue
                self._dial_report(self._dial, (self._hi << 8) | b, t, out)
                self._dial, self._hi = -1, -1
            elif DIAL_BASE <= b <= DIAL_BASE + 7:
                self._dial = b - DIAL_BASE
            elif b >= PRESS_BASE:
                self._button(b, t, out)
            elif b == RESET:
                self.warnings.warn("reset", "box sent an unexpected reset; re-initialising")
                self.needs_reinit = True
            else:
                self._garbage += 1
                self.warnings.warn("garbage", f"unexpected byte 0x{b:02x} (wrong baud rate or line noise?)")
                if self._garbage > MAX_GARBAGE:
                    self.needs_reinit = True
        return out

    def _dial_report(self, n: int, raw: int, t: float, out: list[ControlEvent]) -> None:
        self._garbage = 0
        value = raw - 0x10000 if raw & 0x8000 else raw
        last = self._last[n]
        delta = ((value - (last or 0) + 0x8000) & 0xFFFF) - 0x8000  # int16 wrap-around
        self._last[n] = value
        fresh, self._fresh[n] = self._fresh[n], False
        if abs(delta) > self.counts_per_turn:  # more than a turn in 3 ms: not a real movement
            if not fresh:
                self.warnings.warn("range", f"dial{n} jumped {delta} counts; resynchronised")
            return
        if delta:
            out.append(ControlEvent(self.device, f"dial{n}", "dial", delta / self.counts_per_turn,
                                    float(delta), value, t))

    def _button(self, code: int, t: float, out: list[ControlEvent]) -> None:
        self._garbage = 0
        k = button_index(code)
        pressed = code < RELEASE_BASE
        if self._down[k] == pressed:
            return  # a repeated state (e.g. a release after a re-init) changes nothing
        self._down[k] = pressed
        out.append(ControlEvent(self.device, f"button{k}", "button", 1.0 if pressed else 0.0, None, code, t))


class SgiDevice(SerialPortDevice):
    """The SGI box. Options: ``counts_per_turn`` (default 200), ``pace_ms`` (default 1)."""

    scheme = "sgi"
    FORM = "sgi://PORT[?counts_per_turn=N&pace_ms=MS]"
    OPTIONS = frozenset({"counts_per_turn", "pace_ms", "baud"})
    BAUDRATE = 9600
    RESET_TRIES = 5
    RESET_WAIT = 0.5
    ACK_SETTLE = 0.05

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        self.description = f"SGI dial-and-button box on {self.path}"
        self.controls = sgi_controls()
        cpt = spec.get_int("counts_per_turn", 200, lo=1, hi=32767)
        self.pace = spec.get_float("pace_ms", 1.0, lo=0.0) / 1000.0
        self.parser = SgiParser(self.spec, cpt, self.warnings)
        self._led_mask = 0
        self._leds_sent: int | None = None

    def _handshake(self) -> None:
        """Reset (with retries), then enable dials before buttons, buttons twice, then the LEDs."""
        for _ in range(self.RESET_TRIES):
            self._port.reset_input_buffer()
            self.write(bytes([RESET]))
            if self._wait_for_ack(self.RESET_WAIT):
                break
        else:
            raise OSError(f"{self.path}: no SGI box answered the reset (0x20)")
        # both units on the line answer; let the second ack arrive before it could look like a reset
        self._wait_for_ack(self.ACK_SETTLE, settle=True)
        reinit = self.parser.needs_reinit
        self.write(ENABLE_DIALS + ENABLE_BUTTONS + ENABLE_BUTTONS, pace=self.pace)
        mask = self._led_mask
        self.write(led_bytes(mask), pace=self.pace)
        self._leds_sent = mask
        self.parser.reset_state(buttons=not reinit)

    def _wait_for_ack(self, seconds: float, settle: bool = False) -> bool:
        """Read until a 0x20 arrives (or, with ``settle``, until the time is up); other bytes are
        reports from before the reset and are dropped."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            if self.closing:
                raise OSError("device is closing")
            data, _t = self.read_raw(max(0.001, left))
            if RESET in data and not settle:
                return True
        return False

    def _before_read(self) -> None:
        if self.parser.needs_reinit:
            self._handshake()
        if self._leds_sent != self._led_mask:
            mask = self._led_mask
            self.write(led_bytes(mask), pace=self.pace)
            self._leds_sent = mask

    def _parse(self, data: bytes, t: float) -> list[ControlEvent]:
        return self.parser.feed(data, t)

    def _set_light(self, control: str, level: float) -> None:
        """Queue the new LED mask; the reader thread sends it paced, so callers never block."""
        k = int(control.removeprefix("button"))
        if level >= 0.5:
            self._led_mask |= 1 << k
        else:
            self._led_mask &= ~(1 << k)
        self._wake()
