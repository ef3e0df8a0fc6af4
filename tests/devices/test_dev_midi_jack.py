"""midi:// end to end through real MIDI ports: a private JACK server, python-rtmidi's JACK API, and
controllers emulated in separate processes (played traffic, lights seen on the box's input side,
unplug = the process exits, replug = it comes back)."""

from __future__ import annotations

import time

import pytest
from midijack import MidiBox, jack_server  # noqa: F401  (the fixture)

import devices
from devices import ControlEvent, StatusEvent, open_device


class Collector:
    def __init__(self) -> None:
        self.events: list[object] = []

    def __call__(self, ev: object) -> None:
        self.events.append(ev)

    def controls(self) -> list[ControlEvent]:
        return [e for e in self.events if isinstance(e, ControlEvent)]

    def statuses(self) -> list[str]:
        return [e.status for e in self.events if isinstance(e, StatusEvent)]

    def wait(self, pred: object, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while not pred(self):  # type: ignore[operator]
            assert time.monotonic() < deadline, f"timed out; got {self.events}"
            time.sleep(0.01)


@pytest.fixture()
def nano(jack_server: str):  # noqa: F811
    box = MidiBox("nanoKONTROL2").plug()
    yield box
    box.close()


def test_controls_lights_and_replug(nano: MidiBox) -> None:
    dev = open_device("midi://nanokontrol2?api=jack")  # a substring of the port name, any case
    assert dev.profile.name == "nanokontrol2"
    got = Collector()
    dev.add_listener(got)
    dev.start()
    try:
        got.wait(lambda c: c.statuses() == ["connected"])
        nano.send((0xB0, 0, 0), (0xB0, 0, 64), (0xB0, 0, 127), (0xB0, 32, 127), (0xB0, 32, 0), (0xB0, 17, 100))
        got.wait(lambda c: len(c.controls()) == 6)
        assert [(e.control, e.kind, round(e.value, 3)) for e in got.controls()] == [
            ("fader1", "axis", 0.0), ("fader1", "axis", 0.504), ("fader1", "axis", 1.0),
            ("s1", "button", 1.0), ("s1", "button", 0.0), ("knob2", "axis", 0.787)]
        # lights: the box sees the same CC it sends, once per change
        dev.set_light("s1", True)
        dev.set_light("s1", True)
        dev.set_light("r8", 1.0)
        nano.wait_received(lambda r: (0xB0, 32, 127) in r and (0xB0, 71, 127) in r)
        time.sleep(0.2)
        assert nano.received.count((0xB0, 32, 127)) == 1
        dev.set_light("fader1", 1.0)  # no LED there: nothing is sent
        # unplug mid-show: lost; replug: connected again, input flows, the lit LED comes back
        nano.unplug()
        got.wait(lambda c: c.statuses()[-1:] == ["lost"])
        nano.received.clear()
        nano.plug()
        got.wait(lambda c: c.statuses()[-1:] == ["connected"])
        nano.wait_received(lambda r: (0xB0, 32, 127) in r and (0xB0, 71, 127) in r)
        n = len(got.controls())
        nano.send((0xB0, 33, 127))
        got.wait(lambda c: len(c.controls()) == n + 1)
        assert got.controls()[-1].control == "s2"
        assert not any(len(m) == 3 and m[0] == 0xB0 and m[1] in range(8) for m in nano.received)  # no echo
    finally:
        dev.close()


def test_xtouch_mini_rings_and_lights_on_its_own_channel(jack_server: str) -> None:  # noqa: F811
    box = MidiBox("X-TOUCH MINI", "X-TOUCH MINI MIDI 1").plug()
    try:
        dev = open_device("midi://x-touch mini?api=jack")
        assert dev.profile.name == "xtouch_mini"
        got = Collector()
        dev.add_listener(got)
        dev.start()
        try:
            box.send((0xBA, 1, 70), (0x9A, 8, 127), (0x8A, 8, 0), (0xB0, 1, 5))
            got.wait(lambda c: len(c.controls()) == 4)
            assert [e.control for e in got.controls()] == ["encoder1", "button1", "button1", "ch1.cc1"]
            dev.set_light("encoder1", 0.5)  # the ring follows the channel it drives
            dev.set_light("button1", True)  # lit on note 0, though it sends note 8
            box.wait_received(lambda r: (0xBA, 1, 64) in r and (0x9A, 0, 1) in r)
        finally:
            dev.close()
    finally:
        box.close()


def test_a_port_that_is_not_there_yet_connects_when_it_appears(jack_server: str) -> None:  # noqa: F811
    dev = open_device("midi://nanoKONTROL2?api=jack", require=False)
    got = Collector()
    dev.add_listener(got)
    dev.start()
    box = MidiBox("nanoKONTROL2")
    try:
        time.sleep(0.3)
        assert got.statuses() == []
        box.plug()
        got.wait(lambda c: c.statuses() == ["connected"])
        for _ in range(50):  # an absolute value may be sent again: a cycle the dummy driver dropped
            box.send((0xB0, 5, 99))  # in an XRun of this loaded machine must not fail the test
            time.sleep(0.2)
            if got.controls():
                break
        assert [e.control for e in got.controls()] == ["fader6"]
    finally:
        dev.close()
        box.close()


def test_the_api_is_explicit_and_errors_are_one_line(jack_server: str) -> None:  # noqa: F811
    with pytest.raises(devices.DeviceError, match="ALSA"):  # no /dev/snd/seq here, and no fallback to JACK
        open_device("midi://nanoKONTROL2?api=alsa")
    with pytest.raises(devices.DeviceSpecError, match="api=alsa or api=jack"):
        open_device("midi://nanoKONTROL2?api=oss")
    with pytest.raises(devices.DeviceError, match="no MIDI input port matching 'nothing here'"):
        open_device("midi://nothing here?api=jack")
    with pytest.raises(devices.DeviceSpecError, match="unknown MIDI profile"):
        open_device("midi://nanoKONTROL2?api=jack&profile=nanokontrol9")
    with pytest.raises(devices.DeviceSpecError, match="outside 1..16"):
        open_device("midi://nanoKONTROL2?api=jack&channel=17")


def test_discovery_lists_jack_ports_with_their_profile(jack_server: str) -> None:  # noqa: F811
    box = MidiBox("nanoKONTROL2").plug()
    try:
        found = {i.spec: i for i in devices.discover()}
        spec = "midi://nanoKONTROL2?profile=nanokontrol2&api=jack"
        assert spec in found and found[spec].usable and "Korg nanoKONTROL2" in found[spec].description
    finally:
        box.close()


def _puppet_env() -> dict[str, str]:
    import os

    return {**os.environ, "PYTHONUNBUFFERED": "1"}


def test_puppet_devices_lists_midi_ports(jack_server: str) -> None:  # noqa: F811
    import subprocess
    import sys

    box = MidiBox("nanoKONTROL2").plug()
    synth = MidiBox("Some Synth").plug()
    try:
        out = subprocess.run([sys.executable, "-m", "puppet", "devices"], capture_output=True, text=True,
                             env=_puppet_env(), timeout=60)
    finally:
        box.close()
        synth.close()
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    nano = next(x for x in lines if x.startswith("midi://nanoKONTROL2?profile=nanokontrol2&api=jack"))
    assert "Korg nanoKONTROL2" in nano and "LED Mode = External" in nano
    other = next(x for x in lines if x.startswith("midi://Some Synth?profile=generic&api=jack"))
    assert "puppet learn" in other and "not usable" in other


def test_puppet_learn_binds_a_fader_and_a_button(jack_server: str, tmp_path) -> None:  # noqa: F811
    import subprocess
    import sys

    from midijack import wait_for_host

    from puppet.mapping import load_mapping

    box = MidiBox("nanoKONTROL2").plug()
    show = tmp_path / "show.toml"
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "learn", "--device", "midi://nanoKONTROL2?api=jack",
                             "--map", str(show), "--timeout", "20"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_puppet_env())
    try:
        wait_for_host(jack_server, "nanoKONTROL2:_MIDI 1")
        assert proc.stdin is not None
        proc.stdin.write("jaw\nexpr:happiness\ntoggle\nage\n\nq\n")
        proc.stdin.flush()
        box.send((0xB0, 1, 60), (0xB0, 1, 60), (0xB0, 1, 61), gap=0.05)  # a jittering pot: not a touch
        box.send(*[(0xB0, 6, v) for v in range(0, 40, 4)], gap=0.01)     # fader 7 moved
        time.sleep(1.0)  # learn lets the rest of the gesture pass
        box.send((0xB0, 32, 127), (0xB0, 32, 0))                           # S1 pressed
        time.sleep(1.0)
        box.send((0xB0, 80, 1), (0xB0, 80, 1), (0xB0, 80, 1), gap=0.02)     # an encoder it has no name for
        time.sleep(1.0)
        box.send((0xB0, 48, 127), (0xB0, 48, 0))                           # M1 pressed: answered with q
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        box.close()
    assert proc.returncode == 0, err
    assert "touched fader7 (axis)" in out and "touched s1 (button)" in out, out
    assert "touched ch1.cc80 (relative encoder)" in out, out
    spec = load_mapping(show)
    got = {(b.control, b.device, b.target, b.mode, b.input, b.encoding) for b in spec.bindings}
    assert got == {("fader7", "midi", "jaw", "momentary", None, None),
                   ("s1", "midi", "expr:happiness", "toggle", None, None),
                   ("ch1.cc80", "midi", "age", "momentary", "relative", "twos_complement")}


