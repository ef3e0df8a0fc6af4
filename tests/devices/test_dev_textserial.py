"""serial:// text protocol end to end over a pty, plus parser units."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from emulators import TextBoxEmulator
from devdata import controls, wait_for

from devices import EventQueue, StatusEvent, open_device
from devices.textserial import TextParser, TextSerialDevice


@pytest.fixture
def box(tmp_path: Path) -> Iterator[TextBoxEmulator]:
    emu = TextBoxEmulator(tmp_path / "ttyBOX")
    yield emu
    emu.port.close()


@pytest.fixture
def dev(box: TextBoxEmulator) -> Iterator[tuple[TextSerialDevice, EventQueue]]:
    d = open_device(f"serial://{box.port.link}?baud=115200&buttons=8&dials=2&axes=2")
    assert isinstance(d, TextSerialDevice)
    q = EventQueue()
    d.add_listener(q)
    d.start()
    wait_for(q, lambda e: isinstance(e, StatusEvent))
    yield d, q
    d.close()


def test_lines_become_events(box: TextBoxEmulator, dev: tuple[TextSerialDevice, EventQueue]) -> None:
    d, q = dev
    box.send("H my box\r\nB3 1\r\nD0 +5\nD1 -2\nA1 0.731\n# comment\nB3 0\n")
    got = controls(wait_for(q, lambda e: getattr(e, "control", "") == "button3" and e.value == 0))
    assert [(e.control, e.kind, e.value, e.delta) for e in got] == [
        ("button3", "button", 1.0, None),
        ("dial0", "dial", 5 / 24, 5.0),
        ("dial1", "dial", -2 / 24, -2.0),
        ("axis1", "axis", 0.731, None),
        ("button3", "button", 0.0, None),
    ]
    assert d.description.startswith("my box")


def test_lights_are_sent_as_lines(box: TextBoxEmulator, dev: tuple[TextSerialDevice, EventQueue]) -> None:
    d, _ = dev
    d.set_light("button2", True)
    box.wait_line("L2 1")
    d.set_light("button2", False)
    box.wait_line("L2 0")


def test_garbage_wrong_values_and_split_lines(box: TextBoxEmulator, dev: tuple[TextSerialDevice, EventQueue]) -> None:
    d, q = dev
    box.port.write(b"\xff\xfe\x80garbage\n")
    box.port.write(b"\xf0\x9f\x00\xc3\n" + b"X" * 500 + b"\nB9 1\nA0 7\nA0 nan\nB1 2\nD0 +999\nB")
    box.send("1 1\nA0 1.02\n")
    got = controls(wait_for(q, lambda e: getattr(e, "control", "") == "axis0"))
    assert [(e.control, e.value) for e in got] == [("button1", 1.0), ("axis0", 1.0)]
    assert d.warnings.counts["garbage"] >= 3 and d.warnings.counts["range"] >= 5


def test_unplug_replug(box: TextBoxEmulator, dev: tuple[TextSerialDevice, EventQueue]) -> None:
    d, q = dev
    box.port.unplug()
    assert wait_for(q, lambda e: isinstance(e, StatusEvent))[-1].status == "lost"
    box.port.plug()
    assert wait_for(q, lambda e: isinstance(e, StatusEvent))[-1].status == "connected"
    box.send("D1 +3\n")
    assert controls(wait_for(q, lambda e: getattr(e, "control", "") == "dial1"))[-1].delta == 3


def test_parser_counts_and_ranges() -> None:
    p = TextParser("x", n_buttons=2, n_dials=1, n_axes=1, counts_per_turn=10)
    assert p.feed(b"B0 1\nB0 1\n", 1.0)[0].value == 1 and p.feed(b"B0 1\n", 2.0) == []
    assert p.feed(b"D0 +11\nD0 0\n", 3.0) == []
    assert p.feed(b"A0 -0.01\n", 4.0)[0].value == 0.0


def test_digits_grouped_by_underscores_are_a_bad_number() -> None:
    """`D0 +1_0` was read as a step of 10 and `A0 0.5_0` as 0.5 (Python's literals group digits with
    underscores; the protocol does not): a box sending such a line has a fault, counted as garbage."""
    p = TextParser("x", n_buttons=2, n_dials=1, n_axes=1, counts_per_turn=24)
    assert p.feed(b"D0 +1_0\nA0 0.5_0\nB1 1_0\n", 1.0) == []
    assert p.warnings.counts["garbage"] == 3
    assert [e.delta for e in p.feed(b"D0 +10\n", 2.0)] == [10.0]


def test_permission_denied_says_what_to_do(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import errno

    import serial

    from devices import DeviceError

    def denied(self: serial.Serial) -> None:  # what a user outside 'dialout' gets from pyserial
        raise serial.SerialException(errno.EACCES, f"could not open port {self.port}: Permission denied")

    monkeypatch.setattr(serial.Serial, "open", denied)
    with pytest.raises(DeviceError, match="dialout"):
        open_device(f"serial://{tmp_path / 'ttyUSB9'}")
