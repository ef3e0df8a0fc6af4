"""The scanned head (sim.face.scan) drawn with materials: skin, dark brows, red lips, eyes with a dark
iris on a pale sclera, and the mouth's inside (teeth) drawn only while the lips are apart."""

from __future__ import annotations

from typing import Any

import numpy as np

from render.offscreen import OffscreenRenderer
from render.scan_look import eye_centres
from sim.face import default_model
from sim.face.scan.blendshapes import ScanShapes
from sim.face.scan.data import PARTS, scan_data


class _StillScan:
    """A face model whose drawing is a still pose of the scan's own shapes."""

    def __init__(self, shapes: ScanShapes) -> None:
        self._model = default_model(0)
        self.scan_dressing = shapes

    def __getattr__(self, name: str) -> Any:
        return getattr(self._model, name)


def _shot(gl, shapes: ScanShapes, size=(400, 400)) -> tuple[np.ndarray, OffscreenRenderer, bool]:
    model = _StillScan(shapes)
    off = OffscreenRenderer(model, size, ctx=gl)
    off.renderer.camera.scale = 0.7  # the face fills the picture
    img = off.render_frame(model.rest_state(), record=False).astype(float)
    drawn = off.renderer.scan.mouth_drawn
    return img, off, drawn


def _at(img: np.ndarray, off: OffscreenRenderer, point: np.ndarray, size=(400, 400)) -> np.ndarray:
    x, y = off.renderer.project(np.asarray(point, float)[None], size)[0]
    return img[int(y) - 1:int(y) + 2, int(x) - 1:int(x) + 2].reshape(-1, 3).mean(axis=0)


def test_materials_of_the_scanned_head(gl) -> None:
    d = scan_data()
    img, off, drawn = _shot(gl, ScanShapes())
    try:
        assert not drawn  # lips closed: the mouth's inside is left out
        eye = eye_centres(d.neutral)[0]
        forehead = _at(img, off, [eye[0], eye[1] + 4.0, d.neutral[:PARTS["face"][1], 2].max() - 2.5])
        lum = lambda c: float(c.sum())  # noqa: E731
        # the brow (1.9 cm above the eye's centre, on the skin in front of it) is much darker than the forehead
        brow_pts = d.neutral[:PARTS["face"][1]]
        near = brow_pts[(np.abs(brow_pts[:, 0] - eye[0]) < 0.3) & (np.abs(brow_pts[:, 1] - eye[1] - 1.95) < 0.3)]
        brow = _at(img, off, near[np.argmax(near[:, 2])])
        assert lum(brow) < 0.6 * lum(forehead)
        # the cornea's apex: the pupil, dark; the sclera beside the iris, pale
        lo = PARTS["eyeball_l"][0]
        shell = d.neutral[lo:lo + 770]
        apex = shell[np.argmax(np.linalg.norm(shell - eye, axis=1))]
        pupil = _at(img, off, apex)
        assert lum(pupil) < 0.35 * lum(forehead)
        # the lips are redder than the skin of the chin
        lips = d.neutral[:PARTS["face"][1]]
        lip = lips[(np.abs(lips[:, 0]) < 0.2) & (lips[:, 1] < -3.6) & (lips[:, 1] > -4.3)]
        lip_rgb = _at(img, off, lip[np.argmax(lip[:, 2])])
        chin = lips[(np.abs(lips[:, 0]) < 0.2) & (np.abs(lips[:, 1] + 6.5) < 0.3)]
        chin_rgb = _at(img, off, chin[np.argmax(chin[:, 2])])
        assert lip_rgb[0] / lip_rgb[1] > chin_rgb[0] / chin_rgb[1] + 0.15
    finally:
        off.release()


