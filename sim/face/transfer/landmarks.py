"""The landmark vocabulary and the landmark file: JSON mapping landmark name -> vertex index
(0-based, in the mesh file's vertex order) or a 3D point in the mesh file's own units.

Accepted shapes:
    {"nose_tip": 812, "chin": [0.1, -7.9, 9.2], ...}
    {"landmarks": {...}, "openings": {"eye_l": [...], "eye_r": [...], "mouth": [...]}}
`openings` (optional) names closed vertex loops around the eye and mouth openings, for meshes
whose holes cannot be found automatically.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from safefile import BadFile, few, load_json, quote, read_text

# `_l` / `_r` are the face's own left and right.
LANDMARK_NAMES: tuple[str, ...] = (
    "brow_inner_l", "brow_inner_r", "brow_mid_l", "brow_mid_r", "brow_outer_l", "brow_outer_r",
    "glabella", "forehead_center",
    "eye_inner_l", "eye_inner_r", "eye_outer_l", "eye_outer_r",
    "upper_lid_l", "upper_lid_r", "lower_lid_l", "lower_lid_r",
    "nose_bridge", "nose_tip", "nose_wing_l", "nose_wing_r", "subnasale",
    "upper_lip_top", "upper_lip_center", "lower_lip_center", "lower_lip_bottom",
    "mouth_corner_l", "mouth_corner_r",
    "cheek_l", "cheek_r", "chin", "jaw_angle_l", "jaw_angle_r",
)

# Left/right pairs: their differences give the face's left direction.
SIDE_PAIRS: tuple[tuple[str, str], ...] = tuple(
    (n, n[:-2] + "_r") for n in LANDMARK_NAMES if n.endswith("_l")
)

EYE_LANDMARKS = {
    "eye_l": ("eye_inner_l", "eye_outer_l", "upper_lid_l", "lower_lid_l"),
    "eye_r": ("eye_inner_r", "eye_outer_r", "upper_lid_r", "lower_lid_r"),
}
MOUTH_LANDMARKS = ("mouth_corner_l", "mouth_corner_r", "upper_lip_center", "lower_lip_center")
OPENING_NAMES = ("eye_l", "eye_r", "mouth")
MAX_INDEX = 100_000_000
MAX_COORD = 1e9
MAX_LOOP = 100_000


class TransferError(ValueError):
    """The mesh or landmark file cannot be used for a transfer; the message is one line that names
    the file and says what to fix (the command line turns it into a ConfigError)."""


@dataclass
class LandmarkFile:
    """A parsed landmark file: name -> vertex index (int) or point (3,) and declared openings."""

    path: str
    entries: dict[str, int | np.ndarray]
    openings: dict[str, np.ndarray] = field(default_factory=dict)


def _entry(path: str, name: str, value: object) -> int | np.ndarray:
    if isinstance(value, bool):
        raise TransferError(f"{path}: landmark {name!r} must be a vertex index or [x, y, z]")
    if isinstance(value, int):
        if not 0 <= value <= MAX_INDEX:
            raise TransferError(f"{path}: landmark {quote(name)} is vertex {quote(value)}; indices are 0-based "
                                "vertex numbers of the mesh file")
        return value
    if isinstance(value, list) and len(value) == 3 and all(
        isinstance(c, (int, float)) and not isinstance(c, bool) and abs(c) <= MAX_COORD for c in value
    ):
        point = np.asarray(value, float)
        if np.isfinite(point).all():
            return point
    raise TransferError(f"{path}: landmark {quote(name)} must be a vertex index or [x, y, z], got {quote(value)}")


def parse_landmarks(data: object, path: str = "<landmarks>") -> LandmarkFile:
    """Validate the JSON value of a landmark file (names known, values well formed)."""
    if not isinstance(data, dict):
        raise TransferError(f"{path}: expected a JSON object of landmark name -> index or point")
    openings_raw = {}
    if "landmarks" in data:
        unknown_keys = set(data) - {"landmarks", "openings", "comment"}
        if unknown_keys:
            raise TransferError(f"{path}: unknown key(s) {few(sorted(map(str, unknown_keys)))}; expected "
                                "'landmarks' and optionally 'openings'")
        openings_raw = data.get("openings", {}) or {}
        data = data["landmarks"]
        if not isinstance(data, dict):
            raise TransferError(f"{path}: 'landmarks' must be an object of name -> index or point")
    unknown = sorted(set(data) - set(LANDMARK_NAMES))
    if unknown:
        raise TransferError(f"{path}: unknown landmark(s) {few(unknown)}; the vocabulary is "
                            "documented in docs/import-face.md")
    entries = {name: _entry(path, name, value) for name, value in data.items()}
    if not isinstance(openings_raw, dict):
        raise TransferError(f"{path}: 'openings' must map eye_l/eye_r/mouth to vertex loops")
    openings: dict[str, np.ndarray] = {}
    for name, loop in openings_raw.items():
        if name not in OPENING_NAMES:
            raise TransferError(f"{path}: unknown opening {quote(name)}; expected one of {OPENING_NAMES}")
        if not (isinstance(loop, list) and 3 <= len(loop) <= MAX_LOOP and all(
            isinstance(i, int) and not isinstance(i, bool) and 0 <= i <= MAX_INDEX for i in loop
        )):
            raise TransferError(f"{path}: opening {name!r} must be a list of at least 3 vertex indices")
        openings[name] = np.asarray(loop, dtype=np.int64)
    return LandmarkFile(path, entries, openings)


def read_landmarks(path: str | Path) -> LandmarkFile:
    """Read and validate a landmark JSON file (errors name the file)."""
    path = str(path)
    try:
        data = load_json(read_text(path, "landmark file", 16 * 1024 * 1024), path, "landmark file")
    except BadFile as err:
        raise TransferError(str(err)) from err
    return parse_landmarks(data, path)


def require(lf: LandmarkFile, names: tuple[str, ...] | list[str]) -> None:
    """Fail naming every required landmark the file lacks."""
    missing = [n for n in names if n not in lf.entries]
    if missing:
        raise TransferError(f"{lf.path}: missing landmark(s) {few(missing)} (docs/import-face.md lists them)")
