"""Softening the upper face's and the nose's base's buckles before the scanned head is shaded
(render.scan_draw).

The simulated skin, compressed by the brows' muscles, can buckle between a few of its vertices: in
anger and disgust a sharp V of ridges at the glabella, drawn as a hard dark seam where the scan
folds softly (docs/rendering.md, "The upper face's buckles softened"). (Higher up the forehead's
bound layer, `sim.antifold.bound_layer`, bends stiffly enough in the simulation itself: the drawing
leaves it as simulated.)

Here, on the brows, the skin just above them, the glabella and the nasal root (away from the lids),
and on the nose's base (where disgust's raised upper lip crumples the nostril sills), the posed
scan's displacement from rest is split into a smooth part (a Gaussian average over the rest skin,
SIGMA wide) and what is left (the buckles, and a scan's own fine lines); the residual keeps its
direction but its length goes through a soft limit (LIMIT tanh(r / LIMIT); between the brows and on the nose's base a wider
Gaussian and a firmer limit, WIDE_* and NOSE_*): fine lines of a few tenths of a millimetre stay
nearly whole, a buckle of 2-3 mm becomes a soft fold of about LIMIT. The normals and fold terms
are then made from the softened surface as before, and how deep the skin around each vertex lay
in its buckle's folds (spread by the same Gaussian) adds a soft shadow over it (`shade`). Only the drawing is changed: the simulation, its bits and the
exported vertices (`ScanDressing.pose`) are not.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

SIGMA = 0.5  # cm: the Gaussian's width (the skin's edges there are about 0.37 cm)
REACH = 1.5  # sigmas: the Gaussian is cut off beyond this distance (at 2: the same look by eye, 1.35x the work)
LIMIT = 0.05  # cm: a residual this long keeps three quarters of its length, a longer one at most this
LID_CLEAR = (1.0, 1.8)  # cm from the lid margins: nothing changed nearer, all of it beyond
BELOW_EYES = 0.8  # cm below the eyes' centres at which it starts (fading in over the same span)
TOP = (3.5, 4.5)  # cm above the eyes' centres over which it fades out: above it the skin is the
# forehead's bound layer (sim.antifold.bound_layer, all of it from 4 cm up), whose own bending keeps
# it from buckling, drawn as simulated (to the hairline before: 10.5-11.5 cm)
CREASE_FOLD = 0.15  # the fold term (render.scan_shaders: 1.8 of it darkens) at most added for a softened fold
CREASE_DEPTH = 0.1  # cm: the (spread) depth of softened folds that adds three quarters of CREASE_FOLD
SIDE = 6.5  # cm from the midline: no further (the temples)
# between the brows' heads (centred between the glabella and the nasion, all of it within WIDE_HALF
# across and up and down, fading over WIDE_FADE beyond) the corrugators and procerus fold the skin into
# a V whose bottom is an edge or two wide, drawn as a dark seam: a wider Gaussian and a firmer limit
# there make it a softer fold (wider or firmer, the observer reads anger's V as neutral: docs/rendering.md)
WIDE_SIGMA = 0.7  # cm
WIDE_LIMIT = 0.03  # cm
WIDE_HALF = (0.4, 1.0)  # cm: across, up and down
WIDE_FADE = (0.6, 0.6)  # cm
# the nose's base: the upper lip raised into it crumples the nostril sills into a pleat a few edges
# (1-2 mm) wide; a box around a point NOSE_CENTRE from the subnasale, all of it within 0.7 of
# NOSE_HALF (x, y, z) and fading out at NOSE_HALF
NOSE_SIGMA = 0.3  # cm
NOSE_LIMIT = 0.02  # cm
NOSE_CENTRE = (0.0, 0.35, -0.2)  # cm
NOSE_HALF = (1.7, 0.8, 1.0)  # cm


def _smoothstep(x: np.ndarray) -> np.ndarray:
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


class FoldSoftener:
    """For one rest pose of the scan (a ScanLook): `soften(posed)` gives the posed scan with the
    upper face's buckles softened (a new array; `posed` is left as it is)."""

    def __init__(self, look: object) -> None:
        from render.scan_look import eye_centres
        from sim.build import vertex_normals

        rest = np.asarray(look.rest, np.float64)  # type: ignore[attr-defined]
        n = len(rest)
        skin = np.zeros(n, bool)
        skin[look.groups["skin"].ravel()] = True  # type: ignore[attr-defined]
        eyes = eye_centres(rest)
        eye_y = float(eyes[:, 1].mean())
        margins = [np.asarray(lp) for lp in look.openings  # type: ignore[attr-defined]
                   if np.min(np.linalg.norm(rest[np.asarray(lp)].mean(axis=0) - eyes, axis=1)) < 1.5]
        if len(margins) != 2:
            raise ValueError(f"the scan's skin has {len(margins)} openings at the eyes, expected 2")
        lid = cKDTree(rest[np.concatenate(margins)]).query(rest)[0]
        y = rest[:, 1] - eye_y
        w = (_smoothstep((lid - LID_CLEAR[0]) / (LID_CLEAR[1] - LID_CLEAR[0]))
             * _smoothstep((y + BELOW_EYES) / BELOW_EYES)
             * (1.0 - _smoothstep((y - TOP[0]) / (TOP[1] - TOP[0])))
             * (1.0 - _smoothstep((np.abs(rest[:, 0]) - SIDE + 0.5) / 0.5))
             * (skin & (rest[:, 2] > eyes[:, 2].mean() - 4.0)))
        from sim.face.scan.anatomy import load_landmarks

        marks = load_landmarks()
        gl = 0.5 * (rest[marks["glabella"]] + rest[marks["nose_bridge"]])
        wide = ((1.0 - _smoothstep((np.abs(rest[:, 0] - gl[0]) - WIDE_HALF[0]) / WIDE_FADE[0]))
                * (1.0 - _smoothstep((np.abs(rest[:, 1] - gl[1]) - WIDE_HALF[1]) / WIDE_FADE[1])))
        sigma = SIGMA + (WIDE_SIGMA - SIGMA) * wide
        limit = LIMIT + (WIDE_LIMIT - LIMIT) * wide
        base = np.abs(rest - (rest[marks["subnasale"]] + NOSE_CENTRE)) / NOSE_HALF
        nose = np.prod(1.0 - _smoothstep((base - 0.7) / 0.3), axis=1) * skin
        sigma = np.where(nose > w, NOSE_SIGMA, sigma)
        limit = np.where(nose > w, NOSE_LIMIT, limit)
        w = np.maximum(w, nose)
        zone = np.flatnonzero(w > 0.0)
        skin_v = np.flatnonzero(skin)
        near = cKDTree(rest[skin_v]).query_ball_point(rest[zone], REACH * sigma[zone])
        cols = [skin_v[np.asarray(j, np.int64)] for j in near]
        count = np.array([len(c) for c in cols])
        rows = np.repeat(np.arange(len(zone)), count)
        flat = np.concatenate(cols)
        g = np.exp(-0.5 * np.sum((rest[flat] - rest[zone[rows]]) ** 2, axis=1) / sigma[zone[rows]] ** 2)
        g /= np.bincount(rows, g)[rows]
        self.zone = zone.astype(np.int32)
        self.ptr = np.concatenate([[0], np.cumsum(count)]).astype(np.int32)
        self.cols = flat.astype(np.int32)
        self.gauss = g.astype(np.float32)
        self.weight = w[zone].astype(np.float32)
        self.limit = limit[zone].astype(np.float32)
        self.rest = rest.astype(np.float32)
        self.support = np.unique(np.concatenate([flat, zone])).astype(np.int32)
        self.disp = np.zeros((n, 4), np.float32)
        normal = vertex_normals(rest, np.asarray(look.groups["skin"]))  # type: ignore[attr-defined]
        self.normal = normal[zone].astype(np.float32)
        self.crease = np.zeros(len(zone), np.float32)

    def soften(self, posed: np.ndarray) -> np.ndarray:
        """(N, 3) float32: `posed` with the residual of its displacement from rest on the upper face
        (what the Gaussian average leaves) limited softly to LIMIT, faded by the zone's weight."""
        from render.soften_kernel import soften_zone

        p = np.ascontiguousarray(posed, np.float32)
        out = p.copy()
        soften_zone(p, self.rest, self.support, self.zone, self.ptr, self.cols, self.gauss, self.weight,
                    self.normal, self.limit, np.float32(CREASE_FOLD), np.float32(CREASE_DEPTH), self.disp, out,
                    self.crease)
        return out

    def shade(self, rows: np.ndarray) -> np.ndarray:
        """`rows` (the renderer's x y z nx ny nz fold, made from the last `soften`'s output) with the
        softened folds' depth, spread by the Gaussian, added to the fold term (CREASE_FOLD
        tanh(depth / CREASE_DEPTH)): skin that buckled keeps a soft, broad shadow, not a seam."""
        rows[self.zone, 6] += self.crease
        return rows