def test_mouth_inside_drawn_when_open(gl) -> None:
    img, off, drawn = _shot(gl, ScanShapes(expressions={"jawOpen": 0.6}))
    try:
        assert drawn
        off.renderer.scan.look.mouth_open = lambda posed: False  # the same picture without the inside
        hollow = off.render_frame(off.renderer.model.rest_state(), record=False).astype(float)
        background = np.abs(hollow - img[0, 0]).sum(axis=2) < 3
        through = background & (np.abs(img - img[0, 0]).sum(axis=2) > 30)
        assert through.sum() > 400  # where the open mouth would show the background, the inside is drawn
        inside = img[through]
        assert np.median(inside.sum(axis=1)) < 0.8 * np.median(img[~background].sum(axis=1))  # darker than the skin
        assert inside.sum(axis=1).max() > 450  # and with light teeth in it
    finally:
        off.release()


def _scan_posed(what: str) -> tuple:
    """The default scanned face and its state six steps into `what` (a preset, or an action unit
    such as AU27, the jaw dropped) at full value: the mouth's and eyes' insides on show."""
    from puppet.face_cache import scan_model
    from sim.facs import apply_au, apply_expression
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    sim, state = Simulator(model), model.rest_state()
    control = FaceControl(model)
    if what.startswith("AU"):
        apply_au(control, what, 1.0)
    else:
        apply_expression(control, what, 1.0)
    for _ in range(6):
        sim.step(state, control)
    return model, state

def test_every_view_draws_the_simulated_scanned_head(gl) -> None:

    model, state = _scan_posed("surprise")
    shots = {}
    with OffscreenRenderer(model, (160, 120), ctx=gl) as off:
        assert off.renderer.scan is not None  # the default face is drawn as the whole scan
        for view in ("shaded", "wireframe", "muscles", "trails", "heat"):
            off.view = view
            shots[view] = off.render_frame(state).astype(float)
            assert gl.error == "GL_NO_ERROR"
    face = np.abs(shots["shaded"] - shots["shaded"][0, 0]).sum(axis=2) > 20
    assert face.mean() > 0.15  # the head fills a good part of the picture
    for view in ("wireframe", "muscles", "trails", "heat"):
        assert np.abs(shots[view] - shots["shaded"]).sum(axis=2)[face].mean() > 5, view


def test_plain_skin_shader_draws_the_same_skin(gl) -> None:
    """Most of the skin is drawn with the plain shader, without the brow and vermilion terms and
    with its highlight taken per vertex: the picture must be the one the full skin shader makes,
    brows, lips and highlights included, but for a few levels where the highlight is sharpest."""
    shapes = ScanShapes(expressions={"jawOpen": 0.3, "mouthSmile_L": 0.8, "browInnerUp_R": 0.7})
    img, off, _ = _shot(gl, shapes)
    try:
        scan = off.renderer.scan
        plain = len(scan.look.skin_split()["plain"])
        assert 0.5 * len(scan.look.groups["skin"]) < plain < len(scan.look.groups["skin"])
        scan.split_skin = False
        whole = off.render_frame(off.renderer.model.rest_state(), record=False).astype(float)
        assert gl.error == "GL_NO_ERROR"
        assert np.abs(whole - img[0, 0]).sum(axis=2).astype(bool).mean() > 0.2  # the face is in the picture
        diff = np.abs(whole - img).max(axis=2)
        assert diff.max() <= 12.0  # the highlight per vertex: a few levels at most
        assert (diff > 2).mean() < 0.005  # and hardly anywhere
    finally:
        off.release()


def test_back_faces_left_out_on_the_cpu_change_no_pixel(gl) -> None:
    """The triangles turned away from the camera are left out before OpenGL sees them: from the
    front, the side and behind, with the mouth open, the picture is the one OpenGL's own culling
    makes, and a good share of the triangles is left out."""
    from render.scan_draw import CULLED

    model, state = _scan_posed("AU27")
    with OffscreenRenderer(model, (240, 180), ctx=gl) as off:
        scan = off.renderer.scan
        for yaw, pitch in ((0.0, 0.0), (1.3, 0.4), (3.1, -0.3)):
            off.renderer.camera.yaw, off.renderer.camera.pitch = yaw, pitch
            scan.cull_on_cpu = True
            culled = off.render_frame(state, record=False).astype(int)
            assert scan.mouth_drawn
            kept, whole = int(scan.counts.sum()), int(scan.full.sum())
            if scan.coarse:  # this size draws the coarse plain skin, eyeballs and inside (render.scan_lod): whole lists
                whole -= int(scan.full[0]) - len(scan.coarse_tri)
                whole -= int(scan.full[CULLED.index("eyes")]) - len(scan.coarse_eyes)
                whole -= int(scan.full[CULLED.index("mouth")]) - len(scan.coarse_mouth)
            scan.cull_on_cpu = False
            every = off.render_frame(state, record=False).astype(int)
            assert gl.error == "GL_NO_ERROR"
            assert int(scan.counts.sum()) == whole
            assert kept < 0.8 * whole, (yaw, kept, whole)
            assert np.abs(every - every[0, 0]).sum(axis=2).astype(bool).mean() > 0.1  # the head is in view
            assert np.abs(culled - every).max() <= 1, (yaw, pitch)


