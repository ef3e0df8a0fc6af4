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
from sim.face.scan.data import N_IDENTITIES, scan_data
from sim.model import FaceMesh, FaceRig, LinearMuscle, Muscle, PatchMuscle, SheetMuscle, SphincterMuscle

DIGITS = 7  # carried quantities are rounded to this many decimals (cm)
LID_ROWS = 3  # rows of lid skin from each eye opening that the eye contact sphere is fitted to
LID_CLEARANCE = 0.05  # cm: the contact sphere lies this far inside the lid skin


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
        if isinstance(m, PatchMuscle):  # a zero direction (a pressure along the normal) stays zero
            d = self.direction(m.direction) if np.any(m.direction) else np.zeros(3)
            return PatchMuscle(m.name, self.point(m.center), _r(np.asarray(m.semi_axes, float) / self.s.scale), d,
                               float(_r(m.scale)))
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


def _lid_sphere(points: np.ndarray, skin: np.ndarray, loop: np.ndarray, tri: np.ndarray,
                blink: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the sphere the lids slide on: through the first rows of lid skin
    around the opening, open (neutral) and closed (the scan's eyeBlink), least squares."""
    from sim.face.scan.anatomy import _rings

    rows = _rings(tri, len(skin), loop)
    near = np.flatnonzero(rows <= LID_ROWS)
    p = np.concatenate([points[skin[near]], points[skin[near]] + blink[skin[near]]])
    a = np.column_stack([2.0 * p, np.ones(len(p))])
    sol = np.linalg.lstsq(a, np.sum(p * p, axis=1), rcond=None)[0]
    c = sol[:3]
    r = float(np.sqrt(sol[3] + c @ c))
    # the lid skin at rest must lie outside: the radius is at most the nearest one's distance
    r = min(r, float(np.linalg.norm(points[skin] - c, axis=1).min()))
    return c, r - LID_CLEARANCE


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
    for side, loop in zip("LR", m.eye_loops):
        c, r = _lid_sphere(points, skin, np.asarray(loop), layout.triangles,
                           data.expression(f"eyeBlink_{side}"))
        centres.append(c)
        radii.append(r)
    mesh = FaceMesh(
        vertices=points[skin].copy(), triangles=layout.triangles.copy(), landmarks=dict(m.landmarks),
        held=np.asarray(m.held, bool).copy(), jaw_weight=_r(jaw_weights(points, skin)),
        jaw_pivot=back.point(m.jaw_pivot), jaw_axis=back.direction(m.jaw_axis),
        eye_centers=_r(np.array(centres)), eye_radius=float(_r(min(radii))),
        eye_loops=(np.asarray(m.eye_loops[0]), np.asarray(m.eye_loops[1])), mouth_loop=np.asarray(m.mouth_loop),
        regions={k: np.asarray(v, bool) for k, v in m.regions.items()}, uv=None if m.uv is None else _r(m.uv))
    muscles = {ch: tuple(back.muscle(p) for p in parts) for ch, parts in tr.rig.muscles.items()}
    wrinkles = tuple(back.wrinkle(w, skin, m.vertices) for w in tr.rig.wrinkles)
    return FaceRig(mesh=mesh, muscles=muscles, wrinkles=wrinkles, name=name)
