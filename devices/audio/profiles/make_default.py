"""Make `default.json`, the shipped voice profile: espeak-ng says each class's sound with several
voices and pitches, and the frames of each utterance's steady middle are averaged into templates.
Run by hand (`python -m devices.audio.profiles.make_default`); the file is committed. The voices
`en-us+m2`, `en-us+f2` and `en-us+f4` are kept out, so the benchmark can measure accuracy on voices
the profile never heard."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from devices.audio.analysis import frames_mfcc
from devices.audio.profile import build_profile
from devices.audio.speech import PHONEMES, synthesize

TRAIN_VOICES = ("en-us", "en-us+m1", "en-us+m3", "en-us+f1", "en-us+f3", "en-us+m5")
HELD_OUT_VOICES = ("en-us+m2", "en-us+f2", "en-us+f4")
PITCHES = (35, 50, 65)


def steady_frames(samples: np.ndarray, rate: int) -> np.ndarray:
    """MFCCs of the loud middle of an utterance (within 12 dB of its peak, edges trimmed)."""
    feats, dbs = frames_mfcc(samples, rate)
    keep = np.flatnonzero(dbs > dbs.max() - 12.0)
    if keep.size < 5:
        return feats[keep]
    lo, hi = keep[0], keep[-1]
    cut = (hi - lo) // 5
    idx = keep[(keep >= lo + cut) & (keep <= hi - cut)]
    return feats[idx]


def class_frames(voices: tuple[str, ...], pitches: tuple[int, ...] = PITCHES) -> dict[str, np.ndarray]:
    out: dict[str, list[np.ndarray]] = {k: [] for k in PHONEMES}
    for voice in voices:
        for pitch in pitches:
            for name, texts in PHONEMES.items():
                for text in texts:
                    x, rate = synthesize(text, voice=voice, speed=80, pitch=pitch)
                    out[name].append(steady_frames(x, rate))
    return {k: np.concatenate(v) for k, v in out.items()}


def main() -> int:
    frames = class_frames(TRAIN_VOICES)
    prof = build_profile(frames, note="espeak-ng 1.51 voices " + ", ".join(TRAIN_VOICES) + "; an average voice")
    target = Path(__file__).with_name("default.json")
    prof.save(target)
    print(f"wrote {target} ({', '.join(f'{k}: {len(v)} frames' for k, v in frames.items())})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
