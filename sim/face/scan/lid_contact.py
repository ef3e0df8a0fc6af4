"""The scan's lids laid back onto the eyeballs they close on: what is drawn (render.scan_draw) and
what is exported (`ScanDressing.pose_exported`: OBJ, PC2, `puppet pose --out`) both use this.

The simulation keeps the lid skin out of one sphere per eye (`sim.face.scan.rig._lid_sphere`), but
the margins, which rest on the cornea's bulge inside that sphere, are left out of the contact: a
closing margin passes into the eyeball where the cornea stands out of the sclera. In anger's
narrowed eyes the upper margin's middle sank up to 1.6 mm into the cornea and the lower margin's
outer half up to 1.7 mm, so what showed as the margin was the cornea's outline cut through the lid:
an upper margin peaking over the iris (the iris showing in a notch) and a lower one uneven, with
the lashes, which hang from the margin, following the peak. A real lid rides over the cornea, its
margin pressed onto the globe's curve.

Each pose, each lid vertex near a margin that lies deeper in its eyeball than it did at rest (or
deeper than `CLEAR` outside it, whichever is less deep) is moved out along the eyeball's normal onto
its front (the eyeball's radius about its centre by the angle from its gaze axis, `PROFILE_BINS`
bins over the rest shell, the largest in each: the cornea's bulge and the sclera), as a lid pressed
onto the globe rides over the cornea; the margin's push spreads over the lid within `BAND` of it,
and the lid things hanging from the margin (lashes, the eye's occlusion and blend skins, the
lacrimal) and the back of the lids move with their margin point. Moved along the gaze axis instead
(the margins' outline in the front view kept as simulated), the lids came out over the whole cornea
and anger read less angry (observer 0.44 against 0.55; docs/scan-face.md). A lid that does not
sink (open eyes) is left exactly as posed. The simulation and its bits are not changed: this is a
pass over the posed scan (26,719 vertices, in the scan's order): one compiled pass per eye
(sim.face.scan.lid_kernel, 0.03 ms a pose), checked to the bit against the numpy steps
(`LidContact.press_steps`, 0.7-0.9 ms).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

CLEAR = 0.02  # cm outside the eyeball's front a margin is kept (or its rest depth, if less)
BAND = 0.35  # cm (rest) from a margin over which its push fades out on the lid's skin
PROFILE_BINS = 90  # bins of the angle from the gaze axis, 0..90 degrees, for the eyeball's radius
SUNK = 1e-4  # cm: deeper than this counts as sunk (past a micrometre of rounding)


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


class _Eye:
    """One eye's lids: the band of lid vertices around its margins (the margin chain first), each
    one's allowed depth, fall-off weight and nearest margin vertex; the lid things and lids' backs
    that follow the margin."""

    def __init__(self, rest: np.ndarray, skin: np.ndarray, chain: np.ndarray, centre: np.ndarray,
                 apex: int, profile: np.ndarray) -> None:
        self.centre, self.apex, self.profile = centre, apex, profile
        band = skin[cKDTree(rest[chain]).query(rest[skin])[0] < BAND]
        self.band = np.concatenate([chain, band[~np.isin(band, chain)]])  # chain first: its own weight 1
        dist, self.near = cKDTree(rest[chain]).query(rest[self.band])
        self.n_chain = len(chain)
        self.weight = 1.0 - _smoothstep(dist / BAND)
        self.allowed = np.minimum(self.depth(rest[self.band], self.axis(rest)), CLEAR)
        self.things = self.ends = self.t = self.backs = self.back_at = np.zeros(0, np.int64)

    def axis(self, posed: np.ndarray) -> np.ndarray:
        a = np.asarray(posed[self.apex], np.float64) - self.centre
        return a / np.linalg.norm(a)

    def depth(self, p: np.ndarray, axis: np.ndarray) -> np.ndarray:
        """(P,) cm each point lies outside the eyeball's front (negative: inside)."""
        q = p - self.centre
        r = np.linalg.norm(q, axis=1)
        ang = np.degrees(np.arccos(np.clip(q @ axis / np.maximum(r, 1e-9), -1.0, 1.0)))
        return r - np.interp(ang, np.arange(PROFILE_BINS + 1) * (90.0 / PROFILE_BINS), self.profile)

    def pushes(self, posed: np.ndarray) -> np.ndarray | None:
        """(len(band), 3) cm each band vertex moves out along the eyeball's normal, or None when no
        margin sank: onto the front (to its allowed depth) where it sank, and past the margin chain
        at least its weight times its nearest margin vertex's push (the longer of the two)."""
        q = np.asarray(posed[self.band], np.float64) - self.centre
        r = np.linalg.norm(q, axis=1)
        ang = np.degrees(np.arccos(np.clip(q @ self.axis(posed) / np.maximum(r, 1e-9), -1.0, 1.0)))
        front = np.interp(ang, np.arange(PROFILE_BINS + 1) * (90.0 / PROFILE_BINS), self.profile)
        s = front + self.allowed - r
        sunk = s > SUNK
        if not sunk.any():
            return None
        push = np.where(sunk, s / np.maximum(r, 1e-9), 0.0)[:, None] * q
        rest = slice(self.n_chain, None)
        led = self.weight[rest, None] * push[self.near[rest]]
        longer = (led * led).sum(axis=1) > (push[rest] * push[rest]).sum(axis=1)
        push[rest][longer] = led[longer]
        return push


