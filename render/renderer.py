"""`FaceRenderer`: draws a face state with moderngl into whatever framebuffer is bound, so the glfw
window and the EGL offscreen renderer share every pixel of it. `populate(model)` uploads what never
changes; `draw(state)` uploads the surface and its normals and nothing else that is per-vertex."""

from __future__ import annotations

from typing import Any, NamedTuple

import moderngl
import numpy as np

from render import shaders
from render.camera import OrbitCamera
from render.hud import HudInfo, HudRenderer
from render.meshdata import (HAIR, SKIN, Cavity, brow_coords, MuscleLines, eye_rotation, face_frame, head_turn,
                             skin_tint, spatial_order,
                             surface_rows, unique_edges, uv_sphere)
from render.pipeline import flush, steer_rasterizer, threaded_rasterizer
from render.trails import TrailHistory
from sim.face.turn import is_turned, turn_eye
from sim.gaze_lids import PITCH_MAX as EYE_PITCH_MAX
from sim.gaze_lids import YAW_MAX as EYE_YAW_MAX
from sim.gaze_lids import eye_yaws

VIEWS = ("shaded", "wireframe", "muscles", "trails", "heat")
# px: the HUD goes first (FaceRenderer.hud_first) while the scanned head's box on screen in the frame
# before, this much wider, leaves its panels free, and stays first while this frame's box, HUD_CLEAR_PX
# wider (the rasterizer's rounding of a corner is 1/256 px), does
HUD_FIRST_MARGIN_PX = 24.0
HUD_CLEAR_PX = 2.0
ANTIALIAS = ("fxaa", "none")
BACKGROUND = (0.29, 0.295, 0.305)  # neutral grey, display (gamma-encoded) values
MAX_TRAIL_NODES = 4000
STILL_PATH_CM = 0.02  # nodes that moved less than this over the trail window count as motionless
MOUTH_RIM = (0.20, 0.035, 0.03)
IMPORTED = "imported"  # FaceRig.presets of a head brought in by sim.face.transfer ("imported", "imported-2", ...)
SOCKET_RIM = (0.05, 0.03, 0.03)


def face_cavities(mesh: Any, rest: np.ndarray, base: int = 0, dentition: bool = False
                  ) -> tuple[list[Cavity], list[np.ndarray], list[np.ndarray], list[np.ndarray],
                             list[np.ndarray], int]:
    """The dark pockets behind the mouth and the eye openings of a face mesh (those whose loop has
    three nodes or more), as drawn in one buffer: (cavities, their triangles numbered from `base`,
    depth, teeth share (the mouth's only), rim colour per vertex, the next free vertex number).
    `dentition`: the mouth shows teeth right behind its lips, above and below (`Cavity`)."""
    cavities: list[Cavity] = []
    tris, depth, teeth, rims = [], [], [], []
    for loop, rim in [(mesh.mouth_loop, MOUTH_RIM)] + [(lp, SOCKET_RIM) for lp in mesh.eye_loops]:
        if len(loop) < 3:
            continue
        cav = Cavity(loop, rest, dentition=dentition and rim == MOUTH_RIM)
        cavities.append(cav)
        tris.append(cav.triangles + base)
        depth.append(cav.depth)
        teeth.append(cav.teeth * (1.0 if rim == MOUTH_RIM else 0.0))
        rims.append(np.tile(np.asarray(rim, np.float32), (cav.n_vertices, 1)))
        base += cav.n_vertices
    return cavities, tris, depth, teeth, rims, base


def affordable_antialias(ctx: moderngl.Context) -> str:
    """"fxaa" on a GPU; "none" on a software rasterizer, where the full-screen FXAA pass alone
    costs several frames' budget at 720p (measured in benchmarks/render_frame.py)."""
    name = str(ctx.info.get("GL_RENDERER", "")).lower()
    return "none" if any(w in name for w in ("llvmpipe", "softpipe", "swrast", "software")) else "fxaa"


def _mat(m: np.ndarray) -> bytes:
    """Row-major numpy matrix -> column-major float32 bytes for a GLSL uniform."""
    return np.ascontiguousarray(m.T, dtype=np.float32).tobytes()


class Prepared(NamedTuple):
    """A frame's CPU half made by `FaceRenderer.prepare`: the state, its rows (None: the state
    brings its own), what they were made for, and the renderer's count of rows made then."""

    state: Any
    rows: np.ndarray | None
    key: Any
    made: int


