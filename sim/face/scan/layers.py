"""The scanned head's soft tissue as layers (`sim.layered`): thickness and retaining ligaments.

The scan holds no skull; what lies under its skin is the teeth and gums, the mouth's and the eyes'
sockets and the eyeballs. The tissue's thickness under a skin vertex is taken from them: the
distance to the nearest of those parts, less a millimetre, within THICKNESS_MIN..THICKNESS_MAX
(each of the two layers is half of it), so it is thin on the lids and over the teeth's roots and
thick over the cheeks.

The retaining ligaments (where skin is tied through the fat to bone: the orbital rim, the
zygoma's body, the mandible in front of the jowl, and the lips' skin, which lies on the orbicularis
without fat) are smooth bands placed from the landmarks; `ligaments` gives a field 0..1 over the
skin (1 on a ligament).
"""

from __future__ import annotations

import numpy as np

THICKNESS_MIN, THICKNESS_MAX = 0.2, 1.6  # cm, the whole soft tissue (the two layers together)
INNER_PARTS = ("mouth_socket", "gums_tongue", "teeth", "eyeball_l", "eyeball_r", "eye_socket_l", "eye_socket_r")


def tissue_thickness(model) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(N,) cm: the soft tissue's depth under each skin vertex of the scanned face at rest."""
    from scipy.spatial import cKDTree

    from sim.face.scan.anatomy import skin_layout
    from sim.face.scan.data import PARTS, scan_data

    data = scan_data()
    inner = np.concatenate([np.arange(*PARTS[p]) for p in INNER_PARTS])
    skin = skin_layout().vertices
    d, _ = cKDTree(data.neutral[inner]).query(data.neutral[skin])
    if len(skin) != model.n_vertices:
        raise ValueError("the model's skin is not the scanned head's")
    return np.clip(d - 0.1, THICKNESS_MIN, THICKNESS_MAX)


def ligaments(model, width: float = 0.5) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(N,) 0..1: the retaining ligaments' bands over the skin (Gaussian profiles `width` cm)."""
    rest = np.asarray(model.rest)
    p = {name: rest[model.landmark_index(name)] for name in (
        "eye_inner_l", "eye_outer_l", "eye_inner_r", "eye_outer_r", "mouth_corner_l", "mouth_corner_r",
        "upper_lip_center", "lower_lip_center", "upper_lip_top", "lower_lip_bottom", "chin",
        "jaw_angle_l", "jaw_angle_r")}
    out = np.zeros(len(rest))

    def band(dist: np.ndarray) -> None:
        np.maximum(out, np.exp(-0.5 * (dist / width) ** 2), out=out)

    for s in ("l", "r"):
        inner, outer = p[f"eye_inner_{s}"], p[f"eye_outer_{s}"]
        centre = 0.5 * (inner + outer)
        radius = 0.62 * np.linalg.norm(outer - inner)  # the orbital rim, about a third wider than the opening
        r = rest - centre
        r[:, 2] = 0.0  # seen from the front
        under = rest[:, 1] < centre[1] + 0.3 * radius  # the ORL's lower and lateral arc (the brow lies above)
        d = np.abs(np.linalg.norm(r, axis=1) - radius)
        band(np.where(under, d, np.inf))
        side = np.sign(outer[0] - inner[0])
        zyg = outer + np.array([0.4 * side, -1.8, 0.0])  # the zygoma's body, below and outside the eye
        band(np.linalg.norm((rest - zyg)[:, :2], axis=1) / 1.2)
        jaw = p[f"jaw_angle_{s}"]
        mand = p["chin"] + 0.3 * (jaw - p["chin"]) + np.array([0.0, 0.5, 0.0])  # in front of the jowl
        band(np.linalg.norm((rest - mand)[:, :2], axis=1) / 1.2)
    # the lips' skin: within the lips' outline (top of the upper lip to the bottom of the lower)
    mid = 0.5 * (p["upper_lip_top"] + p["lower_lip_bottom"])
    half_w = 0.5 * np.linalg.norm(p["mouth_corner_l"] - p["mouth_corner_r"])
    half_h = 0.5 * abs(p["upper_lip_top"][1] - p["lower_lip_bottom"][1])
    q = (rest - mid)[:, :2] / np.array([half_w, half_h])
    lips = np.linalg.norm(q, axis=1)
    band(np.maximum(lips - 1.0, 0.0) * half_h)
    return out
