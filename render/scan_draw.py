"""Drawing the scanned head (sim.face.scan) for `FaceRenderer`: the whole scan, posed every frame by
the face's dressing (`pose(surface, control)` -> the scan's 26,719 vertices), with materials
(render.scan_look) and back faces culled. The mouth's inside (lining, gums, tongue, teeth: a third
of the scan's triangles) is drawn only while the lips are apart; the eyeballs' inner layer, the
tear film and the eyes' blend and occlusion shells are never drawn."""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np

from render import scan_shaders
from render.pipeline import flush, threaded_rasterizer
from render.scan_look import IRIS_ANGLE, PUPIL_ANGLE, ScanLook
from render.scan_rows import ScanRows
from render.scan_seam import LidSeam
from render.scan_soften import FoldSoftener
from sim.face.scan.blendshapes import StateControl as PoseControl
from sim.face.scan.lid_contact import LidContact

KINDS = ("SKIN", "CLAY", "HEAT")
# the groups drawn with back faces culled, in drawing order: the skin first (so that the depth test
# rejects the hidden pixels of what follows; the shaded look draws its brows and lips with every
# term and the rest, most pixels, with the plain shader: the same colours, the highlight per vertex),
# the eyeballs, the eye sockets, the mouth's inside
CULLED = ("plain", "features", "eyes", "sockets", "mouth")
# px²: the coarse plain skin (its ears included), eyeballs and mouth's inside (render.scan_lod) and the coarse
# lashes (render.scan_look) are drawn
# while the full plain skin's median triangle would cover at most this at the head's nearest point
# (at 1280x720 the default camera gives 32 px² there, a median of 9 px² over the face as drawn; the
# gallery's 2x2 supersampled 480x480, 90 px²)
LOD_MAX_PX2 = 40.0
# where the draw calls hand the triangles set up so far to llvmpipe's rasterizer threads (glFlush:
# "half", after the first half of the plain skin; a group of CULLED or "lashes", before it), so they
# rasterise them while this thread sets up the rest: llvmpipe does the two one after the other
# within a flush, leaving a core idle while this thread sets up the frame's 13-15k triangles
FLUSH_AT = ("half", "eyes")


def dressing_of(model: Any) -> Any:
    """The scan dressing of a face model, or None for a face that is not the scanned head: the one
    the model carries (`model.scan_dressing`, e.g. a still pose of the scan's own shapes), else the
    one sim.face.scan makes for it."""
    own = getattr(model, "scan_dressing", None)
    if own is not None:
        return own
    rig = getattr(model, "rig", None)
    if rig is None or not str(getattr(rig, "name", "")).startswith("ict"):
        return None  # only the scanned head's rigs are named so (sim.face.scan.rig.scan_rig)
    from sim.face.scan.dressing import dressing_for

    return dressing_for(model)


def sealed_vertices(dressing: Any) -> np.ndarray | None:
    """(26719,) bool the teeth and gums as the face's dressing poses them (rigid with the skull or
    the jaw, behind the lips: tests/sim/test_scan_face.py), not the tongue, which `tongue_out`
    puts out between the lips; None for a dressing that does not say where its tongue is."""
    tongue = getattr(dressing, "tongue_idx", None)
    if tongue is None:
        return None
    from sim.face.scan.data import N_VERTICES, PARTS

    out = np.zeros(N_VERTICES, bool)
    out[PARTS["gums_tongue"][0]:PARTS["teeth"][1]] = True  # the two parts lie next to each other
    out[np.asarray(tongue, np.int64)] = False
    return out


def posed_scan(dressing: Any, softener: FoldSoftener | None, state: Any, contact: LidContact | None = None) -> np.ndarray:
    """The scan as drawn for `state`: posed by the dressing, the upper face's buckles softened
    (render.scan_soften) and the lids that sank into their eyeballs laid back onto them
    (sim.face.scan.lid_contact, as exports lay them; both in the head's own frame, before a head turn), turned with the head."""
    control = PoseControl(state)
    if softener is None and contact is None:
        return dressing.pose_turned(np.asarray(state.surface), control, state)
    posed = dressing.pose(np.asarray(state.surface), control)
    if softener is not None:
        posed = softener.soften(posed)
    if contact is not None:
        posed = contact.press(posed)
    turn = getattr(dressing, "turn_head", None)
    if turn is None:
        return posed
    from sim.face.turn import state_turn

    return turn(posed, *state_turn(state))


