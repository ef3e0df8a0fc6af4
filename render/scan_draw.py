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
from render.scan_look import IRIS_ANGLE, PUPIL_ANGLE, ScanLook, ScanRows
from sim.face.scan.blendshapes import StateControl as PoseControl

KINDS = ("SKIN", "CLAY", "HEAT")


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


class ScanPoser:
    """The per-frame CPU half of drawing a scanned head, without OpenGL: the scan posed to a state
    and its rows (an export's simulating process makes them for its render processes)."""

    def __init__(self, dressing: Any) -> None:
        self.dressing = dressing
        self.look = ScanLook(np.asarray(dressing.rest, np.float64))
        self.maker = ScanRows(self.look)

    def rows(self, state: Any) -> np.ndarray:
        posed = self.dressing.pose_turned(np.asarray(state.surface), PoseControl(state), state)
        return self.maker.rows(posed)


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
        self.look = ScanLook(np.asarray(rest_scan, np.float64))
        self.maker = ScanRows(self.look)
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
        ibos = {g: ctx.buffer(np.ascontiguousarray(t).tobytes()) for g, t in groups.items()}
        self._gl: list[Any] = [self.vbo, *(b for b, _ in bufs.values()), *ibos.values()]
        self.vaos: dict[tuple[str, str], moderngl.VertexArray] = {}
        for kind in KINDS:
            for group in ("skin", "mouth", "sockets"):
                self.vaos[kind, group] = self._vao(self.progs[kind], bufs, ibos[group])
        # the shaded look draws its skin in two parts: the brows and lips with every term, the rest
        # (most pixels) with the plain shader, the same colours with less work per pixel
        self.vaos["SKIN", "features"] = self._vao(self.progs["SKIN"], bufs, ibos["features"])
        self.vaos["PLAIN", "plain"] = self._vao(self.progs["PLAIN"], bufs, ibos["plain"])
        self.eye_vao = self._vao(self.eye_prog, bufs, ibos["eyes"])
        self.lash_vao = self._vao(self.lash_prog, bufs, ibos["lashes"])
        self._gl += [*self.vaos.values(), self.eye_vao, self.lash_vao, *self.progs.values(), self.eye_prog,
                     self.lash_prog]
        self.mouth_drawn = False
        self.split_skin = True  # False: the whole skin with every term (the same pixels, slower)

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

    def rows(self, state: Any) -> np.ndarray:
        """(26719, 7) float32 rows x y z nx ny nz fold of the scan posed to `state` (the same array
        every call)."""
        posed = self.dressing.pose_turned(np.asarray(state.surface), PoseControl(state), state)
        return self.maker.rows(posed)

    def draw(self, rows: np.ndarray, kind: str, mvp: bytes, view_m: bytes, heat_scale: float) -> None:
        self.vbo.write(rows)
        prog = self.progs[kind]
        for p in (prog, self.eye_prog, *((self.progs["PLAIN"],) if kind == "SKIN" else ())):
            p["mvp"].write(mvp)
            p["view"].write(view_m)
        self.lash_prog["mvp"].write(mvp)
        if kind == "HEAT":
            prog["heat_scale"].value = float(heat_scale)
        ctx = self.ctx
        ctx.enable(moderngl.CULL_FACE)
        if kind == "SKIN" and self.split_skin:
            self.vaos["PLAIN", "plain"].render(moderngl.TRIANGLES)
            self.vaos["SKIN", "features"].render(moderngl.TRIANGLES)
        else:
            self.vaos[kind, "skin"].render(moderngl.TRIANGLES)
        self.eye_vao.render(moderngl.TRIANGLES)
        self.vaos[kind, "sockets"].render(moderngl.TRIANGLES)
        self.mouth_drawn = self.look.mouth_open(rows[:, :3])
        if self.mouth_drawn:
            self.vaos[kind, "mouth"].render(moderngl.TRIANGLES)
        ctx.disable(moderngl.CULL_FACE)
        if kind == "SKIN":  # hair over the skin: blended, without depth writes
            fbo = ctx.fbo
            ctx.enable(moderngl.BLEND)
            ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ZERO, moderngl.ONE)
            fbo.depth_mask = False
            self.lash_vao.render(moderngl.TRIANGLES)
            fbo.depth_mask = True
            ctx.disable(moderngl.BLEND)

    def release(self) -> None:
        for obj in reversed(self._gl):
            obj.release()
        self._gl = []
