"""Generated captures for the fit tests: landmark CSVs, and damaged variants of any text file."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return rz @ rx @ ry


def write_landmark_csv(path: Path, times: np.ndarray, points: np.ndarray, names: list[str]) -> None:
    """points (T, P, 3) under the given names, in the base form."""
    head = ["time"] + [f"{n}_{c}" for n in names for c in "xyz"]
    rows = [",".join(head)]
    for t, frame in zip(times, points):
        rows.append(",".join([f"{t:.6f}"] + [f"{x:.7g}" for x in frame.ravel()]))
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")


def damaged_texts(text: str, seed: int = 15) -> dict[str, str]:
    """Damaged variants of a CSV text: truncated mid-row, a column dropped from the header, a NaN,
    a word for a number, times going back, header only, random bytes."""
    rng = np.random.default_rng(seed)
    lines = text.splitlines()
    out = {"truncated": text[: int(len(text) * 0.6)].rsplit(",", 1)[0]}
    out["header_column_dropped"] = "\n".join([",".join(lines[0].split(",")[:-1])] + lines[1:])
    row = lines[2].split(",")
    row[int(rng.integers(1, len(row)))] = "nan"
    out["nan"] = "\n".join(lines[:2] + [",".join(row)] + lines[3:])
    row = lines[2].split(",")
    row[int(rng.integers(1, len(row)))] = "abc"
    out["word"] = "\n".join(lines[:2] + [",".join(row)] + lines[3:])
    out["header_only"] = lines[0] + "\n"
    out["empty"] = ""
    out["garbage"] = bytes(rng.integers(0, 256, 400, dtype=np.uint8)).decode("latin-1")
    return out


def correspond(model0, model1, vertices0: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """For each res-0 vertex, the nearest res-1 vertex at rest (landmarks map to landmarks)."""
    from scipy.spatial import cKDTree

    near = cKDTree(model1.rest).query(model0.rest[vertices0])[1]
    names0 = {int(v): n for n, v in model0.mesh.landmarks.items()}
    for i, v in enumerate(vertices0):
        if int(v) in names0:
            near[i] = model1.mesh.landmarks[names0[int(v)]]
    return near
