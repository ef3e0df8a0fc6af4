"""The take's sound in its video: the WAV beside a take muxed into the exported MP4 as AAC.

Frame j of an export shows take time `start + j * speed / fps` and plays at `j / fps`, so the
sound is cut at `start`, played `speed` times as fast (ffmpeg's atempo, 0.5..100) and ends with
the last frame; AAC's encoder delay is signalled in the file (ffmpeg writes the edit list), so
players start the sound on the first frame. The muxed file replaces the video in one rename."""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

from puppet.errors import PuppetError


def _atempo(speed: float) -> list[str]:
    """atempo takes 0.5..100 per stage; chain stages for slower speeds."""
    stages = []
    while speed < 0.5:
        stages.append("atempo=0.5")
        speed /= 0.5
    stages.append(f"atempo={speed:.9g}")
    return stages


def mux_sound(video: Path, wav: Path, start: float, speed: float, duration: float, shown: Path | None = None) -> None:
    """Add `wav` (from take time `start`, at `speed`) to `video` as its AAC track, in place;
    `shown` is the name errors give (the export's target, where `video` is its temporary file)."""
    shown = video if shown is None else shown
    import imageio_ffmpeg

    # a short name of its own: one made from the video's (already near the file system's 255-byte
    # limit when the user's name is) failed as 'File name too long'
    fd, made = tempfile.mkstemp(prefix=".sound.", suffix=".mp4", dir=video.parent)
    os.close(fd)
    tmp = Path(made)
    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-i", str(video),
           "-ss", f"{start:.6f}", "-i", str(wav), "-map", "0:v:0", "-map", "1:a:0", "-c:v", "copy",
           "-c:a", "aac", "-b:a", "160k"]
    if speed != 1.0:
        cmd += ["-filter:a", ",".join(_atempo(speed))]
    cmd += ["-t", f"{duration:.6f}", "-movflags", "+faststart", str(tmp)]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
    except (OSError, subprocess.TimeoutExpired) as err:
        tmp.unlink(missing_ok=True)
        raise PuppetError(f"{shown}: the sound {wav} could not be added ({err}); {shown} is left as it was") from err
    if done.returncode != 0:
        try:
            tmp.unlink()
        except OSError:
            pass
        last = (done.stderr.strip().splitlines() or ["ffmpeg failed"])[-1]
        raise PuppetError(f"{shown}: the sound {wav} could not be added ({last[:200]}); {shown} is left as it was")
    os.replace(tmp, video)
