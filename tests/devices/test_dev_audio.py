"""The voice analysis alone (devices.audio.analysis), on espeak-ng speech and made-up signals: what
it says about a mouth, that block sizes do not change it, that the gate keeps noise out, and that
nothing a sound card or a file can deliver breaks it. Also profiles and the WAV writer."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from devices.audio.analysis import CONTROLS, VoiceAnalyzer, frames_mfcc
from devices.audio.profile import VoiceProfile, build_profile, load_profile, parse_profile
from devices.audio.recorder import AudioRecorder
from devices.audio.speech import synthesize
from devices.audio.wavfile import WavWriter, read_wav
from safefile import BadFile

RATE = 22050


@pytest.fixture(scope="module")
def vowels() -> dict[str, np.ndarray]:
    return {k: synthesize(t, speed=80, voice="en-us+f2")[0]
            for k, t in (("A", "[[A:]]"), ("I", "[[i:]]"), ("U", "[[u:]]"), ("M", "[[mmmm]]"))}


def peaks(x: np.ndarray, rate: int = RATE) -> dict[str, float]:
    frames = VoiceAnalyzer(rate).feed(np.concatenate([x, np.zeros(rate)]), 0.0)
    arr = np.array([f.values for f in frames])
    return dict(zip(CONTROLS, arr.max(axis=0), strict=True))


def test_each_sound_makes_its_own_mouth(vowels: dict[str, np.ndarray]) -> None:
    """A voice the default profile never heard (espeak-ng's en-us+f2)."""
    a, i, u, m = (peaks(vowels[k]) for k in "AIUM")
    assert a["jaw"] > 0.5 and a["jaw"] > i["jaw"] + 0.2 and a["jaw"] > u["jaw"] + 0.2
    assert i["spread"] > 0.7 and i["spread"] > max(a["spread"], u["spread"]) + 0.4
    assert u["round"] > 0.7 and u["round"] > max(a["round"], i["round"]) + 0.4
    assert m["closed"] > 0.7 and m["jaw"] < 0.2


def test_block_size_does_not_change_a_single_bit(vowels: dict[str, np.ndarray]) -> None:
    x = np.concatenate([vowels["A"], vowels["U"]])
    whole = VoiceAnalyzer(RATE).feed(x, 1.5)
    an = VoiceAnalyzer(RATE)
    pieces, pos, sizes = [], 0, [1, 7, 64, 221, 1024, 3]
    k = 0
    while pos < len(x):
        n = sizes[k % len(sizes)]
        pieces += an.feed(x[pos:pos + n], 1.5 + pos / RATE)
        pos += n
        k += 1
    assert [f.values for f in pieces] == [f.values for f in whole]
    assert [f.t for f in pieces] == pytest.approx([f.t for f in whole], abs=1e-9)


def test_silence_and_noise_below_the_gate_move_nothing() -> None:
    rng = np.random.default_rng(3)
    an = VoiceAnalyzer(48000)
    quiet = rng.standard_normal(48000 * 2) * 10 ** (-60 / 20)  # -60 dBFS: 15 dB under the gate
    frames = an.feed(np.zeros(4800), 0.0) + an.feed(quiet, 0.1)
    assert frames and all(f.values == (0.0,) * len(CONTROLS) and not f.gate for f in frames)


def test_loud_noise_opens_the_gate_and_the_mouth_comes_back_to_rest() -> None:
    rng = np.random.default_rng(4)
    an = VoiceAnalyzer(48000)
    frames = an.feed(rng.standard_normal(24000) * 0.1, 0.0) + an.feed(np.zeros(48000), 0.5)
    assert max(f.values[0] for f in frames) > 0.5
    assert frames[-1].values == (0.0,) * len(CONTROLS)  # exactly at rest, so nothing more is sent


def test_the_level_follows_loudness_and_stays_in_range() -> None:
    t = np.arange(48000) / 48000
    levels = []
    for db in (-40, -30, -20):
        an = VoiceAnalyzer(48000)
        tone = np.sin(2 * np.pi * 220 * t) * np.sqrt(2) * 10 ** (db / 20)
        levels.append(an.feed(tone, 0.0)[-1].values[0])
    assert 0.0 < levels[0] < levels[1] < levels[2] <= 1.0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), max_size=3000),
       st.integers(min_value=8000, max_value=96000))
def test_any_samples_give_values_in_range(samples: list[float], rate: int) -> None:
    an = VoiceAnalyzer(rate)
    for f in an.feed(np.array(samples, dtype=np.float64), 0.0):
        assert all(0.0 <= v <= 1.0 for v in f.values)


def test_a_learnt_profile_round_trips_and_classifies_its_own_voice(tmp_path, vowels) -> None:
    frames = {k: frames_mfcc(x, RATE)[0][10:-10] for k, x in vowels.items()}
    prof = build_profile(frames, base=VoiceProfile.default())
    path = tmp_path / "me.json"
    prof.save(path)
    back = load_profile(path)
    assert back.templates == prof.templates and set(back.templates) >= {"A", "I", "U", "M", "E", "O", "F"}
    an = VoiceAnalyzer(RATE, back)
    for k, f in frames.items():
        got = [an.classify(v) for v in f]
        assert got.count(k) / len(got) > 0.9, (k, got)


