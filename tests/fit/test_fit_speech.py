"""`puppet fit` of a Live Link Face take saying "oo", "ee" and "m", replayed to a point cache: on the
settled skin the lips round and come forward for "oo", spread for "ee" and close for "m"."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from puppet.cli import main
from puppet.export.arkit import ARKIT_SHAPES, ROTATIONS, timecode
from puppet.export.pc2 import read_pc2

FPS = 30
HOLD = 24  # frames per viseme (0.8 s: the skin settles)
#: ARKit weights of the kind Live Link Face records for each sound (a still mouth, rounded "oo" with
#: the lips funnelled and puckered, spread "ee", closed "m" with the lips pressed).
VISEMES = {
    "rest": {},
    "oo": {"JawOpen": 0.12, "MouthFunnel": 0.71, "MouthPucker": 0.55},
    "ee": {"JawOpen": 0.1, "MouthStretchLeft": 0.45, "MouthStretchRight": 0.45, "MouthSmileLeft": 0.35,
           "MouthSmileRight": 0.35},
    "m": {"JawOpen": 0.08, "MouthClose": 0.1, "MouthPressLeft": 0.35, "MouthPressRight": 0.35,
          "MouthRollLower": 0.15},
}


def _write_take(path: Path) -> None:
    lines = [",".join(["Timecode", "BlendShapeCount", *ARKIT_SHAPES, *ROTATIONS])]
    frame = 0
    for weights in VISEMES.values():
        for _ in range(HOLD):
            row = [weights.get(s, 0.0) for s in ARKIT_SHAPES] + [0.0] * len(ROTATIONS)
            lines.append(",".join([timecode(frame, FPS), "61", *(f"{v:.3f}" for v in row)]))
            frame += 1
    path.write_text("\n".join(lines) + "\n")


def test_vowels_and_m_read_on_the_settled_lips(tmp_path: Path) -> None:
    from sim.face import default_model

    csv = tmp_path / "vowels.csv"
    _write_take(csv)
    take, pc2 = tmp_path / "vowels.jsonl", tmp_path / "vowels.pc2"
    assert main(["fit", str(csv), "--out", str(take)]) == 0
    assert main(["replay", str(take), "--out", str(pc2)]) == 0
    _, frames = read_pc2(pc2)
    model = next(m for m in (default_model(r) for r in (0, 1, 2)) if len(m.rest) == frames.shape[1])
    lm = model.mesh.landmarks
    at = {name: frames[min(len(frames) - 1, round((k + 1) * HOLD / FPS * 60) - 2)].astype(float)
          for k, name in enumerate(VISEMES)}  # the end of each hold, at the replay's 60 frames a second

    def width(p: np.ndarray) -> float:
        return float(np.linalg.norm(p[lm["mouth_corner_l"]] - p[lm["mouth_corner_r"]]))

    def gap(p: np.ndarray) -> float:
        return float(p[lm["upper_lip_center"], 1] - p[lm["lower_lip_center"], 1])

    rest = at["rest"]
    assert width(at["oo"]) < width(rest) - 0.4  # rounded: at least 4 mm narrower
    assert at["oo"][lm["upper_lip_center"], 2] > rest[lm["upper_lip_center"], 2] + 0.2  # and forward
    assert width(at["ee"]) > width(rest) + 0.2  # spread
    assert width(at["ee"]) - width(at["oo"]) > 0.8
    assert gap(at["m"]) < gap(rest) + 0.1  # the lips closed over the slightly open jaw
    assert gap(at["oo"]) > gap(at["m"]) + 0.1  # ... where the "oo" keeps them apart
