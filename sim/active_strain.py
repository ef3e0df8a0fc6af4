"""Active strain: a contracting muscle changes the rest state of the tissue it runs through.

A muscle lies inside the soft tissue; as it contracts, that tissue shortens along its fibres and
bulges across them (the active strain or active contraction of FEM faces driven by muscle
activations: Sifakis, Neverov & Fedkiw 2005, "Automatic determination of facial muscle activations
from sparse motion capture marker data", the muscle's fibre contraction as a change of the
tissue's rest shape; Ichim et al. 2017, "Phace", the active rest shape A(a) of each element). In
the skin's spring net it is a change of rest length of the springs inside the channel's zone:

    L_e(v) = L0_e (1 + v s_e),   s_e = d_e^T (E(i) + E(j)) / 2 d_e,

d_e the spring's rest direction, E (N, 6) a symmetric strain per skin vertex (xx, yy, zz, xy, xz,
yz; `FaceRig.strain`), a spring taking the mean of its two ends' and none where either end carries
none. The forces are internal: each spring pushes its two ends apart (s > 0) or together.

Reading chosen: the change enters as its force at the rest shape, k_low L0 v s_e along the rest
direction, added to the channel's force field (`sim.build._muscle_matrix`), so the step, its
matrix and the muscles' responses are those of a pull. That is the rest-length change to first
order about the rest shape (a spring at L0 with rest length L0 (1 + v s) pulls with k_low L0 v s);
it does not turn with the skin and does not move the springs' knee (`SkinParams.strain_threshold`).
"""

from __future__ import annotations

import numpy as np

COMPONENTS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))  # the columns of a strain array


def fibre_terms(rest: np.ndarray, springs: np.ndarray) -> np.ndarray:
    """(S, 6) per spring the products d_p d_q of its rest direction d over COMPONENTS (doubled off
    the diagonal), so that s_e = a_e . (E(i) + E(j)) / 2."""
    i, j = springs[:, 0], springs[:, 1]
    d = rest[i] - rest[j]
    d = d / np.linalg.norm(d, axis=1)[:, None]
    return np.stack([d[:, p] * d[:, q] * (1.0 if p == q else 2.0) for p, q in COMPONENTS], axis=1)


def spring_strain(rest: np.ndarray, springs: np.ndarray, strain: np.ndarray) -> np.ndarray:
    """(S,) each spring's strain s_e at full value from the per-vertex strain (N, 6); 0 where either
    end carries none."""
    springs = np.asarray(springs, np.int64)
    i, j = springs[:, 0], springs[:, 1]
    a = fibre_terms(rest, springs)
    carries = np.any(strain != 0.0, axis=1)
    s = 0.5 * np.sum(a * (strain[i] + strain[j]), axis=1)
    return np.where(carries[i] & carries[j], s, 0.0)


def strain_force(rest: np.ndarray, springs: np.ndarray, rest_length: np.ndarray, k_low: np.ndarray,
                 strain: np.ndarray) -> np.ndarray:
    """(N, 3) the nodal force of the strain at full value, at the rest shape: k_low L0 s_e along
    the spring's rest direction on its first end, the opposite on its second (dyn)."""
    springs = np.asarray(springs, np.int64)
    s = spring_strain(rest, springs, strain)
    on = np.flatnonzero(s)
    i, j = springs[on, 0], springs[on, 1]
    d = rest[i] - rest[j]
    d = d / np.linalg.norm(d, axis=1)[:, None]
    f = (np.asarray(k_low)[on] * np.asarray(rest_length)[on] * s[on])[:, None] * d
    out = np.zeros_like(rest, dtype=np.float64)
    np.add.at(out, i, f)
    np.add.at(out, j, -f)
    return out
