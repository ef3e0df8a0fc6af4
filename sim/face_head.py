"""The rest of the default face's head: cranium, ears and neck, held (not simulated).

The simulated mask (sim.face_builder) ends at the hairline, in front of the ears and under the
chin. `head_shell(mesh)` builds a static closed-looking head around it, in the mask's frame (cm,
+Y up, +Z forward), from adult proportions: head breadth ~15 cm, vertex ~23 cm above the chin,
back of the head ~19 cm behind the glabella, ears ~6 cm long between brow and nose-base level
just behind the jaw hinge, a neck ~11 cm across. Where the mask covers a direction from the head's
centre, the cranium is pulled in behind it (so it never pokes through the face); elsewhere it is
the ellipsoid. Each vertex carries a hair weight (1 on the scalp, 0 on skin) for the renderer.
Only the default face gets one (`shell_for`): an imported head brings its own.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np
from scipy.spatial import cKDTree

from sim.model import FaceMesh, FaceRig

CRANIUM_CENTRE = np.array([0.0, 1.5, -8.3])
CRANIUM_AXES = np.array([7.0, 10.0, 10.6])  # cm: half breadth, centre to vertex, centre to back
BEHIND_MASK = 0.6  # cm the cranium stays behind the mask where the mask covers it
EAR_CENTRE = np.array([6.95, -2.3, -8.9])  # the left ear (the right one mirrors it)
EAR_AXES = np.array([0.75, 3.0, 1.75])  # thickness, height, width
EAR_TILT = 0.26  # rad the ear leans back
NECK_CENTRE = np.array([0.0, 0.0, -7.2])
NECK_AXES = (5.4, 4.6)  # half width, half depth at the top; widening below
NECK_Y = (-6.0, -22.0)


@dataclass(frozen=True)
class HeadShell:
    """vertices (M,3) cm, triangles (K,3) int32 (counter-clockwise seen from outside), hair (M,)
    in 0..1."""

    vertices: np.ndarray
    triangles: np.ndarray
    hair: np.ndarray


def _grid_triangles(rows: int, cols: int, wrap: bool, start: int = 0) -> np.ndarray:
    """Two triangles per quad of a rows x cols grid (vertex r * cols + c), columns wrapping."""
    out = []
    last = cols if wrap else cols - 1
    for r in range(rows - 1):
        for c in range(last):
            a, b = r * cols + c, r * cols + (c + 1) % cols
            d, e = a + cols, b + cols
            out += [(a, d, b), (b, d, e)]
    return np.array(out, dtype=np.int32) + start


def _ellipsoid(centre: np.ndarray, axes: np.ndarray, n_lat: int, n_lon: int) -> tuple[np.ndarray, np.ndarray]:
    """Points of an ellipsoid on a lat-long grid (poles along +Y and -Y excluded) and their
    directions; latitude rows from the top."""
    lat = np.linspace(0.0, np.pi, n_lat + 2)[1:-1]
    lon = np.linspace(0.0, 2.0 * np.pi, n_lon, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    d = np.stack([np.sin(la) * np.sin(lo), np.cos(la), np.sin(la) * np.cos(lo)], axis=-1).reshape(-1, 3)
    return centre + d * axes, d


def _cranium(mesh: FaceMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_lat, n_lon = 22, 36
    pts, _ = _ellipsoid(CRANIUM_CENTRE, CRANIUM_AXES, n_lat, n_lon)
    # pull the shell in behind the mask wherever the mask lies in that direction from the centre
    rel = np.asarray(mesh.vertices) - CRANIUM_CENTRE
    r_mask = np.linalg.norm(rel, axis=1)
    tree = cKDTree(rel / r_mask[:, None])
    rel_p = pts - CRANIUM_CENTRE
    r_p = np.linalg.norm(rel_p, axis=1)
    dist, idx = tree.query(rel_p / r_p[:, None], k=8)
    covered = dist[:, 0] < 0.12  # rad: within the mask's angular coverage
    inner = np.min(r_mask[idx], axis=1) - BEHIND_MASK
    r_new = np.where(covered, np.minimum(r_p, inner), r_p)
    pts = CRANIUM_CENTRE + rel_p * (r_new / r_p)[:, None]
    # poles closed by fans
    top = CRANIUM_CENTRE + [0.0, CRANIUM_AXES[1], 0.0]
    bottom = CRANIUM_CENTRE - [0.0, CRANIUM_AXES[1], 0.0]
    verts = np.vstack([pts, top, bottom])
    tris = [_grid_triangles(n_lat, n_lon, True)]
    t, b = len(pts), len(pts) + 1
    last = (n_lat - 1) * n_lon
    tris.append(np.array([(t, (c + 1) % n_lon, c) for c in range(n_lon)], dtype=np.int32))
    tris.append(np.array([(b, last + c, last + (c + 1) % n_lon) for c in range(n_lon)], dtype=np.int32))
    y, z = verts[:, 1], verts[:, 2]
    # scalp: above the hairline at the front, down to the nape at the back, clear of the ears
    hairline = 6.0 - 9.5 * np.clip((-z - 2.0) / 12.0, 0.0, 1.0)
    t = np.clip((y - hairline) / 1.0, 0.0, 1.0)
    hair = t * t * (3.0 - 2.0 * t)
    return verts, np.vstack(tris), hair


def _ear(side: float) -> tuple[np.ndarray, np.ndarray]:
    pts, d = _ellipsoid(np.zeros(3), EAR_AXES, 10, 16)
    # a shallow bowl facing out and forward: the concha, so the ear reads as an ear, not an egg
    outward = d[:, 0] > 0
    pts[outward, 0] -= 0.45 * EAR_AXES[0] * (1.0 - d[outward, 1] ** 2 - d[outward, 2] ** 2).clip(0) ** 0.5
    c, s = np.cos(EAR_TILT), np.sin(EAR_TILT)
    rot = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    pts = pts @ rot.T + EAR_CENTRE
    pts[:, 0] *= side
    tris = _grid_triangles(10, 16, True)
    top, bottom = len(pts), len(pts) + 1
    verts = np.vstack([pts, EAR_CENTRE * [side, 1, 1] + rot @ [0, EAR_AXES[1], 0] * [side, 1, 1],
                       EAR_CENTRE * [side, 1, 1] - rot @ [0, EAR_AXES[1], 0] * [side, 1, 1]])
    last = 9 * 16
    fans = [(top, (k + 1) % 16, k) for k in range(16)] + [(bottom, last + k, last + (k + 1) % 16) for k in range(16)]
    tris = np.vstack([tris, np.array(fans, dtype=np.int32)])
    if side < 0:  # mirrored: keep the triangles counter-clockwise from outside
        tris = tris[:, [0, 2, 1]]
    return verts, tris


def _neck() -> tuple[np.ndarray, np.ndarray]:
    rows, cols = 8, 32
    ys = np.linspace(NECK_Y[0], NECK_Y[1], rows)
    ang = np.linspace(0.0, 2.0 * np.pi, cols, endpoint=False)
    widen = 1.0 + 0.35 * np.clip((ys[0] - ys - 10.0) / 6.0, 0.0, 1.0) ** 2  # towards the shoulders
    ring = np.stack([np.sin(ang) * NECK_AXES[0], np.zeros(cols), np.cos(ang) * NECK_AXES[1]], axis=1)
    verts = np.vstack([NECK_CENTRE + ring * [w, 0, 1] + [0, y, 0] for y, w in zip(ys, widen)])
    return verts, _grid_triangles(rows, cols, True)


def head_shell(mesh: FaceMesh) -> HeadShell:
    """Cranium, both ears and the neck around a default-face mask, as one static mesh."""
    parts = [(*_cranium(mesh),)]
    for side in (1.0, -1.0):
        v, t = _ear(side)
        parts.append((v, t, np.zeros(len(v))))
    v, t = _neck()
    parts.append((v, t, np.zeros(len(v))))
    verts, tris, hair, base = [], [], [], 0
    for v, t, h in parts:
        verts.append(v)
        tris.append(t + base)
        hair.append(h)
        base += len(v)
    return HeadShell(np.vstack(verts).astype(np.float64), np.vstack(tris).astype(np.int32),
                     np.concatenate(hair).astype(np.float64))


def shell_for(rig: FaceRig) -> HeadShell | None:
    """The head around the default face (a rig named default-N), or None for any other rig."""
    if not str(rig.name).startswith("default-"):
        return None
    return head_shell(rig.mesh)
