"""Fixtures shared by every test package."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator

import pytest

# compiled faces are cached in a private folder for this run, never in the user's cache
# (subprocesses inherit it); removed at the end of the run
_FACE_CACHE = os.environ["PUPPET_CACHE_DIR"] = __import__("tempfile").mkdtemp(prefix="puppet-test-cache-")
# recordings made by tests are registered in a take library inside that folder, never the user's
os.environ["PUPPET_LIBRARY"] = os.path.join(_FACE_CACHE, "takes.db")
# so are the fit's basis (puppet/capture/cache.py: ~/.cache/facepuppet otherwise, which tests/files'
# in-process `puppet fit` runs wrote before tests/fit/conftest.py named its own folder, and which
# another run of the suite or the user's shows rewrite meanwhile) and saved identities (`--face NAME`
# reads them: a user's saved face must not change what a test sees)
os.environ["FACEPUPPET_CACHE"] = os.path.join(_FACE_CACHE, "fit")
os.environ["PUPPET_DATA_DIR"] = os.path.join(_FACE_CACHE, "identities")


# the suite's own fixtures and expectations are the procedural face's unless a test asks for another
# (--face, or PUPPET_FACE in its environment); tests of the scanned head name it
os.environ.setdefault("PUPPET_FACE", "procedural")

# property tests judge results, never speed: on a shared machine a draw can stall for seconds while
# other programs run, which is no fault of the code under test
try:
    from hypothesis import HealthCheck, settings

    settings.register_profile("suite", deadline=None, suppress_health_check=[HealthCheck.too_slow])
    settings.load_profile("suite")
except ImportError:  # pragma: no cover - hypothesis is a test dependency
    pass


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if os.path.basename(_FACE_CACHE).startswith("puppet-test-cache-"):
        shutil.rmtree(_FACE_CACHE, ignore_errors=True)


@pytest.fixture(scope="session")
def xvfb_display() -> Iterator[str]:
    """A private Xvfb server; yields its DISPLAY string (e.g. ':93'). Needs the xvfb package,
    which .ci/setup installs; the test fails (not skips) without it."""
    from xvfb_server import start_xvfb, stop_xvfb

    try:
        proc, display = start_xvfb()
    except RuntimeError as err:
        pytest.fail(str(err))
    try:
        yield display
    finally:
        stop_xvfb(proc)


@pytest.fixture
def arkit_expressible():  # type: ignore[no-untyped-def]
    """A function making a pose one the ARKit shapes can carry (in place, values (..., C) in the
    order of `names`): each calibrated shape's channels within its span (`SHAPE_SPAN`), and each
    share (`SHAPE_SHARES`) at least its share of the shape, and the lips' lift mouthClose's own weight, as a
    stream of shapes gives it."""
    import numpy as np

    from puppet.capture.arkit_in import share_targets, shape_targets
    from puppet.export.arkit import ARKIT_SHAPES, MOUTH_CLOSE_LIFT, MOUTH_CLOSE_SPAN, SHAPE_SHARES, SHAPE_SPAN

    def base(shape: str) -> str:
        return shape.removesuffix("Left").removesuffix("Right")

    def expressible(values: np.ndarray, names: list[str]) -> np.ndarray:
        index = {n: i for i, n in enumerate(names)}
        for shape in ARKIT_SHAPES:
            for ch in shape_targets(shape) if base(shape) in SHAPE_SPAN else ():
                values[..., index[ch]] = np.minimum(values[..., index[ch]], SHAPE_SPAN[base(shape)])
        for _ in range(3):  # a share may drive another shape's channel, which has its own share
            for shape in (s for s in ARKIT_SHAPES if base(s) in SHAPE_SHARES):
                unit = np.minimum(1.0, values[..., index[shape_targets(shape)[0]]] / SHAPE_SPAN.get(base(shape), 1.0))
                for ch, share in SHAPE_SHARES[base(shape)]:
                    for t in share_targets(shape, ch, index):
                        values[..., index[t]] = np.maximum(values[..., index[t]], share * unit)
        if MOUTH_CLOSE_LIFT in index:  # the lips' lift is mouthClose's own weight, the closure over its span
            close = np.minimum(1.0, values[..., index["lip_closure"]])
            values[..., index[MOUTH_CLOSE_LIFT]] = MOUTH_CLOSE_SPAN * close
        return values

    return expressible
