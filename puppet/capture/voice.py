"""`puppet fit speech.wav --out take.jsonl`: the live voice analysis run offline over a recording.

The WAV goes through the same `VoiceAnalyzer` as `audio://` (same hops, same gate, same events),
the events through the shipped voice map (`puppet/maps/voice.toml`) at the take's tick rate, each
applied at the first tick boundary at or after the moment its sound was complete, as the live loop
does. The take records the events and the channel values, names the WAV as its sound, and is the
same, value for value, every time it is made from the same file."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

#: Silence added after the recording so the mouth comes back to rest within the take.
TAIL_S = 0.5


def voice_take(wav: str | Path, face: Any, out: Path, rate: float = 60.0, profile: str | None = None) -> list[str]:
    """Analyse `wav` and write the take `out`; returns lines for the terminal."""

    import sim
    from devices.audio.analysis import CONTROLS, VoiceAnalyzer, changes
    from devices.audio.profile import VoiceProfile, load_profile
    from devices.audio.wavfile import read_wav
    from devices.base import ControlInfo
    from devices.events import ControlEvent
    from puppet.capture.take import atomic_path
    from puppet.errors import ConfigError
    from puppet.live import CHECK_TICKS, session_header
    from puppet.mapping import Mapper
    from puppet.mapping.defaults import load_default_map, merge
    from puppet.replay import state_digest
    from puppet.session import SessionWriter

    wav = Path(wav)
    x, sr = read_wav(wav)
    prof = load_profile(profile) if profile else VoiceProfile.default()
    an = VoiceAnalyzer(sr, prof)
    frames = an.feed(np.concatenate([x, np.zeros(int(TAIL_S * sr))]), 0.0)
    dev = f"audio://{wav.name}"
    spec = merge([(load_default_map("voice"), dev)])
    mapper = Mapper(spec, face.vocab)
    mapper.declare_controls(dev, [ControlInfo(n, "axis", 0.0, 1.0) for n in CONTROLS])
    per_tick: dict[int, list[ControlEvent]] = {}
    sent = [0.0] * len(CONTROLS)
    voiced = 0
    for fr in frames:
        k = max(0, math.ceil(fr.t * rate - 1e-9))
        for i in changes(sent, fr.values):
            per_tick.setdefault(k, []).append(ControlEvent(dev, CONTROLS[i], "axis", fr.values[i], None, None, fr.t))
        voiced += fr.gate
    n = max(1, math.ceil((len(x) / sr + TAIL_S) * rate))
    header = {
        **session_header(face, spec, rate, [dev]),
        "source": {"input": str(wav.resolve()), "kind": "voice"},
        "audio": [{"device": dev, "file": wav.name, "path": str(wav.resolve()), "rate": sr}],
    }
    simulator = sim.Simulator(face.model, 1.0 / rate)
    control = sim.FaceControl(face.model)
    state = face.model.rest_state()
    with atomic_path(out, "take") as tmp:
        with SessionWriter(tmp, header, clock=lambda: 0.0, fsync_seconds=None) as w:
            for k in range(n):
                for ev in per_tick.get(k, ()):
                    w.event(k, ev)
                    mapper.feed(ev)
                values = mapper.step(1.0 / rate)
                w.values(k, values)
                control.values[...] = values
                simulator.step(state, control)
                if (k + 1) % CHECK_TICKS == 0:
                    w.check(k + 1, state_digest(state))
                w.tick(k + 1)
            w.close(n)
            if w.error is not None:
                raise ConfigError(f"{out}: cannot write the take: {w.error.strerror or w.error}")
    return [f"analysed {len(x) / sr:.2f} s of sound at {sr} Hz: {len(frames)} hops, voice in "
            f"{voiced * 100 // max(1, len(frames))} % of them; {sum(len(v) for v in per_tick.values())} events "
            f"through the voice map (puppet/maps/voice.toml)",
            f"wrote a take of {n} ticks ({n / rate:.2f} s at {rate:g} Hz) to {out}; its sound is {wav}"]
