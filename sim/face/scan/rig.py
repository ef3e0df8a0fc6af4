"""The scanned head's rig: the skin of its face area with muscles, lids, lips, jaw hinge, wrinkle
lines and regions placed from its own landmarks by the rig transfer (`sim.face.transfer`, run once
by `sim.face.scan.make_rig`; its result ships as `ict_rig.npz`).

Simulated: the scan's own vertices of the narrow face area, less the inside of the lips and the
back of the lids (`sim.face.scan.anatomy.skin_layout`: 6020 of the 26719; everything else follows
them, `sim.face.scan.dressing`). The rig is in the scan's own frame and units (cm, +Y up, facing
+Z). The lids slide on a sphere holding the scanned eyeball's front (sclera and cornea).

An identity (`weights`, the 100 identity modes' weights) changes positions only: the vertex
numbering, the landmarks and the rig's structure are the same for every identity, and an identity's
rig is carried from the shipped one with elementwise arithmetic, so the rig, its hash and every
replay on it are the same bits whatever BLAS kernel the process runs.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from sim.antifold import FOREHEAD_BENDING
from sim.build import SkinParams
from sim.face.scan.anatomy import skin_layout
from sim.face.scan.data import N_IDENTITIES, PARTS, SCLERA, scan_data
from sim.model import FaceRig, LinearMuscle, Muscle, PatchMuscle, SheetMuscle, SphincterMuscle

RIG_FILE = Path(__file__).with_name("ict_rig.npz")  # the generic head's rig (sim.face.scan.make_rig)

DIGITS = 7  # carried quantities are rounded to this many decimals (cm)
# The scan's skin is 3-10x finer than the procedural face's (median edge 2.8 mm, 0.4 mm at the lid
# margins). A spring network's bending rigidity falls with the square of its edge length, so at the
# procedural face's bend_ratio (0.3) compressed skin buckled at the mesh's own scale (happiness
# folded 2.1 cm2 over). Stiffer bending and support take the folds down and the amplitudes with
# them; the muscles are then made stronger (`FORCE`, per channel `FORCE_OF`). Measured, one sweep
# each (presets and channels at full value; amplitude targets of sim.face.targets):
#   bend 0.3, support 9000, force 1:    13 poses fold > 0.1 cm2
#   bend 10, support 27000, force 1:     1 pose folds, 11 of 39 targets met
#   bend 10, support 27000, force 2:     8 poses fold, 21 targets
#   bend 6, support 27000, force 1.6:    6 poses fold, 24 targets   <- chosen: the expressions read
# The stiffer skin lags the jaw: at the procedural face's 0.55 rad AU27 parts the lips 36 mm (real
# maximal opening 44-57); 0.68 rad gave 41 mm but folded 0.46 cm2 at the mouth, so it stays 0.55.
# The forehead's bound layer bends as a plate 4 mm thick (sim.antifold.FOREHEAD_BENDING, 8 times the
# skin's own): with the skin's own bending alone the frontalis buckled the forehead into uneven bumps
# and jagged arcs over the brows (docs/scan-face.md, "The forehead's bound layer").
SCAN_PARAMS = SkinParams(bend_ratio=6.0, support=27000.0, forehead_bending=FOREHEAD_BENDING)
#: the scanned head's skin before the forehead's bound layer: a take recorded then (its header
#: without "bending", puppet.live.BENDING_AS) replays on it, bit for bit
SCAN_PARAMS_THIN_FOREHEAD = replace(SCAN_PARAMS, forehead_bending=1.0)


def scan_params(bound_forehead: bool = True) -> SkinParams:
    """The scanned head's skin parameters: as shipped, or (False) as before the forehead's bound
    layer, for takes recorded then."""
    return SCAN_PARAMS if bound_forehead else SCAN_PARAMS_THIN_FOREHEAD


#: what a compiled face's cache key gains when it is built with `scan_params(False)`
THIN_FOREHEAD_KEY = b":thin forehead"
FORCE = 1.6
# the orbital sphincter (AU6) folds the skin round the eye first; the lid strips need twice the
# force to close the scan's lids over its cornea (AU45: 7-11.5 mm; sim.face.scan.lids sets the
# upper strips' force itself); the levator twice the others: since the lid fold is lax and the
# retaining ligament holds the skin under the brow (sim.face.scan.lids) its pull lifted the lid
# 1.8 mm at AU5 (target 2.5-5; 2.7 at 2.4), and under fear's brows drawn down (1+2+4+5) only
# 3.0 mm (target 6.5+), where the emotion observer read fear as sad (fear 0.15): at 3.2 AU5
# lifts the lid 3.6 mm and the scan's fear 3.8, which reads fear (docs/scan-face.md); at 4.0 the
# lid's skin folded (the levator alone 0.12 cm2, limit 0.1)
FORCE_OF = {"orbicularis_oculi": 0.7, "orbicularis_oculi_lid": 2.0, "levator_palpebrae": 3.2}
LID_CLEARANCE = 0.03  # cm: the lid contact sphere lies this far outside the eyeball
EYE_REACH = 1.3  # cm off the eyeball's axis: the front the lid contact sphere holds


def scan_points(weights: np.ndarray | None = None) -> np.ndarray:
    """(26719, 3) float64 cm: the scan's neutral head of the identity `weights` (None: the generic
    head; up to 100 weights, ~N(0, 1) each)."""
    data = scan_data()
    if weights is None:
        return data.neutral.copy()
    w = np.asarray(weights, dtype=np.float64).ravel()
    if len(w) > N_IDENTITIES or not np.all(np.isfinite(w)):
        raise ValueError(f"identity weights must be at most {N_IDENTITIES} finite numbers")
    return data.neutral + data.identity_delta(w)


def _r(a: np.ndarray | float) -> np.ndarray:
    return np.round(np.asarray(a, dtype=np.float64), DIGITS)


def _lid_sphere(eyeball: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the sphere the lids slide on: the smallest sphere centred on the
    eyeball's axis (+Z through the sclera's centre) that holds the eyeball's front within
    `EYE_REACH` of the axis (the cornea and the sclera an opening shows), plus `LID_CLEARANCE`.
    The integrator keeps skin out of one sphere per eye; the scanned eyeball is a sclera with a
    bulging cornea, and a closing lid must pass over both. Lid skin that lies inside this sphere at
    rest (the margins resting on the cornea) is left out of the contact by the compiler."""
    centre = eyeball_spheres_one(eyeball)
    p = eyeball - centre
    front = p[(p[:, 2] > 0.0) & (np.hypot(p[:, 0], p[:, 1]) <= EYE_REACH)]
    best = None
    for cz in np.linspace(0.0, 1.0, 201):
        r = float(np.linalg.norm(front - [0.0, 0.0, cz], axis=1).max())
        if best is None or r < best[1]:
            best = (cz, r)
    assert best is not None
    return centre + np.array([0.0, 0.0, best[0]]), best[1] + LID_CLEARANCE


