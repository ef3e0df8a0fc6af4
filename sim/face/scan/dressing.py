"""Posing the whole scanned head from its simulated skin: `ScanDressing.pose(surface, control)`
gives all 26719 vertices in the scan's order.

- The simulated skin (`sim.face.scan.anatomy.skin_layout`) is copied.
- The inside of the lips and the back of the lids follow their opening: each vertex takes the
  motion of the opening's vertex nearest to it along the mesh (so it stays with its own lip or
  lid) and turns with the jaw as that vertex's jaw weight says.
- Lid things (eyelashes, eye occlusion, lacrimal fluid, eye blend) hang from their nearest point
  of the eye's margin (a lash's every row from its root's point, on its own lid) in a frame
  along the margin: as a lid closes its lashes turn with the margin about the eyeball's centre
  (the scan's own blink moves them so), as it opens they keep the frame of the lid's surface
  `LID_UP` rows up at rest, turning with the margin only (the scan's widened eye's lid surface
  turns 1 degree; the simulated one folds back further); the face area's unsimulated skin within `BIND` of the simulated skin keeps its offset
  in the frame of its nearest skin triangle.
- The rest of the face area, head and neck and the eye sockets follow the skin's nearest vertices
  as the procedural face's head does (`sim.face.head`): their displacement, fading over
  `FOLLOW` cm, and over `JAW_FOLLOW` under the chin and down the throat.
- Upper teeth stay with the skull; lower teeth turn and slide with the jaw exactly as the skin's
  jaw targets do (`sim.integrator.jaw_rotation`, `jaw_slide`); gums and tongue by their height
  between the teeth rows (or the nearer row); the mouth socket as the gums, and near the lips as
  the lips.
- The tongue (the gums-and-tongue part away from the teeth, inside the lower arch) slides out with
  `tongue_out` (AU19): forward along the mouth and a little down, its tip most and its root not at
  all, narrowing as it stretches, over the jaw's share it follows; AU19 parts the lips and drops the jaw a
  little (`sim.facs`), so it shows between them.
- The eyeballs (sclera and iris) turn about their centres by `eyes_yaw` / `eyes_pitch` (30 and 20
  degrees at full value, as the renderer turns the procedural face's eyes), each eye's yaw with the
  `eyes_vergence` (`sim.gaze_lids.eye_yaws`).
`turn_head` applies a rigid head turn about a neck pivot, fading down the neck.
"""

from __future__ import annotations

from functools import cached_property

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from sim.face.scan.anatomy import _rings, skin_layout
from sim.face.scan.data import N_IDENTITIES, NARROW_FACE, PARTS, SCLERA, lash_strips, scan_data
from sim.gaze_lids import PITCH_MAX as EYE_PITCH_MAX
from sim.gaze_lids import YAW_MAX as EYE_YAW_MAX

BIND = 0.5  # cm: unsimulated face skin this close to the simulated skin is bound to its triangles
FOLLOW = 4.0  # cm over which the skin's displacement fades into the held head
JAW_FOLLOW = 8.5  # cm: the same under the chin and jaw, down the throat
NEAREST = 4  # skin vertices a following vertex takes its displacement from
LIP_FADE = 1.2  # cm: how far into the mouth socket the lips' motion reaches
LID_UP = 3  # rows up the lid from its margin: with the margin's tangent, the opening lid's frame (at rest)
LID_OPEN = 0.3  # cm the margin moves away from the opening's middle as its things go over to that frame
LID_THINGS = ("eyelashes", "eye_occlusion", "lacrimal", "eye_blend")
TONGUE_REACH = np.array([0.0, 0.95, 3.2])  # cm the tongue's tip moves at tongue_out = 1 (head frame),
# on top of the jaw's share it follows: up over the lower teeth and out between the parted lips
# (2.6 forward until the jaw's hinge was fitted to the scan's jawOpen, `sim.face.scan.jaw_fit`: AU19's
# jaw 0.35 now carries the tip 6.4 mm further back, and at 2.6 it came 4 mm past the lips, not 5)
TONGUE_NARROW = 0.25  # its tip's width shrinks by this share as it stretches out
TONGUE_ROOT, TONGUE_TIP = 6.0, 9.6  # cm (z): where its motion starts, where it is whole
TONGUE_FLOOR = 1.3  # cm below the teeth's occlusal plane: the floor of the mouth, which stays
TEETH_SPLIT = PARTS["teeth"][0] + 2208  # the first lower tooth (the upper 16 teeth have 2208 vertices)
FloatArray = np.ndarray


