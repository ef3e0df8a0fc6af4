"""Each view differs from the shaded face the way it should, and the HUD draws text."""

from __future__ import annotations

import numpy as np
import pytest
from render_faces import Faces, skin_mask

from render.hud import HudInfo, active_channels
from render.offscreen import OffscreenRenderer
from render.renderer import VIEWS


def _render(off: OffscreenRenderer, view: str, state: object, hud: HudInfo | None = None) -> np.ndarray:
    off.view = view
    return off.render_frame(state, hud=hud).astype(int)


def _red(img: np.ndarray) -> np.ndarray:
    return (img[..., 0] > 170) & (img[..., 1] < 80) & (img[..., 2] < 80)


def _warm_saturated(img: np.ndarray) -> np.ndarray:
    """Trail / heat colours other than blue: strongly red, yellow or green over a weak blue."""
    return (np.max(img[..., :2], axis=-1) > 150) & (img[..., 2] < 90) & (np.ptp(img, axis=-1) > 110)


def _blue(img: np.ndarray) -> np.ndarray:
    return (img[..., 2] > 150) & (img[..., 0] < 90)


def test_unknown_view_is_rejected(offscreen: OffscreenRenderer) -> None:
    with pytest.raises(ValueError, match="wireframe"):
        offscreen.view = "xray"


def test_wireframe_draws_dark_lines_over_the_face(offscreen: OffscreenRenderer, faces: Faces) -> None:
    shaded = _render(offscreen, "shaded", faces.rest)
    wire = _render(offscreen, "wireframe", faces.rest)
    face = skin_mask(shaded)
    changed = np.abs(wire - shaded).sum(axis=-1) > 30
    assert changed[face].mean() > 0.2
    assert (wire.sum(-1) < shaded.sum(-1))[changed].mean() > 0.9  # lines darken
    assert changed[~face].mean() < 0.05  # the background is left alone


def test_muscles_view_draws_red_muscle_lines(offscreen: OffscreenRenderer, faces: Faces) -> None:
    assert _red(_render(offscreen, "shaded", faces.rest)).sum() == 0
    assert _red(_render(offscreen, "muscles", faces.rest)).sum() > 150


def test_trails_are_coloured_after_an_expression_and_blue_at_rest(gl, faces: Faces) -> None:
    with OffscreenRenderer(faces.model, (320, 240), view="trails", ctx=gl) as off:
        for s in faces.frames:
            img = off.render_frame(s)
        moving = _warm_saturated(img.astype(int)).sum()
        assert off.renderer.trails is not None and off.renderer.trails.count > 5
        off.renderer.trails.clear()
        still = off.render_frame(faces.rest).astype(int)
    assert moving > 60
    assert _warm_saturated(still).sum() < 0.1 * moving
    assert _blue(still).sum() > 300  # motionless nodes are blue dots


def test_trails_accept_a_given_history(gl, faces: Faces) -> None:
    with OffscreenRenderer(faces.model, (320, 240), view="trails", ctx=gl) as off:
        assert off.renderer.trails is not None
        off.renderer.trails.set([s.surface for s in faces.frames])
        img = off.render_frame(faces.happy).astype(int)
    assert _warm_saturated(img).sum() > 60


def test_heat_shows_displacement(offscreen: OffscreenRenderer, faces: Faces) -> None:
    at_rest = _render(offscreen, "heat", faces.rest)
    happy = _render(offscreen, "heat", faces.happy)
    assert _warm_saturated(at_rest).sum() == 0
    assert _warm_saturated(happy).sum() > 30
    assert _warm_saturated(_render(offscreen, "shaded", faces.happy)).sum() == 0


@pytest.mark.parametrize("view", VIEWS)
def test_every_view_renders_the_face(offscreen: OffscreenRenderer, faces: Faces, view: str) -> None:
    img = _render(offscreen, view, faces.happy)
    bg = img[2, 2]
    assert (np.abs(img - bg).sum(-1) > 40).mean() > 0.15


