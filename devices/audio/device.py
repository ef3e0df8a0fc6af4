"""``audio://NAME[?api=alsa|jack|pulse&channel=N&profile=PATH&gate=DB]`` — a microphone (or any
audio input) analysed into mouth controls: ALSA and PulseAudio through python-sounddevice over
PortAudio, JACK through JACK-Client (devices.audio.sources).

NAME is a case-insensitive part of the input's name (on JACK: the name of the client whose output
port carries the voice; our own client's input port is connected to it). ``api`` names the host
API (default ALSA on Linux; ``pulse`` uses PortAudio's PulseAudio host API where the library has
one, else ALSA's ``pulse`` device with NAME as the PulseAudio source). ``channel`` picks one
channel (1-based; default: the first). ``profile`` is a voice profile file from ``puppet learn``
(default: the shipped average voice); ``gate`` the noise gate in dBFS (default -45, or the profile's).

Threads: the audio system calls back on its own thread (PortAudio's, or the JACK server's process
cycle) with each block; the callback only copies it into a preallocated ring and notes when it came.
This device's reader thread takes what has arrived every 2 ms, runs the analysis in 10 ms hops and
emits an axis event per control whose value changed (``level``, ``jaw``, ``round``, ``spread``,
``closed``, ``upper_lip``), stamped with the capture time of the newest sample that contributed. The
live loop's tick only drains events. An input that goes away is ``lost`` (JACK: its client's port
vanishes or the server stops; ALSA: the stream stops) and is reopened when it comes back
(devices.audio.sources says why JACK is reached without PortAudio).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from devices.audio.analysis import CONTROLS, AnalyzerSettings, VoiceAnalyzer, changes
from devices.audio.profile import VoiceProfile, load_profile
from devices.audio.recorder import AudioRecorder
from devices.audio.sources import make_source
from devices.base import ControlInfo, Device
from devices.errors import DeviceError, DeviceSpecError
from devices.events import ControlEvent
from devices.spec import DeviceSpec
from safefile import BadFile

APIS = ("alsa", "jack", "pulse")
#: Seconds between checks that the input is still there.
PRESENCE_CHECK = 0.25
#: How fast the capture-clock estimate (the earliest arrival seen) may move later: audio and
#: system clocks drift apart by far less than this.
DRIFT = 2e-4
PREFERRED_RATE = 48000
#: Seconds of input the ring between PortAudio's thread and the reader holds.
RING_S = 2.0
#: Reader thread's polling interval.
POLL_S = 0.002


class AudioDevice(Device):
    """A voice on an audio input drives the mouth (see the module docstring)."""

    scheme = "audio"
    FORM = "audio://NAME[?api=alsa|jack|pulse&channel=N&profile=PATH&gate=DB]"
    OPTIONS = frozenset({"api", "channel", "profile", "gate"})

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        if not spec.location:
            raise DeviceSpecError(f"{spec.text}: no input named; expected {self.FORM} "
                                  "(`puppet devices` lists the inputs)")
        api = spec.query.get("api", "alsa").lower()
        if api not in APIS:
            raise DeviceSpecError(f"{spec.text}: api={api!r}; expected api=alsa, api=jack or api=pulse ({self.FORM})")
        super().__init__(spec, **options)
        self.api = api
        self.name = spec.location
        self.channel = spec.get_int("channel", 1, lo=1, hi=64) - 1
        path = spec.query.get("profile")
        try:
            self.profile = load_profile(path) if path else VoiceProfile.default()
        except BadFile as err:
            raise DeviceSpecError(f"{spec.text}: {err}") from err
        gate = self.profile.gate_db if self.profile.gate_db is not None else -45.0
        if "gate" in spec.query:
            gate = _negative_db(spec)
        ceil = self.profile.ceil_db if self.profile.ceil_db is not None else -12.0
        self.settings = AnalyzerSettings(gate_db=gate, ceil_db=max(ceil, gate + 6.0))
        self.description = f"voice on audio input {self.name!r} ({api.upper()})"
        self.controls = [ControlInfo(name, "axis", 0.0, 1.0) for name in CONTROLS]
        self._rate = float(PREFERRED_RATE)
        self._analyzer: VoiceAnalyzer | None = None
        self._next_check = 0.0
        self._woken = False
        self._n = 0
        self._offset: float | None = None
        self._last_read = 0.0
        self._frame0: int | None = None
        self._latency = 0.0
        self._sent = [0.0] * len(CONTROLS)
        self._ring = np.zeros(1, dtype=np.float32)
        self._w = self._r = 0
        self._stamp: tuple[float, int] | None = None
        self._source: Any = None
        self._fresh = True
        self.recorder: AudioRecorder | None = None
        #: called from the reader thread with every block and its capture time (`puppet learn`)
        self.tap: Callable[[np.ndarray, float], None] | None = None
        #: the newest frame's values (level first) and level in dBFS, for the page and the HUD
        self.values: tuple[float, ...] = (0.0,) * len(CONTROLS)
        self.db = -200.0

    @property
    def level(self) -> float:
        """The current noise-gated loudness, 0..1."""
        return self.values[0]

    @property
    def rate(self) -> float:
        return self._rate

    # ------------------------------------------------------------------ handle
    def _open(self) -> None:
        self._close_handle()
        rate_before = self._rate
        self._ring = np.zeros(1, dtype=np.float32)
        self._w = self._r = 0
        self._stamp = None
        source = make_source(self.api, self.name, self.channel)
        self._source = source
        try:
            source.open(self._deliver)
        except DeviceError as err:
            self._source = None
            raise DeviceError(f"{self.spec}: {err}") from err
        except BaseException:
            self._source = None
            raise
        self._rate = source.rate
        self._latency = source.latency
        if self._analyzer is None or self._rate != rate_before:
            self._analyzer = VoiceAnalyzer(self._rate, self.profile, self.settings)
        else:
            self._analyzer.reset()
        self._n = 0
        self._offset = None
        self._frame0 = None
        self._fresh = True
        self._next_check = time.monotonic() + PRESENCE_CHECK
        self.description = f"voice on audio input {source.name!r} ({self.api.upper()}, {self._rate:g} Hz)"

    def _present(self) -> bool:
        return self._source is not None and self._source.present()

    def _close_handle(self) -> None:
        source, self._source = self._source, None
        if source is not None:
            source.close()
        self._release_controls()

    def _release_controls(self) -> None:
        """A lost input says nothing more: the mouth it held comes back to rest."""
        if any(self._sent):
            t = time.monotonic()
            for i, name in enumerate(CONTROLS):
                if self._sent[i] != 0.0:
                    self.emit(ControlEvent(self.spec, name, "axis", 0.0, None, None, t))
            self._sent = [0.0] * len(CONTROLS)
        self.values = (0.0,) * len(CONTROLS)

    def _wake(self) -> None:
        self._woken = True

    def _deliver(self, block: np.ndarray, frame: int | None = None) -> None:
        """The audio system's thread: copy the block into the ring and note the time; nothing else.
        `frame` (JACK: the cycle's frame counter) reveals cycles that were dropped (an XRun): their
        place is kept with silence, so the stream position stays on the audio clock."""
        if frame is not None:
            if self._frame0 is None:
                self._frame0 = frame - self._w
            gap = frame - (self._frame0 + self._w)
            if 0 < gap < 3600 * 48000:
                size = self._ring.shape[0]
                skip = max(0, gap - size)  # a stall longer than the ring: the reader skips it
                self._w += skip
                self._write(np.zeros(gap - skip, dtype=np.float32))
            elif gap != 0:
                self._frame0 = frame - self._w  # the counter started again: follow it
        self._write(block)

    def _write(self, block: np.ndarray) -> None:
        frames = block.shape[0]
        ring = self._ring
        size = ring.shape[0]
        if size < frames * 4:  # the first block tells the block size: a ring of RING_S seconds
            ring = self._ring = np.zeros(max(frames * 4, int(RING_S * self._source_rate())), dtype=np.float32)
            size = ring.shape[0]
        w = self._w
        i = w % size
        first = min(frames, size - i)
        ring[i:i + first] = block[:first]
        if first < frames:
            ring[:frames - first] = block[first:]
        self._w = w + frames
        self._stamp = (time.monotonic(), w + frames)

    def _source_rate(self) -> float:
        src = self._source
        return src.rate if src is not None else self._rate

    # ------------------------------------------------------------------ reader thread
    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        now = time.monotonic()
        if now >= self._next_check:
            if not self._present():
                raise OSError(f"audio input {self.name!r} went away")
            self._next_check = now + PRESENCE_CHECK
        deadline = min(now + timeout, self._next_check)
        self._woken = False
        while True:
            w, r = self._w, self._r
            if w > r:
                return self._process(self._take(w, r))
            now = time.monotonic()
            if self._woken or now >= deadline:
                return []
            time.sleep(min(POLL_S, max(0.0, deadline - now)))

    def _take(self, w: int, r: int) -> np.ndarray:
        """Samples r..w of the ring (the oldest are skipped if the reader fell a whole ring behind)."""
        ring = self._ring
        size = ring.shape[0]
        if w - r > size:  # (before the first read after opening, the ring just waited for start())
            if not self._fresh:
                self.warnings.warn("overrun", f"the analysis fell {(w - r - size) / self._rate:.2f} s behind; skipped")
            self._n += w - r - size
            r = w - size
        self._fresh = False
        self._r = w
        i, j = r % size, w % size
        if i < j:
            return ring[i:j].astype(np.float64)
        return np.concatenate([ring[i:], ring[:j]]).astype(np.float64)

    def _process(self, block: np.ndarray) -> list[ControlEvent]:
        """Samples just read -> events; also feeds the recorder."""
        rate = self._rate
        n0 = self._n
        self._n += len(block)
        stamp = self._stamp
        if stamp is not None:  # (when the callback returned, samples delivered by then)
            now, delivered = stamp
            candidate = now - delivered / rate - self._latency  # stream position 0 on the monotonic clock
            if self._offset is None:
                self._offset = candidate
            else:
                self._offset = min(self._offset + DRIFT * (now - self._last_read), candidate)
            self._last_read = now
        offset = self._offset
        if offset is None:
            offset = time.monotonic() - self._n / rate
        rec = self.recorder
        if rec is not None:
            rec.push(block, offset + n0 / rate)
        tap = self.tap
        if tap is not None:
            tap(block, offset + n0 / rate)
        assert self._analyzer is not None
        frames = self._analyzer.feed(block, n0 / rate)
        events: list[ControlEvent] = []
        sent = self._sent
        for fr in frames:
            t = offset + fr.t
            for i in changes(sent, fr.values):
                events.append(ControlEvent(self.spec, CONTROLS[i], "axis", fr.values[i], None, None, t))
        if frames:
            self.values = frames[-1].values
            self.db = frames[-1].db
        return events

    # ------------------------------------------------------------------ recording
    def record_to(self, path: str, rate: int | None = None) -> AudioRecorder:
        """Start recording this input into a WAV at `path` (see devices.audio.recorder); the
        caller feeds the recorder's clock and closes it."""
        self.recorder = AudioRecorder(path, int(rate or round(self._rate)))
        return self.recorder

    def stop_recording(self, until: float | None = None) -> str | None:
        """Finish the WAV (ending at timeline position `until`, if given); its path, or None."""
        rec, self.recorder = self.recorder, None
        if rec is None:
            return None
        out = rec.close(until)
        return None if out is None else str(out)

    def close(self) -> None:
        super().close()
        self.stop_recording()


def _negative_db(spec: DeviceSpec) -> float:
    raw = spec.query["gate"]
    try:
        v = float(raw)
    except ValueError as err:
        raise DeviceSpecError(f"{spec.text}: option gate={raw!r} is not a number (dBFS, e.g. gate=-45)") from err
    if not (math.isfinite(v) and -120.0 <= v <= 0.0):
        raise DeviceSpecError(f"{spec.text}: option gate={raw} must be a level in dBFS between -120 and 0")
    return v


def audio_inputs(apis: tuple[str, ...] = ("alsa", "jack")) -> list[tuple[str, str]]:
    """(spec, description) of every audio input, for `puppet devices`."""
    from devices.audio.sources import audio_inputs as found

    return found(apis)