class ScanPoser:
    """The per-frame CPU half of drawing a scanned head, without OpenGL: the scan posed to a state
    and its rows (an export's simulating process makes them for its render processes)."""

    def __init__(self, dressing: Any) -> None:
        self.dressing = dressing
        self.look = ScanLook(np.asarray(dressing.rest, np.float64), dressing.eye_margins)
        self.maker = ScanRows(self.look)
        self.softener = FoldSoftener(self.look)
        self.seam = LidSeam(self.look)
        self.contact = LidContact(self.look.rest, self.look.lids, dressing)

    def rows(self, state: Any) -> np.ndarray:
        rows = self.maker.rows(posed_scan(self.dressing, self.softener, state, self.contact))
        return self.seam.shade(self.softener.shade(rows))


class ScanDraw:
    """GL objects and per-frame work for one scanned head. `rows(state)` poses the scan and makes
    the rows to upload (done in the simulating process of an export too); `draw(rows, ...)` draws."""

    def __init__(self, ctx: moderngl.Context, model: Any, dressing: Any) -> None:
        self.ctx = ctx
        self.dressing = dressing
        rest_scan = getattr(dressing, "rest", None)
        if rest_scan is None:  # the scan posed by the face at rest
            rest_state = model.rest_state()
            rest_scan = dressing.pose(np.asarray(rest_state.surface), PoseControl(rest_state))
        from sim.face.scan.dressing import eye_margins

        # the lids' margins from the simulated mesh (the scan's own shapes drawn in its place too)
        self.look = ScanLook(np.asarray(rest_scan, np.float64), eye_margins(model.mesh))
        self.coarse_tri = self.look.coarse_plain()
        # the mouth's lining, gums and tongue drawn from a coarser list with the coarse skin (render.scan_lod)
        self.inside_full, self.coarse_inside = self.look.coarse_inside()
        from render.scan_lod import coarse_eyes

        # the eyeballs' shells drawn from a coarser list with the coarse skin (render.scan_lod)
        self.coarse_eyes = np.ascontiguousarray(coarse_eyes(), np.int32)
        self.maker = ScanRows(self.look, np.concatenate([self.coarse_tri, self.coarse_eyes, self.coarse_inside]),
                              sealed_vertices(dressing), len(self.coarse_inside))
        self.softener: FoldSoftener | None = FoldSoftener(self.look)  # None: the buckles drawn as simulated
        self.seam: LidSeam | None = LidSeam(self.look)  # None: no shadow in the closing lids' seam
        # None: the lids drawn as simulated, sunk into the eyeballs where they close over the cornea (a
        # dressing of the scan's own shapes has no lid things, and its lids do not sink)
        self.contact: LidContact | None = LidContact(self.look.rest, self.look.lids, dressing) if hasattr(dressing, "lid_idx") else None
        from render.scan_lod import coarse_plain

        self.lod_error = coarse_plain()[1]  # cm: the coarse skin's largest distance from the full one
        plain = self.look.skin_split()["plain"]
        r = self.look.rest
        self._plain_area = float(np.median(0.5 * np.linalg.norm(np.cross(r[plain[:, 1]] - r[plain[:, 0]],
                                                                         r[plain[:, 2]] - r[plain[:, 0]]), axis=1)))
        self.progs = {k: ctx.program(vertex_shader=scan_shaders.scan_skin_source(k, vertex=True),
                                     fragment_shader=scan_shaders.scan_skin_source(k)) for k in (*KINDS, "PLAIN")}
        self.eye_prog = ctx.program(vertex_shader=scan_shaders.SCAN_EYE_VS, fragment_shader=scan_shaders.SCAN_EYE_FS)
        self.lash_prog = ctx.program(vertex_shader=scan_shaders.SCAN_LASH_VS,
                                     fragment_shader=scan_shaders.SCAN_LASH_FS)
        self.eye_prog["iris_angle"].value = IRIS_ANGLE
        self.eye_prog["pupil_angle"].value = PUPIL_ANGLE
        look = self.look
        n = len(look.rest)
        self.vbo = ctx.buffer(reserve=n * 28, dynamic=True)
        statics = {"in_albedo": (look.albedo, "3f"), "in_mat": (look.material, "4f"), "in_uv": (look.uv, "2f"),
                   "in_rest": (look.rest.astype(np.float32), "3f"), "in_angle": (look.gaze_angle, "1f")}
        bufs = {name: (ctx.buffer(np.ascontiguousarray(a, np.float32).tobytes()), fmt)
                for name, (a, fmt) in statics.items()}
        groups = {**look.groups, **look.skin_split()}
        # the culled groups share one index buffer, a slice each in drawing order (CULLED); a frame
        # whose rows were made here with the camera's position draws only the triangles of each
        # slice that may face the camera (see rows)
        self.cull_tri = np.ascontiguousarray(np.concatenate([groups[g] for g in CULLED]), np.int32)
        self.starts = np.cumsum([0, *(len(groups[g]) for g in CULLED)]).astype(np.int64)
        self.full = np.diff(self.starts).astype(np.int64)
        # the listing's groups (render.scan_rows: the scan's triangles, then the coarse plain skin's)
        # at each level of detail: the full skin, or its plain part from the coarse list
        own = look.group_of_triangles(CULLED)
        plain, mouth = CULLED.index("plain"), CULLED.index("mouth")
        eyes = CULLED.index("eyes")
        extra = len(self.coarse_tri) + len(self.coarse_eyes) + len(self.coarse_inside)
        self.group = np.concatenate([own, np.full(extra, -1, np.int8)])
        replaced = (own == plain) | (own == eyes)
        lo = len(look.groups["skin"])  # `triangles` are the groups in order, the skin's first
        replaced[lo:lo + len(self.inside_full)] |= self.inside_full
        self.group_coarse = np.concatenate([np.where(replaced, -1, own), np.full(len(self.coarse_tri), plain),
                                            np.full(len(self.coarse_eyes), eyes),
                                            np.full(len(self.coarse_inside), mouth)]).astype(np.int8)
        self.group_coarse_skin = np.concatenate([np.where((own == plain) | (own == eyes), -1, own),
                                                 np.full(len(self.coarse_tri), plain),
                                                 np.full(len(self.coarse_eyes), eyes),
                                                 np.full(len(self.coarse_inside), -1)]).astype(np.int8)
        # the mouth's slice at the coarse level, as the listing orders it: the teeth, then the coarse inside
        self.coarse_mouth = np.ascontiguousarray(np.concatenate([groups["mouth"][~self.inside_full],
                                                                 self.coarse_inside]), np.int32)
        self.kept = self.cull_tri.copy()
        self.counts = self.full.copy()
        self._facing_rows: np.ndarray | None = None  # the rows `kept` was made with
        self._made_rows: np.ndarray | None = None  # the rows last made here (the lips' test made with them)
        # what the index buffer holds: a listing (None), every triangle of a level (coarse, coarse inside)
        self._ibo_level: tuple[bool, bool] | None = (False, False)
        self._box = np.array([[x, y, z, 1.0] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
        lo, hi = self.bounds()
        self._box[:, :3] = lo + self._box[:, :3] * (hi - lo)
        self.ibo = ctx.buffer(self.cull_tri.tobytes(), dynamic=True)
        lashes = ctx.buffer(np.ascontiguousarray(groups["lashes"]).tobytes())
        # the lashes drawn with the coarse plain skin: fewer triangles over the same vertices
        few = ctx.buffer(np.ascontiguousarray(look.coarse_lashes()).tobytes())
        self._gl: list[Any] = [self.vbo, *(b for b, _ in bufs.values()), self.ibo, lashes, few]
        self.vaos = {kind: self._vao(prog, bufs, self.ibo) for kind, prog in self.progs.items()}
        self.eye_vao = self._vao(self.eye_prog, bufs, self.ibo)
        self.lash_vao = self._vao(self.lash_prog, bufs, lashes)
        self.coarse_lash_vao = self._vao(self.lash_prog, bufs, few)
        self._gl += [*self.vaos.values(), self.eye_vao, self.lash_vao, self.coarse_lash_vao, *self.progs.values(),
                     self.eye_prog, self.lash_prog]
        self.mouth_drawn = False
        # (): the scan's triangles set up in one pass (the same pixels), as with no rasterizer threads
        self.flush_at: tuple[str, ...] = FLUSH_AT if threaded_rasterizer() else ()
        self.split_skin = True  # False: the whole skin with every term (the highlight per pixel: slower)
        self.cull_on_cpu = True  # False: every triangle to OpenGL, which culls them (the same pixels)
        self.cull_unseen = True  # False: keep the triangles that cover no pixel or lie hidden inside the head (the same pixels)
        self.lod = True  # False: the full skin (and lashes) at any size on screen
        self.lod_inside = True  # False: the full lining, gums and tongue with the coarse skin
        self.coarse = False  # this frame's level: the plain skin from the coarse list
        self._level_key: tuple[bytes, tuple[int, ...], bool] | None = None  # what `coarse` was chosen for
        self.left_out: set[str] = set()  # groups (of CULLED, or "lashes") not drawn: what each costs, measured

    def _vao(self, prog: moderngl.Program, bufs: dict[str, tuple[moderngl.Buffer, str]],
             ibo: moderngl.Buffer) -> moderngl.VertexArray:
        names = [a for a in ("in_pos", "in_normal", "in_fold") if a in prog]
        fmt = " ".join(("3f" if a != "in_fold" else "1f") if a in names else
                       ("3x4" if a != "in_fold" else "1x4") for a in ("in_pos", "in_normal", "in_fold"))
        attrs = [(self.vbo, fmt, *names)]
        attrs += [(b, f, name) for name, (b, f) in bufs.items() if name in prog]
        return self.ctx.vertex_array(prog, attrs, ibo)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The box a camera frames: the head and the top of the neck."""
        from sim.face.scan.data import PARTS

        rest = self.look.rest
        v = rest[:PARTS["head_neck"][1]]
        face = rest[:PARTS["face"][1]]
        front = face[(np.abs(face[:, 0]) < 1.5) & (face[:, 2] > face[:, 2].max() - 3.5)]
        seen = v[v[:, 1] > front[:, 1].min() - 2.0]  # down to a little below the chin
        return seen.min(axis=0), seen.max(axis=0)

    def choose_level(self, mvp: np.ndarray, size: tuple[int, int]) -> bool:
        """The level of detail for a frame drawn with the camera's `mvp` (projection @ view,
        row-major) into a picture `size` pixels wide and high: the coarse plain skin while the
        full plain skin's triangles are small on screen (their median area at the head's nearest
        point at most LOD_MAX_PX2), else the full skin."""
        m = np.asarray(mvp, np.float64)
        key = (m.tobytes(), tuple(size), self.lod)
        if key == self._level_key:
            return self.coarse
        self._level_key = key
        w = float((self._box @ m[3]).min())
        px_per_cm = 0.5 * size[1] * float(np.linalg.norm(m[1, :3])) / w if w > 1e-6 else np.inf
        self.coarse = bool(self.lod and self._plain_area * px_per_cm**2 <= LOD_MAX_PX2)
        return self.coarse

    def rows(self, state: Any, eye: np.ndarray | None = None, mvp: np.ndarray | None = None,
             size: tuple[int, int] | None = None) -> np.ndarray:
        """(26719, 7) float32 rows x y z nx ny nz fold of the scan posed to `state` (the same array
        every call); given `eye`, the camera's position in model space, also which triangles may
        face it, for the next `draw` of these rows, and given the camera's `mvp` (projection @ view,
        row-major) and the picture's `size` too, without the triangles that cover no pixel or that
        the skin hides (the eyes' and the mouth's, seen only through their openings), unless
        `cull_unseen` is False (the same pixels)."""
        posed = posed_scan(self.dressing, self.softener, state, self.contact)
        if eye is None or not self.cull_on_cpu:
            self._facing_rows = None
            self._made_rows = self._shaded(self.maker.rows(posed))
            return self._made_rows
        if not self.cull_unseen:
            mvp = None
        group = self.group if not self.coarse else self.group_coarse if self.lod_inside else self.group_coarse_skin
        rows = self._shaded(self.maker.rows(posed, eye, group, self.starts, self.kept, self.counts, mvp, size))
        self._facing_rows = self._made_rows = rows
        return rows

    def screen_box(self, rows: np.ndarray) -> np.ndarray | None:
        """(4,) pixels x0 y0 x1 y1 (y up; infinite when a vertex lies behind the camera): the box on
        screen of every vertex of `rows`, all the scan can draw on, if `rows` was last made here with
        the camera and the picture's size; else None."""
        if rows is not self._facing_rows or np.isnan(self.maker.box).any():
            return None
        return self.maker.box.copy()

    def _shaded(self, rows: np.ndarray) -> np.ndarray:
        if self.softener is not None:
            rows = self.softener.shade(rows)
        return rows if self.seam is None else self.seam.shade(rows)

    def _indices(self, rows: np.ndarray, groups: int) -> None:
        """The index buffer's first `groups` slices for these rows: the triangles that may face the
        camera when `rows` made them, else every triangle of this frame's level."""
        if rows is self._facing_rows:
            for g in range(groups):
                lo = int(self.starts[g])
                self.ibo.write(self.kept[lo:lo + int(self.counts[g])], offset=lo * 12)
            self._ibo_level = None
            return
        inside = self.coarse and self.lod_inside
        if self._ibo_level != (self.coarse, inside):
            self.ibo.write(self.cull_tri.tobytes())
            if self.coarse:  # the plain skin's slice comes first
                self.ibo.write(self.coarse_tri.tobytes())
                self.ibo.write(self.coarse_eyes.tobytes(), offset=int(self.starts[CULLED.index("eyes")]) * 12)
            if inside:
                self.ibo.write(self.coarse_mouth.tobytes(), offset=int(self.starts[CULLED.index("mouth")]) * 12)
            self._ibo_level = (self.coarse, inside)
        self.counts[:] = self.full
        if self.coarse:
            self.counts[CULLED.index("plain")] = len(self.coarse_tri)
            self.counts[CULLED.index("eyes")] = len(self.coarse_eyes)
        if inside:
            self.counts[CULLED.index("mouth")] = len(self.coarse_mouth)

    def _render(self, vao: moderngl.VertexArray, group: str, lo: float = 0.0, hi: float = 1.0) -> None:
        """Draw the group's listed triangles (from fraction `lo` of them to `hi`)."""
        g = CULLED.index(group)
        n = int(self.counts[g])
        a, b = int(lo * n), int(hi * n)
        if b > a and group not in self.left_out:
            vao.render(moderngl.TRIANGLES, vertices=3 * (b - a), first=3 * (int(self.starts[g]) + a))

    def draw(self, rows: np.ndarray, kind: str, mvp: bytes, view_m: bytes, heat_scale: float) -> None:
        """Draw the posed scan (its rows) in look `kind`."""
        self.vbo.write(rows)
        # the lips' test made with these rows (render.scan_rows), else made here
        self.mouth_drawn = (not self.maker.closed if rows is self._made_rows
                            else self.look.mouth_open(rows[:, :3]))
        self._made_rows = None
        self._indices(rows, len(CULLED) if self.mouth_drawn else len(CULLED) - 1)
        self._facing_rows = None
        prog = self.progs[kind]
        for p in (prog, self.eye_prog, *((self.progs["PLAIN"],) if kind == "SKIN" else ())):
            p["mvp"].write(mvp)
            p["view"].write(view_m)
        self.lash_prog["mvp"].write(mvp)
        if kind == "HEAT":
            prog["heat_scale"].value = float(heat_scale)
        ctx = self.ctx
        ctx.enable(moderngl.CULL_FACE)
        plain = self.vaos["PLAIN" if kind == "SKIN" and self.split_skin else kind]
        if "half" in self.flush_at:  # Morton order: each half of the plain skin is a region of the face
            self._render(plain, "plain", 0.0, 0.5)
            flush()
            self._render(plain, "plain", 0.5, 1.0)
        else:
            self._render(plain, "plain")
        for vao, group in ((self.vaos[kind], "features"), (self.eye_vao, "eyes"), (self.vaos[kind], "sockets"),
                           (self.vaos[kind], "mouth")):
            if group in self.flush_at:
                flush()
            if group != "mouth" or self.mouth_drawn:
                self._render(vao, group)
        ctx.disable(moderngl.CULL_FACE)
        if "lashes" in self.flush_at:
            flush()
        if kind == "SKIN" and "lashes" not in self.left_out:  # hair over the skin: blended, without depth writes
            fbo = ctx.fbo
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ZERO, moderngl.ONE)
            fbo.depth_mask = False
            (self.coarse_lash_vao if self.coarse else self.lash_vao).render(moderngl.TRIANGLES)
            fbo.depth_mask = True
            ctx.disable(moderngl.BLEND)

    def release(self) -> None:
        self.maker.close()
        for obj in reversed(self._gl):
            obj.release()
        self._gl = []
