"""An imported head has no teeth of its own: its open mouth shows drawn teeth behind both lips
(render.meshdata.Cavity's dentition), where a face drawn without them shows only the dark."""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np
import pytest

from render.offscreen import OffscreenRenderer
from sim.build import compile_model
from sim.integrator import Simulator
from sim.state import FaceControl

SIZE = (240, 240)


@pytest.fixture(scope="module")
def open_mouth():
    """(imported model, the same model asking for no imported look, its state with the jaw open)."""
    from sim.face.transfer.synthetic import coarse_transferred_head

    rig = coarse_transferred_head()
    assert rig.presets.startswith("imported")
    model = compile_model(rig)
    plain = compile_model(dataclasses.replace(rig, presets=""))
    sim = Simulator(model, wrinkles=False)
    state = model.rest_state()
    control = FaceControl(model)
    control.set("jaw", 0.8)
    sim.settle(state, control, max_seconds=3.0)
    return model, plain, state


def _mouth_pixels(gl: moderngl.Context, model, state) -> tuple[np.ndarray, np.ndarray]:
    """(luminance of the pixels inside the open mouth's outline, their rows) in a frontal frame."""
    from sim.face.transfer.geometry import in_polygon

    with OffscreenRenderer(model, SIZE, ctx=gl) as off:
        img = off.render_frame(state, record=False).astype(float)
        loop = off.renderer.project(state.positions[model.mesh.mouth_loop], SIZE)
    ys, xs = np.mgrid[:SIZE[1], :SIZE[0]]
    inside = in_polygon(np.c_[xs.ravel(), ys.ravel()].astype(float), loop).reshape(SIZE[1], SIZE[0])
    return img[inside] @ [0.299, 0.587, 0.114], ys[inside]


def test_an_imported_heads_open_mouth_shows_teeth_above_and_below(gl: moderngl.Context, open_mouth) -> None:
    model, plain, state = open_mouth
    lum, rows = _mouth_pixels(gl, model, state)
    dark, _ = _mouth_pixels(gl, plain, state)
    assert len(lum) > 100  # the mouth is open in the frame
    bright = lum > 150
    assert bright.mean() > 0.1 and (dark > 150).mean() < 0.02
    mid = 0.5 * (rows.min() + rows.max())
    assert bright[rows < mid].any() and bright[rows > mid].any()  # upper and lower teeth
    assert (lum < 60).mean() > 0.1  # and the dark of the mouth between them
