"""Skin with a thickness: it neither turns over nor buckles into ripples at the mesh's own scale.

Real skin is a layer a millimetre or two thick over fat: pressed together it bunches into rounded
furrows, it does not fold over itself at the scale of its own thickness. A spring network has no
thickness; where a muscle compresses fine skin (the glabella under the corrugator, the cheek under a
smile, the lips in a pucker) a triangle can be pushed through its neighbour and turn its back to
the world. This term stands for the thickness that forbids it.

Each triangle's deformation is measured in the plane of its rest normal n0: with (e1, e2) an
orthonormal frame of that plane and Dm the triangle's rest edges in it, F = Ds Dm^-1 (2x2) where Ds
are the current edges projected onto the frame. det F is the triangle's projected area over its rest
area, and it reaches 0 when the triangle stands edge-on to its rest normal and goes negative when it
has turned over (the very test of `tests/sim/test_scan_face.py`). Above `floor` nothing happens. Below
it, F is projected onto the nearest deformation with det = floor (its signed singular values, the
smaller raised) and the triangle is pulled towards it by the gradient of w A0 |F - F'|^2, the
projective-dynamics continuum constraint of Bouaziz et al. 2014 (section 5, "strain limiting"), with
the determinant's sign kept as in their treatment of inversion. So the term is zero wherever the skin
is not close to folding: rest, drift and every pose that does not fold are untouched.

The force is evaluated at the implicit integrator's predicted positions and added to its right-hand
side (not to its constant matrix), as a one-sided, stiffening contact is: `stiffness` per triangle
is a fraction of its own edge springs' high-strain stiffness, which the matrix carries, so the
explicit part stays well inside what the implicit springs damp.

The second part, `skin_bending`, is what thickness does before anything folds: compressed skin a few
millimetres thick bunches into broad rolls, while a spring net as fine as the scan's (2.8 mm edges)
buckles into mesh-scale ripples (a smile crumpled the cheeks and the skin round the eyes). It is a
constant, linear bending of the displacement from the rest shape, carried in the implicit
integrator's matrix (so it is unconditionally stable), that costs next to nothing for the smooth
fields every muscle makes and as much as an edge's stretch for a ripple one edge long.

Over the forehead that bending is stiffer (`bound_layer`, `SkinParams.forehead_bending`). There
the skin is not a sheet of its own over soft fat: skin, the dense connective tissue under it and the
frontalis and galea aponeurotica are bound into one layer (the scalp's first three layers) that
slides over loose areolar tissue on the bone. A plate's bending rigidity grows as the cube of its
thickness (D = E t^3 / 12 (1 - nu^2), for the same material), so a layer t thick bends (t / 2 mm)^3
times as stiffly as the 2 mm of skin the rest of the face bends as. The soft tissue over the
mid-forehead is 4-5 mm deep (adult tissue-depth tables, e.g. De Greef et al. 2006, Forensic Sci.
Int. 159S, table 3): at 4 mm, 8 times, the frontalis' compression folds the forehead in broad,
shallow rolls instead of the thin sheet's uneven bumps and jagged arcs a few edges wide. The
sliding stays free: the term acts on the curvature of the displacement only, not on the layer's
motion over the bone. The layer starts half a centimetre above the brows: over the brows and just
above them the corrugators and procerus insert into the dermis and crease it (the frown lines of
AU4), which the thick plate would smooth away (and the emotion observer then reads anger as
neutral: docs/scan-face.md, "The forehead's bound layer"); there, and on the glabella, the nasal
root and the lids, the skin bends as elsewhere.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numba
import numpy as np

if TYPE_CHECKING:
    import scipy.sparse as sp

FLOOR = 0.3  # projected area / rest area below which the term acts
STRENGTH = 1.0  # stiffness per triangle, in its edge springs' mean high-strain stiffness


def turned_over_area(triangles: np.ndarray, rest: np.ndarray, x: np.ndarray) -> float:
    """cm2 of skin triangles at positions x whose normal points against their rest normal: the
    measure this term keeps near zero (the scans themselves fold at most ~0.25 cm2)."""
    t = np.asarray(triangles)
    n0 = np.cross(rest[t[:, 1]] - rest[t[:, 0]], rest[t[:, 2]] - rest[t[:, 0]])
    n1 = np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]])
    bad = np.einsum("ij,ij->i", n0, n1) < 0
    return float(0.5 * np.linalg.norm(n1[bad], axis=1).sum())


class FoldGuard:
    """Per-triangle rest data of the anti-fold term. tri (M,3) int32; frame (M,2,3) the rest plane's
    axes; dm_inv (M,2,2); area (M,) cm2; k (M,) dyn/cm."""

    def __init__(self, rest: np.ndarray, triangles: np.ndarray, springs: np.ndarray, k_high: np.ndarray,
                 floor: float = FLOOR, strength: float = STRENGTH) -> None:
        rest = np.asarray(rest, np.float64)
        tri = np.ascontiguousarray(triangles, dtype=np.int32)
        a, b, c = rest[tri[:, 0]], rest[tri[:, 1]], rest[tri[:, 2]]
        n = np.cross(b - a, c - a)
        area2 = np.linalg.norm(n, axis=1)
        ok = area2 > 1e-12
        tri, a, b, c, n, area2 = tri[ok], a[ok], b[ok], c[ok], n[ok], area2[ok]
        n /= area2[:, None]
        e1 = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
        e2 = np.cross(n, e1)
        dm = np.stack([np.stack([np.einsum("ij,ij->i", b - a, e1), np.einsum("ij,ij->i", c - a, e1)], 1),
                       np.stack([np.einsum("ij,ij->i", b - a, e2), np.einsum("ij,ij->i", c - a, e2)], 1)], 1)
        self.tri = tri
        self.frame = np.ascontiguousarray(np.stack([e1, e2], axis=1))
        self.dm_inv = np.ascontiguousarray(np.linalg.inv(dm))
        self.area = 0.5 * area2
        self.k = strength * _edge_stiffness(tri, springs, k_high)
        self.floor = float(floor)
        self._t3 = np.ascontiguousarray(3 * tri, dtype=np.uint32)  # (`_fold_forces`)
        self._dets = np.zeros(len(tri))

    def add_forces(self, y: np.ndarray, out: np.ndarray) -> int:
        """Adds the term's forces at positions y (N,3) to out (N,3); the number of triangles acting."""
        return int(_fold_forces(np.ascontiguousarray(y, dtype=np.float64), self._t3, self.tri, self.frame,
                                self.dm_inv, self.area, self.k, self.floor, out, self._dets))


