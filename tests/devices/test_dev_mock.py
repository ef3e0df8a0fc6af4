"""mock://: deterministic scripts, generators, impersonation, injected clock, and `puppet monitor`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from devices import ControlEvent, DeviceSpecError, EventQueue, StatusEvent, open_device
from devices.mock import MockDevice

SCRIPT = """
impersonate = "sgi"
speed = 0
[[events]]
t = 0.5
control = "button3"
value = 1
[[events]]
t = 0.25
control = "dial1"
delta = -7
[[ramp]]
control = "dial0"
start = 1.0
duration = 1.0
from = 0.0
to = 1.0
rate = 10
[[pattern]]
control = "button5"
start = 0.0
period = 1.0
duty = 0.5
count = 2
[[status]]
t = 3.0
status = "lost"
[[events]]
t = 3.5
control = "button4"
value = 1
"""


def _write(tmp_path: Path, text: str, name: str = "s.toml") -> str:
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_script_is_deterministic_and_impersonates_sgi(tmp_path: Path) -> None:
    spec = "mock://" + _write(tmp_path, SCRIPT)
    a, b = open_device(spec), open_device(spec)
    assert isinstance(a, MockDevice)
    assert a.play_all() == b.play_all()
    names = {c.name for c in a.controls}
    assert {"dial0", "dial7", "button0", "button31"} <= names and len(names) == 40
    events = a.play_all()
    assert [e.t for e in events] == sorted(e.t for e in events)
    ramp = [e for e in events if e.control == "dial0"]
    assert sum(e.delta or 0 for e in ramp) == 200  # one full turn at the default 200 counts/turn
    assert sum(e.value for e in ramp) == pytest.approx(1.0)
    assert all(-1 <= e.value <= 1 for e in ramp)
    assert [(e.value, e.t) for e in events if e.control == "button5"] == [(1, 0.0), (0, 0.5), (1, 1.0), (0, 1.5)]
    dial1 = next(e for e in events if e.control == "dial1")
    assert (dial1.kind, dial1.delta, dial1.value) == ("dial", -7, -7 / 200)


def test_threaded_playback_as_fast_as_possible_includes_scripted_unplug(tmp_path: Path) -> None:
    dev = open_device("mock://" + _write(tmp_path, SCRIPT))
    q = EventQueue()
    dev.add_listener(q)
    dev.start()
    got = []
    while not (dev.exhausted and len(q) == 0):
        e = q.get(timeout=5)
        assert e is not None
        got.append(e)
    dev.close()
    statuses = [e.status for e in got if isinstance(e, StatusEvent)]
    assert statuses == ["connected", "lost"]
    assert [e.t for e in got if isinstance(e, StatusEvent)] == [0.0, 3.0]  # script time, reproducible
    controls = [e for e in got if isinstance(e, ControlEvent)]
    assert controls == [e for e in dev.play_all() if e.t < 3.0]  # nothing after the unplug


def test_real_time_playback_with_an_injected_clock(tmp_path: Path) -> None:
    now = [100.0]
    sleeps: list[float] = []

    def sleep(s: float) -> None:
        sleeps.append(s)
        now[0] += s

    path = _write(tmp_path, '[[events]]\nt = 2.0\ncontrol = "x"\nvalue = 0.25\n')
    dev = open_device("mock://" + path + "?speed=2", clock=lambda: now[0], sleep=sleep)
    out = []
    while not out:
        out = list(dev._read(10.0))
    assert out[0].t == 101.0 and now[0] == pytest.approx(101.0)  # 2 s of script at speed 2
    assert out[0].kind == "axis" and out[0].value == 0.25


def test_inline_generators_and_bad_scripts(tmp_path: Path) -> None:
    dev = open_device("mock://?impersonate=sgi&sine=dial2&buttons=button1&duration=1&rate=20&speed=0")
    ev = dev.play_all()
    assert {e.control for e in ev} == {"dial2", "button1"}
    assert all(e.kind == "dial" for e in ev if e.control == "dial2")
    with pytest.raises(DeviceSpecError, match="speed"):
        open_device("mock://?sine=x&speed=fast")
    with pytest.raises(DeviceSpecError, match="samples"):
        open_device("mock://?sine=x&rate=1e9")
    with pytest.raises(DeviceSpecError, match="not on the impersonated box"):
        open_device("mock://?impersonate=sgi&sine=x")
    with pytest.raises(DeviceSpecError, match="outside"):
        open_device("mock://" + _write(tmp_path, '[[events]]\nt=0\ncontrol="x"\nvalue=3\n', "b.toml"))
    with pytest.raises(DeviceSpecError, match="not valid"):
        open_device("mock://" + _write(tmp_path, "[[events]\n", "c.toml"))
    js = _write(tmp_path, json.dumps({"speed": 0, "events": [{"t": 0, "control": "button0", "value": 1}]}), "d.json")
    assert [e.control for e in open_device("mock://" + js).play_all()] == ["button0"]


def test_a_misspelt_script_key_is_one_line_naming_it(tmp_path: Path) -> None:
    """A script's misspelt table (`[[rmp]]`, `[[press]]`) or entry key (`strat`) was ignored: the
    device opened and played nothing of it, silently. One line naming the script, the entry and the
    key, and what the script may hold; the inline form's generators keep working."""
    for text, words in (('impersonate = "sgi"\n[[rmp]]\ncontrol = "dial1"\n', ("'rmp'", "ramp")),
                        ('[[ramp]]\ncontrol = "dial1"\nstrat = 1.0\n', ("ramp[0]", "'strat'", "start")),
                        ('[[events]]\nt = 0\ncontrol = "button1"\nvalu = 1\n', ("events[0]", "'valu'", "value"))):
        path = _write(tmp_path, text, "typo.toml")
        with pytest.raises(DeviceSpecError) as err:
            open_device("mock://" + path)
        msg = str(err.value)
        assert path in msg and "\n" not in msg and all(w in msg for w in words), msg
    dev = open_device("mock://?impersonate=sgi&sine=dial0&ramp=dial2&buttons=button3&duration=1&rate=20&speed=0")
    assert {e.control for e in dev.play_all()} == {"dial0", "dial2", "button3"}