def test_unseen_triangles_left_out_change_no_pixel(gl) -> None:
    """The triangles that cover no pixel (off the picture, too thin to hold a pixel centre) and the
    eyes' and the mouth's that the skin hides are left out too: from the front, the side, above
    and below, with the mouth open, the picture is the one with them kept, fewer of the eyes' and
    mouth's triangles are drawn from the front (fewer of the mouth's than with the openings' boxes
    on screen alone, not their hulls, or with the teeth and gums hidden only behind the mouth's
    opening), and the listing made on the helper thread is the one made on the calling thread."""
    from render.scan_draw import CULLED

    model, state = _scan_posed("AU27")
    inner = [CULLED.index(g) for g in ("eyes", "mouth")]
    mouth_g = CULLED.index("mouth")
    with OffscreenRenderer(model, (320, 180), ctx=gl) as off:
        scan = off.renderer.scan
        for yaw, pitch in ((0.0, 0.0), (-0.9, -0.4), (0.2, -1.2), (0.0, 1.2)):
            off.renderer.camera.yaw, off.renderer.camera.pitch = yaw, pitch
            scan.cull_unseen = True
            left_out = off.render_frame(state, record=False).astype(int)
            counts, kept = scan.counts.copy(), scan.kept.copy()
            scan.maker.threaded = False
            off.render_frame(state, record=False)
            scan.maker.threaded = True
            assert np.array_equal(counts, scan.counts) and np.array_equal(kept, scan.kept)
            scan.maker.use_walls = False  # the teeth and gums hidden only behind the mouth's opening
            plane = off.render_frame(state, record=False).astype(int)
            plane_counts = scan.counts.copy()
            scan.maker.use_walls = True
            scan.cull_unseen = False
            every = off.render_frame(state, record=False).astype(int)
            assert scan.mouth_drawn and gl.error == "GL_NO_ERROR"
            assert np.abs(every - every[0, 0]).sum(axis=2).astype(bool).mean() > 0.1  # the head is in view
            assert np.abs(left_out - every).max() == 0, (yaw, pitch)
            assert np.abs(plane - every).max() == 0, (yaw, pitch)
            assert counts[mouth_g] <= plane_counts[mouth_g]
            if yaw == 0.0 and pitch == 0.0:
                assert counts.sum() < 0.85 * scan.counts.sum()
                assert counts[inner].sum() < 0.8 * scan.counts[inner].sum(), (counts, scan.counts)
                scan.cull_unseen, scan.maker.use_hulls = True, False  # the openings' boxes alone
                boxed = off.render_frame(state, record=False).astype(int)
                scan.maker.use_hulls = True
                assert np.abs(boxed - every).max() == 0
                mouth = CULLED.index("mouth")
                assert counts[mouth] < 0.95 * scan.counts[mouth], (counts, scan.counts)
                assert counts[mouth] < plane_counts[mouth], (counts, plane_counts)
        scan.cull_unseen = True


def _no_balls(n_vertices: int, n_triangles: int, small: float = 0.0) -> tuple[object, ...]:
    """seen_triangles' last arguments for no hiding balls (the triangles' boxes alone for the
    pixel centres unless `small`)."""
    return (np.zeros((0, 4), np.int32), np.zeros((0, 4)), np.zeros(0), np.zeros(0, np.int32), np.zeros(0, np.uint8),
            np.zeros(n_triangles, np.uint8), np.zeros(n_vertices, np.uint8), small)


