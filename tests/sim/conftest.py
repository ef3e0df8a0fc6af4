"""Fixtures for the simulation tests: a small synthetic face (always) and the procedural default face
(once sim.face.builder exists)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from synthetic_face import synthetic_face  # noqa: E402

from sim.build import FaceModel, SkinParams, compile_model  # noqa: E402
from sim.model import FaceRig  # noqa: E402
from sim.face.placement import place_muscles  # noqa: E402


@pytest.fixture(scope="session")
def synth_rig() -> FaceRig:
    mesh = synthetic_face()
    return FaceRig(mesh=mesh, muscles=place_muscles(mesh), name="synthetic")


@pytest.fixture(scope="session")
def synth_model(synth_rig: FaceRig) -> FaceModel:
    return compile_model(synth_rig)


@pytest.fixture(scope="session")
def synth_model_nograv(synth_rig: FaceRig) -> FaceModel:
    return compile_model(synth_rig, SkinParams(gravity=False))


@pytest.fixture(scope="session")
def face_model() -> FaceModel:
    """The default face at resolution 0, gravity off (needs sim.face.builder)."""
    from sim.face import default_rig

    return compile_model(default_rig(0), SkinParams(gravity=False))
