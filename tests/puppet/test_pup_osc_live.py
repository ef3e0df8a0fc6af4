"""End to end through the live loop, headless, as a user runs it: `puppet live` with a TouchOSC
listener and a Live Link Face listener on 127.0.0.1; OSC messages and tracking frames sent over
real UDP move the face's channel values, which the recording shows."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pythonosc.osc_message_builder import OscMessageBuilder

from devices.facestream.livelink import encode_frame
from puppet.session import read_session

ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def listening_ports(proc: subprocess.Popen, specs: list[str]) -> list[int]:  # type: ignore[type-arg]
    """The ports the show's UDP devices, given port 0, bound: each says so on stderr once it
    listens ("SPEC: listening for ... on UDP port N of HOST"). A port picked here, closed and handed
    to the show could be taken by another program in between; and the line is the moment the
    port listens."""
    assert proc.stderr is not None
    ports: dict[str, int] = {}
    said = []
    while len(ports) < len(specs):
        line = proc.stderr.readline()
        assert line, f"the show ended before its devices listened: {''.join(said)}"
        said.append(line)
        for spec in specs:
            if line.startswith(f"{spec}: listening for ") and " on UDP port " in line:
                ports[spec] = int(line.split(" on UDP port ")[1].split()[0])
    return [ports[spec] for spec in specs]


def osc(address: str, value: float) -> bytes:
    b = OscMessageBuilder(address)
    b.add_arg(value)
    return b.build().dgram


def latest_values(rec: Path) -> dict[str, float]:
    """Channel values as far as the recording has been written (changes-only records)."""
    if not rec.exists():
        return {}
    channels: list[str] = []
    cur: dict[str, float] = {}
    for line in rec.read_text().splitlines():
        try:
            r = json.loads(line)
        except ValueError:
            continue  # the line being written
        if r.get("t") == "header":
            channels = r["channels"]
        elif r.get("t") == "v":
            cur.update(r["v"])
    return cur if channels else {}


#: the phone's mouthSmileLeft 0.6 drives the zygomaticus to 0.6 of the smile's span (0.55: the scanned smile)
WANT = {"jaw": 0.7, "zygomaticus_major_l": 0.6 * 0.55, "age": 80.0, "eyes_yaw": 0.3, "zygomaticus_minor_l": 0.25}


def reached(v: dict[str, float]) -> bool:
    return all(abs(v.get(k, -1.0) - want) < 1e-3 for k, want in WANT.items())


def test_touchosc_and_live_link_face_drive_the_live_face(tmp_path: Path) -> None:
    """...while another sender floods the OSC port with garbage and a stream of values."""
    osc_spec, ll_spec = "osc://127.0.0.1:0?profile=touchosc", "livelink://127.0.0.1:0"
    rec = tmp_path / "phone.jsonl"
    proc = subprocess.Popen(
        [sys.executable, "-m", "puppet", "live", "--device", osc_spec, "--device", ll_spec, "--headless",
         "--record", str(rec)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        osc_port, ll_port = listening_ports(proc, [osc_spec, ll_spec])
    except BaseException:
        proc.kill()
        proc.wait(10)
        raise
    weights = {"mouthSmileLeft": 0.6, "eyeLookOutLeft": 0.3, "eyeLookInRight": 0.3}
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stop = threading.Event()

    def flood() -> None:  # garbage and a stream of another control, as fast as Python sends
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        junk, other = b"\x00garbage" * 8, osc("/face/channel/zygomaticus_minor_l", 0.25)
        while not stop.is_set():
            for d in (junk, other, junk):
                try:
                    s.sendto(d, ("127.0.0.1", osc_port))
                except OSError:
                    pass
        s.close()

    blaster = threading.Thread(target=flood)
    blaster.start()
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:  # until reached (a hang guard)
            sock.sendto(osc("/1/fader4", 0.7), ("127.0.0.1", osc_port))  # TouchOSC's jaw fader
            sock.sendto(osc("/face/channel/age", 80.0), ("127.0.0.1", osc_port))  # a generic address
            sock.sendto(encode_frame(weights), ("127.0.0.1", ll_port))  # the phone's face tracking
            if reached(latest_values(rec)) and '"t":"chk"' in rec.read_text(errors="replace"):
                break  # the values reached, and a checkpoint for the replay below to verify
            time.sleep(0.1)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        stop.set()
        blaster.join()
        sock.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 0, err
    assert "performed" in out
    s = read_session(rec)
    assert s.complete and osc_spec in s.header["devices"]
    final: dict[str, float] = {}
    for k in sorted(s.values):
        final.update({s.channels[i]: v for i, v in s.values[k].items()})
    for name, want in WANT.items():
        assert final[name] == pytest.approx(want, abs=1e-3), name
    ctls = {e.get("ctl") for e in s.events}
    assert {"/1/fader4", "/face/channel/age", "mouthSmileLeft"} <= ctls  # the raw events are recorded too
    replay = subprocess.run([sys.executable, "-m", "puppet", "replay", str(rec), "--headless"],
                            capture_output=True, text=True, env=ENV, timeout=120)
    assert replay.returncode == 0, replay.stderr
    assert "bit-identical" in replay.stdout  # OSC and tracking events replay like any box's
