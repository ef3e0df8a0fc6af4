"""Motion-capture markers from a C3D file, read with the `c3d` library (pip `c3d`).

Marker labels are rig landmark names, or any labels with a correspondence file. Occluded samples
(the C3D residual is negative) are filled by linear interpolation between the marker's valid
samples, and the report says how many; a marker never seen is an error."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from puppet.capture.points import PointCapture, resolve_names
from puppet.errors import ConfigError


def _read(path: Path) -> tuple[list[str], float, np.ndarray, np.ndarray]:
    try:
        import c3d
    except ImportError as err:
        raise ConfigError(f"{path}: reading C3D needs the 'c3d' package: pip install c3d") from err
    import warnings

    try:
        with open(path, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "No analog data found": markers are all we read
            reader = c3d.Reader(fh)
            labels = [str(s).strip() for s in reader.point_labels]
            rate = float(reader.point_rate)
            frames = []
            for _, points, _analog in reader.read_frames():
                frames.append(np.array(points[:, :4], dtype=np.float64))
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the C3D file: {err.strerror or err}") from err
    except Exception as err:  # the library signals damaged files with many exception types
        raise ConfigError(f"{path}: not a readable C3D file ({type(err).__name__}: {err})"[:200]) from err
    if not frames:
        raise ConfigError(f"{path}: the C3D file has no frames")
    arr = np.stack(frames)
    if arr.shape[1] != len(labels):
        raise ConfigError(f"{path}: {arr.shape[1]} markers but {len(labels)} labels; the file is damaged")
    if not (np.isfinite(rate) and rate > 0):
        raise ConfigError(f"{path}: the C3D point rate {rate!r} is not a positive number")
    return labels, rate, arr[:, :, :3], arr[:, :, 3]


def read_c3d(path: Path, mesh: Any, corr: dict[str, int] | None = None) -> PointCapture:
    labels, rate, xyz, resid = _read(path)
    if len(set(labels)) != len(labels):
        raise ConfigError(f"{path}: two markers have the same label")
    notes: list[str] = []
    keep, verts = resolve_names(str(path), labels, mesh, corr, notes)
    xyz, resid = xyz[:, keep, :], resid[:, keep]
    valid = (resid >= 0) & np.all(np.isfinite(xyz), axis=2)
    frames = np.arange(len(xyz))
    filled = 0
    for j in range(xyz.shape[1]):
        ok = valid[:, j]
        if not ok.any():
            raise ConfigError(f"{path}: marker {labels[keep[j]]!r} has no valid sample; drop it from the "
                              "correspondence or fix the capture")
        if not ok.all():
            filled += int((~ok).sum())
            for c in range(3):
                xyz[~ok, j, c] = np.interp(frames[~ok], frames[ok], xyz[ok, j, c])
    if filled:
        notes.append(f"{filled} occluded marker samples filled by interpolation")
    times = frames / rate
    return PointCapture(path, times, xyz, [labels[i] for i in keep], verts, 0, notes)
