"""Every filter and relative encoding on scripted input."""

from __future__ import annotations

import math

import numpy as np

import pytest
from hypothesis import given
from hypothesis import strategies as st

from puppet.mapping import filters as F

DT = 1.0 / 60.0


def run(f: F.Filter, xs: list[float]) -> list[float]:
    return [f.step(x, DT) for x in xs]


def test_range_remaps_and_clamps() -> None:
    f = F.RangeMap((0.2, 0.8), (0.0, 1.0))
    assert run(f, [0.2, 0.5, 0.8, 1.0, 0.0]) == pytest.approx([0.0, 0.5, 1.0, 1.0, 0.0])
    g = F.RangeMap((0.0, 1.0), (1.0, 0.5), clamp=False)
    assert g.step(2.0, DT) == pytest.approx(0.0)


def test_invert() -> None:
    assert run(F.Invert(), [0.0, 0.25, 1.0]) == [1.0, 0.75, 0.0]


def test_gamma_curve_keeps_ends_and_bends_middle() -> None:
    f = F.Curve(gamma=2.0)
    assert run(f, [0.0, 0.5, 1.0]) == pytest.approx([0.0, 0.25, 1.0])


def test_point_curve_interpolates() -> None:
    f = F.Curve(points=((0.0, 0.0), (0.5, 0.9), (1.0, 1.0)))
    assert run(f, [-1.0, 0.25, 0.75, 2.0]) == pytest.approx([0.0, 0.45, 0.95, 1.0])


def test_deadzone_is_flat_then_continuous() -> None:
    f = F.DeadZone(width=0.1, center=0.0)
    assert f.step(0.05, DT) == 0.0
    assert f.step(0.1000001, DT) == pytest.approx(0.0, abs=1e-5)
    assert f.step(1.0, DT) == pytest.approx(1.0)
    c = F.DeadZone(width=0.1, center=0.5)
    assert c.step(0.55, DT) == 0.5 and c.step(0.0, DT) == pytest.approx(0.0) and c.step(1.0, DT) == pytest.approx(1.0)


def test_smooth_rises_and_falls_at_their_own_speed() -> None:
    f = F.Smooth(rise=0.02, fall=0.5)
    f.reset(0.0)
    up = run(f, [1.0] * 6)
    assert 0.9 < up[-1] < 1.0 and all(a < b for a, b in zip(up, up[1:]))
    down = run(f, [0.0] * 6)
    # slow fall: after the same time it has lost much less than it gained
    assert 1.0 - down[-1] < 0.5 * up[-1]
    assert down[-1] > 0.7


def test_one_euro_smooths_jitter_but_follows_motion() -> None:
    f = F.OneEuro(min_cutoff=1.0, beta=0.0)
    f.reset(0.5)
    noisy = [0.5 + (0.02 if k % 2 else -0.02) for k in range(120)]
    out = run(f, noisy)
    assert max(abs(y - 0.5) for y in out[60:]) < 0.01
    fast = F.OneEuro(min_cutoff=1.0, beta=50.0)
    fast.reset(0.0)
    slow = F.OneEuro(min_cutoff=1.0, beta=0.0)
    slow.reset(0.0)
    ramp = [k / 30 for k in range(1, 31)]
    assert run(fast, ramp)[-1] > run(slow, ramp)[-1]  # speed lowers the lag


def test_slew_limits_rate() -> None:
    f = F.Slew(rate=6.0)  # 0.1 per tick at 60 Hz
    f.reset(0.0)
    out = run(f, [1.0] * 12)
    assert out[0] == pytest.approx(0.1) and out[9] == pytest.approx(1.0) and out[-1] == 1.0
    g = F.Slew(rate=6.0, fall=0.6)
    g.reset(1.0)
    assert g.step(0.0, DT) == pytest.approx(0.99)


def test_chain_static_value_skips_dynamic_stages() -> None:
    c = F.Chain([F.Invert(), F.Smooth(0.5, 0.5), F.Curve(gamma=2.0)])
    c.reset(0.0)
    assert c.static_value(0.25) == pytest.approx(0.75 ** 2)


@pytest.mark.parametrize(
    "encoding,raw,expected",
    [
        ("twos_complement", 1, 1), ("twos_complement", 127, -1), ("twos_complement", 120, -8),
        ("sign_magnitude", 3, 3), ("sign_magnitude", 65, -1), ("sign_magnitude", 67, -3),
        ("offset64", 64, 0), ("offset64", 65, 1), ("offset64", 61, -3),
        ("binary", 1, 1), ("binary", 127, -1), ("binary", 0, 0),
    ],
)
def test_relative_encodings(encoding: str, raw: int, expected: int) -> None:
    assert F.decode_relative(raw, encoding) == expected


def test_unknown_encoding_is_an_error() -> None:
    with pytest.raises(ValueError, match="twos_complement"):
        F.decode_relative(1, "gray")


@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=50))
def test_smoothing_filters_stay_within_input_hull(xs: list[float]) -> None:
    for f in (F.Smooth(0.1, 0.3), F.OneEuro(1.0, 0.5), F.Slew(3.0)):
        f.reset(xs[0])
        out = run(f, xs)
        assert all(min(xs) - 1e-12 <= y <= max(xs) + 1e-12 and math.isfinite(y) for y in out)


@pytest.mark.parametrize("with_one_euro", [False, True])
def test_a_settled_chain_gives_exactly_what_running_its_stages_would(with_one_euro: bool) -> None:
    # the chain stops running its stages once they settle; that shortcut must never change a value
    def stages() -> list:
        out = [F.DeadZone(0.02), F.Smooth(0.05, 0.2), F.Slew(3.0)]
        return out + [F.OneEuro(1.0, 0.5, 1.0)] if with_one_euro else out

    chain = F.Chain(stages())
    plain = stages()
    rng = np.random.default_rng(3)
    x, skipped = 0.0, 0
    for k in range(6000):
        if k % 1000 == 0:
            x = float(rng.uniform(0, 1))  # a move, then a long hold: the filters settle on it
        if k == 3500:
            chain.reset(0.3)
            y = 0.3
            for f in plain:
                f.reset(y)
                y = f.step(y, 0.0)
        skipped += chain.settled_at(x, 1 / 60)
        want = x
        for f in plain:
            want = f.step(want, 1 / 60)
        assert chain.step(x, 1 / 60) == want, k
    # smoothing (to the last bit) and slew settle within a few hundred ticks of a hold; the One-Euro
    # derivative estimate decays for longer before it stops changing
    assert skipped > (1000 if with_one_euro else 4000)
