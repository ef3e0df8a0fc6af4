"""The lids carried by the turning eye: a force on the skin round each eye that follows the
eyeball's rotation (gaze channels `eyes_yaw`, `eyes_pitch`, `eyes_vergence`).

The upper and lower lids rest on the globe, the margins on the cornea's bulge, and the conjunctiva
joins the lids' back to the globe at the fornices; when the eye turns, the cornea pushes the lid
margins along with it and the lid's skin follows, about 2 mm at the margin for a sideways look
(the lid contour's peak moves with the cornea: the upper lid's highest point shifts towards the
side the eye looks to). Read off the ICT FaceKit's scanned eyeLookIn/Out: the skin round the eye
moves as the eye would turn it, by a share of the eye's rotation that is largest on the lids
(0.21-0.28 of a rigid turn about the centre of the sphere the lids slide on) and falls smoothly
with the distance from the globe's surface (half of it ~5 mm out, nothing past ~12 mm); a rigid
turn scaled per 1-3 mm band of distance holds 73-88 % of the scan's motion there.

Modelled as a spring from every skin vertex near an eye to a point fixed on the turning globe,
stiffness per unit skin area falling with the distance from the globe (`coupling`); only its pull
at the skin's rest position enters the step (`gaze_forces`: gain_i (R (p_i - c) + c - p_i), a force
constant while the gaze holds), so the step's matrix and, at a still gaze, every force are as
without it. The implicit step adds it as the responses to eight fixed fields per eye times
coefficients of the gaze (`basis_fields`), as it adds the muscles, so a moving gaze does not spoil
the solve the live loop makes ahead of its inputs; the explicit step adds the force itself. The eye turns about its centre (the sphere the lids slide on) by the renderer's angles:
30 degrees sideways and 20 up or down at a gaze of 1.
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: the gaze's full range (eyes_yaw, eyes_pitch = +-1) as the eye's rotation, radians: the one
#: definition, used by the lids here, the scan's dressing and the renderer
YAW_MAX = math.radians(30.0)
PITCH_MAX = math.radians(20.0)
#: the coupling's stiffness per unit skin area on the globe, dyn/cm per cm^2 (on the scanned head
#: the lid margins then follow a sideways look as the scan's do; swept 2000-6000 on the fitted
#: skin, `scan_match.py --no-fit`, eyeLookIn/Out: 2000 0.57/0.61, 3000 0.49/0.56, 4000 0.57/0.66,
#: 6000 1.00/1.13 -- stiffer overshoots)
STIFFNESS = 3000.0
#: cm: its fall-off with the distance from the globe's surface (Gaussian width), and where it ends
WIDTH = 0.55
REACH = 1.5
#: the upper and the lower lid carried sideways apart (`coupling`'s `upper`, `lower`: factors of
#: the gain above and below the eye's centre, blended over `SPLIT` cm of height), in the turn about
#: the vertical axis only (`lid_couplings`). The upper lid's tarsus is about twice as tall as the
#: lower's (10 against 4-5 mm) and its margin rests on the cornea's bulge, which sweeps sideways
#: under it as the eye turns; the lower margin lies below the bulge. On the scanned head our upper
#: lid followed a sideways look half as far as the scan's (eyeLookIn_L: 0.71 mm against 1.38
#: across) and the lower lid as far (best scale 0.95). Up and down, the upper lid's height is the
#: levator's (its tone follows the gaze: the ARKit map's shares and the levator's fitted anchors,
#: which were fitted on top of the lids held alike), so the turn about the horizontal axis keeps
#: the gain alike: a stronger upper lid there took eyeLookUp from 0.35 to 0.38.
UPPER = 1.75
LOWER = 0.8
SPLIT = 0.1
#: and the inner and outer parts of the lids apart in the sideways turn (`coupling`'s `medial`,
#: `lateral`: factors of the gain on the nose's side of the eye's centre and on the temple's,
#: blended over `ACROSS` cm): the medial canthal tendon ties the lids' inner ends to the lacrimal
#: crests, while the lateral canthus, on the more yielding lateral retinaculum, moves with the
#: globe. The scan's looks aside move the lids' outer third about twice as far as their inner third
#: (eyeLookIn_L 1.25 against 0.58 mm across); ours, coupled alike across, moved them about as far
#: (0.79 against 0.84).
MEDIAL = 0.8
LATERAL = 1.2
ACROSS = 0.3


def coupling(rest: np.ndarray, area: np.ndarray, held: np.ndarray, centres: np.ndarray,
             radius: float, stiffness: float = STIFFNESS, width: float = WIDTH,
             reach: float = REACH, upper: float = 1.0, lower: float = 1.0, split: float = SPLIT,
             medial: float = 1.0, lateral: float = 1.0,
             across: float = ACROSS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertex indices (G,) int64, their eye (G,) int64: 0 left, 1 right, gains (G,) dyn/cm):
    the free skin within `reach` of an eye's sphere (`centres` (2,3), `radius` cm), in front of
    its centre, with gain stiffness * area * exp(-(d / width)^2) at a distance d outside the
    sphere (d <= 0, the lids resting on the cornea: the full gain), times `upper` above the eye's
    centre and `lower` below it, blended as 0.5 (1 + tanh(h / split)) of the height h above the
    centre, and `medial` on the nose's side of it and `lateral` on the temple's, blended as
    0.5 (1 + tanh(s / across)) of the distance s further from the face's midline than the centre
    (all 1: the lids alike, the coupling takes recorded before the header's "lid coupling" replay
    with)."""
    c = np.asarray(centres, dtype=np.float64)
    dist = np.stack([np.sqrt(np.sum((rest - c[e]) ** 2, axis=1)) for e in range(2)], axis=1)
    eye = np.argmin(dist, axis=1)
    d = dist[np.arange(len(rest)), eye] - float(radius)
    front = (rest[:, 2] - c[eye, 2]) > 0.0
    near = np.flatnonzero((d < reach) & front & ~np.asarray(held, dtype=bool))
    dd = np.maximum(d[near], 0.0)
    gain = stiffness * np.asarray(area, dtype=np.float64)[near] * np.exp(-(dd / width) ** 2)
    if upper != 1.0 or lower != 1.0:
        h = np.asarray(rest, dtype=np.float64)[near, 1] - c[eye[near], 1]
        gain = gain * (lower + (upper - lower) * 0.5 * (1.0 + np.tanh(h / float(split))))
    if medial != 1.0 or lateral != 1.0:
        s = np.abs(np.asarray(rest, dtype=np.float64)[near, 0]) - np.abs(c[eye[near], 0])
        gain = gain * (medial + (lateral - medial) * 0.5 * (1.0 + np.tanh(s / float(across))))
    return near.astype(np.int64), eye[near].astype(np.int64), gain