class FaceRenderer:
    """Renders one face model. Attributes a caller may change between frames: `view` (one of
    VIEWS), `camera` (OrbitCamera), `antialias` ("fxaa" | "none"), `supersample` (n: render n x n
    samples per pixel, for offline export), `heat_scale` (cm of displacement at the top of the
    heat colour map), `trails` (TrailHistory, recorded from the states drawn).

    With antialias "none" and no supersampling the scene is drawn straight into the target; FXAA
    and supersampling render into an internal framebuffer and resolve with one full-screen pass,
    which on llvmpipe costs more than the face itself (see docs/rendering.md)."""

    def __init__(self, ctx: moderngl.Context, view: str = "shaded", antialias: str = "none",
                 supersample: int = 1) -> None:
        self.ctx = ctx
        self.view = view
        self.antialias = antialias
        self.supersample = supersample
        self.camera = OrbitCamera()
        self.heat_scale = 0.8
        self.model: Any = None
        self.trails: TrailHistory | None = None
        self._made = 0  # frames' rows made (prepare, draw): a prepared frame is used only if it is the last
        self.skin_progs = {kind: ctx.program(vertex_shader=shaders.skin_source(kind, vertex=True),
                                             fragment_shader=shaders.skin_source(kind))
                           for kind in ("SKIN", "CLAY", "HEAT")}
        self.scalp_prog = ctx.program(vertex_shader=shaders.skin_source("SCALP", vertex=True),
                                      fragment_shader=shaders.skin_source("SCALP"))
        from sim.face.head import HAIR_EDGE

        self.scalp_prog["hair_albedo"].value = tuple(float(c) for c in HAIR)
        self.scalp_prog["hair_edge"].value = HAIR_EDGE
        self.eye_prog = ctx.program(vertex_shader=shaders.EYE_VS, fragment_shader=shaders.EYE_FS)
        self.cavity_prog = ctx.program(vertex_shader=shaders.CAVITY_VS,
                                       fragment_shader=shaders.CAVITY_FS)
        self.line_prog = ctx.program(**shaders.line_program_sources())
        self.thick_prog = ctx.program(**shaders.line_program_sources(thick=True))
        self.trail_prog = ctx.program(**shaders.line_program_sources(trail=True))
        self.point_prog = ctx.program(vertex_shader=shaders.POINT_VS, fragment_shader=shaders.POINT_FS)
        self._post: dict[str, tuple[moderngl.Program, moderngl.VertexArray]] = {}
        widths = ctx.info.get("GL_ALIASED_LINE_WIDTH_RANGE", (1.0, 1.0))
        self._max_line_width = float(widths[1]) if isinstance(widths, (tuple, list)) else 1.0
        self.hud = HudRenderer(ctx)
        self.scan: Any = None  # render.scan_draw.ScanDraw when the model is the scanned head
        self._scene: tuple[tuple[int, int], moderngl.Framebuffer, moderngl.Texture,
                           moderngl.Renderbuffer] | None = None
        self._gl: list[Any] = []
        # clear the frame first, flushed (render.pipeline.flush), so llvmpipe's rasterizer threads
        # clear its tiles while this thread makes the frame's CPU half (the scanned head's posing
        # and rows) and sets up its triangles; False: clear just before the draw calls (the same
        # pixels), as with no rasterizer threads (LP_NUM_THREADS=0), where it would gain nothing
        self.clear_first = threaded_rasterizer()
        # with clear_first, the scanned head's HUD composited with the clear, so the rasterizer's
        # threads composite it while this thread poses the scan, when the scan's box on screen (made
        # with its triangles' listing) leaves the HUD's panels free: the same pixels. Guessed from
        # the frame before (its box HUD_FIRST_MARGIN_PX wider), and checked against this frame's:
        # where the scan reaches a panel, the frame is cleared again and the HUD composited last
        self.hud_first = True
        self.hud_was_first = False  # whether the last frame drawn composited its HUD first
        # while this thread draws, llvmpipe's rasterizer threads kept off its CPU, and as it returns each
        # moved to a CPU of its own and freed, when the machine has a core to spare:
        # render.pipeline.steer_rasterizer. False: left to the OS (the same pixels)
        self.steer = True
        self._scan_box: tuple[np.ndarray, tuple[int, int]] | None = None  # the last frame's, with its size

    @property
    def antialias(self) -> str:
        return self._antialias

    @antialias.setter
    def antialias(self, mode: str) -> None:
        if mode not in ANTIALIAS:
            raise ValueError(f"unknown antialias {mode!r}; choose one of {', '.join(ANTIALIAS)}")
        self._antialias = mode

    @property
    def view(self) -> str:
        return self._view

    @view.setter
    def view(self, name: str) -> None:
        if name not in VIEWS:
            raise ValueError(f"unknown view {name!r}; choose one of {', '.join(VIEWS)}")
        self._view = name

    # -- setup ------------------------------------------------------------------------------------
    def populate(self, model: Any) -> None:
        """Upload the model's static data and build the per-frame index arrays (once per model)."""
        self._release_model()
        ctx = self.ctx
        mesh = model.mesh
        rest = np.asarray(model.rest, np.float32)
        n = len(rest)
        tris = np.asarray(model.triangles, np.int32)
        self.model = model
        self.normals = surface_rows(model)  # the mask's rows, and the held head's after them
        self.camera.fit(*face_frame(mesh, rest))
        g = self._gl
        # positions and normals interleaved in one buffer, one write per frame
        self.pos_vbo = ctx.buffer(reserve=n * 24, dynamic=True)
        tint = skin_tint(mesh)
        col_vbo = ctx.buffer(tint.tobytes())
        rest_vbo = ctx.buffer(rest.tobytes())
        brow_vbo = ctx.buffer(brow_coords(mesh).tobytes())
        tri_ibo = ctx.buffer(spatial_order(tris, rest).astype(np.int32).tobytes())
        edge_ibo = ctx.buffer(unique_edges(tris).tobytes())
        g += [self.pos_vbo, col_vbo, rest_vbo, brow_vbo, tri_ibo, edge_ibo]
        self.skin_vaos = {}
        for kind, prog in self.skin_progs.items():
            pn = [a for a in ("in_pos", "in_normal") if a in prog]
            pn_fmt = "3f 3f" if len(pn) == 2 else ("3f 3x4" if pn == ["in_pos"] else "3x4 3f")
            attrs = [(self.pos_vbo, pn_fmt, *pn)] if pn else []
            attrs += [(col_vbo, "3f", "in_color"), (rest_vbo, "3f", "in_rest"),
                     (brow_vbo, "2f", "in_brow")]
            self.skin_vaos[kind] = ctx.vertex_array(
                prog, [a for a in attrs if a[0] is self.pos_vbo or a[2] in prog], tri_ibo)
        self.edge_vao = ctx.vertex_array(self.line_prog, [(self.pos_vbo, "3f 3x4", "in_pos")], edge_ibo)
        self._populate_head(model, tint)
        sphere, sphere_tris = uv_sphere(12, 20)
        sph_vbo, sph_ibo = ctx.buffer(sphere.tobytes()), ctx.buffer(sphere_tris.tobytes())
        self.eye_vao = ctx.vertex_array(self.eye_prog, [(sph_vbo, "3f", "in_pos")], sph_ibo)
        g += [sph_vbo, sph_ibo, *self.skin_vaos.values(), self.edge_vao, self.eye_vao]
        # every cavity in one buffer and one draw call: rim colour and teeth per vertex
        # an imported head has no teeth of its own: its mouth's pocket draws them
        self.cavities, tris, depth, teeth, rims, base = face_cavities(
            mesh, rest, dentition=str(getattr(model.rig, "presets", "")).startswith(IMPORTED))
        self.cavity_vao = None
        if self.cavities:
            self.cavity_vbo = ctx.buffer(reserve=base * 12, dynamic=True)
            bufs = [ctx.buffer(np.concatenate(a).astype(np.float32).tobytes())
                    for a in (depth, teeth, rims)]
            ibo = ctx.buffer(np.concatenate(tris).astype(np.int32).tobytes())
            self.cavity_vao = ctx.vertex_array(self.cavity_prog, [
                (self.cavity_vbo, "3f", "in_pos"), (bufs[0], "1f", "in_depth"),
                (bufs[1], "1f", "in_teeth"), (bufs[2], "3f", "in_rim")], ibo)
            g += [self.cavity_vbo, *bufs, ibo, self.cavity_vao]
        self._populate_scan(model)
        self.muscles = MuscleLines(model.rig, rest)
        self.muscle_vbo = ctx.buffer(reserve=max(len(self.muscles), 1) * 12, dynamic=True)
        self.muscle_vao = ctx.vertex_array(self.thick_prog, [(self.muscle_vbo, "3f", "in_pos")])
        g += [self.muscle_vbo, self.muscle_vao]
        self._populate_trails(n)

    def _populate_scan(self, model: Any) -> None:
        """The scanned head (render.scan_draw), drawn in place of the model's own skin, eyes and
        cavities when the model has a scan dressing; the overlays (wireframe, muscles, trails)
        stay on the simulated surface."""
        from render.scan_draw import ScanDraw, dressing_of

        dressing = dressing_of(model)
        if dressing is None:
            return
        self.scan = ScanDraw(self.ctx, model, dressing)
        self._gl.append(self.scan)
        self.cavity_vao = None
        self.cavities = []
        self.camera.fit(*self.scan.bounds())

    def _populate_head(self, model: Any, tint: np.ndarray) -> None:
        """The held head around the default face (sim.face.head: cranium, ears, neck), stitched to
        the mask's border: colours (skin, the mask's own tint on the join, hair on the scalp) and
        rest places uploaded once, positions and normals each frame after the mask's (the rows
        of `self.normals`); drawn with the skin programs."""
        self.head_vaos: dict[str, moderngl.VertexArray] = {}
        shell = self.normals.shell
        if shell is None:
            return
        ctx = self.ctx
        v = shell.vertices.astype(np.float32)
        col = np.tile(SKIN, (len(v), 1)).astype(np.float32)  # the hair is the SCALP shader's
        col[shell.ring] = tint[shell.ring_mask]
        rest = v.copy()
        rest[shell.ring] = np.asarray(model.rest, np.float32)[shell.ring_mask]
        self.head_vbo = ctx.buffer(reserve=len(v) * 24, dynamic=True)
        bufs = [self.head_vbo, ctx.buffer(col.tobytes()), ctx.buffer(rest.tobytes()),
                ctx.buffer(shell.hair_coords.astype(np.float32).tobytes()),  # the SCALP's in_brow
                ctx.buffer(spatial_order(shell.triangles, v).astype(np.int32).tobytes())]
        pos, col_b, rest_b, brow_b, ibo = bufs
        for kind, prog in {**self.skin_progs, "SKIN": self.scalp_prog}.items():
            pn = [a for a in ("in_pos", "in_normal") if a in prog]
            pn_fmt = "3f 3f" if len(pn) == 2 else ("3f 3x4" if pn == ["in_pos"] else "3x4 3f")
            attrs = [(pos, pn_fmt, *pn)] if pn else []
            attrs += [(col_b, "3f", "in_color"), (rest_b, "3f", "in_rest"), (brow_b, "2f", "in_brow")]
            self.head_vaos[kind] = ctx.vertex_array(prog, [a for a in attrs if a[0] is pos or a[2] in prog], ibo)
        self._gl += [*bufs, *self.head_vaos.values()]
        lo, hi = self.camera.lo, self.camera.hi
        seen = v[v[:, 1] > lo[1] - 3.0]  # the head and the top of the neck
        self.camera.fit(np.minimum(lo, seen.min(axis=0)), np.maximum(hi, seen.max(axis=0)))

    def _populate_trails(self, n: int) -> None:
        """GPU ring of trail samples: each new sample overwrites one slot; segments between
        consecutive slots are fixed index pairs, and the shader drops the pair across the ring's
        seam. Large meshes draw trails for an even subset of nodes (a 12k-node tangle reads worse)."""
        self.trails = TrailHistory(n)
        k = self.trails.capacity
        nodes = np.arange(n)
        if n > MAX_TRAIL_NODES:
            nodes = np.linspace(0, n - 1, MAX_TRAIL_NODES).astype(int)
        self.trail_nodes = len(nodes)
        slots = np.arange(k)
        a = (slots[:, None] * n + nodes[None, :]).ravel()
        b = (((slots + 1) % k)[:, None] * n + nodes[None, :]).ravel()
        pairs = np.stack([a, b], axis=1).astype(np.int32)
        self.trail_vbo = self.ctx.buffer(reserve=k * n * 12)
        trail_ibo = self.ctx.buffer(pairs.tobytes())
        self.trail_vao = self.ctx.vertex_array(self.trail_prog, [(self.trail_vbo, "3f", "in_pos")],
                                               trail_ibo)
        self.path_vbo = self.ctx.buffer(reserve=n * 4, dynamic=True)
        self.dot_vao = self.ctx.vertex_array(self.point_prog, [
            (self.pos_vbo, "3f 3x4", "in_pos"), (self.path_vbo, "1f", "in_path")])
        self._gl += [self.trail_vbo, trail_ibo, self.trail_vao, self.path_vbo, self.dot_vao]

    def _scene_target(self, w: int, h: int) -> tuple[moderngl.Framebuffer, moderngl.Texture]:
        """The internal framebuffer the 3D passes render into (resized lazily)."""
        if self._scene is None or self._scene[0] != (w, h):
            if self._scene is not None:
                for obj in self._scene[1:]:
                    obj.release()
            tex = self.ctx.texture((w, h), 4)
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            depth = self.ctx.depth_renderbuffer((w, h))
            fbo = self.ctx.framebuffer([tex], depth)
            self._scene = ((w, h), fbo, tex, depth)
        return self._scene[1], self._scene[2]

    # -- per frame --------------------------------------------------------------------------------
    def prepare(self, state: Any, size: tuple[int, int]) -> Prepared:
        """The CPU half of drawing `state` into a viewport `size` = (w, h) pixels: the scanned
        head posed and its rows and triangle lists made (or a mesh face's rows), no OpenGL call,
        so it may run while llvmpipe still rasterises the frame before (render.pipeline).
        `draw(state, prepared=...)` then uses it if nothing was made or changed since (the
        camera, the size, another frame's rows); else it makes its own: the same pixels."""
        w, h = int(size[0]), int(size[1])
        ss = max(1, int(self.supersample))
        self._made += 1
        if self.scan is not None:
            if getattr(state, "scan_rows", None) is not None:
                return Prepared(state, None, None, self._made)
            view_m, mvp = self._matrices(w / max(h, 1))
            self.scan.choose_level(mvp, (w * ss, h * ss))
            eye = np.linalg.inv(view_m)[:3, 3]
            rows = self.scan.rows(state, eye, mvp, (w * ss, h * ss))
            return Prepared(state, rows, (self._camera_key, (w, h), ss), self._made)
        if getattr(state, "interleaved", None) is not None:
            return Prepared(state, None, None, self._made)
        return Prepared(state, self._mesh_rows(state), None, self._made)

    def _mesh_rows(self, state: Any) -> np.ndarray:
        """A mesh face's rows (x y z nx ny nz per vertex) from its simulated surface, head turned."""
        return self.normals.interleaved(np.ascontiguousarray(state.surface, dtype=np.float32), head_turn(state))

    def _prepared_rows(self, prepared: Prepared | None, state: Any, w: int, h: int, ss: int) -> np.ndarray | None:
        """The rows `prepared` made for this frame, or None when they are not this frame's."""
        if prepared is None or prepared.rows is None or prepared.state is not state or prepared.made != self._made:
            return None
        if self.scan is not None:
            self._matrices(w / max(h, 1))
            if prepared.key != (self._camera_key, (w, h), ss):
                return None
        return prepared.rows

    def draw(self, state: Any, hud: HudInfo | None = None, record: bool = True,
             prepared: Prepared | None = None) -> None:
        """Draw `state` into the bound framebuffer's viewport; record its surface for the trails.
        `prepared`: this frame's CPU half made beforehand by `prepare` (the same pixels)."""
        if self.model is None or self.trails is None:
            raise RuntimeError("FaceRenderer.draw before populate(model)")
        if not self.steer:
            self._draw(state, hud, record, prepared)
            return
        steer_rasterizer(True)
        try:
            self._draw(state, hud, record, prepared)
        finally:
            steer_rasterizer(False)

    def _draw(self, state: Any, hud: HudInfo | None, record: bool, prepared: Prepared | None) -> None:
        ctx = self.ctx
        target = ctx.fbo
        if target is None:
            raise RuntimeError("FaceRenderer.draw needs a bound framebuffer (fbo.use())")
        vx, vy, w, h = target.viewport
        ss = max(1, int(self.supersample))
        ready = self._prepared_rows(prepared, state, w, h, ss)
        self._made += 1
        post = self._post_program(ss)
        first = self.clear_first
        hud_first = False
        if first:  # the rasterizer's threads clear the tiles while this thread makes the CPU half
            fbo, tex = self._clear(target, post, w, h, ss)
            if hud is not None and self._hud_may_go_first(post, (w, h)):
                self._draw_hud(hud, w, h, state)
                hud_first = True
            flush()
        rows = getattr(state, "interleaved", None)  # x y z nx ny nz rows made elsewhere (an export's
        n = self.normals.n  # render process is handed them with the frame: see puppet.export.video)
        if self.scan is not None:
            scan_rows = getattr(state, "scan_rows", None)
            view_m, mvp = self._matrices(w / max(h, 1))
            self.scan.choose_level(mvp, (w * ss, h * ss))
            if scan_rows is None:
                scan_rows = ready
            if scan_rows is None:  # posed here: the camera's position lets it leave back faces out
                eye = np.linalg.inv(view_m)[:3, 3]
                scan_rows = self.scan.rows(state, eye, mvp, (w * ss, h * ss))
            self._scan_rows = scan_rows
            box = self.scan.screen_box(scan_rows) if ss == 1 else None
            self._scan_box = None if box is None else (box, (w, h))
            if hud_first and (box is None or self.hud.covers(_top_down(box, h), HUD_CLEAR_PX)):
                fbo, tex = self._clear(target, post, w, h, ss)  # the scan reaches a panel: the HUD goes last
                hud_first = False
            surface = np.ascontiguousarray(state.surface, dtype=np.float32)
            if self.view in ("wireframe", "muscles", "trails"):  # the overlays' surface, no normals
                rows = self._overlay_rows(surface)
            else:
                rows = None
        elif rows is None:
            rows = ready
            if rows is None:
                rows = self._mesh_rows(state)
            surface = np.ascontiguousarray(rows[:n, :3])  # as drawn: the head turned on the neck
        else:
            surface = np.ascontiguousarray(rows[:n, :3])
        if rows is not None:
            self.pos_vbo.write(rows[:n])  # positions + normals, one upload (and one for the head)
        if self.head_vaos and rows is not None:
            self.head_vbo.write(rows[n:])
        if record or self.trails.count == 0:
            self.trails.push(surface, getattr(state, "time", None))
        view_m, mvp = self._matrices(w / max(h, 1))
        if not first:
            fbo, tex = self._clear(target, post, w, h, ss)
        ctx.enable_only(moderngl.DEPTH_TEST)
        self._draw_scene(state, surface, mvp, view_m, (w * ss, h * ss), ss)
        ctx.enable_only(moderngl.NOTHING)
        if post is not None and tex is not None:
            target.use()
            target.viewport = (vx, vy, w, h)
            tex.use(0)
            prog, vao = post
            prog["scene"].value = 0
            if "texel" in prog:
                prog["texel"].value = (1.0 / w, 1.0 / h)
            vao.render(moderngl.TRIANGLES, vertices=3)
        if hud is not None and not hud_first:
            self._draw_hud(hud, w, h, state)
        self.hud_was_first = hud_first

    def _draw_hud(self, hud: HudInfo, w: int, h: int, state: Any) -> None:
        if self.view == "heat":
            hud = HudInfo(**{**hud.__dict__, "lines": hud.lines + [
                f"heat: blue = still, red ≥ {self.heat_scale:g} cm from rest"]})
        self.hud.draw(hud, (w, h), view=self.view, age=getattr(state, "age", None))

    def _hud_may_go_first(self, post: Any, size: tuple[int, int]) -> bool:
        """Whether to composite the HUD with the clear: the scanned head drawn straight into the
        target in a view without overlays, and its box on screen in the frame before, at the same
        size and HUD_FIRST_MARGIN_PX wider, clear of the HUD's panels (this frame's box is checked
        once its triangles are listed)."""
        last = self._scan_box
        if (not self.hud_first or self.scan is None or post is not None or self.view not in ("shaded", "heat")
                or last is None or last[1] != size):
            return False
        return not self.hud.covers(_top_down(last[0], size[1]), HUD_FIRST_MARGIN_PX)

    def _clear(self, target: moderngl.Framebuffer, post: Any, w: int, h: int,
               ss: int) -> tuple[moderngl.Framebuffer, moderngl.Texture | None]:
        """Clear the frame's framebuffer (the target, or the scene's for a post pass) and bind it."""
        vx, vy = target.viewport[:2]
        if post is None:  # straight into the target: no extra full-screen pass
            whole = (vx, vy, w, h) == (0, 0, *target.size)  # a scissored clear is slow on llvmpipe
            target.clear(*BACKGROUND, 1.0, depth=1.0, viewport=None if whole else (vx, vy, w, h))
            return target, None
        fbo, tex = self._scene_target(w * ss, h * ss)
        fbo.use()
        fbo.clear(*BACKGROUND, 1.0, depth=1.0)
        return fbo, tex

    def _overlay_rows(self, surface: np.ndarray) -> np.ndarray:
        buf = getattr(self, "_overlay_buf", None)
        if buf is None or len(buf) != len(surface):
            buf = self._overlay_buf = np.zeros((len(surface), 6), np.float32)
        buf[:, :3] = surface
        return buf

    def _matrices(self, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        """(view, projection @ view), recomputed only when the camera or the aspect changes."""
        cam = self.camera
        key = (aspect, cam.yaw, cam.pitch, cam.scale, cam.fov_y, cam.margin, cam.lo.tobytes(),
               cam.hi.tobytes())
        if getattr(self, "_camera_key", None) != key:
            view_m, proj = cam.matrices(aspect)
            self._camera_key, self._camera_mats = key, (view_m, proj @ view_m)
        return self._camera_mats

    def _post_program(self, ss: int) -> tuple[moderngl.Program, moderngl.VertexArray] | None:
        """The pass from the internal framebuffer to the target, or None to draw directly."""
        if ss > 1:
            key = f"resolve{ss}"
            src = shaders.resolve_source(ss)
        elif self.antialias == "fxaa":
            key, src = "fxaa", shaders.FXAA_FS
        else:
            return None
        if key not in self._post:
            prog = self.ctx.program(vertex_shader=shaders.POST_VS, fragment_shader=src)
            self._post[key] = (prog, self.ctx.vertex_array(prog, []))
        return self._post[key]

    def _draw_scene(self, state: Any, surface: np.ndarray, mvp: np.ndarray, view_m: np.ndarray,
                    size: tuple[int, int], ss: int) -> None:
        view = self.view
        kind = {"muscles": "CLAY", "trails": "CLAY", "heat": "HEAT"}.get(view, "SKIN")
        skin = self.skin_progs[kind]
        for prog in (skin, self.eye_prog):
            prog["mvp"].write(_mat(mvp))
            prog["view"].write(_mat(view_m))
        if self.scan is not None:
            self.scan.draw(self._scan_rows, kind, _mat(mvp), _mat(view_m), self.heat_scale)
        else:
            self._draw_own_skin(state, surface, kind, mvp, view_m)
        for prog in (self.line_prog, self.thick_prog, self.trail_prog):
            prog["mvp"].write(_mat(mvp))
        self.thick_prog["viewport"].value = (float(size[0]), float(size[1]))
        if view in ("wireframe", "muscles"):
            dark = view == "muscles"
            self._lines(self.edge_vao, (0.06, 0.07, 0.09, 0.75 if dark else 0.4), 1.0, 2e-4)
        if view == "muscles" and len(self.muscles):
            self.muscle_vbo.write(self.muscles.positions(surface).tobytes())
            self.ctx.disable(moderngl.DEPTH_TEST)   # muscles lie under the skin: always show them
            self._lines(self.muscle_vao, (0.93, 0.08, 0.06, 1.0), 2.0 * ss, 0.0)
            self.ctx.enable(moderngl.DEPTH_TEST)
        if view == "trails":
            self._draw_trails(mvp, ss)

    def _draw_own_skin(self, state: Any, surface: np.ndarray, kind: str, mvp: np.ndarray,
                       view_m: np.ndarray) -> None:
        """The model's own skin, its held head, cavities and eyeballs (every face but the scan)."""
        skin = self.skin_progs[kind]
        if kind == "HEAT":
            skin["heat_scale"].value = float(self.heat_scale)
        self.skin_vaos[kind].render(moderngl.TRIANGLES)
        if kind in self.head_vaos:  # closed surfaces seen from outside: their backs never show
            if kind == "SKIN":
                self.scalp_prog["mvp"].write(_mat(mvp))
                self.scalp_prog["view"].write(_mat(view_m))
            self.ctx.enable(moderngl.CULL_FACE)
            self.head_vaos[kind].render(moderngl.TRIANGLES)
            self.ctx.disable(moderngl.CULL_FACE)
        self._draw_cavities(surface, mvp)
        self._draw_eyes(state)

    def _draw_cavities(self, surface: np.ndarray, mvp: np.ndarray) -> None:
        """Dark pockets behind the mouth and eye openings, drawn after the skin (which hides most
        of them cheaply) and without depth writes: a backdrop that shows only through the holes,
        so it can never hide an eyeball drawn after it."""
        if self.cavity_vao is None:
            return
        self.cavity_prog["mvp"].write(_mat(mvp))
        self.cavity_vbo.write(np.concatenate([c.positions(surface) for c in self.cavities]).tobytes())
        fbo = self.ctx.fbo
        fbo.depth_mask = False
        self.cavity_vao.render(moderngl.TRIANGLES)
        fbo.depth_mask = True

    def _draw_eyes(self, state: Any) -> None:
        mesh = self.model.mesh
        yaws = eye_yaws(float(np.clip(getattr(state, "eye_yaw", 0.0), -1, 1)),
                        float(np.clip(getattr(state, "eye_vergence", 0.0), -1, 1)))
        pitch = float(np.clip(getattr(state, "eye_pitch", 0.0), -1, 1)) * EYE_PITCH_MAX
        turn = head_turn(state)
        self.eye_prog["radius"].value = float(mesh.eye_radius)
        self.ctx.enable(moderngl.CULL_FACE)  # the back of an eyeball is never seen
        for c, yaw in zip(np.asarray(mesh.eye_centers, float), yaws):  # left eye, right eye
            gaze = eye_rotation(yaw * EYE_YAW_MAX, pitch)
            c, rot = turn_eye(c, gaze, *turn) if is_turned(*turn) else (c, gaze)
            self.eye_prog["rot"].write(_mat(rot))
            self.eye_prog["center"].value = tuple(c)
            self.eye_vao.render(moderngl.TRIANGLES)
        self.ctx.disable(moderngl.CULL_FACE)

    def _lines(self, vao: moderngl.VertexArray, color: tuple[float, float, float, float],
               width: float, bias: float, ranges: list[tuple[int, int]] | None = None) -> None:
        """Blend lines over the scene; `ranges` are (first, count) slices of the index buffer."""
        prog = vao.program
        prog["color"].value = color
        prog["bias"].value = bias
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA,
                               moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        if "width" in prog:
            prog["width"].value = width
        else:  # native lines: widths in final pixels, so scaled by the supersampling factor
            self.ctx.line_width = min(max(1.0, round(width * self.supersample)), self._max_line_width)
        for first, count in ranges if ranges is not None else [(0, -1)]:
            if count:
                vao.render(moderngl.LINES, vertices=count, first=first)
        self.ctx.line_width = 1.0
        self.ctx.disable(moderngl.BLEND)

    def _draw_trails(self, mvp: np.ndarray, ss: int) -> None:
        tr = self.trails
        assert tr is not None
        n = tr.frames.shape[1]
        for slot in sorted(tr.dirty):
            self.trail_vbo.write(tr.frames[slot].tobytes(), offset=slot * n * 12)
        tr.dirty.clear()
        self.ctx.enable(moderngl.PROGRAM_POINT_SIZE)
        self.point_prog["mvp"].write(_mat(mvp))
        self.point_prog["size"].value = 2.0 * ss
        self.point_prog["color"].value = (0.1, 0.25, 1.0, 1.0)
        self.point_prog["still"].value = STILL_PATH_CM
        self.path_vbo.write(tr.path.tobytes())
        self.dot_vao.render(moderngl.POINTS)
        p = self.trail_prog
        for name, value in (("trail_n", n), ("trail_k", tr.capacity), ("trail_head", tr.head),
                            ("trail_count", tr.count)):
            p[name].value = value
        # index blocks are per ring slot (slot s -> s+1); draw those from the oldest sample up to
        # the newest, in at most two slices, skipping the seam and the unfilled slots
        block = 2 * self.trail_nodes
        first, segs, k = tr.oldest, tr.count - 1, tr.capacity
        head_part = min(segs, k - first)
        ranges = [(first * block, head_part * block), (0, (segs - head_part) * block)]
        self.ctx.disable(moderngl.DEPTH_TEST)  # past positions may lie under today's skin
        self._lines(self.trail_vao, (1.0, 1.0, 1.0, 1.0), 1.5, 0.0, ranges)
        self.ctx.enable(moderngl.DEPTH_TEST)

    def project(self, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """(K, 2) pixel positions (origin top-left) of world points in a `size` image drawn with
        the current camera: lets tests and overlays find the mouth or an eye in a frame."""
        w, h = size
        view_m, proj = self.camera.matrices(w / max(h, 1))
        p = np.c_[np.asarray(points, float).reshape(-1, 3), np.ones(len(np.reshape(points, (-1, 3))))]
        clip = p @ (proj @ view_m).T
        ndc = clip[:, :2] / clip[:, 3:4]
        return np.c_[(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h]

    # -- teardown ---------------------------------------------------------------------------------
    def _release_model(self) -> None:
        for obj in reversed(self._gl):
            obj.release()
        self._gl = []
        self.model = None
        self.scan = None

    def release(self) -> None:
        """Free every GL object this renderer made (the context stays the caller's)."""
        self._release_model()
        if self._scene is not None:
            for obj in self._scene[1:]:
                obj.release()
            self._scene = None
        for prog, vao in self._post.values():
            vao.release()
            prog.release()
        for obj in (*self.skin_progs.values(), self.scalp_prog, self.eye_prog, self.cavity_prog, self.line_prog,
                    self.thick_prog,
                    self.trail_prog, self.point_prog):
            obj.release()
        self.hud.release()


def _top_down(box: np.ndarray, h: int) -> tuple[float, float, float, float]:
    """A box on screen x0 y0 x1 y1 in pixels with y up as x0 y0 x1 y1 from the top-left (the HUD's)."""
    return float(box[0]), float(h - box[3]), float(box[2]), float(h - box[1])
