"""Faces and image helpers shared by the render tests. A module of its own (not conftest) so
`from render_faces import ...` cannot pick up another directory's conftest when several test
directories run in one session."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class Faces:
    """The default face at rest and holding 'happiness', plus the frames in between (for trails)."""

    model: Any
    rest: Any
    happy: Any
    frames: list[Any]


def simulate_faces() -> Faces:
    """The default face driven from rest into happiness the way a performer would."""
    from sim.face import default_model
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


def with_eyes(state: Any, yaw: float = 0.0, pitch: float = 0.0) -> Any:
    s = state.copy()
    s.eye_yaw, s.eye_pitch = yaw, pitch
    return s


def skin_mask(img: np.ndarray) -> np.ndarray:
    """Pixels of skin: warm (red well above blue); the neutral background is grey-blue."""
    f = img.astype(int)
    return (f[..., 0] - f[..., 2]) > 25
