"""The window under Xvfb, driven by xdotool: the keyboard fallback moves a muscle in a recorded
live session; the replay window opens, takes transport keys and quits."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from puppet.session import read_session


def _xdo(display: str, *args: str) -> str:
    out = subprocess.run(["xdotool", *args], capture_output=True, text=True, env={**os.environ, "DISPLAY": display},
                         timeout=20)
    return out.stdout.strip()


def _wait_window(display: str, title: str, proc: subprocess.Popen, timeout: float = 60) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(f"puppet exited early: {proc.communicate()[1]}")
        wid = _xdo(display, "search", "--name", title).split("\n")[0]
        if wid:
            return wid
        time.sleep(0.1)
    pytest.fail(f"no window named {title!r} appeared")


@pytest.fixture(autouse=True)
def _need_xdotool() -> None:
    if shutil.which("xdotool") is None:
        pytest.fail("xdotool is not installed: run `bash .ci/setup`")


def test_keyboard_fallback_drives_a_muscle_in_the_window(xvfb_display: str, tmp_path: Path) -> None:
    rec = tmp_path / "kb.jsonl"
    env = {**os.environ, "DISPLAY": xvfb_display}
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--record", str(rec), "--duration", "30"],
                            env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wid = _wait_window(xvfb_display, "facepuppet live", proc)
        _xdo(xvfb_display, "windowfocus", "--sync", wid)
        time.sleep(0.5)
        _xdo(xvfb_display, "keydown", "a")   # A = smile in the keyboard map
        time.sleep(1.5)
        _xdo(xvfb_display, "keyup", "a")
        _xdo(xvfb_display, "key", "m")       # marker
        time.sleep(0.5)
        _xdo(xvfb_display, "key", "F10")     # quit
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    s = read_session(rec)
    assert s.complete and s.markers and s.markers[0][1] == "M marker"
    assert [e["ctl"] for e in s.events if e.get("t") == "ev"][:2] == ["key:A", "key:A"]
    j = s.channels.index("zygomaticus_major_l")
    smile = s.value_array(np.zeros(len(s.channels)))[:, j]
    assert smile.max() > 0.5 and smile[-1] < smile.max()  # rose while held, relaxed after
    assert "input-to-frame latency" in out
    replay = subprocess.run([sys.executable, "-m", "puppet", "replay", str(rec), "--headless"],
                            capture_output=True, text=True, timeout=120)
    assert "bit-identical" in replay.stdout, replay.stderr


def test_replay_window_transport_keys_and_quit(xvfb_display: str, tmp_path: Path) -> None:
    curves = tmp_path / "c.curves"
    curves.write_text("facepuppet-curves 1\ncurve jaw smooth\n 0 0\n 1 0.8\n 2 0\nend\n")
    env = {**os.environ, "DISPLAY": xvfb_display}
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "replay", "--curves", str(curves)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wid = _wait_window(xvfb_display, "facepuppet replay", proc)
        _xdo(xvfb_display, "windowfocus", "--sync", wid)
        for key in ("space", "Right", "Up", "Down", "Home", "space", "n"):
            _xdo(xvfb_display, "key", key)
            time.sleep(0.1)
        assert proc.poll() is None  # transport keys do not end the replay
        _xdo(xvfb_display, "key", "Escape")
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0