def eyeball_spheres_one(eyeball: np.ndarray) -> np.ndarray:
    """The centre (3,) of one eyeball's sclera: the least-squares sphere through its vertices
    (normal equations summed elementwise and solved by plain elimination, so the same bits whatever
    BLAS kernel the process runs)."""
    p = eyeball[:SCLERA]
    a = np.column_stack([2.0 * p, np.ones(len(p))])
    b = np.sum(p * p, axis=1)
    m = [[float(np.sum(a[:, i] * a[:, j])) for j in range(4)] + [float(np.sum(a[:, i] * b))] for i in range(4)]
    for i in range(4):  # Gauss-Jordan with partial pivoting on the 4x5 system
        piv = max(range(i, 4), key=lambda r: abs(m[r][i]))
        m[i], m[piv] = m[piv], m[i]
        for r in range(4):
            if r != i:
                f = m[r][i] / m[i][i]
                m[r] = [x - f * y for x, y in zip(m[r], m[i])]
    return np.array([m[i][4] / m[i][i] for i in range(3)])


NEAREST = 4  # skin vertices whose identity displacement a carried point takes


def _carry(points: np.ndarray, tree, disp: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Points moved with the skin: the inverse-distance mean of their nearest skin vertices'
    displacement (elementwise arithmetic only: the same bits on any BLAS kernel)."""
    p = np.atleast_2d(np.asarray(points, float))
    d, k = tree.query(p, k=NEAREST)
    w = 1.0 / np.maximum(d, 1e-9)
    w = w / w.sum(axis=1, keepdims=True)
    return _r(p + (w[:, :, None] * disp[k]).sum(axis=1))


def _carry_muscle(m: Muscle, tree, disp: np.ndarray, s: float) -> Muscle:  # type: ignore[no-untyped-def]
    def pt(p: np.ndarray) -> np.ndarray:
        return _carry(p, tree, disp)[0]

    if isinstance(m, LinearMuscle):
        return replace(m, attachment=pt(m.attachment), insertion=pt(m.insertion), radius=float(_r(m.radius * s)))
    if isinstance(m, SphincterMuscle):
        return replace(m, center=pt(m.center), a=float(_r(m.a * s)), b=float(_r(m.b * s)))
    if isinstance(m, PatchMuscle):
        return replace(m, center=pt(m.center), semi_axes=_r(np.asarray(m.semi_axes, float) * s))
    assert isinstance(m, SheetMuscle)
    return replace(m, attach1=pt(m.attach1), attach2=pt(m.attach2), insert1=pt(m.insert1), insert2=pt(m.insert2),
                   length=float(_r(m.length * s)), width=float(_r(m.width * s)))


def _generic_rig() -> FaceRig:
    from sim.rig import load_rig

    return load_rig(RIG_FILE)


def scan_rig(weights: np.ndarray | None = None, name: str = "ict") -> FaceRig:
    """The scanned head's rig for an identity (None: the generic head; else up to 100 identity
    weights). The generic rig is shipped (`ict_rig.npz`, made by `sim.face.scan.make_rig`); an
    identity's is carried from it: its skin is the identity's, muscle points and the jaw hinge move
    with the skin around them, lengths scale with the eyes' distance, the lids' sphere is fitted to
    the identity's eyeballs; weights, regions and the held skin are the generic ones. ~0.1 s."""
    from scipy.spatial import cKDTree

    rig = _generic_rig()
    m = rig.mesh
    if weights is None:
        return replace(rig, name=name)
    points = scan_points(weights)
    skin = skin_layout().vertices
    disp = points[skin] - m.vertices
    tree = cKDTree(m.vertices)
    centres, radii = [], []
    for part in ("eyeball_l", "eyeball_r"):
        lo, hi = PARTS[part]
        c, r = _lid_sphere(points[lo:hi])
        centres.append(c)
        radii.append(r)
    base = scan_points(None)
    ipd = [np.linalg.norm(eyeball_spheres_one(p[PARTS["eyeball_l"][0]:PARTS["eyeball_l"][1]])
                          - eyeball_spheres_one(p[PARTS["eyeball_r"][0]:PARTS["eyeball_r"][1]])) for p in (points, base)]
    s = float(ipd[0] / ipd[1])
    mesh = replace(m, vertices=points[skin].copy(), jaw_pivot=_carry(m.jaw_pivot, tree, disp)[0],
                   eye_centers=_r(np.array(centres)), eye_radius=float(_r(min(radii))))
    muscles = {ch: tuple(_carry_muscle(p, tree, disp, s) for p in parts) for ch, parts in rig.muscles.items()}
    front = cKDTree(m.vertices[:, :2])
    wrinkles = []
    for line in rig.wrinkles:
        _, k = front.query(np.asarray(line.points, float))
        wrinkles.append(replace(line, points=_r(np.asarray(line.points, float) + disp[k, :2]),
                                width_minus=float(_r(line.width_minus * s)), width_plus=float(_r(line.width_plus * s))))
    return FaceRig(mesh=mesh, muscles=muscles, wrinkles=tuple(wrinkles), name=name, insertion=rig.insertion,
                   skin=rig.skin, tissue=rig.tissue, strain=rig.strain, anchor=rig.anchor, gaze=rig.gaze)


def is_scan_rig(rig: FaceRig) -> bool:
    """Whether a rig (e.g. one read from a file: an earlier version of the shipped rig, kept to
    replay takes recorded on it) is the scanned head's: its skin is the scan's simulated skin."""
    tris = skin_layout().triangles
    return (len(rig.mesh.vertices) == len(skin_layout().vertices)
            and np.array_equal(np.asarray(rig.mesh.triangles), np.asarray(tris)))


_MODELS: dict[bytes, object] = {}


def scan_model(weights: np.ndarray | None = None, bound_forehead: bool = True):  # type: ignore[no-untyped-def]
    """The scanned head compiled with `scan_params(bound_forehead)` (kept for the process; the
    application caches it on disk through `puppet.face_cache.scan_model`)."""
    from sim.build import compile_model

    w = None if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    key = (b"generic" if w is None else w.tobytes()) + (b"" if bound_forehead else THIN_FOREHEAD_KEY)
    if key not in _MODELS:
        if len(_MODELS) >= 4:
            _MODELS.pop(next(iter(_MODELS)))
        _MODELS[key] = compile_model(scan_rig(w), scan_params(bound_forehead))
    return _MODELS[key]
