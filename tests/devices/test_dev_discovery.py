"""Discovery: HID listing through a fake hidapi, probing emulated serial boxes, `puppet devices`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from emulators import FirmataEmulator, PtyPort, SgiBoxEmulator, TextBoxEmulator
from fakehid import FakeHidApi, FakeHidUnit
from devdata import MAPLE_RDESC

from devices.discovery import discover, probe_serial_port


def test_hid_listing_profiles_usages_and_probed_descriptors(monkeypatch: pytest.MonkeyPatch) -> None:
    pm = FakeHidUnit(0x077D, 0x0410, "A")
    pad = FakeHidUnit(0x1EAF, 0x0024, "", MAPLE_RDESC, "Maple")
    mouse = FakeHidUnit(0x046D, 0xC077, "", b"", "Mouse")
    mouse.info.update(usage_page=1, usage=2)
    api = FakeHidApi(pm, pad, mouse)
    import devices.discovery as disc

    monkeypatch.setattr(disc, "serial_ports", lambda probe: [])  # never poke the host's real ports
    infos = {i.spec: i for i in discover(probe=False, hid_api_module=api) if i.kind == "hid"}
    assert infos["hid://077d:0410"].usable and "PowerMate" in infos["hid://077d:0410"].description
    assert not infos["hid://1eaf:0024"].usable and "--probe" in infos["hid://1eaf:0024"].description
    assert not infos["hid://046d:c077"].usable
    probed = {i.spec: i for i in discover(probe=True, hid_api_module=api) if i.kind == "hid"}
    assert probed["hid://1eaf:0024"].usable and "39 controls" in probed["hid://1eaf:0024"].description
    assert any(i.spec == "keyboard://" for i in discover(hid_api_module=api))


def test_probe_tells_sgi_from_firmata(tmp_path: Path) -> None:
    sgi = SgiBoxEmulator(tmp_path / "a")
    fir = FirmataEmulator(tmp_path / "b")
    try:
        assert probe_serial_port(str(sgi.port.link)) == "sgi"
        assert probe_serial_port(str(fir.port.link)) == "firmata"
    finally:
        sgi.port.close()
        fir.port.close()


def test_a_probed_silent_port_is_not_usable_and_a_text_box_is(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`puppet devices --probe --json` marked every probed serial port usable, a port where nothing
    answered (a modem, a console, nothing plugged) too. Now a silent port is listed as not usable,
    and a text-protocol box that says its hello (as the example Arduino does on reset) as usable."""
    import threading

    from serial.tools import list_ports, list_ports_common

    import devices.discovery as disc

    monkeypatch.setattr(disc, "TEXT_LISTEN", 1.5)
    silent = PtyPort(tmp_path / "silent")
    box = TextBoxEmulator(tmp_path / "box")
    stop = threading.Event()

    def hello() -> None:  # the box says its hello every 0.3 s (as after each reset)
        while not stop.wait(0.3):
            box.send("H breadboard 4 buttons\n")

    talker = threading.Thread(target=hello, daemon=True)
    talker.start()
    ports = [list_ports_common.ListPortInfo(str(tmp_path / "silent")), list_ports_common.ListPortInfo(str(tmp_path / "box"))]
    monkeypatch.setattr(list_ports, "comports", lambda: ports)
    try:
        infos = {i.spec: i for i in disc.serial_ports(probe=True)}
    finally:
        stop.set()
        talker.join(2)
        silent.close()
        box.port.close()
    # the SGI box's ack is 0x20, a space: the first space of the box's hello passed for one
    assert not any(spec.startswith("sgi://") for spec in infos), infos
    quiet = infos[f"serial://{tmp_path / 'silent'}"]
    assert not quiet.usable and "silent" in quiet.description, quiet
    talking = infos[f"serial://{tmp_path / 'box'}"]
    assert talking.usable and "text-protocol box" in talking.description, talking


