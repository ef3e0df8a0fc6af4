"""Each channel's muscles pulling as hard on the new head as on the reference.

A muscle's force is a density (dyn/cm^2) over the skin its zone covers, and the zones are carried
point by point: on a head of other proportions a zone covers more or less of the skin than the
reference's did (the frontalis' inner part, made to cover its skin, 1.3 x; the corrugator, a pair
of lines whose cone meets less skin, 0.6 x, on the MakeHuman development head), so the same
channel value pulls harder or softer. The skin's response to a force density does not depend on
the head's size (tethers and support are per unit area, the membrane's springs per unit strain),
so the measure compared is the channel's total force over the free skin at full activation,
divided by the face's area scale (the squared distance between the outer eye corners).

A channel is only made stronger, never weaker: a zone that covers less skin than the reference's
(the corrugator's cone) has its force gathered onto what it covers, but a zone that covers more
keeps the reference's density, since each bit of skin moves by the force on it and its
neighbours, not by the channel's total. Weakened to the reference's total, the scanned identity
of the development heads (`benchmarks/observer_mesh.py`), whose zones cover about twice the
reference's skin for its eye width, had 37 of 42 channels scaled, most down to 0.5-0.75, and
moved about half as far as the reference (for a 9 cm eye width, settled: the mouth corners under
AU15 0.25 cm, reference 0.40, kept whole 0.44; the nose wing under AU9 0.28, 0.55, 0.51); its
smile, sadness and disgust read as neutral or anger."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.model import FaceRig, Muscle
from sim.muscles import muscle_field
from sim.springs import vertex_areas
from sim.face.transfer.geometry import vertex_normals

LIMITS = (1.0, 2.0)  # a channel's force scale is multiplied by at least 1 and at most 2


def channel_totals(rig: FaceRig) -> dict[str, float]:
    """Per muscle channel: the sum over free skin vertices of |nodal force| at activation 1 (dyn),
    divided by the squared outer-eye-corner distance (cm^2)."""
    m = rig.mesh
    x = np.asarray(m.vertices, float)
    tris = np.asarray(m.triangles)
    area, normal = vertex_areas(x, tris), vertex_normals(x, tris)
    free = ~np.asarray(m.held, bool)
    width2 = float(np.sum((x[m.landmarks["eye_outer_l"]] - x[m.landmarks["eye_outer_r"]]) ** 2))
    out = {}
    for ch, parts in rig.muscles.items():
        f = muscle_field(parts, x, area, normal)
        out[ch] = float(np.linalg.norm(f[free], axis=1).sum()) / width2
    return out


def match_forces(reference: FaceRig, rig: FaceRig) -> tuple[dict[str, tuple[Muscle, ...]], dict[str, float]]:
    """The new rig's muscles with each channel's force scales multiplied so its total
    (`channel_totals`) is the reference's, the factor clipped to LIMITS; also the factors."""
    want, have = channel_totals(reference), channel_totals(rig)
    muscles, factors = {}, {}
    for ch, parts in rig.muscles.items():
        k = want.get(ch, 0.0) / have[ch] if have.get(ch, 0.0) > 0 else 1.0
        k = float(np.clip(k, *LIMITS)) if k > 0 else 1.0
        factors[ch] = k
        muscles[ch] = tuple(replace(p, scale=p.scale * k) for p in parts)
    return muscles, factors
