"""The fit on settled poses (`sim.fit.settled`): Levenberg-Marquardt whose Jacobian is taken from
the simulator's settled poses about the current one."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def settler():  # type: ignore[no-untyped-def]
    import sim.face
    from sim.fit.basis import Settler

    return Settler(sim.face.default_model(0), max_seconds=3.0)


CHANNELS = ("zygomaticus_major_l", "depressor_labii_l", "risorius_l", "buccinator_l")


def test_a_pose_made_of_channels_is_recovered_from_its_settled_displacement(settler) -> None:  # type: ignore[no-untyped-def]
    """A settled pose of two channels (a smile on the left with the lower lip drawn down) is found
    again from a start at rest among four channels: the other two stay near 0, every accepted step
    lowers the settled misfit, and the result settled from rest matches the target."""
    from sim.fit.settled import fit_settled

    truth = np.array([0.7, 0.4, 0.0, 0.0])

    def values(x: np.ndarray) -> np.ndarray:
        return settler.values_for(dict(zip(CHANNELS, (float(v) for v in x))))

    target = settler.pose(values(truth)) - settler.rest
    fit = fit_settled(settler, values, target, np.zeros(4), np.zeros(4), np.ones(4), rounds=6)
    errors = [e for _, e in fit.history]
    assert errors[0] == pytest.approx(1.0, abs=0.02)  # at rest: as wrong as not moving
    assert all(b <= a for a, b in zip(errors, errors[1:]))
    assert fit.error < 0.08
    np.testing.assert_allclose(fit.x, truth, atol=0.12)
    again = settler.pose(values(fit.x)) - settler.rest
    assert np.linalg.norm(again - target) / np.linalg.norm(target) < 0.1


def test_the_bounds_hold(settler) -> None:  # type: ignore[no-untyped-def]
    """A target beyond what the channel's range reaches ends at the bound, not past it."""
    from sim.fit.settled import fit_settled

    def values(x: np.ndarray) -> np.ndarray:
        return settler.values_for({"zygomaticus_major_l": float(x[0])})

    target = 1.6 * (settler.pose(values(np.array([0.5]))) - settler.rest)
    fit = fit_settled(settler, values, target, np.array([0.1]), np.array([0.0]), np.array([0.6]), rounds=4)
    assert 0.0 <= fit.x[0] <= 0.6
    assert fit.x[0] == pytest.approx(0.6, abs=1e-6)