def _monitor_nanokontrol():  # type: ignore[no-untyped-def]
    """`puppet monitor midi://nanoKONTROL2?api=jack --json` started on the JACK server named by
    $JACK_DEFAULT_SERVER; returns the process, the JSON lines read so far and `until(pred)`, which
    reads lines until pred(lines) holds (30 s at most)."""
    import json
    import subprocess
    import sys

    mon = subprocess.Popen([sys.executable, "-m", "puppet", "monitor", "midi://nanoKONTROL2?api=jack", "--json",
                            "--duration", "60"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                           env=_puppet_env())
    lines: list[dict] = []

    def until(pred: object, timeout: float = 30.0) -> None:
        assert mon.stdout is not None
        deadline = time.monotonic() + timeout
        while not pred(lines):  # type: ignore[operator]
            assert time.monotonic() < deadline, lines
            line = mon.stdout.readline()
            assert line, f"monitor ended; got {lines}"
            lines.append(json.loads(line))

    return mon, lines, until


def _show_on_own_server(monkeypatch: pytest.MonkeyPatch, prefix: str):  # type: ignore[no-untyped-def]
    """A JACK server of this test's own (named prefix + pid, made the default), the nanoKONTROL2
    plugged into it and `puppet monitor` following it: (name, server, box, monitor, lines, until)."""
    import os

    from midijack import start_jackd

    name = f"{prefix}{os.getpid()}"
    monkeypatch.setenv("JACK_DEFAULT_SERVER", name)
    server = start_jackd(name)
    box = MidiBox("nanoKONTROL2").plug()
    return (name, server, box, *_monitor_nanokontrol())


def _server_back(name: str, box, lines: list, until):  # type: ignore[no-untyped-def]
    """The server started again under its name with the box plugged into it: the box's fader is
    followed, and the monitor said connected, lost, connected. Returns the new server."""
    from midijack import start_jackd, wait_for_host

    server = start_jackd(name)
    box.plug()
    wait_for_host(name, "nanoKONTROL2:_MIDI 1")
    box.send((0xB0, 3, 77))
    until(lambda ls: any(x.get("control") == "fader4" for x in ls))
    assert [x.get("status") for x in lines if "status" in x] == ["connected", "lost", "connected"]
    return server


def _end_show(mon, box) -> None:  # type: ignore[no-untyped-def]
    mon.kill()
    mon.wait(10)
    box.close()


def test_the_device_survives_a_jack_server_restart(jack_server: str, monkeypatch: pytest.MonkeyPatch) -> None:  # noqa: F811
    """The JACK server itself goes down and comes back under the same name: the device's clients
    belonged to the old server, so it makes new ones and finds the box again. (`puppet monitor` in
    its own process: one process does not talk to two JACK servers, and this one has the module's.)"""
    from midijack import stop_jackd

    name, server, box, mon, lines, until = _show_on_own_server(monkeypatch, "fprestart")

    try:
        until(lambda ls: any(x.get("status") == "connected" for x in ls))
        box.unplug()
        stop_jackd(server)
        until(lambda ls: ls[-1].get("status") == "lost")
        server = _server_back(name, box, lines, until)
    finally:
        _end_show(mon, box)
        stop_jackd(server)


def test_a_jack_server_stopped_under_a_plugged_box_is_a_loss_and_its_return_is_found(
        jack_server: str, monkeypatch: pytest.MonkeyPatch) -> None:  # noqa: F811
    """The JACK server stops (or crashes) while the box is still plugged in: a JACK client keeps its
    last copy of the server's ports, so the box's port stayed listed; the device said nothing, and
    after the server came back it never found the box (the box's messages were lost for the rest of
    the show). It is `lost` when the server goes and `connected` again with the box on the new one."""
    from midijack import stop_jackd

    name, server, box, mon, lines, until = _show_on_own_server(monkeypatch, "fpstop")

    try:
        until(lambda ls: any(x.get("status") == "connected" for x in ls))
        box.send((0xB0, 2, 50))
        until(lambda ls: any(x.get("control") == "fader3" for x in ls))
        stop_jackd(server)  # the box is still plugged in
        until(lambda ls: ls[-1].get("status") == "lost")
        box.unplug()
        server = _server_back(name, box, lines, until)
    finally:
        _end_show(mon, box)
        stop_jackd(server)


def test_a_jack_server_killed_and_never_restarted_is_a_loss(jack_server: str, monkeypatch: pytest.MonkeyPatch) -> None:  # noqa: F811
    """A JACK server killed (SIGKILL, a crash) leaves its socket file in /dev/shm: the device took
    the file for a live server and stayed `connected`, with nothing arriving, for the rest of the
    show. Now nobody listening on that socket is the server gone: `lost`, and it stays lost."""
    import glob
    import os

    from midijack import start_jackd, stop_jackd, wait_for_host

    name, server, box, mon, lines, until = _show_on_own_server(monkeypatch, "fpkill")
    try:
        wait_for_host(name, "nanoKONTROL2:_MIDI 1")
        until(lambda ls: any(x.get("status") == "connected" for x in ls))
        server.kill()  # SIGKILL: no clean-up of its files
        server.wait(5)
        assert glob.glob(f"/dev/shm/jack_{name}_*"), "the killed server's socket file is the case tested"
        until(lambda ls: ls[-1].get("status") == "lost", timeout=15.0)
        assert [x.get("status") for x in lines if "status" in x] == ["connected", "lost"]
    finally:
        _end_show(mon, box)
        if server.poll() is None:
            server.kill()
            server.wait(5)
        # a killed server keeps its slot in JACK's shared registry (8 slots, freed only by a server
        # of the same name): start one under the name and stop it cleanly, or after a few runs no
        # JACK server starts on this machine ("Too many servers already active")
        stop_jackd(start_jackd(name))
        for leftover in glob.glob(f"/dev/shm/jack_sem.*_{name}_*"):  # the killed server's clients'
            os.unlink(leftover)
