"""Captured motion in: tracked landmarks (CSV), motion-capture markers (C3D), point caches of the
rig's own topology (PC2 + OBJ), phone blendshape recordings (Live Link Face / ARKit CSV); the
displacement basis cache; takes and curves out. Every reader validates at the boundary and fails
with one `ConfigError` line naming the file (and line) and what to do.

`read_capture(path, face, correspondence=None)` picks the reader from the file's suffix and
content and returns a `PointCapture` (points over time, for `sim.fit`) or a `ChannelCapture`
(channel values over time, from blendshapes)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from puppet.capture.points import ChannelCapture, PointCapture, load_correspondence
from puppet.errors import ConfigError
from safefile import not_a_file

__all__ = ["ChannelCapture", "PointCapture", "is_arkit_csv", "load_correspondence", "read_capture"]


def _first_line(path: Path) -> str:
    try:
        with open(path, "rb") as fh:
            head = fh.readline(65536)
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the capture: {err.strerror}") from err
    return head.decode("utf-8", "replace").lstrip("\ufeff").strip()


def is_arkit_csv(path: Path) -> bool:
    """A Live Link Face / ARKit blendshape CSV (its header starts with Timecode), told from a
    landmark CSV by its first line."""
    return path.suffix.lower() == ".csv" and _first_line(path).lower().startswith("timecode")


#: --fps, the rate of a capture that stores none (PC2 samples, ARKit timecodes' frame field)
MIN_FPS, MAX_FPS = 1.0, 10000.0


def read_capture(path: str | Path, face: Any, correspondence: str | Path | None = None,
                 fps: float | None = None) -> PointCapture | ChannelCapture:
    """The capture in `path`, for the rig of `face` (a `puppet.live.Face`); fps: the rate of
    formats that store none (PC2; ARKit timecodes' frame field), default 60."""
    p = Path(path)
    if fps is not None and not MIN_FPS <= fps <= MAX_FPS:
        # --fps 1e-300 spread a point cache's samples over 1e300 s (the take's ticks filled the memory)
        raise ConfigError(f"--fps {fps:g}: expected {MIN_FPS:g}..{MAX_FPS:g} frames a second")
    why = not_a_file(p, "capture file")  # a pipe cannot be read twice (its format is told by its first line)
    if why:
        raise ConfigError(why)
    corr = load_correspondence(correspondence, face.model.mesh) if correspondence else None
    suffix = p.suffix.lower()
    if suffix == ".pc2":
        from puppet.capture.pc2file import read_pc2_capture

        return read_pc2_capture(p, face.model, fps or 60.0)
    if suffix == ".c3d":
        from puppet.capture.c3dfile import read_c3d

        return read_c3d(p, face.model.mesh, corr)
    if suffix == ".csv":
        if is_arkit_csv(p):
            from puppet.capture.arkit_in import read_arkit_csv

            return read_arkit_csv(p, fps)
        from puppet.capture.points import read_landmark_csv

        return read_landmark_csv(p, face.model.mesh, corr)
    raise ConfigError(f"{p}: unknown capture type {suffix!r}; expected a landmark or ARKit .csv, .c3d or .pc2")
