"""The scanned head's lids as the scan's blink shows them: the palpebral orbicularis closing the
upper lid down to the lower one and drawing both towards the nose, and the orbicularis retaining
ligament holding the skin under the brow.

What the scan's eyeBlink does (ICT FaceKit, left eye, over the skin round the eye): the upper lid's
margin travels 8-9.5 mm down and comes to rest on the lower lid's; the motion falls from 9 mm at
1-2 mm above the margin to 1.7 mm at 5.5 mm and nothing past 8 mm (the lid fold unfurls: skin
tucked into the fold at rest comes out and stretches over the globe); the brow and the skin under
it stay (0.1 mm); the lower lid does not rise (0.2 mm) but slides 2.5-2.9 mm towards the nose
over its whole height down to 8 mm below the margin, the upper margin 1.3-1.8 mm. The transferred
rig closed the lids on a line a fifth of the opening above the lower margin (the lower lid rose
3 mm), its upper strips reached 1.7 lid heights up to the brow and dragged it down 3.4 mm: relative
error 1.21 (`benchmarks/scan_match.py --no-fit`), the skin above the lid and the lower lid most of it.

Anatomy modelled (per eye, on the lid channel `orbicularis_oculi_lid_<side>`, AU43/AU45):

- The pretarsal and preseptal orbicularis of the upper lid: the transferred upper strips, inserting
  into the lid from the margin to the fold only (`insertion` gain 1 up to `UPPER_REACH[0]` above
  the margin, fading to 0 at `UPPER_REACH[1]`; above the fold the muscle is the orbital part,
  `orbicularis_oculi`, AU6, another channel), attached just above the lower margin and set back
  into the orbit by `SLOPE` of their drop (the scan's margin's own path over the globe), each as
  strong as its part of the lid has far to travel (`UPPER_FORCE`, `CORNER_BOOST`).
- The palpebral fibres run from the lateral raphe round the lids to the medial canthal tendon,
  which holds while the raphe yields: both lids slide towards the nose as the fibres shorten. A
  force towards the inner corner over the lids (`MEDIAL_PULL`, a patch of the lid channel), in
  place of the transferred lower strips, which lifted the lower lid (the scan's does not rise).
- The lower lid's palpebral orbicularis tightening (AU7, its own channel
  `orbicularis_oculi_lower_lid_<side>`): its fibres arc under the eye and straighten as they
  tighten, lifting the lower lid up the globe (`LOWER_FORCE`, a patch); a blink leaves the lower
  lid where it is, the tightener narrows the eye from below.
- The tarsal plates keep the lids' shape: the skin next to each margin stiffer (`TARSUS`).
- The lid fold: the skin of the upper lid between the tarsus and the fold is laxer (`FOLD`, a
  multiplier of the skin's modulus over `FOLD_BAND` above the margin): skin that lies folded at
  rest is not stretched until the fold unfurls.
- The orbicularis retaining ligament ties the skin under the brow to the orbital rim
  (`LIGAMENT`, a multiplier of the skin's tether over `LIGAMENT_BAND` above the margin,
  `FaceRig.tissue["tether_orbital_retaining"]`; the tarsus and the fold are
  `["modulus_lid_fold"]`).

`with_lids(rig)` rebuilds these keys from the rig's own geometry (margins, corners, eye loops), so
they follow any refit of the rest of the face; `python -m sim.face.scan.lids` rewrites them in
the shipped rig file and nothing else (`make_rig` and `benchmarks/calibrate_scan.py` call it too).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from sim.face.transfer.eyes import mesh_lids
from sim.model import FaceMesh, FaceRig, PatchMuscle, SheetMuscle

CHANNEL = "orbicularis_oculi_lid_{side}"
LOWER_STRIP = "orbicularis_oculi_lid_lower_"  # the transferred lower strips' names start so
UPPER_STRIP = "orbicularis_oculi_lid_upper_"
MEDIAL = "orbicularis_oculi_lid_medial_{side}"
LOWER = "orbicularis_oculi_lower_lid_{side}"  # the lower lid's tightener (AU7): its own channel
LIGAMENT_KEY = "tether_orbital_retaining"  # FaceRig.tissue
FOLD_KEY = "modulus_lid_fold"

UPPER_REACH = (0.15, 0.35)  # cm above the upper margin: full insertion, then fading to none
UPPER_FORCE = 72000.0  # dyn/cm2: the upper strip with the farthest to travel (eq 18's alpha)
CORNER_BOOST = 0.6  # the strips by the corners pull harder than their drop alone asks (held by the canthi)
SLOPE = 0.1  # the upper strips' pull: back into the orbit by this per unit down (the scan's margin: 0.1)
OVERLAP = 1.0  # each strip's zone this many times its share of the lid's width (neighbours overlap)
CLEAR = 0.06  # cm: the attachment line this far above the lower margin's highest point under the strip
STRIP_REACH = 1.3  # the upper strips' zone, in lengths from their attachment to their insertion
MEDIAL_PULL = 6000.0  # dyn/cm2 at the patch's centre
MEDIAL_AXES = (1.6, 1.3, 1.2)  # cm, the patch's semi-axes (along X, Y, Z)
MEDIAL_DROP = 0.2  # cm: the patch's centre below the corners' midpoint (the lower lid moves most)
TARSUS = 4.0  # the tarsal plate: the lid's skin from the margin up stiffer by this
TARSUS_HEIGHT = (0.15, 0.25)  # cm above the upper margin: the plate, then fading to the skin
LOWER_TARSUS = (0.05, 0.15)  # cm below the lower margin
FOLD = 0.3
FOLD_BAND = (0.2, 0.7)  # cm above the upper margin
LIGAMENT = 10.0
LIGAMENT_BAND = (0.6, 1.0)  # cm above the upper margin
EDGE = 0.1  # cm: the bands' smooth edges (fold), 0.2 / 0.3 below / above (ligament)
LOWER_FORCE = 24000.0  # dyn/cm2 at the lower lid tightener's centre: AU7 at 0.85 lifts the margin ~4 mm
LOWER_DROP = 0.2  # cm: its centre below the lower margin's lowest point, under the canthi's midpoint
LOWER_AXES = (0.9, 0.4, 1.0)  # cm, its semi-axes (along X, Y, Z): the lower lid from canthus to canthus
LOWER_UP = (0.0, 1.0, 0.2)  # its push: up the globe's front (the contact keeps the lid on the eye)


def _step(x: np.ndarray, a: float, b: float) -> np.ndarray:
    """Smooth 0 -> 1 between a and b (cubic)."""
    t = np.clip((x - a) / (b - a), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def margin_distances(mesh: FaceMesh, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(N,) distance (cm) of every vertex to the nearest vertex of the upper lid's margin and to
    the lower lid's."""
    v = np.asarray(mesh.vertices, np.float64)
    out = []
    for arc in mesh_lids(mesh, "lr".index(side)):
        p = v[np.asarray(arc)]
        out.append(np.sqrt(np.min(np.sum((v[:, None, :] - p[None]) ** 2, axis=2), axis=1)))
    return out[0], out[1]