def _smoothstep(x: FloatArray) -> FloatArray:
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _frames(p: FloatArray) -> FloatArray:
    """(P,3,3) rows (t1, t2, n) of triangles (P,3,3): t1 along the first edge, n the normal."""
    e1 = p[:, 1] - p[:, 0]
    n = np.cross(e1, p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    t1 = e1 / np.linalg.norm(e1, axis=1)[:, None]
    return np.stack([t1, np.cross(n, t1), n], axis=1)


def _eye_rotations(control: Any) -> tuple[FloatArray, bool]:
    """((2,3,3) each eyeball's rotation, left then right; whether either turns) for the control's
    gaze, as the renderer turns the eyes: each eye's yaw is the gaze's with the vergence
    (`sim.gaze_lids.eye_yaws`), the pitch shared."""
    from sim.gaze_lids import eye_yaws

    yaw = float(np.clip(control.get("eyes_yaw"), -1.0, 1.0))
    verge = float(np.clip(control.get("eyes_vergence"), -1.0, 1.0))
    pitch = float(np.clip(control.get("eyes_pitch"), -1.0, 1.0)) * EYE_PITCH_MAX
    yaws = eye_yaws(yaw, verge)
    if not (any(yaws) or pitch):
        return np.stack([np.eye(3), np.eye(3)]), False
    return np.stack([rotation(y * EYE_YAW_MAX, 0.0, 0.0) @ rotation(0.0, -pitch, 0.0) for y in yaws]), True


def _range(part: str) -> np.ndarray:
    lo, hi = PARTS[part]
    return np.arange(lo, hi)


def rotation(yaw: float, pitch: float, roll: float) -> FloatArray:
    """(3,3): turn about +Y by yaw (the front towards +X), then about +X by pitch (the front down),
    then about +Z by roll, all in rad."""
    cy, sy, cp, sp, cr, sr = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    rz = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    return rz @ rx @ ry


@dataclass(frozen=True, eq=False)
class ScanDressing:
    """Everything needed to pose the scan from a simulated surface. Arrays are in cm.

    rest (26719,3): the identity's rest head; skin (N,): scan index of each simulated vertex.
    lip_idx (L,), lip_anchor (L,) sim vertex, lip_rot (L,) jaw weight of the anchor.
    bound_idx (B,), bound_tri (B,3) sim vertices, bound_bary (B,3), bound_local (B,3).
    lid_idx (D,), lid_margin (D,4) sim vertices: the ends of the eye opening's segment each lid
    thing hangs from and the lid's vertices `LID_UP` rows up from either end, lid_t (D,) where on
    the segment, lid_eye (D,) 0 left / 1 right, lid_local (D,2,3) the offset in the closing and the
    opening frame, lid_open (D,3) away from the opening's middle at rest, over `LID_OPEN`.
    follow_idx (F,), follow_src (F,K) sim vertices, follow_w (F,K) weights (summing to the fade).
    jaw_idx (J,), jaw_w (J,): rigid followers of the jaw (weight 1: lower teeth).
    tongue_idx (T,), tongue_w (T,): the tongue's vertices and their share of `tongue_out`'s motion.
    socket_idx (S,), socket_anchor (S,) scan index of the nearest lip-inside rim vertex, socket_fade (S,).
    eye_idx: two (E,) index arrays; eye_centres (2,3).
    eye_margins: per eye (left, right) its (upper, lower) lid margin, scan indices from the inner
    corner to the outer: the simulated mesh's eye loop split at its corner landmarks.
    jaw_pivot, jaw_axis (3,), jaw_max_angle rad, jaw_slide (3,) cm at jaw = 1.
    neck_pivot (3,), neck_base_y, neck_top_y: the head turn's pivot and its fade down the neck.
    """

    rest: FloatArray
    skin: np.ndarray
    lip_idx: np.ndarray
    lip_anchor: np.ndarray
    lip_rot: FloatArray
    bound_idx: np.ndarray
    bound_tri: np.ndarray
    bound_bary: FloatArray
    bound_local: FloatArray
    lid_idx: np.ndarray
    lid_margin: np.ndarray
    lid_t: FloatArray
    lid_eye: np.ndarray
    lid_local: FloatArray
    lid_open: FloatArray
    follow_idx: np.ndarray
    follow_src: np.ndarray
    follow_w: FloatArray
    jaw_idx: np.ndarray
    jaw_w: FloatArray
    tongue_idx: np.ndarray
    tongue_w: FloatArray
    socket_idx: np.ndarray
    socket_anchor: np.ndarray
    socket_fade: FloatArray
    eye_idx: tuple[np.ndarray, np.ndarray]
    eye_centres: FloatArray
    eye_margins: tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
    jaw_pivot: FloatArray
    jaw_axis: FloatArray
    jaw_max_angle: float
    jaw_slide: FloatArray
    neck_pivot: FloatArray
    neck_base_y: float
    neck_top_y: float

    def jaw_motion(self, jaw: float) -> tuple[FloatArray, FloatArray]:
        """(rotation (3,3), translation (3,)) of the mandible at `jaw`: p -> R p + t."""
        from sim.integrator import jaw_rotation

        if jaw == 0.0:
            return np.eye(3), np.zeros(3)
        rot = jaw_rotation(self.jaw_axis, jaw * self.jaw_max_angle)
        return rot, self.jaw_pivot - rot @ self.jaw_pivot + jaw * self.jaw_slide

    @cached_property
    def _rest64(self) -> FloatArray:
        return np.ascontiguousarray(self.rest, np.float64)

    @cached_property
    def _lid_rest_normals(self) -> FloatArray:
        """(D,2,3) the closing and the opening frame's normal of each lid thing at rest (the opening
        frame keeps its own: `_lid_frames`)."""
        closing, opening, _ = _lid_frames(self.rest[self.skin].astype(np.float64), self.lid_margin, self.lid_t,
                                          self.eye_centres[self.lid_eye])
        return np.ascontiguousarray(np.stack([closing[:, 2], opening[:, 2]], axis=1))

    @cached_property
    def _kernel_args(self) -> tuple:  # type: ignore[type-arg]
        c = np.ascontiguousarray
        return (c(self.skin, np.int64), c(self.lip_idx, np.int64),
                c(self.lip_anchor, np.int64), c(self.lip_rot, np.float64), c(self.bound_idx, np.int64),
                c(self.bound_tri, np.int64), c(self.bound_bary, np.float64), c(self.bound_local, np.float64),
                c(self.lid_idx, np.int64), c(self.lid_margin, np.int64), c(self.lid_t, np.float64),
                c(self.lid_eye, np.int64), c(self.lid_local, np.float64), c(self.lid_open, np.float64),
                c(self.eye_centres, np.float64), c(self._lid_rest_normals, np.float64),
                c(self.follow_idx, np.int64), c(self.follow_src, np.int64), c(self.follow_w, np.float64),
                c(self.jaw_idx, np.int64), c(self.jaw_w, np.float64), c(self.socket_idx, np.int64),
                c(self.socket_anchor, np.int64), c(self.socket_fade, np.float64))

    def pose(self, surface: FloatArray, control: Any) -> FloatArray:
        """(26719,3) float32: the scan posed by the simulated `surface` (N,3) and the control's jaw
        and eyes (a FaceControl, or anything with `get(name)`); one compiled pass
        (`sim.face.scan.pose_kernel`), the steps of `pose_steps`."""
        from sim.face.scan.pose_kernel import pose_scan

        x = np.ascontiguousarray(surface, dtype=np.float64)
        rot, shift = self.jaw_motion(float(control.get("jaw")))
        eye_rot, turned = _eye_rotations(control)
        n = len(self.rest)
        out = np.empty((n, 3), np.float32)
        tongue = float(np.clip(control.get("tongue_out"), 0.0, 1.0))
        pose_scan(self._rest64, x, *self._kernel_args, np.ascontiguousarray(rot, np.float64), np.ascontiguousarray(shift, np.float64),
                  np.ascontiguousarray(self.tongue_idx, np.int64), np.ascontiguousarray(self.tongue_w, np.float64),
                  tongue, np.ascontiguousarray(TONGUE_REACH, np.float64), float(TONGUE_NARROW),
                  np.ascontiguousarray(self.eye_idx[0], np.int64), np.ascontiguousarray(self.eye_idx[1], np.int64),
                  np.ascontiguousarray(self.eye_centres, np.float64), np.ascontiguousarray(eye_rot, np.float64),
                  turned, np.empty((len(x), 3)), np.empty((n, 3)), out)
        return out

    def pose_steps(self, surface: FloatArray, control: Any) -> FloatArray:
        """`pose` step by step in numpy (the reference its kernel is checked against)."""
        x = np.asarray(surface, dtype=np.float64)
        out = self.rest.copy()
        out[self.skin] = x
        d = x - self.rest[self.skin]
        rot, shift = self.jaw_motion(float(control.get("jaw")))
        turn = rot - np.eye(3)
        # the inside of the lips: the anchor's motion, turned with the jaw about the anchor
        p = self.rest[self.lip_idx]
        a0 = self.rest[self.skin[self.lip_anchor]]
        out[self.lip_idx] = p + d[self.lip_anchor] + self.lip_rot[:, None] * ((p - a0) @ turn.T)
        # bound to triangles
        tri = x[self.bound_tri]
        foot = np.einsum("pk,pkj->pj", self.bound_bary, tri)
        out[self.bound_idx] = foot + np.einsum("pk,pkj->pj", self.bound_local, _frames(tri))
        # hanging from the eyes' margins
        closing, opening, foot = _lid_frames(x, self.lid_margin, self.lid_t, self.eye_centres[self.lid_eye],
                                             self._lid_rest_normals)
        a = foot + np.einsum("pk,pkj->pj", self.lid_local[:, 0], closing)
        b = foot + np.einsum("pk,pkj->pj", self.lid_local[:, 1], opening)
        m, t = self.lid_margin, self.lid_t[:, None]
        w = _smoothstep(np.einsum("pj,pj->p", d[m[:, 0]] + t * (d[m[:, 1]] - d[m[:, 0]]), self.lid_open))
        out[self.lid_idx] = a + w[:, None] * (b - a)
        # following the skin's nearest vertices, fading
        out[self.follow_idx] += np.einsum("pk,pkj->pj", self.follow_w, d[self.follow_src])
        # the jaw's rigid followers
        p = self.rest[self.jaw_idx]
        out[self.jaw_idx] = p + self.jaw_w[:, None] * (p @ rot.T + shift - p)
        tongue = float(np.clip(control.get("tongue_out"), 0.0, 1.0))
        if tongue:  # out between the lips, narrowing
            w = tongue * self.tongue_w
            p = self.rest[self.tongue_idx]
            out[self.tongue_idx] += w[:, None] * TONGUE_REACH
            out[self.tongue_idx, 0] -= w * TONGUE_NARROW * p[:, 0]
        # the mouth socket: the jaw's share, and near the lips the lips' motion
        sd = out[self.socket_idx] - self.rest[self.socket_idx]
        ld = out[self.socket_anchor] - self.rest[self.socket_anchor]
        f = self.socket_fade[:, None]
        out[self.socket_idx] = self.rest[self.socket_idx] + f * ld + (1.0 - f) * sd
        # the eyes
        eye_rot, turned = _eye_rotations(control)
        if turned:
            for idx, c, r in zip(self.eye_idx, self.eye_centres, eye_rot):
                out[idx] = (self.rest[idx] - c) @ r.T + c
        return out.astype(np.float32)

    @cached_property
    def turn_weights(self) -> FloatArray:
        """(26719,) each rest point's share of a head turn: all of it above the neck's top, none
        at its base (sim.face.turn)."""
        from sim.face.turn import turn_weights

        return turn_weights(self.rest, self.neck_top_y, self.neck_base_y)

    def turn_head(self, points: FloatArray, yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0) -> FloatArray:
        """`points` (26719,3) turned with the head by the head_yaw/pitch/roll channel values (1 = a
        quarter turn; signs as sim.face.turn's) about this head's neck pivot, the neck taking a
        share fading down to its base. Zero angles return the input."""
        from sim.face.turn import turn_head

        return turn_head(points, self.turn_weights, yaw, pitch, roll, pivot=self.neck_pivot)

    def pose_turned(self, surface: FloatArray, control: Any, state: Any) -> FloatArray:
        """`pose`, then the head turned as the state's head channels say (the lids as simulated)."""
        from sim.face.turn import state_turn

        return self.turn_head(self.pose(surface, control), *state_turn(state))

    @cached_property
    def lid_contact(self) -> Any:
        """The lids laid back onto the eyeballs they sank into (sim.face.scan.lid_contact)."""
        from sim.face.scan.lid_contact import LidContact

        return LidContact(self.rest, self.eye_margins, self)

    def pose_exported(self, surface: FloatArray, control: Any, state: Any) -> FloatArray:
        """What exports write (OBJ, PC2, `puppet pose --out`): `pose`, the lids that sank into
        their eyeballs laid back onto them as the drawing lays them (`lid_contact`), then the head
        turned; 26,719 vertices in the scan's order. The drawing also softens the upper face's
        buckles (render.scan_soften), which exports leave as simulated."""
        from sim.face.turn import state_turn

        return self.turn_head(self.lid_contact.press(self.pose(surface, control)), *state_turn(state))


def _bind(points: FloatArray, skin_pts: FloatArray, tris: np.ndarray) -> tuple[np.ndarray, FloatArray, FloatArray]:
    """Each point's nearest triangle (rows of `tris`, sim indices), its barycentric foot point and
    the offset from the foot in the triangle's frame."""
    from sim.face.transfer.geometry import closest_points

    foot, t, bary, _ = closest_points(points, skin_pts, tris)
    tri = tris[t]
    local = np.einsum("pij,pj->pi", _frames(skin_pts[tri]), points - foot)
    return tri, bary, local


def _along(tan: FloatArray, n: FloatArray) -> FloatArray:
    """(P,3,3) rows (t, n x t, n): the frame of normals n (P,3) and tangents tan made square to them."""
    n = n / np.linalg.norm(n, axis=1)[:, None]
    tan = tan - np.einsum("pj,pj->p", tan, n)[:, None] * n
    tan /= np.linalg.norm(tan, axis=1)[:, None]
    return np.stack([tan, np.cross(n, tan), n], axis=1)


def _lid_frames(x: FloatArray, margin: np.ndarray, t: FloatArray, centre: FloatArray,
                rest_normals: FloatArray | None = None) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(closing (P,3,3), opening (P,3,3), foot (P,3)) for lid things hanging from the margin
    segments margin[:, :2] of `x` at `t` (P,): the foot on the segment; both frames run along the
    segment, the closing one about the normal from the eyeball's `centre` (P,3) through the foot
    (a closing lid slides over the eye), the opening one about the normal of the lid's surface at
    rest (`rest_normals[:, 1]`, (P,2,3); without them, at `x`: from the foot to the same place
    between margin[:, 2:] up the lid), turning with the segment only. An opening lid's lashes stand
    out from its margin as at rest: in the scan's own widened eye the lid's surface above the
    margin turns 1 degree (median) while the margin's path about the eyeball turns 10; the
    simulated lid folds back higher (surprise 28, fear 19 degrees), and lashes turned with its
    surface lay over the lid's skin."""
    a, b = x[margin[:, 0]], x[margin[:, 1]]
    foot = a + t[:, None] * (b - a)
    if rest_normals is None:
        up = x[margin[:, 2]] + t[:, None] * (x[margin[:, 3]] - x[margin[:, 2]])
        opening = np.cross(b - a, up - foot)
    else:
        opening = rest_normals[:, 1]
    return _along(b - a, foot - centre), _along(b - a, opening), foot


def _nearest_on_loop(loop_pts: FloatArray, points: FloatArray,
                     segments: np.ndarray) -> tuple[np.ndarray, FloatArray]:
    """(segment k (P,), t (P,)): each point's nearest point on the closed polyline `loop_pts`,
    among its `segments` (k: from corner k to k + 1), at t along it."""
    a = loop_pts[segments]
    ab = loop_pts[(segments + 1) % len(loop_pts)] - a
    t = np.einsum("pkj,kj->pk", points[:, None] - a[None], ab) / np.einsum("kj,kj->k", ab, ab)[None]
    t = np.clip(t, 0.0, 1.0)
    gap = np.linalg.norm(points[:, None] - (a[None] + t[..., None] * ab[None]), axis=2)
    j = np.argmin(gap, axis=1)
    return segments[j], t[np.arange(len(points)), j]


def _lid_binding(skin_pts: FloatArray, tris: np.ndarray, loop: np.ndarray, corners: tuple[int, int],
                 rest: FloatArray, idx: np.ndarray, lashes: np.ndarray) -> tuple[np.ndarray, FloatArray]:
    """(margin (P,4) sim vertices, t (P,)) where each lid thing `idx` (scan vertices) hangs from
    the eye opening `loop` (sim vertices, in order; `corners` the positions in it of the inner and
    outer corner): its nearest point on the margin, between margin[:, 0] and margin[:, 1] at t,
    and margin[:, 2:] the vertices `LID_UP` rows up the lid nearest to either end; every row of a
    lash strip (`lashes` (S,R,C), rows tip to root) at its root's nearest point on the lid the
    strip's roots lie along, so a lash turns whole and an upper lash never hangs from the lower
    lid at the corners."""
    n = len(loop)
    pts = skin_pts[loop]
    every = np.arange(n)
    i, o = sorted(corners)
    lids = (every[i:o], np.concatenate([every[o:], every[:i]]))  # the segments of either lid
    where = {int(v): j for j, v in enumerate(idx)}
    k, t = _nearest_on_loop(pts, rest[idx], every)
    for strip in lashes:
        roots = np.array([where[int(v)] for v in strip[-1]])
        own = lids[0] if np.isin(k[roots], lids[0]).mean() >= 0.5 else lids[1]
        rk, rt = _nearest_on_loop(pts, rest[strip[-1]], own)
        for row in strip:
            at = np.array([where[int(v)] for v in row])
            k[at], t[at] = rk, rt
    m0, m1 = loop[k], loop[(k + 1) % n]
    up = np.flatnonzero(_rings(tris, len(skin_pts), loop) == LID_UP)
    tree = cKDTree(skin_pts[up])
    return np.stack([m0, m1, up[tree.query(skin_pts[m0])[1]], up[tree.query(skin_pts[m1])[1]]], axis=1), t


def _identity_of(rest_skin: FloatArray) -> np.ndarray | None:
    """The identity weights whose head has these simulated skin positions (None: not the scan)."""
    data = scan_data()
    skin = skin_layout().vertices
    base = data.neutral[skin]
    if np.array_equal(rest_skin, base):
        return np.zeros(0)
    modes = data.identities[:, skin].reshape(N_IDENTITIES, -1).astype(np.float64) * data.identity_scale[:, None]
    b = (rest_skin - base).ravel()
    w = np.linalg.lstsq(modes.T, b, rcond=None)[0]
    if np.abs(modes.T @ w - b).max() > 1e-4:
        return None
    return np.round(w, 9)


def build_dressing(model: Any) -> ScanDressing | None:
    """The dressing of a compiled scanned face (None when `model` is not one)."""
    from sim.face.scan.rig import scan_points
    from sim.integrator import jaw_slide

    layout = skin_layout()
    mesh = model.mesh
    if len(mesh.vertices) != len(layout.vertices) or not np.array_equal(mesh.triangles, layout.triangles):
        return None
    w = _identity_of(np.asarray(mesh.vertices, float))
    if w is None:
        return None
    rest = scan_points(w if len(w) else None)
    skin = layout.vertices
    rest[skin] = mesh.vertices  # exactly the simulated rest
    skin_pts = rest[skin]
    tris = layout.triangles.astype(np.int64)
    n_all = len(rest)

    # the inside of the lips and the back of the lids: the graph-nearest vertex of their opening
    data = scan_data()
    narrow = data.triangles("face")
    narrow = narrow[(narrow < NARROW_FACE).all(axis=1)]
    local_of = -np.ones(n_all, dtype=np.int64)
    local_of[skin] = np.arange(len(skin))
    inside, anchors = [], []
    for hidden, loops in ((layout.lip_inside, [mesh.mouth_loop]), (layout.lid_inside, list(mesh.eye_loops))):
        rim = skin[np.concatenate([np.asarray(lp) for lp in loops])]
        sub = narrow[np.isin(narrow, np.concatenate([hidden, rim])).all(axis=1)]
        nearest = _rings_with_source(sub, NARROW_FACE, rim)
        inside.append(hidden)
        anchors.append(local_of[nearest[hidden]])
    lip_anchor = np.concatenate(anchors)
    if (lip_anchor < 0).any():
        raise RuntimeError("a vertex inside the lips or lids is not connected to its opening")
    inside_all = np.concatenate(inside)
    inside = layout.lip_inside

    # lid things: hanging from the eyes' margins
    c_l, c_r = _eye_centres(rest)
    centres = np.stack([c_l, c_r])
    lid_idx, lid_margin, lid_t, lid_eye, lid_local, lid_open = [], [], [], [], [], []
    for e, (s, loop) in enumerate(zip("lr", mesh.eye_loops)):
        loop = np.asarray(loop)
        idx = np.concatenate([_range(f"{p}_{s}") for p in LID_THINGS])
        corners = tuple(int(np.flatnonzero(loop == mesh.landmarks[f"eye_{c}_{s}"])[0]) for c in ("inner", "outer"))
        lashes = lash_strips(f"eyelashes_{s}")
        margin, t = _lid_binding(skin_pts, tris, loop, corners, rest, idx, lashes)  # type: ignore[arg-type]
        closing, opening, foot = _lid_frames(skin_pts, margin, t, np.broadcast_to(centres[e], (len(idx), 3)))
        lid_idx.append(idx); lid_margin.append(margin); lid_t.append(t); lid_eye.append(np.full(len(idx), e))
        lid_local.append(np.stack([np.einsum("pij,pj->pi", f, rest[idx] - foot) for f in (closing, opening)], axis=1))
        out = foot - skin_pts[loop].mean(axis=0)  # away from the opening's middle
        lid_open.append(out / (np.linalg.norm(out, axis=1)[:, None] * LID_OPEN))
    # nearby unsimulated face skin: bound to triangles
    bound_idx, bound_tri, bound_bary, bound_local = [], [], [], []
    others = np.concatenate([np.arange(NARROW_FACE, PARTS["face"][1]), _range("eye_socket_l"), _range("eye_socket_r")])
    from sim.face.transfer.geometry import closest_points

    _, _, _, gap = closest_points(rest[others], skin_pts, tris)
    near = others[gap < BIND]
    t, b, l = _bind(rest[near], skin_pts, tris)
    bound_idx.append(near); bound_tri.append(t); bound_bary.append(b); bound_local.append(l)

    # the rest of the face area, head and neck, eye sockets: follow with a fade
    follow = np.concatenate([others[gap >= BIND], _range("head_neck")])
    dd, src = cKDTree(skin_pts).query(rest[follow], k=NEAREST)
    inv = 1.0 / np.maximum(dd, 1e-6)
    wts = inv / inv.sum(axis=1, keepdims=True)
    jw = np.einsum("pk,pk->p", wts, np.asarray(mesh.jaw_weight)[src])
    reach = FOLLOW + jw * (JAW_FOLLOW - FOLLOW)
    fade = _smoothstep(1.0 - dd[:, 0] / reach)
    follow_w = wts * fade[:, None]

    # teeth, gums, tongue and the mouth socket with the jaw
    upper = np.arange(PARTS["teeth"][0], TEETH_SPLIT)
    lower = np.arange(TEETH_SPLIT, PARTS["teeth"][1])
    occlusal = 0.5 * (rest[upper, 1].min() + rest[lower, 1].max())
    gums = _range("gums_tongue")
    du, _ = cKDTree(rest[upper]).query(rest[gums])
    dl, _ = cKDTree(rest[lower]).query(rest[gums])
    height = _smoothstep((occlusal + 0.4 - rest[gums, 1]) / 0.8)
    gum_w = np.where(np.minimum(du, dl) < 0.4, (dl < du).astype(float), height)
    arch = np.abs(rest[gums, 0]) < 0.8 * np.abs(rest[lower, 0]).max()
    below = (rest[gums, 1] < occlusal) & (rest[gums, 1] > occlusal - TONGUE_FLOOR)
    is_tongue = (np.minimum(du, dl) > 0.3) & below & arch
    tongue_idx = gums[is_tongue]
    tongue_w = _smoothstep((rest[tongue_idx, 2] - TONGUE_ROOT) / (TONGUE_TIP - TONGUE_ROOT))
    gum_w[is_tongue] = 1.0  # the tongue rides on the floor of the mouth: wholly with the jaw
    socket = _range("mouth_socket")
    sock_w = _smoothstep((occlusal + 0.4 - rest[socket, 1]) / 0.8)
    rim = np.unique(inside[layout.lip_row == 0])
    sd, si = cKDTree(rest[rim]).query(rest[socket])
    socket_fade = _smoothstep(1.0 - sd / LIP_FADE)

    pivot = np.asarray(mesh.jaw_pivot, float)
    neck = rest[_range("head_neck")]
    return ScanDressing(
        rest=rest, skin=skin, lip_idx=inside_all, lip_anchor=lip_anchor,
        lip_rot=np.asarray(mesh.jaw_weight, float)[lip_anchor],
        bound_idx=np.concatenate(bound_idx), bound_tri=np.concatenate(bound_tri),
        bound_bary=np.concatenate(bound_bary), bound_local=np.concatenate(bound_local),
        lid_idx=np.concatenate(lid_idx), lid_margin=np.concatenate(lid_margin), lid_t=np.concatenate(lid_t),
        lid_eye=np.concatenate(lid_eye), lid_local=np.concatenate(lid_local), lid_open=np.concatenate(lid_open),
        follow_idx=follow, follow_src=src, follow_w=follow_w,
        jaw_idx=np.concatenate([lower, gums, socket]),
        jaw_w=np.concatenate([np.ones(len(lower)), gum_w, sock_w]),
        tongue_idx=tongue_idx, tongue_w=tongue_w,
        socket_idx=socket, socket_anchor=rim[si], socket_fade=socket_fade,
        eye_idx=(_range("eyeball_l"), _range("eyeball_r")), eye_centres=centres, eye_margins=eye_margins(mesh),
        jaw_pivot=pivot, jaw_axis=np.asarray(model.jaw_axis, float), jaw_max_angle=float(model.params.jaw_max_angle),
        jaw_slide=jaw_slide(model), neck_pivot=np.array([0.0, pivot[1] - 0.5, pivot[2] - 3.0]),
        neck_base_y=float(neck[:, 1].min() + 3.0), neck_top_y=float(pivot[1] - 0.5))


def eye_margins(mesh: Any) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Per eye (left, right) the (upper, lower) lid margin of the scanned head's simulated `mesh`
    (a FaceMesh) in scan indices, each from the inner corner to the outer."""
    from sim.face.transfer.eyes import mesh_lids

    skin = skin_layout().vertices
    left, right = (tuple(skin[m] for m in mesh_lids(mesh, k)) for k in range(2))
    return (left[0], left[1]), (right[0], right[1])


def _eye_centres(rest: FloatArray) -> tuple[FloatArray, FloatArray]:
    from sim.face.scan.anatomy import eyeball_spheres

    c, _ = eyeball_spheres(rest)
    return c[0], c[1]


def _rings_with_source(tri: np.ndarray, n: int, sources: np.ndarray) -> np.ndarray:
    """For every vertex, the source vertex nearest to it along the triangles' edges (-1: none)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    _, _, src = dijkstra(g + g.T, unweighted=True, indices=sources, min_only=True, return_predecessors=True)
    return src


_CACHE: dict[str, ScanDressing | None] = {}


def dressing_for(model: Any) -> ScanDressing | None:
    """The scan dressing of a compiled face, built once per face (None: not the scanned head)."""
    key = str(getattr(model, "hash", "")) or str(id(model))
    if key not in _CACHE:
        if len(_CACHE) >= 4:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = build_dressing(model)
    return _CACHE[key]
