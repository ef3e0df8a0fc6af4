"""What the renderer knows of the scanned head (sim.face.scan): which of its parts are drawn with
which material, per-vertex albedos and material weights, and the per-frame rows of the posed scan.

The ICT FaceKit ships no textures, so the look is made here from the scan's own layout. The face's
texture chart is a frontal projection shared by every identity (the scan is registered: a vertex
means the same spot on every head), so the brows and the lips' red (vermilion) are shapes drawn in
that chart, placed from the eye openings and the mouth found in it, and they stay on the right skin
whatever the identity or the expression. Per vertex the renderer gets a signed distance (cm) to
each shape's edge and takes the edge per pixel, so both stay sharp. Shadows in folds come from two
terms: a broad one baked from the rest shape (how far each point lies below a smoothed copy of the
surface: eye sockets, nostrils, ears, the corners of the mouth) and a fine one recomputed every
frame from the posed surface (render.scan_kernel: a nasolabial fold or frown lines that deepen
darken). The mouth's inside is darker the deeper it lies behind the front teeth."""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from render.meshdata import spatial_order
from sim.face.scan.data import LASH_COLUMNS, LASH_ROWS, N_VERTICES, PARTS, SCLERA, lash_row, lash_strips, scan_data

# Linear albedos.
SKIN = np.array([0.60, 0.40, 0.30])
CHEEK = np.array([0.62, 0.34, 0.27])  # the warmer, redder skin of cheeks, nose and ears
LIP = np.array([0.46, 0.17, 0.15])
BROW = np.array([0.035, 0.024, 0.018])
LASH = np.array([0.02, 0.015, 0.012])
TEETH = np.array([0.62, 0.58, 0.48])
GUMS = np.array([0.36, 0.10, 0.09])
TONGUE = np.array([0.32, 0.09, 0.08])
SOCKET = np.array([0.16, 0.04, 0.04])  # the mouth's lining, in shadow
EYE_SOCKET = np.array([0.42, 0.18, 0.16])
MOUTH_CORNER_X = 2.45  # cm: the generic head's mouth corners, either side of the midline
IRIS_ANGLE = 0.50  # rad from the gaze axis: the limbus, where the cornea's bulge starts on the scan
PUPIL_ANGLE = 0.19

# cm of signed distance beyond which the skin shader's brow / vermilion terms are exactly nothing:
# the brow's edge smoothstep(-0.12, 0.06, d + 0.07 s) with its hair pattern s in -1..1, the lip's
# smoothstep(-0.05, 0.05, d); a triangle whose corners all lie beyond is drawn without them
BROW_CLEAR = 0.06 + 0.07
LIP_CLEAR = 0.05
LIP_GAP = 0.05  # cm the lips must part by before the mouth's inside is drawn (a pixel is ~0.035 cm at 720p)
TEETH_DEPTH = 2.5  # cm behind the front teeth: the deepest teeth drawn
GUMS_DEPTH = 4.0
SKIN_PARTS = ("face", "head_neck")
LASH_PARTS = ("eyelashes_l", "eyelashes_r")
SOCKET_PARTS = ("eye_socket_l", "eye_socket_r")
EYE_BALL_MARGIN_CM = 0.1  # the eyeballs' hiding balls lie this far inside their outer shells


def part_faces(part: str) -> np.ndarray:
    """(F, 4) the scan's faces of one part (quads and triangles; by their first vertex)."""
    d = scan_data()
    lo, hi = PARTS[part]
    f = d.faces
    return np.flatnonzero((f[:, 0] >= lo) & (f[:, 0] < hi))


def face_chart_uv() -> np.ndarray:
    """(26719, 2) each vertex's coordinate in the face's texture chart (the unit square; vertices
    outside the face's skin keep 0): the corners whose coordinates lie in that chart, of every
    face before the eyeballs (which reuse the unit square for their own chart)."""
    d = scan_data()
    out = np.zeros((N_VERTICES, 2))
    f, fu = d.faces, d.faces_uv
    for k in range(4):
        ok = f[:, k] >= 0
        vi, ti = f[ok, k], fu[ok, k]
        c = d.uv[ti]
        keep = (vi < PARTS["eyeball_l"][0]) & (c[:, 0] < 1.0) & (c[:, 1] <= 1.0)
        out[vi[keep]] = c[keep]
    return out


