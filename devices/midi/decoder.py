"""MIDI messages -> control events, by a controller profile.

CC and pitch bend become axes (absolute, normalised to the control's range) or dials (relative
encoders in the profile's encoding; value in turns, ``delta`` in counts); notes become buttons
(note-on velocity 0 is a release); CC buttons are pressed at value >= 64. 14-bit CC pairs (MSB on
CC n, LSB on CC n+32) and NRPN/RPN data entry are assembled in the order the profile declares.
An absolute control passes a per-control dead band: a change that reverses the last reported
direction by ``dead_band`` counts or less is dropped, so a pot flickering 116/117/116 stays still
while a continuous move keeps every count.

Messages the profile does not name still become events under generic names (``ch1.cc7``,
``ch1.note60``, ``ch1.pitchbend``), so any controller can be learned; a generic CC reports every
message, repeats included, because it may be a relative encoder (``puppet learn`` recognises one,
and a binding reads it with ``input = "relative"`` and its ``encoding``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from devices.base import ControlInfo
from devices.events import ControlEvent
from devices.midi.profile import ControlDef, MidiProfile
from devices.warn import WarningCounter

NRPN_MSB, NRPN_LSB, RPN_MSB, RPN_LSB = 99, 98, 101, 100
DATA_MSB, DATA_LSB, DATA_INC, DATA_DEC = 6, 38, 96, 97
PARAM_CCS = frozenset({NRPN_MSB, NRPN_LSB, RPN_MSB, RPN_LSB, DATA_MSB, DATA_LSB, DATA_INC, DATA_DEC})
NULL_RPN = 0x3FFF


def relative_delta(raw: int, encoding: str) -> int:
    """Signed counts from one relative-encoder value (7 bits) in the profile's encoding."""
    raw &= 0x7F
    if encoding == "twos_complement":
        return raw - 128 if raw >= 64 else raw
    if encoding == "offset64":
        return raw - 64
    return -(raw & 63) if raw & 64 else raw  # sign_magnitude (Mackie V-pots)


def generic_controls() -> list[ControlInfo]:
    """What any message a profile does not name is reported as: per channel, every CC as an
    axis, every note as a button, pitch bend as a centred axis."""
    out = []
    for ch in range(1, 17):
        out += [ControlInfo(f"ch{ch}.cc{n}", "axis", 0.0, 1.0) for n in range(128)]
        out += [ControlInfo(f"ch{ch}.note{n}", "button", 0.0, 1.0) for n in range(128)]
        out.append(ControlInfo(f"ch{ch}.pitchbend", "axis", -1.0, 1.0))
    return out


@dataclass
class _Axis:
    """Dead-band state of one absolute control."""

    last: int | None = None
    direction: int = 0


@dataclass
class _Param:
    """NRPN/RPN state of one channel: the selected parameter and its data bytes."""

    nrpn: bool = True
    msb: int = 0x7F
    lsb: int = 0x7F
    data_msb: int | None = None
    data_lsb: int | None = None

    @property
    def number(self) -> int:
        return self.msb << 7 | self.lsb


