"""Voice profiles: the templates the analysis matches a voice against, as a JSON data file.

A profile holds, per mouth class, the mean of 12 MFCCs over frames of that sound, and one scale per
coefficient (their spread over all frames) that standardises distances. The shipped default
(`profiles/default.json`, made by `profiles/make_default.py` from espeak-ng's voices) fits an
average voice; `puppet learn --device audio://NAME --profile me.json` records a performer's own
A, I, U, E, O and closed lips, and `audio://NAME?profile=me.json` uses it.

File format: {"format": "facepuppet-voice-profile", "version": 1, "templates": {NAME: [12 numbers]},
"scale": [12 numbers], optional "gate_db" and "ceil_db" (dBFS), optional "note"}.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from safefile import BadFile, atomic_write, load_json, number, read_text, sequence, string, table

FORMAT = "facepuppet-voice-profile"
N_CEPS = 12

#: Mouth shape of each class: (jaw opening, lip rounding, lip spread, lips closed, upper lip raise),
#: read from the viseme table of docs/audio.md (Meta's aa/E/ih/oh/ou/PP/FF, ARKit-style weights).
SHAPES: dict[str, tuple[float, float, float, float, float]] = {
    "A": (1.0, 0.0, 0.15, 0.0, 0.1),   # "aa" in car: jaw wide
    "E": (0.5, 0.0, 0.55, 0.0, 0.0),   # "e" in bed: mid-open, wider
    "I": (0.25, 0.0, 1.0, 0.0, 0.0),   # "ee" in see: lips spread, jaw high
    "O": (0.6, 0.7, 0.0, 0.0, 0.0),    # "o" in toe: rounded, jaw mid
    "U": (0.25, 1.0, 0.0, 0.0, 0.0),   # "oo" in food: rounded and pushed out
    "M": (0.0, 0.15, 0.0, 1.0, 0.0),   # m, b, p: lips shut
    "F": (0.1, 0.0, 0.1, 0.0, 1.0),    # f, v: upper teeth on the lower lip
}
#: What `puppet learn` asks a performer to say, in order: (class, prompt).
LEARN_PROMPTS: tuple[tuple[str, str], ...] = (
    ("A", 'say "aaah" (as in "father")'),
    ("I", 'say "eeee" (as in "see")'),
    ("U", 'say "oooo" (as in "food")'),
    ("E", 'say "eeh" (as in "bed")'),
    ("O", 'say "oooh" (as in "go")'),
    ("M", 'hum "mmmm" with your lips closed'),
)


@dataclass
class VoiceProfile:
    """Templates (class -> 12 MFCC means), per-coefficient scale, optional gate/ceiling in dBFS."""

    templates: dict[str, list[float]]
    scale: list[float]
    gate_db: float | None = None
    ceil_db: float | None = None
    note: str = ""
    source: str = "<profile>"
    extra: dict[str, object] = field(default_factory=dict)

    @classmethod
    def default(cls) -> VoiceProfile:
        """The shipped profile (an average voice)."""
        text = (resources.files("devices.audio") / "profiles" / "default.json").read_text(encoding="utf-8")
        return parse_profile(text, "devices/audio/profiles/default.json")

    def to_json(self) -> str:
        out: dict[str, object] = {"format": FORMAT, "version": 1,
                                  "templates": {k: [float(x) for x in v] for k, v in self.templates.items()},
                                  "scale": [float(x) for x in self.scale]}
        if self.gate_db is not None:
            out["gate_db"] = float(self.gate_db)
        if self.ceil_db is not None:
            out["ceil_db"] = float(self.ceil_db)
        if self.note:
            out["note"] = self.note
        return json.dumps(out, indent=1) + "\n"

    def save(self, path: str | Path) -> None:
        """Write the profile; a temporary file is renamed into place, so a failed write keeps the old one."""
        with atomic_write(path) as f:
            f.write(self.to_json())


def parse_profile(text: str, source: str) -> VoiceProfile:
    """Read a profile's JSON text; a BadFile naming `source` when anything is wrong."""
    data = table(load_json(text, source, "voice profile"), source)
    if data.get("format") != FORMAT:
        raise BadFile(f"{source}: not a voice profile (expected \"format\": \"{FORMAT}\"); "
                      "make one with `puppet learn --device audio://NAME --profile FILE`")
    if data.get("version") != 1:
        raise BadFile(f"{source}: unsupported voice profile version {data.get('version')!r}; expected 1")
    raw = table(data.get("templates"), f"{source}: templates", max_len=32)
    templates: dict[str, list[float]] = {}
    for name, vec in raw.items():
        if name not in SHAPES:
            raise BadFile(f"{source}: unknown template {name!r}; expected some of {', '.join(SHAPES)}")
        vals = sequence(vec, f"{source}: templates.{name}", max_len=N_CEPS, min_len=N_CEPS)
        templates[name] = [number(v, f"{source}: templates.{name}", -1e4, 1e4) for v in vals]
    if len(templates) < 2:
        raise BadFile(f"{source}: a voice profile needs at least two templates, got {len(templates)}")
    scale_raw = sequence(data.get("scale"), f"{source}: scale", max_len=N_CEPS, min_len=N_CEPS)
    scale = [number(v, f"{source}: scale", 1e-6, 1e4) for v in scale_raw]
    gate = data.get("gate_db")
    ceil = data.get("ceil_db")
    gate_db = None if gate is None else number(gate, f"{source}: gate_db", -120.0, 0.0)
    ceil_db = None if ceil is None else number(ceil, f"{source}: ceil_db", -120.0, 0.0)
    if gate_db is not None and ceil_db is not None and ceil_db <= gate_db + 3.0:
        raise BadFile(f"{source}: ceil_db {ceil_db:g} must lie at least 3 dB above gate_db {gate_db:g}")
    note = string(data.get("note", ""), f"{source}: note", max_len=500, empty=True)
    return VoiceProfile(templates, scale, gate_db, ceil_db, note, source)


def load_profile(path: str | Path) -> VoiceProfile:
    """A profile file; BadFile (one line naming the file) when it is missing or wrong."""
    return parse_profile(read_text(path, "voice profile", limit=1024 * 1024), str(path))


def build_profile(frames: dict[str, np.ndarray], note: str = "", base: VoiceProfile | None = None) -> VoiceProfile:
    """A profile from MFCC frames per class ((N, 12) arrays). Classes missing from `frames` keep
    `base`'s template; the scale is the spread of every frame given (at least a small floor)."""
    templates: dict[str, list[float]] = {} if base is None else {k: list(v) for k, v in base.templates.items()}
    pooled = []
    for name, f in frames.items():
        f = np.asarray(f, dtype=np.float64)
        if f.ndim != 2 or f.shape[1] != N_CEPS or len(f) == 0:
            raise ValueError(f"template {name}: expected (N, {N_CEPS}) MFCC frames, got shape {f.shape}")
        templates[name] = [float(x) for x in np.median(f, axis=0)]
        pooled.append(f - np.median(f, axis=0))
    within = np.concatenate(pooled)
    scale = np.maximum(np.std(within, axis=0), 0.05)
    if base is not None and len(frames) < 3:
        scale = np.asarray(base.scale)
    return VoiceProfile(templates, [float(x) for x in scale], note=note)
