"""The per-frame rows of the scanned head (x y z nx ny nz fold per vertex) and, for a given camera,
which of its triangles may be seen: the two are independent and made at once by render.scan_kernel
(the rows on the calling thread, the listing on a helper thread; neither kernel holds the
interpreter lock), so the frame's CPU pass takes about as long as the rows alone, on a second core
that sits idle while the rasterizer's threads wait for this frame's triangles."""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from render.scan_look import ScanLook
from sim.face.scan.data import N_VERTICES

# pixel centres: a triangle whose box on screen holds at most this many is tested at each of them
# (render.scan_kernel._no_pixel): at 720p with the jaw open, 2 leaves out 257 more triangles for
# 0.02-0.05 ms more listing, 6 leaves out 485 for 0.11-0.13 ms (the triangles' cost in llvmpipe)
SMALL_BOX = 2.0
OPENING_MARGIN_PX = 3.0  # pixels an opening's box and hull on screen are widened by (rounding, the pixel grid)
WALL_MARGIN_CM = 0.05  # cm the sides of an opening's prism are pushed out by (render.scan_kernel.openings)


def _listing(args: tuple, xy: np.ndarray | None, box: np.ndarray) -> None:  # type: ignore[type-arg]
    """The triangles seen (render.scan_kernel.seen_triangles(*args)) and, given the vertices' pixels
    it leaves in `xy`, their box on screen into `box`."""
    from render.scan_kernel import screen_box, seen_triangles

    seen_triangles(*args)
    if xy is not None:
        screen_box(xy, box)


