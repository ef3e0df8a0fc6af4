"""A voice driving the face: how late, how costly, how right.

1. Sound -> event: a player in its own process (tests/voice_player.py) plays a short vowel into a
   port of a private dummy JACK server (started and stopped here); audio://player?api=jack hears
   it. The sound's time is that of its first loud sample (|x| > 0.05) as a capture card would
   have it: the JACK cycle that hands the block over began at T, so sample i of an n-sample block
   was captured at T - (n - i) / rate (the audio block is included). The event's time is when the
   device hands its first event after the onset (the gate opening) to a listener.
2. Sound -> frame at 60 Hz: the same events drive the live loop (`run_realtime`, the voice map,
   the simulator and an offscreen render of every frame); the time is when the frame of the tick
   that applied that event was rendered.
3. CPU: the device's reader thread's CPU time (polling the ring, the analysis, the events) over
   the run, as a share of one core; and the analysis alone over 30 s of speech.
4. Vowel accuracy on espeak-ng voices the shipped profile never heard (en-us+m2, +f2, +f4, three
   pitches): the share of steady frames classified as their vowel, and of whole vowels (majority).

Run:  nice .venv/bin/python benchmarks/audio_latency.py [--trials N] [--period FRAMES]
"""

from __future__ import annotations

import argparse
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from devices import ControlEvent, EventQueue, open_device  # noqa: E402
from devices.audio.analysis import VoiceAnalyzer  # noqa: E402
from devices.audio.speech import PHONEMES, synthesize  # noqa: E402
from devices.audio.wavfile import WavWriter  # noqa: E402

PLAYER = ROOT / "tests" / "voice_player.py"
RATE = 48000


def pct(xs: list[float], p: float) -> float:
    return float(np.percentile(np.asarray(xs), p))


