"""A private Xvfb server, for the tests' display fixture (tests/conftest.py) and the benchmarks
that need a window (benchmarks/startup.py --window)."""

from __future__ import annotations

import os
import select
import shutil
import subprocess
import time


def start_xvfb(timeout: float = 60.0) -> tuple[subprocess.Popen, str]:  # type: ignore[type-arg]
    """Start Xvfb and return (process, DISPLAY string such as ':93'); RuntimeError if it cannot.
    -displayfd: the server picks a free display number itself and writes it to the pipe once it
    accepts connections, so runs started side by side never race for the same number. `timeout`
    only bounds a server that never answers (a loaded machine's start can take seconds)."""
    if shutil.which("Xvfb") is None:
        raise RuntimeError("Xvfb is not installed: run `bash .ci/setup`")
    rfd, wfd = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(wfd), "-screen", "0", "1600x1000x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, pass_fds=(wfd,))
    os.close(wfd)
    deadline = time.monotonic() + timeout
    text = b""
    try:
        while not text.endswith(b"\n"):
            ready, _, _ = select.select([rfd], [], [], max(0.0, deadline - time.monotonic()))
            chunk = os.read(rfd, 16) if ready else b""
            if not chunk:
                proc.kill()
                proc.wait()
                raise RuntimeError("Xvfb did not start")
            text += chunk
    finally:
        os.close(rfd)
    return proc, f":{int(text.strip())}"


def stop_xvfb(proc: subprocess.Popen) -> None:  # type: ignore[type-arg]
    proc.terminate()
    try:
        proc.wait(5)
    except subprocess.TimeoutExpired:
        proc.kill()