def test_puppet_monitor_json_lines(tmp_path: Path) -> None:
    path = _write(tmp_path, SCRIPT)
    out = subprocess.run([sys.executable, "-m", "puppet", "monitor", f"mock://{path}", "--json", "--duration", "20"],
                         capture_output=True, text=True, timeout=60, cwd=Path(__file__).parents[2])
    assert out.returncode == 0, out.stderr
    lines = [json.loads(line) for line in out.stdout.splitlines()]
    assert lines[0] == {"status": "connected", "device": f"mock://{path}", "t": lines[0]["t"]}
    assert {"status": "lost", "device": f"mock://{path}", "t": lines[-1]["t"]} in lines
    controls = [d for d in lines if "control" in d]
    dial = next(d for d in controls if d["kind"] == "dial")
    assert set(dial) == {"t", "device", "control", "kind", "value", "delta", "raw"}
    button = next(d for d in controls if d["control"] == "button3")
    assert set(button) == {"t", "device", "control", "kind", "value", "raw"} and button["value"] == 1
    assert len(controls) == len([e for e in open_device(f"mock://{path}").play_all() if e.t < 3.0])


def test_puppet_monitor_bad_spec_is_one_line() -> None:
    out = subprocess.run([sys.executable, "-m", "puppet", "monitor", "mock://missing.toml"],
                         capture_output=True, text=True, timeout=60, cwd=Path(__file__).parents[2])
    assert out.returncode == 2
    assert out.stderr.strip().startswith("puppet: error: mock://missing.toml") and len(out.stderr.splitlines()) == 1


@pytest.mark.parametrize("name", ["sgi_rehearsal.toml", "unplug.json"])
def test_example_scripts_load_and_stay_in_range(name: str) -> None:
    dev = open_device(f"mock://{Path(__file__).parents[2] / 'examples' / 'mock' / name}")
    events = dev.play_all()
    assert events
    for e in events:
        info = dev.control(e.control)
        assert info is not None and info.lo <= e.value <= info.hi


def test_impersonated_control_sets_match_the_real_backends(tmp_path: Path) -> None:
    from devices.controlsets import control_set

    for scheme in ("sgi", "firmata", "serial"):
        real = open_device(f"{scheme}://{tmp_path / 'absent'}", require=False)
        assert not real.connected and real.controls == control_set(scheme)
        real.close()
    assert open_device("keyboard://").controls == control_set("keyboard")