def _triangles(part: str) -> np.ndarray:
    return scan_data().triangles(part).astype(np.int32)


def _eyeball_shell(side: str) -> np.ndarray:
    """The eyeball's outer shell (sclera with the cornea's bulge; the inner layer is never seen)."""
    lo, _ = PARTS[f"eyeball_{side}"]
    t = _triangles(f"eyeball_{side}")
    return t[(t < lo + SCLERA).all(axis=1)]


def _smooth(values: np.ndarray, edges: np.ndarray, rounds: int) -> np.ndarray:
    """(N, 3) each round every vertex takes the mean of itself and its mesh neighbours."""
    n = len(values)
    a, b = edges[:, 0], edges[:, 1]
    deg = 1.0 + np.bincount(a, minlength=n) + np.bincount(b, minlength=n)
    v = values.astype(float)
    for _ in range(rounds):
        v = np.stack([(v[:, k] + np.bincount(a, v[b, k], n) + np.bincount(b, v[a, k], n)) / deg
                      for k in range(v.shape[1])], axis=1)
    return v


def _edges(triangles: np.ndarray) -> np.ndarray:
    """(E, 2) int64 undirected edges, each once (by a 1-D key: far faster than unique rows)."""
    t = np.asarray(triangles, np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e.sort(axis=1)
    key = np.unique(e[:, 0] * (int(t.max()) + 1) + e[:, 1])
    return np.stack([key // (int(t.max()) + 1), key % (int(t.max()) + 1)], axis=1)


def _polyline_sdf(points: np.ndarray, line: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Signed distance of 2-D points to a stroke along `line` (K, 2) with half widths `half` (K,)
    (negative inside), with round ends."""
    best = np.full(len(points), np.inf)
    for k in range(len(line) - 1):
        a, ab = line[k], line[k + 1] - line[k]
        t = np.clip((points - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        d = np.linalg.norm(points - a - t[:, None] * ab, axis=1) - (half[k] + t * (half[k + 1] - half[k]))
        best = np.minimum(best, d)
    return best


def _bezier(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, n: int = 24) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return (1 - t) ** 2 * p0 + 2 * (1 - t) * t * p1 + t**2 * p2


def eye_centres(neutral: np.ndarray) -> np.ndarray:
    """(2, 3) the eyeballs' centres (left +X first): sphere fits to their outer shells."""
    out = []
    for side in ("l", "r"):
        lo, _ = PARTS[f"eyeball_{side}"]
        p = neutral[lo:lo + SCLERA]
        x = np.linalg.lstsq(np.c_[2.0 * p, np.ones(len(p))], (p**2).sum(axis=1), rcond=None)[0]
        out.append(x[:3])
    return np.array(out)


def brow_sdf(xy: np.ndarray, eyes: np.ndarray) -> np.ndarray:
    """(N,) cm: signed distance, in the front view of the generic head, to the nearer brow
    (negative inside), placed from the eyeball's centre: a stroke that starts above the inner
    corner of the eye, arches highest a little outside the pupil's line and ends past the outer
    corner, thick at the head and thin at the tail."""
    out = np.full(len(xy), np.inf)
    for c in eyes:
        out_dir = np.sign(c[0]) or 1.0

        def at(a: float, b: float) -> np.ndarray:
            return np.array([c[0] + out_dir * a, c[1] + b])

        line = np.concatenate([_bezier(at(-1.55, 1.55), at(-0.6, 2.05), at(0.45, 2.05), 12),
                               _bezier(at(0.45, 2.05), at(1.5, 2.05), at(2.35, 1.25), 12)[1:]])
        s = np.linspace(0.0, 1.0, len(line))
        half = 0.36 - 0.26 * s**1.4
        out = np.minimum(out, _polyline_sdf(xy, line, half))
    return out


def lip_sdf(xy: np.ndarray, corner_x: float, stomion_y: float) -> np.ndarray:
    """(N,) cm: signed distance (vertical, front view of the generic head) to the vermilion border,
    negative on the red of the lips: the upper border with its Cupid's bow, the fuller lower lip,
    both closing at the mouth corners (x = +-corner_x, at the stomion's height)."""
    t = xy[:, 0] / corner_x
    inside = np.clip(1.0 - t**2, 0.0, None)
    bow = 0.16 * np.exp(-(t / 0.10) ** 2)          # the dip at the philtrum
    peaks = 0.10 * np.exp(-((np.abs(t) - 0.24) / 0.12) ** 2)
    top = stomion_y + 0.72 * inside**0.6 - bow + peaks
    bottom = stomion_y - 0.95 * inside**0.55
    d = np.maximum(xy[:, 1] - top, bottom - xy[:, 1])
    return np.where(np.abs(t) < 1.0, d, np.maximum(d, (np.abs(t) - 1.0) * corner_x))


def _mouth_inside(neutral: np.ndarray) -> np.ndarray:
    """The mouth's inside as drawn: its whole lining (the backdrop that closes the opening), and of
    the teeth, gums and tongue what lies within TEETH_DEPTH / GUMS_DEPTH cm behind the front teeth
    (deeper, the occlusion has them black against the lining: the molars alone are 5,000 triangles)."""
    lo, hi = PARTS["teeth"]
    z_front = neutral[lo:hi, 2].max()
    out = [_triangles("mouth_socket")]
    for part, depth in (("gums_tongue", GUMS_DEPTH), ("teeth", TEETH_DEPTH)):
        t = _triangles(part)
        out.append(t[z_front - neutral[t].mean(axis=1)[:, 2] < depth])
    return np.concatenate(out)


def _mouth_loop() -> np.ndarray:
    """The face's boundary around the mouth (where the lips roll into the mouth's lining)."""
    from sim.springs import boundary_loops

    loops = [np.asarray(lp) for lp in boundary_loops(_triangles("face"))]
    neutral = scan_data().neutral
    return min(loops, key=lambda lp: float(np.linalg.norm(neutral[lp].mean(axis=0)[:2] - (0.0, -3.4))))


@lru_cache(maxsize=1)
def _static_layout() -> dict[str, np.ndarray]:
    """Everything that depends only on the scan's topology and charts (shared by every identity)."""
    d = scan_data()
    uv = face_chart_uv()
    neutral = d.neutral
    n = N_VERTICES
    face = np.zeros(n, bool)
    lo, hi = PARTS["face"]
    face[lo:hi] = True
    xy = neutral[:, :2]
    stomion_y = float(np.mean(neutral[_mouth_loop(), 1]))
    brow = np.full(n, 9.0)
    near = face & (neutral[:, 1] > eye_centres(neutral)[:, 1].min())  # the brows lie above the eyes
    brow[near] = brow_sdf(xy[near], eye_centres(neutral))
    lip = np.where(face & (neutral[:, 2] > 8.0), lip_sdf(xy, MOUTH_CORNER_X, stomion_y), 9.0)
    # redder cheeks, nose and ears: smooth blobs in the face chart, plus the head chart's ears
    cheek = np.zeros(n)
    for cu, cv, r in ((0.30, 0.52, 0.10), (0.70, 0.52, 0.10), (0.5, 0.55, 0.05)):
        cheek += np.exp(-((uv[:, 0] - cu) ** 2 + (uv[:, 1] - cv) ** 2) / r**2) * face
    groups = {
        "skin": np.concatenate([_triangles(p) for p in SKIN_PARTS]),
        "mouth": _mouth_inside(neutral),
        "eyes": np.concatenate([_eyeball_shell("l"), _eyeball_shell("r")]),
        "sockets": np.concatenate([_triangles(p) for p in SOCKET_PARTS]),
        "lashes": np.concatenate([_triangles(p) for p in LASH_PARTS]),
    }
    return {"uv": uv, "brow": brow, "lip": lip, "cheek": np.clip(cheek, 0, 1), **groups,
            "stomion_y": np.array(stomion_y)}


COARSE_LASH_ROWS = (0, 1, 3, 5)  # the rows the coarse strips keep (the curl is sharpest near the tip)
COARSE_LASH_STEP = 2  # and every second column, the last kept


@lru_cache(maxsize=1)
def coarse_lashes() -> np.ndarray:
    """(K, 3) int32 the lashes as fewer triangles over the same vertices: each strip's grid of
    LASH_ROWS x LASH_COLUMNS vertices (`sim.face.scan.data.lash_strips`) kept at rows
    COARSE_LASH_ROWS and every COARSE_LASH_STEP-th column, each quad split along the diagonal most
    of the scan's own quads it spans are split along (2160 -> 648 triangles). Empty when a strip is
    not such a grid."""
    full = _static_layout()["lashes"]
    cols = list(range(0, LASH_COLUMNS, COARSE_LASH_STEP))
    if cols[-1] != LASH_COLUMNS - 1:
        cols.append(LASH_COLUMNS - 1)
    rows = list(COARSE_LASH_ROWS)
    out = []
    for part in LASH_PARTS:
        lo, hi = PARTS[part]
        try:
            grid = lash_strips(part) - lo
        except ValueError:
            return np.zeros((0, 3), np.int32)
        t = full[(full[:, 0] >= lo) & (full[:, 0] < hi)] - lo
        n, count = hi - lo, len(grid)
        place = np.zeros((n, 2), np.int64)  # each vertex's (row, column)
        strip = np.zeros(n, np.int64)
        for k in range(count):
            place[grid[k].ravel()] = np.stack(np.meshgrid(np.arange(LASH_ROWS), np.arange(LASH_COLUMNS),
                                                          indexing="ij"), axis=-1).reshape(-1, 2)
            strip[grid[k].ravel()] = k
        # the scan's split of each of its quads: +1 along the (row, column) diagonal, -1 across it
        split = np.zeros((count, LASH_ROWS - 1, LASH_COLUMNS - 1), np.int64)
        for tri in t:
            rc = place[tri]
            for i, j in ((0, 1), (1, 2), (0, 2)):
                dr, dc = rc[i] - rc[j]
                if dr and dc:
                    split[strip[tri[0]], min(rc[i, 0], rc[j, 0]), min(rc[i, 1], rc[j, 1])] = 1 if dr * dc > 0 else -1
        for k in range(count):
            g = grid[k][np.ix_(rows, cols)] + lo
            for r in range(len(rows) - 1):
                for c in range(len(cols) - 1):
                    a, b, d, e = g[r, c], g[r, c + 1], g[r + 1, c + 1], g[r + 1, c]
                    along = split[k, rows[r]:rows[r + 1], cols[c]:cols[c + 1]].sum() >= 0
                    out += [(a, b, d), (a, d, e)] if along else [(a, b, e), (b, d, e)]
    return np.array(out, np.int32).reshape(-1, 3)


def _extra_coords(face_uv: np.ndarray) -> np.ndarray:
    """The per-vertex coordinates the shaders read besides the face chart: the eyeballs' own chart
    (the iris at its centre: the angle around it gives the iris its fibres) and, on the lashes,
    (position along the lid, 0 at the root .. 1 at the tip). Each lash strip of the scan is six
    rows of its chart from tip to root."""
    d = scan_data()
    out = face_uv.copy()
    every = d.vertex_uv()
    for side in ("l", "r"):
        lo, hi = PARTS[f"eyeball_{side}"]
        out[lo:hi] = every[lo:hi]
        lo, hi = PARTS[f"eyelashes_{side}"]
        uv = every[lo:hi]
        row = lash_row(uv)
        block = np.floor(uv[:, 1] % 1.0 * 2.0)  # the lower lid's strips are the chart's lower half
        out[lo:hi, 0] = uv[:, 0] % 1.0 + 2.0 * (block == 0)
        out[lo:hi, 1] = 1.0 - row / 5.0
    return out


def _lip_pairs(rest: np.ndarray, neutral: np.ndarray, stomion_y: float) -> np.ndarray:
    """(K, 2) vertex pairs, upper lip and lower lip, closest to each other at rest in each column of
    the mouth (columns and lips told apart on the generic head): when any pair parts, the mouth's
    inside can be seen."""
    lo, hi = PARTS["face"]
    idx = np.arange(lo, hi)
    x, y = neutral[idx, 0], neutral[idx, 1]
    near = (np.abs(x) < 0.92 * MOUTH_CORNER_X) & (np.abs(y - stomion_y) < 0.6) & (neutral[idx, 2] > 8.0)
    idx, x, y = idx[near], x[near], y[near]
    edges = np.linspace(-0.92 * MOUTH_CORNER_X, 0.92 * MOUTH_CORNER_X, 17)
    pairs = []
    for a, b in zip(edges[:-1], edges[1:]):
        col = (x >= a) & (x < b)
        up, dn = idx[col & (y > stomion_y)], idx[col & (y <= stomion_y)]
        if len(up) == 0 or len(dn) == 0:
            continue
        dist = np.linalg.norm(rest[up][:, None] - rest[dn][None], axis=2)
        i, j = np.unravel_index(np.argmin(dist), dist.shape)
        pairs.append((up[i], dn[j]))
    return np.array(pairs, np.int64).reshape(-1, 2)


class ScanLook:
    """The drawing data of the scanned head for one rest pose (its identity): index arrays per
    material group (skin: face, head and neck; mouth: its lining, gums, tongue and teeth; eyes:
    the eyeballs' outer shells; sockets; lashes), per-vertex albedo (N, 3), material (N, 4: brow
    and vermilion signed distances in cm, baked occlusion 0..1, specular strength), the face
    chart's coordinates (N, 2, for the brows' hair), the eyeballs' angle from their gaze axis (N,),
    and the lip pairs that tell when the mouth is open. `lids`, carried from the simulated mesh
    (`ScanDressing.eye_margins`; None when drawn without one): per eye its (upper, lower) lid
    margin, scan indices from the inner corner to the outer (render.scan_seam reads them)."""

    def __init__(self, rest: np.ndarray, lids: Sequence[tuple[np.ndarray, np.ndarray]] | None = None) -> None:
        lay = _static_layout()
        rest = np.asarray(rest, np.float64)
        if rest.shape != (N_VERTICES, 3):
            raise ValueError(f"a scanned head has {N_VERTICES} vertices, got {rest.shape}")
        self.rest = rest
        self.lids = None if lids is None else [(np.asarray(u, np.int64), np.asarray(lo, np.int64)) for u, lo in lids]
        self.groups = {k: spatial_order(lay[k], rest).astype(np.int32)
                       for k in ("skin", "mouth", "eyes", "sockets", "lashes")}
        tri = np.concatenate(list(self.groups.values()))
        self.triangles = tri
        edges = _edges(tri)
        self.edges = edges
        n = N_VERTICES
        nbr = np.concatenate([edges, edges[:, ::-1]])
        nbr = nbr[np.lexsort((nbr[:, 1], nbr[:, 0]))]
        self.nbr_ptr = np.searchsorted(nbr[:, 0], np.arange(n + 1)).astype(np.int32)
        self.nbr = nbr[:, 1].astype(np.int32)
        length = np.linalg.norm(rest[edges[:, 0]] - rest[edges[:, 1]], axis=1)
        total = np.bincount(edges[:, 0], length, n) + np.bincount(edges[:, 1], length, n)
        deg = np.maximum(np.bincount(edges[:, 0], minlength=n) + np.bincount(edges[:, 1], minlength=n), 1)
        self.inv_len = (deg / np.maximum(total, 1e-6)).astype(np.float32)
        self.uv = _extra_coords(lay["uv"]).astype(np.float32)
        self.albedo, self.material = self._materials(lay, rest, edges)
        self.gaze_angle = self._gaze_angles(rest)
        self.lip_pairs = _lip_pairs(rest, scan_data().neutral, float(lay["stomion_y"]))
        self.lip_rest = np.linalg.norm(rest[self.lip_pairs[:, 0]] - rest[self.lip_pairs[:, 1]], axis=1)
        self.mouth_opening = -1  # which of `openings` is the mouth's (-1: none known)
        self.openings, self.behind = self._openings(rest)

    def _openings(self, rest: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        """The skin's openings (its boundary loops: the mouth, the eyes, the neck's cut), each
        ordered so that its area vector points out of the head, and per triangle of `triangles` a
        bit per opening it can be seen through (0: not inside the head): the mouth's inside through
        the mouth or the neck, an eyeball or eye socket through its own eye or the neck."""
        from sim.springs import boundary_loops

        skin = self.groups["skin"]
        centre = rest[np.unique(skin)].mean(axis=0)
        loops = []
        for lp in boundary_loops(skin):
            lp = np.asarray(lp, np.int32)
            c = rest[lp].mean(axis=0)
            area = np.cross(rest[lp] - c, rest[np.roll(lp, -1)] - c).sum(axis=0)
            loops.append(lp if area @ (c - centre) > 0 else lp[::-1].copy())
        mids = np.array([rest[lp].mean(axis=0) for lp in loops])
        neck = int(np.argmin(mids[:, 1]))
        lips = rest[self.lip_pairs.ravel()] if len(self.lip_pairs) else rest[self.groups["mouth"].ravel()]
        mouth = int(np.argmin(np.linalg.norm(mids - lips.mean(axis=0), axis=1)))
        eyes = [k for k in range(len(loops)) if k not in (neck, mouth)]
        if len(loops) > 7 or neck == mouth or not eyes:
            return loops, np.zeros(len(self.triangles), np.uint8)  # not the layout expected: hide nothing
        self.mouth_opening = mouth
        behind = [np.zeros(len(self.groups["skin"]), np.uint8),
                  np.full(len(self.groups["mouth"]), (1 << mouth) | (1 << neck), np.uint8)]
        for name in ("eyes", "sockets"):
            first = self.groups[name][:, 0]
            bits = np.zeros(len(first), np.uint8)
            for part in (f"eyeball_{side}" if name == "eyes" else f"eye_socket_{side}" for side in "lr"):
                lo, hi = PARTS[part]
                own = eyes[int(np.argmin(np.linalg.norm(mids[eyes] - rest[lo:hi].mean(axis=0), axis=1)))]
                bits[(first >= lo) & (first < hi)] = (1 << own) | (1 << neck)
            behind.append(bits)
        behind.append(np.zeros(len(self.groups["lashes"]), np.uint8))
        return loops, np.concatenate(behind)

    def _materials(self, lay: dict[str, np.ndarray], rest: np.ndarray,
                   edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = N_VERTICES
        alb = np.tile(SKIN, (n, 1))
        alb += (CHEEK - SKIN) * lay["cheek"][:, None]
        ao = np.ones(n)
        spec = np.full(n, 0.10)
        # broad occlusion: depth below a heavily smoothed copy of the skin, along the normal
        from sim.build import vertex_normals

        skin_tri = self.groups["skin"]
        normals = vertex_normals(rest, skin_tri)
        skin_edges = _edges(skin_tri)
        smooth = _smooth(rest, skin_edges, 24)
        depth = np.einsum("ij,ij->i", smooth - rest, normals)
        used = np.zeros(n, bool)
        used[skin_tri.ravel()] = True
        ao[used] = np.exp(-2.2 * np.clip(depth[used], 0.0, None))
        # the mouth's inside: darker the deeper behind the front teeth
        lo, hi = PARTS["mouth_socket"][0], PARTS["teeth"][1]
        z_front = rest[PARTS["teeth"][0]:hi, 2].max()
        behind = np.clip(z_front - rest[lo:hi, 2], 0.0, None)
        ao[lo:hi] = np.exp(-behind / 1.0)
        a, b = PARTS["mouth_socket"]
        alb[a:b] = SOCKET
        a, b = PARTS["gums_tongue"]
        # the tongue is the middle of the floor; the gums are the rest of that part
        mid = (np.abs(rest[a:b, 0]) < 2.2) & (rest[a:b, 1] < rest[a:b, 1].min() + 2.4)
        alb[a:b] = np.where(mid[:, None], TONGUE, GUMS)
        # the tongue's front comes out between the lips (tongue_out): less of the mouth's shade on it
        tip = mid & (rest[a:b, 2] > z_front - 3.0)
        ao[a:b][tip] = np.exp(-np.clip(z_front - rest[a:b, 2][tip], 0.0, None) / 2.5)
        spec[a:b] = 0.25
        a, b = PARTS["teeth"]
        alb[a:b] = TEETH
        spec[a:b] = 0.35
        for part in SOCKET_PARTS:
            a, b = PARTS[part]
            alb[a:b] = EYE_SOCKET
            spec[a:b] = 0.5
        for part in LASH_PARTS:
            a, b = PARTS[part]
            alb[a:b] = LASH
            spec[a:b] = 0.0
        mat = np.stack([lay["brow"], lay["lip"], ao, spec], axis=1).astype(np.float32)
        return alb.astype(np.float32), mat

    def _gaze_angles(self, rest: np.ndarray) -> np.ndarray:
        """(N,) float32: each eyeball shell vertex's angle (rad) from its eye's gaze axis at rest (the
        axis through the sphere's centre and the cornea's apex)."""
        out = np.full(N_VERTICES, 3.0, np.float32)
        for side in ("l", "r"):
            lo, _ = PARTS[f"eyeball_{side}"]
            p = rest[lo:lo + SCLERA]
            a = np.c_[2.0 * p, np.ones(len(p))]
            x = np.linalg.lstsq(a, (p**2).sum(axis=1), rcond=None)[0]
            c = x[:3]
            r = np.linalg.norm(p - c, axis=1)
            g = p[np.argmax(r)] - c
            g /= np.linalg.norm(g)
            cosang = (p - c) @ g / np.maximum(r, 1e-9)
            out[lo:lo + SCLERA] = np.arccos(np.clip(cosang, -1.0, 1.0))
        return out

    def eye_balls(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Balls that hide what lies behind them, one in each eyeball: (K, 4) int32 sclera
        vertices and (K, 4) float64 affine weights whose combination is the ball's centre (so it
        follows the eyeball's rigid motion: gaze and head turn), (K,) float64 radii, and per
        triangle of `triangles` a bit per ball that can hide it (the eye sockets behind their
        eyeball). The centre is the sclera's fitted sphere's; the radius the least distance from
        it to the plane of any triangle of the eyeball's outer shell, less EYE_BALL_MARGIN_CM, so
        the ball lies inside that closed shell (drawn, opaque) with room for the depth buffer's
        precision."""
        rest = self.rest
        idx, weights, radii = [], [], []
        occluded = np.zeros(len(self.triangles), np.uint8)
        lo_sockets = sum(len(self.groups[g]) for g in ("skin", "mouth", "eyes"))
        sockets = self.groups["sockets"]
        for k, side in enumerate("lr"):
            lo, _ = PARTS[f"eyeball_{side}"]
            p = rest[lo:lo + SCLERA]
            fit = np.linalg.lstsq(np.c_[2.0 * p, np.ones(len(p))], (p**2).sum(axis=1), rcond=None)[0]
            centre = fit[:3]
            shell = _eyeball_shell(side)
            a, b, c = rest[shell[:, 0]], rest[shell[:, 1]], rest[shell[:, 2]]
            n = np.cross(b - a, c - a)
            n /= np.maximum(np.linalg.norm(n, axis=1), 1e-12)[:, None]
            reach = np.einsum("ij,ij->i", a - centre, n)  # + : the triangle faces away from the centre
            if len(reach) == 0 or reach.min() <= EYE_BALL_MARGIN_CM:
                continue  # not a closed shell around its centre: hides nothing
            own = lo + np.array([np.argmin(p[:, 0]), np.argmax(p[:, 0]), np.argmax(p[:, 1]), np.argmax(p[:, 2])])
            m = np.vstack([rest[own].T, np.ones(4)])
            if abs(np.linalg.det(m)) < 1e-9:
                continue
            idx.append(own)
            weights.append(np.linalg.solve(m, np.r_[centre, 1.0]))
            radii.append(float(reach.min()) - EYE_BALL_MARGIN_CM)
            slo, shi = PARTS[f"eye_socket_{side}"]
            mine = (sockets[:, 0] >= slo) & (sockets[:, 0] < shi)
            occluded[lo_sockets:lo_sockets + len(sockets)][mine] |= np.uint8(1 << (len(idx) - 1))
        return (np.array(idx, np.int32).reshape(-1, 4), np.array(weights, np.float64).reshape(-1, 4),
                np.array(radii, np.float64), occluded)

    def skin_split(self) -> dict[str, np.ndarray]:
        return {k: self.groups["skin"][m] for k, m in self._skin_masks().items()}

    def _skin_masks(self) -> dict[str, np.ndarray]:
        """The skin's triangles in two groups: "features", those a brow or the vermilion reaches
        (a corner within the brow's or the lip's shading edge, render.scan_shaders.SCAN_SKIN_FS),
        and "plain", the rest, where those terms are exactly nothing."""
        t = self.groups["skin"]
        m = self.material
        plain = (m[t, 0] >= BROW_CLEAR).all(axis=1) & (m[t, 1] >= LIP_CLEAR).all(axis=1)
        return {"features": ~plain, "plain": plain}

    def coarse_plain(self) -> np.ndarray:
        """(K, 3) int32 the plain skin's coarser list (render.scan_lod: four fifths of its triangles,
        over the same vertices, meeting the features' triangles edge for edge), in Z-order."""
        from render.scan_lod import coarse_plain

        return spatial_order(coarse_plain()[0], self.rest).astype(np.int32)

    def coarse_inside(self) -> tuple[np.ndarray, np.ndarray]:
        """((T,) bool the mouth group's triangles that render.scan_lod's coarse inside stands for (its
        lining, gums and tongue), (K, 3) int32 that coarse list, in Z-order)."""
        from render.scan_lod import coarse_inside, inside_of

        return inside_of(self.groups["mouth"]), spatial_order(coarse_inside()[0], self.rest).astype(np.int32)

    def coarse_lashes(self) -> np.ndarray:
        """(K, 3) int32 the lashes as fewer triangles (`coarse_lashes`), in Z-order as the full list;
        the full list when the scan's strips are not the grids expected."""
        few = coarse_lashes()
        return spatial_order(few, self.rest).astype(np.int32) if len(few) else self.groups["lashes"]

    def group_of_triangles(self, order: tuple[str, ...]) -> np.ndarray:
        """(T,) int8: for each triangle of `triangles`, its group's place in `order` (group names,
        the skin's as "plain" / "features" of skin_split), -1 for a group not in it."""
        out = []
        for name, t in self.groups.items():
            if name == "skin":
                masks = self._skin_masks()
                g = np.where(masks["plain"], order.index("plain") if "plain" in order else -1,
                             order.index("features") if "features" in order else -1)
            else:
                g = np.full(len(t), order.index(name) if name in order else -1)
            out.append(g)
        return np.concatenate(out).astype(np.int8)

    def mouth_open(self, posed: np.ndarray) -> bool:
        """Whether the lips have parted anywhere along the mouth (the inside can be seen)."""
        if not len(self.lip_pairs):
            return True
        gap = np.linalg.norm(posed[self.lip_pairs[:, 0]] - posed[self.lip_pairs[:, 1]], axis=1)
        return bool(np.any(gap > self.lip_rest + LIP_GAP))
