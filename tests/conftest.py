"""Fixtures shared by every test package."""

from __future__ import annotations

import os
import select
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


@pytest.fixture(scope="session")
def xvfb_display() -> Iterator[str]:
    """A private Xvfb server; yields its DISPLAY string (e.g. ':93'). Needs the xvfb package,
    which .ci/setup installs; the test fails (not skips) without it."""
    if shutil.which("Xvfb") is None:
        pytest.fail("Xvfb is not installed: run `bash .ci/setup`")
    # -displayfd: the server picks a free display number itself and writes it to the pipe, so
    # test runs started side by side never race for the same number.
    rfd, wfd = os.pipe()
    proc = subprocess.Popen(
        ["Xvfb", "-displayfd", str(wfd), "-screen", "0", "1600x1000x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        pass_fds=(wfd,),
    )
    os.close(wfd)
    deadline = time.monotonic() + 10
    text = b""
    while not text.endswith(b"\n"):
        ready, _, _ = select.select([rfd], [], [], max(0.0, deadline - time.monotonic()))
        chunk = os.read(rfd, 16) if ready else b""
        if not chunk:
            os.close(rfd)
            proc.kill()
            pytest.fail("Xvfb did not start")
        text += chunk
    os.close(rfd)
    n = int(text.strip())
    try:
        yield f":{n}"
    finally:
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