def start_jackd(name: str, period: int) -> subprocess.Popen[bytes]:
    proc = subprocess.Popen(["jackd", "-n", name, "--no-realtime", "-d", "dummy", "-r", str(RATE), "-p", str(period)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    env = {**os.environ, "JACK_NO_START_SERVER": "1"}
    deadline = time.monotonic() + 15
    while subprocess.run(["jack_lsp", "-s", name], env=env, capture_output=True).returncode != 0:
        if proc.poll() is not None or time.monotonic() > deadline:
            raise SystemExit("jackd did not start")
        time.sleep(0.05)
    return proc


def trial_wav(path: Path) -> float:
    """A 0.15 s cut of an "aa" (then silence); returns the onset's offset in seconds."""
    from scipy.signal import resample_poly

    x, r = synthesize("[[A:]]", speed=80)
    x = resample_poly(x, 320, 147)
    onset = int(np.argmax(np.abs(x) > 0.05))
    x = x[onset:onset + int(0.15 * RATE)]
    ramp = np.linspace(1.0, 0.0, 480)
    x[-480:] *= ramp
    w = WavWriter(path, RATE)
    w.write(x)
    w.close()
    return 0.0


def thread_cpu(tid: int) -> float:
    """CPU seconds (user + system) of one thread of this process."""
    fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def live_run(trials: int, gap: float, period: int) -> dict[str, object]:
    from puppet.live import LiveCore, load_face, run_realtime
    from puppet.mapping import Mapper
    from puppet.mapping.defaults import load_default_map, merge
    from render.offscreen import OffscreenRenderer

    name = f"fpbench{os.getpid()}"
    os.environ["JACK_DEFAULT_SERVER"] = name
    os.environ["JACK_NO_START_SERVER"] = "1"
    server = start_jackd(name, period)
    tmp = Path(tempfile.mkdtemp())
    wav = tmp / "aa.wav"
    trial_wav(wav)
    player = subprocess.Popen([sys.executable, str(PLAYER), "player"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True, bufsize=1, cwd=ROOT,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(x.strip()) for x in player.stdout], daemon=True).start()  # type: ignore[union-attr]
    assert lines.get(timeout=30) == "ready"
    dev = open_device("audio://player?api=jack")
    face = load_face()
    spec = merge([(load_default_map("voice"), dev.spec)])
    mapper = Mapper(spec, face.vocab)
    mapper.declare_controls(dev.spec, dev.controls)
    core = LiveCore(face, mapper)
    q = EventQueue()
    emitted: list[tuple[float, ControlEvent]] = []
    dev.add_listener(lambda e: emitted.append((time.monotonic(), e)) if isinstance(e, ControlEvent) else None)
    dev.add_listener(q)
    applied: list[tuple[int, list[ControlEvent]]] = []
    rendered: dict[int, float] = {}

    def drain() -> list:
        evs = q.drain()
        applied.append((core.tick_count, [e for e in evs if isinstance(e, ControlEvent)]))
        return evs

    rend = OffscreenRenderer(face.model, (640, 360))

    def on_frame(c: LiveCore) -> None:
        rend.render_frame(c.state)
        rendered[c.tick_count - 1] = time.monotonic()

    starts: list[float] = []

    def play_all() -> None:
        time.sleep(1.0)
        for _ in range(trials):
            player.stdin.write(f"play {wav}\n")  # type: ignore[union-attr]
            player.stdin.flush()  # type: ignore[union-attr]
            while True:
                line = lines.get(timeout=30)
                if line.startswith("start "):
                    _, _frame, mono, off, n = line.split()
                    starts.append(float(mono) - (int(n) - int(off)) / RATE)
                    break
            time.sleep(gap)

    dev.start()
    tid_wait = time.monotonic() + 5
    while dev._thread is None or dev._thread.native_id is None:
        assert time.monotonic() < tid_wait
        time.sleep(0.01)
    tid = dev._thread.native_id
    cpu0, wall0 = thread_cpu(tid), time.monotonic()
    feeder = threading.Thread(target=play_all, daemon=True)
    feeder.start()
    run_realtime(core, drain, 1.5 + trials * (gap + 0.2), on_frame=on_frame)
    cpu = thread_cpu(tid) - cpu0
    wall = time.monotonic() - wall0
    dev.close()
    rend.close() if hasattr(rend, "close") else None
    player.stdin.write("quit\n")  # type: ignore[union-attr]
    player.stdin.flush()  # type: ignore[union-attr]
    player.wait(10)
    server.terminate()
    server.wait(10)
    to_event, to_frame = [], []
    tick_of = {id(e): k for k, evs in applied for e in evs}
    for s in starts:
        after = [(t, e) for t, e in emitted if t > s and e.control == "level" and e.value > 0]
        if not after:
            continue
        t, e = after[0]
        to_event.append(t - s)
        k = tick_of.get(id(e))
        if k is not None and k in rendered:
            to_frame.append(rendered[k] - s)
    return {"trials": len(starts), "event": to_event, "frame": to_frame, "cpu": cpu / wall, "period": period}


def analysis_cost() -> float:
    """CPU seconds per second of sound for VoiceAnalyzer alone (48 kHz speech, 10 ms hops)."""
    x, r = synthesize("The quick brown fox jumps over the lazy dog, and the puppet says hello to you all.")
    from scipy.signal import resample_poly

    x = np.tile(resample_poly(x, 320, 147), 6)
    an = VoiceAnalyzer(RATE)
    t0 = time.process_time()
    for i in range(0, len(x), 256):
        an.feed(x[i:i + 256], i / RATE)
    return (time.process_time() - t0) / (len(x) / RATE)


def accuracy() -> tuple[float, float, int]:
    from devices.audio.profiles.make_default import HELD_OUT_VOICES, steady_frames

    an = VoiceAnalyzer(22050)
    ok = total = v_ok = v_total = 0
    for voice in HELD_OUT_VOICES:
        for pitch in (35, 50, 65):
            for name, texts in PHONEMES.items():
                for text in texts:
                    x, r = synthesize(text, voice=voice, speed=80, pitch=pitch)
                    got = [an.classify(f) for f in steady_frames(x, r)]
                    ok += got.count(name)
                    total += len(got)
                    v_total += 1
                    v_ok += bool(got) and max(set(got), key=got.count) == name
    return ok / total, v_ok / v_total, v_total


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=60)
    ap.add_argument("--gap", type=float, default=0.55, help="silence between trials (s)")
    ap.add_argument("--period", type=int, default=256, help="JACK period in frames at 48 kHz")
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    r = live_run(args.trials, args.gap, args.period)
    print(f"load average {load0:.1f} before, {os.getloadavg()[0]:.1f} after (2 cores shared)")
    ev, fr = r["event"], r["frame"]
    print(f"JACK dummy {RATE} Hz, period {args.period} frames ({args.period / RATE * 1e3:.1f} ms); "
          f"{len(ev)}/{r['trials']} onsets heard")  # type: ignore[arg-type]
    if ev:
        print(f"sound -> event  p50 {pct(ev, 50) * 1e3:6.1f} ms  p99 {pct(ev, 99) * 1e3:6.1f} ms  max {max(ev) * 1e3:6.1f} ms")  # type: ignore[arg-type]
    if fr:
        print(f"sound -> frame  p50 {pct(fr, 50) * 1e3:6.1f} ms  p99 {pct(fr, 99) * 1e3:6.1f} ms  max {max(fr) * 1e3:6.1f} ms "  # type: ignore[arg-type]
              "(60 Hz ticks, 640x360 offscreen render)")
    print(f"CPU of the device's reader thread: {r['cpu'] * 100:.1f} % of one core")  # type: ignore[operator]
    print(f"analysis alone: {analysis_cost() * 100:.2f} % of one core (48 kHz, 10 ms hops)")
    frames, vowels, n = accuracy()
    print(f"vowel accuracy on held-out espeak-ng voices: {frames * 100:.1f} % of steady frames, "
          f"{vowels * 100:.1f} % of {n} whole sounds (A I U E O M F)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
