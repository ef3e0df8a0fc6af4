"""rawmidi:// end to end over a pseudo-terminal in raw mode (a stand-in for /dev/snd/midiC*D* and for
DIN MIDI on a UART): garbage, running status, clock bytes inside messages, SysEx, lights written
back to the box, unplug and replug behind the same path."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from emulators import PtyPort

from devices import ControlEvent, StatusEvent, open_device


class RawBox:
    """A MIDI controller on a byte stream; ``received`` is what the host wrote to it."""

    def __init__(self, link: Path) -> None:
        self.received = b""
        self._cond = threading.Condition()
        self.port = PtyPort(link, self._on_bytes)

    def _on_bytes(self, data: bytes) -> None:
        with self._cond:
            self.received += data
            self._cond.notify_all()

    def wait_received(self, data: bytes, timeout: float = 5.0) -> None:
        with self._cond:
            assert self._cond.wait_for(lambda: data in self.received, timeout), self.received.hex(" ")


class Got:
    def __init__(self) -> None:
        self.events: list[object] = []
        self.cond = threading.Condition()

    def __call__(self, ev: object) -> None:
        with self.cond:
            self.events.append(ev)
            self.cond.notify_all()

    def controls(self) -> list[ControlEvent]:
        return [e for e in self.events if isinstance(e, ControlEvent)]

    def wait(self, pred: object, timeout: float = 5.0) -> None:
        with self.cond:
            assert self.cond.wait_for(lambda: pred(self), timeout), self.events  # type: ignore[operator]


@pytest.fixture()
def box(tmp_path: Path) -> Iterator[RawBox]:
    b = RawBox(tmp_path / "midiC1D0")
    yield b
    b.port.close()


@pytest.mark.parametrize("query", ["profile=nanokontrol2", "profile=nanokontrol2&baud=31250"])
def test_byte_stream_lights_and_replug(box: RawBox, query: str) -> None:
    dev = open_device(f"rawmidi://{box.port.link}?{query}")
    got = Got()
    dev.add_listener(got)
    dev.start()
    try:
        got.wait(lambda g: any(isinstance(e, StatusEvent) for e in g.events))
        stream = bytes([
            0x12, 0x7F,                    # garbage before any status
            0xB0, 0x00, 0x10,              # fader1
            0x00, 0x20,                    # running status: fader1 again
            0x10, 0xF8, 0x40,              # running status, a clock byte inside: knob1
            0xF0, 0x42, 0x40, 0xF8, 0x00, 0xF7,  # SysEx with a clock inside
            0xB0, 0xFE, 0x20, 0x7F,        # active sensing between status and data: S1 pressed
            0xF9, 0xFD,                    # undefined
            0x20, 0x00,                    # running status survives undefined bytes: S1 released
            0xB0, 0x20, 0x00,              # released again: not a change, not reported
        ])
        for i in range(0, len(stream), 3):  # in pieces, as a slow line delivers them
            box.port.write(stream[i:i + 3])
            time.sleep(0.002)
        got.wait(lambda g: len(g.controls()) == 5)
        assert [(e.control, e.raw) for e in got.controls()] == [
            ("fader1", 0x10), ("fader1", 0x20), ("knob1", 0x40), ("s1", 0x7F), ("s1", 0)]
        assert dev.warnings.counts["garbage"] >= 4
        dev.set_light("s1", True)
        box.wait_received(bytes([0xB0, 0x20, 0x7F]))
        box.port.unplug()
        got.wait(lambda g: [e.status for e in g.events if isinstance(e, StatusEvent)][-1:] == ["lost"])
        box.received = b""
        box.port.plug()
        got.wait(lambda g: [e.status for e in g.events if isinstance(e, StatusEvent)][-1:] == ["connected"])
        box.wait_received(bytes([0xB0, 0x20, 0x7F]))  # the light is restored
        n = len(got.controls())
        box.port.write(bytes([0xB0, 0x21, 0x7F]))
        got.wait(lambda g: len(g.controls()) == n + 1)
        assert got.controls()[-1].control == "s2"
    finally:
        dev.close()


def test_echoed_lights_do_not_come_back_as_input(box: RawBox) -> None:
    """A box with MIDI Thru on sends back what the host sends it: that is not a button press."""
    box.port.on_bytes = lambda data: (box._on_bytes(data), box.port.write(data))  # type: ignore[assignment]
    dev = open_device(f"rawmidi://{box.port.link}?profile=nanokontrol2")
    got = Got()
    dev.add_listener(got)
    dev.start()
    try:
        dev.set_light("s3", True)
        box.wait_received(bytes([0xB0, 0x22, 0x7F]))
        time.sleep(0.2)
        assert got.controls() == []
        assert dev.feedback.echoes == 1
        box.port.write(bytes([0xB0, 0x23, 0x7F]))  # a real press still arrives
        got.wait(lambda g: [e.control for e in g.controls()] == ["s4"])
    finally:
        dev.close()


def test_rawmidi_errors_are_one_line(tmp_path: Path) -> None:
    import devices

    with pytest.raises(devices.DeviceSpecError, match="expected rawmidi://"):
        open_device("rawmidi://")
    with pytest.raises(devices.DeviceSpecError, match="unknown option api"):
        open_device(f"rawmidi://{tmp_path}/x?api=jack")
    with pytest.raises(devices.DeviceError, match="midiC9D0"):
        open_device(f"rawmidi://{tmp_path}/midiC9D0")
