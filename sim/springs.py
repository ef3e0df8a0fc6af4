"""Skin springs: the biphasic spring of seed 000 (eqs 1-5) and the spring network built on a mesh.

Reading chosen for the strain (eqs 2-3): the paper's eps_j = r_j - r_j^r is a length difference, so
its threshold eps^c would depend on the mesh's edge lengths. We switch on the *relative* strain
(r_j - r_j^r) / r_j^r instead, which is scale-free: the same eps^c means "the skin is stretched by
15 %" on every resolution. The force stays eq 1's k (r - r^r) u with k in dyn/cm.

Reading chosen for eqs 1 and 3 together: taken literally, q = k(eps) eps jumps by (k_h - k_l) eps^c
at the threshold. That is not the continuous biphasic *curve* of the paper's Fig. 1, and a spring
resting at the threshold then chatters for ever (we measured the face never settling). We read k_ij
as the slope of that curve: |q| = k_l eps below eps^c and k_l eps^c + k_h (eps - eps^c) above, so
the force is continuous and the stiffness still switches exactly at eps^c.

Network: every mesh edge carries a spring, plus one *bending* spring across every interior edge,
between the two vertices opposite it in the adjacent triangles. Edge springs alone leave each edge a
free hinge, so a pulled surface folds and crumples at no cost; a cross spring changes length when its
hinge folds, giving the sheet a resistance to bending (and to in-plane shear) that holds its shape.
"""

from __future__ import annotations

import numpy as np

# ---------------------------------------------------------------- the equations (numpy, reference)


def spring_strain(length: np.ndarray, rest_length: np.ndarray) -> np.ndarray:
    """Seed 000 eq 2, read as relative strain: (r_j - r_j^r) / r_j^r (dimensionless)."""
    return (length - rest_length) / rest_length


def biphasic_stiffness(
    strain: np.ndarray, k_low: np.ndarray, k_high: np.ndarray, threshold: float
) -> np.ndarray:
    """Seed 000 eq 3: the spring's stiffness (slope of its force curve) is k_l while the relative
    strain is <= eps^c, k_h beyond (at exactly eps^c it is still soft)."""
    return np.where(strain <= threshold, k_low, k_high)


