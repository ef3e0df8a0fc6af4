"""A Live Link Face / ARKit blendshape CSV recording -> channel values, through the inverse of the
mapping `puppet.export.arkit` writes (docs/live.md): each blendshape drives the channel(s) it was
computed from, scaled by the shape's calibrated span (`SHAPE_SPAN`; many also drive other channels by
shares, `SHAPE_SHARES`: MouthPress the mentalis, ...); where two shapes drive one channel (EyeSquint and CheekSquint)
the larger wins (BrowDown, exported from corrugator and procerus, comes back as the corrugator). Every one of the 52
shapes has a channel (JawLeft and JawRight together give the signed jaw_sideways; MouthFunnel
everts both lips, MouthShrugUpper the upper one). The head's rotation columns turn the head (head_yaw, head_pitch, head_roll, quarter
turns); gaze comes from the EyeLook shapes: the eyes' mean yaw and pitch, and half the difference of
their yaws as the vergence (one eye's look alone turns that eye only).

Column names are matched without regard to case (MediaPipe writes `mouthSmileLeft`).
Timecode HH:MM:SS:FF(.mmm), FF counted at the recording's frame rate (--fps; by default read
from where the seconds roll over, or 60, Live Link's default, for a clip shorter than a second)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from puppet.capture.points import ChannelCapture, check_times, csv_rows, read_csv_text
from puppet.errors import ConfigError
from puppet.export.arkit import (ARKIT_SHAPES, GAZE_LIDS, MOUTH_CLOSE_LIFT, MOUTH_CLOSE_SPAN, ONE_CHANNEL, ROTATIONS, SHAPE_SHARES, SHAPE_SPAN,
                                 SIMPLE_SHAPES, UNSUPPORTED)

_TC = re.compile(r"(\d+):(\d{2}):(\d{2})[:;](\d+)(?:\.(\d+))?")
RATES = (24, 25, 30, 50, 60)


def _simple(base: str) -> str | None:
    if base == "BrowDown":
        return "corrugator"
    return SIMPLE_SHAPES.get(base)


def shape_targets(shape: str) -> list[str]:
    """The channels one ARKit shape drives (empty: not expressible)."""
    side = "_l" if shape.endswith("Left") else "_r"
    base = shape.removesuffix("Left").removesuffix("Right")
    ch = _simple(base)
    if ch:
        return [ch + side]
    if shape in ONE_CHANNEL:
        return [ONE_CHANNEL[shape]] + (["orbicularis_oris_peripheralis_upper"] if shape == "MouthFunnel" else [])
    return {"BrowInnerUp": ["frontalis_inner_l", "frontalis_inner_r"], "JawOpen": ["jaw"],
            "MouthShrugLower": ["mentalis"], "MouthPressLeft": ["orbicularis_oris_l"],
            "MouthPressRight": ["orbicularis_oris_r"]}.get(shape, [])


def share_targets(shape: str, channel: str, index: dict[str, int]) -> list[str]:
    """The channels a shape's share (`SHAPE_SHARES`) drives: named without its side, the shape's
    own side (a one-sided shape drives the side's half of an unsided muscle, `sim.channels.HALVES`,
    where the face has one; both sides for an unsided shape); else the channel itself."""
    if shape.endswith(("Left", "Right")):
        sided = channel + ("_l" if shape.endswith("Left") else "_r")
        if sided in index or channel not in index:
            return [sided]
    if channel in index:
        return [channel]
    return [channel + "_l", channel + "_r"]


def shape_channels(shapes: dict[str, np.ndarray], n: int,
                   turns: dict[str, np.ndarray] | None = None, couple: bool = True) -> np.ndarray:
    """(n, C) channel values for blendshape columns ``{PascalCase shape: (n,) weights 0..1}`` and
    rotation columns (``HeadYaw`` ...), through the inverted export mapping; channels no column
    drives keep their defaults. `couple`: the gaze carries the lids (`GAZE_LIDS`)."""
    from sim.channels import CHANNEL_NAMES, CHANNEL_SPECS

    values = np.zeros((n, len(CHANNEL_NAMES)))
    values[:] = [s.default for s in CHANNEL_SPECS]
    index = {name: i for i, name in enumerate(CHANNEL_NAMES)}
    driven = np.zeros(len(CHANNEL_NAMES), bool)
    for shape, col in shapes.items():
        col = np.asarray(col, float)
        if shape == "MouthClose":
            if MOUTH_CLOSE_LIFT in index:  # the lips' lift follows the shape itself (MOUTH_CLOSE_LIFT)
                i = index[MOUTH_CLOSE_LIFT]
                own = np.clip(col, 0.0, 1.0)
                values[:, i] = np.maximum(values[:, i], own) if driven[i] else own
                driven[i] = True
            col = col / MOUTH_CLOSE_SPAN
        base = shape.removesuffix("Left").removesuffix("Right")
        span = SHAPE_SPAN.get(base, 1.0)
        for ch in shape_targets(shape):
            i = index[ch]
            own = span * np.clip(col, 0.0, 1.0)
            values[:, i] = np.maximum(values[:, i], own) if driven[i] else own
            driven[i] = True
        for ch, share in SHAPE_SHARES.get(base, ()):
            for target in share_targets(shape, ch, index):
                i = index[target]
                own = share * np.clip(col, 0.0, 1.0)
                values[:, i] = np.maximum(values[:, i], own) if driven[i] else own
                driven[i] = True

    def g(name: str) -> np.ndarray:
        return np.asarray(shapes.get(name, np.zeros(n)), float)

    for look, (lid, share) in GAZE_LIDS.items() if couple else ():
        for side, suffix in (("Left", "_l"), ("Right", "_r")):
            if look + side in shapes and share > 0.0:
                i = index[lid + suffix]
                values[:, i] = np.maximum(values[:, i], share * np.clip(g(look + side), 0.0, 1.0))

    # each eye's yaw (+ towards the face's left): their mean is the shared gaze, half their
    # difference the vergence (sim.gaze_lids.eye_yaws)
    yaw_l, yaw_r = g("EyeLookOutLeft") - g("EyeLookInLeft"), g("EyeLookInRight") - g("EyeLookOutRight")
    yaw = 0.5 * (yaw_l + yaw_r)
    pitch = 0.5 * ((g("EyeLookUpLeft") - g("EyeLookDownLeft")) + (g("EyeLookUpRight") - g("EyeLookDownRight")))
    if "JawLeft" in shapes or "JawRight" in shapes:
        values[:, index["jaw_sideways"]] = np.clip(g("JawLeft") - g("JawRight"), -1, 1)
    values[:, index["eyes_yaw"]] = np.clip(yaw, -1, 1)
    values[:, index["eyes_vergence"]] = np.clip(0.5 * (yaw_r - yaw_l), -1, 1)
    values[:, index["eyes_pitch"]] = np.clip(pitch, -1, 1)
    for column, channel in (("HeadYaw", "head_yaw"), ("HeadPitch", "head_pitch"), ("HeadRoll", "head_roll")):
        if turns and column in turns:
            values[:, index[channel]] = np.clip(turns[column], -1.0, 1.0)
    return values


def _timecode(path: Path, lineno: int, text: str) -> tuple[int, int, float]:
    m = _TC.fullmatch(text.strip())
    if not m:
        raise ConfigError(f"{path}:{lineno}: timecode {text!r} is not HH:MM:SS:FF.mmm")
    hh, mm, ss, ff = (int(m.group(i)) for i in range(1, 5))
    frac = float("0." + m.group(5)) if m.group(5) else 0.0
    return hh * 3600 + mm * 60 + ss, ff, frac


def _rate(stamps: list[tuple[int, int, float]], max_ff: int) -> float:
    """The frame rate the FF field counts at: where a second rolls over, the last FF before it
    plus one (rounded up to a known rate); with no rollover in the file, 60 (Live Link's
    default) unless the frame numbers need more."""
    wraps = [a[1] + 1 for a, b in zip(stamps, stamps[1:]) if b[0] == a[0] + 1 and b[1] < a[1]]
    top = max(wraps) if wraps else max(max_ff + 1, 60)
    return float(next((r for r in RATES if r >= top), top))


def read_arkit_csv(path: Path, fps: float | None = None) -> ChannelCapture:
    from sim.channels import CHANNEL_NAMES

    rows = csv_rows(path, read_csv_text(path, "ARKit CSV"), "ARKit CSV")
    header = [h.strip() for h in rows[0]] if rows else []
    if len(header) < 2 or header[0].lower() != "timecode":
        raise ConfigError(f"{path}:1: expected a header 'Timecode,BlendShapeCount,EyeBlinkLeft,...'")
    known = {s.lower(): s for s in (*ARKIT_SHAPES, *ROTATIONS)}
    known.update({"blendshapecount": "BlendShapeCount", "_neutral": "_neutral"})
    cols: list[str] = []
    for j, h in enumerate(header[1:], start=2):
        name = known.get(h.lower())
        if name is None:
            raise ConfigError(f"{path}:1: column {j} {h!r} is not an ARKit blendshape or rotation name")
        cols.append(name)
    if len(set(cols)) != len(cols):
        raise ConfigError(f"{path}:1: a column appears twice")
    if not any(c in ARKIT_SHAPES for c in cols):
        raise ConfigError(f"{path}:1: no ARKit blendshape columns")
    stamps, data = [], []
    for lineno, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise ConfigError(f"{path}:{lineno}: {len(row)} values, expected {len(header)} (file cut off?)")
        stamps.append(_timecode(path, lineno, row[0]))
        try:
            vals = [float(c) for c in row[1:]]
        except ValueError:
            raise ConfigError(f"{path}:{lineno}: expected numbers after the timecode") from None
        if not np.all(np.isfinite(vals)):
            raise ConfigError(f"{path}:{lineno}: a value is NaN or infinite")
        data.append(vals)
    if not data:
        raise ConfigError(f"{path}: no frames after the header")
    arr = np.array(data)
    max_ff = max(s[1] for s in stamps)
    rate = float(fps) if fps else _rate(stamps, max_ff)
    if max_ff >= rate:
        raise ConfigError(f"{path}: frame field {max_ff} does not fit --fps {rate:g}")
    times = np.array([(s + (ff + frac) / rate) for s, ff, frac in stamps])
    times -= times[0]
    check_times(str(path), times)
    shapes = {c: arr[:, j] for j, c in enumerate(cols) if c in ARKIT_SHAPES}
    for shape, col in shapes.items():
        if col.min() < -0.01 or col.max() > 1.01:
            raise ConfigError(f"{path}: blendshape {shape} leaves 0..1 (min {col.min():.3g}, max {col.max():.3g})")
    turns = {c: arr[:, j] for j, c in enumerate(cols) if c in ROTATIONS}
    values = shape_channels(shapes, len(arr), turns)
    ignored = [s for s in shapes if s in UNSUPPORTED and np.any(shapes[s] > 0.05)]
    notes = [f"ARKit timecodes read at {rate:g} fps"]
    if ignored:
        notes.append(f"shapes the face cannot express were ignored: {', '.join(ignored)}")
    return ChannelCapture(path, times, list(CHANNEL_NAMES), values, notes)
