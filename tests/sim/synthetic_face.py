"""A small synthetic face for the simulation tests: a curved, mirror-symmetric grid patch with the
landmarks, eye and mouth loops, jaw weights and held border that a FaceMesh carries. No holes: the
tests that need real eye and mouth openings use the procedural face builder."""

from __future__ import annotations

import numpy as np

from sim.model import FaceMesh


def _surface_z(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    nose = 1.8 * np.exp(-((x / 0.9) ** 2) - ((y + 3.0) / 2.2) ** 2)
    return -0.045 * x**2 - 0.012 * (y + 2.0) ** 2 + nose


def _ring(vertices: np.ndarray, cx: float, cy: float, a: float, b: float) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    pts = np.stack([cx + a * np.cos(t), cy + b * np.sin(t)], axis=1)
    d = ((vertices[None, :, :2] - pts[:, None, :]) ** 2).sum(-1)
    idx = np.argmin(d, axis=1)
    _, first = np.unique(idx, return_index=True)
    return idx[np.sort(first)]


def synthetic_face(spacing: float = 0.5) -> FaceMesh:
    """Grid from x in [-7, 7], y in [-11.5, 7] cm (eye line at y = 0), spacing cm, symmetric in x."""
    nx = int(round(7.0 / spacing))
    xs = np.arange(-nx, nx + 1) * spacing
    ys = np.arange(-11.5, 7.0 + 1e-9, spacing)
    X, Y = np.meshgrid(xs, ys)
    verts = np.stack([X.ravel(), Y.ravel(), _surface_z(X.ravel(), Y.ravel())], axis=1)
    ncol = len(xs)
    tris = []
    for r in range(len(ys) - 1):
        for c in range(ncol - 1):
            a, b = r * ncol + c, r * ncol + c + 1
            d, e = a + ncol, b + ncol
            if xs[c] < 0:  # diagonals mirror across x = 0 so the mesh is symmetric
                tris += [(a, b, e), (a, e, d)]
            else:
                tris += [(a, b, d), (b, e, d)]
    tris_arr = np.array(tris, dtype=np.int32)

    def near(x: float, y: float) -> int:
        return int(np.argmin((verts[:, 0] - x) ** 2 + (verts[:, 1] - y) ** 2))

    marks = {
        "eye_inner_l": (1.5, 0.0), "eye_outer_l": (4.5, 0.0), "brow_inner_l": (1.5, 1.5),
        "brow_outer_l": (4.5, 1.5), "mouth_corner_l": (2.5, -7.0), "nose_wing_l": (1.5, -4.0),
        "cheek_l": (4.0, -3.0),
    }
    landmarks: dict[str, int] = {}
    for name, (x, y) in marks.items():
        landmarks[name] = near(x, y)
        landmarks[name[:-2] + "_r"] = near(-x, y)
    for name, (x, y) in {"nose_tip": (0.0, -3.0), "nose_bridge": (0.0, 0.5), "chin": (0.0, -10.5),
                         "upper_lip_center": (0.0, -6.5), "lower_lip_center": (0.0, -7.5)}.items():
        landmarks[name] = near(x, y)
    held = (np.abs(verts[:, 0]) > 6.9) | (verts[:, 1] > 6.9) | (verts[:, 1] < -11.4)
    jaw = np.clip((-7.0 - verts[:, 1]) / 1.5, 0.0, 1.0) * np.clip((6.0 - np.abs(verts[:, 0])) / 1.5, 0.0, 1.0)
    z_eye = float(_surface_z(np.array(3.0), np.array(0.0)))
    eye_centers = np.array([[3.0, 0.0, z_eye - 1.0], [-3.0, 0.0, z_eye - 1.0]])
    return FaceMesh(
        vertices=verts,
        triangles=tris_arr,
        landmarks=landmarks,
        held=held,
        jaw_weight=jaw,
        jaw_pivot=np.array([0.0, -2.5, -6.0]),
        jaw_axis=np.array([1.0, 0.0, 0.0]),
        eye_centers=eye_centers,
        eye_radius=1.2,
        eye_loops=(_ring(verts, 3.0, 0.0, 1.5, 0.55), _ring(verts, -3.0, 0.0, 1.5, 0.55)),
        mouth_loop=_ring(verts, 0.0, -7.0, 2.5, 0.25),
        regions={"forehead": verts[:, 1] > 2.0},
        uv=verts[:, :2].copy(),
    )
