"""The compiled wrinkle layer on a synthetic patch of skin: bulges need age and compression, grow
with both, draw a crease, and do not depend on the mesh resolution."""

from __future__ import annotations

import numpy as np
import pytest

from sim.wrinkles.bulge import AGE_0
from sim.wrinkles.layer import compile_wrinkles, wrinkle_displacement
from sim.wrinkles.mask import WrinkleLine


def _patch(n: int, size: float = 6.0) -> tuple[np.ndarray, np.ndarray]:
    """A gently domed square patch of skin facing +Z, n x n vertices."""
    xs = np.linspace(-size / 2, size / 2, n)
    gx, gy = np.meshgrid(xs, xs)
    v = np.stack([gx.ravel(), gy.ravel(), -0.02 * (gx**2 + gy**2).ravel()], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return v, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


LINE = WrinkleLine("test", np.array([[-2.0, 0.0], [0.0, 0.05], [2.0, 0.0]]), ("m",), 0.5, 0.5)


def _squeeze(v: np.ndarray, factor: float) -> np.ndarray:
    """Compress the patch across the line (along Y) by `factor`, as a muscle would."""
    p = v.copy()
    p[:, 1] *= factor
    return p


@pytest.fixture(scope="module")
def patch() -> tuple[np.ndarray, np.ndarray]:
    return _patch(61)


def _height(layer, positions: np.ndarray, age: float) -> np.ndarray:
    return wrinkle_displacement(layer, positions, age)[:, 2]


def test_no_bulge_at_rest_or_when_stretched(patch) -> None:
    v, t = patch
    layer = compile_wrinkles(v, t, (LINE,))
    for age in (20, 50, 90):
        assert np.abs(wrinkle_displacement(layer, v, age)).max() == 0
        assert np.abs(wrinkle_displacement(layer, _squeeze(v, 1.1), age)).max() == 0


def test_no_bulge_before_age_0_and_growth_after(patch) -> None:
    v, t = patch
    layer = compile_wrinkles(v, t, (LINE,))
    p = _squeeze(v, 0.9)
    assert np.abs(wrinkle_displacement(layer, p, AGE_0 - 5)).max() == 0
    crests = [_height(layer, p, age).max() for age in (40, 55, 70, 85)]
    assert crests[0] > 0.005
    assert np.all(np.diff(crests) > 0)


def test_bulge_grows_with_compression(patch) -> None:
    v, t = patch
    layer = compile_wrinkles(v, t, (LINE,))
    crests = [_height(layer, _squeeze(v, f), 75).max() for f in (0.98, 0.95, 0.9, 0.8)]
    assert np.all(np.diff(crests) > 0)


def test_crease_lies_below_the_rolls(patch) -> None:
    """Across the line the surface rises on both sides and dips at the line itself."""
    v, t = patch
    layer = compile_wrinkles(v, t, (LINE,))
    p = _squeeze(v, 0.9)
    surf = p + wrinkle_displacement(layer, p, 75)
    column = np.abs(v[:, 0] - v[np.argmin(np.abs(v[:, 0] - 0.3)), 0]) < 1e-9
    ys, zs = p[column, 1], surf[column, 2] - p[column, 2]
    at_line = zs[np.argmin(np.abs(ys - 0.04))]
    above = zs[(ys > 0.1) & (ys < 0.45)].max()
    below = zs[(ys < -0.1) & (ys > -0.45)].max()
    assert above - at_line > 0.02 and below - at_line > 0.02
    assert zs[np.abs(ys) > 0.6].max() == 0  # nothing beyond the rolls


def test_resolution_independent_crest(patch) -> None:
    crests = []
    for n in (31, 61, 121):
        v, t = _patch(n)
        layer = compile_wrinkles(v, t, (LINE,))
        crests.append(_height(layer, _squeeze(v, 0.9), 75).max())
    assert max(crests) / min(crests) < 1.35, crests


def test_emphasis_scales_the_bulge(patch) -> None:
    v, t = patch
    strong = WrinkleLine("s", LINE.points, ("m",), 0.5, 0.5, emphasis=2.0)
    p = _squeeze(v, 0.95)
    h1 = _height(compile_wrinkles(v, t, (LINE,)), p, 60).max()
    h2 = _height(compile_wrinkles(v, t, (strong,)), p, 60).max()
    assert h2 > 1.2 * h1


def test_asymmetric_roll_leans_to_the_furrow(patch) -> None:
    v, t = patch
    width = 1.0
    line = WrinkleLine("a", LINE.points, ("m",), 0.0, width, asym_plus=True)
    sym = WrinkleLine("s", LINE.points, ("m",), 0.0, width)
    p = _squeeze(v, 0.9)
    column = np.abs(v[:, 0] - v[np.argmin(np.abs(v[:, 0] - 0.3)), 0]) < 1e-9
    ys = v[column, 1] - 0.05
    centroids = []
    for ln in (line, sym):
        zs = _height(compile_wrinkles(v, t, (ln,)), p, 75)[column]
        assert zs[ys < -0.15].max() == 0  # no roll on the other side
        centroids.append(np.sum(ys * zs) / np.sum(zs))
    assert abs(centroids[1] - width / 2) < 0.05
    assert centroids[0] < centroids[1] - 0.03


def test_line_round_trips_through_its_plain_form_and_rejects_bad_points() -> None:
    back = WrinkleLine.from_dict(LINE.to_dict())
    np.testing.assert_array_equal(back.points, LINE.points)
    assert (back.name, back.muscles, back.width_minus, back.width_plus) == (
        LINE.name, LINE.muscles, LINE.width_minus, LINE.width_plus)
    bad = LINE.to_dict()
    bad["points"] = [[0.0, 1.0, 2.0]]
    with pytest.raises(ValueError, match="points"):
        WrinkleLine.from_dict(bad)


def test_compiled_frame_matches_the_numpy_reference(patch) -> None:
    from sim.wrinkles.layer import compiled_displacement

    v, t = patch
    lines = (LINE, WrinkleLine("a", np.array([[-2.0, 1.2], [2.0, 1.3]]), ("m",), 0.3, 0.8,
                               asym_plus=True, emphasis=1.5),
             WrinkleLine("n", np.array([[-1.0, -1.5], [1.0, -1.5]]), ("m",), 0.0, 0.0))
    layer = compile_wrinkles(v, t, lines)
    rng = np.random.default_rng(5)
    for age in (30, 50, 85):
        p = _squeeze(v, 0.88) + rng.normal(0, 0.01, v.shape)
        ref = wrinkle_displacement(layer, p, age)
        got = compiled_displacement(layer, p, age)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)
        assert (np.abs(ref).max() > 0) == (age > AGE_0)


def test_unit_dilatation_has_the_bits_of_the_numpy_law() -> None:
    """The age's dilatation made on floats every frame the age dial moves is the very value of
    `dilatation(1.0, age)`: the same wrinkles' bits, beyond the ramp's ends and for NaN too."""
    import math

    from sim.wrinkles.bulge import dilatation
    from sim.wrinkles.layer import _unit_dilatation

    ages = list(np.linspace(-40.0, 160.0, 4001)) + [35.0, 90.0, math.inf, -math.inf, math.nan, 0.0, -0.0]
    for age in ages:
        want = np.float64(dilatation(1.0, float(age)))
        got = np.float64(_unit_dilatation(float(age)))
        assert got.tobytes() == want.tobytes(), age
