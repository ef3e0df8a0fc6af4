"""audio:// end to end through a real JACK port: a private JACK server, speech synthesised by
espeak-ng and played by another process into its own port (the microphone), unplugged by ending
that process; and `puppet live` recording a take and its sound while the voice speaks."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from audiojack import Analysed, Voice, speech_wav, wait_connected
from midijack import jack_server  # noqa: F401  (the fixture)

import devices
from devices import ControlEvent, StatusEvent, open_device

#: Vowels at known places, each followed by silence; then noise below the gate.
PARTS = [("[[A:]]", 0.8), ("[[i:]]", 0.8), ("[[u:]]", 0.8), ("[[mmmm]]", 0.8)]
NOISE_DB = -62.0


@pytest.fixture(scope="module")
def speech(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple[float, float]]]:
    path = tmp_path_factory.mktemp("voice") / "speech.wav"
    return path, speech_wav(path, PARTS, noise_db=NOISE_DB)


def segments(events: list[tuple[float, str, float]]) -> list[dict[str, float]]:
    """Spans where `level` is above 0, each with the largest value of every control in it."""
    out: list[dict[str, float]] = []
    cur: dict[str, float] | None = None
    for _, ctl, v in events:
        if ctl == "level" and v > 0 and cur is None:
            cur = {}
            out.append(cur)
        if cur is not None:
            cur[ctl] = max(cur.get(ctl, 0.0), v)
        if ctl == "level" and v == 0.0:
            cur = None
    return out


def check_mouth(segs: list[dict[str, float]]) -> None:
    """aa opens the jaw, ee spreads the lips, oo rounds them, m closes them."""
    assert len(segs) == 4, segs
    aa, ee, oo, mm = segs
    assert aa["jaw"] > 0.5 and aa["jaw"] > max(aa.get("round", 0), aa.get("closed", 0)), aa
    assert ee.get("spread", 0) > 0.7 and ee.get("spread", 0) > ee.get("round", 0) + 0.4, ee
    assert oo.get("round", 0) > 0.7 and oo.get("round", 0) > oo.get("spread", 0) + 0.4, oo
    assert mm.get("closed", 0) > 0.7 and mm.get("jaw", 0) < 0.25, mm
    for s in segs:
        assert s["level"] > 0.3


def test_vowels_move_the_mouth_and_silence_and_noise_do_not(jack_server: str, speech) -> None:  # noqa: F811
    path, _ = speech
    voice = Voice().plug()
    dev = open_device("audio://VOI?api=jack")  # a substring of the client's name, any case
    got: list[object] = []
    dev.add_listener(got.append)
    analysed = Analysed(dev)
    dev.start()
    try:
        wait_connected(jack_server, "voice:out_1")
        voice.play(path)
        voice.wait_done()
        analysed.wait_past(time.monotonic())
        controls = [(e.t, e.control, e.value) for e in got if isinstance(e, ControlEvent)]
        check_mouth(segments(controls))
        # the mouth came back to rest after the last sound, and the noise below the gate moved nothing
        last = {c: v for _, c, v in controls}
        assert all(v == 0.0 for v in last.values()), last
        rest_from = max(t for t, c, v in controls if c == "level" and v == 0.0)
        assert not [x for x in controls if x[0] > rest_from]
        # unplug mid-show: lost; plug back: connected, and the voice moves the mouth again
        voice.unplug()
        deadline = time.monotonic() + 10
        while not [e for e in got if isinstance(e, StatusEvent) and e.status == "lost"]:
            assert time.monotonic() < deadline, got[-5:]
            time.sleep(0.02)
        n = len(got)
        voice.plug()
        wait_connected(jack_server, "voice:out_1")
        voice.play(path)
        voice.wait_done()
        analysed.wait_past(time.monotonic())
        again = [e for e in got[n:]]
        assert [e.status for e in again if isinstance(e, StatusEvent)] == ["connected"]
        check_mouth(segments([(e.t, e.control, e.value) for e in again if isinstance(e, ControlEvent)]))
    finally:
        dev.close()
        voice.close()


def test_errors_are_one_line(jack_server: str, tmp_path: Path) -> None:  # noqa: F811
    with pytest.raises(devices.DeviceError, match="no audio input matching 'nobody'"):
        open_device("audio://nobody?api=jack")
    with pytest.raises(devices.DeviceSpecError, match="api=alsa, api=jack or api=pulse"):
        open_device("audio://voice?api=oss")
    with pytest.raises(devices.DeviceSpecError, match="gate"):
        open_device("audio://voice?api=jack&gate=loud")
    bad = tmp_path / "me.json"
    bad.write_text('{"format": "something else"}')
    with pytest.raises(devices.DeviceSpecError, match="not a voice profile"):
        open_device(f"audio://voice?api=jack&profile={bad}")
    out = subprocess.run([sys.executable, "-m", "puppet", "live", "--device", "audio://nobody?api=jack",
                          "--headless", "--duration", "1"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "no audio input matching 'nobody'" in out.stderr


def test_puppet_devices_lists_the_voice(jack_server: str) -> None:  # noqa: F811
    voice = Voice("Studio Mic").plug()
    try:
        out = subprocess.run([sys.executable, "-m", "puppet", "devices"], capture_output=True, text=True, timeout=60)
    finally:
        voice.close()
    assert out.returncode == 0, out.stderr
    line = next(x for x in out.stdout.splitlines() if x.startswith("audio://Studio Mic?api=jack"))
    assert "audio input" in line and "JACK" in line


@pytest.mark.timeout(900)  # a hang guard: two shows and the speech, on a machine that may run 10x slower
def test_puppet_live_records_the_take_and_its_sound(jack_server: str, speech, tmp_path: Path) -> None:  # noqa: F811
    from devices.audio.wavfile import read_wav
    from puppet.session import read_session

    path, _ = speech
    take = tmp_path / "take.jsonl"
    voice = Voice().plug()
    show = [sys.executable, "-m", "puppet", "live", "--device", "audio://voice?api=jack", "--headless", "--no-panel",
            "--record", str(take)]
    live = subprocess.Popen([*show, "--duration", "9"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_connected(jack_server, "voice:out_1")
        # a hang guard: the first show of a test run builds the face's caches (a minute or more on a busy machine)
        deadline = time.monotonic() + 300
        while not (take.exists() and '"tick"' in take.read_text()):  # the show has begun
            assert time.monotonic() < deadline and live.poll() is None, live.stderr.read() if live.stderr else ""
            time.sleep(0.05)
        voice.play(path)
        out, err = live.communicate(timeout=300)
        assert live.returncode == 0, err
        first = (tmp_path / "take.wav").read_bytes()
        # a second show recording to the same take: the first take is kept aside with its own sound
        # (its sound was kept aside apart from it, and the kept take then played the new show's)
        again = subprocess.run([*show, "--duration", "1"], capture_output=True, text=True, timeout=300)
        assert again.returncode == 0, again.stderr
    finally:
        if live.poll() is None:
            live.kill()
            live.wait(10)
        voice.close()
    from puppet.audio_take import take_audio

    kept = take_audio(read_session(tmp_path / "take.1.jsonl"))
    assert kept == tmp_path / "take.1.wav" and kept.read_bytes() == first
    assert take_audio(read_session(take)) == tmp_path / "take.wav"
    assert (tmp_path / "take.wav").read_bytes() != first
    shutil.copy(tmp_path / "take.1.jsonl", take)  # the first take where it was, for the checks below
    shutil.copy(tmp_path / "take.1.wav", tmp_path / "take.wav")
    session = read_session(take)
    spec = "audio://voice?api=jack"
    evs = [(e["time"], e["ctl"], e["value"]) for e in session.events if e.get("dev") == spec and "ctl" in e]
    check_mouth(segments(evs))
    # the channels the default map drives: each sound's own channel is the one that moved most
    ticks = {e["ctl"]: [] for e in session.events if "ctl" in e}
    for e in session.events:
        if "ctl" in e:
            ticks[e["ctl"]].append(e["tick"])
    values = session.value_array(np.zeros(len(session.channels)))
    idx = {n: i for i, n in enumerate(session.channels)}
    spans, start = [], None
    for e in session.events:
        if e.get("ctl") == "level":
            if e["value"] > 0 and start is None:
                start = e["tick"]
            elif e["value"] == 0 and start is not None:
                spans.append((start, e["tick"]))
                start = None
    peak = [values[a:b + 1].max(axis=0) for a, b in spans]
    aa, ee, oo, mm = peak
    assert aa[idx["jaw"]] > 0.2 and aa[idx["jaw"]] > mm[idx["jaw"]] + 0.15
    assert ee[idx["risorius_l"]] > 0.45 and ee[idx["risorius_l"]] > oo[idx["risorius_l"]] + 0.3
    assert oo[idx["orbicularis_oris"]] > 0.5 and oo[idx["orbicularis_oris"]] > ee[idx["orbicularis_oris"]] + 0.3
    assert mm[idx["mentalis"]] > 0.3
    assert values[-1][idx["jaw"]] == 0.0 and values[-1][idx["orbicularis_oris"]] == 0.0  # at rest again
    # the sound beside the take: what was played, on the take's clock
    assert session.header["audio"][0]["file"] == "take.wav"
    rec, rate = read_wav(tmp_path / "take.wav")
    played, prate = read_wav(path)
    assert rate == prate == 48000
    assert len(rec) == round(session.ticks / session.tick_rate * rate)  # as long as the take
    heard = _parts_heard(rec, played, speech[1], rate)
    for (onset, _), (first, _) in zip(heard, spans):
        # each sound lies in the WAV where the take has it: the tick its voice's first event came in
        # follows its start in the WAV by the analysis' window and the event's way to the loop
        # (10-30 ms on a quiet machine; at a load of 8-15 on 2 cores, 150 ms after and once 150 ms
        # before it: a wrong clock puts sounds seconds away)
        assert -0.2 <= first / session.tick_rate - onset <= 0.5, (onset, first / session.tick_rate)
    assert np.mean([share for _, share in heard]) > 0.6, heard


def _parts_heard(rec: np.ndarray, played: np.ndarray, parts: list[tuple[float, float]], rate: int,
                 block: int = 256) -> list[tuple[float, float]]:
    """Each played sound (`parts`: start, end in seconds of the played file) found in the recording:
    (where it begins there, seconds; the share of its sounding 256-sample blocks found sample for
    sample (16-bit) within 0.5 s of that place; another recording finds ~0 %). A block is looked
    for from 2.5 s before its place in the played file to 0.5 s after it: when the show's loop
    drops wall time (a machine too busy for a while), the take's clock skips it and the WAV, kept on
    that clock, drops it too, so what follows lies earlier. Not every block survives a loaded
    machine either: the dummy JACK driver, without real-time priority, drops cycles (an XRun loses
    that period for the player or for us)."""
    from scipy.signal import correlate

    c = np.concatenate([[0.0], np.cumsum(rec * rec)])
    out = []
    for a, b in parts:
        lags = []
        for start in range(int(a * rate), int(b * rate) - block, block):
            piece = played[start:start + block]
            if np.max(np.abs(piece)) < 0.01:
                continue
            lo, hi = max(0, start - int(2.5 * rate)), min(len(rec), start + block + rate // 2)
            if hi - lo < block:
                lags.append(None)
                continue
            energy = c[lo + block:hi + 1] - c[lo:hi + 1 - block]  # least squared difference, by FFT
            ssd = energy - 2 * correlate(rec[lo:hi], piece, mode="valid", method="fft") + np.dot(piece, piece)
            k = int(np.argmin(ssd))
            lags.append(lo + k - start if ssd[k] < block * (1.0 / 32768) ** 2 else None)
        found = [x for x in lags if x is not None]
        lag = float(np.median(found)) if found else 0.0
        near = sum(abs(x - lag) <= rate // 2 for x in found)
        out.append((a + lag / rate, near / max(1, len(lags))))
    return out


def test_puppet_learn_records_a_voice_profile_the_device_then_uses(jack_server: str, tmp_path: Path) -> None:  # noqa: F811
    import re

    from devices.audio.profile import load_profile

    sounds = {"A": "[[A:]]", "I": "[[i:]]", "U": "[[u:]]", "E": "[[E]]", "O": "[[o:]]", "M": "[[mmmm]]"}
    wavs = {}
    for name, text in sounds.items():
        wavs[name] = tmp_path / f"{name}.wav"
        speech_wav(wavs[name], [(text, 0.1)], voice="en-us+f4")
    profile = tmp_path / "me.json"
    voice = Voice().plug()
    learn = subprocess.Popen([sys.executable, "-m", "puppet", "learn", "--device", "audio://voice?api=jack",
                              "--profile", str(profile)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, bufsize=1)
    asked = []
    try:
        assert learn.stdout is not None and learn.stdin is not None
        for line in learn.stdout:
            m = re.match(r"([AIUEOM]): .*press Enter", line)
            if m:
                asked.append(m.group(1))
                learn.stdin.write("\n")
                learn.stdin.flush()
            m = re.match(r"([AIUEOM]): listening", line)
            if m:  # the sound once learn records (0.3 s after Enter was too soon on a busy machine)
                voice.play(wavs[m.group(1)])
        learn.wait(60)
    finally:
        if learn.poll() is None:
            learn.kill()
            learn.wait(10)
    assert learn.returncode == 0, learn.stderr.read() if learn.stderr else ""
    assert asked == ["A", "I", "U", "E", "O", "M"]
    prof = load_profile(profile)
    assert set(prof.templates) >= set(sounds) and prof.gate_db is not None
    # the learnt voice speaks again, through the device with its profile: the mouth follows
    seq = tmp_path / "seq.wav"
    speech_wav(seq, PARTS, voice="en-us+f4")
    dev = open_device(f"audio://voice?api=jack&profile={profile}")
    got: list[object] = []
    dev.add_listener(got.append)
    analysed = Analysed(dev)
    dev.start()
    try:
        wait_connected(jack_server, "voice:out_1")
        voice.play(seq)
        voice.wait_done()
        analysed.wait_past(time.monotonic())
    finally:
        dev.close()
        voice.close()
    check_mouth(segments([(e.t, e.control, e.value) for e in got if isinstance(e, ControlEvent)]))


def test_replay_plays_the_takes_sound_where_there_is_an_output(jack_server: str, speech) -> None:  # noqa: F811
    """The window replay's player (puppet.sound_out) on PortAudio's JACK output, heard by a JACK
    client of the test: the sound plays while the replay plays, and is silent while paused."""
    import jack

    from puppet.sound_out import TakeSound

    path, spans = speech
    player = TakeSound(path)
    assert player.available
    ear = jack.Client("ear", no_start_server=True)
    port = ear.inports.register("in")
    heard: list[np.ndarray] = []
    ear.set_process_callback(lambda n: heard.append(port.get_array().copy()))
    ear.activate()
    try:
        ear.connect(next(p.name for p in ear.get_ports("PortAudio", is_output=True)), port)
        for _ in range(30):  # paused at the first vowel
            player.sync(spans[0][0] + 0.1, 1.0, False)
            time.sleep(1 / 60)
        paused = np.concatenate(heard) if heard else np.zeros(1)
        heard.clear()
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.0:  # playing from the first vowel on
            player.sync(spans[0][0] + time.monotonic() - t0, 1.0, True)
            time.sleep(1 / 60)
    finally:
        player.close()
        ear.deactivate()
        ear.close()
    played = np.concatenate(heard)
    assert np.max(np.abs(paused)) == 0.0
    assert np.sqrt(np.mean(played ** 2)) > 0.02


def test_the_device_survives_a_jack_server_restart(jack_server: str, speech, monkeypatch: pytest.MonkeyPatch) -> None:  # noqa: F811
    """The JACK server goes down and comes back under the same name: `puppet monitor` (its own
    process) reports lost, then connected, and the voice moves the mouth again."""
    import json
    import os

    from midijack import start_jackd, stop_jackd

    path, _ = speech
    name = f"fpaudio{os.getpid()}"
    monkeypatch.setenv("JACK_DEFAULT_SERVER", name)
    server = start_jackd(name)
    voice = Voice().plug()
    mon = subprocess.Popen([sys.executable, "-m", "puppet", "monitor", "audio://voice?api=jack", "--json",
                            "--duration", "60"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    lines: list[dict] = []

    def until(pred: object, timeout: float = 30.0) -> None:
        assert mon.stdout is not None
        deadline = time.monotonic() + timeout
        while not pred(lines):  # type: ignore[operator]
            assert time.monotonic() < deadline, lines[-5:]
            line = mon.stdout.readline()
            assert line, f"monitor ended; got {lines[-5:]}"
            lines.append(json.loads(line))

    try:
        until(lambda ls: any(x.get("status") == "connected" for x in ls))
        voice.unplug()
        stop_jackd(server)
        until(lambda ls: ls[-1].get("status") == "lost")
        server = start_jackd(name)
        voice.plug()
        wait_connected(name, "voice:out_1")
        voice.play(path)
        until(lambda ls: any(x.get("control") == "jaw" and x["value"] > 0.3 for x in ls))
        assert [x.get("status") for x in lines if "status" in x] == ["connected", "lost", "connected"]
    finally:
        mon.kill()
        mon.wait(10)
        voice.close()
        stop_jackd(server)
