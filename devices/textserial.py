"""``serial://PORT?baud=N`` — a tiny text protocol so anyone can build a box with a few lines of
firmware (see examples/arduino_textbox/arduino_textbox.ino and docs/devices.md).

Box -> host, one ASCII line per change (``\\n`` or ``\\r\\n``):
``B<n> 1`` / ``B<n> 0`` button n pressed/released; ``D<n> +5`` dial n turned by signed counts;
``A<n> 0.731`` axis n at a position in 0..1; ``H <name>`` optional hello; ``# ...`` comments.
Host -> box: ``L<n> 1`` / ``L<n> 0`` light of button n.
"""

from __future__ import annotations

import math
from typing import Any

from devices.controlsets import text_controls
from devices.events import ControlEvent
from devices.serialport import SerialPortDevice
from devices.spec import DeviceSpec
from devices.warn import WarningCounter

MAX_LINE = 80
#: Axis values a little outside 0..1 (ADC offsets) are clamped; beyond this they are rejected.
AXIS_SLACK = 0.05


class TextParser:
    """Bytes -> events for the text protocol; ``hello`` keeps the box's self-description."""

    def __init__(self, device: str, n_buttons: int = 16, n_dials: int = 8, n_axes: int = 8,
                 counts_per_turn: int = 24, warnings: WarningCounter | None = None) -> None:
        self.device = device
        self.limits = {"B": n_buttons, "D": n_dials, "A": n_axes}
        self.counts_per_turn = counts_per_turn
        self.warnings = warnings or WarningCounter(device)
        self.hello = ""
        self._buf = bytearray()
        self._overflow = False
        self._down: dict[int, bool] = {}

    def feed(self, data: bytes, t: float) -> list[ControlEvent]:
        """Decode a chunk; a partial last line waits for the next chunk."""
        out: list[ControlEvent] = []
        for b in data:
            if b == 0x0A:
                if self._overflow:
                    self.warnings.warn("garbage", "over-long line dropped")
                else:
                    self._line(bytes(self._buf), t, out)
                self._buf.clear()
                self._overflow = False
            elif not self._overflow:
                self._buf.append(b)
                if len(self._buf) > MAX_LINE:
                    self._overflow = True
                    self._buf.clear()
        return out

    def _bad(self, kind: str, line: bytes, why: str) -> None:
        self.warnings.warn(kind, f"{why}: {line[:40]!r}")

    def _line(self, raw: bytes, t: float, out: list[ControlEvent]) -> None:
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            self._bad("garbage", raw, "not ASCII (wrong baud rate?)")
            return
        if not line or line.startswith("#"):
            return
        if line.startswith("H"):
            self.hello = line[1:].strip()
            return
        head, _, arg = line.partition(" ")
        kind, index_text = head[:1], head[1:]
        if kind not in self.limits or not index_text.isdigit() or not arg:
            self._bad("garbage", raw, "not a B/D/A line")
            return
        n = int(index_text)
        if n >= self.limits[kind]:
            self._bad("range", raw, f"no control {kind}{n} declared (see the buttons/dials/axes options)")
            return
        try:
            if "_" in arg:  # Python reads "1_0" as 10 (digits grouped); the protocol has no such numbers
                raise ValueError(arg)
            value = float(arg) if kind == "A" else int(arg.strip(), 10)
        except ValueError:
            self._bad("garbage", raw, "bad number")
            return
        if kind == "B":
            self._button(n, value, raw, t, out)
        elif kind == "D":
            if value == 0:
                return
            if abs(value) > self.counts_per_turn:
                self._bad("range", raw, "dial step larger than a turn")
                return
            out.append(ControlEvent(self.device, f"dial{n}", "dial", value / self.counts_per_turn,
                                    float(value), int(value), t))
        else:
            if not math.isfinite(value) or not -AXIS_SLACK <= value <= 1 + AXIS_SLACK:
                self._bad("range", raw, "axis value outside 0..1")
                return
            out.append(ControlEvent(self.device, f"axis{n}", "axis", min(1.0, max(0.0, value)), None, value, t))

    def _button(self, n: int, value: float, raw: bytes, t: float, out: list[ControlEvent]) -> None:
        if value not in (0, 1):
            self._bad("range", raw, "button value must be 0 or 1")
            return
        pressed = value == 1
        if self._down.get(n, False) == pressed:  # buttons start released
            return
        self._down[n] = pressed
        out.append(ControlEvent(self.device, f"button{n}", "button", float(value), None, int(value), t))


class TextSerialDevice(SerialPortDevice):
    """A home-made box on a serial port. Options: ``baud`` (115200), ``buttons`` (16), ``dials``
    (8), ``axes`` (8), ``counts_per_turn`` (24, a common detented encoder)."""

    scheme = "serial"
    FORM = "serial://PORT[?baud=N&buttons=N&dials=N&axes=N&counts_per_turn=N]"
    OPTIONS = frozenset({"baud", "buttons", "dials", "axes", "counts_per_turn"})
    BAUDRATE = 115200

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        nb = spec.get_int("buttons", 16, lo=0, hi=256)
        nd = spec.get_int("dials", 8, lo=0, hi=256)
        na = spec.get_int("axes", 8, lo=0, hi=256)
        cpt = spec.get_int("counts_per_turn", 24, lo=1, hi=1_000_000)
        self.controls = text_controls(nb, nd, na)
        self.parser = TextParser(self.spec, nb, nd, na, cpt, self.warnings)
        self.description = f"text-protocol box on {self.path}"

    def _handshake(self) -> None:
        self._port.reset_input_buffer()
        self.parser._buf.clear()

    def _parse(self, data: bytes, t: float) -> list[ControlEvent]:
        events = self.parser.feed(data, t)
        if self.parser.hello:
            self.description = f"{self.parser.hello} (text protocol on {self.path})"
        return events

    def _set_light(self, control: str, level: float) -> None:
        self.send_later(f"L{control.removeprefix('button')} {1 if level >= 0.5 else 0}\n".encode("ascii"))
