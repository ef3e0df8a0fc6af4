"""Small recordings for the studio tests, written with the program's own SessionWriter (no live
show needed): a ramp of a few channels, so each take replays to a moving face."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from puppet import live
from puppet.mapping.config import MappingSpec
from puppet.session import SessionWriter

_FACE = None


def face():
    global _FACE
    if _FACE is None:
        _FACE = live.load_face()
    return _FACE


def write_take(path: Path, ticks: int = 30, seed: int = 0, performer: str | None = None,
               markers: dict[int, str] | None = None, start_time: str | None = None) -> Path:
    """A take of `ticks` ticks at 60 Hz; `seed` changes which channels move and how far."""
    f = face()
    names = [c.name for c in f.vocab.channels]
    header = live.session_header(f, MappingSpec(name="test", bindings=[], combine={}, source="test", text=""), 60.0, ["mock://studio"])
    if performer:
        header["performer"] = performer
    if start_time:
        header["start_time"] = start_time
    rng = np.random.default_rng(seed)
    moving = rng.choice([i for i, c in enumerate(f.vocab.channels) if c.kind == "muscle"], 3, replace=False)
    values = np.array(f.vocab.defaults(), dtype=np.float64)
    path.parent.mkdir(parents=True, exist_ok=True)
    with SessionWriter(path, header, fsync_seconds=None) as w:
        for k in range(ticks):
            for j, i in enumerate(moving):
                values[i] = min(1.0, (0.3 + 0.2 * j) * k / max(1, ticks - 1))
            w.values(k, values)
            if markers and k in markers:
                w.marker(k, markers[k])
            w.tick(k + 1)
        w.close(ticks)
    assert len(names) == len(values)
    return path
