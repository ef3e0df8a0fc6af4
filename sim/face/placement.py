"""Placing the face's muscles on any mesh from its landmarks.

Every point is a landmark plus an anatomical offset given in centimetres *of a reference face*
(inter-pupillary distance 6.3 cm), scaled by this face's own size, then put on the skin (its depth
taken from the nearest front-facing vertex) and, for skull attachments, pushed behind the skin along
-Z. Nothing refers to vertex numbers, so the same code rigs any head with the landmarks; rig transfer
relies on that.

Landmarks used, from the project vocabulary (`sim.face.transfer.landmarks.LANDMARK_NAMES`), each with a
fallback derived from the mesh's eye loops, mouth loop, eye centres or other landmarks when the mesh
lacks it: eye_inner_l/r, eye_outer_l/r, brow_inner_l/r, brow_outer_l/r, nose_bridge, nose_tip,
nose_wing_l/r, mouth_corner_l/r, upper_lip_center, lower_lip_center, chin.
"""

from __future__ import annotations

import numpy as np

from sim.model import FaceMesh, LinearMuscle, Muscle, PatchMuscle, SheetMuscle, SphincterMuscle
from sim.rowmath import norm3

REFERENCE_IPD = 6.3  # cm, inter-pupillary distance of the reference face the offsets are given on
BASE_FORCE = 3000.0  # dyn/cm^2 of skin, the force density of a muscle of strength 1


class FaceFrame:
    """Landmarks of one mesh in a form placement can use: scaled offsets, skin projection, sides."""

    def __init__(self, mesh: FaceMesh) -> None:
        self.mesh = mesh
        v = mesh.vertices
        self.s = norm3(mesh.eye_centers[0] - mesh.eye_centers[1]) / REFERENCE_IPD
        self.mid_x = float(0.5 * (mesh.eye_centers[0, 0] + mesh.eye_centers[1, 0]))
        self._front_xy = v[:, :2]
        self.points: dict[str, np.ndarray] = {}
        for side, sign, loop in (("l", 1.0, mesh.eye_loops[0]), ("r", -1.0, mesh.eye_loops[1])):
            ring = v[np.asarray(loop)]
            lateral = sign * (ring[:, 0] - self.mid_x)
            self._set(f"eye_inner_{side}", ring[np.argmin(lateral)])
            self._set(f"eye_outer_{side}", ring[np.argmax(lateral)])
            self._set(f"eye_top_{side}", ring[np.argmax(ring[:, 1])])
            self._set(f"eye_bottom_{side}", ring[np.argmin(ring[:, 1])])
        mouth = v[np.asarray(mesh.mouth_loop)]
        self._set("mouth_corner_l", mouth[np.argmax(mouth[:, 0])])
        self._set("mouth_corner_r", mouth[np.argmin(mouth[:, 0])])
        self.mouth_center = 0.5 * (self.get("mouth_corner_l") + self.get("mouth_corner_r"))
        self.mouth_center[1] = float(np.mean(mouth[:, 1]))
        s = self.s
        for side, sign in (("l", 1.0), ("r", -1.0)):
            inner, outer = self.get(f"eye_inner_{side}"), self.get(f"eye_outer_{side}")
            self._set(f"brow_inner_{side}", self.skin(inner + s * np.array([-0.1 * sign, 1.3, 0.0])))
            self._set(f"brow_outer_{side}", self.skin(outer + s * np.array([0.3 * sign, 1.1, 0.0])))
            self._set(f"nose_wing_{side}", None)
        eyes_mid = 0.5 * (self.get("eye_inner_l") + self.get("eye_inner_r"))
        self._set("nose_bridge", self.skin(eyes_mid + s * np.array([0.0, 0.3, 0.0])))
        self._set("nose_tip", self._nose_tip())
        for side, sign in (("l", 1.0), ("r", -1.0)):
            tip = self.get("nose_tip")
            self._set(f"nose_wing_{side}", self.skin(tip + s * np.array([1.6 * sign, -0.4, 0.0])))
        mc = self.mouth_center
        self._set("upper_lip_center", self.skin(mc + s * np.array([0.0, 0.5, 0.0])))
        self._set("lower_lip_center", self.skin(mc + s * np.array([0.0, -0.5, 0.0])))
        self._set("chin", self.skin(mc + s * np.array([0.0, -3.6, 0.0])))

    def _set(self, name: str, fallback: np.ndarray | None) -> None:
        """Prefer the mesh's own landmark; else the fallback (None = decide later)."""
        if name in self.mesh.landmarks:
            self.points[name] = np.array(self.mesh.landmark(name), dtype=np.float64)
        elif fallback is not None:
            self.points[name] = np.array(fallback, dtype=np.float64)

    def get(self, name: str) -> np.ndarray:
        return self.points[name].copy()

    def _nose_tip(self) -> np.ndarray:
        v = self.mesh.vertices
        eyes_y = float(self.mesh.eye_centers[:, 1].mean())
        band = (np.abs(v[:, 0] - self.mid_x) < 0.8 * self.s) & (v[:, 1] < eyes_y) & (
            v[:, 1] > self.mouth_center[1]
        )
        cand = v[band] if band.any() else v
        return cand[np.argmax(cand[:, 2])]

    def skin(self, p: np.ndarray) -> np.ndarray:
        """p moved along Z onto the front of the skin: inverse-distance-weighted z of the vertices
        within 0.4 reference cm (in x, y) of p's nearest vertex, keeping only the front-most layer
        (z within 0.5 cm of the largest) where the surface folds back (lids, lips, nose). Defined by
        distances only, so it is mirror-symmetric and scale-invariant (no tie-breaking by index)."""
        d = np.sqrt(np.sum((self._front_xy - p[:2]) ** 2, axis=1))
        near = d <= d.min() + 0.4 * self.s
        z = self.mesh.vertices[near, 2]
        front = z >= z.max() - 0.5 * self.s
        w = 1.0 / (d[near][front] + 0.05 * self.s)
        return np.array([p[0], p[1], float(np.sum(w * z[front]) / np.sum(w))])

    def at(self, name: str, side: float, dx: float, dy: float, depth: float = 0.0) -> np.ndarray:
        """Landmark + (lateral dx, up dy) reference-face cm, on the skin, then depth cm behind it.
        side: +1 for the face's left, -1 for its right (dx > 0 is away from the midline)."""
        p = self.get(name) + self.s * np.array([side * dx, dy, 0.0])
        q = self.skin(p)
        q[2] -= self.s * depth
        return q


