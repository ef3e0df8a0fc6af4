"""Decoders for HID boxes whose reports are vendor-defined, so their descriptors say too little:
Griffin PowerMate, Contour ShuttleXpress/ShuttlePro, P.I. Engineering X-keys. Byte layouts are in
docs/devices.md with their sources (Linux powermate.c, VRPN, node-xkeys)."""

from __future__ import annotations

from dataclasses import dataclass

from devices.base import ControlInfo
from devices.controlsets import buttons, powermate_controls, shuttle_controls
from devices.events import ControlEvent
from devices.warn import WarningCounter

GRIFFIN, CONTOUR, PIENG = 0x077D, 0x0B33, 0x05F3


@dataclass(frozen=True)
class Command:
    """A host->device transfer: an output report (``write``) or a feature report."""

    kind: str  # "write" | "feature"
    data: bytes


def _s8(b: int) -> int:
    return b - 256 if b & 0x80 else b


class Profile:
    """Base of the per-product decoders."""

    name = "profile"
    report_size = 64

    def __init__(self, device: str, warnings: WarningCounter, counts_per_turn: int | None = None) -> None:
        self.device = device
        self.warnings = warnings
        self.controls: list[ControlInfo] = []
        self._down: dict[str, bool] = {}

    def decode(self, report: bytes, t: float) -> list[ControlEvent]:
        raise NotImplementedError

    def init_commands(self) -> list[Command]:
        return []

    def light(self, control: str, level: float) -> list[Command]:
        return []

    def _button(self, name: str, pressed: bool, raw: int, t: float, out: list[ControlEvent]) -> None:
        if self._down.get(name, False) != pressed:
            self._down[name] = pressed
            out.append(ControlEvent(self.device, name, "button", float(pressed), None, raw, t))


class PowerMateProfile(Profile):
    """Knob (int8 delta at byte 1), push button (bit 0 of byte 0), LED brightness and pulse through
    the 9-byte feature report ``00 41 01 cmd 00 arg_lo arg_hi 00 00``."""

    name = "Griffin PowerMate"
    report_size = 8

    def __init__(self, device: str, warnings: WarningCounter, counts_per_turn: int | None = None) -> None:
        super().__init__(device, warnings)
        self.counts_per_turn = counts_per_turn or 94  # Linux powermate.c: about 94 clicks a turn
        self.controls = powermate_controls()

    def decode(self, report: bytes, t: float) -> list[ControlEvent]:
        if len(report) < 3:
            self.warnings.warn("truncated", f"PowerMate report of {len(report)} bytes")
            return []
        out: list[ControlEvent] = []
        self._button("button0", bool(report[0] & 0x01), report[0], t, out)
        delta = _s8(report[1])
        if abs(delta) > self.counts_per_turn:
            self.warnings.warn("range", f"knob step {delta} is larger than a turn")
        elif delta:
            out.append(ControlEvent(self.device, "knob", "dial", delta / self.counts_per_turn, float(delta), delta, t))
        return out

    @staticmethod
    def feature(cmd: int, arg: int) -> Command:
        return Command("feature", bytes([0x00, 0x41, 0x01, cmd, 0x00, arg & 0xFF, (arg >> 8) & 0xFF, 0x00, 0x00]))

    def light(self, control: str, level: float) -> list[Command]:
        return [self.feature(0x03, 0), self.feature(0x01, round(level * 255))]

    def pulse(self, on: bool, speed: int = 255) -> list[Command]:
        """Pulse the LED while awake; ``speed`` 0..510, 255 = normal (the kernel's encoding)."""
        speed = max(0, min(510, speed))
        op, arg = (0, 255 - speed) if speed < 255 else ((2, speed - 255) if speed > 255 else (1, 0))
        return [self.feature(0x04, arg << 8 | op), self.feature(0x03, int(on))]


