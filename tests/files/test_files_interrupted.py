"""An export stopped by Ctrl-C (SIGINT) or by `kill` / a service manager (SIGTERM) while it writes:
it ends, the file it was replacing stays as it was, and nothing of it is left (no hidden temporary
file, no encoder process), whatever state its encoder is in."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import formats

ROOT = Path(__file__).resolve().parents[2]
OLD = formats.OLD

# an encoder that has stopped taking frames (a hung ffmpeg, a stalled disk under it): it says it
# runs (its pid in a file) and never reads its input
STALLED_FFMPEG = """#!/bin/sh
echo $$ > "$STALLED_MARK"
exec sleep 600
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_an_export_stopped_while_its_encoder_stalls_ends_and_leaves_nothing(tmp_path: Path, sig: int,
                                                                            code: int) -> None:
    """SIGTERM killed the export at once: its hidden `.take.*.part.mp4` stayed beside the video.
    SIGINT waited for the encoder to take in the frames it had not read: forever, when it had
    stopped reading. Both end now (SIGTERM as 143), the old video kept, nothing left behind."""
    formats.good_recording(tmp_path)
    (tmp_path / "take.mp4").write_bytes(OLD)
    fake = tmp_path / "ffmpeg"
    fake.write_text(STALLED_FFMPEG)
    fake.chmod(0o755)
    mark = tmp_path / "encoder.pid"
    env = dict(os.environ, PYTHONPATH=str(ROOT), IMAGEIO_FFMPEG_EXE=str(fake), STALLED_MARK=str(mark))
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "replay", "good.jsonl", "--size", "320x240", "--out",
                             "take.mp4"], cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        while not (mark.exists() and mark.read_text().strip()):  # the export is writing
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        encoder = int(mark.read_text())
        assert any(".part" in p.name for p in tmp_path.iterdir())
        proc.send_signal(sig)
        try:
            out, err = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            pytest.fail("the export did not end")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if mark.exists() and mark.read_text().strip() and _alive(int(mark.read_text())):
            os.kill(int(mark.read_text()), signal.SIGKILL)
    assert proc.returncode == code and "Traceback" not in err, err[-2000:]
    assert (tmp_path / "take.mp4").read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir() if ".part" in p.name) == []
    for _ in range(100):  # the encoder is reaped by its parent's exit at the latest
        if not _alive(encoder):
            break
        time.sleep(0.05)
    assert not _alive(encoder)