def _linear(f: FaceFrame, name: str, attach: np.ndarray, insert: np.ndarray, *, reach: float = 1.5,
            angle: float = 0.6, eta: float = 1.0, strength: float = 1.0) -> LinearMuscle:
    length = norm3(insert - attach)
    return LinearMuscle(name, attach, insert, reach * length, angle, eta, BASE_FORCE * strength)


def _sheet(f: FaceFrame, name: str, a1: np.ndarray, a2: np.ndarray, i1: np.ndarray, i2: np.ndarray, *,
           width: float, reach: float = 1.35, eta: float = 1.0, strength: float = 1.0) -> SheetMuscle:
    span = norm3(0.5 * (a1 + a2) - 0.5 * (i1 + i2))
    return SheetMuscle(name, a1, a2, i1, i2, reach * span, width * f.s, eta, BASE_FORCE * strength)


def _sphincter(f: FaceFrame, name: str, center: np.ndarray, a: float, b: float,
               strength: float) -> SphincterMuscle:
    major = np.array([1.0, 0.0, 0.0])
    minor = np.array([0.0, 1.0, 0.0])
    return SphincterMuscle(name, center, major, minor, a * f.s, b * f.s, BASE_FORCE * strength)


LID_STRIPS = 9  # sheets across each lid, from the inner to the outer corner
CORNER_BOOST = 0.6  # extra pull of the strips near the canthi, where the lid is held by the corner
LID_MEET = 0.2  # where the lids meet, as a fraction of the opening above the lower margin
INNER_BIAS = 0.4  # the strips pull harder towards the inner canthus and softer towards the outer