Coupling = tuple[np.ndarray, np.ndarray, np.ndarray, "np.ndarray | None"]


def lid_couplings(model: object) -> tuple[Coupling, Coupling]:
    """The model's two couplings (vertex indices, their eye, gains in the sideways turn, gains in
    the turn up and down: None, the same), the lids alike and the lids apart (`UPPER`, `LOWER`,
    `MEDIAL`, `LATERAL` in the sideways turn): the first for takes recorded before the take
    header's "lid coupling", the second for every other."""
    m = model
    args = (m.rest, m.area, m.held, m.mesh.eye_centers, float(m.eye_contact_radius))  # type: ignore[attr-defined]
    idx, eye, gain = coupling(*args)
    apart = coupling(*args, upper=UPPER, lower=LOWER, medial=MEDIAL, lateral=LATERAL)[2]
    return (idx, eye, gain, None), (idx, eye, apart, gain)


def eye_yaws(yaw: float, vergence: float) -> tuple[float, float]:
    """(left, right) eye's yaw (-1..1, + towards the face's left) for the shared gaze `yaw` and
    the `vergence` (+ the eyes turned towards each other): the left eye turns by yaw - vergence,
    the right one by yaw + vergence (a version and a vergence, each eye's turn their sum)."""
    return min(1.0, max(-1.0, yaw - vergence)), min(1.0, max(-1.0, yaw + vergence))


def eye_rotation(yaw: float, pitch: float) -> np.ndarray:
    """(3,3): the eye turned by `yaw` (+ towards the face's left, +X) and `pitch` (+ up) as the
    gaze channels give them (-1..1), about +Y then X, as the renderer turns the eyeballs."""
    a, b = yaw * YAW_MAX, -pitch * PITCH_MAX
    ry = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(b), -math.sin(b)], [0.0, math.sin(b), math.cos(b)]])
    return ry @ rx


@numba.njit(cache=True, nogil=True)
def _add_gaze_forces(rest, idx, eye, gain, centres, rot, out):  # type: ignore[no-untyped-def]
    for k in range(idx.shape[0]):
        i = idx[k]
        e = eye[k]
        d0 = rest[i, 0] - centres[e, 0]
        d1 = rest[i, 1] - centres[e, 1]
        d2 = rest[i, 2] - centres[e, 2]
        for j in range(3):
            turned = d0 * rot[e, j, 0] + d1 * rot[e, j, 1] + d2 * rot[e, j, 2] + centres[e, j]
            out[i, j] += gain[k] * (turned - rest[i, j])


