"""Full-activation amplitudes of the AUs and presets against real faces and our stated FACS targets
(`sim.face.targets.TARGETS`, with their sources), on the default face at resolutions 0, 1 and 2
and on the coarse transferred head (437 vertices), gravity on. Each value is read in mm of a 90 mm outer-canthal-width adult."""

from __future__ import annotations

import pytest

from sim.face import targets as et
from sim.face import default_model
from sim.integrator import Simulator


@pytest.fixture(scope="module", params=[0, 1, 2])
def settled(request):
    model = default_model(request.param)
    out = {}
    for pose in sorted({t.pose for t in et.TARGETS}):
        sim = Simulator(model, wrinkles=False)
        state = model.rest_state()
        sim.settle(state, et.pose_control(pose), max_seconds=3.0)
        assert not sim.guard_events, pose
        out[pose] = state.positions.copy()
    return model, out


def test_every_target_is_met(settled) -> None:
    model, poses = settled
    misses = []
    for t in et.TARGETS:
        value = et.measure(t, model.mesh.landmarks, model.rest, poses[t.pose])
        if not t.lo <= value <= t.hi:
            misses.append(f"{t.pose} {t.landmark} {t.component} = {value:.2f} mm, want {t.lo}-{t.hi} ({t.source})")
    assert not misses, "\n".join(misses)


def test_left_and_right_move_alike(settled) -> None:
    """The targets name the left landmarks; the right ones are their mirrors."""
    model, poses = settled
    for t in et.TARGETS:
        if t.landmark.endswith("_l") and t.component in ("up", "down", "out", "in", "total"):
            right = et.Target(t.pose, t.landmark[:-2] + "_r", t.component, t.lo, t.hi, t.source)
            a, b = (et.measure(x, model.mesh.landmarks, model.rest, poses[t.pose]) for x in (t, right))
            assert abs(a - b) < 0.05 + 0.02 * abs(a), (t.pose, t.landmark, a, b)


def test_presets_differ_where_the_expressions_do(settled) -> None:
    """Sadness raises the inner brows only, surprise the whole brow; fear is not surprise with a
    wider mouth: its brows are raised less and drawn together, its lips stretched sideways."""
    model, poses = settled
    lm = model.mesh.landmarks

    def d(pose: str, name: str) -> dict[str, float]:
        return et.components(name, 10.0 * (poses[pose][lm[name]] - model.rest[lm[name]]))

    assert d("sadness", "brow_outer_l")["up"] < 0.4 * d("sadness", "brow_inner_l")["up"]
    assert d("surprise", "brow_outer_l")["up"] > 0.6 * d("surprise", "brow_inner_l")["up"] > 2.0
    assert d("fear", "brow_mid_l")["up"] < d("surprise", "brow_mid_l")["up"] - 1.5
    assert d("fear", "brow_inner_l")["in"] > d("surprise", "brow_inner_l")["in"] + 0.5
    assert d("fear", "mouth_corner_l")["out"] > d("surprise", "mouth_corner_l")["out"] + 2.0
    assert d("disgust", "chin")["down"] < 1.0 and d("disgust", "lower_lip_center")["down"] < 1.0


def test_transferred_head_meets_the_targets() -> None:
    from coarse_head import coarse_head_model

    model = coarse_head_model()
    misses = []
    for pose in sorted({t.pose for t in et.TARGETS}):
        sim = Simulator(model, wrinkles=False)
        state = model.rest_state()
        sim.settle(state, et.pose_control(pose), max_seconds=3.0)
        assert not sim.guard_events, pose
        for t in (t for t in et.TARGETS if t.pose == pose):
            value = et.measure(t, model.mesh.landmarks, model.rest, state.positions)
            if not t.lo <= value <= t.hi:
                misses.append(f"{t.pose} {t.landmark} {t.component} = {value:.2f} mm, want {t.lo}-{t.hi}")
    assert not misses, "\n".join(misses)