def _drop(m: SheetMuscle, lower: np.ndarray) -> float:
    """How far (cm) an upper strip's insertion line lies above the lower margin beneath it."""
    mid = 0.5 * (m.insert1 + m.insert2)
    return float(mid[1] - lower[int(np.argmin(np.abs(lower[:, 0] - mid[0]))), 1])


def _upper_strip(m: SheetMuscle, lower: np.ndarray, share: float) -> SheetMuscle:
    """An upper strip pulling its part of the lid down to the lower margin beneath it (`lower`:
    the lower margin's vertices) along the globe's front: its attachment line under its insertion
    line just above the lower margin (so its zone, which starts there, leaves the lower lid), set back into the orbit by `SLOPE` of the drop; its force
    `UPPER_FORCE` times `share`."""
    x0, x1 = sorted((float(m.insert1[0]), float(m.insert2[0])))
    under = lower[(lower[:, 0] >= x0 - 0.05) & (lower[:, 0] <= x1 + 0.05)]
    floor = float(under[:, 1].max() if len(under) else lower[int(np.argmin(np.abs(lower[:, 0] - x0))), 1]) + CLEAR
    ends = []
    for ins in (m.insert1, m.insert2):
        drop = float(ins[1] - floor)
        ends.append(np.array([ins[0], floor, ins[2] - SLOPE * drop]))
    span = float(np.linalg.norm(0.5 * (ends[0] + ends[1]) - 0.5 * (m.insert1 + m.insert2)))
    return replace(m, attach1=np.round(ends[0], 7), attach2=np.round(ends[1], 7), length=round(STRIP_REACH * span, 7),
                   width=round(OVERLAP * m.width, 7), scale=round(UPPER_FORCE * share / OVERLAP, 4))


