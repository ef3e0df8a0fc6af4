"""Seed 003 section 3.1 (end) and 3.2: project a mask radially onto its cylinder, unroll the
cylinder into the plane, and cast points of the plane back onto a surface along the radius."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.face.transfer.cylinder import Cylinder
from sim.face.transfer.geometry import locate_2d, ray_triangle

FloatArray = np.ndarray
IntArray = np.ndarray


@dataclass(frozen=True)
class CylinderChart:
    """An unrolled cylinder. Flat coordinates are (u, v) = (r * theta, height along the axis);
    theta = 0 faces `front`, positive theta turns towards `left` = axis x front (the face's own
    left when the axis is up and front is forward), so the seam lies behind the head."""

    cylinder: Cylinder
    front: FloatArray
    left: FloatArray

    @classmethod
    def facing(cls, cylinder: Cylinder, forward: FloatArray) -> CylinderChart:
        """The chart whose seam is opposite `forward` (the face's forward direction)."""
        axis = cylinder.axis
        f = np.asarray(forward, float) - (np.asarray(forward, float) @ axis) * axis
        norm = np.linalg.norm(f)
        if norm < 1e-9:
            raise ValueError("the forward direction is parallel to the cylinder axis")
        f = f / norm
        return cls(cylinder, f, np.cross(axis, f))

    def flatten(self, points: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Flat (u, v) (P, 2) of each point and its distance rho (P,) from the axis."""
        c = self.cylinder
        w = np.atleast_2d(np.asarray(points, float)) - c.origin
        h = w @ c.axis
        x, y = w @ self.front, w @ self.left
        theta = np.arctan2(y, x)
        return np.stack([c.radius * theta, h], axis=1), np.hypot(x, y)

    def rays(self, uv: FloatArray) -> tuple[FloatArray, FloatArray]:
        """For flat points, the ray from the axis outwards along the radius: (origins, unit dirs)."""
        c = self.cylinder
        uv = np.atleast_2d(np.asarray(uv, float))
        theta = uv[:, 0] / c.radius
        origins = c.origin + np.outer(uv[:, 1], c.axis)
        dirs = np.outer(np.cos(theta), self.front) + np.outer(np.sin(theta), self.left)
        return origins, dirs

    def unflatten(self, uv: FloatArray, rho: FloatArray) -> FloatArray:
        """The 3D point at flat position uv and distance rho from the axis."""
        origins, dirs = self.rays(uv)
        return origins + np.asarray(rho, float)[:, None] * dirs


def flat_triangulation(
    chart: CylinderChart, vertices: FloatArray, triangles: IntArray
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Flatten a mesh on a chart, dropping triangles that straddle the seam (behind the head).
    Returns (uv (N,2), rho (N,), kept triangle indices)."""
    uv, rho = chart.flatten(vertices)
    span = np.ptp(uv[triangles, 0], axis=1)
    keep = np.nonzero(span < np.pi * chart.cylinder.radius)[0]
    return uv, rho, keep


def project_back(
    chart: CylinderChart,
    uv: FloatArray,
    vertices: FloatArray,
    triangles: IntArray,
    mesh_uv: FloatArray,
    keep: IntArray,
    k: int = 12,
) -> tuple[FloatArray, np.ndarray]:
    """Cast each flat point back onto the surface along the cylinder's radius (seed 003 sec 3.2,
    'project it back onto the surface of the new face'). Candidate triangles come from the flat
    chart; the exact ray-triangle hit is taken and, where a ray meets several layers (lids, nose),
    the outermost. Rays that miss (through an opening or past the border) fall back to the
    nearest flat triangle's barycentric point. Returns (points (P,3), hit (P,) bool)."""
    uv = np.atleast_2d(np.asarray(uv, float))
    tris = triangles[keep]
    origins, dirs = chart.rays(uv)
    from scipy.spatial import cKDTree

    tree = cKDTree(mesh_uv[tris].mean(axis=1))
    k = min(k, len(tris))
    _, cand = tree.query(uv, k=k)
    cand = cand.reshape(len(uv), k)
    tv = vertices[tris[cand]]  # (P, k, 3, 3)
    t = ray_triangle(origins[:, None], dirs[:, None], tv[..., 0, :], tv[..., 1, :], tv[..., 2, :])
    t_fin = np.where(np.isfinite(t), t, -np.inf)
    best = t_fin.max(axis=1)
    hit = np.isfinite(best)
    points = origins + np.where(hit, best, 0.0)[:, None] * dirs
    if not hit.all():
        miss = ~hit
        tri, bary, _ = locate_2d(uv[miss], mesh_uv, tris)
        points[miss] = np.einsum("pk,pkj->pj", bary, vertices[tris[tri]])
    return points, hit


def hidden_under(
    chart: CylinderChart, vertices: FloatArray, triangles: IntArray, uv: FloatArray, keep: IntArray,
    depth: float,
) -> np.ndarray:
    """(N,) bool: vertices lying more than `depth` under another layer of the surface, seen along
    the cylinder's radius (the inside of the mouth behind the lips, an eye socket's lining behind
    the lids, the inside of the nostrils). A user's head often models those; the rig must know
    them, since nothing outside the face should be drawn where the mouth parts."""
    outer, hit = project_back(chart, uv, vertices, triangles, uv, keep)
    _, rho_outer = chart.flatten(outer)
    _, rho = chart.flatten(vertices)
    return hit & (rho_outer - rho > depth)
