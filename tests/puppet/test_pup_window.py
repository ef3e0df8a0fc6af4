"""The window under Xvfb, driven by xdotool: the keyboard fallback moves a muscle in a recorded
live session (frames serial or pipelined); the replay window opens, takes transport keys and quits."""

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


def _wait_window(display: str, title: str, proc: subprocess.Popen, timeout: float = 240) -> str:
    """The window's id once it is mapped; `timeout` is a hang guard (the run's first show builds the
    face's caches first: over a minute on a loaded machine)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(f"puppet exited early: {proc.communicate()[1]}")
        wid = _xdo(display, "search", "--name", title).split("\n")[0]
        if wid:
            return wid
        time.sleep(0.1)
    pytest.fail(f"no window named {title!r} appeared")


def _smile(s, j: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    return s.value_array(np.zeros(len(s.channels)))[:, j]


def _recorded(rec: Path, proc: subprocess.Popen, what: str, pred, timeout: float = 240):  # type: ignore[no-untyped-def]
    """The recording read as the show writes it (up to its last whole record), once `pred` holds;
    the test fails if the show ends first or (a hang guard) nothing comes for `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        if proc.poll() is not None:
            pytest.fail(f"puppet exited before {what}: {proc.communicate()[1][-2000:]}")
        if rec.exists():
            try:
                s = read_session(rec)
            except Exception:  # noqa: BLE001 - the header itself not written yet
                s = None
            if s is not None and s.ticks > 0 and pred(s):
                return s
        if time.monotonic() > deadline:
            pytest.fail(f"the recording never showed {what}")
        time.sleep(0.05)


@pytest.fixture(autouse=True)
def _need_xdotool() -> None:
    if shutil.which("xdotool") is None:
        pytest.fail("xdotool is not installed: run `bash .ci/setup`")


@pytest.mark.parametrize("mode", [[], ["--pipelined"]], ids=["serial", "pipelined"])
def test_keyboard_fallback_drives_a_muscle_in_the_window(xvfb_display: str, tmp_path: Path, mode: list[str]) -> None:
    rec = tmp_path / "kb.jsonl"
    env = {**os.environ, "DISPLAY": xvfb_display}
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--record", str(rec), "--duration", "120", *mode],
                            env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wid = _wait_window(xvfb_display, "facepuppet live", proc)
        _xdo(xvfb_display, "windowfocus", "--sync", wid)
        # the window opens while the show is still being prepared: keys pressed before its loop
        # polls them arrive together, press and release in one tick; so each step waits for the
        # recording (written tick by tick) to show the one before, never for a stretch of time
        s = _recorded(rec, proc, "the show's first tick", lambda s: s.ticks > 0)
        j = s.channels.index("zygomaticus_major_l")
        _xdo(xvfb_display, "keydown", "a")   # A = smile in the keyboard map
        _recorded(rec, proc, "the smile rising while A is held", lambda s: _smile(s, j).max() > 0.5)
        _xdo(xvfb_display, "keyup", "a")
        _xdo(xvfb_display, "key", "m")       # marker
        # released, the smile relaxes; and a checkpoint, which the replay below verifies
        _recorded(rec, proc, "the marker, the smile relaxing and a checkpoint",
                  lambda s: bool(s.markers) and _smile(s, j)[-1] < _smile(s, j).max()
                  and '"chk"' in rec.read_text(errors="replace"))
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


KEY_HELP_PROBE = r"""
import json, sys
from render.window import FaceWindow, HELP_LINES
from puppet import live
from sim.face import default_model

model = default_model(0)
out = {}
win = live._window_or_none(model, "probe live", live.LIVE_HELP)
out["live_builtin"] = win.builtin_keys
win.renderer.view = "wireframe"
live._common_key(win, "f1")                      # F1: the window's help, showing our keys
out["live_f1"] = win._hud_for_frame().lines
win._on_key(None, 49, 0, 1, 0)                    # "1" pressed: the window's own keys stay off
win._on_key(None, 256, 0, 1, 0)                   # Esc pressed: no quit (it is the panic key)
out["live_view_after_key"] = win.renderer.view
out["live_closing"] = win.should_close
win._on_char(None, ord("?"))                      # ? toggles the same help
out["live_q_off"] = win.show_help
win.close()
view = FaceWindow(model, title="probe view")      # `puppet view`: the window's own keys
view._on_char(None, ord("?"))
out["view_help"] = view._hud_for_frame().lines
view._builtin("2")
out["view_after_2"] = view.renderer.view
view.close()
json.dump(out, sys.stdout)
"""


def test_window_help_lists_the_keys_that_are_active(xvfb_display: str) -> None:
    import json

    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "DISPLAY": xvfb_display, "PYTHONPATH": str(root)}
    run = subprocess.run([sys.executable, "-c", KEY_HELP_PROBE], env=env, cwd=root, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    out = json.loads(run.stdout)
    live_help = "\n".join(out["live_f1"])
    assert out["live_builtin"] is False
    assert "F10: quit" in live_help and "ESC: ease back to neutral" in live_help and "F5: reset the view" in live_help
    assert "Esc: quit" not in live_help and "1-5" not in live_help and "R / Home" not in live_help
    assert out["live_view_after_key"] == "wireframe" and out["live_closing"] is False
    assert out["live_q_off"] is False
    view_help = "\n".join(out["view_help"])
    assert "1-5" in view_help and "Esc: quit" in view_help and "F10" not in view_help
    assert out["view_after_2"] == "wireframe"
