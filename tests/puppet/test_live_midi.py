"""Done when a newcomer plugs in a nanoKONTROL2 and runs `puppet live`: the box is found on its
own, the faders move the face, the buttons fire expressions with their LEDs lit, and unplugging
and replugging it mid-show costs nothing. Run for real: `puppet live` in its own process, a
private JACK server, the box emulated in a third process."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from midijack import MidiBox, jack_server, wait_for_host  # noqa: F401  (the fixture)

from puppet.session import read_session

SPEC = "midi://nanoKONTROL2?profile=nanokontrol2&api=jack"


def test_nanokontrol2_live_show_with_unplug(tmp_path: Path, jack_server: str) -> None:  # noqa: F811
    box = MidiBox("nanoKONTROL2").plug()
    rec = tmp_path / "show.jsonl"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONUNBUFFERED"] = "1"
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--headless", "--duration", "10",
                             "--record", str(rec)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=tmp_path)
    try:
        wait_for_host(jack_server, "nanoKONTROL2:_MIDI 1")
        box.send(*[(0xB0, 0, v) for v in range(0, 103, 6)], gap=0.01)  # fader 1 up to 0.8: smile
        box.send((0xB0, 32, 127), (0xB0, 32, 0))                           # S1: happiness
        box.wait_received(lambda r: (0xB0, 32, 127) in r, timeout=90)    # ... and its LED lit, once the show runs
        time.sleep(1.5)                                                    # the preset eases in
        box.unplug()                                                       # mid-show
        time.sleep(0.6)
        box.received.clear()
        box.plug()
        box.wait_received(lambda r: (0xB0, 32, 127) in r)                 # the LED comes back by itself
        box.send((0xB0, 6, 127), (0xB0, 33, 127), (0xB0, 33, 0))          # fader 7 far away; S2: sadness
        box.wait_received(lambda r: (0xB0, 33, 127) in r and (0xB0, 32, 0) in r)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        box.close()
    assert proc.returncode == 0, err
    session = read_session(rec)
    assert session.complete and session.ticks == 600  # the show ran its full length
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
    assert np.all(jaw == 0.0)                         # fader 7 after the replug waits for pickup
    ctls = [e["ctl"] for e in session.events if "ctl" in e]
    assert ctls.count("s1") == 2 and ctls.count("s2") == 2