class MidiDecoder:
    """Pure: ``decode(message, t)`` turns one complete MIDI message into 0..n events."""

    def __init__(self, device: str, profile: MidiProfile, warnings: WarningCounter | None = None) -> None:
        self.device = device
        self.profile = profile
        self.warnings = warnings or WarningCounter(device)
        self._by_msg: dict[tuple[str, int, int], ControlDef] = {}
        self._param_channels: set[int] = set()
        for cd in profile.controls:
            if cd.message == "cc14":
                self._by_msg[("cc", cd.channel, cd.number)] = cd
                self._by_msg[("cc", cd.channel, cd.number + 32)] = cd
            else:
                self._by_msg[(cd.message, cd.channel, cd.number)] = cd
            if cd.message in ("nrpn", "rpn"):
                self._param_channels.add(cd.channel)
        self.reset()

    def controls(self) -> list[ControlInfo]:
        """The declared controls: the profile's, then the generic names."""
        named = [ControlInfo(cd.name, cd.kind, cd.lo, cd.hi, cd.light is not None or cd.ring is not None)  # type: ignore[arg-type]
                 for cd in self.profile.controls]
        return named + generic_controls()

    def reset(self) -> None:
        """Forget every control's state (after a reconnect: the box may have moved meanwhile)."""
        self._axes: dict[str, _Axis] = {}
        self._buttons: dict[str, bool] = {}
        self._msb: dict[tuple[int, int], int] = {}
        self._lsb: dict[tuple[int, int], int] = {}
        self._params: dict[int, _Param] = {}

    # ------------------------------------------------------------------------------ dispatch
    def decode(self, msg: Sequence[int], t: float) -> list[ControlEvent]:
        if not msg or msg[0] >= 0xF0:
            return []  # clock, transport, SysEx: not controls
        status, ch = msg[0] & 0xF0, msg[0] & 0x0F
        if status == 0xB0 and len(msg) == 3:
            return self._cc(ch, msg[1], msg[2], t)
        if status in (0x90, 0x80) and len(msg) == 3:
            on = status == 0x90 and msg[2] > 0
            cd = self._by_msg.get(("note", ch, msg[1]))
            if cd is None:
                return self._button(f"ch{ch + 1}.note{msg[1]}", on, msg[2], t)
            if cd.kind == "button":
                return self._button(cd.name, on, msg[2], t)
            return self._absolute(cd, msg[2] if on else 0, t)
        if status == 0xE0 and len(msg) == 3:
            raw = msg[2] << 7 | msg[1]
            cd = self._by_msg.get(("pitchbend", ch, 0))
            if cd is None:
                return self._axis_event(f"ch{ch + 1}.pitchbend", -1.0, 1.0, raw, 16383, t, dead_band=0)
            return self._absolute(cd, raw, t)
        return []  # program change, aftertouch: not used by any profile

    def _cc(self, ch: int, num: int, val: int, t: float) -> list[ControlEvent]:
        if ch in self._param_channels and num in PARAM_CCS:
            return self._param(ch, num, val, t)
        cd = self._by_msg.get(("cc", ch, num))
        if cd is None:
            # every message, repeats too: an unprofiled CC may be a relative encoder sending 1, 1, 1
            return self._axis_event(f"ch{ch + 1}.cc{num}", 0.0, 1.0, val, 127, t, dead_band=0, repeats=True)
        if cd.message == "cc14":
            return self._cc14(cd, num == cd.number, val, t)
        if cd.kind == "button":
            return self._button(cd.name, val >= 64, val, t)
        if cd.kind == "dial":
            return self._dial(cd, relative_delta(val, cd.encoding), val, t)
        return self._absolute(cd, val, t)

    def _cc14(self, cd: ControlDef, is_msb: bool, val: int, t: float) -> list[ControlEvent]:
        key = (cd.channel, cd.number)
        if is_msb:
            self._msb[key] = val
            if cd.order == "msb_lsb":
                self._lsb[key] = 0  # the spec: an MSB resets the receiver's LSB; wait for the LSB
                return []
            lsb = self._lsb.get(key, 0) if cd.order == "lsb_msb" else 0
            return self._absolute(cd, val << 7 | lsb, t)
        self._lsb[key] = val
        if cd.order != "msb_lsb" or key not in self._msb:
            return []  # lsb_msb: the MSB that follows completes it; no MSB yet: nothing to add to
        return self._absolute(cd, self._msb[key] << 7 | val, t)

    def _param(self, ch: int, num: int, val: int, t: float) -> list[ControlEvent]:
        p = self._params.setdefault(ch, _Param())
        if num in (NRPN_MSB, RPN_MSB):
            p.nrpn, p.msb, p.data_msb, p.data_lsb = num == NRPN_MSB, val, None, None
            return []
        if num in (NRPN_LSB, RPN_LSB):
            p.nrpn, p.lsb, p.data_msb, p.data_lsb = num == NRPN_LSB, val, None, None
            return []
        if not p.nrpn and p.number == NULL_RPN:
            return []
        cd = self._by_msg.get(("nrpn" if p.nrpn else "rpn", ch, p.number))
        if cd is None:
            self.warnings.warn("unmapped", f"{'NRPN' if p.nrpn else 'RPN'} {p.number} on channel {ch + 1} is not in the profile")
            return []
        if num in (DATA_INC, DATA_DEC):
            step = 1 if num == DATA_INC else -1
            if cd.kind == "dial":
                return self._dial(cd, step, val, t)
            base = self._axes.get(cd.name, _Axis()).last or 0
            return self._absolute(cd, max(0, min(cd.max_raw, base + step)), t)
        if cd.kind == "dial":  # a relative encoder on data entry MSB
            return self._dial(cd, relative_delta(val, cd.encoding), val, t) if num == DATA_MSB else []
        if num == DATA_MSB:
            p.data_msb = val
            if cd.order == "msb":
                return self._absolute(cd, val, t)
            if cd.order == "lsb_msb" and p.data_lsb is not None:
                return self._absolute(cd, val << 7 | p.data_lsb, t)
            if cd.order == "lsb_msb":
                return self._absolute(cd, val << 7, t)
            return []
        p.data_lsb = val
        if cd.order == "msb_lsb" and p.data_msb is not None:
            return self._absolute(cd, p.data_msb << 7 | val, t)
        return []

    # ------------------------------------------------------------------------------ events
    def _button(self, name: str, down: bool, raw: int, t: float) -> list[ControlEvent]:
        if self._buttons.get(name) == down or (name not in self._buttons and not down):
            self._buttons[name] = down
            return []  # changes only; a release with no press seen is nothing to report
        self._buttons[name] = down
        return [ControlEvent(self.device, name, "button", 1.0 if down else 0.0, None, raw, t)]

    def _dial(self, cd: ControlDef, counts: int, raw: int, t: float) -> list[ControlEvent]:
        if counts == 0:
            return []
        turns = max(-1.0, min(1.0, counts / cd.counts_per_turn))
        return [ControlEvent(self.device, cd.name, "dial", turns, float(counts), raw, t)]

    def _absolute(self, cd: ControlDef, raw: int, t: float) -> list[ControlEvent]:
        if cd.kind == "button":
            return self._button(cd.name, raw >= (cd.max_raw + 1) // 2, raw, t)
        return self._axis_event(cd.name, cd.lo, cd.hi, raw, cd.max_raw, t, cd.dead_band)

    def _axis_event(self, name: str, lo: float, hi: float, raw: int, top: int, t: float,
                    dead_band: int, repeats: bool = False) -> list[ControlEvent]:
        st = self._axes.get(name)
        if st is None:
            st = self._axes[name] = _Axis()
        if st.last is not None:
            step = raw - st.last
            if step == 0 and not repeats:
                return []
            direction = 1 if step > 0 else -1 if step < 0 else st.direction
            if direction != st.direction and abs(step) <= dead_band and 0 < raw < top:
                return []  # jitter: a small reversal inside the dead band
            st.direction = direction
        st.last = raw
        if lo < 0.0 < hi and top == 16383:  # a centred wheel: 8192 is exactly 0, both ends reached
            value = (raw - 8192) / 8191.0 * hi if raw >= 8192 else (8192 - raw) / 8192.0 * lo
        else:
            value = lo + (hi - lo) * raw / top
        return [ControlEvent(self.device, name, "axis", value, None, raw, t)]
