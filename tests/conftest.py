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


#: run once before a broad run's first test (`pytest_collection_finish`), in a process of its own: the
#: default face built into this run's face cache and every kernel a show's ticks call compiled into
#: numba's cache, as `puppet live` prepares them (the warm-up thread, the face, `prepare_kernels`)
_WARM_UP = """
from puppet import live
live.warm_up_in_background()
face = live.load_face(None, 0, face="procedural")
live.prepare_kernels(face.model, 1.0 / 240)
assert live.join_background(600)
"""


def pytest_collection_finish(session: pytest.Session) -> None:
    """A run of more than one test package builds the default face and compiles the show's kernels
    before its first test. Otherwise the first test to start a show paid for it inside its own
    timeout, whichever test that was: on a fresh clone ~42 s of CPU (numba compiling every kernel),
    which at load 19 took 425 s, and the suite's first show (`test_puppet_live_records_the_take_and_
    its_sound`) ran into pytest's 300 s; the processes that first needed a kernel also compiled and
    wrote it side by side. A run of one package (a developer's) builds what it needs as before."""
    import subprocess
    import sys
    from pathlib import Path

    if session.config.option.collectonly:
        return
    root = Path(__file__).resolve().parent
    packages = set()
    for item in session.items:
        try:
            parts = Path(str(item.path)).resolve().relative_to(root).parts
        except ValueError:
            continue
        if len(parts) > 1:  # tests/PACKAGE/test_x.py
            packages.add(parts[0])
    if len(packages) < 2:
        return
    import time

    t0 = time.monotonic()
    try:  # a hang guard only: a fresh clone's compile took 427 s at load 17-19
        run = subprocess.run([sys.executable, "-c", _WARM_UP], cwd=root.parent, capture_output=True, text=True,
                             env={**os.environ, "PYTHONPATH": str(root.parent)}, timeout=1800)
        failed = run.stderr[-2000:] if run.returncode != 0 else None
    except subprocess.TimeoutExpired:
        failed = "no end in 1800 s"
    said = (f"the default face and the show's kernels prepared before the first test ({time.monotonic() - t0:.0f} s)"
            if failed is None else  # the tests that need the face say what is wrong, each in its place
            f"preparing the default face and the show's kernels failed:\n{failed}")
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line(f"tests/conftest.py: {said}")
    else:
        print(f"tests/conftest.py: {said}", file=sys.stderr)


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
