"""The scanned head: the ICT FaceKit's morphable head, as shipped in `ict_head.npz`.

A head registered from light-stage scans of real people by the USC Institute for Creative
Technologies' Vision and Graphics Lab (ICT-FaceKit, `FaceXModel/`, MIT licence: the text is in
`LICENSE-ICT-FaceKit` beside this file). Units cm, +Y up, the face looks along +Z, +X is the face's
own left. A posed head is `neutral + identities.T @ w_id + expressions.T @ w_expr` (linear).

`PARTS` gives each part's vertex range [start, end) in the scan's order, which every export keeps.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

DATA = Path(__file__).with_name("ict_head.npz")
N_VERTICES = 26719
N_IDENTITIES = 100

# Vertex ranges [start, end) of the scan's parts (from the toolkit's documentation).
PARTS: dict[str, tuple[int, int]] = {
    "face": (0, 9409),  # the full face area; the narrow face area is the first 6706
    "head_neck": (9409, 11248),
    "mouth_socket": (11248, 13294),
    "eye_socket_l": (13294, 13678),
    "eye_socket_r": (13678, 14062),
    "gums_tongue": (14062, 17039),
    "teeth": (17039, 21451),
    "eyeball_l": (21451, 23021),  # sclera (770) then iris (800)
    "eyeball_r": (23021, 24591),
    "lacrimal_l": (24591, 24795),
    "lacrimal_r": (24795, 24999),
    "eye_blend_l": (24999, 25023),
    "eye_blend_r": (25023, 25047),
    "eye_occlusion_l": (25047, 25199),
    "eye_occlusion_r": (25199, 25351),
    "eyelashes_l": (25351, 26035),
    "eyelashes_r": (26035, 26719),
}
NARROW_FACE = 6706
SCLERA = 770  # the first vertices of each eyeball; the rest are the iris
LASH_ROWS, LASH_COLUMNS = 6, 19  # each lash strip of the scan: rows from tip to root, columns along the lid


@dataclass(frozen=True)
class ScanData:
    """The shipped arrays, decoded. Read-only; shared by every face built from the scan."""

    neutral: np.ndarray  # (26719, 3) float64, cm
    faces: np.ndarray  # (F, 4) int64, quads and triangles (4th index -1)
    faces_uv: np.ndarray  # (F, 4) int64, indices into `uv`
    uv: np.ndarray  # (U, 2) float64
    expressions: np.ndarray  # (57, 26719, 3) float32, deltas (cm)
    expression_names: tuple[str, ...]
    identities: np.ndarray  # (100, 26719, 3) int8; times identity_scale -> cm
    identity_scale: np.ndarray  # (100,) float64

    def identity_delta(self, weights: np.ndarray) -> np.ndarray:
        """(26719, 3) float64: the identity modes weighted (`weights` (<=100,), ~N(0, 1) each)."""
        w = np.zeros(N_IDENTITIES)
        w[: len(weights)] = weights
        w = w * self.identity_scale
        out = np.zeros((N_VERTICES, 3))
        for k in np.flatnonzero(w):  # sequential, so the sum is the same bits on any BLAS kernel
            out += self.identities[k].astype(np.float64) * w[k]
        return out

    def expression(self, name: str) -> np.ndarray:
        """(26719, 3) float64: one scanned expression's delta (cm)."""
        return self.expressions[self.expression_names.index(name)].astype(np.float64)

    def triangles(self, part: str | None = None) -> np.ndarray:
        """(T, 3) int64: the part's faces (all faces when None) split into triangles."""
        f = self.faces
        if part is not None:
            lo, hi = PARTS[part]
            f = f[(f[:, 0] >= lo) & (f[:, 0] < hi)]
        tri = f[:, :3]
        quads = f[f[:, 3] >= 0]
        return np.concatenate([tri, quads[:, [0, 2, 3]]])

    def vertex_uv(self) -> np.ndarray:
        """(26719, 2): one texture coordinate per vertex (the first corner that names it)."""
        out = np.zeros((N_VERTICES, 2))
        v = self.faces.reshape(-1)
        t = self.faces_uv.reshape(-1)
        keep = v >= 0
        v, t = v[keep][::-1], t[keep][::-1]
        out[v] = self.uv[t]
        return out


@lru_cache(maxsize=1)
def scan_data() -> ScanData:
    """The shipped scan, loaded once (about 0.2 s)."""
    with np.load(DATA, allow_pickle=False) as d:
        return ScanData(
            neutral=d["neutral"].astype(np.float64),
            faces=d["faces"].astype(np.int64),
            faces_uv=d["faces_uv"].astype(np.int64),
            uv=d["uv"].astype(np.float64),
            expressions=d["expressions"].astype(np.float32),
            expression_names=tuple(str(n) for n in d["expression_names"]),
            identities=d["identities"],
            identity_scale=d["identity_scale"].astype(np.float64),
        )


def lash_row(uv: np.ndarray) -> np.ndarray:
    """(K,) the row (0 .. LASH_ROWS - 1, tip to root) of each lash vertex from its chart coordinates."""
    return np.rint((uv[:, 1] % 1.0 - 0.014) / 0.0278).astype(int) % LASH_ROWS


@lru_cache(maxsize=2)
def lash_strips(part: str) -> np.ndarray:
    """(S, LASH_ROWS, LASH_COLUMNS) int64 scan indices: the lash part's strips (`eyelashes_l` or
    `_r`: three layered strips per lid), each a grid of rows from tip to root by columns along the
    lid. Raises ValueError when a strip is not such a grid."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    d = scan_data()
    lo, hi = PARTS[part]
    n = hi - lo
    t = d.triangles(part) - lo
    uv = d.vertex_uv()[lo:hi]
    row = lash_row(uv)
    link = coo_matrix((np.ones(t.size), (np.repeat(t[:, 0], 3), t.ravel())), shape=(n, n))
    count, strip = connected_components(link + link.T, directed=False)
    grid = np.zeros((count, LASH_ROWS, LASH_COLUMNS), np.int64)
    for k in range(count):
        for r in range(LASH_ROWS):
            members = np.flatnonzero((strip == k) & (row == r))
            if len(members) != LASH_COLUMNS:
                raise ValueError(f"{part}: strip {k} row {r} has {len(members)} vertices, not {LASH_COLUMNS}")
            grid[k, r] = members[np.argsort(uv[members, 0] % 1.0)]
    grid += lo
    grid.flags.writeable = False
    return grid