@numba.njit(cache=True, nogil=True)
def _add_gaze_forces_apart(rest, idx, eye, gain, pitch_gain, centres, side, updown, out):  # type: ignore[no-untyped-def]
    for k in range(idx.shape[0]):
        i = idx[k]
        e = eye[k]
        d0 = rest[i, 0] - centres[e, 0]
        d1 = rest[i, 1] - centres[e, 1]
        d2 = rest[i, 2] - centres[e, 2]
        for j in range(3):
            a = d0 * side[e, j, 0] + d1 * side[e, j, 1] + d2 * side[e, j, 2]
            b = d0 * updown[e, j, 0] + d1 * updown[e, j, 1] + d2 * updown[e, j, 2]
            out[i, j] += gain[k] * a + pitch_gain[k] * b


def gaze_forces(rest: np.ndarray, idx: np.ndarray, eye: np.ndarray, gain: np.ndarray,
                centres: np.ndarray, yaw: float, pitch: float, vergence: float, out: np.ndarray,
                pitch_gain: np.ndarray | None = None) -> None:
    """Adds to `out` (N,3) dyn the coupling's pull for the gaze (yaw, pitch, vergence): each
    coupled vertex towards where its rest position would be if its eye turned it rigidly, times
    its gain; with `pitch_gain`, R - I = (Ry - I) Rx + (Rx - I) split into the sideways turn's part,
    times `gain`, and the turn up or down's, times `pitch_gain`."""
    yaws = eye_yaws(yaw, vergence)
    c = np.ascontiguousarray(centres, dtype=np.float64)
    if pitch_gain is None:
        rot = np.stack([eye_rotation(y, pitch) for y in yaws])
        _add_gaze_forces(rest, idx, eye, gain, c, np.ascontiguousarray(rot), out)
        return
    rx = eye_rotation(0.0, pitch)
    side = np.stack([(eye_rotation(y, 0.0) - np.eye(3)) @ rx for y in yaws])
    updown = np.stack([rx - np.eye(3)] * 2)
    _add_gaze_forces_apart(rest, idx, eye, gain, pitch_gain, c, side, updown, out)


#: The eye's turn minus the identity, R - I with R = Ry(a) Rx(b), as a sum of eight fixed matrices
#: times functions of the angles: with A = sin a Ky + (1 - cos a) Ky^2 and B likewise about x,
#: R - I = A + B + A B. So the pull of a turned eye is a sum of eight fixed force fields per eye, each
#: times a coefficient of the gaze (`basis_fields`, `basis_coefficients`): the implicit step adds their
#: precomputed responses as it adds the muscles' (`sim.implicit.muscle_responses`), and a moving gaze
#: leaves the solve the live loop makes ahead of the inputs usable.
_KY = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
_KX = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_BASIS = (_KY, _KY @ _KY, _KX, _KX @ _KX, _KY @ _KX, _KY @ _KX @ _KX, _KY @ _KY @ _KX, _KY @ _KY @ _KX @ _KX)
N_BASIS = 2 * len(_BASIS)  # fields: eye 0's eight, then eye 1's


#: the fields of the turn up or down alone (B's), which take `pitch_gain` (`basis_fields`)
_UPDOWN = (2, 3)


def basis_fields(rest: np.ndarray, idx: np.ndarray, eye: np.ndarray, gain: np.ndarray,
                 centres: np.ndarray, pitch_gain: np.ndarray | None = None) -> np.ndarray:
    """(N_BASIS, N, 3) dyn: the fixed force fields whose sum, each times its `basis_coefficients`,
    is the coupling's pull (`gaze_forces`): gain_i M_k (p_i - c_e) on eye e's vertices (the turn up
    or down's alone with `pitch_gain`, when given)."""
    out = np.zeros((N_BASIS, len(rest), 3))
    c = np.asarray(centres, dtype=np.float64)
    for e in range(2):
        on = eye == e
        d = np.asarray(rest, dtype=np.float64)[idx[on]] - c[e]
        for k, m in enumerate(_BASIS):
            g = gain if pitch_gain is None or k not in _UPDOWN else pitch_gain
            out[e * len(_BASIS) + k, idx[on]] = g[on, None] * (d @ m.T)
    return out


def basis_coefficients(yaw: float, pitch: float, vergence: float) -> np.ndarray:
    """(N_BASIS,): the coefficients of `basis_fields` for the gaze (each eye's yaw with the
    vergence, `eye_yaws`; the pitch shared)."""
    b = -pitch * PITCH_MAX
    sb, vb = math.sin(b), 1.0 - math.cos(b)
    out = []
    for y in eye_yaws(yaw, vergence):
        a = y * YAW_MAX
        sa, va = math.sin(a), 1.0 - math.cos(a)
        out += [sa, va, sb, vb, sa * sb, sa * vb, va * sb, va * vb]
    return np.array(out)


