"""Bring an imported head's lips together at rest. A modelled head often leaves its lips apart
(MakeHuman's base mesh: the lower lip 2.5 mm below the upper and 5.7 mm behind it, in the rig's
frame); the reference face's lips meet at rest (1.2 mm apart at the middle, on a 5 cm mouth), and
its lip channels, the jaw and the presets part them. A head whose lips stand apart shows a dark
gap (or, with drawn teeth, a row of teeth) in every expression, the resting face included. The
two lips are moved towards each other along the line joining their middles, each taking half,
with the skin around them following (`lids.set_gap`), until they stand as far apart as the
reference's for the mouth's width."""

from __future__ import annotations

import dataclasses

import numpy as np

from sim.model import FaceMesh
from sim.face.transfer.eyes import lid_chains
from sim.face.transfer.lids import set_gap

FloatArray = np.ndarray
LIP_SHARE = 0.5  # of the closing made by the upper lip


def lip_gap(mesh: FaceMesh) -> FloatArray:
    """(3,) from the lower lip's middle (`lower_lip_center`) to the upper's (cm)."""
    return mesh.landmark("upper_lip_center") - mesh.landmark("lower_lip_center")


def mouth_width(mesh: FaceMesh) -> float:
    return float(np.linalg.norm(mesh.landmark("mouth_corner_l") - mesh.landmark("mouth_corner_r")))


def rest_lips(mesh: FaceMesh, reference: FaceMesh) -> tuple[FaceMesh, list[str]]:
    """The mesh with its lips brought to the reference's gap (scaled by the mouths' widths) when they
    stand farther apart than that; a note for the report when they were moved."""
    gap = lip_gap(mesh)
    now = float(np.linalg.norm(gap))
    want = float(np.linalg.norm(lip_gap(reference))) * mouth_width(mesh) / mouth_width(reference)
    if now <= want or len(mesh.mouth_loop) < 4:
        return mesh, []
    v = np.asarray(mesh.vertices, float)
    upper, lower = lid_chains(v, mesh.mouth_loop, mesh.landmark("mouth_corner_r"), mesh.landmark("mouth_corner_l"))
    moved = set_gap(v, upper, lower, want, gap / now, upper_share=LIP_SHARE)
    out = dataclasses.replace(mesh, vertices=moved)
    return out, [f"the lips stood {now:.2f} cm apart at rest; brought to {float(np.linalg.norm(lip_gap(out))):.2f} "
                 f"(the reference's {want:.2f} for this mouth)"]
