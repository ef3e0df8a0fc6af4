"""The lower lid's tightener (AU7) on an imported head sits on the head's own lower lid
(sim.face.transfer.lower_lid): the built-in face (resolution 0) with its eyes 3 mm lower, as a head
whose lids stand elsewhere than the skin correspondence put the reference's (seated or parted after
it) has them, with the reference's muscles left where they were. Left there, the tightener lifts
the lower lid about half as far as the reference's lifts its own; placed, as far, and the upper lid
stays where it is."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim.build import compile_model
from sim.face import default_rig
from sim.face.transfer.eyes import lid_chains
from sim.face.transfer.lower_lid import place_lower_lids
from sim.integrator import Simulator
from sim.model import FaceRig
from sim.state import FaceControl

DROP = 0.3  # cm: how much lower the head's eyes sit than the reference's


@pytest.fixture(scope="module")
def reference():
    return default_rig(0)


@pytest.fixture(scope="module")
def lowered(reference):
    """The reference's mesh with each eye, its lids and the skin within 1.5 cm of its axis moved
    DROP down (fading to nothing at 2.5 cm), and the reference's muscles where they were."""
    m = reference.mesh
    v = np.asarray(m.vertices, float).copy()
    centres = np.asarray(m.eye_centers, float).copy()
    for k in range(2):
        d = np.linalg.norm(v[:, :2] - centres[k, :2], axis=1)
        v[:, 1] -= DROP * np.clip(2.5 - d, 0.0, 1.0)
        centres[k, 1] -= DROP
    mesh = dataclasses.replace(m, vertices=v, eye_centers=centres)
    return FaceRig(mesh=mesh, muscles=dict(reference.muscles), wrinkles=reference.wrinkles, name="lowered")


def _lifts(rig: FaceRig) -> tuple[float, float]:
    """(lower, upper) lid margin's mean rise over its middle half (cm), the left tightener at 1."""
    model = compile_model(rig)
    sim = Simulator(model, wrinkles=False)
    rest = model.rest_state()
    sim.settle(rest, FaceControl(model), 1.5)
    control = FaceControl(model)
    control.set("orbicularis_oculi_lower_lid_l", 1.0)
    pose = rest.copy()
    sim.settle(pose, control, 1.5)
    m = rig.mesh
    upper, lower = lid_chains(np.asarray(m.vertices, float), m.eye_loops[0], m.landmark("eye_inner_l"),
                              m.landmark("eye_outer_l"))
    rise = pose.positions[:, 1] - rest.positions[:, 1]
    middle = lambda chain: chain[len(chain) // 4: 3 * len(chain) // 4]  # noqa: E731
    return float(rise[middle(lower)].mean()), float(rise[middle(upper)].mean())


def test_the_tightener_moves_with_the_lid_it_belongs_to(reference, lowered) -> None:
    muscles, notes = place_lower_lids(reference, lowered.mesh, lowered.muscles)
    for side in "lr":
        name = f"orbicularis_oculi_lower_lid_{side}"
        own, placed = reference.muscles[name][0], muscles[name][0]
        assert np.allclose(placed.center, np.asarray(own.center) - [0.0, DROP, 0.0], atol=1e-5)
        assert np.allclose(placed.semi_axes, own.semi_axes, atol=1e-5)  # the eye is as wide
        assert placed.scale == own.scale and np.allclose(placed.direction, own.direction)
    assert len(notes) == 2 and all("3.0 mm" in n for n in notes)
    others = [ch for ch in muscles if not ch.startswith("orbicularis_oculi_lower_lid")]
    assert all(muscles[ch] is lowered.muscles[ch] for ch in others)


def test_placed_it_lifts_the_lower_lid_as_the_references_does(reference, lowered) -> None:
    own, _ = _lifts(reference)
    left, _ = _lifts(lowered)
    muscles, _ = place_lower_lids(reference, lowered.mesh, lowered.muscles)
    placed, upper = _lifts(dataclasses.replace(lowered, muscles=muscles))
    assert own > 0.15  # the reference's own lower lid rises 1.9 mm
    assert left < 0.7 * own  # left where the correspondence put it: 1.1 mm
    assert abs(placed - own) < 0.15 * own
    assert abs(upper) < 0.02  # the upper lid stays
