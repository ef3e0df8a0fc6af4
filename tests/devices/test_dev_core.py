"""Specs, the backend registry, EventQueue and the base reader thread's loss/reconnect handling."""

from __future__ import annotations

import threading
from collections.abc import Iterable
from typing import Any

import pytest

import devices
from devices import ControlEvent, Device, DeviceError, DeviceSpecError, EventQueue, StatusEvent, parse_spec
from devices.base import ControlInfo
from devices.spec import DeviceSpec


def test_spec_parsing() -> None:
    s = parse_spec("serial:///dev/ttyUSB1?baud=115200")
    assert (s.scheme, s.location, s.query) == ("serial", "/dev/ttyUSB1", {"baud": "115200"})
    assert s.get_int("baud", 9600) == 115200
    assert parse_spec("hid://077d:0410").location == "077d:0410"
    assert parse_spec("can://virtual/panel?dbc=x.dbc&bitrate=250000").query["bitrate"] == "250000"
    for bad in ("/dev/ttyUSB0", "", "9x://a", "sgi://a?x=1&x=2"):
        with pytest.raises(DeviceSpecError):
            parse_spec(bad)
    with pytest.raises(DeviceSpecError, match="outside 1..9"):
        parse_spec("sgi://a?counts_per_turn=0").get_int("counts_per_turn", 200, lo=1, hi=9)
    with pytest.raises(DeviceSpecError, match=r"index=-1 must be 0 or more$"):  # not 'outside 0..None'
        parse_spec("hid://077d:0410?index=-1").get_int("index", 0, lo=0)
    with pytest.raises(DeviceSpecError, match=r"n=9 must be 8 or less$"):
        parse_spec("x://a?n=9").get_int("n", 0, hi=8)


def test_unknown_scheme_and_option_show_the_expected_form() -> None:
    with pytest.raises(DeviceSpecError, match="expected one of .*sgi"):
        devices.open_device("nope://x")
    with pytest.raises(DeviceSpecError, match="keyboard://"):
        devices.open_device("keyboard://?colour=red")
    with pytest.raises(DeviceSpecError, match="no address; expected keyboard://"):
        devices.open_device("keyboard://x")  # was opened as the keyboard, the x ignored
    devices.open_device("keyboard://").close()


def test_importing_devices_imports_no_backend_library() -> None:
    import subprocess
    import sys

    code = "import sys, devices; print(sorted(m for m in ('hid','can','cantools','glfw','serial') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


class FlakyDevice(Device):
    """A backend whose 'hardware' can be unplugged and replugged by the test."""

    scheme = "flaky"
    reconnect_interval = 0.01
    read_timeout = 0.01

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        self.present = threading.Event()
        self.present.set()
        self.opens = 0
        self.closes = 0
        self.pending: list[float] = []
        self.controls = [ControlInfo("button0", "button", 0, 1, True)]
        self.lights: list[tuple[str, float]] = []

    def _open(self) -> None:
        if not self.present.is_set():
            raise OSError("not there")
        self.opens += 1

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        if not self.present.is_set():
            raise OSError("read error")
        if self.pending:
            return [ControlEvent(self.spec, "button0", "button", self.pending.pop(0), t=1.0)]
        self._stop.wait(timeout)
        return ()

    def _close_handle(self) -> None:
        self.closes += 1

    def _set_light(self, control: str, level: float) -> None:
        self.lights.append((control, level))


def _wait_for(q: EventQueue, pred: Any, timeout: float = 5.0) -> list[Any]:
    seen = []
    while True:
        e = q.get(timeout=timeout)
        assert e is not None, f"timed out; saw {seen}"
        seen.append(e)
        if pred(e):
            return seen


def test_loss_and_reconnect_with_plugin_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(devices.BACKENDS, "flaky", (__name__, "FlakyDevice"))
    dev = devices.open_device("flaky://x")
    assert isinstance(dev, FlakyDevice) and dev.connected
    q = EventQueue()
    boom_calls = []

    def boom(e: Any) -> None:
        boom_calls.append(e)
        raise RuntimeError("a buggy listener")

    dev.add_listener(boom)
    dev.add_listener(q)
    dev.set_light("button0", True)
    dev.set_light("nonexistent", True)  # silent no-op
    dev.start()
    assert isinstance(q.get(timeout=5), StatusEvent)
    dev.pending.append(1.0)
    _wait_for(q, lambda e: isinstance(e, ControlEvent))
    dev.present.clear()
    lost = _wait_for(q, lambda e: isinstance(e, StatusEvent))[-1]
    assert lost.status == "lost" and not dev.connected
    closes = dev.closes
    assert closes >= 1  # the stale handle was closed
    dev.present.set()
    back = _wait_for(q, lambda e: isinstance(e, StatusEvent))[-1]
    assert back.status == "connected" and dev.connected
    assert dev.lights.count(("button0", 1.0)) >= 2  # the light came back on after the replug
    dev.pending.append(0.0)
    assert _wait_for(q, lambda e: isinstance(e, ControlEvent))[-1].value == 0.0
    assert boom_calls and dev.warnings.counts["listener"] >= 1
    dev.close()
    dev.close()
    assert not dev.connected


