"""A layered face in linear statics: the skin over a deep layer (SMAS and fat) over bone.

The shipped skin is one mass-spring sheet tied to its rest place by a tether and a support along the
normal. Here the soft tissue has three layers of nodes, one node per skin vertex in each, stacked
along the skin's rest normal:

- the skin (the shipped sheet's vertices and springs);
- a deep layer `thickness` below it (the superficial musculo-aponeurotic system and the fat
  between it and the skin), with springs on the same edges, `deep_modulus` times the skin's;
- bone, `thickness` below the deep layer (held: it does not move).

Neighbouring layers are tied by central springs, so every force is internal: each node to the node
below it (the tissue's resistance to indentation) and to the nodes below its neighbours (its
resistance to shear, which is how far the skin slides over the deep layer or the deep layer over
bone: lax over fat pads, stiff at the retaining ligaments). The springs are sized so that at
multipliers 1 the two ties in series give the shipped sheet's tether across the normal and its
support along it (or more, where the slanted ties alone are stiffer along the normal);
`skin_shear` and `bone_shear` (per vertex) scale the ties across the normal from there.

A spring between rest points p and q with stiffness k adds k (e_p - e_q)(e_p - e_q)^T (x) d d^T
(d the unit direction p -> q) to the stiffness: a translation or an infinitesimal rotation of all
the nodes, bone included, stretches no spring, so the tissue is strain-free under a rigid motion
of the bone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SKIN, DEEP, BONE = 0, 1, 2


@dataclass(frozen=True)
class Layers:
    """The assembled model: rest positions of the 3N nodes (skin, deep, bone, each in skin-vertex
    order), its springs (S,2) and their stiffnesses (S,) dyn/cm, and which nodes are held."""

    rest: np.ndarray
    springs: np.ndarray
    k: np.ndarray
    held: np.ndarray

    @property
    def n(self) -> int:
        return len(self.rest) // 3

    def stiffness(self):  # type: ignore[no-untyped-def]
        """(9N, 9N) sparse stiffness of every node (bone included), symmetric, xyz interleaved."""
        from sim.build import stiffness_matrix

        return stiffness_matrix(self.rest, self.springs, self.k, np.zeros(len(self.rest)))

    def free_dofs(self) -> np.ndarray:
        return np.flatnonzero(np.repeat(~self.held, 3))


def _edges(triangles: np.ndarray, n: int) -> np.ndarray:
    """The mesh's edges (E,2) among the first n vertices, each once (i < j)."""
    tri = np.asarray(triangles, np.int64)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    e = e[(e < n).all(axis=1)]
    return np.unique(np.sort(e, axis=1), axis=0)


def layered(rest: np.ndarray, normal: np.ndarray, triangles: np.ndarray, springs: np.ndarray,
            k_skin: np.ndarray, support: np.ndarray, tether: np.ndarray, held: np.ndarray,
            thickness: np.ndarray, deep_modulus: float | np.ndarray = 1.0,
            skin_shear: float | np.ndarray = 1.0, bone_shear: float | np.ndarray = 1.0) -> Layers:
    """The layered tissue under a skin sheet (rest (N,3), unit rest normals (N,3), its triangles,
    springs (S,2) with stiffness k_skin (S,), support along the normal and tether per vertex (N,),
    held (N,)). thickness (N,) cm: each of the two layers below. deep_modulus: the deep layer's
    springs per skin spring (scalar or per spring); skin_shear, bone_shear: multipliers (scalar or
    per vertex) of the skin-deep and deep-bone ties across the normal. Held skin vertices hold the
    nodes below them too."""
    rest = np.asarray(rest, float)
    n = len(rest)
    normal = np.asarray(normal, float)
    t = np.broadcast_to(np.asarray(thickness, float), (n,))
    if np.any(t <= 0):
        raise ValueError("the layers need a positive thickness")
    nodes = np.concatenate([rest, rest - t[:, None] * normal, rest - 2.0 * t[:, None] * normal])
    springs = np.asarray(springs, np.int64)
    deep_k = np.broadcast_to(np.asarray(deep_modulus, float), (len(springs),)) * np.asarray(k_skin, float)
    edges = _edges(triangles, n)
    parts_s, parts_k = [springs, springs + n], [np.asarray(k_skin, float), deep_k]
    for upper, shear in ((SKIN, skin_shear), (DEEP, bone_shear)):
        lo = upper + 1
        mult = np.broadcast_to(np.asarray(shear, float), (n,))
        # diagonal ties to the neighbours' nodes below: across the normal they sum to twice the
        # tether (times the multiplier), spread over the vertex's diagonals by their slant (for a
        # vertex whose neighbours surround it evenly, the sum is isotropic in the tangent plane)
        a = np.concatenate([edges[:, 0], edges[:, 1]])
        b = np.concatenate([edges[:, 1], edges[:, 0]])
        d = nodes[lo * n + b] - nodes[upper * n + a]
        d /= np.linalg.norm(d, axis=1)[:, None]
        cos2 = np.einsum("ij,ij->i", d, normal[a]) ** 2
        across = np.bincount(a, weights=1.0 - cos2, minlength=n)  # sum of sin^2 over the diagonals
        k = 2.0 * mult[a] * np.asarray(tether, float)[a] * 2.0 / np.maximum(across[a], 1e-9)
        parts_s.append(np.stack([upper * n + a, lo * n + b], axis=1))
        parts_k.append(k)
        # vertical ties: along the normal each tie (diagonals included) is twice the support, so
        # two in series give it (where the diagonals alone are stiffer, they set it)
        along = np.bincount(a, weights=k * cos2, minlength=n)
        parts_s.append(np.stack([upper * n + np.arange(n), lo * n + np.arange(n)], axis=1))
        parts_k.append(np.maximum(2.0 * np.asarray(support, float) - along, 0.0))
    held3 = np.concatenate([np.asarray(held, bool), np.asarray(held, bool), np.ones(n, bool)])
    return Layers(nodes, np.concatenate(parts_s), np.concatenate(parts_k), held3)
