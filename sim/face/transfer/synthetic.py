"""A small procedural face-like rig (cm, project frame) with openings, landmarks and muscles.

It exists so the transfer can be tested and benchmarked on known geometry at any resolution, and
without the default face: a head is an elliptic cylinder with a nose, brows, lips and chin, eye and
mouth holes, and a few muscles of each type. It is not meant to look good."""

from __future__ import annotations

import numpy as np

from sim.model import FaceMesh, FaceRig, LinearMuscle, SheetMuscle, SphincterMuscle
from sim.face.transfer.geometry import boundary_loops

FloatArray = np.ndarray

H_RANGE = (-12.0, 10.0)
EYES = ((0.34, 2.5), (-0.34, 2.5))  # (theta, h) of the left (+X) and right eye openings
EYE_AXES = (0.17, 0.42)
MOUTH = ((0.0, -5.0), (0.27, 0.3))

# Landmark (theta, h); theta > 0 is the face's own left (+X).
SPOTS: dict[str, tuple[float, float]] = {
    "forehead_center": (0.0, 8.0), "glabella": (0.0, 4.3), "nose_bridge": (0.0, 3.0),
    "nose_tip": (0.0, -2.5), "subnasale": (0.0, -3.6), "upper_lip_top": (0.0, -4.2),
    "lower_lip_bottom": (0.0, -6.0), "chin": (0.0, -10.5),
}
for _s, _k in (("l", 1.0), ("r", -1.0)):
    SPOTS.update({
        f"brow_inner_{_s}": (_k * 0.15, 4.1), f"brow_mid_{_s}": (_k * 0.33, 4.5),
        f"brow_outer_{_s}": (_k * 0.52, 4.1), f"nose_wing_{_s}": (_k * 0.17, -2.8),
        f"cheek_{_s}": (_k * 0.55, -1.0), f"jaw_angle_{_s}": (_k * 1.15, -7.0),
    })
# Landmarks that sit on an opening's rim: (opening, theta, h).
RIM: dict[str, tuple[str, float, float]] = {
    "upper_lip_center": ("mouth", 0.0, -4.7), "lower_lip_center": ("mouth", 0.0, -5.3),
    "mouth_corner_l": ("mouth", 0.27, -5.0), "mouth_corner_r": ("mouth", -0.27, -5.0),
}
for _i, (_s, _k) in enumerate((("l", 1.0), ("r", -1.0))):
    _t = EYES[_i][0]
    RIM.update({
        f"eye_inner_{_s}": (f"eye_{_s}", _t - _k * EYE_AXES[0], 2.5),
        f"eye_outer_{_s}": (f"eye_{_s}", _t + _k * EYE_AXES[0], 2.5),
        f"upper_lid_{_s}": (f"eye_{_s}", _t, 2.5 + EYE_AXES[1]),
        f"lower_lid_{_s}": (f"eye_{_s}", _t, 2.5 - EYE_AXES[1]),
    })


def radius(theta: FloatArray, h: FloatArray) -> FloatArray:
    """Distance from the vertical axis of the synthetic skin at (theta, h)."""
    base = 1.0 / np.sqrt((np.sin(theta) / 7.2) ** 2 + (np.cos(theta) / 9.5) ** 2)
    taper = np.clip(1.0 - 0.0022 * (h + 1.0) ** 2, 0.6, 1.0)
    g = lambda x, s: np.exp(-0.5 * (x / s) ** 2)  # noqa: E731
    nose_h = np.where(h >= -2.5, np.clip((4.0 - h) / 6.5, 0.0, 1.0), np.exp(-((h + 2.5) / 0.6) ** 2))
    nose = 2.3 * nose_h * g(theta, 0.11)
    brow = 0.4 * g(h - 4.2, 0.6) * g(theta, 0.7)
    lips = 0.5 * g(h + 5.0, 0.8) * g(theta, 0.3)
    chin = 0.7 * g(h + 10.0, 1.2) * g(theta, 0.3)
    sockets = sum(-0.6 * g(theta - t, 0.16) * g(h - e, 0.9) for t, e in EYES)
    return base * taper + nose + brow + lips + chin + sockets