def _margins(f: FaceFrame, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An opening's upper and lower margin heights (cm) as functions of x, read off the mesh at
    rest: (xs ascending, upper y, lower y) at the loop's vertices. The loop is split at its
    leftmost and rightmost vertices (the canthi, or the mouth corners)."""
    ring = f.mesh.vertices[np.asarray(loop)]
    tie = 1e-6 * np.abs(ring[:, 1] - ring[:, 1].mean())  # of two equally far vertices, the one
    a, b = int(np.argmin(ring[:, 0] + tie)), int(np.argmax(ring[:, 0] - tie))  # nearer the middle
    lo, hi = min(a, b), max(a, b)
    one, other = ring[lo:hi + 1], np.vstack([ring[hi:], ring[:lo + 1]])
    up, low = (one, other) if one[:, 1].mean() > other[:, 1].mean() else (other, one)
    xs = np.unique(ring[:, 0])
    return xs, np.interp(xs, *_curve(up, np.max)), np.interp(xs, *_curve(low, np.min))


def _curve(p: np.ndarray, pick) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """A margin as y(x): ascending unique x, and where vertices share an x the outermost y."""
    xs = np.unique(p[:, 0])
    return xs, np.array([pick(p[p[:, 0] == x, 1]) for x in xs])


def _lids(f: FaceFrame, side: str, sg: float) -> tuple[Muscle, ...]:
    """Orbicularis oculi pars palpebralis: each lid a row of LID_STRIPS narrow sheets (eqs 18-22)
    pulling the upper lid down and the lower lid up towards the line where they meet (LID_MEET of
    the opening above the lower margin), each strip as strong as the opening is high at its
    centre, so every part of the margin travels its own share of the opening and the lids meet
    along the whole lid line while the canthi (tied to the bone by their tendons) stay put.

    Why not eq 14's sphincter: its pull towards one centre point drags the lid corners inwards as
    hard as the margins down, and the closed lids crumpled into a star around that point. One sheet
    of uniform strength per lid pulled the corners down as far as the middle, and the triangles at
    the canthi folded over. The palpebral fibres run along the lids; a curved band of them that
    shortens flattens the lid onto the eyeball, hardest where the lid is most curved away from
    the meeting line."""
    s = f.s
    xs, top, bottom = _margins(f, f.mesh.eye_loops[0 if side == "l" else 1])
    inner, outer = f.get(f"eye_inner_{side}")[0], f.get(f"eye_outer_{side}")[0]
    x_in, x_out = inner - sg * 0.1 * s, outer + sg * 0.1 * s
    edges = np.linspace(x_in, x_out, LID_STRIPS + 1)
    h_max = float(np.max(top - bottom))
    centre = f.mesh.eye_centers[0 if side == "l" else 1]
    radius = f.mesh.eye_radius + 0.1 * s
    parts: list[Muscle] = []
    for k, (x0, x1) in enumerate(zip(edges[:-1], edges[1:])):
        xc = 0.5 * (x0 + x1)
        t, b = float(np.interp(xc, xs, top)), float(np.interp(xc, xs, bottom))
        height = max(t - b, 0.0) / h_max
        # near the canthi the skin is held by its neighbours at the fixed corner, so the same
        # force moves it less: the end strips pull harder than their height alone would ask
        share = height * (1.0 + CORNER_BOOST * (1.0 - height))
        # the inner half of the upper lid runs down the steeper side of the eyeball and is held
        # by the medial canthal tendon: with one strength along the lid it stayed open at the
        # inner corner while the outer half closed past the lower lid
        share *= 1.0 + INNER_BIAS * (1.0 - 2.0 * (k + 0.5) / LID_STRIPS)
        if height < 0.05:
            continue
        meet = b + LID_MEET * (t - b)
        # the attachment line lies where the lids meet, on the front of the eyeball (lid thickness
        # 1 mm): the pull then has the forward component that keeps a closing lid on the eyeball
        # instead of driving it through the eyeball along the chord
        za = float(centre[2] + np.sqrt(max(radius**2 - (meet - centre[1]) ** 2 - (xc - centre[0]) ** 2, 0.0)))
        # towards the canthi the eyeball falls away behind the skin: an attachment on it there
        # pulled the corner strips back into the globe's edge, the eyeball contact pushed them out
        # along its normal, and the upper margin next to the inner canthus slid past the corner
        za = max(za, float(f.skin(np.array([xc, meet, 0.0]))[2]) - 0.1 * s)
        a1, a2 = np.array([x0, meet, za]), np.array([x1, meet, za])
        width = abs(x1 - x0) / s
        parts.append(_sheet(f, f"orbicularis_oculi_lid_upper_{side}_{k}", a1, a2,
                            f.skin(np.array([x0, t + 0.3 * s, 0.0])), f.skin(np.array([x1, t + 0.3 * s, 0.0])),
                            width=width, reach=1.7, strength=3.0 * share))
        parts.append(_sheet(f, f"orbicularis_oculi_lid_lower_{side}_{k}", a1, a2,
                            f.skin(np.array([x0, b - 0.3 * s, 0.0])), f.skin(np.array([x1, b - 0.3 * s, 0.0])),
                            width=width, reach=1.6, strength=1.575 * share))
    return tuple(parts)


LOWER_LID_STRENGTH = 2.0  # the lower lid tightener's push (BASE_FORCE units) at its centre


def _lower_lid_tightener(f: FaceFrame, side: str, sg: float) -> tuple[Muscle, ...]:
    """The lower lid's palpebral orbicularis (AU7) as its own channel: its fibres arc under the eye
    from the lateral raphe to the medial canthal tendon, and tightening straightens the arc, which
    lifts the lower lid up the globe's front. A push up over the lower lid, below its margin."""
    xs, _, bottom = _margins(f, f.mesh.eye_loops[0 if side == "l" else 1])
    x = 0.5 * (f.get(f"eye_inner_{side}")[0] + f.get(f"eye_outer_{side}")[0])
    centre = f.skin(np.array([x, float(bottom.min()) - 0.2 * f.s, 0.0]))
    d = np.array([0.0, 1.0, 0.2])
    return (PatchMuscle(f"orbicularis_oculi_lower_lid_{side}", centre, f.s * np.array([0.9, 0.4, 1.0]),
                        d / np.linalg.norm(d), BASE_FORCE * LOWER_LID_STRENGTH),)


RAISER_STRIPS = 5  # sheets across the upper lid's middle, the levator's aponeurosis


def _lid_raiser(f: FaceFrame, side: str, sg: float) -> tuple[Muscle, ...]:
    """Levator palpebrae superioris (AU5): its aponeurosis spreads across the upper lid and pulls
    it up and back into the orbit, under the brow. A row of narrow sheets over the lid's middle
    (the canthi stay tied to the bone), each attached deep under the orbital rim above its part
    of the lid and inserted along the lid just above the margin, as strong as the lid is high
    there, so the margin rises as a curve and the fold above it deepens."""
    s = f.s
    xs, top, bottom = _margins(f, f.mesh.eye_loops[0 if side == "l" else 1])
    inner, outer = f.get(f"eye_inner_{side}")[0], f.get(f"eye_outer_{side}")[0]
    edges = np.linspace(inner + 0.15 * (outer - inner), outer - 0.1 * (outer - inner), RAISER_STRIPS + 1)
    h_max = float(np.max(top - bottom))
    parts: list[Muscle] = []
    for k, (x0, x1) in enumerate(zip(edges[:-1], edges[1:])):
        xc = 0.5 * (x0 + x1)
        t, b = float(np.interp(xc, xs, top)), float(np.interp(xc, xs, bottom))
        share = max(t - b, 0.0) / h_max
        y_att = t + RAISER_RISE * s
        z_att = float(f.skin(np.array([xc, y_att, 0.0]))[2]) - RAISER_DEPTH * s
        a1, a2 = np.array([x0, y_att, z_att]), np.array([x1, y_att, z_att])
        i1, i2 = f.skin(np.array([x0, t + 0.1 * s, 0.0])), f.skin(np.array([x1, t + 0.1 * s, 0.0]))
        parts.append(_sheet(f, f"levator_palpebrae_{side}_{k}", a1, a2, i1, i2,
                            width=abs(x1 - x0) / s, reach=1.5, strength=RAISER_STRENGTH * share))
    return tuple(parts)


RAISER_RISE = 0.9  # cm (reference face) above the margin where the aponeurosis runs under the rim
RAISER_DEPTH = 0.4  # cm behind the skin there (inside the orbit)
RAISER_STRENGTH = 0.85

LIP_FIBRES = 15  # linear fibres along the mouth line, corner to corner
PRESS_DEPTH = 0.7  # cm of a reference face: how far behind the mouth line they are attached


def _lip_press(f: FaceFrame, strength: float) -> tuple[Muscle, ...]:
    """The marginal part of orbicularis oris (AU23/24 press and tighten the lips): LIP_FIBRES
    linear fibres (eqs 9-13) along the mouth line, each attached PRESS_DEPTH behind the line and
    inserted on it, so its pull takes both lips back against the teeth and onto the line between
    them. Their cones overlap, so the pull varies smoothly along the mouth, strongest in the
    middle and fading towards the corners. The ring of eq 14 alone dragged the corners inwards
    while the lip centres stayed, and the lips bunched into zig-zags; narrow sheets side by side
    made steps (a vertex on a step was pulled by both). `strength` is that of 7 fibres: the total
    does not change with LIP_FIBRES."""
    s = f.s
    xs, top, bottom = _margins(f, f.mesh.mouth_loop)
    mid, half = 0.5 * (xs[-1] + xs[0]), 0.5 * (xs[-1] - xs[0])
    parts: list[Muscle] = []
    for k, u in enumerate(np.linspace(-0.8, 0.8, LIP_FIBRES)):
        x = float(mid + u * half)
        share = float(np.sqrt(1.0 - u * u))
        line = 0.5 * (float(np.interp(x, xs, top)) + float(np.interp(x, xs, bottom)))
        insert = f.skin(np.array([x, line, 0.0]))
        attach = insert - np.array([0.0, 0.0, PRESS_DEPTH * s])
        parts.append(_linear(f, f"orbicularis_oris_press_{k}", attach, insert, reach=1.5,
                             angle=0.9, strength=strength * share * 7.0 / LIP_FIBRES))
    return tuple(parts)


def _side_muscles(f: FaceFrame, side: str, sg: float) -> dict[str, tuple[Muscle, ...]]:
    """The paired muscles of one side (sg = +1 left, -1 right)."""
    out: dict[str, tuple[Muscle, ...]] = {}
    bi, bo = f"brow_inner_{side}", f"brow_outer_{side}"
    mc = f"mouth_corner_{side}"
    eye_c = f.mesh.eye_centers[0 if side == "l" else 1]
    f.points[f"eye_center_{side}"] = np.array(eye_c, dtype=np.float64)
    ec = f"eye_center_{side}"
    out[f"frontalis_inner_{side}"] = (_sheet(
        f, f"frontalis_inner_{side}",
        f.at(bi, sg, -0.6, 4.5, 0.3), f.at(bi, sg, 1.1, 4.6, 0.3),
        f.at(bi, sg, -0.6, -0.2), f.at(bi, sg, 1.1, 0.0), width=1.9, strength=1.95),)
    out[f"frontalis_outer_{side}"] = (_sheet(
        f, f"frontalis_outer_{side}",
        f.at(bo, sg, -2.0, 4.3, 0.3), f.at(bo, sg, 0.2, 4.0, 0.3),
        f.at(bo, sg, -2.0, 0.2), f.at(bo, sg, 0.2, 0.0), width=2.5, strength=1.25),)
    out[f"corrugator_{side}"] = (_linear(
        f, f"corrugator_{side}", f.at(bi, sg, -0.9, -0.5, 0.5), f.at(bi, sg, 0.6, 0.2),
        reach=1.8, angle=0.7, strength=2.2), _linear(
        f, f"depressor_supercilii_{side}", f.at(bi, sg, -0.3, -1.7, 0.4), f.at(bi, sg, 0.4, 0.3),
        reach=1.6, angle=0.7, strength=1.3))
    out[f"orbicularis_oculi_{side}"] = (_sphincter(
        f, f"orbicularis_oculi_{side}", f.at(ec, sg, 0.1, 0.4), 3.0, 2.4, 1.2),)
    out[f"orbicularis_oculi_lid_{side}"] = _lids(f, side, sg)
    out[f"levator_palpebrae_{side}"] = _lid_raiser(f, side, sg)
    out[f"orbicularis_oculi_lower_lid_{side}"] = _lower_lid_tightener(f, side, sg)
    out[f"levator_labii_alaeque_nasi_{side}"] = (_linear(
        f, f"levator_labii_alaeque_nasi_{side}", f.at(f"eye_inner_{side}", sg, -0.3, -0.2, 0.4),
        f.at(f"nose_wing_{side}", sg, 0.0, -0.2), reach=1.3, angle=0.35, strength=1.3),)
    out[f"levator_labii_{side}"] = (_linear(
        f, f"levator_labii_{side}", f.at(ec, sg, -0.2, -1.7, 0.4), f.at(mc, sg, -1.1, 0.6),
        reach=1.25, angle=0.4, strength=1.2),)
    out[f"zygomaticus_minor_{side}"] = (_linear(
        f, f"zygomaticus_minor_{side}", f.at(ec, sg, 1.1, -2.2, 0.4), f.at(mc, sg, -0.5, 0.5),
        reach=1.25, angle=0.35, strength=1.0),)
    out[f"zygomaticus_major_{side}"] = (_linear(
        f, f"zygomaticus_major_{side}", f.at(f"eye_outer_{side}", sg, 1.3, -2.9, 0.5),
        f.at(mc, sg, 0.1, 0.0), reach=1.3, angle=0.45, strength=2.2),)
    out[f"levator_anguli_oris_{side}"] = (_linear(
        f, f"levator_anguli_oris_{side}", f.at(mc, sg, -0.4, 2.8, 0.5), f.at(mc, sg, 0.0, 0.1),
        reach=1.3, angle=0.4, strength=1.2),)
    out[f"buccinator_{side}"] = (_linear(
        f, f"buccinator_{side}", f.at(mc, sg, 3.0, 0.0, 1), f.at(mc, sg, 0.1, 0.0),
        reach=1.3, angle=0.4, strength=1.2),)
    out[f"depressor_anguli_oris_{side}"] = (_linear(
        f, f"depressor_anguli_oris_{side}", f.at(mc, sg, 0.6, -3.0, 0.4), f.at(mc, sg, 0.0, -0.1),
        reach=1.3, angle=0.4, strength=1.4),)
    out[f"depressor_labii_{side}"] = (_linear(
        f, f"depressor_labii_{side}", f.at("lower_lip_center", sg, 1.1, -3.0, 0.4),
        f.at("lower_lip_center", sg, 0.7, -0.1), reach=1.3, angle=0.4, strength=1.2),)
    out[f"risorius_{side}"] = (_linear(
        f, f"risorius_{side}", f.at(mc, sg, 3.4, 0.2, 0.4), f.at(mc, sg, 0.1, 0.0),
        reach=1.3, angle=0.35, strength=1.2),)
    return out


def place_muscles(mesh: FaceMesh) -> dict[str, tuple[Muscle, ...]]:
    """Channel name -> muscle parts, placed from the mesh's landmarks (see the module docstring)."""
    from sim.channels import HALVES, MUSCLE_CHANNELS

    f = FaceFrame(mesh)
    out: dict[str, tuple[Muscle, ...]] = {}
    out.update(_side_muscles(f, "l", 1.0))
    out.update(_side_muscles(f, "r", -1.0))
    out["procerus"] = (_linear(
        f, "procerus", f.at("nose_bridge", 1.0, 0.0, -1.8, 0.4), f.at("nose_bridge", 1.0, 0.0, 1.0),
        reach=1.35, angle=0.4, strength=2.2),)
    out["mentalis"] = (_sheet(
        f, "mentalis",
        f.at("lower_lip_center", 1.0, 0.9, -1.2, 0.5), f.at("lower_lip_center", -1.0, 0.9, -1.2, 0.5),
        f.at("chin", 1.0, 1.0, 0.3), f.at("chin", -1.0, 1.0, 0.3), width=2.4, reach=1.5,
        strength=1.2),)
    half_mouth = 0.5 * abs(f.get("mouth_corner_l")[0] - f.get("mouth_corner_r")[0]) / f.s
    out["orbicularis_oris"] = (_sphincter(
        f, "orbicularis_oris", f.skin(f.mouth_center), half_mouth + 0.7, 1.9, 0.3),
        *_lip_press(f, 1.2))
    from sim.face.mouth_actions import mouth_actions

    out.update(mouth_actions(f))
    return {name: out[name] for name in MUSCLE_CHANNELS if name not in HALVES}  # halves: sim.build
