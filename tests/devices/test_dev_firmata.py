"""firmata:// end to end over a pty against a StandardFirmata emulator, plus parser units."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from emulators import FirmataEmulator
from devdata import controls, wait_for

from devices import DeviceError, EventQueue, StatusEvent, open_device
from devices.firmata import FirmataDevice, FirmataParser


@pytest.fixture
def board(tmp_path: Path) -> Iterator[FirmataEmulator]:
    emu = FirmataEmulator(tmp_path / "ttyACM")
    yield emu
    emu.port.close()


@pytest.fixture
def dev(board: FirmataEmulator) -> Iterator[tuple[FirmataDevice, EventQueue]]:
    d = open_device(f"firmata://{board.port.link}?analog=0-1&digital=2-4,9&encoders=5:6&interval=20&boot_wait=2")
    assert isinstance(d, FirmataDevice)
    q = EventQueue()
    d.add_listener(q)
    d.start()
    wait_for(q, lambda e: isinstance(e, StatusEvent))
    assert board.configured.wait(5)
    yield d, q
    d.close()


def test_configuration_sent_to_the_board(board: FirmataEmulator, dev: tuple[FirmataDevice, EventQueue]) -> None:
    d, _ = dev
    assert board.sampling_ms == 20
    assert {p: board.pin_modes[p] for p in (2, 3, 4, 9)} == {2: 11, 3: 11, 4: 11, 9: 11}
    assert board.report_ports == {0, 1}
    assert board.encoders == {0: (5, 6)}
    assert "StandardFirmata.ino 2.5" in d.description
    assert {c.name for c in d.controls} == {"axis0", "axis1", "button2", "button3", "button4", "button9", "dial0"}


def test_inputs_become_events(board: FirmataEmulator, dev: tuple[FirmataDevice, EventQueue]) -> None:
    _, q = dev
    import time

    deadline = time.monotonic() + 5
    while board.report_analog != {0, 1} and time.monotonic() < deadline:
        time.sleep(0.01)
    board.analog(1, 1023)
    board.analog(1, 1023)  # sent every sampling interval: only changes become events
    board.analog(0, 0)
    board.digital(3, 0)  # pressed (pull-up)
    board.digital(9, 0)
    board.digital(3, 1)
    board.encoder(0, -10)  # first report: the baseline
    board.encoder(0, -4)
    got = controls(wait_for(q, lambda e: getattr(e, "control", "") == "dial0"))
    assert [(e.control, e.value) for e in got] == [
        ("axis1", 1.0), ("axis0", 0.0), ("button3", 1.0), ("button9", 1.0), ("button3", 0.0), ("dial0", 6 / 96)]
    assert got[-1].delta == 6


def test_garbage_and_truncated_messages_on_the_wire(board: FirmataEmulator, dev: tuple[FirmataDevice, EventQueue]) -> None:
    d, q = dev
    board.port.write(bytes([0x01, 0x7F, 0xE0, 0x10, 0x95, 0xAB, 0xF0, 0x61, 0x00]))  # noise, cut-short messages
    board.port.write(bytes([0xF7]))
    board.digital(4, 0)
    got = controls(wait_for(q, lambda e: getattr(e, "control", "") == "button4"))
    assert got[-1].value == 1.0 and d.connected
    assert d.warnings.counts["garbage"] >= 2 and d.warnings.counts["truncated"] >= 1


def test_unplug_and_replug(board: FirmataEmulator, dev: tuple[FirmataDevice, EventQueue]) -> None:
    _, q = dev
    board.port.unplug()
    assert wait_for(q, lambda e: isinstance(e, StatusEvent))[-1].status == "lost"
    board.report_ports.clear()
    board.configured.clear()
    board.port.plug()
    assert wait_for(q, lambda e: isinstance(e, StatusEvent))[-1].status == "connected"
    assert board.configured.wait(5)
    board.digital(2, 0)
    assert controls(wait_for(q, lambda e: getattr(e, "control", "") == "button2"))[-1].value == 1.0


def test_silent_port_is_not_a_firmata_board(tmp_path: Path) -> None:
    from emulators import PtyPort

    silent = PtyPort(tmp_path / "silent")
    try:
        with pytest.raises(DeviceError, match="no Firmata board"):
            open_device(f"firmata://{silent.link}?boot_wait=0.3")
    finally:
        silent.close()


def test_parser_truncation_range_and_stray_bytes() -> None:
    p = FirmataParser("x", analog=[0], digital=[2], bits=10)
    assert p.feed(bytes([0xE0, 0x10, 0x90, 0x00, 0x00]), 1.0)[0].control == "button2"  # cut-short analog
    assert p.warnings.counts["truncated"] == 1
    assert p.feed(bytes([0xE0, 0x7F, 0x7F]), 2.0) == []  # 16383 > 10-bit range
    assert p.warnings.counts["range"] == 1
    assert p.feed(bytes([0x05, 0x06]), 3.0) == [] and p.warnings.counts["garbage"] == 2
    assert p.feed(bytes([0xE0, 0x7F, 0x07]), 4.0)[0].value == 1.0


def test_the_emulator_speaks_firmata_a_maintained_client_understands(board: FirmataEmulator,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Cross-check of the test double: pyfirmata2 (an independent Firmata client) drives the
    emulator and decodes its analog and digital reports, so our parser is tested against real
    Firmata framing, not just against itself."""
    import threading

    import pyfirmata2
    import pyfirmata2.pyfirmata2 as core

    monkeypatch.setattr(core, "BOARD_SETUP_WAIT_TIME", 0)  # its fixed 5 s wait for an Arduino reset
    client = pyfirmata2.Board(str(board.port.link), pyfirmata2.BOARDS["arduino"])
    got: dict[str, object] = {}
    done = threading.Event()

    def record(key: str) -> object:
        def cb(value: object) -> None:
            got[key] = value
            if len(got) == 2:
                done.set()
        return cb

    try:
        client.samplingOn(20)
        client.analog[2].register_callback(record("a2"))
        client.analog[2].enable_reporting()
        pin = client.get_pin("d:3:u")  # INPUT_PULLUP
        pin.register_callback(record("d3"))
        pin.enable_reporting()
        assert board.configured.wait(5)
        import time

        deadline = time.monotonic() + 5
        while 2 not in board.report_analog and time.monotonic() < deadline:
            time.sleep(0.01)
        assert board.sampling_ms == 20 and board.pin_modes[3] == 11
        board.analog(2, 1023)
        board.digital(3, 0)
        assert done.wait(5), got
        assert got == {"a2": 1.0, "d3": False}
    finally:
        client.exit()
