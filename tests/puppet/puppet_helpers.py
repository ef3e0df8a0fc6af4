"""Small shared helpers for the puppet tests: a face vocabulary that needs no sim, event makers."""

from __future__ import annotations

import os
import subprocess
import sys

from devices.events import ControlEvent
from puppet.mapping import ChannelInfo, Mapper, Vocabulary, parse_mapping

CHANNELS = [
    ChannelInfo("zygomaticus_major_l", "muscle", 0.0, 1.0, 0.0),
    ChannelInfo("zygomaticus_major_r", "muscle", 0.0, 1.0, 0.0),
    ChannelInfo("frontalis_inner_l", "muscle", 0.0, 1.0, 0.0),
    ChannelInfo("frontalis_inner_r", "muscle", 0.0, 1.0, 0.0),
    ChannelInfo("orbicularis_oculi_lid_l", "muscle", 0.0, 1.0, 0.0),
    ChannelInfo("orbicularis_oculi_lid_r", "muscle", 0.0, 1.0, 0.0),
    ChannelInfo("jaw", "jaw", 0.0, 1.0, 0.0),
    ChannelInfo("eyes_yaw", "eyes", -1.0, 1.0, 0.0),
    ChannelInfo("age", "age", 0.0, 120.0, 30.0),
]
AUS = {
    "AU1": {"frontalis_inner_l": 1.0, "frontalis_inner_r": 1.0},
    "AU12": {"zygomaticus_major_l": 1.0, "zygomaticus_major_r": 1.0},
    "AU26": {"jaw": 0.5},
    "AU45": {"orbicularis_oculi_lid_l": 1.0, "orbicularis_oculi_lid_r": 1.0},
}
EXPRESSIONS = {"happiness": {"AU12": 0.8}, "surprise": {"AU1": 1.0, "AU26": 1.0}}

DT = 1.0 / 60.0


def vocab() -> Vocabulary:
    return Vocabulary(CHANNELS, AUS, EXPRESSIONS)


def mapper(text: str) -> Mapper:
    return Mapper(parse_mapping(text, "test.toml"), vocab())


def ev(control: str, value: float, kind: str = "axis", device: str = "mock://", raw: object = None) -> ControlEvent:
    return ControlEvent(device, control, kind, value, None, raw, 0.0)  # type: ignore[arg-type]


def idx(name: str) -> int:
    return [c.name for c in CHANNELS].index(name)


#: what a `puppet` subprocess of a test runs with: output unbuffered, so a killed show has said its lines
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def run_puppet(*args: str, env: dict | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    """`python -m puppet ARGS` as a user runs it, its output captured."""
    return subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True,
                          env=env or ENV, timeout=timeout)
