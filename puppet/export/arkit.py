"""Channel values -> ARKit's 52 blendshapes, written as a Live Link Face-style CSV.

The mapping is a documented approximation (see docs/live.md): ARKit has shapes we cannot drive
(cheekPuff, jaw sideways/forward, tongue, lip roll, funnel) and we have muscles ARKit cannot
express (zygomaticus minor AU11, levator anguli oris AU13, age). "Left" is the face's own left,
the `_l` side of our channels."""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path
from typing import IO

import numpy as np

from devices.facestream import ARKIT_NAMES
from puppet.errors import ConfigError

#: The 52 blendshapes in ARKit's order, spelt as the Live Link Face CSV does (PascalCase).
ARKIT_SHAPES = tuple(n[0].upper() + n[1:] for n in ARKIT_NAMES)
ROTATIONS = ("HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
             "RightEyeYaw", "RightEyePitch", "RightEyeRoll")

Getter = Callable[[str], float]


def _side(shape: str) -> str:
    return "_l" if shape.endswith("Left") else "_r"


#: Sided shapes (base name without Left/Right) that are one channel of the same side.
SIMPLE_SHAPES = {
    "EyeBlink": "orbicularis_oculi_lid", "EyeWide": "levator_palpebrae", "EyeSquint": "orbicularis_oculi", "CheekSquint": "orbicularis_oculi",
    "NoseSneer": "levator_labii_alaeque_nasi", "MouthSmile": "zygomaticus_major",
    "MouthFrown": "depressor_anguli_oris", "MouthDimple": "buccinator", "MouthStretch": "risorius",
    "MouthLowerDown": "depressor_labii", "MouthUpperUp": "levator_labii", "BrowOuterUp": "frontalis_outer",
}


def _rule(shape: str) -> Callable[[Getter], float] | None:
    """How one ARKit shape is computed from channel values (None: we cannot express it)."""
    s = _side(shape)
    base = shape.removesuffix("Left").removesuffix("Right")
    simple = SIMPLE_SHAPES
    if base in simple:
        name = simple[base] + s
        return lambda g: g(name)
    if base == "BrowDown":
        return lambda g: max(g("corrugator" + s), g("procerus"))
    if base == "MouthPress":
        return lambda g: g("orbicularis_oris")
    if shape == "BrowInnerUp":
        return lambda g: 0.5 * (g("frontalis_inner_l") + g("frontalis_inner_r"))
    if shape == "JawOpen":
        return lambda g: g("jaw")
    if shape == "MouthShrugLower":
        return lambda g: g("mentalis")
    # gaze: +yaw looks towards the face's left: out for the left eye, in for the right one
    gaze = {
        "EyeLookOutLeft": lambda g: max(0.0, g("eyes_yaw")), "EyeLookInLeft": lambda g: max(0.0, -g("eyes_yaw")),
        "EyeLookInRight": lambda g: max(0.0, g("eyes_yaw")), "EyeLookOutRight": lambda g: max(0.0, -g("eyes_yaw")),
        "EyeLookUpLeft": lambda g: max(0.0, g("eyes_pitch")), "EyeLookUpRight": lambda g: max(0.0, g("eyes_pitch")),
        "EyeLookDownLeft": lambda g: max(0.0, -g("eyes_pitch")),
        "EyeLookDownRight": lambda g: max(0.0, -g("eyes_pitch")),
    }
    return gaze.get(shape)


RULES = {shape: _rule(shape) for shape in ARKIT_SHAPES}
UNSUPPORTED = tuple(s for s, r in RULES.items() if r is None)


def arkit_row(values: np.ndarray, index: dict[str, int]) -> list[float]:
    """The 52 blendshape weights (0..1) for one tick's channel values."""
    def g(name: str) -> float:
        i = index.get(name)
        return float(values[i]) if i is not None else 0.0

    return [min(1.0, max(0.0, r(g))) if r is not None else 0.0 for r in RULES.values()]


def timecode(frame: int, fps: float) -> str:
    """HH:MM:SS:FF.mmm with an integer frame count at `fps` (never seconds an importer rounds)."""
    ifps = max(1, round(fps))
    secs, ff = divmod(frame, ifps)
    hh, rem = divmod(secs, 3600)
    mm, ss = divmod(rem, 60)
    return f"{hh:02d}:{mm:02d}:{ss:02d}:{ff:02d}.000"


class ArkitCsvWriter:
    """Writes Timecode, BlendShapeCount (61), the 52 shapes, then head and eye rotations.
    Head rotations are 0 (the face does not move its head); eye yaw/pitch are our -1..1 gaze."""

    def __init__(self, path: str | Path, channel_names: list[str], fps: float) -> None:
        self.index = {n: i for i, n in enumerate(channel_names)}
        self.fps = fps
        try:
            self._fh: IO[str] | None = open(path, "w", newline="", encoding="utf-8")
        except OSError as err:
            raise ConfigError(f"{path}: cannot write the ARKit CSV: {err.strerror}") from err
        self._csv = csv.writer(self._fh)
        self._csv.writerow(["Timecode", "BlendShapeCount", *ARKIT_SHAPES, *ROTATIONS])

    def add(self, frame: int, values: np.ndarray) -> None:
        yaw = float(values[self.index["eyes_yaw"]]) if "eyes_yaw" in self.index else 0.0
        pitch = float(values[self.index["eyes_pitch"]]) if "eyes_pitch" in self.index else 0.0
        shapes = arkit_row(values, self.index)
        self._csv.writerow([timecode(frame, self.fps), len(ARKIT_SHAPES) + len(ROTATIONS),
                            *(f"{v:.6g}" for v in shapes), 0, 0, 0, yaw, pitch, 0, yaw, pitch, 0])

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