def surface_point(theta: FloatArray, h: FloatArray, depth: float = 0.0) -> FloatArray:
    """Point(s) of the skin, or `depth` cm inside it along the radius."""
    theta, h = np.asarray(theta, float), np.asarray(h, float)
    r = radius(theta, h) - depth
    return np.stack([r * np.sin(theta), h + 0 * r, r * np.cos(theta)], axis=-1)


def _in_openings(theta: FloatArray, h: FloatArray, mouth: bool = True, eyes: bool = True) -> np.ndarray:
    hole = np.zeros(theta.shape, bool)
    for (t, e) in EYES if eyes else ():
        hole |= ((theta - t) / EYE_AXES[0]) ** 2 + ((h - e) / EYE_AXES[1]) ** 2 < 1.0
    (t, e), (a, b) = MOUTH
    return hole | (mouth & (((theta - t) / a) ** 2 + ((h - e) / b) ** 2 < 1.0))


def synthetic_mesh(
    n_theta: int = 48, n_h: int = 44, full_head: bool = False, mouth_open: bool = True, eyes_open: bool = True
) -> tuple[FloatArray, np.ndarray, FloatArray]:
    """(vertices, triangles, (theta, h) per vertex) of the synthetic skin with its openings; a
    full head wraps all the way round (open at crown and neck), otherwise a face mask; with
    mouth_open False the lips are closed (no mouth hole), like many scans; with eyes_open False
    the lids are shut (no eye holes), like a scan taken with the eyes closed."""
    t_lo, t_hi = (-np.pi, np.pi) if full_head else (-1.45, 1.45)
    thetas = np.linspace(t_lo, t_hi, n_theta, endpoint=not full_head)
    hs = np.linspace(*H_RANGE, n_h)
    tt, hh = np.meshgrid(thetas, hs)
    vid = np.arange(tt.size).reshape(tt.shape)
    cols = n_theta if full_head else n_theta - 1
    a = vid[:-1, :cols]
    b = np.roll(vid, -1, axis=1)[:-1, :cols]
    c = vid[1:, :cols]
    d = np.roll(vid, -1, axis=1)[1:, :cols]
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([b, d, c], -1).reshape(-1, 3)])
    th, h = tt.ravel(), hh.ravel()
    cen_t = np.angle(np.exp(1j * th[tris]).mean(axis=1))
    tris = tris[~_in_openings(cen_t, h[tris].mean(axis=1), mouth_open, eyes_open)]
    used = np.unique(tris)
    remap = -np.ones(th.size, dtype=np.int64)
    remap[used] = np.arange(len(used))
    th, h = th[used], h[used]
    return surface_point(th, h), remap[tris].astype(np.int32), np.stack([th, h], axis=1)


def _nearest(param: FloatArray, t: float, h: float, among: np.ndarray | None = None) -> int:
    d = (param[:, 0] - t) ** 2 * 81.0 + (param[:, 1] - h) ** 2
    if among is not None:
        d = np.where(among, d, np.inf)
    return int(d.argmin())


def opening_loops(triangles: np.ndarray, param: FloatArray) -> dict[str, np.ndarray]:
    """The eye_l, eye_r and mouth boundary loops of a synthetic mesh."""
    centres = {"eye_l": EYES[0], "eye_r": EYES[1], "mouth": MOUTH[0]}
    out = {}
    for loop in boundary_loops(triangles):
        mt, mh = param[loop, 0].mean(), param[loop, 1].mean()
        for key, (t, h) in centres.items():
            if abs(mt - t) < 0.1 and abs(mh - h) < 0.5:
                out[key] = loop
    return out


def synthetic_landmarks(triangles: np.ndarray, param: FloatArray) -> dict[str, int]:
    """Landmark name -> vertex index; rim landmarks are taken on their opening's loop."""
    loops = opening_loops(triangles, param)
    out = {n: _nearest(param, t, h) for n, (t, h) in SPOTS.items()}
    for n, (key, t, h) in RIM.items():
        mask = np.zeros(len(param), bool)
        mask[loops[key]] = True
        out[n] = _nearest(param, t, h, mask)
    return out


