"""Glue between the readers and `sim.fit`: the basis of a face (cached), a fit of a point
capture, a take's simulated motion; shared by `puppet fit`, `puppet recognize` and the benchmark."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from puppet.capture.points import PointCapture


def stderr_progress(what: str, i: int, n: int) -> None:
    if i == 1 or i == n:
        print(f"puppet: building the fit {what} from the simulator ({i}/{n}; cached afterwards)",
              file=sys.stderr)


def face_basis(face: Any, use_cache: bool = True) -> tuple[Any, Any, Any]:
    from puppet.capture.cache import basis_for

    return basis_for(face.model, stderr_progress, use_cache)


def fit_points(cap: PointCapture, settler: Any, basis: Any, options: Any = None, neutral: int | None | str = "auto") -> Any:
    """Fit a point capture; neutral: a frame index, None (the rig's rest) or "auto" (the reader's)."""
    from sim.fit.solve import Fitter, Track

    n = cap.neutral if neutral == "auto" else neutral
    track = Track(cap.times, cap.points, cap.vertices, n)
    return Fitter(basis, settler, options).fit(track)


def simulate_take(face: Any, values: np.ndarray, rate: float, every: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(times (T,), positions (T, N, 3)) of every `every`-th tick of a replay of `values`."""
    import sim

    simulator = sim.Simulator(face.model, 1.0 / rate, wrinkles=False)
    control = sim.FaceControl(face.model)
    state = face.model.rest_state()
    times, frames = [], []
    for k in range(len(values)):
        control.values[...] = values[k]
        simulator.step(state, control)
        if (k + 1) % every == 0:
            times.append((k + 1) / rate)
            frames.append(state.positions.copy())
    return np.array(times), np.array(frames)