def _edge_stiffness(tri: np.ndarray, springs: np.ndarray, k_high: np.ndarray) -> np.ndarray:
    """(M,) mean high-strain stiffness of each triangle's edge springs (the median of all where an
    edge has none)."""
    s = np.sort(np.asarray(springs, np.int64), axis=1)
    n = int(max(s.max(), tri.max())) + 1
    lookup = {int(i) * n + int(j): float(k) for (i, j), k in zip(s, np.asarray(k_high))}
    med = float(np.median(k_high))
    out = np.empty(len(tri))
    for t, (p, q, r) in enumerate(tri):
        ks = [lookup.get(min(u, v) * n + max(u, v), med) for u, v in ((p, q), (q, r), (r, p))]
        out[t] = sum(ks) / 3.0
    return out


def thin_skin(regions: dict[str, np.ndarray], n: int) -> np.ndarray:
    """(n,) bool: the vertices of the regions named as lids or lips (thin skin that creases)."""
    out = np.zeros(n, bool)
    for name, mask in regions.items():
        if "lid" in name or "lip" in name:
            out |= np.asarray(mask, bool)
    return out


@numba.njit(cache=True, nogil=True)
def _fold_at(y, tri, frame, dm_inv, area, k, floor, out, t):  # type: ignore[no-untyped-def]
    """Triangle t's term (the module docstring's equations): its forces added to out when det F <
    floor (or is not a number); returns 1 then, else 0."""
    i0 = tri[t, 0]
    i1 = tri[t, 1]
    i2 = tri[t, 2]
    # current edges projected on the rest plane: Ds (2x2), columns = edges
    d00 = d01 = d10 = d11 = 0.0
    for c in range(3):
        ea = y[i1, c] - y[i0, c]
        eb = y[i2, c] - y[i0, c]
        d00 += ea * frame[t, 0, c]
        d01 += eb * frame[t, 0, c]
        d10 += ea * frame[t, 1, c]
        d11 += eb * frame[t, 1, c]
    m = dm_inv[t]
    f00 = d00 * m[0, 0] + d01 * m[1, 0]
    f01 = d00 * m[0, 1] + d01 * m[1, 1]
    f10 = d10 * m[0, 0] + d11 * m[1, 0]
    f11 = d10 * m[0, 1] + d11 * m[1, 1]
    det = f00 * f11 - f01 * f10
    if det >= floor:
        return 0
    # signed singular values of F (2x2, closed form): F = R(a) diag(s1, s2) R(-b)
    e = 0.5 * (f00 + f11)
    f = 0.5 * (f00 - f11)
    g = 0.5 * (f10 + f01)
    h = 0.5 * (f10 - f01)
    q = math.sqrt(e * e + h * h)
    r = math.sqrt(f * f + g * g)
    s1 = q + r
    s2 = q - r  # det = s1 s2: negative when turned over
    a1 = math.atan2(g, f)
    a2 = math.atan2(h, e)
    th = 0.5 * (a2 - a1)
    ph = 0.5 * (a2 + a1)
    # the nearest deformation with det = floor: raise s2 (and s1 if it has collapsed too)
    s1n = max(s1, math.sqrt(floor))
    s2n = floor / s1n
    # F' = R(ph) diag(s1n, s2n) R(th); F' - F = R(ph) diag(s1n - s1, s2n - s2) R(th)
    cp, sp_ = math.cos(ph), math.sin(ph)
    ct, st = math.cos(th), math.sin(th)
    u1 = s1n - s1
    u2 = s2n - s2
    # R(ph) diag(u1, u2) R(th)
    g00 = cp * u1 * ct - sp_ * u2 * st
    g01 = -cp * u1 * st - sp_ * u2 * ct
    g10 = sp_ * u1 * ct + cp * u2 * st
    g11 = -sp_ * u1 * st + cp * u2 * ct
    # forces on vertices 1, 2 (2D): 2 k A (F' - F) Dm^-T; the force scale k A |Dm^-1|^2 ~ k
    w = 2.0 * k[t] * area[t]
    p1x = w * (g00 * m[0, 0] + g01 * m[0, 1])
    p1y = w * (g10 * m[0, 0] + g11 * m[0, 1])
    p2x = w * (g00 * m[1, 0] + g01 * m[1, 1])
    p2y = w * (g10 * m[1, 0] + g11 * m[1, 1])
    for c in range(3):
        v1 = p1x * frame[t, 0, c] + p1y * frame[t, 1, c]
        v2 = p2x * frame[t, 0, c] + p2y * frame[t, 1, c]
        out[i1, c] += v1
        out[i2, c] += v2
        out[i0, c] -= v1 + v2
    return 1


