"""The displacement basis: what each channel does to the skin, measured on the simulator.

Column c is the settled displacement of every vertex with channel c at `amplitude` (all others at
rest) minus the settled rest pose (which includes the sag under gravity), divided by the
amplitude: a chord of the channel's response, in cm per unit activation. Nothing here is a stored
number; everything is settled from whatever model is given, so a retuned face gets its own basis.

Expression templates (seed 000 section 6, "templates of optical flow") are the settled
displacements of each preset of `sim.facs.EXPRESSIONS` at a few weights.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sim.channels import CHANNEL_SPECS

DEFAULT_AMPLITUDE = 0.5
TEMPLATE_WEIGHTS = (0.4, 1.0)
SETTLE_SECONDS = 4.0

Progress = Callable[[int, int], None]


def fit_channels() -> tuple[str, ...]:
    """The channels a fit solves for: every muscle and the jaw (the eyes and age do not move the
    skin in a way a displacement fit can see)."""
    return tuple(s.name for s in CHANNEL_SPECS if s.kind in ("muscle", "jaw"))


class Settler:
    """Settled poses of one model: `pose(values)` -> (N, 3) positions at rest under those channel
    values, starting from the nearest pose settled before (fewer steps, same equilibrium)."""

    def __init__(self, model: object, max_seconds: float = SETTLE_SECONDS, method: str = "auto") -> None:
        from sim.integrator import Simulator
        from sim.state import FaceControl

        self.model = model
        self.sim = Simulator(model, wrinkles=False, method=method)
        # the fits change the implicit step's float64 responses in place (sim.fit.rig_settled,
        # benchmarks/anchor_limits.py, sided_limits.py): read them, not a float32 copy made before
        self.sim.single_responses = False
        self.control = FaceControl(model)
        self.defaults = self.control.values.copy()
        self.max_seconds = max_seconds
        state = model.rest_state()  # type: ignore[attr-defined]
        self.sim.settle(state, self.control, max_seconds)
        self.rest_state = state
        self.rest = state.positions.copy()
        self.settles = 1

    def pose(self, values: np.ndarray, start: object | None = None) -> np.ndarray:
        """Settled positions (N, 3) for a full channel array (C,) in the model's channel order."""
        state = (start or self.rest_state).copy()  # type: ignore[attr-defined]
        state.velocities[...] = 0.0
        self.control.values[...] = values
        self.sim.settle(state, self.control, self.max_seconds)
        self.settles += 1
        self.last_state = state
        return state.positions.copy()

    def values_for(self, activations: dict[str, float]) -> np.ndarray:
        """A full channel array: the defaults with the named channels set."""
        from sim.channels import CHANNEL_INDEX

        out = self.defaults.copy()
        for name, v in activations.items():
            out[CHANNEL_INDEX[name]] = v
        return out


@dataclass
class Basis:
    """channels: names (K,); hi: (K,) upper bounds; rest: (N, 3) settled rest, cm;
    columns: (K, N, 3) displacement per unit activation, cm; amplitude: the activation it was
    measured at; model_hash: the model it belongs to."""

    channels: tuple[str, ...]
    hi: np.ndarray
    rest: np.ndarray
    columns: np.ndarray
    amplitude: float
    model_hash: str

    def matrix(self, points: np.ndarray | None = None) -> np.ndarray:
        """(3P, K) matrix of the columns at the given vertex indices (all vertices if None), rows
        ordered x0, y0, z0, x1, ..."""
        cols = self.columns if points is None else self.columns[:, points, :]
        return cols.reshape(len(self.channels), -1).T

    def predict(self, a: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """Linear displacement (P, 3) for activations a (K,)."""
        m = self.matrix(points) @ np.asarray(a, float)
        return m.reshape(-1, 3)


def build_basis(settler: Settler, channels: Sequence[str] | None = None,
                amplitude: float = DEFAULT_AMPLITUDE, progress: Progress | None = None) -> Basis:
    """Settle each channel alone at `amplitude` and keep its displacement per unit activation."""
    from sim.channels import channel_spec

    names = tuple(channels or fit_channels())
    cols = np.empty((len(names), *settler.rest.shape))
    for i, name in enumerate(names):
        pos = settler.pose(settler.values_for({name: amplitude}))
        cols[i] = (pos - settler.rest) / amplitude
        if progress:
            progress(i + 1, len(names))
    hi = np.array([channel_spec(n).hi for n in names])
    return Basis(names, hi, settler.rest.copy(), cols, amplitude, str(getattr(settler.model, "hash", "")))


def preset_values(name: str, weight: float = 1.0, face: str | None = None) -> dict[str, float]:
    """The channel values a preset sets at a weight (through `sim.facs.apply_expression`), only
    the channels it moves; `face` (`sim.facs.preset_face` of a rig) picks the face's own
    intensities, None the shared table."""
    from sim.facs import apply_expression
    from sim.state import FaceControl

    c = FaceControl()
    base = c.values.copy()
    apply_expression(c, name, weight, face)
    return {CHANNEL_SPECS[i].name: float(c.values[i]) for i in np.flatnonzero(c.values != base)}


@dataclass
class Templates:
    """names: preset names (E,); weights: the weights each was settled at (W,);
    fields: (E, W, N, 3) settled displacement, cm; activations: (E, K) the preset's channel vector
    at weight 1 over `channels`."""

    names: tuple[str, ...]
    weights: tuple[float, ...]
    fields: np.ndarray
    channels: tuple[str, ...]
    activations: np.ndarray


def build_templates(settler: Settler, weights: Sequence[float] = TEMPLATE_WEIGHTS,
                    channels: Sequence[str] | None = None, progress: Progress | None = None) -> Templates:
    """The settled displacement of every preset at each weight (the seed's flow templates), at
    the intensities the settler's face plays them with (`sim.facs.FACE_EXPRESSIONS`: the scanned
    head's surprise raises the lids, its sadness leaves the outer brows; the templates were the
    shared table's, so a take's own presets were matched against other poses)."""
    from sim.facs import EXPRESSIONS, preset_face

    face = preset_face(getattr(settler.model, "rig", None))
    names = tuple(EXPRESSIONS)
    chans = tuple(channels or fit_channels())
    fields = np.empty((len(names), len(weights), *settler.rest.shape))
    acts = np.zeros((len(names), len(chans)))
    step = 0
    for e, name in enumerate(names):
        for w, weight in enumerate(weights):
            fields[e, w] = settler.pose(settler.values_for(preset_values(name, weight, face))) - settler.rest
            step += 1
            if progress:
                progress(step, len(names) * len(weights))
        for ch, v in preset_values(name, 1.0, face).items():
            if ch in chans:
                acts[e, chans.index(ch)] = v
    return Templates(names, tuple(float(w) for w in weights), fields, chans, acts)
