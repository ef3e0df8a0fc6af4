"""The shadow in a closing eye's seam, for the scanned head (render.scan_draw).

When the lids close (a blink, a squint, anger's narrowed eyes) the simulated upper margin comes
down to within a millimetre or two of the lower one but not onto it everywhere: at the inner half
of a blink 1.3-1.9 mm stay open. The lower lid's margin there turns up towards the key light, and
with the upper lashes hanging past it it was drawn as a pale fleck at the closed lid's seam, where
a real closed eye shows a dark line (the margins in the shadow of the lid and its lashes, as the
scan's own blink). Here, every frame, the gap between the two margins is measured along the eye
(each margin vertex's distance to the other lid's margin, a polyline) and the skin near the
margins is darkened through the fold term by how far that gap has closed: nothing while the eye is
open (the gap more than `GAP[1]`, or closed by less than `CLOSED[0]` of its rest width), all of
`SEAM_FOLD` at a gap of `GAP[0]` closed past `CLOSED[1]`. Only the drawing changes: the simulation, its bits and the
exported vertices (`ScanDressing.pose`) are not. An eye whose seam is shut across its middle
(`SHUT`) has its eyeball drawn in the lids' shadow too (through the fold term of its rows, which the
eyeballs' shader reads only for this): what shows of the iris where the margins do not quite meet is
a dark gap, not a brown fleck.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

SEAM_FOLD = 2.6  # the fold term added at a closed seam: up to 0.4 darkens the ambient light to its least, past
# 1 the key light and the highlight too (render.scan_shaders: at most 0.85 of them taken)
GAP = (0.1, 0.3)  # cm between the margins: all of the shadow at the first, none beyond the second
# how much of its rest width (taken as at least REST_FLOOR) the gap closed: none of the shadow below the
# first, all of it above the second
CLOSED = (0.2, 0.5)
REST_FLOOR = 0.3  # cm: near the corners, where the margins meet at rest, the gap closes by nothing
BAND = 0.4  # cm (rest) from a margin: the skin darkened, fading to nothing there
SHUT = (0.6, 0.95)  # the seam's mean shadow over the middle half of the eye at which the eyeball seen
# through it starts to darken, and is darkened fully (render.scan_shaders: to 0.15 of its light)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _to_polyline(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(P,) the distance of each point p (P,3) from the polyline `line` (L,3)."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.einsum("pld,ld->pl", p[:, None, :] - a[None], ab) / np.maximum(np.einsum("ld,ld->l", ab, ab), 1e-12)
    q = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.sqrt(((p[:, None, :] - q) ** 2).sum(axis=2).min(axis=1))


class LidSeam:
    """For one rest pose of the scan (a ScanLook carrying the simulated mesh's lid margins: its eye
    loops split at the corner landmarks, `ScanDressing.eye_margins`): `shade(rows)` adds the closing
    seams' shadow to the rows' fold term (in place; the rows are returned) and sets the eyeballs'
    (how shut each eye is, 0..1)."""

    def __init__(self, look: object) -> None:
        from sim.face.scan.data import PARTS

        rest = np.asarray(look.rest, np.float64)  # type: ignore[attr-defined]
        margins = look.lids  # type: ignore[attr-defined]  # per eye (upper, lower), from the simulated mesh
        if margins is None or len(margins) != 2:
            raise ValueError("the scan's look carries no lid margins of the simulated mesh (ScanLook(rest, lids))")
        skin = np.unique(np.asarray(look.groups["skin"]))  # type: ignore[attr-defined]
        self.lids: list[tuple[np.ndarray, np.ndarray]] = []  # per eye (upper, lower) margin, corner to corner
        self.band, self.weight, self.at, self.rest_gap, self.middle, self.balls = [], [], [], [], [], []
        for (upper, lower), side in zip(margins, "lr"):  # the left eye's then the right's
            upper, lower = np.asarray(upper, np.int64), np.asarray(lower, np.int64)
            self.lids.append((upper, lower))
            chain = np.concatenate([upper, lower])
            gap = np.concatenate([_to_polyline(rest[upper], rest[lower]), _to_polyline(rest[lower], rest[upper])])
            dist, near = cKDTree(rest[chain]).query(rest[skin])
            keep = dist < BAND
            self.band.append(skin[keep].astype(np.int64))
            self.weight.append((1.0 - _smoothstep(dist[keep] / BAND)).astype(np.float32))
            self.at.append(near[keep].astype(np.int64))
            self.rest_gap.append(gap)
            xs = rest[chain, 0]
            span = xs.max() - xs.min()
            self.middle.append(np.flatnonzero((xs > xs.min() + 0.25 * span) & (xs < xs.max() - 0.25 * span)))
            self.balls.append(PARTS[f"eyeball_{side}"])
        self._gap, self._closed, self._shut = np.array([*GAP, REST_FLOOR]), np.array(CLOSED), np.array(SHUT)
        self._scratch = np.zeros(max(len(u) + len(lo) for u, lo in self.lids))

    def shadow(self, pos: np.ndarray) -> list[np.ndarray]:
        """Per eye, 0..1 per margin vertex (upper then lower): how closed the seam is there."""
        from render.seam_kernel import seam_shadow

        out = []
        for (upper, lower), rest_gap in zip(self.lids, self.rest_gap):
            s = np.zeros(len(upper) + len(lower))
            seam_shadow(pos, upper, lower, rest_gap, self._gap, self._closed, s)
            out.append(s)
        return out

    def shade(self, rows: np.ndarray) -> np.ndarray:
        """`rows` (the renderer's x y z nx ny nz fold) with the closing seams' shadow added to the
        fold term of the skin within BAND of the margins, and each eyeball's fold term set to how
        shut its eye is (0..1, which its shader reads)."""
        from render.seam_kernel import seam_shade

        for (upper, lower), rest_gap, band, w, at, middle, (lo, hi) in zip(
                self.lids, self.rest_gap, self.band, self.weight, self.at, self.middle, self.balls):
            seam_shade(rows, upper, lower, rest_gap, band, w, at, middle, lo, hi, SEAM_FOLD, self._gap,
                       self._closed, self._shut, self._scratch)
        return rows
