"""Bring an imported head's lips together at rest. A modelled head often leaves its lips apart
(MakeHuman's base mesh: the lower lip 2.5 mm below the upper and 5.7 mm behind it, in the rig's
frame); the reference face's lips meet at rest (1.2 mm apart at the middle, on a 5 cm mouth), and
its lip channels, the jaw and the presets part them. A head whose lips stand apart shows a dark
gap (or, with drawn teeth, a row of teeth) in every expression, the resting face included. The
two lips are moved towards each other along the line joining their middles, each taking half,
with the skin around them following (`lids.set_gap`), until they stand as far apart as the
reference's for the mouth's width. Then, seen from the front, each column of the mouth from corner
to corner is closed to the reference's gap there (`seen_gaps`, scaled by the mouths' widths; only
closing): the middle alone, brought together along a line that runs mostly in depth (the lower
lip behind the upper) with the modelled shape kept, left MakeHuman's lips 2.5 mm apart half way to
the corners (the reference's 1 mm) and a row of teeth showed there in every pose. Only for lips
modelled apart (more than PARTED x the reference's gap): closed so on a scan whose lips meet, the
scanned head's identity lost its sadness (read as neutral) and, with its lids shut, its anger and
disgust."""

from __future__ import annotations

import dataclasses

import numpy as np

from sim.model import FaceMesh
from sim.face.transfer.eyes import lid_chains
from sim.face.transfer.lids import set_gap

FloatArray = np.ndarray
LIP_SHARE = 0.5  # of the closing made by the upper lip
PARTED = 2.0  # lips further apart than this x the reference's gap were modelled apart (MakeHuman's
# 4.8 x); a scan's lips that meet, their landmarks a hair off the rims (1.7 x on the scanned head's
# identity), are only brought to the reference's gap at the middle
OPEN_AT_REST = 0.2  # of the mouth's width: lips further apart than this stand open at rest (a jaw
# dropped in the file: 0.40 on the scanned identity with jawOpen at 0.6; MakeHuman's modelled gap 0.12)
MOST_CLOSING = 0.6  # rad: the furthest the jaw is turned shut at rest
COLUMNS = 21  # points from corner to corner at which the gap seen from the front is compared
UP = np.array([0.0, 1.0, 0.0])


def lip_gap(mesh: FaceMesh) -> FloatArray:
    """(3,) from the lower lip's middle (`lower_lip_center`) to the upper's (cm)."""
    return mesh.landmark("upper_lip_center") - mesh.landmark("lower_lip_center")


def seen_gaps(mesh: FaceMesh, columns: int = COLUMNS) -> tuple[float, FloatArray]:
    """(the lips' rims' vertical gap at the middle of the mouth, at `columns` evenly spaced points
    from corner to corner) in cm, as seen from the front: the upper rim's height less the lower's."""
    v = np.asarray(mesh.vertices, float)
    upper, lower = lid_chains(v, mesh.mouth_loop, mesh.landmark("mouth_corner_r"), mesh.landmark("mouth_corner_l"))
    a, axis = v[upper[0]], v[upper[-1]] - v[upper[0]]
    t = np.linspace(0.0, 1.0, columns)

    def height(chain: np.ndarray) -> FloatArray:
        tc = (v[chain] - a) @ axis / float(axis @ axis)
        order = np.argsort(tc)
        return np.interp(t, tc[order], v[chain][order, 1])

    seen = height(upper) - height(lower)
    return float(np.interp(0.5, t, seen)), seen


def mouth_width(mesh: FaceMesh) -> float:
    return float(np.linalg.norm(mesh.landmark("mouth_corner_l") - mesh.landmark("mouth_corner_r")))


def turn_jaw(mesh: FaceMesh, angle: float) -> FloatArray:
    """(N, 3) the mesh's vertices with the mandible turned by `angle` (rad; negative closes) about
    its hinge, each vertex by its jaw weight, as the simulation opens the jaw."""
    from sim.integrator import jaw_rotation

    v = np.asarray(mesh.vertices, float)
    axis = np.asarray(mesh.jaw_axis, float) / float(np.linalg.norm(mesh.jaw_axis))
    pivot = np.asarray(mesh.jaw_pivot, float)
    turned = (v - pivot) @ jaw_rotation(axis, angle).T + pivot
    w = np.clip(np.asarray(mesh.jaw_weight, float), 0.0, 1.0)[:, None]
    return v + w * (turned - v)


def close_jaw(mesh: FaceMesh) -> tuple[FaceMesh, list[str]]:
    """The mesh with a mouth that stands open at rest (lips more than OPEN_AT_REST x the mouth's
    width apart: a head modelled or scanned with the jaw dropped) closed by turning its jaw about
    the rig's own hinge, by its jaw weights, until the lips' middles are nearest (at most
    MOST_CLOSING). The transfer then makes the correspondence again on the closed head, so the
    muscles are carried onto the closed jaw. Brought together by the lips alone (`lids.set_gap`, which moves the skin within
    a lip's reach) the open jaw's lips met only half way (a 2 cm gap closed to 1.1 cm) and the
    chin stayed dropped in every expression."""
    from scipy.optimize import minimize_scalar

    now = float(np.linalg.norm(lip_gap(mesh)))
    if now <= OPEN_AT_REST * mouth_width(mesh):
        return mesh, []
    up, low = mesh.landmarks["upper_lip_center"], mesh.landmarks["lower_lip_center"]

    def gap(angle: float) -> float:
        v = turn_jaw(mesh, angle)
        return float(np.linalg.norm(v[up] - v[low]))

    best = minimize_scalar(gap, bounds=(-MOST_CLOSING, 0.0), method="bounded", options={"xatol": 1e-4})
    angle = float(best.x)
    if gap(angle) >= now:
        return mesh, []
    out = dataclasses.replace(mesh, vertices=turn_jaw(mesh, angle))
    return out, [f"the mouth stood open at rest (the lips {now:.2f} cm apart, {now / mouth_width(mesh):.2f} of its "
                 f"width); the jaw was turned {np.degrees(-angle):.1f} degrees shut about its hinge "
                 f"(lips {gap(angle):.2f} cm apart)"]


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
    ref_gap, ref_profile = seen_gaps(reference)
    if now > PARTED * want and ref_gap > 0:  # lips modelled apart: then, as seen from the front, no
        # column of the mouth further apart than the reference's
        wide = ref_gap * mouth_width(mesh) / mouth_width(reference)
        moved = set_gap(moved, upper, lower, wide, UP, upper_share=LIP_SHARE, profile=ref_profile / ref_gap)
    out = dataclasses.replace(mesh, vertices=moved)
    return out, [f"the lips stood {now:.2f} cm apart at rest; brought to {float(np.linalg.norm(lip_gap(out))):.2f} "
                 f"(the reference's {want:.2f} for this mouth)"]
