"""What the library keeps about a take, read from the take file itself: its content hash and
the recording's header and records (date, duration, face, devices, markers, performer)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from puppet.errors import ConfigError


def file_hash(path: str | Path) -> tuple[str, int]:
    """(SHA-256 hex of the file's bytes, size in bytes); a ConfigError naming the file if unreadable."""
    try:
        with open(path, "rb") as fh:
            digest = hashlib.file_digest(fh, "sha256")
            size = fh.tell()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the take: {err.strerror}") from err
    return digest.hexdigest(), size


@dataclass
class TakeInfo:
    path: str
    hash: str
    size: int
    recorded: str | None
    duration: float
    ticks: int
    tick_rate: float
    face: str | None
    identity: str | None
    resolution: int | None
    program: str | None
    devices: list[str] = field(default_factory=list)
    markers: list[tuple[float, str]] = field(default_factory=list)
    performer: str = ""
    warnings: list[str] = field(default_factory=list)
    ended: bool = True  # the take has its end record (False: its show died; it reads to its last whole tick)

    def devices_json(self) -> str:
        return json.dumps(self.devices)

    def markers_json(self) -> str:
        return json.dumps([[round(t, 4), label] for t, label in self.markers])


def read_take_info(path: str | Path) -> TakeInfo:
    """The library's fields of the recording at `path` (checked by the session reader: a file that
    is not a recording is one ConfigError line)."""
    from puppet.session import read_session

    p = Path(path).resolve()
    s = read_session(p)  # first: bounded, it refuses what is not a recording (hashing read a 3 GB file whole)
    digest, size = file_hash(p)
    return TakeInfo(
        path=str(p), hash=digest, size=size, duration=float(s.duration), ticks=int(s.ticks),
        markers=[(k / s.tick_rate, str(label)[:200]) for k, label in s.markers[:10_000]],
        warnings=list(s.warnings), ended=bool(s.complete), **header_fields(s.header),
    )


def _face(rig: dict[str, Any]) -> str | None:
    """The face as `--face` names it (ict, ict?identity=3, procedural, a saved identity's name),
    which `face:NAME` searches; a take made with `--rig FILE` (or before faces were named) by its
    rig's name. (The rig's name alone said "ict" for every character and "default" for the
    procedural face, so `face:bob` and `face:procedural` found nothing.)"""
    spec = rig.get("face")
    if isinstance(spec, str) and spec:
        return spec[:200]
    if isinstance(rig.get("name"), str):
        return rig["name"][:200]
    return "file" if rig.get("path") else None


def header_fields(h: dict[str, Any]) -> dict[str, Any]:
    """The library's fields a recording's header holds (date, tick rate, face and identity,
    program, devices, performer): all the library knows of a take when its recording starts."""
    rig = h.get("rig") or {}
    if not isinstance(rig, dict):
        rig = {}
    devs = h.get("devices")
    performer = h.get("performer")
    start = h.get("start_time")
    program = h.get("program")
    rate = h.get("tick_rate")
    return dict(
        recorded=str(start)[:40] if isinstance(start, str) else None,
        tick_rate=float(rate) if isinstance(rate, (int, float)) and not isinstance(rate, bool) else 60.0,
        face=_face(rig),
        identity=rig.get("hash") if isinstance(rig.get("hash"), str) else None,
        resolution=rig.get("resolution") if isinstance(rig.get("resolution"), int) else None,
        program=str(program)[:100] if isinstance(program, str) else None,
        devices=[str(d)[:200] for d in devs[:64]] if isinstance(devs, list) else [],
        performer=str(performer)[:200] if isinstance(performer, str) else "",
    )
