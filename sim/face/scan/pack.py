"""Packs the ICT FaceKit's light model into the compact file this package ships (`ict_head.npz`).

Run by a maintainer when the source changes, never at run time:
`python -m sim.face.scan.pack PATH/TO/ict_facekit.npz`. What is kept, and how:

- `neutral` (26719, 3) float32, cm: the generic neutral head, every part, the scan's vertex order.
- `faces` (26384, 4) int16 and `faces_uv` (26384, 4) int16: quads and triangles (4th index -1).
- `uv` (28911, 2) float32: texture coordinates.
- `expressions` (57, 26719, 3) float16 and `expression_names`: deltas from `neutral` (cm); float16
  keeps 0.01 mm at the largest (3.5 cm) delta.
- `identities` (100, 26719, 3) int8 with `identity_scale` (100,) float32: identity modes as deltas
  (cm) = int8 * scale; one step is at most 0.11 mm (the largest mode reaches 1.33 cm).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from safefile import atomic_write

OUT = Path(__file__).with_name("ict_head.npz")


def pack(src: Path, out: Path = OUT) -> None:
    d = np.load(src, allow_pickle=False)
    ident = d["identities"].astype(np.float64)
    scale = np.abs(ident).max(axis=(1, 2)) / 127.0
    q = np.round(ident / scale[:, None, None]).astype(np.int8)
    arrays = {
        "neutral": d["neutral"].astype(np.float32),
        "faces": d["faces_v"].astype(np.int16),
        "faces_uv": d["faces_uv"].astype(np.int16),
        "uv": d["uv"].astype(np.float32),
        "expressions": d["expressions"].astype(np.float16),
        "expression_names": d["expression_names"].astype(str),
        "identities": q,
        "identity_scale": scale.astype(np.float32),
    }

    with atomic_write(out, "wb") as fh:
        np.savez_compressed(fh, **arrays)


if __name__ == "__main__":
    pack(Path(sys.argv[1]))
