"""The built-in demo: `puppet live` with neither a box nor a display, and `puppet live --demo`,
perform the bundled script through mock:// -> SGI map -> simulator, record it (the recording replays
bit for bit), and leave an MP4 with frames and the last frame as a PNG."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from puppet.demo import SCRIPT
from puppet.session import read_session

ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}
NO_DISPLAY = {k: v for k, v in ENV.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}


def puppet(*args: str, env: dict, cwd: Path, timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True, env=env,
                          cwd=cwd, timeout=timeout)


def _mp4_frames(path: Path) -> int:
    import imageio_ffmpeg

    return imageio_ffmpeg.count_frames_and_secs(str(path))[0]


def test_demo_script_covers_the_advertised_moves() -> None:
    import devices

    dev = devices.open_device(f"mock://{SCRIPT}")
    try:
        pressed = {it.control for it in dev.script.items if it.value == 1.0}
        assert {f"button{i}" for i in range(7)} <= pressed  # the seven expression presets
        assert {"button7", "button15", "button10", "button11", "button12", "button13"} <= pressed
        assert any(it.control == "dial0" for it in dev.script.items)  # age
        assert 15 <= dev.script.duration <= 25 and dev.script.speed == 0
    finally:
        dev.close()


def test_no_box_no_display_performs_the_demo_into_files(tmp_path: Path) -> None:
    out = puppet("live", "--duration", "2", env=NO_DISPLAY, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    first = out.stderr.strip().splitlines()[0]
    assert "no control box and no display" in first and "demo" in first
    recs = list(tmp_path.glob("puppet-demo-*.jsonl"))
    assert len(recs) == 1
    rec = recs[0]
    s = read_session(rec)
    assert s.complete and s.ticks == 120
    assert rec.with_suffix(".png").exists() and rec.with_suffix(".mp4").exists()
    assert _mp4_frames(rec.with_suffix(".mp4")) == 60
    assert str(rec.with_suffix(".mp4").name) in out.stdout and f"puppet replay {rec.name}" in out.stdout
    # the face moved: the first preset (happiness) is rising by 2 s
    j = s.channels.index("zygomaticus_major_l")
    assert s.value_array(np.zeros(len(s.channels)))[:, j].max() > 0.5
    replay = puppet("replay", str(rec), "--headless", env=NO_DISPLAY, cwd=tmp_path)
    assert replay.returncode == 0, replay.stderr
    assert "bit-identical to the live session at 2 checkpoints" in replay.stdout


def test_demo_flag_headless_with_record_path(tmp_path: Path) -> None:
    rec = tmp_path / "sub" / "show.jsonl"
    rec.parent.mkdir()
    out = puppet("live", "--demo", "--headless", "--duration", "1", "--record", str(rec), env=ENV, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert read_session(rec).ticks == 60
    assert _mp4_frames(rec.with_suffix(".mp4")) == 30 and rec.with_suffix(".png").exists()


def test_demo_refuses_a_device(tmp_path: Path) -> None:
    out = puppet("live", "--demo", "--device", "mock://", "--headless", env=ENV, cwd=tmp_path)
    assert out.returncode == 2 and "--demo" in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_demo_in_a_window_plays_and_records(xvfb_display: str, tmp_path: Path) -> None:
    rec = tmp_path / "w.jsonl"
    out = puppet("live", "--demo", "--duration", "1.5", "--record", str(rec),
                 env={**ENV, "DISPLAY": xvfb_display}, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    s = read_session(rec)
    assert s.tick_rate == 60.0  # a window runs the ticks due right before each frame: 60 Hz
    assert s.complete and s.ticks == 90 and any(e.get("ctl") == "button0" for e in s.events)
    assert not rec.with_suffix(".mp4").exists() and "puppet replay" in out.stdout


@pytest.mark.parametrize("flag", ["--demo"])
def test_help_mentions_demo(flag: str, tmp_path: Path) -> None:
    out = puppet("live", "--help", env=ENV, cwd=tmp_path)
    assert flag in out.stdout


def test_a_missing_map_is_said_before_the_demo_starts(tmp_path: Path) -> None:
    """With no box and no display, a --map that is not there is one line and exit 2, before the
    demo's announcement (and nothing is recorded)."""
    r = puppet("live", "--headless", "--map", str(tmp_path / "mine.toml"), env={**NO_DISPLAY, "PUPPET_LIBRARY": "off"},
               cwd=tmp_path, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [f"puppet: error: {tmp_path / 'mine.toml'}: no such map file "
                                             "(`puppet learn --map FILE` makes one)"]
    assert not list(tmp_path.iterdir())


def test_a_reader_who_leaves_does_not_stop_the_show(tmp_path: Path) -> None:
    """`puppet live 2>&1 | head -1`: the pipe breaks at the show's first lines; the show goes on,
    its take ends complete and the demo's MP4 and PNG are written (it was killed mid-way, exit 141)."""
    env = {**NO_DISPLAY, "PUPPET_LIBRARY": "off"}
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--headless", "--duration", "3",
                             "--record", "t.jsonl"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            env=env, cwd=tmp_path)
    assert proc.stdout is not None
    proc.stdout.readline()
    proc.stdout.close()  # the reader leaves
    assert proc.wait(timeout=180) == 0
    assert read_session(tmp_path / "t.jsonl").complete
    assert (tmp_path / "t.mp4").stat().st_size > 0 and (tmp_path / "t.png").stat().st_size > 0
