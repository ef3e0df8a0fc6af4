"""The mouth's and cheeks' actions that a line of pull alone cannot make, placed from landmarks like
the rest of the muscles (`sim.face.placement`): lip pucker (AU18), funneler (AU22) and the upper
lip's shrug, lip suck (AU28), lips meeting over an open jaw, the lips shifted sideways, and the
cheek puff (AU33/34).

What each models:
- Pucker: the incisivus labii superioris and inferioris (from the incisive fossae of maxilla and
  mandible to the modiolus) draw the mouth corners towards the midline; the lips, incompressible
  tissue squeezed between them, bunch and bulge forward (a forward patch over both lips).
- Funneler: the pars peripheralis of orbicularis oris, whose fibres run into the skin around the
  lips, everts them: each lip pushed forward and turned out (up for the upper, down for the lower)
  so the mouth opens into a funnel. The upper part alone is the upper lip's shrug.
- Lip suck: the pars marginalis, the fibres curled in the red lip, rolls each lip in over the
  teeth: backwards and towards the line where the lips meet.
- Lips meeting: the same marginal fibres draw the free edges together, the upper lip down and the
  lower lip up, whatever the jaw does (ARKit's mouthClose is used over an open jaw).
- Lips lifted: the closed lips carried up and forward as one, as when they meet over an open jaw
  (ARKit's mouthClose, whose scan lifts the lower lip 38 mm and carries it 17 mm forward, over the
  upper one). The lower lip's elevators (the mentalis pushing its base, the marginal fibres rolling
  it) lift it against the upper lip, which rides up on it: an upward patch over both lips and the
  modioli, so the lips rise together and the margin between them is not squeezed (a lift on the
  lower lip alone buckled it against the upper one); and a forward patch over the lower lip and
  the skin below it, so the lower lip comes forward more than the upper.
- Neck tightener (AU21): the platysma, a thin sheet from the skin over the mandible's body and
  under the corner of the mouth down over the neck, draws the jowl out and down and the skin under
  the chin down towards the chest: one patch per side over the jowl, one under the chin.
- Mouth left/right: one side's buccinator and risorius pull the modiolus back and out, the other
  side's let go, and the orbicularis ring, a closed band, carries both lips towards the pulling
  side (a sideways patch over the lips and the skin around them).
- Cheek puff: the lips sealed, air pressed into the vestibule pushes the cheeks out: a pressure
  along the skin's outward normal over each buccal region.

Patch strengths are force densities in units of `BASE_FORCE`, set so that each action at 1 moves
its landmarks by the amounts faces do (pucker: mouth corners ~8 mm in, lips ~6 mm forward).
"""

from __future__ import annotations

import numpy as np

from sim.face.placement import BASE_FORCE, FaceFrame, _linear
from sim.model import Muscle, PatchMuscle


#: the lips' lift (`lip_lift`), in units of BASE_FORCE: under a third of the scanned head's fitted
#: parts (`sim.face.scan.make_rig.LIP_LIFT_*`, 3.3 and 4.6 of these units with the scan's factor
#: 1.6), which on the synthetic test face with every channel at full outran the explicit step's guard
LIP_LIFT_UP = 1.0
LIP_LIFT_FORWARD = 1.4
#: the platysma (`platysma_l/_r`, AU21), in units of BASE_FORCE: the scanned head's patches
#: (`sim.face.scan.make_rig.PLATYSMA_*`) divided by BASE_FORCE and the scan's muscles' factor (1.6)
PLATYSMA_FACE = 0.3
PLATYSMA_NECK = 2.5


def _patch(f: FaceFrame, name: str, center: np.ndarray, semi: tuple[float, float, float],
           direction: tuple[float, float, float], strength: float) -> PatchMuscle:
    d = np.asarray(direction, np.float64)
    if np.any(d):
        d = d / np.linalg.norm(d)
    return PatchMuscle(name, np.asarray(center, np.float64), f.s * np.asarray(semi, np.float64), d,
                       BASE_FORCE * strength)


