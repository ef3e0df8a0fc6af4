"""Exports of the scanned head keep the scan's own vertices: 26,719 in the scan's order (the ICT
FaceKit's topology, so a take drops onto ICT-topology assets), its quads and triangles as the scan
has them, posed each frame by the face's dressing from the simulated surface, jaw and eyes, with
the lids laid back onto the eyeballs where a closing margin sank into the cornea, as the drawing
lays them (sim.face.scan.lid_contact; the simulation's surface itself is not changed)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from puppet.errors import ConfigError


def scan_dressing(model: Any) -> Any:
    """The scan dressing of a face model (sim.face.scan.dressing), or None for any other face."""
    rig = getattr(model, "rig", None)
    if rig is None or not str(getattr(rig, "name", "")).startswith("ict"):
        return None  # only the scanned head's rigs are named so (sim.face.scan.rig.scan_rig)
    from sim.face.scan.dressing import dressing_for

    return dressing_for(model)


def posed(dressing: Any, state: Any) -> np.ndarray:
    """(26719, 3) float32: the whole scan posed to a state as it is drawn: the lids that sank into
    the eyeballs laid back onto them (sim.face.scan.lid_contact), the head turned on the neck."""
    from sim.face.scan.blendshapes import StateControl

    return dressing.pose_exported(np.asarray(state.surface), StateControl(state), state)


def write_scan_obj(path: str | Path, vertices: np.ndarray, comment: str = "") -> None:
    """An OBJ of the scan: `vertices` (26719, 3) in the scan's order, then its faces (quads and
    triangles, 1-based, in the scan's order); no normals or UVs, so no importer splits vertices."""
    lines = [f"# {c}" for c in comment.splitlines()] if comment else []
    try:
        Path(path).write_text("".join(line + "\n" for line in lines) + _scan_obj_body(vertices), encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot write the mesh: {err.strerror}") from err


_bodies: dict[bytes, str] = {}  # the OBJ's vertex and face lines by the vertices' digest (a batch
# worker writes the same rest mesh beside every take's point cache: formatting it takes ~0.25 s)


def _scan_obj_body(vertices: np.ndarray) -> str:
    import hashlib

    from sim.face.scan.data import scan_data

    v = np.ascontiguousarray(vertices, dtype=np.float64)
    key = hashlib.sha256(v.tobytes()).digest()
    body = _bodies.get(key)
    if body is None:
        lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in v]
        for f in scan_data().faces + 1:
            lines.append("f " + " ".join(str(int(i)) for i in f if i > 0))
        body = "\n".join(lines) + "\n"
        if len(_bodies) >= 2:
            _bodies.clear()
        _bodies[key] = body
    return body
