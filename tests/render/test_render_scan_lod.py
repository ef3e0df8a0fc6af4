"""The scanned head's coarse plain skin (render.scan_lod), drawn while the skin's triangles are small
on screen: the same skin with fewer triangles over the same vertices, meeting the brows, lips and
openings edge for edge, never turned over, and the same picture but for a few levels here and there."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from render.offscreen import OffscreenRenderer
from render.scan_draw import CULLED
from render.scan_lod import coarse_plain
from render.scan_look import ScanLook
from sim.face.scan.data import scan_data


def _directed(tri: np.ndarray) -> Counter:
    return Counter(map(tuple, np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]).tolist()))


def test_coarse_plain_skin_covers_the_same_skin_without_cracks() -> None:
    look = ScanLook(scan_data().neutral)
    full = look.skin_split()["plain"]
    coarse, error = coarse_plain()
    assert len(coarse) < 0.9 * len(full)
    assert set(np.unique(coarse)) <= set(np.unique(full))  # no new vertex: every export keeps the scan's
    d_full, d_coarse = _directed(full), _directed(coarse)
    assert max(d_coarse.values()) == 1  # one winding, a manifold
    # the border (edges with no twin): the openings' rims and the seam with the brows and lips, the same
    border = {e for e in d_full if (e[1], e[0]) not in d_full}
    assert {e for e in d_coarse if (e[1], e[0]) not in d_coarse} == border
    r = look.rest
    area = 0.5 * np.linalg.norm(np.cross(r[coarse[:, 1]] - r[coarse[:, 0]], r[coarse[:, 2]] - r[coarse[:, 0]]), axis=1)
    assert area.min() > 1e-4  # cm²: no sliver left behind
    full_area = 0.5 * np.linalg.norm(np.cross(r[full[:, 1]] - r[full[:, 0]], r[full[:, 2]] - r[full[:, 0]]), axis=1)
    assert abs(area.sum() - full_area.sum()) < 0.01 * full_area.sum()
    assert 0.0 < error < 0.2  # cm, over the poses it was made for


@pytest.fixture(scope="module")
def posed():
    """The default face at rest, with the jaw dropped, and smiling (simulated)."""
    from puppet.face_cache import scan_model
    from sim.facs import apply_au, apply_expression
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    out = {"rest": model.rest_state()}
    for name, dial in (("jaw", lambda c: apply_au(c, "AU27", 1.0)),
                       ("smile", lambda c: apply_expression(c, "happiness", 1.0))):
        sim, state = Simulator(model), model.rest_state()
        control = FaceControl(model)
        dial(control)
        for _ in range(8):
            sim.step(state, control)
        out[name] = state
    return model, out


def test_coarse_triangles_turn_over_only_where_the_skin_does(posed) -> None:
    """Posed, every triangle the coarse list makes (not one of the full skin's) faces the way the
    full skin's normals at its corners do, but where it touches a triangle of the full skin that
    is itself turned over so (under the chin, with the jaw dropped)."""
    from render.scan_draw import ScanPoser, dressing_of

    model, states = posed
    poser = ScanPoser(dressing_of(model))
    full = ScanLook(scan_data().neutral).skin_split()["plain"]
    own = {tuple(t) for t in np.sort(full, axis=1).tolist()}
    coarse = coarse_plain()[0]
    made = coarse[[tuple(t) not in own for t in np.sort(coarse, axis=1).tolist()]]
    assert len(made) > 1000

    def over(tri: np.ndarray, rows: np.ndarray) -> np.ndarray:
        p, n = rows[:, :3].astype(float), rows[:, 3:6].astype(float)
        face = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
        return np.einsum("ij,ij->i", face, n[tri].sum(axis=1)) <= 0

    for name, state in states.items():
        rows = poser.rows(state)
        folded = np.zeros(len(rows), bool)
        folded[full[over(full, rows)].ravel()] = True
        bad = made[over(made, rows)]
        assert not bad.size or folded[bad].any(axis=1).all(), (name, bad)
        if name != "jaw":
            assert not bad.size, name


def test_coarse_skin_drawn_while_small_looks_the_same(gl, posed) -> None:
    """At a size where the skin's triangles are small the coarse plain skin is drawn: fewer
    triangles, and the picture of the full skin but for a few levels on a few pixels, the head's
    outline in place; larger (1920x1080, the gallery's supersampled stills) the full skin is drawn.
    The lashes, coarse with the coarse skin too, are left out of both pictures (compared below)."""
    model, states = posed
    plain = CULLED.index("plain")
    with OffscreenRenderer(model, (640, 360), ctx=gl) as off:
        scan = off.renderer.scan
        scan.left_out = {"lashes"}
        for name, state in states.items():
            scan.lod = True
            coarse = off.render_frame(state, record=False).astype(int)
            assert scan.coarse
            drawn = int(scan.counts[plain])
            scan.lod = False
            full = off.render_frame(state, record=False).astype(int)
            assert not scan.coarse and drawn < 0.85 * int(scan.counts[plain]), (name, drawn, scan.counts)
            bg = full[0, 0]
            head = np.abs(full - bg).sum(axis=2) > 0
            assert head.mean() > 0.1  # the head is in the picture
            diff = np.abs(full - coarse).max(axis=2)
            assert diff[head].mean() < 1.0, name  # levels of 255
            assert (diff[head] > 8).mean() < 0.005, name
            outline = head != (np.abs(coarse - bg).sum(axis=2) > 0)
            assert outline.sum() < 0.002 * head.sum(), name
        scan.lod = True
    for size, scale in (((1920, 1080), 1.0), ((960, 960), 0.78)):
        with OffscreenRenderer(model, size, ctx=gl) as off:
            off.renderer.camera.scale = scale
            off.render_frame(states["rest"], record=False)
            assert not off.renderer.scan.coarse, size


def test_coarse_ears_stay_on_the_full_ears(posed) -> None:
    """The ears are drawn from fewer triangles (render.scan_lod.build_ears), and every vertex of the
    full ears lies within about a pixel at 1280x720 of the coarse skin, at rest and posed: the rim
    that makes the head's outline from the front and the sides stays where it was."""
    from render.scan_draw import ScanPoser, dressing_of
    from render.scan_lod import EAR_TOL_CM, deviation, ear_vertices

    model, states = posed
    full = ScanLook(scan_data().neutral).skin_split()["plain"]
    coarse = coarse_plain()[0]
    in_full, in_coarse = ear_vertices(full, 0)[full].all(axis=1), ear_vertices(full, 0)[coarse].all(axis=1)
    assert in_coarse.sum() < 0.8 * in_full.sum()  # 3,480 -> 2,466 in the ears' box
    poser = ScanPoser(dressing_of(model))
    for name, state in states.items():
        p = poser.rows(state)[:, :3].astype(np.float64)
        assert deviation(coarse, full[in_full], p[None]) < 1.5 * EAR_TOL_CM, name


def test_coarse_ears_keep_the_outline_from_the_side(gl, posed, monkeypatch) -> None:
    """Seen from either side and three-quarters at 1280x720, the coarse skin with its ears made coarser
    covers the pixels the coarse skin with the full ears covers (the list before `build_ears`, shipped
    as `skin_plain`) but for a few, and the ears look the same but for a few levels."""
    import render.scan_lod as lod

    model, states = posed
    with np.load(lod.DATA) as d:
        before = d["skin_plain"].astype(np.int32)
    shots: list[list[np.ndarray]] = []
    for plain in (None, before):
        if plain is not None:
            monkeypatch.setattr(lod, "coarse_plain", lambda: (plain, 0.1))
        with OffscreenRenderer(model, (1280, 720), ctx=gl) as off:
            assert len(off.renderer.scan.coarse_tri) == len(plain if plain is not None else coarse_plain()[0])
            shots.append([])
            for yaw in (1.5708, -1.5708, 0.7):
                off.renderer.camera.yaw = yaw
                shots[-1].append(off.render_frame(states["rest"], record=False).astype(int))
                assert off.renderer.scan.coarse
    for ears, whole in zip(*shots):
        bg = whole[0, 0]
        cover = lambda img: np.abs(img - bg).max(axis=2) > 0  # noqa: E731
        assert (cover(ears) != cover(whole)).sum() <= 12
        diff = np.abs(whole - ears).max(axis=2)
        assert diff.max() > 0  # the ears were drawn coarser
        assert diff.mean() < 0.05 and (diff > 8).mean() < 0.0005
    assert gl.error == "GL_NO_ERROR"


def test_coarse_eyeballs_cover_the_same_shells(posed) -> None:
    """The eyeballs' shells drawn with the coarse skin (render.scan_lod.coarse_eyes) are fewer
    triangles over the same vertices, with the same borders, and stay within 0.3 mm of the full
    shells posed (the shell is convex: a facet lies inside it, so no lid is poked through)."""
    from render.scan_draw import ScanPoser, dressing_of
    from render.scan_lod import coarse_eyes, deviation

    model, states = posed
    full = ScanLook(scan_data().neutral).groups["eyes"]
    coarse = coarse_eyes()
    assert len(coarse) < 0.75 * len(full)
    assert set(np.unique(coarse)) <= set(np.unique(full))
    d_full, d_coarse = _directed(full), _directed(coarse)
    assert max(d_coarse.values()) == 1
    assert {e for e in d_coarse if (e[1], e[0]) not in d_coarse} == {e for e in d_full if (e[1], e[0]) not in d_full}
    poser = ScanPoser(dressing_of(model))
    for name, state in states.items():
        p = poser.rows(state)[:, :3].astype(np.float64)
        assert deviation(coarse, full, p[None], every=True) < 0.03, name


def test_coarse_eyeballs_look_like_the_full_ones(gl, monkeypatch) -> None:
    """At 1280x720 the eyes drawn from the coarse shells are the full shells' picture but for a few
    levels on a few pixels (the iris and pupil round, the highlight in place), open, half shut and
    shut, from the front and three-quarters."""
    import render.scan_lod as lod
    from puppet.face_cache import scan_model
    from sim.facs import apply_au
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    states = []
    for w in (0.0, 0.5, 1.0):
        sim, state = Simulator(model), model.rest_state()
        for _ in range(30):
            control = FaceControl(model)
            apply_au(control, "AU45", w)
            sim.step(state, control)
        states.append(state)
    full = ScanLook(scan_data().neutral).groups["eyes"].astype(np.int32)
    shots: list[list[np.ndarray]] = []
    for eyes in (None, full):
        if eyes is not None:
            monkeypatch.setattr(lod, "coarse_eyes", lambda: eyes)
        with OffscreenRenderer(model, (1280, 720), ctx=gl) as off:
            shots.append([])
            for state in states:
                for yaw in (0.0, 0.7):
                    off.renderer.camera.yaw = yaw
                    shots[-1].append(off.render_frame(state, record=False).astype(int))
                    assert off.renderer.scan.coarse
    for k, (coarse, whole) in enumerate(zip(*shots)):
        diff = np.abs(whole - coarse).max(axis=2)
        assert diff.mean() < 0.02 and (diff > 8).mean() < 0.0002, k
    assert gl.error == "GL_NO_ERROR"


def test_coarse_lashes_cover_the_same_strips() -> None:
    """The coarse lashes are fewer triangles over the lashes' own vertices, none degenerate, spanning
    the same strips: about the same area at rest, and the same extent on each side."""
    from render.scan_look import coarse_lashes
    from sim.face.scan.data import PARTS

    rest = scan_data().neutral
    full = ScanLook(rest).groups["lashes"]
    few = coarse_lashes()
    assert 0 < len(few) < 0.35 * len(full)
    lo, hi = min(PARTS["eyelashes_l"][0], PARTS["eyelashes_r"][0]), max(PARTS["eyelashes_l"][1],
                                                                          PARTS["eyelashes_r"][1])
    assert few.min() >= lo and few.max() < hi

    def areas(t: np.ndarray) -> np.ndarray:
        return 0.5 * np.linalg.norm(np.cross(rest[t[:, 1]] - rest[t[:, 0]], rest[t[:, 2]] - rest[t[:, 0]]), axis=1)

    assert areas(few).min() > 0.01 * np.median(areas(full))
    assert 0.85 < areas(few).sum() / areas(full).sum() < 1.05
    for part in ("eyelashes_l", "eyelashes_r"):
        a, b = PARTS[part]
        side_full = rest[np.unique(full[(full[:, 0] >= a) & (full[:, 0] < b)])]
        side_few = rest[np.unique(few[(few[:, 0] >= a) & (few[:, 0] < b)])]
        assert np.abs(side_full.min(axis=0) - side_few.min(axis=0)).max() < 0.05  # cm
        assert np.abs(side_full.max(axis=0) - side_few.max(axis=0)).max() < 0.05


def test_coarse_lashes_look_like_the_full_ones(gl, posed) -> None:
    """Drawn with the coarse skin, the coarse lashes darken about as many pixels as the full lashes
    do, and the picture differs from the full lashes' by a few levels on a few pixels."""
    model, states = posed
    with OffscreenRenderer(model, (1280, 720), ctx=gl) as off:
        scan = off.renderer.scan
        for name, state in states.items():
            few = off.render_frame(state, record=False).astype(int)
            assert scan.coarse
            coarse_vao = scan.coarse_lash_vao
            scan.coarse_lash_vao = scan.lash_vao
            full = off.render_frame(state, record=False).astype(int)
            scan.coarse_lash_vao = coarse_vao
            scan.left_out = {"lashes"}
            bare = off.render_frame(state, record=False).astype(int)
            scan.left_out = set()
            head = np.abs(full - full[0, 0]).sum(axis=2) > 0
            hair_full = (np.abs(full - bare).max(axis=2) > 8).sum()
            hair_few = (np.abs(few - bare).max(axis=2) > 8).sum()
            assert hair_full > 500 and 0.8 < hair_few / hair_full < 1.2, (name, hair_full, hair_few)
            diff = np.abs(full - few).max(axis=2)
            assert diff[head].mean() < 0.5, name
            assert (diff[head] > 8).mean() < 0.01, name
            assert gl.error == "GL_NO_ERROR"


@pytest.fixture(scope="module")
def mouth_open():
    """The default face settled with the jaw dropped, with the tongue out (AU19+26) and surprised,
    and settled at rest (the lips shut)."""
    from puppet.face_cache import scan_model
    from sim.facs import apply_au, apply_expression
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    out = {}
    for name, dial in (("jaw", lambda c, w: apply_au(c, "AU27", w)),
                       ("tongue", lambda c, w: (apply_au(c, "AU19", w), apply_au(c, "AU26", w))),
                       ("surprise", lambda c, w: apply_expression(c, "surprise", w)),
                       ("rest", lambda c, w: None)):
        sim, state = Simulator(model), model.rest_state()
        for k in range(40):
            control = FaceControl(model)
            dial(control, min(1.0, (k + 1) / 30))
            sim.step(state, control)
        out[name] = state
    return model, out


def test_coarse_inside_stays_on_the_full_one(mouth_open) -> None:
    """The coarse lining, gums and tongue (render.scan_lod.coarse_inside) are fewer triangles over
    the same vertices, meeting the rest of the mouth and the lips' edge where the full ones do, and
    with the mouth open every vertex of the full inside lies within the skin's tolerance of them."""
    from render.scan_draw import ScanPoser, dressing_of
    from render.scan_lod import TOL_CM, coarse_inside, deviation, inside_of

    model, states = mouth_open
    mouth = ScanLook(scan_data().neutral).groups["mouth"]
    full = mouth[inside_of(mouth)]
    coarse, error = coarse_inside()
    assert len(coarse) < 0.6 * len(full)
    assert set(np.unique(coarse)) <= set(np.unique(full))
    d_full, d_coarse = _directed(full), _directed(coarse)
    assert max(d_coarse.values()) == 1
    border = {e for e in d_full if (e[1], e[0]) not in d_full}
    assert {e for e in d_coarse if (e[1], e[0]) not in d_coarse} == border
    assert 0.0 < error < 1.2 * TOL_CM
    poser = ScanPoser(dressing_of(model))
    for name in ("jaw", "tongue", "surprise"):
        p = poser.rows(states[name])[:, :3].astype(np.float64)
        assert deviation(coarse, full, p[None], every=True) < 1.2 * TOL_CM, name


def test_coarse_inside_drawn_with_the_coarse_skin(gl, mouth_open) -> None:
    """With the coarse skin the mouth's inside is drawn from fewer triangles, the picture of the full
    inside but for a few levels on a few pixels inside the mouth; with the lips shut the picture is
    the same to the byte."""
    model, states = mouth_open
    mouth = CULLED.index("mouth")
    with OffscreenRenderer(model, (1280, 720), ctx=gl) as off:
        scan = off.renderer.scan
        for name, state in states.items():
            scan.lod_inside = True
            coarse = off.render_frame(state, record=False).astype(int)
            drawn, opened = int(scan.counts[mouth]), scan.mouth_drawn
            assert scan.coarse
            scan.lod_inside = False
            full = off.render_frame(state, record=False).astype(int)
            scan.lod_inside = True
            if name == "rest":
                assert not opened and np.array_equal(full, coarse)
                continue
            assert opened and drawn < int(scan.counts[mouth]), (name, drawn, scan.counts)
            diff = np.abs(full - coarse).max(axis=2)
            assert diff.max() > 0, name  # the coarse inside was drawn
            assert diff.mean() < 0.05, name  # levels of 255 over the picture
            assert (diff > 8).mean() < 0.001, name
        assert gl.error == "GL_NO_ERROR"


def test_the_rebuild_command_asks_before_it_rewrites_the_shipped_lists() -> None:
    """`--help` or an unknown part is answered without building or rewriting scan_lod.npz."""
    import subprocess
    import sys

    from render.scan_lod import DATA

    before = (DATA.stat().st_mtime_ns, DATA.read_bytes())
    shown = subprocess.run([sys.executable, "-m", "render.scan_lod", "--help"], capture_output=True, text=True,
                           timeout=120)
    assert shown.returncode == 0 and "inside" in shown.stdout
    wrong = subprocess.run([sys.executable, "-m", "render.scan_lod", "bogus"], capture_output=True, text=True,
                           timeout=120)
    assert wrong.returncode == 2 and "invalid choice" in wrong.stderr
    assert (DATA.stat().st_mtime_ns, DATA.read_bytes()) == before