@numba.njit(cache=True, nogil=True)
def _fold_forces(y, t3, tri, frame, dm_inv, area, k, floor, out, dets):  # type: ignore[no-untyped-def]
    """The kernel of FoldGuard.add_forces (and of the implicit step's prediction) in two passes:
    every triangle's det F first (y read flat by t3 = 3 x tri as uint32: no negative-index
    wraparound, no branch), into dets (T,), then `_fold_at` for the triangles whose det is not
    >= floor, in triangle order (the few that act). The same bits as `_fold_at` over every
    triangle in one pass, as it was written before: 83 -> 71 us on the scanned head."""
    yf = y.reshape(-1)
    for t in range(t3.shape[0]):
        i0 = t3[t, 0]
        i1 = t3[t, 1]
        i2 = t3[t, 2]
        d00 = d01 = d10 = d11 = 0.0
        for c in range(3):
            ea = yf[i1 + c] - yf[i0 + c]
            eb = yf[i2 + c] - yf[i0 + c]
            d00 += ea * frame[t, 0, c]
            d01 += eb * frame[t, 0, c]
            d10 += ea * frame[t, 1, c]
            d11 += eb * frame[t, 1, c]
        f00 = d00 * dm_inv[t, 0, 0] + d01 * dm_inv[t, 1, 0]
        f01 = d00 * dm_inv[t, 0, 1] + d01 * dm_inv[t, 1, 1]
        f10 = d10 * dm_inv[t, 0, 0] + d11 * dm_inv[t, 1, 0]
        f11 = d10 * dm_inv[t, 0, 1] + d11 * dm_inv[t, 1, 1]
        dets[t] = f00 * f11 - f01 * f10
    acting = 0
    for t in range(t3.shape[0]):
        if not dets[t] >= floor:
            acting += _fold_at(y, tri, frame, dm_inv, area, k, floor, out, t)
    return acting


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel on one triangle."""
    rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    guard = FoldGuard(rest, np.array([[0, 1, 2]]), np.array([[0, 1], [1, 2], [0, 2]]), np.ones(3))
    y = rest.copy()
    y[2, 1] = -0.5
    guard.add_forces(y, np.zeros_like(y))


THIN_SMOOTHING = 0.2  # its share on thin skin (the lids, the lips: 0.5 mm against ~2 mm)
SKIN_LAYER = 0.2  # cm: the skin that bends on its own over the rest of the face
BOUND_LAYER = 0.4  # cm: the forehead's skin, connective tissue, frontalis and galea bound as one
FOREHEAD_BENDING = (BOUND_LAYER / SKIN_LAYER) ** 3  # the bound layer's bending in the skin's own (8)
BOUND_ABOVE_EYES = (3.0, 4.0)  # cm above the eyes' centres: none of it below, all of it above (the
# brows lie 1.7-2.5 cm above them, the corrugators' creases just above the brows' heads)
BOUND_LID_CLEAR = (0.6, 1.4)  # cm from the lid margins: none of it nearer, all of it beyond


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _nearest_distance(points: np.ndarray, to: np.ndarray) -> np.ndarray:
    """(n,) each point's distance to the nearest of `to` (a few dozen lid-margin vertices): by brute
    force, the squares summed x, y, z in order as a k-d tree sums them, so the same bits as its query,
    without importing scipy.spatial (0.28 s of a start before the first tick)."""
    best = np.full(len(points), np.inf)
    for q in to:
        d = points - q
        np.minimum(best, (d * d).sum(axis=1), out=best)
    return np.sqrt(best)


def bound_layer(rest: np.ndarray, eye_centers: np.ndarray, eye_loops: "list[np.ndarray]") -> np.ndarray:
    """(n,) 0..1: how much of each skin vertex lies on the forehead's bound layer (module
    docstring): none below `BOUND_ABOVE_EYES`[0] above the eyes' centres, all of it above [1] (the
    forehead from half a centimetre above the brows to the hairline and the temples), and none within
    `BOUND_LID_CLEAR`[0] of a lid margin, all of it beyond [1]; smooth in between."""
    rest = np.asarray(rest, np.float64)
    margins = np.concatenate([np.asarray(loop, np.int64) for loop in eye_loops])
    lid = _nearest_distance(rest, rest[margins])
    y = rest[:, 1] - float(np.asarray(eye_centers, np.float64)[:, 1].mean())
    c0, c1 = BOUND_LID_CLEAR
    y0, y1 = BOUND_ABOVE_EYES
    return _smoothstep((lid - c0) / (c1 - c0)) * _smoothstep((y - y0) / (y1 - y0))


def bending_weights(model: object) -> np.ndarray:
    """(n,) each skin vertex's share of `skin_bending`'s stiffness on a compiled face: a fifth on
    the lids and lips (thin skin), `SkinParams.forehead_bending` times over the forehead's bound
    layer (`bound_layer`; not on a face whose parameter is 1), 1 elsewhere."""
    mesh = model.mesh  # type: ignore[attr-defined]
    n = int(model.n_vertices)  # type: ignore[attr-defined]
    w = np.ones(n)
    w[thin_skin(mesh.regions, n)] *= THIN_SMOOTHING
    thick = float(model.params.forehead_bending)  # type: ignore[attr-defined]
    if thick != 1.0:
        w *= 1.0 + (thick - 1.0) * bound_layer(model.rest, mesh.eye_centers, mesh.eye_loops)  # type: ignore[attr-defined]
    return w


def bending_of(model: object) -> "sp.csr_matrix":
    """(n, n) the implicit step's bending in its matrix: the lid and lip rows'
    (`sim.margin_contact.margin_bending`) plus the skin's own (`skin_bending`, weighted by
    `bending_weights`), as `sim.implicit.prepare` and the strain fit's statics use it."""
    from sim.margin_contact import margin_bending

    p = model.params  # type: ignore[attr-defined]
    k_high = np.asarray(model.spring_k_high)  # type: ignore[attr-defined]
    bend = margin_bending(model.mesh, model.rest, np.asarray(model.spring_indices), k_high,  # type: ignore[attr-defined]
                          p.lid_bending, p.lip_bending)
    if p.skin_bending:
        bend = bend + skin_bending(int(model.n_vertices), model.triangles, k_high, p.skin_bending,  # type: ignore[attr-defined]
                                   weights=bending_weights(model))
    return bend


