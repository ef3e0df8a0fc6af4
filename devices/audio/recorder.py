"""The sound of a show, recorded beside its take: blocks from the device's reader thread are placed
in a WAV by their capture time, so WAV sample i is the sound at position i / rate of the caller's
timeline (the take's tick clock: tick k at k / tick rate seconds).

The timeline is given either as its origin (`anchor`: the monotonic time of position 0, e.g. a
show's schedule, which moves when the show drops wall time) or as (position, monotonic time) pairs,
e.g. once per tick; of the pairs, the earliest-looking of the last few wins (a tick that woke late
only looks later), so a timeline that jumps ahead is followed only once they have rolled over. Blocks
that arrive before the first pair wait in a short buffer. When the placement and what was written
disagree by more than ``TOLERANCE_S`` (a device unplugged and plugged back, a loop that dropped
time), silence is inserted or samples are dropped, so the sound stays in step with the ticks."""

from __future__ import annotations

import threading
from collections import deque
from pathlib import Path

import numpy as np

from devices.audio.wavfile import WavWriter

TOLERANCE_S = 0.010
#: Pairs the timeline estimate looks back over (half a second of 60 Hz ticks).
CLOCK_PAIRS = 30
EARLY_BUFFER_S = 3.0


class AudioRecorder:
    """Mono WAV of the device's input on the caller's timeline (see the module docstring)."""

    def __init__(self, path: str | Path, rate: int) -> None:
        self.rate = int(rate)
        self.writer = WavWriter(path, self.rate)
        self._pairs: deque[tuple[float, float]] = deque(maxlen=CLOCK_PAIRS)
        self._early: deque[tuple[np.ndarray, float]] = deque()
        self._early_n = 0
        self._anchor: float | None = None
        self._lock = threading.Lock()
        self.adjustments = 0  # times silence was inserted or samples dropped

    @property
    def path(self) -> Path:
        return self.writer.path

    def clock(self, position: float, t: float) -> None:
        """Timeline position `position` (seconds) happened at monotonic time `t`. Any thread."""
        self._pairs.append((position, t))

    def anchor(self, origin: float) -> None:
        """Timeline position 0 is at monotonic time `origin` (from now on, until anchored again). Any thread."""
        self._anchor = origin

    def _origin(self) -> float | None:
        """Monotonic time of timeline position 0."""
        if self._anchor is not None:
            return self._anchor
        pairs = list(self._pairs)
        if not pairs:
            return None
        return min(t - pos for pos, t in pairs)

    def push(self, block: np.ndarray, t_first: float) -> None:
        """A block of samples whose first was captured at monotonic time `t_first` (reader thread)."""
        with self._lock:
            origin = self._origin()
            if origin is None:
                self._early.append((np.array(block, dtype=np.float64), t_first))
                self._early_n += len(block)
                while self._early_n > EARLY_BUFFER_S * self.rate and len(self._early) > 1:
                    self._early_n -= len(self._early.popleft()[0])
                return
            while self._early:
                b, t = self._early.popleft()
                self._place(b, t, origin)
            self._early_n = 0
            self._place(np.asarray(block, dtype=np.float64), t_first, origin)

    def _place(self, block: np.ndarray, t_first: float, origin: float) -> None:
        w = self.writer
        idx = int(round((t_first - origin) * self.rate))
        gap = idx - w.frames
        if w.frames == 0 or abs(gap) > TOLERANCE_S * self.rate:
            if w.frames > 0:
                self.adjustments += 1
            if gap > 0:
                w.write_silence(gap)
            elif gap < 0:
                block = block[-gap:]  # already covered (or before position 0)
        w.write(block)

    def close(self, until: float | None = None) -> Path | None:
        """Finish the file (renamed into place); its path, or None when writing failed. With
        `until` (a timeline position, seconds) the file ends exactly there: silence is added for
        sound that never came (an input lost at the end), and what came after is cut."""
        with self._lock:
            if until is not None:
                end = int(round(until * self.rate))
                self.writer.write_silence(end - self.writer.frames)
                self.writer.truncate(end)
            return self.writer.close()
