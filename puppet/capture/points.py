"""Tracked points: the landmark CSV and the correspondence file.

Landmark CSV (the base form): a header `time` then `NAME_x,NAME_y,NAME_z` per point, one row per
frame, times in seconds, strictly increasing. NAME is a landmark of the rig vocabulary
(`sim.face.transfer.landmarks.LANDMARK_NAMES`, e.g. `nose_tip`) or `v<index>` for a rig vertex; any
subset of at least 4 points; any units and frame (the fit removes scale and rigid motion).

With a correspondence file the names are the input's own (MediaPipe indices, 68-point numbers,
marker labels) and the file says which rig point each one is:

    {"layout": "ibug-68", "points": {"30": "nose_tip", "48": "mouth_corner_r", ...}}

Input points the correspondence does not name are ignored; a name it lists that the input lacks
is an error.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from puppet.errors import ConfigError
from safefile import few, load_json, quote, read_text

MIN_POINTS = 4
_VERTEX = re.compile(r"v(\d+)")


@dataclass
class PointCapture:
    """times (T,) s; points (T, P, 3) as given; names (P,) the input's names; vertices (P,) rig
    vertex per point; neutral: the frame at rest, or None for the rig's own skin; notes: what
    the reader had to do (gaps filled, points ignored), for the report."""

    path: Path
    times: np.ndarray
    points: np.ndarray
    names: list[str]
    vertices: np.ndarray
    neutral: int | None = 0
    notes: list[str] = field(default_factory=list)


@dataclass
class ChannelCapture:
    """times (T,) s and channel values (T, C) in `channels` order, from a blendshape recording."""

    path: Path
    times: np.ndarray
    channels: list[str]
    values: np.ndarray
    notes: list[str] = field(default_factory=list)


def rig_point(name: str, mesh: Any) -> int | None:
    """The rig vertex a point name stands for (a landmark name or v<index>), or None."""
    if name in mesh.landmarks:
        return int(mesh.landmarks[name])
    m = _VERTEX.fullmatch(name)
    if m and int(m.group(1)) < len(mesh.vertices):
        return int(m.group(1))
    return None


def _unknown(where: str, name: str, mesh: Any) -> ConfigError:
    some = ", ".join(sorted(mesh.landmarks)[:6])
    return ConfigError(f"{where}: {quote(name)} is not a rig landmark ({some}, ...; docs/fit.md lists them) "
                       f"nor a vertex v0..v{len(mesh.vertices) - 1}; use a correspondence file (--map) "
                       "for other layouts")


def load_correspondence(path: str | Path, mesh: Any) -> dict[str, int]:
    """input point name -> rig vertex, from a correspondence JSON file, or one shipped in
    puppet/capture/layouts/ named by its stem (`mediapipe`, `ibug68`)."""
    p = Path(path)
    shipped = Path(__file__).parent / "layouts" / f"{p.name}.json"
    if not p.exists() and p.parent == Path(".") and shipped.is_file():
        p = shipped
    data = load_json(read_text(p, "correspondence file", 16 << 20), str(p), "correspondence file")
    if isinstance(data, dict) and "points" in data:
        extra = set(data) - {"points", "layout", "comment"}
        if extra:
            raise ConfigError(f"{p}: unknown key(s) {few([quote(k) for k in sorted(extra)])}; expected layout, "
                              "points, comment")
        data = data["points"]
    if not isinstance(data, dict) or not data:
        raise ConfigError(f"{p}: expected {{\"points\": {{\"INPUT_NAME\": \"rig_landmark\", ...}}}}")
    out: dict[str, int] = {}
    used: dict[int, str] = {}
    for key, value in data.items():
        if not isinstance(value, str):
            raise ConfigError(f"{p}: point {quote(key)} must name a rig landmark (a string), got {quote(value)}")
        v = rig_point(value, mesh)
        if v is None:
            raise _unknown(f"{p}: point {quote(key)}", value, mesh)
        if v in used:
            raise ConfigError(f"{p}: points {quote(used[v])} and {quote(key)} both map to {quote(value)}; map each "
                              "rig point once")
        used[v] = key
        out[str(key)] = v
    if len(out) < MIN_POINTS:
        raise ConfigError(f"{p}: maps {len(out)} points; at least {MIN_POINTS} are needed")
    return out


def resolve_names(where: str, names: list[str], mesh: Any, corr: dict[str, int] | None,
                  notes: list[str]) -> tuple[list[int], np.ndarray]:
    """(positions in `names` to keep, rig vertex of each kept one)."""
    keep: list[int] = []
    verts: list[int] = []
    if corr is None:
        for i, n in enumerate(names):
            v = rig_point(n, mesh)
            if v is None:
                raise _unknown(where, n, mesh)
            keep.append(i)
            verts.append(v)
        if len(set(verts)) != len(verts):
            raise ConfigError(f"{where}: the same rig point appears twice")
    else:
        index = {n: i for i, n in enumerate(names)}
        missing = [k for k in corr if k not in index]
        if missing:
            raise ConfigError(f"{where}: the correspondence names point(s) {', '.join(missing[:5])} that the "
                              "input does not have; check the layout or the correspondence file")
        for k, v in corr.items():
            keep.append(index[k])
            verts.append(v)
        ignored = len(names) - len(keep)
        if ignored:
            notes.append(f"{ignored} input points not in the correspondence were ignored")
    if len(keep) < MIN_POINTS:
        raise ConfigError(f"{where}: {len(keep)} points; at least {MIN_POINTS} are needed")
    return keep, np.array(verts, dtype=np.int64)


def check_times(where: str, times: np.ndarray) -> None:
    bad = np.flatnonzero(np.diff(times) <= 0)
    if len(bad):
        raise ConfigError(f"{where}: times must increase from frame to frame (frame {bad[0] + 1} to {bad[0] + 2})")


def csv_rows(path: Path, text: str, what: str) -> list[list[str]]:
    """The rows of a capture's CSV text; what the csv module refuses (a cell beyond its 128 KiB
    limit, a NUL) is one line naming the file and line."""
    reader = csv.reader(text.splitlines())
    try:
        return list(reader)
    except csv.Error as err:
        raise ConfigError(f"{path}: line {reader.line_num}: not a readable {what} ({err})") from err


#: a capture CSV's bytes (468 tracked points at 60 fps are about 90 MB a minute) and its header's
MAX_CSV_BYTES = 1024 * 1024 * 1024
MAX_CSV_HEADER = 4 * 1024 * 1024


def read_csv_text(path: Path, what: str) -> str:
    """A capture CSV's text, read with bounds: a file over `MAX_CSV_BYTES`, or whose first line runs
    on past `MAX_CSV_HEADER` (/dev/zero, a video, a file of one endless line), is one line naming
    it after reading that much at most (a 3 GB file was read whole: a MemoryError traceback)."""
    from safefile import BadFile, open_to_read, read_bytes

    try:
        with open_to_read(path, what) as fh:
            first = fh.readline(MAX_CSV_HEADER + 1)
        if len(first) > MAX_CSV_HEADER and not first.endswith(b"\n"):
            raise ConfigError(f"{path}:1: not a {what} (its first line runs on past "
                              f"{MAX_CSV_HEADER // (1024 * 1024)} MB; is it the right file?)")
        data = read_bytes(path, what, MAX_CSV_BYTES)
    except BadFile as err:
        raise ConfigError(str(err)) from err
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        raise ConfigError(f"{path}:{line}: the {what} is not UTF-8 text") from err


def read_landmark_csv(path: Path, mesh: Any, corr: dict[str, int] | None = None) -> PointCapture:
    """The landmark CSV (module docstring)."""
    rows = csv_rows(path, read_csv_text(path, "landmark CSV"), "landmark CSV")
    if not rows or not rows[0]:
        raise ConfigError(f"{path}:1: empty file; expected a header 'time,NAME_x,NAME_y,NAME_z,...'")
    header = [h.strip() for h in rows[0]]
    if header[0].lower() != "time" or (len(header) - 1) % 3 or len(header) < 4:
        raise ConfigError(f"{path}:1: expected a header 'time' then NAME_x,NAME_y,NAME_z per point")
    names = []
    for j in range(1, len(header), 3):
        stem = header[j][:-2]
        if [header[j], header[j + 1], header[j + 2]] != [stem + "_x", stem + "_y", stem + "_z"] or not stem:
            raise ConfigError(f"{path}:1: columns {j + 1}-{j + 3} must be NAME_x,NAME_y,NAME_z, got "
                              f"{quote(','.join(header[j:j + 3]))}")
        names.append(stem)
    if len(set(names)) != len(names):
        raise ConfigError(f"{path}:1: a point appears twice in the header")
    notes: list[str] = []
    keep, verts = resolve_names(f"{path}:1", names, mesh, corr, notes)
    data = []
    for lineno, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise ConfigError(f"{path}:{lineno}: {len(row)} values, expected {len(header)} (file cut off or "
                              "columns missing?)")
        try:
            vals = [float(c) for c in row]
        except ValueError:
            raise ConfigError(f"{path}:{lineno}: expected numbers, got {','.join(row)[:60]!r}") from None
        if not np.all(np.isfinite(vals)):
            raise ConfigError(f"{path}:{lineno}: a value is NaN or infinite; remove the frame or fill the gap")
        data.append(vals)
    if not data:
        raise ConfigError(f"{path}: no frames after the header")
    arr = np.array(data)
    times = arr[:, 0]
    check_times(str(path), times)
    pts = arr[:, 1:].reshape(len(arr), -1, 3)[:, keep, :]
    return PointCapture(path, times, pts, [names[i] for i in keep], verts, 0, notes)