def _lower_tightener(v: np.ndarray, lower: np.ndarray, inner: np.ndarray, outer: np.ndarray,
                     side: str) -> PatchMuscle:
    """The lower lid's palpebral orbicularis (AU7), its own channel: the fibres run in an arc under
    the eye from the lateral raphe to the medial canthal tendon, and tightening straightens the arc,
    which lifts the lower lid up over the globe (a blink, the lid channel, leaves the lower lid where
    it is, as the scan's does). A push up the lid's front over the lower lid's height."""
    low = lower[int(np.argmin(lower[:, 1]))]
    centre = np.array([0.5 * (inner[0] + outer[0]), low[1] - LOWER_DROP, low[2]])
    up = np.asarray(LOWER_UP, np.float64)
    return PatchMuscle(LOWER.format(side=side), np.round(centre, 7), np.array(LOWER_AXES),
                       np.round(up / np.linalg.norm(up), 7), LOWER_FORCE)


def with_lids(rig: FaceRig) -> FaceRig:
    """The rig with its lid channels, their insertion gains, the lid fold and the retaining
    ligament built as the module docstring says (idempotent: built again from the geometry)."""
    mesh = rig.mesh
    v = np.asarray(mesh.vertices, np.float64)
    muscles = dict(rig.muscles)
    insertion = dict(rig.insertion)
    fold = np.ones(len(v))
    ligament = np.ones(len(v))
    for side in ("l", "r"):
        ch = CHANNEL.format(side=side)
        up, low = margin_distances(mesh, side)
        above = up < low
        gain = 1.0 - _step(up, *UPPER_REACH)
        insertion[ch] = np.round(np.where(above, gain, 1.0), 6)
        inner, outer = v[mesh.landmarks[f"eye_inner_{side}"]], v[mesh.landmarks[f"eye_outer_{side}"]]
        towards = inner - outer
        towards[1:] = 0.0  # along the face, level: the lids slide towards the nose
        centre = 0.5 * (inner + outer) - np.array([0.0, MEDIAL_DROP, 0.0])
        medial = PatchMuscle(MEDIAL.format(side=side), np.round(centre, 7), np.array(MEDIAL_AXES),
                             np.round(towards / np.linalg.norm(towards), 7), MEDIAL_PULL)
        lower = v[mesh_lids(mesh, "lr".index(side))[1]]
        strips = [m for m in muscles[ch] if m.name.startswith(UPPER_STRIP)]
        drops = np.array([_drop(m, lower) for m in strips])
        h = drops / drops.max()
        share = {m.name: float(hk * (1.0 + CORNER_BOOST * (1.0 - hk))) for m, hk in zip(strips, h)}
        kept = tuple(_upper_strip(m, lower, share[m.name]) if m.name in share else m for m in muscles[ch]
                     if not m.name.startswith(LOWER_STRIP) and m.name != medial.name)
        muscles[ch] = kept + (medial,)
        muscles[LOWER.format(side=side)] = (_lower_tightener(v, lower, inner, outer, side),)
        fold *= 1.0 + (TARSUS - 1.0) * np.where(above, 1.0 - _step(up, *TARSUS_HEIGHT),
                                                1.0 - _step(low, *LOWER_TARSUS))
        fold *= 1.0 + (FOLD - 1.0) * above * _step(up, FOLD_BAND[0] - EDGE, FOLD_BAND[0]) * (
            1.0 - _step(up, FOLD_BAND[1], FOLD_BAND[1] + EDGE))
        ligament *= 1.0 + (LIGAMENT - 1.0) * above * _step(up, LIGAMENT_BAND[0] - 0.2, LIGAMENT_BAND[0]) * (
            1.0 - _step(up, LIGAMENT_BAND[1], LIGAMENT_BAND[1] + 0.3))
    return replace(rig, muscles=muscles, insertion=insertion,
                   tissue={**rig.tissue, LIGAMENT_KEY: np.round(ligament, 6), FOLD_KEY: np.round(fold, 6)})


def rewrite(path: str | Path | None = None) -> FaceRig:
    """Rebuild the lid keys of a rig file (default: the shipped `ict_rig.npz`) and write it back
    (to a temporary file renamed into place); everything else in it is kept as it is."""
    from sim.face.scan.rig import RIG_FILE
    from sim.rig import load_rig, save_rig

    target = Path(path) if path is not None else RIG_FILE
    rig = with_lids(load_rig(target))
    save_rig(rig, target)
    return rig


if __name__ == "__main__":
    import sys

    out = rewrite(sys.argv[1] if len(sys.argv) > 1 else None)
    print(f"rebuilt the lids of {out.name}: " + ", ".join(sorted(k for k in out.tissue)))