def _listed(pos: np.ndarray, tri: np.ndarray, clip: np.ndarray, size: np.ndarray, eye: np.ndarray,
            tail: tuple[object, ...]) -> set[int]:
    """The triangles seen_triangles keeps (one group, no openings)."""
    from render.scan_kernel import seen_triangles

    n, t = len(pos), len(tri)
    kept, counts = np.zeros((t, 3), np.int32), np.zeros(1, np.int64)
    seen_triangles(pos, tri, np.zeros(t, np.uint8), False, np.zeros(t, np.int8), np.zeros(1, np.int64),
                   eye.astype(np.float32), kept, counts, np.zeros(t, np.uint8), clip, size, np.zeros((0, 4)),
                   np.zeros((0, 4)), np.zeros((0, 1, 3)), np.zeros(0, np.int64), np.zeros(n, np.uint8),
                   np.zeros((n, 2), np.float32), np.zeros(n, np.int32), np.zeros(n, np.uint8), *tail,
                   np.zeros(t, np.uint8), np.zeros((0, 1, 4)), np.zeros(0, np.int64))
    return {k for k, corners in enumerate(tri) if any(np.array_equal(corners, row) for row in kept[:counts[0]])}


def test_small_triangle_between_pixel_centres_left_out() -> None:
    """A small triangle whose box holds a pixel centre that the triangle misses is left out when
    the centres are tested one by one (it cannot cover a pixel); one that holds a centre, or
    passes within the rasterizer's rounding of one, is kept."""
    clip = np.diag([0.01, 0.01, 0.1, 1.0])  # orthographic: x pixels = 100 + x of a 200 x 200 picture
    size = np.array([200.0, 200.0])
    corners = {"sliver beside the centre (10.5, 10.5)": [(10.0, 10.0), (10.4, 10.0), (11.2, 11.0)],
               "holds (20.5, 20.5)": [(20.0, 20.0), (21.2, 20.0), (20.0, 21.2)],
               "its edge 1/200 px from (30.5, 30.5)": [(30.0, 30.0), (31.0, 31.0 - 0.005 * np.sqrt(2.0)),
                                                       (30.0, 31.0)]}
    pos = np.array([(x - 100.0, y - 100.0, 0.0) for tri in corners.values() for x, y in tri], np.float32)
    tri = np.arange(len(pos), dtype=np.int32).reshape(-1, 3)
    eye = np.array([0.0, 0.0, 10.0])
    assert _listed(pos, tri, clip, size, eye, _no_balls(len(pos), len(tri))) == {0, 1, 2}  # the boxes alone
    assert _listed(pos, tri, clip, size, eye, _no_balls(len(pos), len(tri), small=6.0)) == {1, 2}


def test_triangles_behind_a_ball_left_out() -> None:
    """A triangle that a ball may hide is left out when it lies in the ball, or in the ball's cone
    of sight behind it; kept beside it, in front of it, or astride the cone's edge, and when the
    ball follows the vertices that carry it away."""
    ring = np.array([(1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)], np.float64)  # their mean: the centre
    tris = {"in the ball": [(-0.2, -0.2, -0.5), (0.2, -0.2, -0.5), (0.0, 0.2, -0.5)],
            "behind it": [(-0.2, -0.2, -3.0), (0.2, -0.2, -3.0), (0.0, 0.2, -3.0)],
            "beside it": [(2.8, -0.2, -3.0), (3.2, -0.2, -3.0), (3.0, 0.2, -3.0)],
            "in front of it": [(-0.2, -0.2, 2.0), (0.2, -0.2, 2.0), (0.0, 0.2, 2.0)],
            "astride the cone's edge": [(0.5, -0.2, -3.0), (1.5, -0.2, -3.0), (1.0, 0.2, -3.0)]}
    pos = np.concatenate([ring, *(np.array(t) for t in tris.values())]).astype(np.float32)
    tri = (len(ring) + np.arange(3 * len(tris))).reshape(-1, 3).astype(np.int32)
    clip = np.diag([0.1, 0.1, 0.01, 1.0])
    size = np.array([200.0, 200.0])
    near = np.arange(len(ring), len(pos), dtype=np.int32)
    tail = (np.arange(4, dtype=np.int32)[None], np.full((1, 4), 0.25), np.array([1.0]), near,
            np.ones(len(near), np.uint8), np.ones(len(tri), np.uint8), np.zeros(len(pos), np.uint8), 0.0)
    eye = np.array([0.0, 0.0, 10.0])
    shown = {name for k, name in enumerate(tris) if k in _listed(pos, tri, clip, size, eye, tail)}
    assert shown == {"beside it", "in front of it", "astride the cone's edge"}
    pos[:len(ring), 0] += 3.0  # the ball moves over to the triangle beside it
    shown = {name for k, name in enumerate(tris) if k in _listed(pos, tri, clip, size, eye, tail)}
    assert shown == {"in the ball", "behind it", "in front of it", "astride the cone's edge"}