def spring_direction(xi: np.ndarray, xj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Seed 000 eq 4: u_ij = (x_j - x_i) / r_j, returned with r_j = |x_j - x_i|."""
    d = xj - xi
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    return d / r[:, None], r


def spring_tension(
    length: np.ndarray,
    rest_length: np.ndarray,
    k_low: np.ndarray,
    k_high: np.ndarray,
    threshold: float,
) -> np.ndarray:
    """Seed 000 eq 1's magnitude k_ij eps_j (dyn, > 0 when stretched), with eq 3's k_ij as the slope of
    the biphasic curve (see the module docstring): k_l (r - r^r) up to the threshold length
    r^r (1 + eps^c), then k_h beyond it."""
    stretch = length - rest_length
    knee = threshold * rest_length
    soft = k_low * stretch
    return np.where(stretch <= knee, soft, k_low * knee + k_high * (stretch - knee))


def spring_force(
    xi: np.ndarray,
    xj: np.ndarray,
    rest_length: np.ndarray,
    k_low: np.ndarray,
    k_high: np.ndarray,
    threshold: float,
) -> np.ndarray:
    """Seed 000 eq 1: q_ij = k_ij eps_j u_ij, the force of spring j on its end i (dyn, (E,3)); its end
    j feels -q_ij."""
    u, r = spring_direction(xi, xj)
    return spring_tension(r, rest_length, k_low, k_high, threshold)[:, None] * u


def elastic_forces(
    positions: np.ndarray,
    springs: np.ndarray,
    rest_length: np.ndarray,
    k_low: np.ndarray,
    k_high: np.ndarray,
    threshold: float,
) -> np.ndarray:
    """Seed 000 eq 5: Q_i = sum over the springs at node i of q_ij (dyn, (N,3)). Note eq 23 writes
    +Q_i on the left-hand side; with u_ij pointing from i to j, q_ij is the pull *on* i, so we add Q_i
    to the right-hand side (a stretched spring pulls its ends together)."""
    i, j = springs[:, 0], springs[:, 1]
    q = spring_force(positions[i], positions[j], rest_length, k_low, k_high, threshold)
    out = np.zeros_like(positions)
    np.add.at(out, i, q)
    np.add.at(out, j, -q)
    return out


# ---------------------------------------------------------------- the network on a mesh


def triangle_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area (cm^2) of each triangle, (M,)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def vertex_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Lumped area (cm^2) of each vertex: a third of each adjacent triangle, (N,)."""
    out = np.zeros(len(vertices))
    np.add.at(out, triangles.ravel(), np.repeat(triangle_areas(vertices, triangles) / 3.0, 3))
    return out


def mesh_edges(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique undirected edges (E,2) sorted (i < j), and for each edge its first and second adjacent
    triangle (second = -1 on the boundary)."""
    t = np.asarray(triangles, dtype=np.int64)
    m = len(t)
    half = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    tri_of = np.tile(np.arange(m), 3)
    key = np.sort(half, axis=1)
    order = np.lexsort((tri_of, key[:, 1], key[:, 0]))
    key, tri_of = key[order], tri_of[order]
    new = np.ones(len(key), dtype=bool)
    new[1:] = np.any(key[1:] != key[:-1], axis=1)
    starts = np.flatnonzero(new)
    edges = key[starts]
    first = tri_of[starts]
    second = np.full(len(edges), -1, dtype=np.int64)
    has_two = np.zeros(len(edges), dtype=bool)
    nxt = starts + 1
    ok = nxt < len(key)
    ok[ok] = ~new[nxt[ok]]
    has_two[ok] = True
    second[has_two] = tri_of[nxt[has_two]]
    return edges, first, second


def opposite_vertex(triangles: np.ndarray, tri: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """For each edge and one of its triangles, the triangle's vertex not on the edge."""
    t = triangles[tri]
    not_on = (t != edges[:, :1]) & (t != edges[:, 1:2])
    return t[np.arange(len(t)), np.argmax(not_on, axis=1)]


def build_springs(
    vertices: np.ndarray,
    triangles: np.ndarray,
    sheet_modulus: float,
    bend_ratio: float,
    max_ratio: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The skin's springs: (indices (S,2) int32, rest lengths (S,), low-strain stiffness (S,) dyn/cm,
    number of edge springs E; springs E.. are bending springs).

    Edge stiffness k_e = Y * (area of the triangles at e) / r_e^2 makes the network a membrane of 2D
    Young's modulus Y (dyn/cm) whatever the resolution: on equilateral triangles this is the lattice
    value k = (sqrt(3)/2) Y. A bending spring gets bend_ratio times the stiffness of its edge.
    max_ratio > 0 caps k_e at max_ratio times the median edge stiffness: the short edge of a sliver
    triangle (large area over a tiny length squared) would otherwise be many times stiffer than the
    skin around it and alone set the explicit time step, for no visible benefit.
    """
    tris = np.asarray(triangles, dtype=np.int64)
    edges, first, second = mesh_edges(tris)
    area = triangle_areas(vertices, tris)
    adj_area = area[first] + np.where(second >= 0, area[np.maximum(second, 0)], 0.0)
    rest_e = np.linalg.norm(vertices[edges[:, 1]] - vertices[edges[:, 0]], axis=1)
    k_e = sheet_modulus * adj_area / rest_e**2
    if max_ratio > 0:  # short edges of sliver triangles: see the docstring
        k_e = np.minimum(k_e, max_ratio * float(np.median(k_e)))
    interior = second >= 0
    a = opposite_vertex(tris, first[interior], edges[interior])
    b = opposite_vertex(tris, second[interior], edges[interior])
    bend = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    rest_b = np.linalg.norm(vertices[bend[:, 1]] - vertices[bend[:, 0]], axis=1)
    k_b = bend_ratio * k_e[interior] * (rest_e[interior] / rest_b) ** 2
    indices = np.concatenate([edges, bend]).astype(np.int32)
    return indices, np.concatenate([rest_e, rest_b]), np.concatenate([k_e, k_b]), len(edges)


def boundary_loops(triangles: np.ndarray) -> list[np.ndarray]:
    """Closed loops of boundary edges (edges used by one triangle), each in walking order.
    Vertices where several loops meet are walked greedily, which is enough to find openings."""
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    key = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = directed[counts[inverse.ravel()] == 1]
    nxt: dict[int, list[int]] = {}
    for a, b in boundary:
        nxt.setdefault(int(a), []).append(int(b))
    loops: list[np.ndarray] = []
    while nxt:
        start = next(iter(nxt))
        loop = [start]
        cur = start
        while True:
            outs = nxt.get(cur)
            if not outs:
                break
            b = outs.pop()
            if not outs:
                del nxt[cur]
            if b == start:
                break
            loop.append(b)
            cur = b
        if len(loop) >= 3:
            loops.append(np.asarray(loop, dtype=np.int64))
    return loops