def synthetic_muscles() -> dict[str, tuple]:
    """A few muscles of each type, defined on the synthetic skin's parameters (cm)."""
    p = surface_point
    zyg = tuple(LinearMuscle(f"zygomatic_major_{s}", p(k * 0.75, 0.5, 1.0), p(k * 0.26, -4.9, 0.3),
                             2.0, 0.5, 1.0, 4000.0) for s, k in (("l", 1), ("r", -1)))
    corr = tuple(LinearMuscle(f"corrugator_{s}", p(k * 0.3, 4.6, 0.8), p(k * 0.1, 4.0, 0.2),
                              1.2, 0.6, 1.0, 2000.0) for s, k in (("l", 1), ("r", -1)))
    oris = SphincterMuscle("orbicularis_oris", p(0.0, -5.0, 0.8), np.array([1.0, 0, 0]),
                           np.array([0, 1.0, 0]), 2.4, 1.3, 3000.0)
    front = SheetMuscle("frontalis", p(-0.35, 9.5, 0.8), p(0.35, 9.5, 0.8), p(-0.35, 5.2, 0.2),
                        p(0.35, 5.2, 0.2), 4.3, 6.0, 1.0, 3000.0)
    return {"smile": zyg, "brow_lower": corr, "lip_pucker": (oris,), "brow_raise": (front,)}


def synthetic_rig(n_theta: int = 48, n_h: int = 44, full_head: bool = False) -> FaceRig:
    """The synthetic face as a FaceRig (mesh fields filled the way sim/model.py documents)."""
    v, t, param = synthetic_mesh(n_theta, n_h, full_head)
    th, h = param[:, 0], param[:, 1]
    loops = opening_loops(t, param)
    dh = (H_RANGE[1] - H_RANGE[0]) / (n_h - 1)
    held = (h < H_RANGE[0] + 1.5 * dh) | (h > H_RANGE[1] - 1.5 * dh) | (np.abs(th) > 1.3)
    jaw = np.clip((-5.3 - h) / 2.5, 0.0, 1.0) * (np.abs(th) < 1.2)
    eyes = np.stack([surface_point(et, eh, 1.3) for et, eh in EYES])
    mesh = FaceMesh(
        vertices=v, triangles=t, landmarks=synthetic_landmarks(t, param), held=held,
        jaw_weight=jaw, jaw_pivot=np.array([0.0, -2.5, -1.0]), jaw_axis=np.array([1.0, 0.0, 0.0]),
        eye_centers=eyes, eye_radius=1.2, eye_loops=(loops["eye_l"], loops["eye_r"]),
        mouth_loop=loops["mouth"], regions={"forehead": h > 4.8, "lower_lip": (h < -5) & (h > -6.5) & (np.abs(th) < 0.3)},
        uv=np.stack([(th + np.pi) / (2 * np.pi), (h - H_RANGE[0]) / (H_RANGE[1] - H_RANGE[0])], axis=1))
    return FaceRig(mesh=mesh, muscles=synthetic_muscles(), name="synthetic")


def coarse_transferred_head() -> FaceRig:
    """The default face's rig (resolution 0, 864 vertices) carried onto a 437-vertex sampling of
    the same surface (`sim.face.builder.build_coarse_face_mesh`: 16 vertices per eye opening, 20
    round the mouth, no wrinkle rows), given to the transfer as a user's mesh and landmark file
    would be: the low-polygon head of tests and benchmarks for lids, lips and amplitudes."""
    from sim.face.builder import build_coarse_face_mesh
    from sim.face import default_rig
    from sim.face.transfer.landmarks import parse_landmarks
    from sim.face.transfer.meshfile import from_arrays
    from sim.face.transfer.pipeline import TransferOptions, transfer_rig

    mesh = build_coarse_face_mesh()
    lms = parse_landmarks({k: int(i) for k, i in mesh.landmarks.items()}, "coarse.json")
    head = from_arrays(mesh.vertices, mesh.triangles, "coarse.obj")
    # on the integrator its work picks (RK2), as the amplitudes it was measured with
    return transfer_rig(default_rig(0), head, lms, name="coarse", options=TransferOptions(integrator="auto")).rig