def test_a_box_back_after_a_loss_is_said_as_the_loss_was(monkeypatch: pytest.MonkeyPatch,
                                                        caplog: pytest.LogCaptureFixture) -> None:
    """A headless show's log said "lost (...); reconnecting" when a box went, and nothing when it
    came back: the performer without a window could not tell the box worked again."""
    monkeypatch.setitem(devices.BACKENDS, "flaky", (__name__, "FlakyDevice"))
    with caplog.at_level("WARNING", logger="devices"):
        dev = devices.open_device("flaky://x")
        q = EventQueue()
        dev.add_listener(q)
        dev.start()
        try:
            _wait_for(q, lambda e: isinstance(e, StatusEvent))
            dev.present.clear()
            _wait_for(q, lambda e: isinstance(e, StatusEvent) and e.status == "lost")
            dev.present.set()
            _wait_for(q, lambda e: isinstance(e, StatusEvent) and e.status == "connected")
        finally:
            dev.close()
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("flaky://x: ")]
    assert len(said) == 2 and "lost" in said[0] and said[1] == "flaky://x: connected again", said


def test_missing_device_raises_or_waits(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(devices.BACKENDS, "flaky", (__name__, "FlakyDevice"))
    monkeypatch.setattr(FlakyDevice, "_open", lambda self: (_ for _ in ()).throw(OSError("absent")))
    with pytest.raises(DeviceError, match="flaky://gone"):
        devices.open_device("flaky://gone")
    dev = devices.open_device("flaky://gone", require=False)
    assert not dev.connected
    dev.close()


def test_entry_point_backends_are_found(monkeypatch: pytest.MonkeyPatch) -> None:
    class EP:
        name, value = "myplug", f"{__name__}:FlakyDevice"

    monkeypatch.setattr(devices.registry, "entry_points", lambda group: [EP()] if group == "puppet.devices" else [])
    assert "myplug" in devices.known_schemes()
    assert devices.backend_class("myplug") is FlakyDevice


def test_event_queue_drops_oldest_when_full() -> None:
    q = EventQueue(maxsize=2)
    for i in range(3):
        q.put(StatusEvent(f"d{i}", "lost"))
    assert [e.device for e in q.drain()] == ["d1", "d2"] and q.dropped == 1
    assert q.drain() == [] and q.get(timeout=0.01) is None


def test_opt_in_realtime_reader_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    def can_go_realtime() -> bool:
        result: list[bool] = []

        def trial() -> None:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
                result.append(True)
            except OSError:
                result.append(False)

        t = threading.Thread(target=trial)
        t.start()
        t.join()
        return result[0]

    policies: list[int] = []
    monkeypatch.setenv("PUPPET_REALTIME_DEVICES", "1")
    dev = devices.open_device("mock://?sine=x&duration=0.1&rate=10&speed=0")
    dev.add_listener(lambda e: policies.append(os.sched_getscheduler(0)))
    q = EventQueue()
    dev.add_listener(q)
    dev.start()
    assert q.get(timeout=5) is not None
    dev.close()
    expected = os.SCHED_FIFO if can_go_realtime() else os.SCHED_OTHER
    assert policies and set(policies) == {expected}
    assert os.sched_getscheduler(0) == os.SCHED_OTHER  # the caller's thread is untouched


def test_status_events_strictly_alternate(monkeypatch: pytest.MonkeyPatch) -> None:
    """Whatever order a backend reports in, listeners hear connected, lost, connected...: a second
    `lost` is not repeated and a reopen whose loss went unreported is told as lost-then-connected."""
    monkeypatch.setitem(devices.BACKENDS, "flaky", (__name__, "FlakyDevice"))
    dev = devices.open_device("flaky://x")
    q = EventQueue()
    dev.add_listener(q)
    for status in ("connected", "lost", "lost", "connected", "connected", "lost"):
        dev._status(status, "test")
    told = [e.status for e in q.drain()]
    assert told == ["connected", "lost", "connected", "lost", "connected", "lost"]
    dev.close()


def test_a_first_open_that_fails_on_an_existing_address_is_retried(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(devices.BACKENDS, "flaky", (__name__, "FlakyDevice"))
    monkeypatch.setattr(FlakyDevice, "address_exists", lambda self: True)
    tries = []

    def flaky_open(self: FlakyDevice) -> None:
        tries.append(1)
        if len(tries) < 3:
            raise OSError("Could not configure port: (5, 'Input/output error')")

    monkeypatch.setattr(FlakyDevice, "_open", flaky_open)
    with pytest.raises(DeviceError):
        devices.open_device("flaky://x")
    dev = devices.open_device("flaky://x", require="present")
    assert not dev.connected and "Input/output error" in dev.last_error
    q = EventQueue()
    dev.add_listener(q)
    dev.start()
    first = _wait_for(q, lambda e: isinstance(e, StatusEvent))
    assert [(e.status, e.detail) for e in first] == [("connected", "opened")] and dev.connected
    dev.close()


def test_a_device_lost_as_soon_as_it_opens_is_retried_at_the_reconnect_pace(monkeypatch: pytest.MonkeyPatch) -> None:
    """A node that opens and then fails its first read (rawmidi:///dev/null reads end of file, a
    box dying right after its handshake) must not spin: the reopen waits the reconnect interval,
    so the show and its recording get a few status events a second, not tens of thousands."""
    monkeypatch.setitem(devices.BACKENDS, "flaky", (__name__, "FlakyDevice"))
    monkeypatch.setattr(FlakyDevice, "reconnect_interval", 0.05)

    def dead_read(self: FlakyDevice, timeout: float) -> Iterable[ControlEvent]:
        raise OSError("end of stream")

    monkeypatch.setattr(FlakyDevice, "_read", dead_read)
    dev = devices.open_device("flaky://x")
    q = EventQueue()
    dev.add_listener(q)
    dev.start()
    threading.Event().wait(0.5)
    dev.close()
    told = q.drain()
    assert told and told[0].status == "connected"
    assert len(told) <= 2 * (0.5 / 0.05 + 2), f"{len(told)} status events in 0.5 s"
    assert dev.opens <= 0.5 / 0.05 + 2
