"""Carry rig geometry from the reference surface to the new one.

The correspondence is the reference mesh deformed onto the new surface (same triangles, every
vertex cast back onto the new face). A rig point is written as (reference triangle, barycentric
foot point, offset in the local frame at the foot) and rebuilt on the deformed triangle with the
offset scaled by the local stretch, so deep points (skull attachments, eye centres, the jaw hinge)
stay at the same relative depth under the new skin."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sim.model import LinearMuscle, Muscle, PatchMuscle, SheetMuscle, SphincterMuscle
from sim.face.transfer.geometry import closest_points, triangle_normals, vertex_normals

FloatArray = np.ndarray
IntArray = np.ndarray


def _unit(v: FloatArray) -> FloatArray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def _frames(normals: FloatArray, tv: FloatArray, bary: FloatArray) -> FloatArray:
    """(P, 3, 3) rows (t1, t2, n): n the interpolated vertex normal, t1 the first triangle edge
    made tangent, t2 = n x t1."""
    n = _unit(np.einsum("pk,pkj->pj", bary, normals))
    e = tv[:, 1] - tv[:, 0]
    t1 = _unit(e - np.einsum("pj,pj->p", e, n)[:, None] * n)
    return np.stack([t1, np.cross(n, t1), n], axis=1)


@dataclass
class SurfaceMap:
    """The reference mesh and its image on the new surface, with per-vertex stretch
    sqrt(area new / area reference), clipped to [0.2, 5] so one bad triangle cannot explode it.

    A point on the skin uses the local frame at its foot point; deeper points blend (linearly, fully
    at `deep` cm) towards a moving-least-squares affine map fitted to the vertex correspondences
    around them. The frame alone scales depth by the surface stretch and so misses a head's
    stretch in depth (eye centres); the affine map sees it, and it is the only sensible carrier for
    points far off the mask (the jaw hinge), which one boundary frame cannot place."""

    ref_vertices: FloatArray
    triangles: IntArray
    new_vertices: FloatArray
    deep: float = 2.0

    def __post_init__(self) -> None:
        self.ref_normals = vertex_normals(self.ref_vertices, self.triangles)
        self.new_normals = vertex_normals(self.new_vertices, self.triangles)
        a_ref = np.linalg.norm(triangle_normals(self.ref_vertices, self.triangles), axis=1)
        a_new = np.linalg.norm(triangle_normals(self.new_vertices, self.triangles), axis=1)
        ratio = np.sqrt(np.clip(a_new / np.maximum(a_ref, 1e-300), 0.04, 25.0))
        acc = np.zeros(len(self.ref_vertices))
        wsum = np.zeros(len(self.ref_vertices))
        for k in range(3):
            np.add.at(acc, self.triangles[:, k], a_ref * ratio)
            np.add.at(wsum, self.triangles[:, k], a_ref)
        self.stretch = np.divide(acc, wsum, out=np.ones_like(acc), where=wsum > 0)

    def points(self, points: FloatArray) -> FloatArray:
        """Map reference-frame points (P, 3) onto the new face."""
        pts = np.atleast_2d(np.asarray(points, float))
        foot, tri, bary, _ = closest_points(pts, self.ref_vertices, self.triangles)
        idx = self.triangles[tri]
        f_ref = _frames(self.ref_normals[idx], self.ref_vertices[idx], bary)
        f_new = _frames(self.new_normals[idx], self.new_vertices[idx], bary)
        local = np.einsum("pij,pj->pi", f_ref, pts - foot)
        scale = np.einsum("pk,pk->p", bary, self.stretch[idx])
        new_foot = np.einsum("pk,pkj->pj", bary, self.new_vertices[idx])
        near = new_foot + scale[:, None] * np.einsum("pij,pi->pj", f_new, local)
        dist = np.linalg.norm(pts - foot, axis=1)
        blend = np.clip(dist / self.deep, 0.0, 1.0)
        out = near.copy()
        for i in np.nonzero(blend > 0)[0]:
            out[i] = (1 - blend[i]) * near[i] + blend[i] * self._affine(pts[i], max(dist[i], 0.5 * self.deep))
        return out

    def _affine(self, p: FloatArray, width: float) -> FloatArray:
        """Moving least squares: the affine map best matching the correspondences, weighted by a
        Gaussian of width `width` (cm) around p, applied to p."""
        d2 = ((self.ref_vertices - p) ** 2).sum(axis=1)
        w = np.sqrt(np.exp(-0.5 * d2 / (width * width)))
        a = np.column_stack([self.ref_vertices - p, np.ones(len(d2))]) * w[:, None]
        sol, *_ = np.linalg.lstsq(a, self.new_vertices * w[:, None], rcond=None)
        return sol[3]

    def point(self, p: FloatArray) -> FloatArray:
        return self.points(np.asarray(p, float)[None])[0]


def _length_ratio(m: SurfaceMap, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    pa, pb = m.points(np.stack([a, b]))
    before = float(np.linalg.norm(b - a))
    return pa, pb, float(np.linalg.norm(pb - pa)) / before if before > 0 else 1.0


def carry_muscle(m: SurfaceMap, muscle: Muscle) -> Muscle:
    """One muscle on the new face: points mapped, zone sizes scaled by how much the muscle's own
    extent stretched; angles, exponents and force scales kept."""
    if isinstance(muscle, LinearMuscle):
        a, i, s = _length_ratio(m, muscle.attachment, muscle.insertion)
        return LinearMuscle(muscle.name, a, i, muscle.radius * s, muscle.angle, muscle.eta, muscle.scale)
    if isinstance(muscle, SphincterMuscle):
        c = np.asarray(muscle.center, float)
        ends = np.stack([c, c + muscle.a * muscle.major_axis, c - muscle.a * muscle.major_axis,
                         c + muscle.b * muscle.minor_axis, c - muscle.b * muscle.minor_axis])
        c2, ma, mb, na, nb = m.points(ends)
        major = ma - mb
        a = 0.5 * float(np.linalg.norm(major))
        major = major / np.linalg.norm(major)
        minor = na - nb
        minor = minor - (minor @ major) * major
        b = 0.5 * float(np.linalg.norm(na - nb))
        return SphincterMuscle(muscle.name, c2, major, minor / np.linalg.norm(minor), a, b, muscle.scale,
                               muscle.protrude)
    if isinstance(muscle, SheetMuscle):
        pts = np.stack([muscle.attach1, muscle.attach2, muscle.insert1, muscle.insert2]).astype(float)
        a1, a2, i1, i2 = m.points(pts)
        along = np.linalg.norm(0.5 * (i1 + i2) - 0.5 * (a1 + a2)) / max(
            np.linalg.norm(0.5 * (pts[2] + pts[3]) - 0.5 * (pts[0] + pts[1])), 1e-12)
        across = (np.linalg.norm(a2 - a1) + np.linalg.norm(i2 - i1)) / max(
            np.linalg.norm(pts[1] - pts[0]) + np.linalg.norm(pts[3] - pts[2]), 1e-12)
        return SheetMuscle(muscle.name, a1, a2, i1, i2, muscle.length * float(along),
                           muscle.width * float(across), muscle.eta, muscle.scale)
    if isinstance(muscle, PatchMuscle):
        c = np.asarray(muscle.center, float)
        sx, sy = float(muscle.semi_axes[0]), float(muscle.semi_axes[1])
        pts = np.stack([c, c + [sx, 0.0, 0.0], c - [sx, 0.0, 0.0], c + [0.0, sy, 0.0], c - [0.0, sy, 0.0]])
        c2, xa, xb, ya, yb = m.points(pts)
        kx = float(np.linalg.norm(xa - xb)) / (2.0 * sx)
        ky = float(np.linalg.norm(ya - yb)) / (2.0 * sy)
        axes = np.asarray(muscle.semi_axes, float) * np.array([kx, ky, 0.5 * (kx + ky)])
        return PatchMuscle(muscle.name, c2, axes, np.asarray(muscle.direction, float), muscle.scale)
    raise TypeError(f"unknown muscle type {type(muscle).__name__}")


def cover_sheet(m: SurfaceMap, reference: SheetMuscle, carried: SheetMuscle, strong: float = 0.25) -> SheetMuscle:
    """The carried sheet widened and slid along its attachment line until its zone (the rectangle
    of `sim.muscles.sheet_zone`) covers the skin the reference sheet pulls on, as the
    correspondence carries that skin (the reference's vertices where the sheet's fall-off reaches
    `strong` of its peak). The four points carry separately, the deep attachment and the skin's
    insertion by different maps, so the carried rectangle can lie askew on the skin it should
    cover: two neighbouring sheets (the frontalis' inner and outer parts) then leave a strip of
    skin between them that neither pulls. All four points move by the same vector along the
    attachment line, so the pull direction and every point's length ratio (eqs 19, 21) are kept;
    the width only grows, so a sheet already covering its skin is left as it is."""
    from sim.muscles import sheet_falloff, sheet_length_ratio, sheet_length_ratio_limit, sheet_zone

    ref_x = m.ref_vertices
    w = sheet_falloff(sheet_length_ratio(reference, ref_x), reference.eta,
                      sheet_length_ratio_limit(reference)) * sheet_zone(reference, ref_x)
    if not np.any(w > 0):
        return carried
    images = m.new_vertices[w >= strong * w.max()]
    a1, a2 = np.asarray(carried.attach1, float), np.asarray(carried.attach2, float)
    t = (a2 - a1) / np.linalg.norm(a2 - a1)
    ac = 0.5 * (a1 + a2)
    lateral = (images - ac) @ t
    lo = min(float(lateral.min()), -0.5 * carried.width)
    hi = max(float(lateral.max()), 0.5 * carried.width)
    shift = 0.5 * (lo + hi) * t
    return SheetMuscle(carried.name, a1 + shift, a2 + shift, np.asarray(carried.insert1, float) + shift,
                       np.asarray(carried.insert2, float) + shift, carried.length, hi - lo, carried.eta,
                       carried.scale)


def muscle_points(muscle: Muscle) -> FloatArray:
    """The defining points of a muscle, for comparisons and reports."""
    if isinstance(muscle, LinearMuscle):
        return np.stack([muscle.attachment, muscle.insertion])
    if isinstance(muscle, (SphincterMuscle, PatchMuscle)):
        return np.asarray(muscle.center, float)[None]
    return np.stack([muscle.attach1, muscle.attach2, muscle.insert1, muscle.insert2])


def frontal_to_surface(vertices: FloatArray, triangles: IntArray, xy: FloatArray) -> FloatArray:
    """Drop frontal (x, y) points onto the skin along -Z (the first, outermost hit), the way
    `sim.wrinkles` lays its lines; points off the mesh take the nearest triangle's plane."""
    from scipy.spatial import cKDTree

    from sim.face.transfer.geometry import locate_2d, ray_triangle

    xy = np.atleast_2d(np.asarray(xy, float))
    tv = vertices[triangles]
    k = min(24, len(triangles))
    _, cand = cKDTree(tv[:, :, :2].mean(axis=1)).query(xy, k=k)
    cand = cand.reshape(len(xy), k)
    top = float(vertices[:, 2].max()) + 1.0
    origins = np.column_stack([xy, np.full(len(xy), top)])
    down = np.array([0.0, 0.0, -1.0])
    c = tv[cand]
    t = ray_triangle(origins[:, None], down, c[..., 0, :], c[..., 1, :], c[..., 2, :]).min(axis=1)
    out = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * down
    miss = ~np.isfinite(t)
    if miss.any():
        tri, bary, _ = locate_2d(xy[miss], vertices[:, :2], triangles)
        out[miss] = np.einsum("pk,pkj->pj", bary, vertices[triangles[tri]])
    return out


def carry_wrinkle(m: SurfaceMap, line: Any) -> Any:
    """A wrinkle line of `sim.wrinkles` (frontal (x, y) polyline + roll widths) on the new face:
    its points dropped onto the reference skin, carried, and seen from the front again; roll
    widths scaled by the line's own change of length."""
    from dataclasses import replace

    pts3 = frontal_to_surface(m.ref_vertices, m.triangles, line.points)
    new3 = m.points(pts3)
    before = np.linalg.norm(np.diff(pts3, axis=0), axis=1).sum()
    after = np.linalg.norm(np.diff(new3, axis=0), axis=1).sum()
    s = float(after / before) if before > 0 else 1.0
    return replace(line, points=new3[:, :2].copy(), width_minus=line.width_minus * s,
                   width_plus=line.width_plus * s)
