"""Fixtures for the fit tests: the default face's basis (built once per session into a private
cache folder, which the commands run in-process then find), and data from ANOTHER resolution of the
face (res 1), so a test never fits the mesh that made its data."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(scope="session")
def fit_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.getbasetemp() / "fit-cache"
    os.environ["FACEPUPPET_CACHE"] = str(path)
    return path


@pytest.fixture(scope="session")
def face0(fit_cache: Path):  # type: ignore[no-untyped-def]
    from puppet.live import load_face

    return load_face(None)


@pytest.fixture(scope="session")
def basis0(face0):  # type: ignore[no-untyped-def]
    """(settler, basis, templates) of the default face at resolution 0."""
    from puppet.capture.cache import basis_for

    return basis_for(face0.model)


@pytest.fixture(scope="session")
def res1():  # type: ignore[no-untyped-def]
    """A settler of the default face at resolution 1 (another mesh, same landmarks)."""
    import sim.face
    from sim.fit.basis import Settler

    return Settler(sim.face.default_model(1))
