"""sgi:// end to end through pyserial over a pty against the box emulator, plus parser units."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from devdata import controls, wait_for
from emulators import SgiBoxEmulator

from devices import EventQueue, StatusEvent, open_device
from devices.sgi import SgiDevice, SgiParser, button_code, button_index


@pytest.fixture
def box(tmp_path: Path) -> Iterator[SgiBoxEmulator]:
    emu = SgiBoxEmulator(tmp_path / "ttySGI")
    yield emu
    emu.port.close()


@pytest.fixture
def dev(box: SgiBoxEmulator) -> Iterator[tuple[SgiDevice, EventQueue]]:
    d = open_device(f"sgi://{box.port.link}?pace_ms=0.2")
    assert isinstance(d, SgiDevice)
    q = EventQueue()
    d.add_listener(q)
    d.start()
    assert wait_for(q, lambda e: isinstance(e, StatusEvent))[-1].status == "connected"
    yield d, q
    d.close()


def test_button_numbering_matches_the_vrpn_table() -> None:
    assert [button_index(c) for c in (0xD8, 0xDF, 0xD0, 0xC8, 0xC0, 0xF8, 0xE7)] == [0, 7, 8, 16, 24, 0, 31]
    assert all(button_index(button_code(k, p)) == k for k in range(32) for p in (True, False))


def test_init_order_dials_turns_buttons(box: SgiBoxEmulator, dev: tuple[SgiDevice, EventQueue]) -> None:
    d, q = dev
    box.wait_ready()
    cmds = [c[0] for c in box.commands]
    assert cmds[0] == 0x20 and cmds.index(0x50) < cmds.index(0x73)
    assert cmds.count(0x73) == 2 and cmds.count(0x71) == 2
    box.turn(2, 5)
    box.turn(2, -3)
    box.button(17, True)
    box.button(17, False)
    got = controls(wait_for(q, lambda e: getattr(e, "control", "") == "button17" and e.value == 0))
    assert [(e.control, e.kind, e.delta) for e in got[:2]] == [("dial2", "dial", 5), ("dial2", "dial", -3)]
    assert got[0].value == pytest.approx(5 / 200) and got[0].device == d.spec
    assert [(e.control, e.value) for e in got[2:]] == [("button17", 1.0), ("button17", 0.0)]
    assert all(e.t > 0 for e in got)


def test_value_bytes_that_look_like_commands_and_wrap_around(box: SgiBoxEmulator, dev: tuple[SgiDevice, EventQueue]) -> None:
    _, q = dev
    box.wait_ready()
    # 0x20C0 = 8384: the high byte looks like a reset, the low byte like a button press
    steps = [100] * 83 + [84, -20, 52]  # walks through 0x20C0 and 0x2020
    for s in steps:
        box.turn(0, s)
    total = sum(e.delta for e in controls(wait_for(q, lambda e: getattr(e, "delta", None) == 52)))
    assert total == sum(steps)
    # wrap: walk to near +32767 and across it
    for _ in range(327):
        box.turn(1, 100)
    box.turn(1, 60)  # counter at 32760
    box.turn(1, 15)  # wraps to -32761
    got = controls(wait_for(q, lambda e: getattr(e, "delta", None) == 15))
    assert box.counters[1] == -32761 and sum(e.delta for e in got if e.control == "dial1") == 327 * 100 + 60 + 15
    assert all(-1 <= e.value <= 1 for e in got)
    assert not any(e.control.startswith("button") for e in got)


def test_lights_follow_set_light(box: SgiBoxEmulator, dev: tuple[SgiDevice, EventQueue]) -> None:
    d, _ = dev
    box.wait_ready()
    d.set_light("button3", True)
    d.set_light("button31", 1.0)
    assert box.wait_leds(lambda m: m == (1 << 3) | (1 << 31)) == (1 << 3) | (1 << 31)
    d.set_light("button3", False)
    box.wait_leds(lambda m: m == 1 << 31)
    d.set_light("dial0", True)  # no light there: silently ignored


def test_garbage_and_spontaneous_reset_reinitialise(box: SgiBoxEmulator, dev: tuple[SgiDevice, EventQueue]) -> None:
    d, q = dev
    box.wait_ready()
    d.set_light("button5", True)
    box.wait_leds(lambda m: m == 1 << 5)
    resets = box.resets
    box.port.write(bytes([0x01, 0x02, 0x03, 0x10, 0x40, 0x41, 0x99]))
    box.port.write(bytes([0x31]))  # a truncated dial packet eats the next two bytes
    box.ready.clear()
    import time

    deadline = time.monotonic() + 5
    while box.resets == resets and time.monotonic() < deadline:
        time.sleep(0.01)
    assert box.resets > resets  # garbage made the host re-initialise the box
    box.wait_ready()
    assert d.warnings.counts["garbage"] >= 6
    box.turn(4, 7)
    assert controls(wait_for(q, lambda e: getattr(e, "control", "") == "dial4"))[-1].delta == 7
    # the box resets by itself (power glitch): the host must enable it again and restore lights
    box.leds = 0
    box.spontaneous_reset()
    box.wait_ready()
    box.wait_leds(lambda m: m == 1 << 5)
    box.button(9, True)
    assert controls(wait_for(q, lambda e: getattr(e, "control", "") == "button9"))[-1].value == 1.0
    assert d.warnings.counts["reset"] >= 1


def test_unplug_and_replug_behind_the_same_path(box: SgiBoxEmulator, dev: tuple[SgiDevice, EventQueue]) -> None:
    d, q = dev
    box.wait_ready()
    d.set_light("button0", True)
    box.unplug()
    lost = wait_for(q, lambda e: isinstance(e, StatusEvent))[-1]
    assert lost.status == "lost" and not d.connected
    box.replug()
    back = wait_for(q, lambda e: isinstance(e, StatusEvent))[-1]
    assert back.status == "connected" and d.connected
    box.wait_ready()
    box.wait_leds(lambda m: m == 1)
    box.turn(6, -9)
    assert controls(wait_for(q, lambda e: getattr(e, "control", "") == "dial6"))[-1].delta == -9


def test_no_box_on_the_port_is_an_error(tmp_path: Path) -> None:
    from emulators import PtyPort

    from devices import DeviceError

    silent = PtyPort(tmp_path / "silent")
    try:
        SgiDevice.RESET_TRIES, old = 2, SgiDevice.RESET_TRIES
        try:
            with pytest.raises(DeviceError, match="no SGI box answered"):
                open_device(f"sgi://{silent.link}")
        finally:
            SgiDevice.RESET_TRIES = old
    finally:
        silent.close()


def test_parser_keeps_state_across_chunks_and_rejects_jumps() -> None:
    p = SgiParser("x", counts_per_turn=100)
    stream = bytes([0x30, 0x00, 0x05, 0x30, 0x00]) + bytes([0x0A, 0xDF])
    out = [e for i in range(len(stream)) for e in p.feed(stream[i : i + 1], float(i))]
    assert [(e.control, e.delta) for e in out] == [("dial0", 5), ("dial0", 5), ("button7", None)]
    assert p.feed(bytes([0x30, 0x40, 0x00]), 9.0) == []  # a 16000-count jump is not a movement
    assert p.warnings.counts["range"] == 1
    assert [e.delta for e in p.feed(bytes([0x30, 0x40, 0x01]), 10.0)] == [1]


def test_puppet_monitor_json_against_the_emulated_box(box: SgiBoxEmulator) -> None:
    import json
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "puppet", "monitor", f"sgi://{box.port.link}", "--json",
                             "--duration", "30"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=Path(__file__).parents[2])
    try:
        assert proc.stdout is not None
        first = json.loads(proc.stdout.readline())
        assert first["status"] == "connected" and first["device"] == f"sgi://{box.port.link}"
        box.wait_ready()
        box.turn(5, -4)
        box.button(30, True)
        dial = json.loads(proc.stdout.readline())
        button = json.loads(proc.stdout.readline())
        assert {k: dial[k] for k in ("control", "kind", "delta")} == {"control": "dial5", "kind": "dial", "delta": -4}
        assert dial["value"] == pytest.approx(-4 / 200) and dial["raw"] == -4
        assert {k: button[k] for k in ("control", "kind", "value")} == {"control": "button30", "kind": "button", "value": 1}
        assert "delta" not in button
        box.unplug()
        assert json.loads(proc.stdout.readline())["status"] == "lost"
    finally:
        proc.terminate()
        proc.wait(10)


def test_close_while_waiting_for_a_silent_box_is_prompt(tmp_path: Path) -> None:
    import threading

    from emulators import PtyPort

    silent = PtyPort(tmp_path / "silent")
    try:
        d = open_device(f"sgi://{silent.link}", require=False)  # nobody answers the reset
        d.start()
        started = threading.Event()
        closer = threading.Thread(target=lambda: (started.set(), d.close()))
        closer.start()
        started.wait()
        closer.join(2.0)  # a full handshake would take 5 x 0.5 s
        assert not closer.is_alive() and not d.connected
    finally:
        silent.close()