def test_inside_seen_only_through_the_opening_hull() -> None:
    """A triangle inside the head behind a round opening is left out when it lies beyond the
    opening's convex hull on screen though inside the opening's box (the corners of the box), and
    kept when any of it can show through the opening, or when it lies in front of the opening."""
    from render.scan_kernel import openings, seen_triangles

    ring = np.linspace(0.0, 2.0 * np.pi, 32, endpoint=False)
    loop_pos = np.stack([np.cos(ring), np.sin(ring), np.zeros_like(ring)], axis=1)  # counter-clockwise from +z
    tris = {"corner, behind": ([0.8, 0.85, -0.5], [0.9, 0.85, -0.5], [0.85, 0.95, -0.5]),
            "centre, behind": ([-0.1, -0.1, -0.5], [0.1, -0.1, -0.5], [0.0, 0.1, -0.5]),
            "astride the rim, behind": ([0.6, 0.6, -0.5], [0.95, 0.7, -0.5], [0.9, 0.95, -0.5]),
            "corner, in front": ([0.8, 0.85, 0.5], [0.9, 0.85, 0.5], [0.85, 0.95, 0.5])}
    pos = np.concatenate([loop_pos, *(np.array(t) for t in tris.values())]).astype(np.float32)
    n_loop = len(loop_pos)
    tri = (n_loop + np.arange(3 * len(tris)).reshape(-1, 3)).astype(np.int32)
    clip = np.diag([0.5, 0.5, 0.1, 1.0])  # orthographic: a unit is 50 pixels of a 200 x 200 picture
    size = np.array([200.0, 200.0])
    planes, boxes = np.zeros((1, 4)), np.zeros((1, 4))
    hulls, hull_n = np.zeros((1, n_loop + 1, 3)), np.zeros(1, np.int64)
    walls, wall_n = np.zeros((1, n_loop + 1, 4)), np.zeros(1, np.int64)
    openings(pos, np.array([0, n_loop]), np.arange(n_loop, dtype=np.int32), clip, size, 3.0, planes, boxes, hulls,
             hull_n, walls, wall_n, 0.05)
    assert hull_n[0] == n_loop and np.allclose(planes[0], [0.0, 0.0, 1.0, 0.0], atol=1e-6)
    inside = np.zeros(len(pos), np.uint8)
    inside[n_loop:] = 1
    kept, counts = np.zeros((len(tri), 3), np.int32), np.zeros(1, np.int64)
    seen_triangles(pos, tri, np.zeros(len(tri), np.uint8), False, np.zeros(len(tri), np.int8), np.zeros(1, np.int64),
                   np.array([0.0, 0.0, 10.0], np.float32), kept, counts, np.ones(len(tri), np.uint8), clip, size,
                   planes, boxes, hulls, hull_n, inside, np.zeros((len(pos), 2), np.float32),
                   np.zeros(len(pos), np.int32), np.zeros(len(pos), np.uint8), *_no_balls(len(pos), len(tri)),
                   np.zeros(len(tri), np.uint8), walls, wall_n)
    shown = {name for name, t in zip(tris, tri) if any(np.array_equal(t, k) for k in kept[:counts[0]])}
    assert shown == {"centre, behind", "astride the rim, behind", "corner, in front"}


