"""The lids drawn over the eyeball they close on, for the scanned head (render.scan_draw).

The simulation keeps the lid skin out of one sphere per eye (`sim.face.scan.rig._lid_sphere`), but
the margins, which rest on the cornea's bulge inside that sphere, are left out of the contact: a
closing margin passes into the drawn eyeball where the cornea stands out of the sclera. In anger's
narrowed eyes the upper margin's middle sank up to 1.6 mm into the cornea and the lower margin's
outer half up to 1.7 mm, so what showed as the margin was the cornea's outline cut through the lid:
an upper margin peaking over the iris (the iris showing in a notch) and a lower one uneven, with
the lashes, which hang from the margin, following the peak. A real lid rides over the cornea, its
margin pressed onto the globe's curve.

Here, every frame, each lid vertex near a margin that lies deeper in its eyeball than it did at rest
(or deeper than `CLEAR` outside it, whichever is less deep) is moved out along the eyeball's normal
onto its drawn front (the eyeball's radius about its centre by the angle from its gaze axis,
`PROFILE_BINS` bins over the rest shell, the largest in each: the cornea's bulge and the sclera),
as a lid pressed onto the globe rides over the cornea; the margin's push spreads over the lid within
`BAND` of it, and the lid things hanging from the margin (lashes, the eye's occlusion and blend
skins, the lacrimal) and the back of the lids move with their margin point. Moved along the gaze
axis instead (the margins' outline in the front view kept as simulated), the lids came out over the
whole cornea and anger read less angry (observer 0.44 against 0.55; docs/scan-face.md). A lid that
does not sink (open eyes) is drawn as simulated, exactly. Only the drawing changes: the simulation,
its bits and the exported vertices (`ScanDressing.pose`) are not.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

CLEAR = 0.02  # cm outside the eyeball's drawn front a margin is kept (or its rest depth, if less)
BAND = 0.35  # cm (rest) from a margin over which its push fades out on the lid's skin
PROFILE_BINS = 90  # bins of the angle from the gaze axis, 0..90 degrees, for the eyeball's radius


def _smoothstep(x: np.ndarray) -> np.ndarray:
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def eyeball_profile(shell: np.ndarray, centre: np.ndarray, axis: np.ndarray, bins: int = PROFILE_BINS) -> np.ndarray:
    """(bins + 1,) cm: the eyeball's radius about `centre` by the angle from its gaze `axis` (bin k
    from k to k + 1 of 90 / bins degrees; the largest of the shell's vertices in it, bins without
    any taken from their neighbours, the last bin repeated)."""
    q = shell - centre
    r = np.linalg.norm(q, axis=1)
    ang = np.degrees(np.arccos(np.clip(q @ axis / r, -1.0, 1.0)))
    k = np.minimum((ang / (90.0 / bins)).astype(np.int64), bins)
    out = np.full(bins + 1, -1.0)
    np.maximum.at(out, k, r)
    have = out > 0.0
    out[~have] = np.interp(np.flatnonzero(~have), np.flatnonzero(have), out[have])
    return out


class LidContact:
    """For one scan dressing (a ScanDressing; its look carrying the lid margins): `press(posed)`
    moves the lids that sank into their eyeballs back onto them (in place; returned)."""

    def __init__(self, look: Any, dressing: Any) -> None:
        from sim.face.scan.data import PARTS, SCLERA

        rest = np.asarray(look.rest, np.float64)
        margins = look.lids
        if margins is None or len(margins) != 2:
            raise ValueError("the scan's look carries no lid margins of the simulated mesh (ScanLook(rest, lids))")
        skin_of = np.asarray(dressing.skin, np.int64)  # scan index of each simulated vertex
        # the lids' front: the simulated skin (the lids' backs, drawn skin too, follow their margin)
        skin = np.unique(np.asarray(dressing.skin, np.int64))
        self.centres = np.asarray(dressing.eye_centres, np.float64)
        self.apex = np.zeros(2, np.int64)  # the eyeball vertex on its gaze axis
        self.profile = np.zeros((2, PROFILE_BINS + 1))
        chains, bands, weights, nears, allowed = [], [], [], [], []
        margin_of = -np.ones(len(rest), np.int64)  # scan vertex -> its place in its eye's chain
        eye_of = -np.ones(len(rest), np.int64)
        for e, ((upper, lower), side) in enumerate(zip(margins, "lr")):
            lo, _ = PARTS[f"eyeball_{side}"]
            shell = rest[lo:lo + SCLERA]
            c = self.centres[e]
            apex = int(np.argmax((shell - c) @ np.array([0.0, 0.0, 1.0]) / np.linalg.norm(shell - c, axis=1)))
            self.apex[e] = lo + apex
            axis = (shell[apex] - c) / np.linalg.norm(shell[apex] - c)
            self.profile[e] = eyeball_profile(shell, c, axis)
            chain = np.unique(np.concatenate([upper, lower]))
            margin_of[chain], eye_of[chain] = np.arange(len(chain)), e
            band = skin[cKDTree(rest[chain]).query(rest[skin])[0] < BAND]
            # the band lists the chain first (at distance 0, its own weight 1)
            band = np.concatenate([chain, band[~np.isin(band, chain)]])
            dist, near = cKDTree(rest[chain]).query(rest[band])
            chains.append(chain)
            bands.append(band)
            weights.append(1.0 - _smoothstep(dist / BAND))
            nears.append(near)
            allowed.append(np.minimum(self._depth(rest[band], e, axis), CLEAR))
        self.chains, self.bands, self.weights, self.nears, self.allowed = chains, bands, weights, nears, allowed
        # the lid things: from their margin segment's two ends; the lids' backs: from their anchor
        m = np.asarray(dressing.lid_margin, np.int64)
        things, eye = np.asarray(dressing.lid_idx, np.int64), np.asarray(dressing.lid_eye, np.int64)
        ends = np.stack([margin_of[skin_of[m[:, 0]]], margin_of[skin_of[m[:, 1]]]], axis=1)
        if (ends < 0).any():
            raise ValueError("a lid thing of the dressing hangs from outside the lids' margins")
        t = np.asarray(dressing.lid_t, np.float64)
        anchor = skin_of[np.asarray(dressing.lip_anchor, np.int64)]
        backs = np.asarray(dressing.lip_idx, np.int64)
        self.things = [(things[eye == e], ends[eye == e], t[eye == e]) for e in range(2)]
        self.backs = [(backs[eye_of[anchor] == e], margin_of[anchor[eye_of[anchor] == e]]) for e in range(2)]
        self._push = np.zeros((max(len(b) for b in bands), 3))

    def _depth(self, p: np.ndarray, e: int, axis: np.ndarray) -> np.ndarray:
        """(P,) cm each point lies outside eye e's drawn front (negative: inside), its gaze `axis`."""
        q = p - self.centres[e]
        r = np.linalg.norm(q, axis=1)
        ang = np.degrees(np.arccos(np.clip(q @ axis / np.maximum(r, 1e-9), -1.0, 1.0)))
        return r - np.interp(ang, np.arange(PROFILE_BINS + 1) * (90.0 / PROFILE_BINS), self.profile[e])

    def press(self, posed: np.ndarray) -> np.ndarray:
        """`posed` (the scan posed, before a head turn) with the lids that sank into their eyeballs
        moved out onto them, their things and backs with them (in place; returned)."""
        from render.seam_kernel import lid_press

        for e in range(2):
            lid_press(posed, self.bands[e], self.allowed[e], self.weights[e], self.nears[e], len(self.chains[e]),
                      self.centres[e], int(self.apex[e]), self.profile[e], 90.0 / PROFILE_BINS, *self.things[e],
                      *self.backs[e], self._push)
        return posed