def test_puppet_devices_json_runs() -> None:
    out = subprocess.run([sys.executable, "-m", "puppet", "devices", "--json"], capture_output=True, text=True,
                         timeout=60, cwd=Path(__file__).parents[2])
    assert out.returncode == 0, out.stderr
    rows = [json.loads(line) for line in out.stdout.splitlines()]
    assert {"spec": "keyboard://", "kind": "keyboard", "usable": True} == {k: rows[-1][k] for k in ("spec", "kind", "usable")}
    assert all(set(r) == {"spec", "description", "kind", "usable"} for r in rows)


def test_a_driver_that_never_answers_hides_nothing_else(monkeypatch: pytest.MonkeyPatch,
                                                        caplog: pytest.LogCaptureFixture) -> None:
    """A wedged JACK server blocks its client for good: discovery leaves that family out after its
    time, says so, and still lists every other box (a show must never wait on it)."""
    import threading
    import time

    import devices.discovery as disc

    stuck = threading.Event()
    monkeypatch.setattr(disc, "serial_ports", lambda probe: [])
    monkeypatch.setattr(disc, "midi_ports", lambda: [stuck.wait(), []][1])  # blocks until released
    monkeypatch.setattr(disc, "audio_inputs", lambda: 1 / 0)
    api = FakeHidApi(FakeHidUnit(0x077D, 0x0410, "A"))
    try:
        t0 = time.monotonic()
        with caplog.at_level("WARNING", logger="devices"):
            specs = [i.spec for i in discover(hid_api_module=api, timeout=0.5)]
        assert time.monotonic() - t0 < 30  # it returned (the blocked family is not waited for)
    finally:
        stuck.set()
    assert specs == ["hid://077d:0410", "keyboard://"]
    assert "MIDI ports did not answer" in caplog.text and "division by zero" in caplog.text


def test_a_stuck_midi_listing_makes_the_next_one_give_up(monkeypatch: pytest.MonkeyPatch) -> None:
    """While one listing is stuck in its server, the next does not queue behind it for good."""
    from devices.errors import DeviceError
    from devices.midi import discover as mdisc
    from devices.midi import port

    monkeypatch.setattr(port, "ENUM_WAIT", 0.2)
    monkeypatch.setattr(port, "api_available", lambda api: True)
    monkeypatch.setattr(port, "_server_identity", lambda api: api)
    assert port._ENUM_LOCK.acquire(timeout=5)
    try:
        with pytest.raises(DeviceError, match="did not answer"):
            port.list_ports("jack")
        assert mdisc.midi_ports() == []  # both APIs left out, with a warning, no exception
    finally:
        port._ENUM_LOCK.release()


def test_serial_ports_are_probed_side_by_side(monkeypatch: pytest.MonkeyPatch) -> None:
    """A probe takes up to ~6 s a port (the SGI reset, a Firmata board's boot, a text box's hello);
    one after the other, ten ports outlasted discovery's minute and the whole family was left out.
    Three ports' probes must be under way at once (a barrier of three: one at a time never passes)."""
    import threading

    from serial.tools import list_ports, list_ports_common

    import devices.discovery as disc

    barrier = threading.Barrier(3, timeout=20)

    def probe(path: str) -> str | None:
        barrier.wait()  # BrokenBarrierError unless all three are probing together
        return "sgi" if path.endswith("1") else None

    monkeypatch.setattr(disc, "probe_serial_port", probe)
    monkeypatch.setattr(list_ports, "comports",
                        lambda: [list_ports_common.ListPortInfo(f"/dev/ttyFAKE{i}") for i in range(3)])
    infos = {i.spec: i for i in disc.serial_ports(probe=True)}
    assert set(infos) == {"serial:///dev/ttyFAKE0", "sgi:///dev/ttyFAKE1", "serial:///dev/ttyFAKE2"}
    assert infos["sgi:///dev/ttyFAKE1"].usable and not infos["serial:///dev/ttyFAKE0"].usable
