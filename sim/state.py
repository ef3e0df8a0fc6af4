"""Per-step data: `FaceState` (what changes every step) and `FaceControl` (the inputs).

Kept apart from `FaceModel` (frozen, rest geometry) after warp.sim's Model/State/Control split, so a
recorder can snapshot a state or a control without touching the model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sim.channels import CHANNEL_INDEX, CHANNEL_NAMES, CHANNEL_SPECS, channel_spec, check_value

if TYPE_CHECKING:
    from sim.build import FaceModel


@dataclass(eq=False)
class FaceState:
    """positions, velocities (N,3) cm and cm/s: the dynamics. surface (N,3) cm: what is drawn
    (positions plus wrinkle bulges; equals positions until wrinkles exist). time in s. eye_yaw,
    eye_pitch, eye_vergence (-1..1), age (years) and the head's turn head_yaw, head_pitch, head_roll (-1..1, see
    sim.face.turn) are copied from the control at the last step so that a renderer needs only the
    state."""

    positions: np.ndarray
    velocities: np.ndarray
    surface: np.ndarray
    time: float = 0.0
    eye_yaw: float = 0.0
    eye_pitch: float = 0.0
    age: float = 30.0
    jaw: float = 0.0  # the jaw channel at the last step: a scanned head's teeth follow it when drawn
    head_yaw: float = 0.0
    head_pitch: float = 0.0
    head_roll: float = 0.0
    tongue_out: float = 0.0  # the tongue channel at the last step: a scanned head's tongue follows it
    eye_vergence: float = 0.0  # the eyes turned towards each other (sim.gaze_lids.eye_yaws)
    # the implicit integrator's contact memory after the last step (impulses and pairs its next step
    # starts from; sim.margin_contact.SolvedContact.memory), None before the first: a state copied
    # or restored carries it, so stepping on from a checkpoint gives the same bits as the original
    contact: np.ndarray | None = None

    def copy(self) -> FaceState:
        """An independent deep copy (arrays copied)."""
        return FaceState(
            self.positions.copy(),
            self.velocities.copy(),
            self.surface.copy(),
            self.time,
            self.eye_yaw,
            self.eye_pitch,
            self.age,
            self.jaw,
            self.head_yaw,
            self.head_pitch,
            self.head_roll,
            self.tongue_out,
            self.eye_vergence,
            None if self.contact is None else self.contact.copy(),
        )

    def assign(self, other: FaceState) -> None:
        """Overwrite this state with other's values, in place (keeps the array objects)."""
        self.positions[...] = other.positions
        self.velocities[...] = other.velocities
        self.surface[...] = other.surface
        self.time = other.time
        self.eye_yaw, self.eye_pitch, self.age = other.eye_yaw, other.eye_pitch, other.age
        self.jaw, self.tongue_out, self.eye_vergence = other.jaw, other.tongue_out, other.eye_vergence
        self.head_yaw, self.head_pitch, self.head_roll = other.head_yaw, other.head_pitch, other.head_roll
        self.contact = None if other.contact is None else other.contact.copy()


def rest_state(rest: np.ndarray) -> FaceState:
    """The state at rest: positions = rest, zero velocity, time 0, default eyes and age."""
    pos = np.array(rest, dtype=np.float64, copy=True)
    return FaceState(pos, np.zeros_like(pos), pos.copy(), 0.0, 0.0, 0.0, channel_spec("age").default)


class FaceControl:
    """Channel values aligned with `model.channels` (`values` (C,) float64), each within its range.

    Written by the channel mapping, read by the integrator. Unknown names and out-of-range values raise
    `sim.channels.ChannelError` (a ValueError) naming the valid choices.
    """

    def __init__(self, model: FaceModel | None = None) -> None:
        self.values = np.array([s.default for s in CHANNEL_SPECS], dtype=np.float64)

    def set(self, name: str, value: float) -> None:
        """Set one channel; checks name and range."""
        spec = channel_spec(name)
        self.values[CHANNEL_INDEX[name]] = check_value(spec, value)

    def get(self, name: str) -> float:
        """The current value of one channel."""
        channel_spec(name)
        return float(self.values[CHANNEL_INDEX[name]])

    def copy(self) -> FaceControl:
        """An independent copy."""
        out = FaceControl()
        out.values[...] = self.values
        return out

    def reset(self) -> None:
        """Every channel back to its default (all muscles relaxed, jaw closed, age 30)."""
        self.values[...] = [s.default for s in CHANNEL_SPECS]

    def as_dict(self) -> dict[str, float]:
        """Channel name -> value, in channel order."""
        return {n: float(v) for n, v in zip(CHANNEL_NAMES, self.values)}
