"""The scanned head's rig: the skin of its face area with muscles, lids, lips, jaw hinge, wrinkle
lines and regions placed from its own landmarks by the rig transfer (`sim.face.transfer`).

Simulated: the scan's own vertices of the narrow face area, less the inside of the lips
(`sim.face.scan.anatomy.skin_layout`: 6188 of the 26719; everything else follows them, see
`sim.face.scan.dressing`). The rig is in the scan's own frame and units (cm, +Y up, facing +Z):
the transfer works in the project's reference frame, and its result is carried back by the inverse
of the similarity it fitted. The eyeballs are the scan's: the lids slide on the sphere through the
lid skin of the open and the scanned closed eye (`eyeBlink`), which covers the cornea.

An identity (`weights`, the 100 identity modes' weights) changes the positions only; the vertex
numbering, the landmarks and hence the rig's structure are the same for every identity. Carried
quantities are rounded to 1e-7 cm so the rig (and its hash) does not depend on the last bits of
the linear algebra kernels used by the transfer.
"""

from __future__ import annotations

import numpy as np

from sim.face.scan.anatomy import load_landmarks, skin_layout
from sim.face.scan.data import N_IDENTITIES, PARTS, scan_data
from sim.build import SkinParams, vertex_normals
from sim.model import FaceMesh, FaceRig, LinearMuscle, Muscle, SheetMuscle, SphincterMuscle

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
SCAN_PARAMS = SkinParams(bend_ratio=6.0, support=27000.0)
FORCE = 1.6
# the orbital sphincter (AU6) folds the skin round the eye first; the lid strips need twice the
# force to close the scan's lids over its cornea (AU45: 7-11.5 mm)
FORCE_OF = {"orbicularis_oculi": 0.7, "orbicularis_oculi_lid": 2.0}
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


class _Back:
    """The inverse of the transfer's similarity: points, directions and lengths back to the scan."""

    def __init__(self, similarity) -> None:  # type: ignore[no-untyped-def]
        self.s = similarity

    def point(self, p: np.ndarray) -> np.ndarray:
        return _r(self.s.invert(np.asarray(p, float)))

    def direction(self, d: np.ndarray) -> np.ndarray:
        v = np.asarray(d, float) @ self.s.rotation
        return _r(v / np.linalg.norm(v))

    def length(self, x: float) -> float:
        return float(_r(x / self.s.scale))

    def muscle(self, m: Muscle) -> Muscle:
        if isinstance(m, LinearMuscle):
            return LinearMuscle(m.name, self.point(m.attachment), self.point(m.insertion), self.length(m.radius),
                                float(_r(m.angle)), float(_r(m.eta)), float(_r(m.scale)))
        if isinstance(m, SphincterMuscle):
            return SphincterMuscle(m.name, self.point(m.center), self.direction(m.major_axis),
                                   self.direction(m.minor_axis), self.length(m.a), self.length(m.b), float(_r(m.scale)))
        assert isinstance(m, SheetMuscle)
        return SheetMuscle(m.name, self.point(m.attach1), self.point(m.attach2), self.point(m.insert1),
                           self.point(m.insert2), self.length(m.length), self.length(m.width), float(_r(m.eta)),
                           float(_r(m.scale)))

    def wrinkle(self, line, skin: np.ndarray, project_skin: np.ndarray):  # type: ignore[no-untyped-def]
        """A wrinkle line's frontal points: each put on the skin (the nearest skin vertex in the
        frontal plane of the project frame gives its depth), carried back, frontal again."""
        from dataclasses import replace

        from scipy.spatial import cKDTree

        pts = np.asarray(line.points, float)
        _, near = cKDTree(project_skin[:, :2]).query(pts)
        p3 = np.column_stack([pts, project_skin[near, 2]])
        back = self.s.invert(p3)
        scale = 1.0 / self.s.scale
        return replace(line, points=_r(back[:, :2]), width_minus=float(_r(line.width_minus * scale)),
                       width_plus=float(_r(line.width_plus * scale)))


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
    """The centre (3,) of one eyeball's sclera (least-squares sphere through its vertices)."""
    from sim.face.scan.data import SCLERA

    p = eyeball[:SCLERA]
    a = np.column_stack([2.0 * p, np.ones(len(p))])
    return np.linalg.lstsq(a, np.sum(p * p, axis=1), rcond=None)[0][:3]


