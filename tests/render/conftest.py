"""One EGL context for the whole render test session (creating contexts is slow on llvmpipe), checked
for GL errors around every test, and the faces the tests draw."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import moderngl
import numpy as np
import pytest

from render.offscreen import OffscreenRenderer, create_context


@pytest.fixture(scope="session")
def gl_session() -> Iterator[moderngl.Context]:
    ctx = create_context()
    yield ctx
    ctx.release()


@pytest.fixture()
def gl(gl_session: moderngl.Context) -> Iterator[moderngl.Context]:
    """The shared context, asserting no GL error is left before or after the test."""
    assert gl_session.error == "GL_NO_ERROR"
    yield gl_session
    assert gl_session.error == "GL_NO_ERROR"


@dataclass
class Faces:
    """The default face at rest and holding 'happiness', plus the frames in between (for trails)."""

    model: Any
    rest: Any
    happy: Any
    frames: list[Any]


def _simulate() -> Faces:
    """The default face driven from rest into happiness the way a performer would."""
    from sim import default_model
    from sim.facs import apply_expression
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = default_model(0)
    rest = model.rest_state()
    sim = Simulator(model)
    state = rest.copy()
    frames = [state.copy()]
    for k in range(1, 46):  # a performer turning the dial up over half a second
        control = FaceControl(model)
        apply_expression(control, "happiness", min(k / 30, 1.0))
        sim.step(state, control)
        frames.append(state.copy())
    sim.settle(state, control)
    return Faces(model, rest, state, frames)


@pytest.fixture(scope="session")
def faces() -> Faces:
    return _simulate()


@pytest.fixture()
def offscreen(gl: moderngl.Context, faces: Faces) -> Iterator[OffscreenRenderer]:
    off = OffscreenRenderer(faces.model, (200, 150), ctx=gl)
    yield off
    off.release()


def with_eyes(state: Any, yaw: float = 0.0, pitch: float = 0.0) -> Any:
    s = state.copy()
    s.eye_yaw, s.eye_pitch = yaw, pitch
    return s


def skin_mask(img: np.ndarray) -> np.ndarray:
    """Pixels of skin: warm (red well above blue); the neutral background is grey-blue."""
    f = img.astype(int)
    return (f[..., 0] - f[..., 2]) > 25
