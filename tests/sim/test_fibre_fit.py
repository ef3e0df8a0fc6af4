"""The lines-of-action fit (sim.face.scan.fibre_fit) on the synthetic face: its gradient in the
offsets is the objective's, the sides stay mirror images, and it finds where muscles pull from when
shapes were made by muscles pulling from elsewhere."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.build import compile_model
from sim.face.scan.calibrate import Shape
from sim.face.scan.fibre_fit import FibreCalibration, moved
from sim.model import LinearMuscle


def _shapes(cal: FibreCalibration, channels: list[str]) -> list[Shape]:
    out = []
    for ch in channels:
        v = np.zeros(len(cal.model.channels))
        v[cal.model.channel_index[ch]] = 1.0
        s = Shape(ch, ch, np.zeros((cal.n, 3)), v, None)
        s.target = cal.predict_all([s])[0]
        out.append(s)
    return out


def _linear_pair(cal: FibreCalibration) -> str:
    return next(c for c in cal.channels if c.endswith("_l") and isinstance(cal.parts[c][0], LinearMuscle)
                and (c, 0) in cal.index)


def test_offset_gradient_is_the_objectives(synth_model) -> None:  # type: ignore[no-untyped-def]
    cal = FibreCalibration(synth_model)
    ch = _linear_pair(cal)
    shapes = _shapes(cal, [ch, ch[:-2] + "_r"])
    vals = np.array([s.values for s in shapes])
    b = np.stack([1.3 * s.target.ravel() for s in shapes], axis=1)  # not the shapes themselves: a gradient
    w = np.array([1.0 / float(np.sum(s.target**2)) for s in shapes])
    x = np.concatenate([cal.gains, cal.theta])
    idx = cal.index[(ch, 0)]
    x[idx] = [0.2, -0.1, 0.15]
    _, grad = cal.joint_objective(x, vals, b, w)
    for i in idx:
        h = np.zeros_like(x)
        h[cal.n_params + i] = 1e-4
        num = (cal.joint_objective(x + h, vals, b, w)[0] - cal.joint_objective(x - h, vals, b, w)[0]) / 2e-4
        ana = grad[cal.n_params + i]
        assert abs(num - ana) < 0.02 * abs(ana) + 1e-8, (num, ana)


def test_sides_move_as_mirror_images(synth_model) -> None:  # type: ignore[no-untyped-def]
    cal = FibreCalibration(synth_model)
    ch = _linear_pair(cal)
    cal.theta[cal.index[(ch, 0)]] = [0.3, 0.2, -0.1]
    m = cal.muscles()
    dl = np.asarray(m[ch][0].attachment) - np.asarray(synth_model.rig.muscles[ch][0].attachment)
    dr = np.asarray(m[ch[:-2] + "_r"][0].attachment) - np.asarray(synth_model.rig.muscles[ch[:-2] + "_r"][0].attachment)
    assert np.allclose(dl, [0.3, 0.2, -0.1], atol=1e-6) and np.allclose(dr, [-0.3, 0.2, -0.1], atol=1e-6)


def test_fit_finds_where_a_muscle_pulls_from(synth_model) -> None:  # type: ignore[no-untyped-def]
    """Shapes made by a pair of linear muscles whose attachments sit 0.5 cm higher are out of reach
    of the insertion gains alone (the pull's direction differs) and within reach of this fit."""
    base = FibreCalibration(synth_model)
    ch = _linear_pair(base)
    pair = [ch, ch[:-2] + "_r"]
    shift = np.array([0.0, 0.5, 0.0])
    muscles = dict(synth_model.rig.muscles)
    for c in pair:
        muscles[c] = tuple(moved(p, shift) for p in muscles[c])
    truth = FibreCalibration(compile_model(replace(synth_model.rig, muscles=muscles), synth_model.params))
    shapes = _shapes(truth, pair)
    zero = {s.label: np.zeros_like(s.target) for s in shapes}

    def rel(cal: FibreCalibration) -> float:
        u = cal.predict_all(shapes)
        return max(float(np.linalg.norm(u[i] - s.target) / np.linalg.norm(s.target)) for i, s in enumerate(shapes))

    gains_only = FibreCalibration(synth_model, bound=0.0)
    gains_only.fit(shapes, zero, iters=60)
    fibres = FibreCalibration(synth_model, pull_offset=1e-6)
    fibres.fit(shapes, zero, iters=60)
    assert rel(fibres) < 0.5 * rel(gains_only)
    assert abs(fibres.theta[fibres.index[(ch, 0)]][1] - 0.5) < 0.2