class ShuttleProfile(Profile):
    """5-byte report: shuttle int8 -7..7, jog uint8 counter, 0, buttons uint16 LE. The device
    re-sends its whole state on each change, so jog and buttons are diffed."""

    XPRESS_MASKS = (0x0010, 0x0020, 0x0040, 0x0080, 0x0100)

    def __init__(self, device: str, warnings: WarningCounter, counts_per_turn: int | None = None,
                 pro: bool = False) -> None:
        super().__init__(device, warnings)
        self.name = "Contour ShuttlePro" if pro else "Contour ShuttleXpress"
        self.masks = tuple(1 << i for i in range(15)) if pro else self.XPRESS_MASKS
        self.controls = shuttle_controls(len(self.masks))
        self.counts_per_turn = counts_per_turn or 10  # ten detents on the jog wheel
        self._jog: int | None = None
        self._shuttle: int | None = None

    def decode(self, report: bytes, t: float) -> list[ControlEvent]:
        if len(report) < 5:
            self.warnings.warn("truncated", f"Shuttle report of {len(report)} bytes")
            return []
        out: list[ControlEvent] = []
        shuttle = _s8(report[0])
        if not -7 <= shuttle <= 7:
            self.warnings.warn("range", f"shuttle position {shuttle} outside -7..7")
        elif shuttle != self._shuttle:
            self._shuttle = shuttle
            out.append(ControlEvent(self.device, "shuttle", "axis", shuttle / 7, None, shuttle, t))
        jog = report[1]
        if self._jog is not None and jog != self._jog:
            delta = _s8((jog - self._jog) & 0xFF)
            if abs(delta) <= self.counts_per_turn:
                out.append(ControlEvent(self.device, "jog", "dial", delta / self.counts_per_turn, float(delta), jog, t))
            else:
                self.warnings.warn("range", f"jog jumped {delta} detents")
        self._jog = jog
        bits = report[3] | report[4] << 8
        for i, mask in enumerate(self.masks):
            self._button(f"button{i}", bool(bits & mask), bits, t, out)
        return out


#: X-keys models: PIDs -> (name, columns, rows). node-xkeys products.ts.
XKEYS_MODELS: dict[int, tuple[str, int, int]] = {
    **{pid: ("X-keys XK-24", 4, 6) for pid in (1027, 1029)},
    **{pid: ("X-keys XK-80", 10, 8) for pid in (1089, 1091, 1217, 1220)},
    **{pid: ("X-keys XK-60", 10, 8) for pid in (1121, 1123, 1231, 1234)},
}


class XkeysProfile(Profile):
    """Byte 0 unit ID, byte 1 bit 0 program switch (``button0``), then one byte per column with a
    bit per row; key ``col*rows + row + 1`` is ``button<key>``; blue backlights by command 181."""

    def __init__(self, device: str, warnings: WarningCounter, counts_per_turn: int | None = None,
                 model: tuple[str, int, int] = ("X-keys XK-24", 4, 6)) -> None:
        super().__init__(device, warnings)
        self.name, self.cols, self.rows = model
        self.report_size = 36
        self.controls = [ControlInfo("button0", "button")] + buttons(self.cols * self.rows, lights=True, start=1)

    def decode(self, report: bytes, t: float) -> list[ControlEvent]:
        if len(report) < 2 + self.cols:
            self.warnings.warn("truncated", f"X-keys report of {len(report)} bytes")
            return []
        if report[1] > 3:  # a version or other non-key report
            return []
        out: list[ControlEvent] = []
        self._button("button0", bool(report[1] & 1), report[1], t, out)
        for col in range(self.cols):
            byte = report[2 + col]
            for row in range(self.rows):
                self._button(f"button{col * self.rows + row + 1}", bool(byte >> row & 1), byte, t, out)
        return out

    def _out(self, *payload: int) -> Command:
        return Command("write", bytes([0x00, *payload]).ljust(36, b"\x00"))

    def init_commands(self) -> list[Command]:
        return [self._out(177)]  # ask for the full state, so held keys are known at once

    def light(self, control: str, level: float) -> list[Command]:
        key = int(control.removeprefix("button")) - 1
        if key < 0:
            return []
        col, row = divmod(key, self.rows)
        return [self._out(181, col * 8 + row, 1 if level >= 0.5 else 0)]


def profile_for(vid: int, pid: int, device: str, warnings: WarningCounter, counts_per_turn: int | None) -> Profile | None:
    """The profile of a known product, or None to fall back to the report descriptor."""
    if vid == GRIFFIN and pid in (0x0410, 0x04AA):
        return PowerMateProfile(device, warnings, counts_per_turn)
    if vid == CONTOUR and pid in (0x0010, 0x0020, 0x0030):
        return ShuttleProfile(device, warnings, counts_per_turn, pro=pid != 0x0020)
    if vid == PIENG and pid in XKEYS_MODELS:
        return XkeysProfile(device, warnings, counts_per_turn, XKEYS_MODELS[pid])
    return None


def known_name(vid: int, pid: int) -> str | None:
    """Product name for discovery listings."""
    p = profile_for(vid, pid, "", WarningCounter(""), None)
    return p.name if p else None