def _listed_through(pos: np.ndarray, tri: np.ndarray, loop: np.ndarray, clip: np.ndarray, size: np.ndarray,
                    eye: np.ndarray, sealed: np.ndarray) -> np.ndarray:
    """(T,) bool: the triangles seen_triangles keeps, all inside the head behind one opening (its
    corners `loop`), `sealed` marking those that never pass through it."""
    from render.scan_kernel import openings, seen_triangles

    n, t = len(pos), len(tri)
    planes, boxes = np.zeros((1, 4)), np.zeros((1, 4))
    hulls, hull_n = np.zeros((1, len(loop) + 1, 3)), np.zeros(1, np.int64)
    walls, wall_n = np.zeros((1, len(loop) + 1, 4)), np.zeros(1, np.int64)
    openings(pos, np.array([0, len(loop)]), loop, clip, size, 3.0, planes, boxes, hulls, hull_n, walls, wall_n, 0.05)
    inside = np.ones(n, np.uint8)
    inside[loop] = 0
    kept, counts = np.zeros((t, 3), np.int32), np.zeros(1, np.int64)
    seen_triangles(pos, tri, np.zeros(t, np.uint8), False, np.zeros(t, np.int8), np.zeros(1, np.int64),
                   eye.astype(np.float32), kept, counts, np.ones(t, np.uint8), clip, size, planes, boxes, hulls,
                   hull_n, inside, np.zeros((n, 2), np.float32), np.zeros(n, np.int32), np.zeros(n, np.uint8),
                   *_no_balls(n, t), sealed.astype(np.uint8), walls, wall_n)
    return np.array([any(np.array_equal(c, k) for k in kept[:counts[0]]) for c in tri])


def test_sealed_triangles_hidden_beside_the_opening() -> None:
    """A triangle that never passes through the opening (a tooth behind the lips) is left out when
    it lies beside the opening (outside the prism along the opening's normal over its outline) and
    beyond the opening's outline on screen, though in front of the opening's plane; kept when it is
    not so marked, and kept when it lies in front of the opening within that prism (an incisor's
    edge between parted lips) even where a camera from the side sees it beyond the outline."""
    ring = np.linspace(0.0, 2.0 * np.pi, 32, endpoint=False)
    loop_pos = np.stack([np.cos(ring), np.sin(ring), np.zeros_like(ring)], axis=1)  # counter-clockwise from +z
    tris = {"beside, in front": ([-0.1, 1.3, 0.2], [0.1, 1.3, 0.2], [0.0, 1.4, 0.2]),
            "within, in front": ([-0.1, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 1.0])}
    pos = np.concatenate([loop_pos, *(np.array(t) for t in tris.values())]).astype(np.float32)
    loop = np.arange(len(loop_pos), dtype=np.int32)
    tri = (len(loop_pos) + np.arange(3 * len(tris)).reshape(-1, 3)).astype(np.int32)
    size = np.array([200.0, 200.0])
    front = np.diag([0.5, 0.5, 0.1, 1.0])  # orthographic along -z: a unit is 50 pixels
    side = front.copy()
    side[0, 2] = 0.8  # and sheared: a point 1 in front of the opening moves 80 pixels right
    sealed = np.ones(len(tri), np.uint8)
    eye = np.array([0.0, 0.0, 10.0])
    assert list(_listed_through(pos, tri, loop, front, size, eye, sealed)) == [False, True]
    assert list(_listed_through(pos, tri, loop, front, size, eye, 0 * sealed)) == [True, True]
    assert list(_listed_through(pos, tri, loop, side, size, eye, sealed)) == [False, True]


