"""The wrinkles show in the pixels: an aged frown renders differently in the glabella, and mostly
there (offscreen EGL render through render.offscreen; skipped where no OpenGL context can be made)."""

from __future__ import annotations

import numpy as np
import pytest

from sim.build import compile_model
from sim.facs import apply_au
from sim.integrator import Simulator
from sim.face import default_rig
from sim.state import FaceControl

offscreen = pytest.importorskip("render.offscreen")

SIZE = (320, 320)


@pytest.fixture(scope="module")
def gl_ctx():
    try:
        ctx = offscreen.create_context()
    except Exception as err:  # no EGL / no Mesa: nothing to draw with
        pytest.skip(f"no offscreen OpenGL context: {err}")
    yield ctx
    ctx.release()


def test_aged_frown_differs_in_the_glabella(gl_ctx) -> None:
    model = compile_model(default_rig(0))
    sim = Simulator(model)
    states = {}
    for age in (30.0, 75.0):
        state = model.rest_state()
        control = FaceControl(model)
        apply_au(control, "AU4", 1.0)
        control.set("age", age)
        sim.settle(state, control, max_seconds=2.0)
        states[age] = state
    # the dynamics barely change with age (softer skin); take the young positions for both, so
    # the pixels differ only through the wrinkles drawn on top
    aged = states[30.0].copy()
    aged.age = 75.0
    from sim.wrinkles import apply_wrinkles

    apply_wrinkles(model, aged)
    assert np.abs(aged.surface - aged.positions).max() > 0.02
    with offscreen.OffscreenRenderer(model, SIZE, ctx=gl_ctx) as off:
        young_img = off.render_frame(states[30.0]).astype(float)
        old_img = off.render_frame(aged).astype(float)
        glab = model.rig.mesh.regions["glabella"]
        px = off.renderer.project(states[30.0].surface[glab], SIZE)
    assert gl_ctx.error == "GL_NO_ERROR"
    diff = np.abs(old_img - young_img).mean(axis=2)
    x0, y0 = np.floor(px.min(axis=0)).astype(int) - 2
    x1, y1 = np.ceil(px.max(axis=0)).astype(int) + 2
    inside = np.zeros(diff.shape, bool)
    inside[max(y0, 0):y1, max(x0, 0):x1] = True
    assert inside.sum() > 50
    assert diff[inside].max() > 10  # a visible change of shading somewhere in the glabella
    assert diff[inside].mean() > 1.0
    assert diff[inside].mean() > 3 * diff[~inside].mean()  # and it is where the frown creases
