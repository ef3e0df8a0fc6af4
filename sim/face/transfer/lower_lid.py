"""Place the lower lid's tightener (AU7, `orbicularis_oculi_lower_lid_<side>`) on an imported head's
own lower lid.

The tightener is a small push (a patch a few millimetres high) under the lower lid's margin, so it
must sit where the head's lid is, not where the skin correspondence carries the reference's: on a
head of other proportions, or one whose lids were parted or brought to a resting opening after the
correspondence was made (`lids.open_lids`, `eyes.seat_eyes`), the carried patch landed up to 7 mm
to the side of the lid's middle and lifted the margin 0.9-2.1 mm where the reference's lifts its
own 2.3 mm (placed: 1.8-2.7 mm; the third-party heads of docs/import-face.md). Here
the reference's patch is measured against its own lower margin (the centre's offset from the
margin's point midway between the corners, in units of the eye's width) and rebuilt so on the new
head's margin: the same offset and semi-axes scaled by the new eye's width, the same push and
force (a later `forces.match_forces` scales it like any channel)."""

from __future__ import annotations

import dataclasses

import numpy as np

from sim.model import FaceMesh, FaceRig, Muscle, PatchMuscle
from sim.face.transfer.eyes import margin_point, mesh_lids

FloatArray = np.ndarray
CHANNEL = "orbicularis_oculi_lower_lid_{side}"
SIDES = ("l", "r")  # the order of FaceMesh.eye_loops
FRONTAL = np.array([1.0, 1.0, 0.0])  # a direction's part in the face's plane (the face looks along +Z)


def _anchor(mesh: FaceMesh, k: int, side: str) -> tuple[FloatArray, float]:
    """The lower margin's point midway between the eye's corners as seen from the front, and the
    eye's width (cm)."""
    inner, outer = mesh.landmark(f"eye_inner_{side}"), mesh.landmark(f"eye_outer_{side}")
    v = np.asarray(mesh.vertices, float)
    _, lower = mesh_lids(mesh, k)
    a = v[lower[0]]
    # the corners' axis seen from the front (along the 3D axis, a margin bulging forward in its
    # middle put the reference's halfway point 3.5 mm towards the outer corner)
    across = (v[lower[-1]] - a) * FRONTAL
    return margin_point(v, lower, a, across, 0.5), float(np.linalg.norm(outer - inner))


def place_lower_lids(reference: FaceRig, mesh: FaceMesh,
                     muscles: dict[str, tuple[Muscle, ...]]) -> tuple[dict[str, tuple[Muscle, ...]], list[str]]:
    """`muscles` (carried onto `mesh`) with each side's lower lid tightener placed on the head's own
    lower lid as the reference's sits on its lid; and a line per side saying how far it moved. A
    channel the reference lacks, or one not made of a single patch, is left as carried."""
    out = dict(muscles)
    notes: list[str] = []
    ref = reference.mesh
    if len(ref.eye_loops) < 2 or len(mesh.eye_loops) < 2:
        return out, notes
    for k, side in enumerate(SIDES):
        name = CHANNEL.format(side=side)
        own, carried = reference.muscles.get(name, ()), out.get(name, ())
        if len(own) != 1 or len(carried) != 1 or not isinstance(own[0], PatchMuscle):
            continue
        ref_anchor, ref_width = _anchor(ref, k, side)
        new_anchor, new_width = _anchor(mesh, k, side)
        scale = new_width / ref_width
        centre = new_anchor + scale * (np.asarray(own[0].center, float) - ref_anchor)
        out[name] = (dataclasses.replace(carried[0], center=np.round(centre, 7),
                                         semi_axes=np.round(scale * np.asarray(own[0].semi_axes, float), 7)),)
        moved = float(np.linalg.norm(centre - np.asarray(carried[0].center, float)))
        notes.append(f"{name} placed on the head's own lower lid ({10 * moved:.1f} mm from where the skin "
                     "correspondence carried it)")
    return out, notes