def test_frame_in_parts_is_the_frame_in_one_pass(gl) -> None:
    """The frame cleared first and its triangles handed to the rasterizer in parts (glFlush between
    them, so llvmpipe rasterises while the rest is made and set up) is the frame drawn in one pass:
    with the mouth open and the HUD, drawn straight into the target, supersampled, and into a
    viewport within a larger framebuffer."""
    from render.hud import HudInfo
    from render.scan_draw import CULLED, FLUSH_AT

    model, state = _scan_posed("AU27")
    hud = HudInfo(channels=[("jaw", 0.8, 0, 1)], age=30, devices=[], fps=60.0, latency_ms=10.0, lines=["? help"])
    every = ("half", *CULLED, "lashes")
    with OffscreenRenderer(model, (320, 180), ctx=gl) as off:
        r = off.renderer
        for ss, viewport in ((1, None), (2, None), (1, (40, 20, 200, 120))):
            r.supersample = ss
            shots = []
            for first, at in ((False, ()), (True, FLUSH_AT), (True, every)):
                r.clear_first, r.scan.flush_at = first, at
                if viewport is None:
                    shots.append(off.render_frame(state, hud, record=False))
                else:
                    off.fbo.use()
                    off.fbo.viewport = (0, 0, *off.size)
                    off.fbo.clear(1.0, 0.0, 0.0, 1.0)
                    off.fbo.viewport = viewport
                    r.draw(state, hud, record=False)
                    whole = (0, 0, *off.size)
                    shots.append(np.frombuffer(off.fbo.read(viewport=whole, components=3, alignment=1),
                                               np.uint8).reshape(off.size[1], off.size[0], 3))
                assert r.scan.mouth_drawn
                assert gl.error == "GL_NO_ERROR"
            assert np.abs(shots[0].astype(int) - shots[0][-1, -1]).max() > 50  # the head is in view
            assert np.array_equal(shots[0], shots[1]), (ss, viewport)
            assert np.array_equal(shots[0], shots[2]), (ss, viewport)


def test_hud_composited_first_is_the_hud_composited_last(gl) -> None:
    """The scanned head's HUD composited with the clear (before the face, while the scan is posed)
    gives the frame it gives composited last: while the head's box on screen leaves the HUD's
    panels free it goes first; where the head reaches a panel (the camera close) it goes last, also
    when the frame before had left them free (the frame is cleared again)."""
    from render.hud import HudInfo

    model, state = _scan_posed("AU27")
    hud = HudInfo(channels=[("jaw", 0.8, 0, 1)], age=30, devices=[("keyboard://", True)], fps=60.0,
                  latency_ms=10.0, lines=["? help"])
    scales = (1.0, 1.0, 0.45, 0.45, 1.0, 2.0)  # far enough: the panels lie beside the head; close: over it
    with OffscreenRenderer(model, (640, 360), ctx=gl) as off:
        r = off.renderer
        if not r.clear_first:  # no rasterizer threads (LP_NUM_THREADS=0): the HUD always goes last
            return
        shots, first = {}, []
        for on in (False, True):
            r.hud_first = on
            r._scan_box = None  # no frame before
            shots[on] = []
            for scale in scales:
                r.camera.scale = 2.0 * scale
                shots[on].append(off.render_frame(state, hud, record=False))
                if on:
                    first.append(r.hud_was_first)
        assert gl.error == "GL_NO_ERROR"
    for a, b in zip(shots[False], shots[True]):
        assert np.array_equal(a, b)
    # the first frame has no frame before; the close ones reach the panels (the first of them is
    # guessed free from the one before, then cleared again)
    assert first == [False, True, False, False, False, True]


def test_screen_box_holds_every_vertex_and_gives_up_behind_the_camera() -> None:
    """The scan's box on screen (what the HUD is kept clear of) is the vertices' own box, and the
    whole plane when a vertex is not in front of the camera (its pixels NaN)."""
    from render.scan_kernel import screen_box

    xy = np.random.default_rng(3).normal(300.0, 80.0, (5000, 2)).astype(np.float32)
    box = np.zeros(4)
    screen_box(xy, box)
    assert np.array_equal(box, [*xy.min(axis=0), *xy.max(axis=0)])
    xy[1234, 1] = np.nan
    screen_box(xy, box)
    assert np.array_equal(box, [-np.inf, -np.inf, np.inf, np.inf])