class ScanRows:
    """The posed scan as the renderer's rows x y z nx ny nz fold (one (N, 7) float32 array,
    rewritten every call: upload it, don't keep it). While the lips are shut the mouth's inside is
    not drawn, and the rows of its deep part (what no drawn vertex's normal or fold reads) are left
    as they were: its triangles are a quarter of the scan's. `listed`: triangles over the same
    vertices listed after the scan's own (a group index per triangle of both chooses which are
    drawn), that the normals and fold terms do not read (the coarse plain skin, render.scan_lod),
    the last `listed_mouth` of them the mouth's (the coarse lining, gums and tongue: hidden by the
    mouth's opening as its triangles are, and passed over while the lips are shut); the others lie
    behind the openings the scan's triangles at their corners all do (the coarse eyeballs' shells
    behind their eyes').
    `sealed`: (N,) bool the vertices that never pass through the lips (the teeth and gums as the
    face's dressing poses them): the mouth's triangles among them may be hidden beside the mouth's
    opening as well as behind it (render.scan_kernel.seen_triangles)."""

    def __init__(self, look: ScanLook, listed: np.ndarray | None = None, sealed: np.ndarray | None = None,
                 listed_mouth: int = 0) -> None:
        self.look = look
        self.buffer = np.zeros((N_VERTICES, 7), np.float32)
        self.scratch = np.zeros(N_VERTICES, np.float32)
        self.code = np.zeros(N_VERTICES, np.int32)
        self.deep = np.zeros(N_VERTICES, np.uint8)
        self.xy = np.zeros((N_VERTICES, 2), np.float32)
        self.size = np.zeros(2)
        self.tri = np.ascontiguousarray(look.triangles, np.int32)
        self.skip_tri, self.skip_v = self._deep_mouth()
        unread_tri, unread_v = self._unread()
        self.skip_tri |= unread_tri << 1
        self.skip_v |= unread_v << 1
        self.inside = np.zeros(N_VERTICES, np.uint8)  # the corners of triangles inside the head
        self.inside[self.tri[look.behind != 0].ravel()] = 1
        extra = np.zeros((0, 3), np.int32) if listed is None else np.asarray(listed, np.int32)
        self.list_tri = np.ascontiguousarray(np.concatenate([self.tri, extra]), np.int32)
        self.list_skip = np.concatenate([self.skip_tri & 1, np.zeros(len(extra), np.uint8)])
        self.list_behind = np.concatenate([look.behind, np.zeros(len(extra), look.behind.dtype)])
        if len(extra):  # a listed triangle lies behind the openings every scan triangle at its corners does
            bits = np.zeros(N_VERTICES, look.behind.dtype)
            np.bitwise_or.at(bits, self.tri.ravel(), np.repeat(look.behind, 3))
            self.list_behind[len(self.tri):] = bits[extra[:, 0]] & bits[extra[:, 1]] & bits[extra[:, 2]]
        if listed_mouth:
            lo = len(look.groups["skin"])  # `triangles` are the groups in order, the skin's first
            self.list_skip[-listed_mouth:] = 1
            self.list_behind[-listed_mouth:] = look.behind[lo:lo + len(look.groups["mouth"])].max(initial=0)
        self.loops = [np.asarray(lp, np.int32) for lp in look.openings]
        self.loop_ptr = np.cumsum([0, *(len(lp) for lp in self.loops)]).astype(np.int64)
        self.loop_all = np.ascontiguousarray(np.concatenate(self.loops) if self.loops else np.zeros(0, np.int32))
        self.planes = np.zeros((len(self.loops), 4))
        self.boxes = np.zeros((len(self.loops), 4))
        self.hulls = np.zeros((len(self.loops), max((len(lp) for lp in self.loops), default=0) + 1, 3))
        self.hull_n = np.zeros(len(self.loops), np.int64)
        self.hull_none = np.zeros(len(self.loops), np.int64)
        self.walls = np.zeros((len(self.loops), max((len(lp) for lp in self.loops), default=0) + 1, 4))
        self.wall_n = np.zeros(len(self.loops), np.int64)
        self.sealed = np.zeros(len(self.list_tri), np.uint8)
        if sealed is not None and look.mouth_opening >= 0:
            mouth = np.zeros(len(self.list_tri), bool)
            mouth[:] = (self.list_behind >> look.mouth_opening) & 1 != 0
            self.sealed[mouth & np.asarray(sealed, bool)[self.list_tri].all(axis=1)] = 1 << look.mouth_opening
        self.use_walls = True  # False: the teeth and gums hidden only behind the mouth's opening (the same pixels)
        self._no_walls = np.zeros_like(self.sealed)
        self.use_hulls = True  # False: the openings' boxes on screen alone hide the inside (the same pixels)
        self._no_view = (np.zeros((0, 4)), np.zeros((0, 4)), np.zeros((0, 1, 3)), np.zeros(0, np.int64), np.eye(4),
                         np.zeros(2))
        # the eyeballs' hiding balls (render.scan_look.eye_balls): the eye sockets behind them left out
        self.ball_idx, self.ball_w, self.ball_r, occluded = look.eye_balls()
        self.occluded = np.concatenate([occluded, np.zeros(len(extra), np.uint8)])
        bits = np.zeros(N_VERTICES, np.uint8)  # the balls that may hide a triangle at each vertex
        for k in range(len(self.ball_r)):
            bits[self.list_tri[(self.occluded >> k) & 1 != 0].ravel()] |= np.uint8(1 << k)
        self.near = np.flatnonzero(bits).astype(np.int32)
        self.near_bits = bits[self.near]
        self.sides = np.zeros(N_VERTICES, np.uint8)
        self._balls = (self.ball_idx, self.ball_w, self.ball_r, self.near, self.near_bits, self.occluded)
        self._no_balls = (self.ball_idx[:0], self.ball_w[:0], self.ball_r[:0], self.near, self.near_bits,
                          np.zeros_like(self.occluded))
        self.use_balls = True  # False: the eyeballs hide nothing (the same pixels)
        self.small_box = SMALL_BOX  # 0: the triangles' boxes alone tell which hold no pixel centre (the same pixels)
        # the box on screen (pixels x0 y0 x1 y1, y up) of every vertex in the rows last made with a
        # camera and a picture size; NaN when they were made without
        self.box = np.full(4, np.nan)
        self.closed = True  # whether the lips were shut in the rows last made
        self.threaded = True  # False: the listing of the triangles seen on the calling thread too
        self._pool: ThreadPoolExecutor | None = None

    def _deep_mouth(self) -> tuple[np.ndarray, np.ndarray]:
        """(T,) uint8 the mouth's triangles and (N,) uint8 the vertices that only the mouth's inside
        uses and that lie over one edge away from any vertex drawn with the lips shut (the normals
        of those next to a drawn vertex feed its fold term, so they are kept exact)."""
        look = self.look
        n = N_VERTICES
        drawn = np.zeros(n, bool)
        for name, t in look.groups.items():
            if name != "mouth":
                drawn[t.ravel()] = True
        near = drawn.copy()
        for i in np.flatnonzero(drawn):
            near[look.nbr[look.nbr_ptr[i]:look.nbr_ptr[i + 1]]] = True
        mouth = np.zeros(n, bool)
        mouth[look.groups["mouth"].ravel()] = True
        in_mouth = np.zeros(len(self.tri), bool)
        lo = len(look.groups["skin"])
        in_mouth[lo:lo + len(look.groups["mouth"])] = True  # `triangles` are the groups in order
        skip_tri = in_mouth & ~near[self.tri].any(axis=1)
        skip_v = mouth & ~near
        return skip_tri.astype(np.uint8), skip_v.astype(np.uint8)

    def _unread(self) -> tuple[np.ndarray, np.ndarray]:
        """(T,) uint8 the triangles whose corners' normals no shader reads, directly or through a
        fold term, and (N,) uint8 the vertices whose fold term none reads (render.scan_shaders: the
        skin's shader, which draws the skin, the sockets and the mouth's inside, reads both; the
        eyes' reads the normal; the lashes' neither)."""
        look = self.look
        n = N_VERTICES
        fold = np.zeros(n, bool)
        for name in ("skin", "sockets", "mouth"):
            fold[look.groups[name].ravel()] = True
        near = fold.copy()  # a fold term reads its neighbours' normals and positions
        for i in np.flatnonzero(fold):
            near[look.nbr[look.nbr_ptr[i]:look.nbr_ptr[i + 1]]] = True
        normal = near.copy()
        normal[look.groups["eyes"].ravel()] = True
        return (~normal[self.tri].any(axis=1)).astype(np.uint8), (~near).astype(np.uint8)

    def rows(self, posed: np.ndarray, eye: np.ndarray | None = None, group: np.ndarray | None = None,
             starts: np.ndarray | None = None, kept: np.ndarray | None = None,
             counts: np.ndarray | None = None, mvp: np.ndarray | None = None,
             size: tuple[int, int] | None = None) -> np.ndarray:
        """The rows of the scan posed so; given `eye` (the camera's position) and a group per
        triangle of `look.triangles` and then of `listed` (-1: none), also the triangles of each
        group g that may face the eye, at kept[starts[g]:][:counts[g]]; given also the camera's
        `mvp` (projection @ view) and the picture's `size`, without those that cover no pixel or that the skin hides
        (render.scan_kernel.seen_triangles, on a helper thread while this one makes the rows)."""
        from render.scan_kernel import openings, scan_rows

        p = np.ascontiguousarray(posed, dtype=np.float32)
        closed = self.closed = not self.look.mouth_open(p)
        listing: Future[None] | None = None
        self.box[:] = np.nan
        if not (eye is None or group is None or starts is None or kept is None or counts is None):
            planes, boxes, hulls, hull_n, clip, px = self._no_view
            view = mvp is not None and size is not None and min(size) > 0
            if view:
                clip, px = np.ascontiguousarray(mvp, np.float64), self.size
                px[:] = size
                planes, boxes, hulls, hull_n = self.planes, self.boxes, self.hulls, self.hull_n
                openings(p, self.loop_ptr, self.loop_all, clip, px, OPENING_MARGIN_PX, planes, boxes, hulls, hull_n,
                         self.walls, self.wall_n, WALL_MARGIN_CM)
                if not self.use_hulls:
                    hull_n = self.hull_none
            args = (p, self.list_tri, self.list_skip, closed, group, starts, np.asarray(eye, np.float32), kept,
                    counts, self.list_behind, clip, px, planes, boxes, hulls, hull_n, self.inside, self.xy, self.code,
                    self.deep, *(self._balls if self.use_balls else self._no_balls), self.sides, float(self.small_box),
                    self.sealed if self.use_walls else self._no_walls, self.walls, self.wall_n)
            if not self.threaded:
                _listing(args, self.xy if view else None, self.box)
            else:
                if self._pool is None:
                    self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="scan-rows")
                listing = self._pool.submit(_listing, args, self.xy if view else None, self.box)
        try:
            scan_rows(p, self.tri, self.look.nbr_ptr, self.look.nbr, self.look.inv_len, self.scratch, self.buffer,
                      self.skip_tri, self.skip_v, closed)
        finally:
            if listing is not None:
                listing.result()
        return self.buffer

    def close(self) -> None:
        """Stop the helper thread (made again if rows are asked for later)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