def _rigid_fit(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t with b ~ R a + t, least squares (Kabsch)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rot, cb - rot @ ca


def jaw_weights(points: np.ndarray, skin: np.ndarray) -> np.ndarray:
    """(N,) how much each skin vertex follows the mandible, read off the scan's own `jawOpen`: the
    share of the lower teeth's rigid motion (fitted) that the vertex makes, clipped to [0, 1]. The
    transfer's weights cannot tell the upper lip's line from the lower one's (0.8 mm apart)."""
    from sim.face.scan.dressing import TEETH_SPLIT
    from sim.face.scan.data import PARTS

    delta = scan_data().expression("jawOpen")
    lower = np.arange(TEETH_SPLIT, PARTS["teeth"][1])
    rot, t = _rigid_fit(points[lower], points[lower] + delta[lower])
    p = points[skin]
    rigid = p @ rot.T + t - p
    w = np.einsum("ij,ij->i", delta[skin], rigid) / np.maximum(np.einsum("ij,ij->i", rigid, rigid), 1e-12)
    return np.clip(w, 0.0, 1.0)


def _stronger(m: Muscle, channel: str) -> Muscle:
    from dataclasses import replace

    base = channel[:-2] if channel.endswith(("_l", "_r")) else channel
    return replace(m, scale=float(_r(m.scale * FORCE_OF.get(base, FORCE))))


def scan_rig(weights: np.ndarray | None = None, name: str = "ict") -> FaceRig:
    """The scanned head's rig for an identity (None: the generic head). Takes a few seconds (the
    transfer); compile it through a cache (`puppet.face_cache.scan_model`)."""
    from sim.face import default_rig
    from sim.face.transfer.landmarks import LandmarkFile
    from sim.face.transfer.meshfile import HeadMesh
    from sim.face.transfer.pipeline import transfer_rig

    points = scan_points(weights)
    layout = skin_layout()
    skin = layout.vertices
    local = {int(s): i for i, s in enumerate(skin)}
    landmarks = {k: local[v] for k, v in load_landmarks().items()}
    head = HeadMesh(f"<{name} scan>", points[skin], layout.triangles, np.arange(len(skin)))
    tr = transfer_rig(default_rig(1), head, LandmarkFile(f"<{name} landmarks>", landmarks), name=name)
    m = tr.rig.mesh
    if len(m.vertices) != len(skin):
        raise RuntimeError("the scan's skin lost vertices in the transfer")
    back = _Back(tr.similarity)
    data = scan_data()
    centres, radii = [], []
    for part, loop in zip(("eyeball_l", "eyeball_r"), m.eye_loops):
        lo, hi = PARTS[part]
        c, r = _lid_sphere(points[lo:hi])
        centres.append(c)
        radii.append(r)
    # under the chin the skin is held and follows the jaw by its weights: between the chin and the
    # held neck it is squeezed as the jaw opens and buckled (0.6-1.9 cm2 of folds at jaw = 1)
    rest = points[skin]
    normal = vertex_normals(rest, layout.triangles)
    chin = rest[landmarks["chin"]]
    under = (normal[:, 1] < -0.5) & (rest[:, 1] < chin[1] - 0.3)
    mesh = FaceMesh(
        vertices=rest.copy(), triangles=layout.triangles.copy(), landmarks=dict(m.landmarks),
        held=np.asarray(m.held, bool) | under, jaw_weight=_r(jaw_weights(points, skin)),
        jaw_pivot=back.point(m.jaw_pivot), jaw_axis=back.direction(m.jaw_axis),
        eye_centers=_r(np.array(centres)), eye_radius=float(_r(min(radii))),
        eye_loops=(np.asarray(m.eye_loops[0]), np.asarray(m.eye_loops[1])), mouth_loop=np.asarray(m.mouth_loop),
        regions={k: np.asarray(v, bool) for k, v in m.regions.items()}, uv=None if m.uv is None else _r(m.uv))
    muscles = {ch: tuple(_stronger(back.muscle(p), ch) for p in parts) for ch, parts in tr.rig.muscles.items()}
    wrinkles = tuple(back.wrinkle(w, skin, m.vertices) for w in tr.rig.wrinkles)
    return FaceRig(mesh=mesh, muscles=muscles, wrinkles=wrinkles, name=name)


_MODELS: dict[bytes, object] = {}


def scan_model(weights: np.ndarray | None = None):  # type: ignore[no-untyped-def]
    """The scanned head compiled with `SCAN_PARAMS` (kept for the process; the application caches
    it on disk through `puppet.face_cache.scan_model`)."""
    from sim.build import compile_model

    w = None if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    key = b"generic" if w is None else w.tobytes()
    if key not in _MODELS:
        if len(_MODELS) >= 4:
            _MODELS.pop(next(iter(_MODELS)))
        _MODELS[key] = compile_model(scan_rig(w), SCAN_PARAMS)
    return _MODELS[key]