def skin_bending(n: int, triangles: np.ndarray, k_high: np.ndarray, strength: float,
                 thin: np.ndarray | None = None, thin_share: float = THIN_SMOOTHING,
                 weights: np.ndarray | None = None) -> "sp.csr_matrix":
    """(n, n) the skin's own bending for the implicit integrator's matrix: the energy k_b/2 sum_i |u_i -
    mean_j u_j|^2 of the displacements u from the (jaw-turned) rest shape, the mean over vertex i's
    neighbours along the triangles' edges (the umbrella operator; u - mean u is the discrete
    Laplacian of the displacement, ~ its curvature times the edge length squared), k_b = strength
    (SkinParams.skin_bending) times the median high-strain edge stiffness. A displacement smooth
    over a few edges (every muscle's pull, a translation) costs next to nothing; one alternating
    from vertex to vertex (the buckled ripples a fine spring net makes of compressed skin, which
    skin a few millimetres thick does not) costs as much as stretching an edge. At `thin` (n,) bool
    vertices (the lids and lips, whose thin skin creases) the term is `thin_share` as stiff;
    `weights` (n,), when given, is each vertex's share instead (`bending_weights`)."""
    import scipy.sparse as sp

    tri = np.asarray(triangles, np.int64)
    i = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2], tri[:, 1], tri[:, 2], tri[:, 0]])
    j = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0], tri[:, 0], tri[:, 1], tri[:, 2]])
    adj = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)).tocsr()
    adj.data[:] = 1.0
    deg = np.asarray(adj.sum(axis=1)).ravel()
    w = np.where(deg > 0, 1.0, 0.0)
    if weights is not None:
        w *= np.asarray(weights, np.float64)
    elif thin is not None:
        w[np.asarray(thin, bool)] *= thin_share
    lap = sp.eye(n, format="csr") - sp.diags(1.0 / np.maximum(deg, 1.0)) @ adj
    kb = float(strength) * float(np.median(k_high))
    return (kb * (lap.T @ sp.diags(w) @ lap)).tocsr()