@pytest.mark.parametrize("text, words", [
    ("not json", "not valid JSON"),
    ('{"format": "x"}', "not a voice profile"),
    ('{"format": "facepuppet-voice-profile", "version": 1, "templates": {"Q": []}, "scale": []}', "unknown template"),
    ('{"format": "facepuppet-voice-profile", "version": 1, "templates": {"A": [1]}, "scale": []}', "templates.A"),
])
def test_a_bad_profile_is_one_line_naming_the_file(text: str, words: str) -> None:
    with pytest.raises(BadFile, match=words) as err:
        parse_profile(text, "me.json")
    assert "me.json" in str(err.value) and "\n" not in str(err.value)


def test_the_shipped_profile_is_valid() -> None:
    prof = VoiceProfile.default()
    assert set(prof.templates) == {"A", "I", "U", "E", "O", "M", "F"}
    assert json.loads(prof.to_json())["format"] == "facepuppet-voice-profile"


def test_wav_writer_is_readable_and_moved_into_place(tmp_path) -> None:
    x = np.sin(np.arange(4800) / 10) * 0.5
    w = WavWriter(tmp_path / "a.wav", 48000)
    w.write(x)
    assert not (tmp_path / "a.wav").exists() and (tmp_path / "a.wav.partial").exists()
    assert w.close() == tmp_path / "a.wav" and not (tmp_path / "a.wav.partial").exists()
    y, rate = read_wav(tmp_path / "a.wav")
    assert rate == 48000 and np.max(np.abs(y - x)) < 1 / 32768
    (tmp_path / "b.wav").write_bytes(b"RIFF\x00\x00\x00\x00WAVEjunk")
    with pytest.raises(BadFile, match="b.wav"):
        read_wav(tmp_path / "b.wav")


def test_recorder_places_blocks_on_the_callers_clock(tmp_path) -> None:
    rate = 8000
    rec = AudioRecorder(tmp_path / "r.wav", rate)
    block = np.ones(800)  # 0.1 s
    rec.push(block * 0.1, 9.9)  # before position 0 (it ends there): dropped
    rec.clock(0.0, 10.0)  # position 0 is at monotonic 10.0
    rec.push(block * 0.2, 10.0)
    rec.push(block * 0.3, 10.1)
    rec.push(block * 0.4, 10.5)  # a gap (an unplugged input): silence keeps the timeline
    rec.close(until=0.7)  # the take ended at 0.7 s: the file is exactly that long
    y, _ = read_wav(tmp_path / "r.wav")
    assert len(y) == 5600
    assert np.allclose(y[:800], 0.2, atol=1e-3) and np.allclose(y[800:1600], 0.3, atol=1e-3)
    assert np.all(y[1600:4000] == 0) and np.allclose(y[4000:4800], 0.4, atol=1e-3) and np.all(y[4800:] == 0)
    cut = AudioRecorder(tmp_path / "c.wav", rate)
    cut.clock(0.0, 10.0)
    cut.push(block, 10.0)
    cut.close(until=0.05)
    assert len(read_wav(tmp_path / "c.wav")[0]) == 400


def test_recorder_follows_a_schedule_that_drops_wall_time_at_once(tmp_path) -> None:
    """A show that fell behind drops wall time: its clock's origin moves on by what it dropped.
    Sound captured right after is placed on the new clock at once (the sound of the dropped time
    is what is cut), not a fraction of a second late until per-tick pairs catch up."""
    rate = 8000
    rec = AudioRecorder(tmp_path / "r.wav", rate)
    rec.anchor(10.0)
    for k in range(10):  # 0.0-1.0 s of sound
        rec.push(np.full(800, 0.1), 10.0 + 0.1 * k)
    for k in range(30):  # ticks that had run on time, then the drop
        rec.clock(0.95 + k / 240, 10.95 + k / 240)
    rec.anchor(10.3)  # 0.3 s dropped: position 1.0 is now at monotonic 11.3
    rec.push(np.full(800, 0.5), 11.3)
    rec.close(until=1.1)
    y, _ = read_wav(tmp_path / "r.wav")
    assert len(y) == 8800
    assert np.allclose(y[:8000], 0.1, atol=1e-3) and np.allclose(y[8000:], 0.5, atol=1e-3)


def test_wav_writer_records_beside_a_take_named_near_the_file_system_limit(tmp_path) -> None:
    """A take of 254 bytes (`NAME.jsonl`) records its sound to `NAME.wav` (252 bytes): the writer's
    `NAME.wav.partial` was 260 bytes and the show's sound could not be opened ('File name too long').
    The WAV is written and moved into place, nothing left beside it."""
    target = tmp_path / ("ä" * 123 + "xx.wav")
    assert len(target.name.encode()) == 254 - len(".jsonl") + len(".wav")
    x = np.sin(np.arange(4800) / 10) * 0.5
    w = WavWriter(target, 48000)
    w.write(x)
    assert w.close() == target
    y, rate = read_wav(target)
    assert rate == 48000 and np.max(np.abs(y - x)) < 1 / 32768
    assert [p.name for p in tmp_path.iterdir()] == [target.name]
