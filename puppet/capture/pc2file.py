"""A PC2 point cache of the rig's own topology (e.g. `puppet replay --out take.pc2`, another take,
another integrator), with the rest-pose OBJ beside it (same name, .obj) that says the vertex order.

The OBJ must have the rig's vertex count (and, if it lists faces, the rig's triangles); the cache
is compared with the rig's settled rest (not with its first frame), after a similarity. On the
scanned head a cache may also hold the whole scan (26,719 points in the scan's order, as `puppet
replay --out take.pc2` writes it): its simulated skin's vertices are picked out of it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from puppet.capture.points import PointCapture
from puppet.errors import ConfigError


def _obj(path: Path) -> tuple[int, np.ndarray | None]:
    from safefile import BadFile, read_bytes

    try:  # the scan's rest OBJ is under 2 MB
        text = read_bytes(path, "OBJ beside the point cache", 256 * 1024 * 1024).decode("utf-8", "replace")
    except BadFile as err:
        raise ConfigError(str(err)) from err
    nv = 0
    faces = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            try:
                xyz = [float(x) for x in parts[1:4]]
            except ValueError:
                raise ConfigError(f"{path}:{lineno}: a vertex needs three numbers") from None
            if len(xyz) != 3 or not np.all(np.isfinite(xyz)):
                raise ConfigError(f"{path}:{lineno}: a vertex needs three finite numbers")
            nv += 1
        elif parts[0] == "f":
            try:
                idx = [int(p.split("/")[0]) - 1 for p in parts[1:]]
            except ValueError:
                raise ConfigError(f"{path}:{lineno}: a face needs vertex numbers") from None
            if len(idx) != 3:
                return nv, None  # polygons: not our triangulation; the vertex count still checks order
            faces.append(idx)
    return nv, (np.array(faces) if faces else None)


class _ScanSkin:
    """The simulated skin's place in the whole scan: `index` (N,) scan index of each simulated vertex."""

    def __init__(self, scan: np.ndarray, index: np.ndarray) -> None:
        self.scan, self.index = scan, index


def _scan_skin(model: Any, points: int) -> _ScanSkin | None:
    """On the scanned head, a cache of the whole scan's points (None: the rig's own topology)."""
    if points == model.n_vertices:
        return None
    from puppet.export.scan import scan_dressing

    dressing = scan_dressing(model)
    if dressing is None or points != len(dressing.rest):
        return None
    return _ScanSkin(dressing.rest, np.asarray(dressing.skin))


def read_pc2_capture(path: Path, model: Any, fps: float = 60.0) -> PointCapture:
    """PC2 stores no rate: sample k is at k * sampling / fps seconds."""
    from puppet.export.pc2 import read_pc2

    obj = path.with_suffix(".obj")
    if not obj.is_file():
        raise ConfigError(f"{path}: needs its rest-pose OBJ beside it ({obj.name}) to check the vertex order")
    head, frames = read_pc2(path)
    n = model.n_vertices
    skin = _scan_skin(model, int(head["num_points"]))
    if head["num_points"] != n and skin is None:
        raise ConfigError(f"{path}: {head['num_points']} points, but the rig has {n} vertices; a point cache "
                          "must have the rig's topology (a take's cache: --face or --rig as it was recorded; "
                          "a landmark CSV for other meshes)")
    nv, faces = _obj(obj)
    if skin is not None:  # the whole scan, as the scanned head's exports write it: its faces are quads
        if nv != len(skin.scan):
            raise ConfigError(f"{obj}: {nv} vertices, but the scanned head has {len(skin.scan)}; not the scan's "
                              "topology")
    elif nv != n:
        raise ConfigError(f"{obj}: {nv} vertices, but the rig has {n}; not the rig's topology")
    elif faces is not None and (faces.shape != model.triangles.shape or not np.array_equal(faces, model.triangles)):
        raise ConfigError(f"{obj}: its faces are not the rig's triangles; not the rig's topology")
    if head["num_samples"] < 1:
        raise ConfigError(f"{path}: the point cache has no samples")
    pts = (frames if skin is None else frames[:, skin.index]).astype(np.float64)
    if not np.all(np.isfinite(pts)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(pts), axis=(1, 2)))[0])
        raise ConfigError(f"{path}: sample {bad} holds NaN or infinite coordinates")
    sampling = float(head["sampling"]) or 1.0
    if not (np.isfinite(sampling) and sampling > 0):
        raise ConfigError(f"{path}: the sampling field {head['sampling']!r} must be positive")
    return PointCapture(path, np.arange(len(pts)) * sampling / fps, pts, [f"v{i}" for i in range(n)],
                        np.arange(n), None, [f"PC2 samples read at {fps:g} frames per second (--fps)"])
