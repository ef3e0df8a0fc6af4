"""The rig's insertion gains fitted on settled poses (`sim.fit.rig_settled`): the running simulator's
responses rewritten per bump, what a rig file stores, and the fit over several poses at once."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def settler():  # type: ignore[no-untyped-def]
    import sim.face
    from sim.fit.basis import Settler

    return Settler(sim.face.default_model(0), max_seconds=3.0, method="implicit")


GROUPS = ("zygomaticus_major", "depressor_labii")


def test_gains_one_are_the_rig_and_a_doubled_muscle_is_its_channel_at_twice_the_value(settler) -> None:  # type: ignore[no-untyped-def]
    """All gains 1 leave the settled pose as it was; one muscle's gains all at 2 settle where its
    channel at twice the value does (the step is linear in a muscle's force); restore undoes it."""
    from sim.fit.rig_settled import InsertionBumps

    rig = InsertionBumps(settler, GROUPS, 3)
    v = settler.values_for({"zygomaticus_major_l": 0.3, "depressor_labii_l": 0.4})
    p0 = settler.pose(v)
    rig.apply(np.ones(rig.n_params))
    np.testing.assert_allclose(settler.pose(v), p0, atol=1e-3)  # within the settling's own tolerance
    x = np.ones(rig.n_params)
    x[:3] = 2.0
    rig.apply(x)
    doubled = settler.pose(v)
    rig.restore()
    assert np.max(np.abs(doubled - p0)) > 0.05  # the pull doubled moves the skin
    np.testing.assert_allclose(doubled, settler.pose(settler.values_for({"zygomaticus_major_l": 0.6, "depressor_labii_l": 0.4})),
                               atol=1e-3)
    np.testing.assert_allclose(settler.pose(v), p0, atol=1e-3)  # within the settling's own tolerance


def test_the_written_insertion_settles_where_the_fit_measured(settler) -> None:  # type: ignore[no-untyped-def]
    """A rig compiled with `insertion(x)` settles as the running simulator did under gains x, on
    both sides (the right side's bumps mirror the left's and share their gains)."""
    from dataclasses import replace

    from sim.build import compile_model
    from sim.fit.basis import Settler
    from sim.fit.rig_settled import InsertionBumps

    rig = InsertionBumps(settler, GROUPS, 3)
    x = np.array([1.6, 0.5, 1.0, 0.7, 1.3, 1.0])
    v = settler.values_for({"zygomaticus_major_l": 0.5, "zygomaticus_major_r": 0.5, "depressor_labii_l": 0.5,
                            "depressor_labii_r": 0.5})
    rig.apply(x)
    fitted = settler.pose(v)
    rig.restore()
    model = settler.model
    written = Settler(compile_model(replace(model.rig, insertion=rig.insertion(x, model.rig.insertion)), model.params),
                      max_seconds=3.0, method="implicit")
    again = written.pose(v)
    assert np.max(np.abs(fitted - settler.pose(v))) > 0.02  # the gains change the pose
    np.testing.assert_allclose(again - written.rest, fitted - settler.rest, atol=1e-3)


def test_a_rig_made_with_other_gains_is_found_again_from_two_poses(settler) -> None:  # type: ignore[no-untyped-def]
    """Two poses settled under known gains are targets; the fit from gains 1 lowers the misfit at
    every accepted step and ends near them."""
    from sim.fit.rig_settled import InsertionBumps, Pose, fit_rig_settled

    rig = InsertionBumps(settler, ("zygomaticus_major",), 2)
    truth = np.array([1.5, 0.7])
    poses = []
    for name, values in (("smile", {"zygomaticus_major_l": 0.6}), ("both", {"zygomaticus_major_l": 0.4,
                                                                           "zygomaticus_major_r": 0.4})):
        v = settler.values_for(values)
        rig.apply(truth)
        target = settler.pose(v) - settler.rest
        rig.restore()
        poses.append(Pose(name, v, target))
    fit = fit_rig_settled(settler, rig, poses, np.ones(2), np.full(2, 0.2), np.full(2, 3.0), rounds=6)
    errors = [e for _, e in fit.history]
    assert errors[0] > 0.1
    assert all(b <= a for a, b in zip(errors, errors[1:]))
    assert fit.error < 0.3 * errors[0]
    np.testing.assert_allclose(fit.x, truth, atol=0.2)


def test_an_unsided_muscles_bumps_are_mirror_symmetric_and_a_partition_of_unity() -> None:
    """A muscle across the midline gets bumps that weigh each point as its mirror image (a fit on a
    left shape then moves the right side alike) and sum to 1 over its zone, 0 outside it."""
    from sim.fit.rig_settled import mirrored_bumps

    rng = np.random.default_rng(3)
    half = rng.uniform([0.05, -2.0, 0.0], [3.0, 2.0, 1.0], (200, 3))
    mid = np.column_stack([np.zeros(20), rng.uniform(-2.0, 2.0, 20), rng.uniform(0.0, 1.0, 20)])
    points = np.concatenate([half, half * np.array([-1.0, 1.0, 1.0]), mid])
    zone = np.abs(points[:, 1]) < 1.5
    phi = mirrored_bumps(points, zone, 4)
    assert phi.shape == (4, len(points))
    np.testing.assert_allclose(phi[:, :200], phi[:, 200:400], atol=1e-12)
    np.testing.assert_allclose(phi.sum(axis=0)[zone], 1.0, atol=1e-12)
    assert not phi[:, ~zone].any()
    assert np.all(phi.max(axis=1) > 0.5)  # four distinct bumps, not one smeared over the zone


def test_a_laxer_skin_about_the_mouth_lets_a_smile_move_further(settler) -> None:  # type: ignore[no-untyped-def]
    """The skin's bumps at 0 settle as the rig; the tether and modulus halved about the mouth corners
    let the same smile carry the corner further; the skin far from the bumps keeps its fields."""
    from sim.fit.rig_settled import SkinBumps

    model = settler.model
    rest = np.asarray(model.rest)
    v = settler.values_for({"zygomaticus_major_l": 0.8})
    smile = np.linalg.norm(settler.pose(v) - settler.rest, axis=1)
    corner = rest[np.argmax(smile)]  # where the smile moves the skin most
    skin = SkinBumps(model, [np.array([corner, corner * np.array([-1.0, 1.0, 1.0])])], sigma=1.0, method="implicit")
    same = skin.settler(np.zeros(2))
    np.testing.assert_allclose(same.pose(v) - same.rest, settler.pose(v) - settler.rest, atol=1e-3)
    lax = skin.settler(np.full(2, np.log(0.5)))
    moved = np.linalg.norm(lax.pose(v) - lax.rest, axis=1).max()
    assert moved > 1.05 * smile.max()
    far = np.linalg.norm(rest - corner, axis=1) > 6.0
    for field in ("tether", "modulus"):
        np.testing.assert_allclose(skin.skin(np.full(2, np.log(0.5)))[field][far & (rest[:, 0] > 0)],
                                   np.asarray(model.rig.skin.get(field, np.ones(len(rest))))[far & (rest[:, 0] > 0)],
                                   rtol=1e-3)