def mouth_actions(f: FaceFrame) -> dict[str, tuple[Muscle, ...]]:
    """Channel name -> parts for the channels above, on the face `f`."""
    half = 0.5 * abs(f.get("mouth_corner_l")[0] - f.get("mouth_corner_r")[0]) / f.s  # reference cm
    mouth = f.skin(f.mouth_center)
    upper, lower = f.get("upper_lip_center"), f.get("lower_lip_center")
    lips = (half + 0.4, 1.5, 1.5)
    lip = (half + 0.3, 0.75, 1.2)
    out: dict[str, tuple[Muscle, ...]] = {}
    incisivus: list[Muscle] = []
    for side, sg in (("l", 1.0), ("r", -1.0)):
        corner = f"mouth_corner_{side}"
        incisivus.append(_linear(f, f"incisivus_{side}", f.at(corner, sg, -1.6, 0.0, 0.3),
                                 f.at(corner, sg, 0.1, 0.0), reach=1.4, angle=0.5, strength=4.5))
    incisivus.append(_patch(f, "incisivus_bunching", mouth, lips, (0.0, 0.0, 1.0), 0.7))
    out["incisivus"] = tuple(incisivus)
    out["orbicularis_oris_peripheralis_upper"] = (
        _patch(f, "peripheralis_upper", upper + f.s * np.array([0.0, 0.2, 0.0]), lip, (0.0, 0.8, 1.0), 1.2),)
    out["orbicularis_oris_peripheralis_lower"] = (
        _patch(f, "peripheralis_lower", lower - f.s * np.array([0.0, 0.2, 0.0]), lip, (0.0, -0.8, 1.0), 1.2),)
    out["orbicularis_oris_marginalis_upper"] = (
        _patch(f, "marginalis_upper", upper, lip, (0.0, -0.5, -1.0), 1.8),)
    out["orbicularis_oris_marginalis_lower"] = (
        _patch(f, "marginalis_lower", lower, lip, (0.0, 0.5, -1.0), 1.8),)
    out["lip_closure"] = (_patch(f, "closure_upper", upper, lip, (0.0, -1.0, 0.0), 25.0),
                          _patch(f, "closure_lower", lower, lip, (0.0, 1.0, 0.0), 25.0))
    wide = half + 2.8  # as wide as the modioli and more: the corners ride up with the lips
    out["lip_lift"] = (_patch(f, "lip_lift_up", lower - f.s * np.array([0.0, 0.5, 0.0]), (wide, 0.8, 3.3),
                              (0.0, 1.0, 0.0), LIP_LIFT_UP),
                       _patch(f, "lip_lift_forward", lower - f.s * np.array([0.0, 1.0, 0.0]), (wide, 1.0, 3.3),
                              (0.0, 0.0, 1.0), LIP_LIFT_FORWARD))
    for side, sg in (("l", 1.0), ("r", -1.0)):  # the scan's places (make_rig.PLATYSMA_*) from corner and chin
        jowl = f.get(f"mouth_corner_{side}") + f.s * np.array([2.4 * sg, -1.7, -3.1])
        neck = f.get("chin") + f.s * np.array([1.4 * sg, -1.6, -1.6])  # its shallower underside
        out[f"platysma_{side}"] = (_patch(f, f"platysma_face_{side}", jowl, (2.2, 2.6, 3.0), (0.95 * sg, -0.3, 0.0),
                                          PLATYSMA_FACE),
                                   _patch(f, f"platysma_neck_{side}", neck, (2.6, 2.0, 2.2), (0.0, -0.95, 0.3),
                                          PLATYSMA_NECK))
    band = (half + 1.3, 1.9, 1.6)
    out["mouth_shift_l"] = (_patch(f, "mouth_shift_l", mouth, band, (1.0, 0.0, 0.0), 1.0),)
    out["mouth_shift_r"] = (_patch(f, "mouth_shift_r", mouth, band, (-1.0, 0.0, 0.0), 1.0),)
    out["cheek_puff"] = tuple(
        _patch(f, f"cheek_puff_{side}", f.at(f"mouth_corner_{side}", sg, 2.3, 0.6), (2.3, 2.6, 3.0),
               (0.0, 0.0, 0.0), 4.0) for side, sg in (("l", 1.0), ("r", -1.0)))
    return out
