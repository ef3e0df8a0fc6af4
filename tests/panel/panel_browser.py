"""A headless Debian chromium driven by Selenium (the system browser and chromedriver, never a
download), and a `puppet live` process serving the page on a private port."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest

CHROMIUM, DRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
FLAGS = ("--headless --no-sandbox --disable-gpu --disable-quic --no-first-run --disable-background-networking "
         "--disable-component-update --disable-sync --window-size=1400,1000").split()
ROOT = Path(__file__).resolve().parents[2]
# axe-core from npm, installed by .ci/setup (`npm install --prefix .ci/axe axe-core`), never vendored here
AXE = ROOT / ".ci" / "axe" / "node_modules" / "axe-core" / "axe.min.js"
# a trimmed environment for `puppet` subprocesses (no DISPLAY, none of the shell's OPENBLAS_* settings),
# but the run's private face cache and take library (tests/conftest.py), never the user's
CHILD_ENV = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin",
             **{k: v for k, v in os.environ.items() if k in ("PUPPET_CACHE_DIR", "PUPPET_LIBRARY")}}


def browser() -> Any:
    """A fresh headless chromium (its own profile folder); the caller quits it."""
    if not (os.path.exists(CHROMIUM) and os.path.exists(DRIVER)):
        pytest.fail("chromium and chromium-driver are needed: run `bash .ci/setup`")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in FLAGS:
        opts.add_argument(a)
    profile = tempfile.mkdtemp(prefix="puppet-chromium-")
    opts.add_argument(f"--user-data-dir={profile}")
    drv = webdriver.Chrome(service=Service(DRIVER), options=opts)
    drv._puppet_profile = profile  # type: ignore[attr-defined]
    return drv


def quit_browser(drv: Any) -> None:
    try:
        drv.quit()
    finally:
        shutil.rmtree(getattr(drv, "_puppet_profile", ""), ignore_errors=True)


def wait_for(fn: Any, timeout: float = 20.0, what: str = "condition") -> Any:
    end = time.monotonic() + timeout
    while True:
        got = fn()
        if got:
            return got
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


class PuppetProcess:
    """`python -m puppet ARGS...` with this checkout first on the path; `url` is the page's URL
    read from its output."""

    def __init__(self, *args: str, cwd: Path) -> None:
        env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1")
        env.pop("DISPLAY", None)
        self.out_path = cwd / "puppet.out"
        self._out = open(self.out_path, "w")
        self.proc = subprocess.Popen([sys.executable, "-m", "puppet", *args], cwd=cwd, env=env,
                                     stdout=self._out, stderr=subprocess.STDOUT)
        self.url = wait_for(self._url, 90, "the page URL on puppet's output")

    def output(self) -> str:
        return self.out_path.read_text()

    def _url(self) -> str | None:
        if self.proc.poll() is not None:
            raise AssertionError(f"puppet exited early:\n{self.output()}")
        m = re.search(r"(http://127\.0\.0\.1:\d+/\S*)", self.output())
        return m.group(1) if m else None

    def stop(self) -> str:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._out.close()
        return self.output()


def axe_violations(drv: Any, impacts: tuple[str, ...] = ("serious", "critical")) -> list[str]:
    """axe-core run on the page open in `drv`: its violations of the given impacts, one line each
    (rule, impact, the first elements)."""
    if not AXE.exists():
        pytest.fail(f"axe-core is needed at {AXE}: run `bash .ci/setup`")
    drv.execute_script(AXE.read_text())
    drv.set_script_timeout(120)
    found = drv.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "axe.run(document, { resultTypes: ['violations'] }).then((r) => done(r.violations.map((v) =>"
        " [v.id, v.impact, v.nodes.slice(0, 3).map((n) => n.target.join(' '))])), (e) => done([['axe failed', String(e), []]]));")
    return [f"{rule} ({impact}): {', '.join(nodes)}" for rule, impact, nodes in found if impact in impacts or rule == "axe failed"]