#: the looks of `FaceRig.gaze` (the tissue round the globe) per eye, as the eye's own yaw and pitch
#: take them at +1 and -1: the left eye (eye 0, on the face's left, +X) looks out at yaw +1 and in at
#: -1, the right eye in at +1 and out at -1; both look up at pitch +1
_LOOKS = (("out", "in"), ("in", "out"))
_SIDES = ("l", "r")


def tissue_fields(model: object) -> np.ndarray | None:
    """(N_BASIS, N, 3) dyn, or None when the face has none: the tissue round each globe (Tenon's
    capsule, the orbital fat, the check ligaments, the lids' retractors) carried by the turning eye,
    as forces to add to `basis_fields`' (so a frame reads no more responses than without it). The rig
    gives the tether anchors' displacement d with each eye turned fully each way (`FaceRig.gaze`,
    "<look>_<side>", cm); the tether being linear, they pull k_r d. A turn part of the way carries
    them as a smooth function of its angle to second order, which the two full turns fix: about the
    vertical axis, sin a (d+ - d-) / (2 sin A) + (1 - cos a) (d+ + d-) / (2 (1 - cos A)) for the
    eye's yaw angle a of the most A (d+ at yaw +1, d- at -1), and likewise about the horizontal axis
    (the fields of the coefficients sin a, 1 - cos a, sin b and 1 - cos b, `basis_coefficients`)."""
    rig = getattr(model, "rig", None)
    gaze = getattr(rig, "gaze", None)
    if not gaze:
        return None
    kr = np.asarray(model.rest_stiffness, dtype=np.float64)[:, None]  # type: ignore[attr-defined]
    n = len(kr)
    zero = np.zeros((n, 3))
    out = np.zeros((N_BASIS, n, 3))
    sa, va = math.sin(YAW_MAX), 1.0 - math.cos(YAW_MAX)
    sb, vb = math.sin(PITCH_MAX), 1.0 - math.cos(PITCH_MAX)
    for e, side in enumerate(_SIDES):
        f = {look: kr * np.asarray(gaze.get(f"{look}_{side}", zero), dtype=np.float64)
             for look in ("in", "out", "up", "down")}
        plus, minus = (f[look] for look in _LOOKS[e])
        row = e * len(_BASIS)
        out[row + 0] = (plus - minus) / (2.0 * sa)  # sin a, a = yaw * YAW_MAX
        out[row + 1] = (plus + minus) / (2.0 * va)  # 1 - cos a
        out[row + 2] = (f["down"] - f["up"]) / (2.0 * sb)  # sin b, b = -pitch * PITCH_MAX
        out[row + 3] = (f["up"] + f["down"]) / (2.0 * vb)  # 1 - cos b
    return out


def add_tissue_forces(tissue: np.ndarray, yaw: float, pitch: float, vergence: float, out: np.ndarray) -> None:
    """Adds to `out` (N,3) dyn the pull of the tissue carried by the turned eyes (`tissue_fields`)
    for the gaze (the explicit step's; the implicit one reads their responses)."""
    coef = basis_coefficients(yaw, pitch, vergence)
    for k in np.flatnonzero(coef):
        if k % len(_BASIS) < 4:
            out += coef[k] * tissue[k]


def look_coefficients(yaw: float, pitch: float, vergence: float) -> dict[str, float]:
    """{"<look>_<side>": coefficient}: how much of each of the rig's look fields (`FaceRig.gaze`) the
    gaze carries the tissue by (`tissue_fields`: 1 for the look an eye turns fully, and for a turn
    part of the way the sine's and the versine's shares of the full turn's fields)."""
    out = {}
    sa, va = math.sin(YAW_MAX), 1.0 - math.cos(YAW_MAX)
    sb, vb = math.sin(PITCH_MAX), 1.0 - math.cos(PITCH_MAX)
    p = pitch * PITCH_MAX
    for e, y in enumerate(eye_yaws(yaw, vergence)):
        a = y * YAW_MAX
        plus, minus = _LOOKS[e]
        s, v = math.sin(a) / (2.0 * sa), (1.0 - math.cos(a)) / (2.0 * va)
        out[f"{plus}_{_SIDES[e]}"], out[f"{minus}_{_SIDES[e]}"] = s + v, v - s
        s, v = math.sin(p) / (2.0 * sb), (1.0 - math.cos(p)) / (2.0 * vb)
        out[f"up_{_SIDES[e]}"], out[f"down_{_SIDES[e]}"] = s + v, v - s
    return out
