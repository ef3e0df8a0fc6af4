"""A voice for tests: speech synthesised by espeak-ng, played into a real JACK port by another
process (tests/voice_player.py), on the private JACK server of tests/midijack.py."""

from __future__ import annotations

import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
from midijack import jack_lsp, ready_line, stop_child

PLAYER = Path(__file__).with_name("voice_player.py")


class Voice:
    """A JACK client playing WAV files: ``plug()`` starts it, ``unplug()`` ends it."""

    def __init__(self, name: str = "voice") -> None:
        self.name = name
        self.proc: subprocess.Popen[str] | None = None
        self.lines: queue.Queue[str] = queue.Queue()

    def plug(self) -> Voice:
        self.proc = subprocess.Popen([sys.executable, str(PLAYER), self.name], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, bufsize=1)
        threading.Thread(target=self._pump, args=(self.proc,), daemon=True).start()
        assert ready_line(self.lines, self.proc) == "ready"
        return self

    def _pump(self, proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            self.lines.put(line.strip())

    def play(self, path: str | Path) -> None:
        """Queue a file; `wait_done` then waits for the end of the last file queued."""
        assert self.proc is not None and self.proc.stdin is not None
        while not self.lines.empty():  # what earlier files said
            self.lines.get_nowait()
        self.proc.stdin.write(f"play {path}\n")
        self.proc.stdin.flush()

    def wait_done(self, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            line = self.lines.get(timeout=max(0.1, deadline - time.monotonic()))
            if line == "done":
                return

    def unplug(self) -> None:
        stop_child(self.proc)
        self.proc = None

    close = unplug


class Analysed:
    """How far an audio:// device has analysed what it heard: made its `tap` (`Analysed(dev)`), it
    sees every block, stamped with its capture time on the monotonic clock, just before the block is
    analysed. `wait_past(t)` returns once a block captured after `t` and one more have come: by then
    the events of all the sound heard before `t` have been sent, however far the device's thread
    lags on a busy machine (a fixed pause after the voice ended stood in for this)."""

    def __init__(self, dev: object) -> None:
        self._cond = threading.Condition()
        self.last: float | None = None
        self.blocks = 0
        dev.tap = self  # type: ignore[attr-defined]

    def __call__(self, block: np.ndarray, t: float) -> None:
        with self._cond:
            self.last, self.blocks = t, self.blocks + 1
            self._cond.notify_all()

    def wait_past(self, t: float, timeout: float = 120.0) -> None:
        with self._cond:
            ok = self._cond.wait_for(lambda: self.last is not None and self.last > t, timeout)
            assert ok, f"the device analysed nothing heard after the voice ended (last block at {self.last})"
            n = self.blocks
            assert self._cond.wait_for(lambda: self.blocks > n, timeout), "the device stopped analysing"


def speech_wav(path: Path, parts: list[tuple[str, float]], rate: int = 48000, noise_db: float | None = None,
               seed: int = 1, voice: str = "en-us") -> list[tuple[float, float]]:
    """Write a WAV of espeak-ng sounds, each followed by the given seconds of silence (and, with
    `noise_db`, one second of white noise at that RMS level at the end). Returns each sound's
    (start, end) in seconds from the file's start."""
    from math import gcd

    from scipy.signal import resample_poly

    from devices.audio.speech import synthesize
    from devices.audio.wavfile import WavWriter

    chunks, spans, t = [np.zeros(int(0.3 * rate))], [], 0.3
    for text, gap in parts:
        x, r = synthesize(text, speed=80, voice=voice)
        g = gcd(rate, r)
        x = resample_poly(x, rate // g, r // g)
        spans.append((t, t + len(x) / rate))
        chunks += [x, np.zeros(int(gap * rate))]
        t += len(x) / rate + gap
    if noise_db is not None:
        rng = np.random.default_rng(seed)
        chunks.append(rng.standard_normal(rate) * 10 ** (noise_db / 20))
    chunks.append(np.zeros(int(0.3 * rate)))
    w = WavWriter(path, rate)
    w.write(np.concatenate(chunks))
    w.close()
    return spans


def connected(server: str, port: str) -> bool:
    run = jack_lsp(server, "-c")
    out = run.stdout if run is not None else ""
    lines = out.splitlines()
    for i, line in enumerate(lines):
        if line.strip() == port:
            return i + 1 < len(lines) and lines[i + 1].startswith((" ", "\t"))
    return False


def wait_connected(server: str, port: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not connected(server, port):
        assert time.monotonic() < deadline, f"nothing listened to {port} within {timeout} s"
        time.sleep(0.05)
