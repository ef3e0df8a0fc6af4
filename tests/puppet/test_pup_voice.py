"""A voice offline and in exports: `puppet fit speech.wav` (the live analysis over a file, the same
take every time), replayed bit for bit, and exported to an MP4 whose AAC sound is in step with the
picture (a click lands within one frame)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from devices.audio.speech import synthesize
from devices.audio.wavfile import WavWriter

RATE = 48000
CLICK_S = 1.0
VOWEL_S = 1.3
FPS = 30


def puppet(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Silence, a 1 ms click at 1.0 s, an "aa" from 1.3 s."""
    from scipy.signal import resample_poly

    x = np.zeros(int(2.2 * RATE))
    i = int(CLICK_S * RATE)
    x[i:i + 48] = 0.9
    a, sr = synthesize("[[A:]]", speed=80)
    a = resample_poly(a, 320, 147)
    j = int(VOWEL_S * RATE)
    x[j:j + len(a)] += a
    path = tmp_path_factory.mktemp("clip") / "speech.wav"
    w = WavWriter(path, RATE)
    w.write(x)
    w.close()
    return path


def records(take: Path) -> list[dict]:
    return [json.loads(line) for line in take.read_text().splitlines()[1:]]


def test_fit_a_voice_is_deterministic_and_replays_exactly(clip: Path, tmp_path: Path) -> None:
    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    for out in (a, b):
        done = puppet("fit", str(clip), "--out", str(out))
        assert done.returncode == 0, done.stderr
    assert records(a) == records(b)
    recs = records(a)
    jaw = [r["value"] for r in recs if r["t"] == "ev" and r["ctl"] == "jaw"]
    assert max(jaw) > 0.5
    first = min(r["tick"] for r in recs if r["t"] == "ev")
    assert CLICK_S * 60 <= first <= CLICK_S * 60 + 3  # the click opens the gate at once
    done = puppet("replay", str(a), "--headless")
    assert done.returncode == 0 and "bit-identical" in done.stdout, done.stdout + done.stderr
    header = json.loads(a.read_text().splitlines()[0])
    assert header["audio"][0]["file"] == "speech.wav"


def test_a_bad_wav_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "speech.wav"
    bad.write_bytes(b"RIFF1234WAVEfmt ")
    done = puppet("fit", str(bad), "--out", str(tmp_path / "t.jsonl"))
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "speech.wav" in done.stderr
    assert not (tmp_path / "t.jsonl").exists()


def test_the_mp4_has_the_sound_in_step(clip: Path, tmp_path: Path) -> None:
    take, video = tmp_path / "take.jsonl", tmp_path / "take.mp4"
    assert puppet("fit", str(clip), "--out", str(take)).returncode == 0
    done = puppet("replay", str(take), "--out", str(video), "--fps", str(FPS), "--size", "160x96")
    assert done.returncode == 0, done.stderr
    probe = subprocess.run(["ffprobe", "-v", "error", "-show_entries", "stream=codec_type,codec_name",
                            "-of", "csv=p=0", str(video)], capture_output=True, text=True).stdout
    assert "aac,audio" in probe and "h264,video" in probe
    pcm = subprocess.run(["ffmpeg", "-v", "error", "-i", str(video), "-map", "0:a", "-f", "f32le", "-ac", "1",
                          "-ar", str(RATE), "-"], capture_output=True).stdout
    sound = np.frombuffer(pcm, np.float32)
    click = int(np.argmax(np.abs(sound) > 0.3)) / RATE
    assert abs(click - CLICK_S) < 1.0 / FPS
    raw = subprocess.run(["ffmpeg", "-v", "error", "-i", str(video), "-map", "0:v", "-f", "rawvideo",
                          "-pix_fmt", "gray", "-"], capture_output=True).stdout
    frames = np.frombuffer(raw, np.uint8).reshape(-1, 96, 160).astype(int)
    moved = [j for j in range(len(frames)) if np.abs(frames[j] - frames[0]).max() > 8]
    assert moved, "the face never moved"
    assert CLICK_S * FPS <= moved[0] <= VOWEL_S * FPS + 6  # the mouth moves with the sound, not before it


def test_a_damaged_sound_keeps_the_users_old_video(clip: Path, tmp_path: Path) -> None:
    """The take's WAV damaged (random bytes): the export wrote the silent video over the user's
    old MP4 and then failed naming the MP4. One line naming the WAV now, exit 2, the old MP4
    byte for byte."""
    take, video = tmp_path / "take.jsonl", tmp_path / "take.mp4"
    assert puppet("fit", str(clip), "--out", str(take)).returncode == 0
    (tmp_path / "speech.wav").write_bytes(np.random.default_rng(5).integers(0, 256, 3000, np.uint8).tobytes())
    video.write_bytes(b"the user's old video")
    done = puppet("replay", str(take), "--out", str(video), "--fps", str(FPS), "--size", "160x96", "--to", "0.3")
    errors = [ln for ln in done.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert done.returncode == 2 and len(errors) == 1 and "speech.wav" in errors[0], done.stderr
    assert video.read_bytes() == b"the user's old video"


def test_a_video_named_near_the_file_system_limit_gets_its_sound(clip: Path, tmp_path: Path) -> None:
    """An MP4 name of 245 bytes (a valid name): its sound's temporary file was named after the
    video's temporary name plus '.sound.mp4', past 255 bytes, so the export failed as 'File name
    too long'. The video is written with its sound and nothing is left beside it."""
    take = tmp_path / "take.jsonl"
    assert puppet("fit", str(clip), "--out", str(take)).returncode == 0
    video = tmp_path / ("é" * 120 + "s.mp4")
    assert len(video.name.encode()) == 245
    done = puppet("replay", str(take), "--out", str(video), "--fps", str(FPS), "--size", "96x64", "--to", "0.3")
    assert done.returncode == 0, done.stderr
    probe = subprocess.run(["ffprobe", "-v", "error", "-show_entries", "stream=codec_type", "-of", "csv=p=0",
                            str(video)], capture_output=True, text=True).stdout
    assert "audio" in probe and "video" in probe
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([take.name, video.name])
