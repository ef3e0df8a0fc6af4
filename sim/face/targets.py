"""How far the face's landmarks move per AU and preset at full activation, against real faces.

`TARGETS` lists, per pose, a landmark motion and the range it must fall in (mm), with where the
range comes from: measured adults (published 3D measurements: Jorge 2012, Bae 2003,
Cruz 2004, Feng 2015, the mouth-opening surveys), or, where no millimetres exist (AU4, AU9, AU15,
AU16, AU17, the preset differences), our own reading of FACS' appearance descriptions, marked
"FACS". Used by tests/sim/test_amplitudes.py and benchmarks/expressions.py; nothing here knows
files or devices.

Components of a landmark's displacement d (mm, project frame: +Y up, +Z forward, +X the face's
left): up = d_y, down = -d_y, out = d_x away from the midline (+X for *_l landmarks, -X for *_r),
in = -out, forward = d_z, total = |d|. "opening" is the distance between two landmarks at the pose,
"gap" the height of the first above the second (mm, not displacements; a negative gap is overlap).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim import facs
from sim.state import FaceControl


@dataclass(frozen=True)
class Target:
    pose: str  # an AU ("AU12"), a preset ("happiness") or "AU1+2" style sums of AUs at 1.0
    landmark: str  # a landmark, or "a/b" for the opening between two landmarks
    component: str  # up, down, out, in, forward, total, opening; "ratio:<c>:<landmark>" (see below)
    lo: float
    hi: float
    source: str


# component "ratio:up:brow_inner_l" on landmark L: L's up divided by brow_inner_l's up, e.g. the
# outer brow rises at most 0.4 x as far as the inner one in sadness (oblique brows).
TARGETS: tuple[Target, ...] = (
    Target("AU6+12", "mouth_corner_l", "total", 9.0, 14.0, "Jorge 2012 9.3 +- 2.8, Bae 2003 13.7 (3D)"),
    Target("AU6+12", "mouth_corner_l", "up", 5.5, 9.0, "Bae 2003 derived vertical ~7.1"),
    Target("AU6+12", "mouth_corner_l", "out", 4.0, 8.0, "Bae 2003 derived lateral ~5.5"),
    Target("happiness", "mouth_corner_l", "total", 9.0, 14.0, "Jorge 2012, Bae 2003 (3D)"),
    Target("happiness", "lower_lid_l", "up", 2.0, 5.0, "Feng 2015 grinning lower lid ~4"),
    Target("happiness", "upper_lid_l", "down", -1.0, 3.5, "Feng 2015 smiling upper lid 2.5-3"),
    Target("happiness", "upper_lid_l/lower_lid_l", "gap", 3.5, 12.0,
           "narrowed, not a slit: 10.7 at rest less Feng's ~3 + ~4"),
    Target("AU1+2", "brow_mid_l", "up", 7.5, 10.5, "Cruz 2004 7.6-9.0, Jorge 2012 10.6 +- 2.5"),
    Target("AU1", "brow_inner_l", "up", 4.0, 10.0, "FACS AU1 raises the inner brow"),
    Target("AU1", "brow_outer_l", "ratio:up:brow_inner_l", -0.5, 0.4, "FACS AU1: oblique brow"),
    Target("AU2", "brow_outer_l", "up", 4.0, 10.0, "FACS AU2 raises the outer brow"),
    Target("AU4", "brow_inner_l", "down", 3.0, 9.0, "FACS AU4 lowers the brow (our target)"),
    Target("AU4", "brow_inner_l", "in", 3.0, 8.0, "FACS AU4 draws the brows together (our target)"),
    Target("AU4", "brow_mid_l", "down", 2.0, 7.0, "FACS AU4 lowers the whole brow (our target)"),
    Target("AU9", "nose_wing_l", "up", 3.0, 10.0, "FACS AU9 raises the nose wings (our target)"),
    Target("AU9", "upper_lip_center", "up", 1.0, 5.0, "FACS AU9 lifts the upper lip (our target)"),
    Target("AU15", "mouth_corner_l", "down", 3.0, 7.0, "FACS AU15 pulls the corners down (our target)"),
    Target("AU16", "lower_lip_center", "down", 3.0, 7.0, "FACS AU16 lowers the lower lip (our target)"),
    Target("AU17", "chin", "up", 2.0, 6.0, "FACS AU17 pushes the chin boss up (our target)"),
    Target("AU5", "upper_lid_l", "up", 2.5, 5.0,
           "FACS AU5 bares sclera above the iris; the margin rests 2-3 mm below the limbus (our target)"),
    Target("AU5", "brow_mid_l", "up", -1.0, 1.5, "FACS AU5 lifts the lid, not the brow (our target)"),
    Target("AU45", "upper_lid_l", "down", 7.0, 11.5, "Jorge 2012 eyelid 9.1 +- 2.2"),
    Target("AU45", "upper_lid_l/lower_lid_l", "gap", -0.8, 0.8, "the lids meet"),
    Target("AU27", "upper_lip_center/lower_lip_center", "opening", 44.0, 57.0,
           "max interincisal 44-57 (n = 894, 142, 1262)"),
    Target("surprise", "brow_mid_l", "up", 7.5, 10.5, "Cruz 2004, Jorge 2012 (AU1+2)"),
    Target("sadness", "brow_inner_l", "up", 3.0, 9.0, "FACS 1+4+15: inner brow raised"),
    Target("sadness", "brow_outer_l", "ratio:up:brow_inner_l", -1.0, 0.4, "FACS: oblique brows"),
    Target("sadness", "mouth_corner_l", "down", 2.5, 7.0, "FACS AU15 (our target)"),
    Target("anger", "brow_inner_l", "down", 3.0, 9.0, "FACS AU4 (our target)"),
    Target("anger", "brow_inner_l", "in", 3.0, 8.0, "FACS AU4 (our target)"),
    Target("disgust", "nose_wing_l", "up", 3.0, 10.0, "FACS AU9 (our target)"),
    Target("disgust", "upper_lip_center", "up", 2.0, 7.0, "FACS AU9+10 (our target)"),
    Target("disgust", "lower_lip_center", "down", -5.0, 1.0, "FACS: no jaw drop"),
    Target("disgust", "chin", "down", -5.0, 1.0, "FACS: no jaw drop"),
    Target("fear", "upper_lid_l", "up", 6.5, 12.0, "FACS 1+2+4+5: the eyes widened, more than by 1+2+4 alone"),
    Target("fear", "brow_mid_l", "up", 2.5, 8.0, "FACS 1+2+4: raised less than in 1+2"),
    Target("fear", "brow_inner_l", "in", 0.5, 5.0, "FACS 1+2+4: drawn together"),
    Target("fear", "mouth_corner_l", "out", 3.0, 9.0, "FACS AU20 stretches the lips sideways"),
    Target("fear", "lower_lip_center", "down", 5.0, 30.0, "FACS AU26 jaw drop"),
)

REFERENCE_EX_EX_MM = 90.0  # the real adults' outer-canthal width the ranges are given for


def pose_control(pose: str) -> FaceControl:
    """The FaceControl of a pose name: a preset, an AU, or AUs joined by '+' ("AU6+12")."""
    c = FaceControl()
    if pose in facs.EXPRESSIONS:
        facs.apply_expression(c, pose, 1.0)
        return c
    first, *rest = pose.split("+")
    for au in [first] + ["AU" + r if not r.upper().startswith("AU") else r for r in rest]:
        facs.apply_au(c, au, 1.0)
    return c


def poses() -> list[str]:
    """Every AU of the table (both sides), the combined poses of TARGETS, and every preset."""
    aus = [au for au in facs.AU_TABLE if not au.endswith(("_L", "_R"))]
    combined = sorted({t.pose for t in TARGETS if "+" in t.pose})
    return aus + combined + list(facs.EXPRESSIONS)


def components(name: str, d: np.ndarray) -> dict[str, float]:
    """up/down/out/in/forward/total (mm) of one landmark's displacement d (mm, (3,))."""
    side = -1.0 if name.endswith("_r") else 1.0
    out = side * float(d[0]) if name.endswith(("_l", "_r")) else 0.0
    return {"up": float(d[1]), "down": -float(d[1]), "out": out, "in": -out, "forward": float(d[2]),
            "total": float(np.linalg.norm(d))}


def face_scale_mm(landmarks: dict[str, int], rest: np.ndarray) -> float:
    """Factor from this face's mm to the reference adult's: 90 mm over its outer-canthal width."""
    ex = np.linalg.norm(rest[landmarks["eye_outer_l"]] - rest[landmarks["eye_outer_r"]]) * 10.0
    return REFERENCE_EX_EX_MM / float(ex)


def measure(target: Target, landmarks: dict[str, int], rest: np.ndarray, pos: np.ndarray) -> float:
    """The value of a target on a settled pose (positions in cm), in reference-face mm."""
    k = 10.0 * face_scale_mm(landmarks, rest)
    if target.component in ("opening", "gap"):
        a, b = target.landmark.split("/")
        d = pos[landmarks[a]] - pos[landmarks[b]]
        return k * float(np.linalg.norm(d) if target.component == "opening" else d[1])

    def comp(name: str, c: str) -> float:
        return components(name, k * (pos[landmarks[name]] - rest[landmarks[name]]))[c]

    if target.component.startswith("ratio:"):
        _, c, other = target.component.split(":")
        return comp(target.landmark, c) / max(comp(other, c), 1e-6)
    return comp(target.landmark, target.component)
