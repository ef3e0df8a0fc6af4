"""Fixtures shared by every test package."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from collections.abc import Iterator

import pytest

# compiled faces are cached in a private folder for this run, never in the user's cache
# (subprocesses inherit it); removed at the end of the run
_FACE_CACHE = os.environ["PUPPET_CACHE_DIR"] = __import__("tempfile").mkdtemp(prefix="puppet-test-cache-")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if os.path.basename(_FACE_CACHE).startswith("puppet-test-cache-"):
        shutil.rmtree(_FACE_CACHE, ignore_errors=True)


def _free_display() -> int:
    for n in range(90, 200):
        if not os.path.exists(f"/tmp/.X11-unix/X{n}") and not os.path.exists(f"/tmp/.X{n}-lock"):
            return n
    raise RuntimeError("no free X display number")


@pytest.fixture(scope="session")
def xvfb_display() -> Iterator[str]:
    """A private Xvfb server; yields its DISPLAY string (e.g. ':93'). Needs the xvfb package,
    which .ci/setup installs; the test fails (not skips) without it."""
    if shutil.which("Xvfb") is None:
        pytest.fail("Xvfb is not installed: run `bash .ci/setup`")
    n = _free_display()
    proc = subprocess.Popen(
        ["Xvfb", f":{n}", "-screen", "0", "1600x1000x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 10
    while not os.path.exists(f"/tmp/.X11-unix/X{n}"):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail("Xvfb did not start")
        time.sleep(0.05)
    try:
        yield f":{n}"
    finally:
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
