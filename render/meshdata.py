"""Geometry the renderer derives from the face model: built once in `populate`, then only the cheap
per-frame parts (normals, cavity rims, muscle ends) are recomputed from the drawn surface."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from sim.face.turn import is_turned, state_turn, turn_head, turn_weights
from sim.model import FaceMesh, FaceRig, LinearMuscle, SheetMuscle, SphincterMuscle

# Linear-light albedos: skin, lips.
SKIN = np.array([0.58, 0.40, 0.31])
LIPS = np.array([0.50, 0.17, 0.16])
HAIR = np.array([0.10, 0.065, 0.045])  # dark brown, linear albedo (the default head's scalp)
CAVITY = np.array([0.05, 0.015, 0.012])  # the inside of the mouth, in shadow (linear albedo)


class NormalComputer:
    """Area-weighted vertex normals of a moving surface, by a compiled kernel (numba,
    render.normals_kernel) that writes positions and normals interleaved into one preallocated
    (N, 6) float32 array: each frame is one pass over the triangles and one upload of
    `interleaved(positions)`. The kernel is loaded at the first call, not at import: a render
    process that is handed the interleaved rows (puppet.export.video) never loads numba at all."""

    def __init__(self, triangles: np.ndarray, n_vertices: int) -> None:
        self.tri = np.ascontiguousarray(triangles, dtype=np.int32)
        self.buffer = np.zeros((n_vertices, 6), np.float32)

    def interleaved(self, positions: np.ndarray) -> np.ndarray:
        """(N, 6) float32 rows x y z nx ny nz (the same array every call: upload it, don't keep it)."""
        from render.normals_kernel import interleave_normals

        p = np.ascontiguousarray(positions, dtype=np.float32)
        interleave_normals(p, self.tri, self.buffer)
        return self.buffer

    def __call__(self, positions: np.ndarray) -> np.ndarray:
        """(N, 3) float32 unit normals (a copy)."""
        return self.interleaved(positions)[:, 3:].copy()


class SurfaceRows:
    """The rows x y z nx ny nz of everything drawn of a face's skin, in one (N + M, 6) float32
    array: the mask's surface (N) and, when the face has a held head (sim.face.head.HeadShell),
    the head's vertices (M) posed to that surface, with normals computed over both meshes, so the
    shading runs on across the join. Without a head it is the mask's NormalComputer."""

    def __init__(self, triangles: np.ndarray, n_vertices: int, shell: object | None = None,
                 rest: np.ndarray | None = None) -> None:
        self.n = int(n_vertices)
        self.shell = shell
        self.mask_turn = np.ones(self.n) if rest is None else turn_weights(rest)
        if shell is None:
            self.normals = NormalComputer(triangles, self.n)
            return
        m = len(shell.vertices)  # type: ignore[attr-defined]
        joined = np.vstack([np.asarray(triangles, np.int32), shell.joined_triangles(self.n)])  # type: ignore[attr-defined]
        self.normals = NormalComputer(joined, self.n + m)
        self.positions = np.zeros((self.n + m, 3), np.float32)
        self.ring = self.n + np.asarray(shell.ring)  # type: ignore[attr-defined]
        self.ring_mask = np.asarray(shell.ring_mask)  # type: ignore[attr-defined]
        self.shell_turn = turn_weights(shell.vertices)  # type: ignore[attr-defined]

    def interleaved(self, surface: np.ndarray, turn: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
        """(N + M, 6) rows (the same array every call: upload it, don't keep it), the head turned
        on the neck by `turn` = (yaw, pitch, roll) channel values (sim.face.turn)."""
        turned = is_turned(*turn)
        if self.shell is None:
            return self.normals.interleaved(turn_head(surface, self.mask_turn, *turn) if turned else surface)
        self.positions[:self.n] = surface
        self.positions[self.n:] = self.shell.pose(surface)  # type: ignore[attr-defined]
        if turned:
            self.positions[:self.n] = turn_head(self.positions[:self.n], self.mask_turn, *turn)
            self.positions[self.n:] = turn_head(self.positions[self.n:], self.shell_turn, *turn)
        rows = self.normals.interleaved(self.positions)
        rows[self.ring] = rows[self.ring_mask]  # the join's vertices are the mask's own
        return rows


def surface_rows(model: object) -> SurfaceRows:
    """The SurfaceRows of a face model (its rig's held head included, if it has one)."""
    from sim.face.head import shell_for

    rig = getattr(model, "rig", None)
    shell = shell_for(rig) if rig is not None else None
    return SurfaceRows(np.asarray(model.triangles, np.int32), len(model.rest), shell,  # type: ignore[attr-defined]
                       np.asarray(model.rest))  # type: ignore[attr-defined]


head_turn = state_turn  # the state's head turn, for the renderer and the export's frames


def spatial_order(triangles: np.ndarray, positions: np.ndarray, bits: int = 10) -> np.ndarray:
    """The triangles reordered along a Z-order (Morton) curve of their centroids in the front view
    (x, y), so consecutive triangles share vertices and screen tiles: llvmpipe shades the
    vertices of a run of triangles once per batch (an index-keyed cache) and bins neighbours into
    the same tiles. Same triangles, same winding; only the drawing order changes."""
    t = np.asarray(triangles)
    if len(t) == 0:
        return t.copy()
    c = np.asarray(positions, np.float64)[t].mean(axis=1)[:, :2]
    lo, span = c.min(axis=0), np.maximum(np.ptp(c, axis=0), 1e-12)
    q = ((c - lo) / span * ((1 << bits) - 1)).astype(np.int64)
    code = np.zeros(len(t), np.int64)
    for b in range(bits):
        code |= ((q[:, 0] >> b) & 1) << (2 * b) | ((q[:, 1] >> b) & 1) << (2 * b + 1)
    return t[np.argsort(code, kind="stable")]


def unique_edges(triangles: np.ndarray) -> np.ndarray:
    """(E, 2) int32 undirected edges of a triangle mesh, each once."""
    t = np.asarray(triangles)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0).astype(np.int32)


def _region_mask(mesh: FaceMesh, words: Iterable[str], avoid: Iterable[str] = ()) -> np.ndarray:
    mask = np.zeros(len(mesh.vertices), bool)
    for name, m in mesh.regions.items():
        low = name.lower()
        if any(w in low for w in words) and not any(a in low for a in avoid):
            mask |= np.asarray(m, bool)
    return mask


def _smooth(mask: np.ndarray, triangles: np.ndarray, rounds: int = 2) -> np.ndarray:
    """Blur a per-vertex mask over mesh neighbours so tints fade instead of stepping: each round a
    vertex takes the mean of itself and its neighbours. (numpy only: a render process of an export
    should not pay for importing scipy.)"""
    n = len(mask)
    e = unique_edges(triangles)
    deg = 1.0 + np.bincount(e[:, 0], minlength=n) + np.bincount(e[:, 1], minlength=n)
    v = mask.astype(float)
    for _ in range(rounds):
        total = v.copy()
        np.add.at(total, e[:, 0], v[e[:, 1]])
        np.add.at(total, e[:, 1], v[e[:, 0]])
        v = total / deg
    return v


def _distance_to_loop(points: np.ndarray, loop: np.ndarray) -> np.ndarray:
    """(N,) distance of 2-D points to a closed polyline (not just to its nodes)."""
    a, b = loop, np.roll(loop, -1, axis=0)
    ab = b - a
    t = np.einsum("nkd,kd->nk", points[:, None, :] - a[None], ab) / np.maximum(
        np.einsum("kd,kd->k", ab, ab), 1e-12)
    q = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.min(np.linalg.norm(points[:, None, :] - q, axis=2), axis=1)


def skin_tint(mesh: FaceMesh) -> np.ndarray:
    """(N, 3) float32 linear albedo: skin, with the red of the lips (the vermilion).

    The vermilion is a smooth function of the front-view distance to the mouth opening (the
    polyline through the mouth loop, not its nodes), a band that narrows towards the corners and
    fades out over its outer half. A smooth weight stays smooth when interpolated over a coarse
    mesh, where a per-region mask came out blotchy. Brows: see `brow_coords`."""
    v = mesh.vertices
    col = np.tile(SKIN, (len(v), 1))
    if len(mesh.mouth_loop) < 3:
        return _cavity_dark(mesh, col).astype(np.float32)
    loop = v[mesh.mouth_loop][:, :2]
    width = float(np.ptp(loop[:, 0])) or 1.0
    d = _distance_to_loop(v[:, :2], loop)
    across = np.clip((v[:, 0] - loop[:, 0].mean()) / (0.5 * width), -1.0, 1.0)
    band = 0.16 * width * (0.6 + 0.4 * (1.0 - across**2))    # narrower at the corners
    t = np.clip((d - 0.45 * band) / (0.55 * band), 0.0, 1.0)
    w = 1.0 - t * t * (3.0 - 2.0 * t)                         # smoothstep fade
    w *= v[:, 2] > loop_depth(v, mesh.mouth_loop, width)      # only the front, not inside the mouth
    w = w[:, None]
    return _cavity_dark(mesh, SKIN * (1 - w) + LIPS * w).astype(np.float32)


def _cavity_dark(mesh: FaceMesh, col: np.ndarray) -> np.ndarray:
    """An imported head's own lining of the mouth, sockets and nostrils (the region "cavity" the
    rig transfer marks) in the dark of a cavity, fading over one ring of neighbours, so a mouth
    that opens shows a dark inside instead of lit skin."""
    mask = mesh.regions.get("cavity")
    if mask is None or not np.any(mask):
        return col
    w = np.maximum(_smooth(np.asarray(mask, bool), mesh.triangles, 1), np.asarray(mask, float))[:, None]
    return col * (1 - w) + CAVITY * w


def face_frame(mesh: FaceMesh, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box (cm) the camera frames: the mesh's bounds, held to the head around the face when the
    mesh carries more (an imported head with its neck and shoulders would leave the face small in
    the picture): at most 0.15 of the chin-forehead span below the chin, 0.5 above the forehead
    and 0.6 either side of the midline. The built-in faces lie inside that box."""
    lo, hi = rest.min(axis=0).astype(float), rest.max(axis=0).astype(float)
    lm = mesh.landmarks
    if "chin" not in lm or "forehead_center" not in lm:
        return lo, hi
    chin, top = rest[lm["chin"]], rest[lm["forehead_center"]]
    span = float(top[1] - chin[1])
    if span <= 0:
        return lo, hi
    mid = 0.5 * float(chin[0] + top[0])
    lo[:2] = np.maximum(lo[:2], [mid - 0.6 * span, chin[1] - 0.15 * span])
    hi[:2] = np.minimum(hi[:2], [mid + 0.6 * span, top[1] + 0.5 * span])
    return lo, np.maximum(hi, lo + 1e-3)


def loop_depth(v: np.ndarray, loop: np.ndarray, width: float) -> float:
    """A depth (z) behind the mouth opening: vertices behind it are not lips."""
    return float(v[loop][:, 2].min() - 0.3 * width)


def brow_polylines(mesh: FaceMesh) -> np.ndarray:
    """(B, 3, 3) rest points inner -> mid -> outer of each brow, from the landmarks
    brow_{inner,mid,outer}_{l,r} (B = 0 when the mesh has none)."""
    lines = []
    for side in ("l", "r"):
        names = [f"brow_{part}_{side}" for part in ("inner", "mid", "outer")]
        if all(n in mesh.landmarks for n in names):
            lines.append([mesh.landmark(n) for n in names])
    return np.array(lines, float).reshape(-1, 3, 3)


def brow_coords(mesh: FaceMesh) -> np.ndarray:
    """(N, 2) float32 per vertex: signed distance (cm, front view) across the nearest brow line
    (inner -> mid -> outer landmarks) and the position along it (0 at the inner end, 1 at the
    outer). Both are close to linear over a triangle, so the shader interpolates them and draws a
    crisp tapered brow at a few operations per pixel, sharp even on a coarse mesh."""
    p = mesh.vertices[:, :2]
    out = np.full((len(p), 2), (1e3, -1.0), np.float32)
    best = np.full(len(p), np.inf)
    for line in brow_polylines(mesh):
        pts = line[:, :2]
        seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        total = float(seg_len.sum()) or 1.0
        start = 0.0
        for k in range(2):
            a, ab = pts[k], pts[k + 1] - pts[k]
            t = (p - a) @ ab / max(float(ab @ ab), 1e-12)
            tc = np.clip(t, 0.0, 1.0)
            d = np.linalg.norm(p - a - tc[:, None] * ab, axis=1)
            sd = ((p - a) @ np.array([-ab[1], ab[0]])) / max(seg_len[k], 1e-9)
            if pts[-1, 0] < pts[0, 0]:
                sd = -sd  # the right brow runs the other way: keep + = up on both sides
            u = (start + t * seg_len[k]) / total
            take = d < best
            best[take] = d[take]
            out[take, 0], out[take, 1] = sd[take], u[take]
            start += seg_len[k]
    return out


def uv_sphere(rings: int = 16, segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Unit sphere with its poles on +-Z (the eye's gaze axis): (V, 3) float32, (T, 3) int32."""
    th = np.linspace(0.0, np.pi, rings + 1)
    ph = np.linspace(0.0, 2 * np.pi, segments + 1)
    t, p = np.meshgrid(th, ph, indexing="ij")
    pos = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    idx = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    tris = np.concatenate([np.stack([a, c, d], -1).reshape(-1, 3),
                           np.stack([a, d, b], -1).reshape(-1, 3)])
    return pos.astype(np.float32), tris.astype(np.int32)


def eye_rotation(yaw: float, pitch: float) -> np.ndarray:
    """3x3 rotation turning the gaze (+Z) by yaw towards +X (the face's left) and pitch towards +Y."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, sp], [0, -sp, cp]])  # +pitch lifts +Z towards +Y
    return ry @ rx


class Cavity:
    """A dark pocket behind a hole of the skin (the mouth, the eye sockets): rings that shrink
    and recede from the hole's rim to an apex, so the background never shows through a hole.
    The rim ring follows every node of the hole's loop; the inner rings, mostly hidden behind
    the skin, take at most MAX_INNER of them (evenly spaced), so a fine mesh's 128-node mouth
    does not cost a thousand thin triangles per frame. A mouth's pocket has dim upper teeth
    behind the upper lip; with `dentition` (a head without teeth of its own, brought in by
    sim.face.transfer, whose rig's presets start with "imported") a ring just inside the lips
    carries bright teeth all round, upper and lower, so lips that part show teeth as a person's
    do rather than a dark hole."""

    RINGS = ((1.0, 0.0), (0.8, 0.35), (0.5, 0.9), (0.2, 1.3))  # (scale about centre, depth/width)
    # a mouth with teeth right behind the lips (`dentition`): a ring just inside the rim, where
    # the front teeth stand, then the rings above
    DENTITION_RINGS = ((1.0, 0.0), (0.9, 0.06), (0.75, 0.16), (0.5, 0.9), (0.2, 1.3))
    TEETH_SHADE = 2.2  # the teeth of `dentition`: in_teeth's value, brightening the shader's teeth
    MAX_INNER = 32

    def __init__(self, loop: np.ndarray, rest: np.ndarray, dentition: bool = False) -> None:
        self.loop = np.asarray(loop, np.int64)
        rings_spec = self.DENTITION_RINGS if dentition else self.RINGS
        m, k = len(self.loop), len(rings_spec)
        rim = rest[self.loop]
        self.width = float(max(np.ptp(rim[:, 0]), np.ptp(rim[:, 1]), 1e-3))
        # which loop positions each ring uses: all on the rim, an even subset inside
        inner = np.unique(np.linspace(0, m, min(m, self.MAX_INNER), endpoint=False).astype(np.int64))
        rings = [np.arange(m)] + [inner] * (k - 1)
        starts = np.cumsum([0] + [len(r) for r in rings])
        tris = []
        for r in range(k - 1):
            a_n, b_n = len(rings[r]), len(rings[r + 1])
            if a_n == b_n:
                for i in range(a_n):
                    j = (i + 1) % a_n
                    a, b = starts[r] + i, starts[r] + j
                    c, d = starts[r + 1] + i, starts[r + 1] + j
                    tris += [(a, b, d), (a, d, c)]
            else:  # the rim (a_n nodes) stitched to a coarser ring (b_n): a fan per inner step
                pos_b = rings[r + 1]
                owner = np.searchsorted(pos_b, np.arange(a_n), side="right") - 1  # inner node at or before
                for i in range(a_n):
                    j = (i + 1) % a_n
                    a, b = starts[r] + i, starts[r] + j
                    oi, oj = owner[i] % b_n, owner[j] % b_n
                    c, d = starts[r + 1] + oi, starts[r + 1] + oj
                    tris.append((a, b, d))
                    if oi != oj:
                        tris.append((a, d, c))
        last = rings[-1]
        apex = int(starts[-1])
        base = int(starts[-2])
        tris += [(base + i, base + (i + 1) % len(last), apex) for i in range(len(last))]
        self.triangles = np.array(tris, np.int32)
        self.depth = np.r_[np.concatenate([np.full(len(rg), d) for rg, (_, d) in zip(rings, rings_spec)]),
                           1.6].astype(np.float32)
        self.n_vertices = apex + 1
        # upper teeth: the upper half of the second and third rings, behind the upper lip
        above = (rim[:, 1] > rim[:, 1].mean()).astype(np.float32)
        self.teeth = np.zeros(self.n_vertices, np.float32)
        if dentition:  # upper and lower teeth all round, just behind the lips
            self.teeth[starts[1]:starts[3]] = self.TEETH_SHADE
        else:
            self.teeth[starts[1]:starts[2]] = above[rings[1]]
            self.teeth[starts[2]:starts[3]] = above[rings[2]]
        # per vertex: which rim node it scales from, the scale about the centre, the depth (cm)
        self._index = np.r_[np.concatenate([self.loop[rg] for rg in rings]), self.loop[:1]]
        self._scale = np.r_[np.concatenate([np.full(len(rg), sc) for rg, (sc, _) in zip(rings, rings_spec)]),
                            0.0].astype(np.float32)[:, None]
        self._drop = (self.depth * self.width * 0.5).astype(np.float32)
        self._m = m

    def positions(self, surface: np.ndarray) -> np.ndarray:
        rim = np.take(surface, self._index, axis=0)
        c = rim[:self._m].mean(axis=0)
        out = c + self._scale * (rim - c)
        out[:, 2] -= self._drop
        return out.astype(np.float32, copy=False)


class MuscleLines:
    """Line segments showing the rig's muscles (seed 000 Fig. 6/8): linear muscles from attachment
    to insertion, sphincters as ellipses, sheets as quads with a few fibres. Ends in the skin
    (insertions, sphincters) follow their nearest vertex; skull attachments stay put."""

    def __init__(self, rig: FaceRig, rest: np.ndarray, ellipse_segments: int = 32) -> None:
        ends: list[np.ndarray] = []
        flags: list[bool] = []
        for parts in rig.muscles.values():
            for mus in parts:
                for seg, in_skin in _muscle_segments(mus, ellipse_segments):
                    ends.extend(seg)
                    flags.extend(in_skin)
        self.fixed = np.array(ends, float).reshape(-1, 3)
        self.skin = np.array(flags, bool)
        if len(self.fixed):
            d = np.linalg.norm(self.fixed[:, None, :] - rest[None, :, :], axis=2)
            self.vertex = np.argmin(d, axis=1)
        else:
            self.vertex = np.zeros(0, np.int64)
        self.offset = self.fixed - rest[self.vertex]

    def __len__(self) -> int:
        return len(self.fixed)

    def positions(self, surface: np.ndarray) -> np.ndarray:
        """(2S, 3) float32 segment ends for the current surface."""
        out = self.fixed.copy()
        if self.skin.any():
            out[self.skin] = surface[self.vertex[self.skin]] + self.offset[self.skin]
        return out.astype(np.float32)


def _muscle_segments(mus: object, n: int) -> list[tuple[np.ndarray, tuple[bool, bool]]]:
    """Segments of one muscle, each with which of its two ends lies in the skin."""
    if isinstance(mus, LinearMuscle):
        return [(np.array([mus.attachment, mus.insertion]), (False, True))]
    if isinstance(mus, SphincterMuscle):
        t = np.linspace(0, 2 * np.pi, n + 1)
        ring = (mus.center + mus.a * np.cos(t)[:, None] * mus.major_axis
                + mus.b * np.sin(t)[:, None] * mus.minor_axis)
        return [(ring[i:i + 2], (True, True)) for i in range(n)]
    if isinstance(mus, SheetMuscle):
        a1, a2, i1, i2 = mus.attach1, mus.attach2, mus.insert1, mus.insert2
        segs = [(np.array([a1, a2]), (False, False)), (np.array([i1, i2]), (True, True))]
        for f in np.linspace(0.0, 1.0, 4):
            segs.append((np.array([a1 + f * (a2 - a1), i1 + f * (i2 - i1)]), (False, True)))
        return segs
    return []