def test_hud_draws_text_and_bars(gl, faces: Faces) -> None:
    info = HudInfo(channels=[("jaw", 0.5, 0.0, 1.0)], age=64, devices=[("sgi:///dev/ttyS0", False)],
                   fps=59.9, latency_ms=12.5, lines=["press ? for help"])
    with OffscreenRenderer(faces.model, (480, 360), ctx=gl) as off:
        plain = off.render_frame(faces.rest).astype(int)
        hud = off.render_frame(faces.rest, hud=info).astype(int)
    diff = np.abs(hud - plain).sum(-1) > 60
    h, w = diff.shape
    corners = {"channels": diff[: h // 4, : w // 3], "status": diff[: h // 3, -w // 3:],
               "lines": diff[-h // 5:, : w // 2]}
    for name, region in corners.items():
        assert region.sum() > 40, name
    text = (hud.min(-1) > 200) & diff
    assert text.sum() > 100  # white glyphs
    lost = (hud[..., 0] > 180) & (hud[..., 1] < 110) & diff
    assert lost.sum() > 10  # the lost device is shown in red


def test_active_channels_lists_only_values_off_their_default() -> None:
    class Spec:
        def __init__(self, name: str, lo: float, hi: float, default: float) -> None:
            self.name, self.lo, self.hi, self.default = name, lo, hi, default

    specs = [Spec("jaw", 0, 1, 0), Spec("age", 20, 90, 30), Spec("eyes_yaw", -1, 1, 0)]
    assert active_channels(specs, [0.0, 45.0, -0.5]) == [("age", 45.0, 20.0, 90.0),
                                                        ("eyes_yaw", -0.5, -1.0, 1.0)]


def test_hud_readings_update_at_most_every_period(gl, faces: Faces) -> None:
    from render import hud as hud_mod

    now = [100.0]
    base = HudInfo(age=30, fps=10.0, latency_ms=5.0)
    with OffscreenRenderer(faces.model, (480, 360), ctx=gl) as off:
        off.renderer.hud.clock = lambda: now[0]
        first = off.render_frame(faces.rest, hud=base).astype(int)
        now[0] += 0.3 * hud_mod.NUMBER_PERIOD
        held = off.render_frame(faces.rest, hud=HudInfo(age=30, fps=88.8, latency_ms=77.7)).astype(int)
        now[0] += hud_mod.NUMBER_PERIOD
        moved = off.render_frame(faces.rest, hud=HudInfo(age=30, fps=88.8, latency_ms=77.7)).astype(int)
        gone = off.render_frame(faces.rest, hud=HudInfo(age=30)).astype(int)
        plain_age = off.render_frame(faces.rest, hud=HudInfo(age=30)).astype(int)
    assert np.array_equal(first, held)          # within the period the old readings stay
    assert np.abs(moved - first).sum(-1).max() > 100   # after it the new ones show
    assert np.array_equal(gone, plain_age)      # a reading that disappears goes at once


def test_hud_layer_composites_like_drawing_over_the_frame(gl, faces: Faces) -> None:
    """The cached HUD layer drawn again (content unchanged) gives the same pixels, and the HUD
    only changes pixels inside its panels."""
    info = HudInfo(channels=[("jaw", 0.5, 0.0, 1.0)], age=64, devices=[("kbd", True)],
                   lines=["press ? for help"])
    with OffscreenRenderer(faces.model, (480, 360), ctx=gl) as off:
        plain = off.render_frame(faces.rest).astype(int)
        once = off.render_frame(faces.rest, hud=info).astype(int)
        again = off.render_frame(faces.rest, hud=info).astype(int)
    assert np.array_equal(once, again)
    changed = np.abs(once - plain).sum(-1) > 0
    h, w = changed.shape
    assert not changed[h // 3: 2 * h // 3, w // 3: 2 * w // 3].any()   # the face in the middle is untouched
