"""sim.fit: Procrustes, the bounded fit on data from another resolution, recognition."""

from __future__ import annotations

import numpy as np
import pytest
from fitdata import correspond, rotation

from sim.fit.align import rms, similarity
from sim.fit.basis import preset_values
from sim.fit.recognize import NEUTRAL, activation_scores, segment, template_scores
from sim.fit.solve import FitOptions, Fitter, Track


def test_similarity_recovers_a_rotated_scaled_translated_copy() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(40, 3))
    r = rotation(0.7, -0.3, 0.2)
    y = 3.7 * x @ r.T + np.array([5.0, -2.0, 1.0])
    t = similarity(x, y)
    assert t.scale == pytest.approx(3.7, rel=1e-9)
    assert np.allclose(t.rotation, r, atol=1e-9)
    assert rms(t.apply(x), y) < 1e-9
    rigid = similarity(x, y, scale=False)
    assert rigid.scale == 1.0 and np.allclose(rigid.rotation, r, atol=1e-9)


def test_similarity_never_returns_a_reflection() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(size=(30, 3))
    mirrored = x * np.array([-1.0, 1.0, 1.0])
    t = similarity(x, mirrored)
    assert np.linalg.det(t.rotation) == pytest.approx(1.0)


def _data(res1, model0, vertices, truths, hold: int = 1):  # type: ignore[no-untyped-def]
    """Frame 0 at rest, then each truth's settled pose held for `hold` frames (a take that holds
    each pose, so temporal smoothing sees a steady pose)."""
    near = correspond(model0, res1.model, vertices)
    frames = [res1.rest[near]] * hold
    for truth in truths:
        frames += [res1.pose(res1.values_for(truth))[near]] * hold
    return np.array(frames)


CASES = [
    {"zygomaticus_major_l": 0.8, "zygomaticus_major_r": 0.8},
    {"frontalis_inner_l": 0.6, "frontalis_inner_r": 0.6, "corrugator_l": 0.4},
    {"depressor_anguli_oris_r": 0.9, "mentalis": 0.5},
]


def test_known_activations_come_back_from_another_resolution(basis0, res1, face0) -> None:  # type: ignore[no-untyped-def]
    """Data from the resolution-1 face. Its muscle fields are not exactly the rig's, so the test is
    the one analysis by synthesis promises: the activations are close, the strongest true channel
    is found, and re-simulating the fitted activations on the rig reproduces the observed motion."""
    settler, basis, _ = basis0
    model = face0.model
    landmarks = np.array(sorted(model.mesh.landmarks.values()))
    random68 = np.random.default_rng(2).choice(np.flatnonzero(~model.held), 68, replace=False)
    for verts in (landmarks, random68):
        pts = _data(res1, model, verts, CASES, hold=5)
        result = Fitter(basis, settler, FitOptions()).fit(Track(np.arange(len(pts)) / 30.0, pts, verts, 0))
        assert result.reports[0].active == ()  # the neutral frame
        assert all(r.residual_mm < 1.0 for r in result.reports)
        for k, truth in enumerate(CASES, start=1):
            want = np.array([truth.get(c, 0.0) for c in basis.channels])
            got = result.activations[5 * k + 2]
            shown = dict(zip(basis.channels, got.round(2)))
            assert np.abs(got - want).mean() < 0.08, (truth, shown)
            top = max(truth, key=truth.get)
            assert got[basis.channels.index(top)] == pytest.approx(truth[top], abs=0.25), (truth, shown)
            observed = result.displacements[5 * k + 2]
            synth = settler.pose(settler.values_for(dict(zip(basis.channels, got)))) - settler.rest
            err = np.sqrt(np.mean(np.sum((synth[verts] - observed) ** 2, axis=1)))
            assert err < 0.35 * np.sqrt(np.mean(np.sum(observed**2, axis=1))), (truth, shown)


def test_head_motion_and_units_do_not_change_the_fit(basis0, res1, face0) -> None:  # type: ignore[no-untyped-def]
    settler, basis, _ = basis0
    model = face0.model
    verts = np.array(sorted(model.mesh.landmarks.values()))
    pts = _data(res1, model, verts, CASES[:2], hold=2)
    moved = np.array([10.0 * f @ rotation(0.1 * k, -0.05 * k, 0.03).T + np.array([3.0, -1.0, 40.0 + k])
                      for k, f in enumerate(pts)])
    opts = FitOptions(relinearise=None)
    plain = Fitter(basis, None, opts).fit(Track(np.arange(6.0), pts, verts, 0))
    fitted = Fitter(basis, None, opts).fit(Track(np.arange(6.0), moved, verts, 0))
    assert np.allclose(plain.activations, fitted.activations, atol=0.02)
    assert fitted.neutral.scale == pytest.approx(0.1, rel=1e-3)
    assert max(r.rotation_degrees for r in fitted.reports) > 5.0  # the head's motion was found and removed


def test_relinearising_never_explains_the_data_worse(basis0, res1, face0) -> None:  # type: ignore[no-untyped-def]
    settler, basis, _ = basis0
    model = face0.model
    verts = np.flatnonzero(~model.held)[::3]
    combo = {**preset_values("happiness", 1.0), **preset_values("surprise", 0.8)}
    pts = _data(res1, model, verts, [combo])
    track = Track(np.array([0.0, 1.0]), pts, verts, 0)
    lin = Fitter(basis, None, FitOptions(relinearise=None)).fit(track)
    rel = Fitter(basis, settler, FitOptions(relinearise=0.0, min_mm=0.0)).fit(track)
    assert rel.reports[1].relinearised and rel.settles >= 1
    assert rel.reports[1].residual_mm <= lin.reports[1].residual_mm + 1e-9


def test_templates_recognise_presets_from_another_resolution(basis0, res1, face0) -> None:  # type: ignore[no-untyped-def]
    settler, basis, tpl = basis0
    verts = np.array(sorted(face0.model.mesh.landmarks.values()))
    names = list(tpl.names)
    truths = [preset_values(n, 0.6) for n in names]
    pts = _data(res1, face0.model, verts, truths)
    disp = pts - pts[0]
    scores = template_scores(disp, tpl, verts)
    labels = [*names, NEUTRAL]
    assert labels[int(np.argmax(scores[0]))] == NEUTRAL
    for k, n in enumerate(names, start=1):
        assert labels[int(np.argmax(scores[k]))] == n, (n, dict(zip(labels, scores[k].round(2))))
    acts = np.array([[t.get(c, 0.0) for c in basis.channels] for t in [{}] + truths])
    by_acts = activation_scores(acts, tpl)
    assert [labels[int(i)] for i in np.argmax(by_acts, axis=1)] == [NEUTRAL, *names]


def test_segments_follow_the_winner_with_every_score() -> None:
    times = np.arange(120) / 60.0
    scores = np.zeros((120, 3))
    scores[:40, 2] = 1.0
    scores[40:, 0] = 0.9
    scores[40:, 1] = 0.2
    scores[70, 1] = 5.0  # one frame's blip is not a span
    spans = segment(times, scores, ("a", "b"))
    assert [s.expression for s in spans] == [NEUTRAL, "a"]
    assert spans[1].start == pytest.approx(40 / 60.0, abs=2 / 60.0)  # within the smoothing window
    assert set(spans[1].scores) == {"a", "b", NEUTRAL}
