"""The per-vertex insertion fit (sim.face.scan.insertion_fit) on the synthetic face: its gradient is
the objective's, and it finds gains that reproduce shapes made by known gains."""

from __future__ import annotations

import numpy as np

from sim.face.scan.calibrate import Shape
from sim.face.scan.insertion_fit import VertexCalibration


def _shapes(cal: VertexCalibration, gains: np.ndarray) -> list[Shape]:
    """One shape per muscle channel at full activation, made by the linear model at `gains`."""
    out = []
    for ch in cal.channels:
        v = np.zeros(len(cal.model.channels))
        v[cal.model.channel_index[ch]] = 1.0
        s = Shape(ch, ch, np.zeros((cal.n, 3)), v, None)
        s.target = cal.predict_all([s], gains)[0]
        out.append(s)
    return out


def _rel(cal: VertexCalibration, shapes: list[Shape]) -> float:
    u = cal.predict_all(shapes)
    return float(np.median([np.linalg.norm(u[i] - s.target) / np.linalg.norm(s.target) for i, s in enumerate(shapes)]))


def test_gradient_is_the_objectives(synth_model) -> None:  # type: ignore[no-untyped-def]
    cal = VertexCalibration(synth_model, smooth=1e-2, pull=1e-3)
    rng = np.random.default_rng(0)
    shapes = _shapes(cal, 1.0 + rng.random(cal.n_params))[:4]
    vals = np.array([s.values for s in shapes])
    b = np.stack([s.target.ravel() for s in shapes], axis=1)
    w = np.array([1.0 / float(np.sum(s.target**2)) for s in shapes])
    g = 0.5 + rng.random(cal.n_params)
    f0, grad = cal.objective(g, vals, b, w)
    for i in rng.choice(np.flatnonzero(np.abs(grad) > 1e-3 * np.abs(grad).max()), 5, replace=False):
        h = np.zeros_like(g)
        h[i] = 1e-5
        numeric = (cal.objective(g + h, vals, b, w)[0] - cal.objective(g - h, vals, b, w)[0]) / 2e-5
        assert numeric == np.float64(grad[i]) or abs(numeric - grad[i]) < 1e-4 * abs(grad[i]) + 1e-9


def test_fit_recovers_shapes_made_by_smooth_gains(synth_model) -> None:  # type: ignore[no-untyped-def]
    """Shapes made with each muscle inserting twice as densely on the upper half of its zone as on
    the lower are out of reach of the placed muscles (gain 1) and within reach of the fit."""
    cal = VertexCalibration(synth_model, smooth=1e-6, pull=1e-8)
    y = np.zeros(cal.n_params)
    for ch in cal.channels:
        y[cal.par[ch]] = cal.rest[cal.vert[ch], 1]
    truth = np.where(y > np.median(y), 2.0, 0.5)
    shapes = _shapes(cal, truth)[::6]  # a few muscles: seconds, not minutes
    before = _rel(cal, shapes)
    cal.fit(shapes, {s.label: np.zeros_like(s.target) for s in shapes}, iters=150)
    assert before > 0.2 and _rel(cal, shapes) < 0.2 * before
    written = cal.insertion()
    assert set(written) == set(cal.channels)
    assert all(g.shape == (cal.n,) and g.min() >= 0.0 for g in written.values())
