"""The skin's material fit (sim.face.scan.skin_fit) on the synthetic face: its gradient in the
fields is the objective's, the linear model it fits is the compiled face's, and it finds skin that
reproduces shapes made by a known lax region."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.build import compile_model
from sim.face.scan.calibrate import Shape
from sim.face.scan.skin_fit import SkinCalibration


def _shapes(cal: SkinCalibration, theta: np.ndarray) -> list[Shape]:
    """One shape per muscle channel at full activation, made by the linear model at `theta`."""
    out = []
    keep = cal.theta.copy()
    cal.factor(theta)
    for ch in cal.channels:
        v = np.zeros(len(cal.model.channels))
        v[cal.model.channel_index[ch]] = 1.0
        s = Shape(ch, ch, np.zeros((cal.n, 3)), v, None)
        s.target = cal.predict_all([s])[0]
        out.append(s)
    cal.factor(keep)
    return out


def _problem(cal: SkinCalibration, shapes: list[Shape]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    vals = np.array([s.values for s in shapes])
    b = np.stack([s.target.ravel() for s in shapes], axis=1)
    w = np.array([1.0 / float(np.sum(s.target**2)) for s in shapes])
    return vals, b, w


def test_gradient_in_the_fields_is_the_objectives(synth_model) -> None:  # type: ignore[no-untyped-def]
    cal = SkinCalibration(synth_model, bumps=6)
    rng = np.random.default_rng(1)
    shapes = _shapes(cal, 0.5 * rng.standard_normal(len(cal.theta)))[:5]
    vals, b, w = _problem(cal, shapes)
    x = np.concatenate([0.5 + rng.random(cal.n_params), 0.3 * rng.standard_normal(len(cal.theta))])
    _, grad = cal.joint_objective(x, vals, b, w)
    for i in cal.n_params + np.arange(len(cal.theta)):
        h = np.zeros_like(x)
        h[i] = 1e-6
        numeric = (cal.joint_objective(x + h, vals, b, w)[0] - cal.joint_objective(x - h, vals, b, w)[0]) / 2e-6
        assert abs(numeric - grad[i]) < 1e-4 * np.abs(grad[cal.n_params:]).max()


def test_the_fields_written_are_the_linear_models_skin(synth_model) -> None:  # type: ignore[no-untyped-def]
    """The rig's skin multipliers, compiled, give the stiffness the fit's linear model used: a
    muscle's settled displacement under the compiled face's stiffness matches the model's."""
    from sim.face.scan.calibrate import _stiffness

    cal = SkinCalibration(synth_model, bumps=6)
    cal.theta = np.random.default_rng(2).uniform(-1.0, 1.0, len(cal.theta))
    cal.factor(cal.theta)
    shape = _shapes(cal, cal.theta)[0]
    compiled = compile_model(replace(synth_model.rig, skin=cal.skin()), synth_model.params)
    lu, free = _stiffness(compiled)
    f = cal._forces(cal.gains, np.array([shape.values]))[:, 0]
    u = np.zeros_like(f)
    u[free] = lu.solve(f[free])
    assert np.linalg.norm(u - shape.target.ravel()) < 1e-3 * np.linalg.norm(shape.target)


def test_fit_finds_a_lax_region(synth_model) -> None:  # type: ignore[no-untyped-def]
    """Shapes made on skin whose attachment is ten times laxer on the upper face than below are
    out of reach of uniform skin at the placed insertions and within reach of the fit."""
    cal = SkinCalibration(synth_model, bumps=6, fields=("tether", "support"))
    y = cal.rest[:, 1]
    lax = np.where(y > np.median(y), np.log(0.1), 0.0)
    # the truth in the fit's own basis: least squares of the bumps onto the lax field
    t = np.linalg.lstsq(cal.basis.toarray(), lax, rcond=None)[0]
    shapes = _shapes(cal, np.concatenate([t, t]))[::5]
    zero = {s.label: np.zeros_like(s.target) for s in shapes}
    before = float(np.median([np.linalg.norm(u - s.target) / np.linalg.norm(s.target)
                              for u, s in zip(cal.predict_all(shapes), shapes)]))
    cal.fit(shapes, zero, iters=80)
    after = float(np.median([np.linalg.norm(u - s.target) / np.linalg.norm(s.target)
                             for u, s in zip(cal.predict_all(shapes), shapes)]))
    assert before > 0.05 and after < 0.3 * before
    assert cal.multipliers()["tether"][y > np.quantile(y, 0.8)].mean() < 0.5
