"""hid:// decoding from real report descriptors and report bytes, at the hidapi object boundary."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from devdata import MAPLE_RDESC, MAPLE_REPORT, ROLLER_EVENTS, ROLLER_RDESC, controls, wait_for
from fakehid import FakeHidApi, FakeHidUnit

from devices import DeviceError, EventQueue, StatusEvent, open_device
from devices.hid.descriptor import DescriptorError, GenericDecoder, ReportDescriptor
from devices.hid.device import HidDevice
from devices.hid.profiles import PowerMateProfile

def test_maple_descriptor_and_report_decode_as_hid_recorder_did() -> None:
    desc = ReportDescriptor.parse(MAPLE_RDESC)
    assert desc.numbered and desc.report_bytes == {0x14: 12}
    dec = GenericDecoder("m", desc)
    names = [c.name for c in dec.controls]
    assert names[:32] == [f"button{i}" for i in range(32)]
    assert names[32:] == ["hat", "x", "y", "rx", "ry", "slider", "slider1"]
    got = {e.control: e.raw for e in dec.decode(MAPLE_REPORT, 1.0)}
    assert got == {"hat": 15, "x": 512, "y": 512, "rx": 0, "ry": 0, "slider": 0, "slider1": 7}
    again = dec.decode(MAPLE_REPORT, 2.0)
    assert again == []  # the same state twice is not a change
    pressed = bytearray(MAPLE_REPORT)
    pressed[1] |= 0x01  # button 1
    pressed[4] |= 0x80  # button 32
    pressed[5] = (pressed[5] & 0xF0) | 0x02  # hat east
    ev = {e.control: e.value for e in dec.decode(bytes(pressed), 3.0)}
    assert ev == {"button0": 1.0, "button31": 1.0, "hat": 2.0}
    for e in dec.decode(MAPLE_REPORT, 4.0):
        info = next(c for c in dec.controls if c.name == e.control)
        assert info.lo <= e.value <= info.hi


def test_rollermouse_button_press_release_from_recording() -> None:
    dec = GenericDecoder("r", ReportDescriptor.parse(ROLLER_RDESC))
    kinds = {c.name: c.kind for c in dec.controls}
    assert kinds["x"] == "dial" and kinds["y"] == "dial" and kinds["wheel"] == "dial"
    assert kinds["button0"] == "button" and kinds["button23"] == "button"  # report 3's buttons 9-24
    seq = [[(e.control, e.value) for e in dec.decode(r, float(i))] for i, r in enumerate(ROLLER_EVENTS)]
    assert seq == [[], [("button0", 1.0)], [("button0", 0.0)]]
    moved = bytearray(ROLLER_EVENTS[0])
    moved[2:4] = (5).to_bytes(2, "little")  # X +5
    moved[6] = 0xFF  # wheel -1
    ev = {e.control: e.delta for e in dec.decode(bytes(moved), 9.0)}
    assert ev == {"x": 5, "wheel": -1}
    assert dec.decode(b"\x09\x00", 10.0) == [] and dec.warnings.counts["unknown-report"] == 1
    assert dec.decode(ROLLER_EVENTS[0][:5], 11.0) == [] and dec.warnings.counts["truncated"] == 1


def test_malformed_descriptors_are_rejected() -> None:
    with pytest.raises(DescriptorError):
        ReportDescriptor.parse(MAPLE_RDESC[:-2] + b"\x26\xff")
    with pytest.raises(DescriptorError):
        ReportDescriptor.parse(b"\xc0")
    with pytest.raises(DescriptorError):
        ReportDescriptor.parse(b"\x85\x00")
    with pytest.raises(DescriptorError, match="count"):
        ReportDescriptor.parse(bytes.fromhex("05 01 09 30 75 08 97 ff ff ff ff 81 02"))
    upside_down = GenericDecoder("u", ReportDescriptor.parse(bytes.fromhex("05 01 09 30 15 1e 25 00 75 08 95 01 81 02")))
    assert upside_down.controls == []  # logical max below min: no value can be valid
    huge = GenericDecoder("h", ReportDescriptor.parse(bytes.fromhex("05 01 09 30 15 00 25 7f 75 08 96 00 10 81 02")))
    assert len(huge.controls) == 256


@pytest.fixture
def events() -> Iterator[EventQueue]:
    yield EventQueue()


def _start(spec: str, api: FakeHidApi, q: EventQueue) -> HidDevice:
    d = open_device(spec, hid_api_module=api)
    assert isinstance(d, HidDevice)
    d.add_listener(q)
    d.start()
    wait_for(q, lambda e: isinstance(e, StatusEvent))
    return d


def test_powermate_knob_button_and_led(events: EventQueue) -> None:
    unit = FakeHidUnit(0x077D, 0x0410, "PM1")
    api = FakeHidApi(unit)
    d = _start("hid://077d:0410", api, events)
    assert "PowerMate" in d.description and {c.name for c in d.controls} == {"knob", "button0"}
    for r in ([0x00, 0x01, 0x00, 0x80, 0x00, 0x00], [0x01, 0x00, 0x00, 0x80, 0x00, 0x00],
              [0x01, 0xFD, 0x00, 0x80, 0x00, 0x00], [0x00, 0x00, 0x00, 0x80, 0x00, 0x00],
              [0x00, 0x90, 0x00, 0x80, 0x00, 0x00]):  # last: -112 clicks in one poll is impossible
        unit.send(r)
    unit.send([0x00, 0x07, 0x00, 0x80, 0x00, 0x00])
    got = controls(wait_for(events, lambda e: getattr(e, "delta", None) == 7))
    assert [(e.control, e.delta if e.kind == "dial" else e.value) for e in got] == [
        ("knob", 1), ("button0", 1.0), ("knob", -3), ("button0", 0.0), ("knob", 7)]
    assert got[0].value == pytest.approx(1 / 94) and d.warnings.counts["range"] == 1
    d.set_light("button0", 80 / 255)
    unit.wait_written(lambda u: bytes.fromhex("00 41 01 01 00 50 00 00 00") in u.features)
    d.set_pulse(True, 255)
    unit.wait_written(lambda u: bytes.fromhex("00 41 01 04 00 01 00 00 00") in u.features)
    d.close()


def test_shuttlexpress_ring_jog_wrap_and_buttons(events: EventQueue) -> None:
    unit = FakeHidUnit(0x0B33, 0x0020)
    d = _start("hid://0b33:0020", FakeHidApi(unit), events)
    unit.send([0x00, 0xFE, 0x00, 0x00, 0x00])  # baseline: jog counter 254
    unit.send([0x00, 0xFF, 0x00, 0x00, 0x00])  # +1
    unit.send([0x00, 0x01, 0x00, 0x00, 0x00])  # 255 -> 1 wraps: +2
    unit.send([0xF9, 0x01, 0x00, 0x10, 0x00])  # ring full left, button 0
    unit.send([0x03, 0x00, 0x00, 0x00, 0x01])  # ring right 3, jog -1, button 4 only
    unit.send([0x09, 0x00, 0x00, 0x00, 0x01])  # impossible ring position
    unit.send([0x00, 0x00, 0x00, 0x00, 0x00])
    got = controls(wait_for(events, lambda e: e.control == "button4" and e.value == 0))
    assert [(e.control, e.delta if e.kind == "dial" else e.value) for e in got] == [
        ("shuttle", 0.0), ("jog", 1), ("jog", 2), ("shuttle", -1.0), ("button0", 1.0),
        ("shuttle", 3 / 7), ("jog", -1), ("button0", 0.0), ("button4", 1.0),
        ("shuttle", 0.0), ("button4", 0.0)]
    assert d.warnings.counts["range"] == 1
    d.close()


def test_xkeys_keys_and_backlights(events: EventQueue) -> None:
    unit = FakeHidUnit(0x05F3, 1029)  # XK-24: 4 columns of 6 keys
    d = _start("hid://05f3:0405", FakeHidApi(unit), events)
    unit.wait_written(lambda u: any(w[1] == 177 for w in u.written))  # asked for the full state
    report = [0x00, 0x00, 0x00, 0x04, 0x00, 0x00] + [0x00] * 26
    unit.send(report)  # column 1, row 2 -> key 1*6+2+1 = 9
    report2 = list(report)
    report2[1] = 0x01  # program switch
    report2[3] = 0x00
    unit.send(report2)
    unit.send([0x00, 214] + [0x00] * 30)  # a version report: not keys
    got = controls(wait_for(events, lambda e: e.control == "button9" and e.value == 0))
    assert [(e.control, e.value) for e in got] == [("button9", 1.0), ("button0", 1.0), ("button9", 0.0)]
    d.set_light("button9", True)
    unit.wait_written(lambda u: bytes([0, 181, 1 * 8 + 2, 1]).ljust(36, b"\0") in u.written)
    d.close()


def test_unknown_panel_through_its_descriptor_and_hot_plug(events: EventQueue) -> None:
    unit = FakeHidUnit(0x1EAF, 0x0024, "S1", MAPLE_RDESC, "LeafLabs Maple")
    other = FakeHidUnit(0x1EAF, 0x0024, "S2", MAPLE_RDESC, "LeafLabs Maple")
    api = FakeHidApi(other, unit)
    d = _start("hid://1eaf:0024?serial=S1", api, events)
    assert "LeafLabs Maple" in d.description and d.control("slider1") is not None
    unit.send(MAPLE_REPORT)
    assert {e.control for e in controls(wait_for(events, lambda e: getattr(e, "control", "") == "slider1"))} >= {"x", "y"}
    api.unplug(unit)
    assert wait_for(events, lambda e: isinstance(e, StatusEvent))[-1].status == "lost"
    assert unit.opens == 1
    api.replug(unit)
    assert wait_for(events, lambda e: isinstance(e, StatusEvent))[-1].status == "connected"
    assert unit.opens == 2 and other.opens == 0  # the same unit, chosen by serial number
    moved = bytearray(MAPLE_REPORT)
    moved[1] = 0x02
    unit.send(bytes(moved))
    assert controls(wait_for(events, lambda e: getattr(e, "control", "") == "button1"))[-1].value == 1.0
    d.close()


def test_missing_or_unusable_devices() -> None:
    with pytest.raises(DeviceError, match="no HID device 1234:5678"):
        open_device("hid://1234:5678", hid_api_module=FakeHidApi())
    vendor_only = bytes.fromhex("06 00 ff 09 01 a1 01 15 00 26 ff 00 75 08 95 08 81 02 c0")
    with pytest.raises(DeviceError, match="no buttons, axes or dials"):
        open_device("hid://1234:5678", hid_api_module=FakeHidApi(FakeHidUnit(0x1234, 0x5678, descriptor=vendor_only)))
    from devices import DeviceSpecError

    with pytest.raises(DeviceSpecError, match="VID:PID"):
        open_device("hid://powermate")


def test_powermate_pulse_encoding() -> None:
    from devices.warn import WarningCounter

    p = PowerMateProfile("p", WarningCounter("p"))
    slow, fast = p.pulse(True, 100), p.pulse(True, 400)
    assert slow[0].data[5:7] == bytes([0, 155]) and fast[0].data[5:7] == bytes([2, 145])

