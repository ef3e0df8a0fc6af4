"""What the MIDI backends share: the profile, the decoder, the feedback (lights and rings), and a
fast control lookup (a profile plus the generic names declares a few thousand controls)."""

from __future__ import annotations

from typing import Any

from devices.base import ControlInfo, Device
from devices.errors import DeviceSpecError
from devices.events import ControlEvent
from devices.midi.decoder import MidiDecoder
from devices.midi.feedback import Feedback
from devices.midi.profile import MidiProfile, load_profile, profile_for_port
from devices.spec import DeviceSpec


class MidiDevice(Device):
    """Base of ``midi://`` and ``rawmidi://``: subclasses move bytes, this class gives them meaning."""

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        name = spec.query.get("profile") or profile_for_port(spec.location)
        channel = spec.get_int("channel", 0, lo=1, hi=16) if "channel" in spec.query else None
        self.profile: MidiProfile = load_profile(name, channel)
        self.decoder = MidiDecoder(self.spec, self.profile, self.warnings)
        self.feedback = Feedback(self.profile, self.warnings)
        self.controls = self.decoder.controls()
        self._by_name = {c.name: c for c in self.controls}

    def control(self, name: str) -> ControlInfo | None:
        return self._by_name.get(name)

    def _decode(self, msg: tuple[int, ...], t: float) -> list[ControlEvent]:
        """One complete message from the box -> events (an echo of our own lights is dropped)."""
        if self.feedback.is_echo(msg, t):
            return []
        try:
            return self.decoder.decode(msg, t)
        except Exception as err:  # a decoder bug must cost one message, never the device
            self.warnings.warn("decode", f"cannot decode {bytes(msg).hex(' ')}: {err!r}")
            return []

    def _set_light(self, control: str, level: float) -> None:
        if self.feedback.request(control, level):
            self._wake()


def check_location(spec: DeviceSpec, form: str) -> None:
    if not spec.location:
        raise DeviceSpecError(f"{spec.text}: no port given; expected {form}")
