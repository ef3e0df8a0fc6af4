"""`puppet view` end to end: a window under Xvfb that Esc closes, and the one-line offscreen
fallback when there is no display."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    return {**env, "PYTHONPATH": str(ROOT), **extra}


def test_view_without_display_writes_an_image_and_says_where(tmp_path: Path) -> None:
    out = tmp_path / "face.png"
    run = subprocess.run([sys.executable, "-m", "puppet", "view", "--expression", "happiness",
                          "--size", "160x120", "--seconds", "0.3", "--out", str(out)],
                         env=_env(), cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "display" in lines[0] and str(out) in lines[0]
    with Image.open(out) as im:
        img = np.asarray(im.convert("RGB")).astype(int)
    assert img.shape == (120, 160, 3)
    assert ((img[..., 0] - img[..., 2]) > 25).mean() > 0.1  # a face is in it


def test_view_without_display_keeps_an_earlier_picture_of_the_default_name(tmp_path: Path) -> None:
    """With no --out, the fallback picture of an earlier `puppet view` is kept: the new one goes
    beside it as puppet-view.1.png (it was replaced without a word)."""
    earlier = tmp_path / "puppet-view.png"
    earlier.write_bytes(b"an earlier picture the user kept")
    run = subprocess.run([sys.executable, "-m", "puppet", "view", "--face", "procedural", "--size", "160x120",
                          "--seconds", "0"], env=_env(), cwd=tmp_path, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert earlier.read_bytes() == b"an earlier picture the user kept"
    new = tmp_path / "puppet-view.1.png"
    assert str(new) in run.stderr
    with Image.open(new) as im:
        assert im.size == (160, 120)


def test_view_rejects_an_unknown_view(tmp_path: Path) -> None:
    run = subprocess.run([sys.executable, "-m", "puppet", "view", "--view", "xray"], env=_env(),
                         cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "wireframe" in run.stderr


def test_view_opens_a_window_that_escape_closes(xvfb_display: str, tmp_path: Path) -> None:
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "view", "--size", "320x240",
                             "--seconds", "0.2", "--view", "muscles"],
                            env=_env(DISPLAY=xvfb_display), cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        found = subprocess.run(["xdotool", "search", "--sync", "--onlyvisible", "--name", "facepuppet"],
                               env=_env(DISPLAY=xvfb_display), capture_output=True, text=True,
                               timeout=60)
        wid = found.stdout.split()[-1]
        time.sleep(0.5)
        assert proc.poll() is None  # the window stays up
        # the window closes on the key press, so xdotool may find it gone when it sends the
        # release (BadWindow): its exit status says nothing here, the process's does
        subprocess.run(["xdotool", "key", "--window", wid, "Escape"],
                       env=_env(DISPLAY=xvfb_display), capture_output=True)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert not (tmp_path / "puppet-view.png").exists()  # it did not fall back


def test_view_plays_a_preset_as_pose_does_on_the_scanned_head(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """`puppet view --expression surprise` drew the scanned head's surprise at the shared table's
    intensities (no raised upper lids, AU5; the jaw at 0.4), where `puppet pose` plays the head's
    own (sim.facs.FACE_EXPRESSIONS): the window showed another face than the pose's file."""
    from puppet import cmd_view
    from puppet.cli import main
    from sim import facs
    from sim.state import FaceControl

    seen = []
    real = cmd_view.pose
    monkeypatch.setattr(cmd_view, "pose", lambda model, control, seconds: (seen.append(control.values.copy()),
                                                                            real(model, control, seconds))[1])
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    out = tmp_path / "v.png"
    assert main(["view", "--face", "ict", "--expression", "surprise", "--seconds", "0", "--size", "64x48",
                 "--out", str(out)]) == 0
    want = FaceControl()
    facs.apply_expression(want, "surprise", 1.0, "ict")
    assert np.array_equal(seen[0], want.values)
    assert want.get("levator_palpebrae_l") > 0 and out.is_file()
