"""can:// on python-can's virtual bus with the example DBCs, injected error frames and bad frames."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import can
import cantools
import pytest
from devdata import BJM1_DBC, PANEL_DBC, controls, wait_for

from devices import DeviceSpecError, EventQueue, StatusEvent, open_device
from devices.candev import CanDevice

PANEL, BJM1 = PANEL_DBC, BJM1_DBC
_channels = itertools.count()


@pytest.fixture
def channel() -> str:
    return f"facepuppet-test-{next(_channels)}"


@pytest.fixture
def panel_bus(channel: str) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


def _open(spec: str) -> tuple[CanDevice, EventQueue]:
    d = open_device(spec)
    assert isinstance(d, CanDevice)
    q = EventQueue()
    d.add_listener(q)
    d.start()
    wait_for(q, lambda e: isinstance(e, StatusEvent))
    return d, q


def test_panel_dials_buttons_faders_and_bus_errors(channel: str, panel_bus: can.BusABC) -> None:
    db = cantools.database.load_file(PANEL)
    d, q = _open(f"can://virtual/{channel}?dbc={PANEL}")
    names = {c.name: c.kind for c in d.controls}
    assert sum(k == "dial" for k in names.values()) == 8 and sum(k == "button" for k in names.values()) == 16
    dials = {f"Dial{i}": 0 for i in range(8)}

    def send(name: str, **values: float) -> None:
        msg = db.get_message_by_name(name)
        panel_bus.send(can.Message(arbitration_id=msg.frame_id, data=msg.encode(values), is_extended_id=False))

    send("PanelDials", **dials)  # baseline counters
    send("PanelDials", **{**dials, "Dial3": 5})
    send("PanelDials", **{**dials, "Dial3": 250})  # 5 -> 250 wraps backwards: -11
    buttons = {f"Button{i}": 0 for i in range(16)}
    send("PanelButtons", **{**buttons, "Button12": 1})
    panel_bus.send(can.Message(arbitration_id=0x004, is_error_frame=True, data=bytes([0, 0x10, 0, 0, 0, 0, 0, 0])))
    panel_bus.send(can.Message(arbitration_id=0x101, data=b"\x01", is_extended_id=False))  # too short for the DBC
    panel_bus.send(can.Message(arbitration_id=0x555, data=b"\x01\x02", is_extended_id=False))  # not in the DBC
    send("PanelFaders", Fader0=0.25, Fader1=1.0)
    send("PanelButtons", **buttons)
    got = controls(wait_for(q, lambda e: getattr(e, "control", "") == "Button12" and e.value == 0))
    assert [(e.control, e.delta if e.kind == "dial" else e.value) for e in got] == [
        ("Dial3", 5), ("Dial3", -11), ("Button12", 1.0), ("Fader0", 0.25), ("Fader1", 1.0), ("Button12", 0.0)]
    assert got[0].value == pytest.approx(5 / 24)
    assert d.connected
    assert d.bus_errors["controller problem, RX passive"] == 1
    assert d.warnings.counts["decode"] == 1 and d.decoder.unknown_frames == 1
    d.close()


def test_j1939_joystick_any_source_address(channel: str, panel_bus: can.BusABC) -> None:
    db = cantools.database.load_file(BJM1)
    msg = db.get_message_by_name("BJM1")
    d, q = _open(f"can://virtual/{channel}?dbc={BJM1}")
    assert d.control("Joystick1XAxisPosition").lo == -1.0  # type: ignore[union-attr]
    base = {s.name: 0 for s in msg.signals}
    frame = msg.encode({**base, "Joystick1XAxisPosition": 50.0, "Jstk1XAxsLvrLftNgtvPstnStts": 1,
                        "Joystick1Button1PressedStatus": 1, "Joystick1Button12PressedStatus": 3})
    panel_bus.send(can.Message(arbitration_id=0x0CFDD613, data=frame, is_extended_id=True))  # source 0x13
    frame2 = msg.encode({**base, "Joystick1YAxisPosition": 100.0, "Joystick1Button1PressedStatus": 2})
    panel_bus.send(can.Message(arbitration_id=0x0CFDD613, data=frame2, is_extended_id=True))
    got = controls(wait_for(q, lambda e: getattr(e, "control", "") == "Joystick1YAxisPosition" and e.value == 1))
    seen = [(e.control, e.value) for e in got]
    assert ("Joystick1XAxisPosition", -0.5) in seen and ("Joystick1Button1PressedStatus", 1.0) in seen
    assert ("Joystick1YAxisPosition", 1.0) in seen
    assert not any(c.startswith("Jstk1") for c, _ in seen)  # status signals are ignored
    assert d.warnings.counts["range"] == 1  # the button's "error" state
    d.close()


def test_bus_failure_is_a_lost_device_that_comes_back(channel: str) -> None:
    d, q = _open(f"can://virtual/{channel}?dbc={PANEL}")
    d._bus.shutdown()  # the interface went down under us
    assert wait_for(q, lambda e: isinstance(e, StatusEvent))[-1].status == "lost"
    assert wait_for(q, lambda e: isinstance(e, StatusEvent))[-1].status == "connected"
    d.close()


def test_bad_specs(tmp_path: Path) -> None:
    with pytest.raises(DeviceSpecError, match="DBC file"):
        open_device("can://virtual/x")
    with pytest.raises(DeviceSpecError, match="not found"):
        open_device("can://virtual/x?dbc=/nonexistent.dbc")
    bad = tmp_path / "bad.dbc"
    bad.write_text("BO_ this is not a dbc")
    with pytest.raises(DeviceSpecError, match="cannot load"):
        open_device(f"can://virtual/x?dbc={bad}")
    with pytest.raises(DeviceSpecError, match="INTERFACE/CHANNEL"):
        open_device(f"can://virtual?dbc={PANEL}")


def test_an_extended_frame_is_not_the_standard_message_of_its_number(channel: str, panel_bus: can.BusABC) -> None:
    """The panel DBC's PanelButtons is the standard frame 0x101; an extended frame 0x101 is another
    frame (another node's, a J1939 one): it moves no button and is counted as unknown."""
    d, q = _open(f"can://virtual/{channel}?dbc={PANEL}")
    try:
        panel_bus.send(can.Message(arbitration_id=0x101, data=b"\x01\x00", is_extended_id=True))
        panel_bus.send(can.Message(arbitration_id=0x101, data=b"\x02\x00", is_extended_id=False))
        got = controls(wait_for(q, lambda e: getattr(e, "control", None) == "Button1"))
        assert [(e.control, e.value) for e in got] == [("Button1", 1.0)]
        assert q.get(timeout=0.2) is None  # nothing else: Button0 never pressed
        assert d.decoder.unknown_frames == 1
    finally:
        d.close()


def test_a_j1939_pdu1_message_matches_whatever_its_destination(channel: str, panel_bus: can.BusABC,
                                                               tmp_path: Path) -> None:
    """PDU1 messages (PDU format below 240) carry a destination address where PDU2 ones carry part
    of the PGN. The DBC names the message sent to the global address (0x18EFFFFE); the panel sends it
    to this host (0x27) from another source (0x13): it matched nothing before (the destination was
    taken as part of the PGN), and is the DBC's message now."""
    dbc = tmp_path / "pdu1.dbc"
    dbc.write_text('VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_: Panel Host\n\n'
                   'BO_ 2565865470 PropA: 8 Panel\n'  # 0x80000000 | 0x18EFFFFE: extended, PGN 0xEF00
                   ' SG_ Knob : 0|8@1+ (1,0) [0|255] "" Host\n\n'
                   'CM_ SG_ 2565865470 Knob "kind=axis";\n')
    d, q = _open(f"can://virtual/{channel}?dbc={dbc}")
    try:
        panel_bus.send(can.Message(arbitration_id=0x18EF2713, data=bytes([51, 0, 0, 0, 0, 0, 0, 0]),
                                   is_extended_id=True))
        got = controls(wait_for(q, lambda e: getattr(e, "control", None) == "Knob"))
        assert got[-1].value == pytest.approx(51 / 255) and d.decoder.unknown_frames == 0
    finally:
        d.close()
