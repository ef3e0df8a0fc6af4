"""`puppet learn --device audio://NAME --profile FILE`: a performer's own vowels as a voice profile.

The room is measured first (quiet, 1.5 s: it sets the gate), then the performer says each sound
when asked (A, I, U, E, O, and closed lips), pressing Enter before each; two seconds are
recorded from the line "X: listening", and the frames of the steady middle of what was heard
become that sound's template.
Sounds not asked for (F) keep the shipped profile's. The file is written in one rename, and
`audio://NAME?profile=FILE` (or `puppet fit X.wav --voice-profile FILE`) uses it.
Prompts go to stdout and Enter comes from stdin, so a session can be scripted."""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

import numpy as np

ROOM_S = 1.5
TAKE_S = 2.0
MIN_FRAMES = 8
TRIES = 3


class _Buffer:
    """Blocks from the device's reader thread, kept while `on`."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.blocks: list[np.ndarray] = []
        self.on = False

    def __call__(self, block: np.ndarray, t: float) -> None:
        if self.on:
            with self.lock:
                self.blocks.append(np.array(block))

    def record(self, seconds: float, started: Any = None) -> np.ndarray:
        """What arrives in the next `seconds`; `started()` is called once blocks are being kept."""
        with self.lock:
            self.blocks = []
        self.on = True
        if started is not None:
            started()
        time.sleep(seconds)
        self.on = False
        with self.lock:
            return np.concatenate(self.blocks) if self.blocks else np.zeros(0)


def steady(samples: np.ndarray, rate: float, floor_db: float) -> tuple[np.ndarray, np.ndarray]:
    """(MFCCs, dBFS) of the frames of the loud middle of one recorded sound."""
    from devices.audio.analysis import frames_mfcc

    feats, dbs = frames_mfcc(samples, rate)
    if len(dbs) == 0:
        return feats, dbs
    keep = np.flatnonzero((dbs > floor_db) & (dbs > dbs.max() - 15.0))
    if keep.size >= 5:
        cut = (keep[-1] - keep[0]) // 6
        keep = keep[(keep >= keep[0] + cut) & (keep <= keep[-1] - cut)]
    return feats[keep], dbs[keep]


def learn_voice(spec: str, out: str, stdin: TextIO | None = None, timeout: float | None = None) -> int:
    """Run the session (see the module docstring); 0 when the profile was written."""
    import devices
    from devices.audio.profile import LEARN_PROMPTS, VoiceProfile, build_profile
    from puppet.errors import PuppetError

    stdin = stdin or sys.stdin
    dev: Any = devices.open_device(spec)
    if not hasattr(dev, "tap"):
        dev.close()
        raise PuppetError(f"{spec}: --profile learns a voice: give an audio:// device")
    buf = _Buffer()
    dev.tap = buf
    dev.start()
    try:
        rate = dev.rate
        print(f"learning a voice profile into {out} from {spec}", flush=True)
        print(f"quiet please: measuring the room for {ROOM_S:g} s", flush=True)
        room = buf.record(ROOM_S)
        rms = float(np.sqrt(np.mean(room ** 2))) if room.size else 0.0
        room_db = 20 * np.log10(rms) if rms > 1e-10 else -120.0
        gate = float(np.clip(room_db + 12.0, -60.0, -30.0))
        print(f"room at {room_db:.0f} dBFS: the gate opens at {gate:.0f} dBFS", flush=True)
        frames: dict[str, np.ndarray] = {}
        loud: list[np.ndarray] = []
        for name, prompt in LEARN_PROMPTS:
            for attempt in range(TRIES):
                print(f"{name}: {prompt} for about a second; press Enter, then start", flush=True)
                if stdin.readline() == "":
                    raise PuppetError("learning stopped before every sound was recorded; nothing written")
                # said once it listens: a performer (or a script) who starts at Enter on a busy
                # machine spoke before the recording began and was told "heard too little"
                sound = buf.record(TAKE_S, lambda: print(f"{name}: listening ({TAKE_S:g} s)", flush=True))
                f, d = steady(sound, rate, gate)
                if len(f) >= MIN_FRAMES:
                    frames[name] = f
                    loud.append(d)
                    print(f"{name}: heard {len(f)} frames at {np.median(d):.0f} dBFS", flush=True)
                    break
                print(f"{name}: heard too little (is the input live? louder, or longer)", flush=True)
            else:
                raise PuppetError(f"did not hear {name} after {TRIES} tries; nothing written")
    finally:
        dev.close()
    prof = build_profile(frames, note=f"learnt from {spec}", base=VoiceProfile.default())
    prof.gate_db = gate
    prof.ceil_db = float(min(-1.0, max(gate + 10.0, np.percentile(np.concatenate(loud), 95) + 3.0)))
    try:
        prof.save(out)
    except OSError as err:
        raise PuppetError(f"{out}: cannot write the voice profile: {err.strerror or err}") from err
    print(f"wrote {out}; perform with --device '{spec.split('?')[0]}?{_query(spec, out)}'", flush=True)
    return 0


def _query(spec: str, out: str) -> str:
    rest = spec.split("?", 1)[1] if "?" in spec else ""
    parts = [p for p in rest.split("&") if p and not p.startswith("profile=")]
    return "&".join([*parts, f"profile={Path(out)}"])
