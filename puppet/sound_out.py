"""The take's sound played with a replay in the window, where this machine has an audio output.

`TakeSound.sync(position, speed, playing)` is called once per frame with the replay's position in
take seconds: at normal speed the sound plays from there (re-aligned when it drifts by more than
SLACK_S, e.g. after a seek); paused, or at another speed, it is silent. No output (no sound card, no
server) means a silent replay and one line saying so, never a failed one."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

SLACK_S = 0.05


class TakeSound:
    """A WAV on the take's clock, played through python-sounddevice's default output."""

    def __init__(self, wav: Path) -> None:
        from devices.audio.wavfile import read_wav

        self.samples, self.rate = read_wav(wav)
        self.samples = self.samples.astype(np.float32)
        self._pos = 0  # next sample the callback plays
        self._playing = False
        self._stream: Any = None
        self._sd = False
        try:
            from devices.audio.sources import sounddevice

            sd = sounddevice()
            self._sd = True
            self._stream = sd.OutputStream(samplerate=self.rate, channels=1, dtype="float32",
                                           callback=self._callback)
            self._stream.start()
        except Exception as err:  # no output here: the replay is silent
            print(f"puppet: the take's sound ({wav.name}) is not played: no audio output ({err})", file=sys.stderr)
            self.close()

    @property
    def available(self) -> bool:
        return self._stream is not None

    def _callback(self, outdata: Any, frames: int, time_info: Any, status: Any) -> None:
        out = outdata[:, 0]
        if not self._playing:
            out[:] = 0.0
            return
        i = self._pos
        chunk = self.samples[i:i + frames]
        out[:len(chunk)] = chunk
        out[len(chunk):] = 0.0
        self._pos = i + frames

    def sync(self, position: float, speed: float, playing: bool) -> None:
        """The replay shows take time `position` (seconds) now."""
        want = int(position * self.rate)
        self._playing = playing and speed == 1.0 and 0 <= want < len(self.samples)
        if self._playing and abs(self._pos - want) > SLACK_S * self.rate:
            self._pos = want

    def close(self) -> None:
        stream, self._stream = self._stream, None
        if stream is not None:
            try:
                stream.abort()
                stream.close()
            except Exception:
                pass
        if self._sd:
            from devices.audio.sources import release_portaudio

            self._sd = False
            release_portaudio()
