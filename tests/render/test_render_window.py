"""A real glfw window under Xvfb: it opens, draws what the offscreen renderer draws, answers keys,
and closes. The window runs in a child process so its GL context and glfw never meet the test
session's EGL context."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from render_faces import Faces

from render.offscreen import OffscreenRenderer

PROBE = Path(__file__).with_name("window_probe.py")
ROOT = Path(__file__).resolve().parents[2]


def test_window_renders_like_offscreen_and_answers_keys(xvfb_display: str, gl, faces: Faces,
                                                        tmp_path: Path) -> None:
    env = {**os.environ, "DISPLAY": xvfb_display, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, str(PROBE), str(tmp_path)], env=env, cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    events = json.loads((tmp_path / "events.json").read_text())
    shot = np.load(tmp_path / "screenshot.npy")
    assert tuple(events["size"]) == (320, 240) and shot.shape == (240, 320, 3)
    # read back between drawing and showing (the performer's pages get this): the frame drawn
    assert np.abs(np.load(tmp_path / "after_draw.npy").astype(int) - shot.astype(int)).mean() < 1.0

    with OffscreenRenderer(faces.model, (320, 240), ctx=gl, antialias=events["antialias"]) as off:
        ref = off.render_frame(faces.rest).astype(int)
    diff = np.abs(shot.astype(int) - ref)
    assert diff.mean() < 1.0
    assert np.percentile(diff.max(axis=-1), 99) < 24
    assert np.abs(shot.astype(int) - ref[::-1]).mean() > 5  # not trivially equal (e.g. flipped)

    assert ["2", "press"] in events["keys"] and ["2", "release"] in events["keys"]
    assert events["views"] == ["wireframe", "muscles", "trails", "trails"]
    assert events["frames"] > 3
    assert events["reset"]


def test_window_without_display_raises_no_display(monkeypatch: pytest.MonkeyPatch, faces: Faces) -> None:
    from render.window import FaceWindow, NoDisplayError

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(NoDisplayError, match="DISPLAY"):
        FaceWindow(faces.model)


PIPELINE_PROBE = Path(__file__).with_name("window_pipeline_probe.py")


def test_pipelined_window_shows_the_serial_frames(xvfb_display: str, tmp_path: Path) -> None:
    """Pipelined (each step makes its frame's CPU half while the frame before still rasterises,
    then shows that one): every state drawn reaches the window with the serial frame's pixels."""
    env = {**os.environ, "DISPLAY": xvfb_display, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, str(PIPELINE_PROBE), str(tmp_path)], env=env, cwd=ROOT,
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr[-2000:]
    serial, piped = np.load(tmp_path / "serial.npz"), np.load(tmp_path / "pipelined.npz")
    shown = json.loads((tmp_path / "shown.json").read_text())
    assert sorted(serial.files) == sorted(piped.files) and len(serial.files) >= 9
    n = len(serial.files)
    assert shown == {"serial": [n - 1], "pipelined": [n - 1]}  # the last state is the one left on screen
    for k in serial.files:
        assert np.array_equal(serial[k], piped[k]), k
    assert np.abs(serial["f0"].astype(int) - serial[f"f{n - 1}"].astype(int)).mean() > 0.1  # the face moved
