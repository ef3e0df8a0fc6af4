"""Done when a newcomer plugs in a nanoKONTROL2 and runs `puppet live`: the box is found on its
own, the faders move the face, the buttons fire expressions with their LEDs lit, unplugging and
replugging it mid-show costs nothing, and a second box plugged in mid-show is adopted. Run for real: `puppet live` in its own process, a
private JACK server, the box emulated in a third process."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from midijack import MidiBox, jack_server, wait_for_host  # noqa: F401  (the fixture)

from puppet.session import read_session

SPEC = "midi://nanoKONTROL2?profile=nanokontrol2&api=jack"


def wait_recorded(rec: Path, proc: subprocess.Popen, want: dict, timeout: float = 120) -> None:  # type: ignore[type-arg]
    """Until the show's recording (written tick by tick) holds a record with `want`'s fields; the
    show ending first fails, and `timeout` is only a hang guard."""
    deadline = time.monotonic() + timeout
    while True:
        for line in rec.read_text(errors="replace").splitlines() if rec.exists() else []:
            try:
                r = json.loads(line)
            except ValueError:  # the line being written
                continue
            if isinstance(r, dict) and all(r.get(k) == v for k, v in want.items()):
                return
        assert proc.poll() is None, f"the show ended before its recording held {want}"
        assert time.monotonic() < deadline, f"the recording never held {want}"
        time.sleep(0.05)


def test_nanokontrol2_live_show_with_unplug(tmp_path: Path, jack_server: str) -> None:  # noqa: F811
    box = MidiBox("nanoKONTROL2").plug()
    xtouch = MidiBox("X-TOUCH MINI", "X-TOUCH MINI MIDI 1")
    rec = tmp_path / "show.jsonl"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONUNBUFFERED"] = "1"
    env["PYTHONFAULTHANDLER"] = "1"  # on a failure below, SIGABRT makes it print where each thread was
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--headless", "--duration", "14",
                             "--record", str(rec)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=tmp_path)
    try:
        wait_for_host(jack_server, "nanoKONTROL2:_MIDI 1")
        box.send(*[(0xB0, 0, v) for v in range(0, 103, 6)], gap=0.01)  # fader 1 up to 0.8: smile
        box.send((0xB0, 32, 127), (0xB0, 32, 0))                           # S1: happiness
        box.wait_received(lambda r: (0xB0, 32, 127) in r, timeout=90)    # ... and its LED lit, once the show runs
        time.sleep(1.5)                                                    # the preset eases in
        box.unplug()                                                       # mid-show
        # the show looks for its port every 0.25 s: a box plugged back before one look would be a
        # port replaced unseen (the show connected to the old one), not the unplug this test is about;
        # so the box comes back once the recording says the show lost it, however long that takes
        wait_recorded(rec, proc, {"t": "st", "dev": SPEC, "status": "lost"})
        box.received.clear()
        box.plug()
        box.wait_received(lambda r: (0xB0, 32, 127) in r)                 # the LED comes back by itself
        box.send((0xB0, 6, 127), (0xB0, 33, 127), (0xB0, 33, 0))          # fader 7 far away; S2: sadness
        box.wait_received(lambda r: (0xB0, 33, 127) in r and (0xB0, 32, 0) in r)
        xtouch.plug()                                                      # a second box, mid-show
        wait_for_host(jack_server, "X-TOUCH MINI:X-TOUCH MINI MIDI 1")      # adopted with its own map
        xtouch.send((0x9A, 10, 127), (0x8A, 10, 0))                        # its button 3: surprise
        xtouch.wait_received(lambda r: (0x9A, 2, 1) in r)                  # lit on its LED note
    except BaseException:
        proc.send_signal(signal.SIGABRT)
        out, err = proc.communicate(timeout=30)
        print(f"puppet live said:\n{out}\n{err}")
        box.close()
        xtouch.close()
        raise
    out, err = proc.communicate(timeout=120)
    box.close()
    xtouch.close()
    assert proc.returncode == 0, err
    assert "LED Mode = External" in err  # the one thing the box needs from its user is said
    session = read_session(rec)
    assert session.complete and session.ticks == round(14 * session.tick_rate)  # the show ran its full length
    assert SPEC in session.header["devices"]
    statuses = [e["status"] for e in session.events if "status" in e and e.get("dev") == SPEC]
    assert statuses[:1] == ["connected"] and "lost" in statuses and statuses[-1] == "connected"
    names = session.channels
    values = session.value_array(np.zeros(len(names)), names)
    smile = values[:, names.index("zygomaticus_major_l")]
    lost_tick = next(e["tick"] for e in session.events if e.get("status") == "lost")
    s2_tick = next(e["tick"] for e in session.events if e.get("ctl") == "s2")
    assert smile[lost_tick] > 0.5                           # the fader (and the happy preset) moved the face
    assert abs(smile[s2_tick - 1] - smile[lost_tick]) < 0.01  # the unplug and replug moved nothing
    assert abs(smile[-1] - 102 / 127) < 0.01                # after the preset changed, the fader still holds
    jaw = values[:, names.index("jaw")]
    surprise_tick = next(e["tick"] for e in session.events if e.get("ctl") == "button3")
    assert np.all(jaw[:surprise_tick] == 0.0)  # fader 7 after the replug waits for pickup
    assert jaw[-1] > 0.1                       # the second box's preset opens the mouth
    ctls = [e["ctl"] for e in session.events if "ctl" in e]
    assert ctls.count("s1") == 2 and ctls.count("s2") == 2
    assert any(m[1] == "plugged in: midi://X-TOUCH MINI?profile=xtouch_mini&api=jack" for m in session.markers)
    assert ctls.count("button3") == 2