class LidContact:
    """For one scan dressing (a ScanDressing) and the lid margins of its simulated mesh (per eye
    (upper, lower) scan indices, `ScanDressing.eye_margins`): `press(posed)` moves the lids that sank
    into their eyeballs back onto them (in place; returned)."""

    def __init__(self, rest: np.ndarray, margins: Any, dressing: Any) -> None:
        from sim.face.scan.data import PARTS, SCLERA

        rest = np.asarray(rest, np.float64)
        if margins is None or len(margins) != 2:
            raise ValueError("no lid margins of the simulated mesh (per eye its upper and lower margin)")
        skin_of = np.asarray(dressing.skin, np.int64)  # scan index of each simulated vertex
        # the lids' front: the simulated skin (the lids' backs, drawn skin too, follow their margin)
        skin = np.unique(skin_of)
        self.centres = np.asarray(dressing.eye_centres, np.float64)
        self.eyes: list[_Eye] = []
        margin_of = -np.ones(len(rest), np.int64)  # scan vertex -> its place in its eye's chain
        eye_of = -np.ones(len(rest), np.int64)
        for e, ((upper, lower), side) in enumerate(zip(margins, "lr")):
            lo, _ = PARTS[f"eyeball_{side}"]
            shell = rest[lo:lo + SCLERA]
            c = self.centres[e]
            apex = int(np.argmax((shell - c) @ np.array([0.0, 0.0, 1.0]) / np.linalg.norm(shell - c, axis=1)))
            axis = (shell[apex] - c) / np.linalg.norm(shell[apex] - c)
            chain = np.unique(np.concatenate([np.asarray(upper, np.int64), np.asarray(lower, np.int64)]))
            margin_of[chain], eye_of[chain] = np.arange(len(chain)), e
            self.eyes.append(_Eye(rest, skin, chain, c, lo + apex, eyeball_profile(shell, c, axis)))
        # the lid things: from their margin segment's two ends; the lids' backs: from their anchor
        m = np.asarray(dressing.lid_margin, np.int64)
        things, eye = np.asarray(dressing.lid_idx, np.int64), np.asarray(dressing.lid_eye, np.int64)
        ends = np.stack([margin_of[skin_of[m[:, 0]]], margin_of[skin_of[m[:, 1]]]], axis=1)
        if (ends < 0).any():
            raise ValueError("a lid thing of the dressing hangs from outside the lids' margins")
        t = np.asarray(dressing.lid_t, np.float64)
        anchor = skin_of[np.asarray(dressing.lip_anchor, np.int64)]
        backs = np.asarray(dressing.lip_idx, np.int64)
        for e, one in enumerate(self.eyes):
            one.things, one.ends, one.t = things[eye == e], ends[eye == e], t[eye == e]
            one.backs, one.back_at = backs[eye_of[anchor] == e], margin_of[anchor[eye_of[anchor] == e]]
        self._push = np.zeros((max(len(e.band) for e in self.eyes), 3))  # the kernel's scratch

    def press(self, posed: np.ndarray) -> np.ndarray:
        """`posed` (26719, 3), the scan posed (before a head turn), with the lids that sank into
        their eyeballs moved out onto them, their things and backs with them (in place; returned).
        One compiled pass per eye (sim.face.scan.lid_kernel), the steps of `press_steps`."""
        from sim.face.scan.lid_kernel import lid_press

        for e in self.eyes:
            lid_press(posed, e.band, e.allowed, e.weight, e.near, e.n_chain, e.centre, e.apex, e.profile,
                      90.0 / PROFILE_BINS, e.things, e.ends, e.t, e.backs, e.back_at, self._push)
        return posed

    def press_steps(self, posed: np.ndarray) -> np.ndarray:
        """`press` step by step in numpy (the reference its kernel is checked against)."""
        for eye in self.eyes:
            push = eye.pushes(posed)
            if push is None:
                continue
            posed[eye.band] += push
            posed[eye.things] += (1.0 - eye.t)[:, None] * push[eye.ends[:, 0]] + eye.t[:, None] * push[eye.ends[:, 1]]
            posed[eye.backs] += push[eye.back_at]
        return posed
