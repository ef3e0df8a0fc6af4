"""A HID report-descriptor parser and a generic input-report decoder built on it.

The descriptor is a stream of short items (prefix byte: size in bits 0-1, type in bits 2-3, tag in
bits 4-7). Global items (usage page, logical range, report size/count/ID, push/pop) persist; local
items (usages) are consumed by the next main item. Each Input main item lays ``count`` fields of
``size`` bits at the current bit offset of its report. From the usages we keep what a control box
needs: Button-page buttons (variable or array), Generic-Desktop axes and hat switches, the
Simulation page's rudder/throttle/accelerator/brake and the consumer AC Pan; relative fields
(wheels, dials, mice) become dials.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from devices.base import ControlInfo
from devices.controlsets import DIAL_HI, DIAL_LO
from devices.events import ControlEvent
from devices.warn import WarningCounter

PAGE_DESKTOP, PAGE_SIMULATION, PAGE_BUTTON, PAGE_CONSUMER = 0x01, 0x02, 0x09, 0x0C
MAX_USAGES = 4096
MAX_COUNT = 65535
#: Controls made from one variable field at most (a vendor blob reusing one usage is not 4096 axes).
MAX_SLOTS = 256

NAMED_USAGES: dict[int, str] = {
    PAGE_DESKTOP << 16 | 0x30: "x", PAGE_DESKTOP << 16 | 0x31: "y", PAGE_DESKTOP << 16 | 0x32: "z",
    PAGE_DESKTOP << 16 | 0x33: "rx", PAGE_DESKTOP << 16 | 0x34: "ry", PAGE_DESKTOP << 16 | 0x35: "rz",
    PAGE_DESKTOP << 16 | 0x36: "slider", PAGE_DESKTOP << 16 | 0x37: "dial", PAGE_DESKTOP << 16 | 0x38: "wheel",
    PAGE_DESKTOP << 16 | 0x39: "hat",
    PAGE_SIMULATION << 16 | 0xBA: "rudder", PAGE_SIMULATION << 16 | 0xBB: "throttle",
    PAGE_SIMULATION << 16 | 0xC4: "accelerator", PAGE_SIMULATION << 16 | 0xC5: "brake",
    PAGE_CONSUMER << 16 | 0x238: "pan",
}


class DescriptorError(ValueError):
    """The bytes are not a well-formed report descriptor."""


@dataclass(frozen=True, slots=True)
class Field:
    """One Input main item: ``count`` slots of ``size`` bits from ``offset`` in report ``report_id``
    (offset counted after the report-ID byte). ``usages`` are full 32-bit (page << 16 | id)."""

    report_id: int
    offset: int
    size: int
    count: int
    usages: tuple[int, ...]
    logical_min: int
    logical_max: int
    flags: int

    @property
    def constant(self) -> bool:
        return bool(self.flags & 0x01)

    @property
    def variable(self) -> bool:
        return bool(self.flags & 0x02)

    @property
    def relative(self) -> bool:
        return bool(self.flags & 0x04)

    @property
    def null_state(self) -> bool:
        return bool(self.flags & 0x40)

    def value(self, bits: int, k: int) -> int:
        """Slot ``k`` out of a report given as one little-endian integer; signed when the logical
        range is."""
        raw = (bits >> (self.offset + k * self.size)) & ((1 << self.size) - 1)
        if self.logical_min < 0 and raw & (1 << (self.size - 1)):
            raw -= 1 << self.size
        return raw


@dataclass
class ReportDescriptor:
    """Input fields of every report and the size in bytes of each input report (without ID)."""

    fields: list[Field] = field(default_factory=list)
    report_bytes: dict[int, int] = field(default_factory=dict)
    numbered: bool = False

    @classmethod
    def parse(cls, data: bytes | list[int]) -> ReportDescriptor:
        """Parse descriptor bytes; DescriptorError when they are malformed."""
        data = bytes(data)
        out = cls()
        glob = {"page": 0, "lmin": 0, "lmax": 0, "lmax_size": 1, "size": 0, "count": 0, "id": 0}
        stack: list[dict[str, int]] = []
        usages: list[int] = []
        umin: int | None = None
        depth = 0
        bits: dict[int, int] = {}
        i = 0
        while i < len(data):
            prefix = data[i]
            if prefix == 0xFE:  # long item: skip its payload
                if i + 2 >= len(data):
                    raise DescriptorError("truncated long item")
                i += 3 + data[i + 1]
                continue
            size = (0, 1, 2, 4)[prefix & 3]
            if i + 1 + size > len(data):
                raise DescriptorError(f"item at byte {i} runs past the end")
            raw = data[i + 1 : i + 1 + size]
            u = int.from_bytes(raw, "little")
            s = int.from_bytes(raw, "little", signed=True) if size else 0
            kind, tag = (prefix >> 2) & 3, prefix >> 4
            i += 1 + size
            if kind == 1:  # global
                if tag == 0:
                    glob["page"] = u
                elif tag == 1:
                    glob["lmin"] = s
                elif tag == 2:
                    glob["lmax"], glob["lmax_size"] = s, max(size, 1)
                    glob["lmax_u"] = u
                elif tag == 7:
                    glob["size"] = u
                elif tag == 8:
                    if not 0 < u < 256:
                        raise DescriptorError(f"report ID {u} out of range")
                    glob["id"], out.numbered = u, True
                elif tag == 9:
                    if u > MAX_COUNT:
                        raise DescriptorError(f"report count {u} is not plausible")
                    glob["count"] = u
                elif tag == 10:
                    stack.append(dict(glob))
                elif tag == 11:
                    if not stack:
                        raise DescriptorError("pop without push")
                    glob = stack.pop()
            elif kind == 2:  # local
                full = u if size == 4 else (glob["page"] << 16 | u)
                if tag == 0:
                    usages.append(full)
                elif tag == 1:
                    umin = full
                elif tag == 2 and umin is not None:
                    if full - umin > MAX_USAGES:
                        raise DescriptorError("usage range too large")
                    usages.extend(range(umin, full + 1))
                    umin = None
            elif kind == 0:  # main
                if tag == 8:  # Input
                    lmin, lmax = glob["lmin"], glob["lmax"]
                    if lmax < lmin:  # a max written unsigned (e.g. 0xFF with min 0)
                        lmax = glob.get("lmax_u", lmax)
                    nbits = glob["size"] * glob["count"]
                    rid = glob["id"]
                    if glob["size"] > 32:
                        raise DescriptorError("report size above 32 bits")
                    if nbits:
                        out.fields.append(Field(rid, bits.get(rid, 0), glob["size"], glob["count"],
                                                tuple(usages), lmin, lmax, u))
                    bits[rid] = bits.get(rid, 0) + nbits
                elif tag == 10:
                    depth += 1
                elif tag == 12:
                    depth -= 1
                    if depth < 0:
                        raise DescriptorError("end collection without collection")
                usages, umin = [], None
        out.report_bytes = {rid: (n + 7) // 8 for rid, n in bits.items()}
        return out


@dataclass
class _Slot:
    name: str
    kind: str
    field: Field
    k: int


class GenericDecoder:
    """Decodes input reports of any device through its descriptor; emits changes only."""

    def __init__(self, device: str, desc: ReportDescriptor, counts_per_turn: int = 24,
                 warnings: WarningCounter | None = None) -> None:
        self.device = device
        self.desc = desc
        self.counts_per_turn = counts_per_turn
        self.warnings = warnings or WarningCounter(device)
        self.controls: list[ControlInfo] = []
        self._slots: dict[int, list[_Slot]] = {}
        self._arrays: dict[int, list[tuple[Field, dict[int, str]]]] = {}
        self._last: dict[str, float] = {}
        self._plan()

    def _add(self, info: ControlInfo) -> str:
        names = {c.name for c in self.controls}
        name, n = info.name, 1
        while name in names:
            name, n = f"{info.name}{n}", n + 1
        self.controls.append(ControlInfo(name, info.kind, info.lo, info.hi, info.has_light))
        return name

    def _plan(self) -> None:
        for f in self.desc.fields:
            if f.constant or not f.usages or f.logical_max < f.logical_min:
                continue  # padding, or a range no value can be inside
            if not f.variable:  # an array: slots hold the index of the pressed usage
                buttons = {u: self._add(ControlInfo(f"button{(u & 0xFFFF) - 1}", "button"))
                           for u in f.usages if u >> 16 == PAGE_BUTTON}
                if buttons:
                    self._arrays.setdefault(f.report_id, []).append((f, buttons))
                continue
            for k in range(min(f.count, MAX_SLOTS)):
                u = f.usages[min(k, len(f.usages) - 1)]
                if u >> 16 == PAGE_BUTTON:
                    info = ControlInfo(f"button{(u & 0xFFFF) - 1}", "button")
                elif u in NAMED_USAGES:
                    base = NAMED_USAGES[u]
                    if f.relative:
                        info = ControlInfo(base, "dial", DIAL_LO, DIAL_HI)
                    elif base == "hat":
                        info = ControlInfo(base, "axis", -1.0, float(f.logical_max - f.logical_min))
                    else:
                        info = ControlInfo(base, "axis", -1.0 if f.logical_min < 0 else 0.0, 1.0)
                else:
                    continue
                name = self._add(info)
                self._slots.setdefault(f.report_id, []).append(_Slot(name, info.kind, f, k))

    def usable(self) -> bool:
        """True when the device has at least one button, axis or dial we understand."""
        return bool(self.controls)

    def decode(self, report: bytes, t: float) -> list[ControlEvent]:
        """One input report as read by hidapi (report ID first for numbered devices)."""
        rid = 0
        if self.desc.numbered:
            if not report:
                return []
            rid, report = report[0], report[1:]
        if rid not in self.desc.report_bytes:
            self.warnings.warn("unknown-report", f"report ID {rid} is not in the descriptor")
            return []
        if len(report) < self.desc.report_bytes[rid]:
            self.warnings.warn("truncated", f"report {rid} has {len(report)} bytes, expected {self.desc.report_bytes[rid]}")
            return []
        bits = int.from_bytes(report, "little")
        out: list[ControlEvent] = []
        for s in self._slots.get(rid, ()):
            self._slot(s, s.field.value(bits, s.k), t, out)
        for f, buttons in self._arrays.get(rid, ()):
            pressed = set()
            for k in range(f.count):
                idx = f.value(bits, k) - f.logical_min
                if 0 <= idx < len(f.usages) and f.usages[idx] in buttons:
                    pressed.add(buttons[f.usages[idx]])
            for name in buttons.values():
                self._emit(name, "button", 1.0 if name in pressed else 0.0, None, int(name in pressed), t, out)
        return out

    def _slot(self, s: _Slot, raw: int, t: float, out: list[ControlEvent]) -> None:
        f = s.field
        if s.kind == "button":
            self._emit(s.name, "button", 1.0 if raw else 0.0, None, raw, t, out)
        elif s.kind == "dial":
            if raw and abs(raw) <= self.counts_per_turn:
                out.append(ControlEvent(self.device, s.name, "dial", raw / self.counts_per_turn, float(raw), raw, t))
            elif raw:
                self.warnings.warn("range", f"{s.name} step {raw} is larger than a turn")
        elif not f.logical_min <= raw <= f.logical_max:
            if s.name.startswith("hat") and f.null_state:
                self._emit(s.name, "axis", -1.0, None, raw, t, out)  # hat released
            else:
                self.warnings.warn("range", f"{s.name}={raw} outside {f.logical_min}..{f.logical_max}")
        elif s.name.startswith("hat"):
            self._emit(s.name, "axis", float(raw - f.logical_min), None, raw, t, out)
        else:
            span = (f.logical_max - f.logical_min) or 1
            unit = (raw - f.logical_min) / span
            value = 2 * unit - 1 if f.logical_min < 0 else unit
            self._emit(s.name, "axis", value, None, raw, t, out)

    def _emit(self, name: str, kind: str, value: float, delta: float | None, raw: int, t: float,
              out: list[ControlEvent]) -> None:
        if self._last.get(name, 0.0 if kind == "button" else None) == value:
            return  # buttons start released, so a first report only announces pressed ones
        self._last[name] = value
        out.append(ControlEvent(self.device, name, kind, value, delta, raw, t))  # type: ignore[arg-type]
