"""What `puppet live` loads before its first tick: from a warm face cache, neither scipy.sparse
(the cached muscle matrix is plain CSR arrays) nor the page's web server (aiohttp, asyncio), which
is served once the show runs. The start-up time itself is measured by benchmarks/startup.py, not
here (no timing thresholds in tests); these are the deterministic parts of it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"

# runs `puppet live`, and at the first published frame writes which modules are loaded, then exits
PROBE = """
import json, os, sys
from puppet import live
def after_frame(self):
    names = sorted(sys.modules)
    with open(os.environ["PROBE_OUT"], "w") as fh:
        json.dump({"modules": names, "ticks": self.tick_count}, fh)
    os._exit(0)
live.LiveCore.after_frame = after_frame
from puppet.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _live(tmp: Path, *extra: str, probe: bool) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PUPPET_CACHE_DIR": str(tmp / "cache"),
           "PROBE_OUT": str(tmp / "probe.json")}
    head = [sys.executable, "-c", PROBE] if probe else [sys.executable, "-m", "puppet"]
    return subprocess.run([*head, "live", "--headless", "--device", f"mock://{SCRIPT}?speed=1", *extra],
                          cwd=tmp, env=env, capture_output=True, text=True, timeout=300)


def test_warm_start_reaches_its_first_tick_without_scipy_sparse_or_the_web_server(tmp_path: Path) -> None:
    _live(tmp_path, "--duration", "0.5", probe=False)  # fills the face cache
    r = _live(tmp_path, "--duration", "5", "--record", "take.jsonl", probe=True)
    assert r.returncode == 0, r.stderr
    seen = json.loads((tmp_path / "probe.json").read_text())
    assert seen["ticks"] == 1
    loaded = set(seen["modules"])
    assert "sim.integrator" in loaded and "puppet.panel.device" in loaded  # the probe saw a real start
    for heavy in ("scipy.sparse", "aiohttp", "asyncio"):
        assert heavy not in loaded, f"{heavy} imported before the first tick"


def test_the_page_nobody_asked_for_is_still_served_once_the_show_runs(tmp_path: Path) -> None:
    import re
    import urllib.request

    env = {**os.environ, "PYTHONPATH": str(ROOT), "PUPPET_CACHE_DIR": str(tmp_path / "cache")}
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--headless", "--device",
                             f"mock://{SCRIPT}?speed=1", "--duration", "60"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = ""
        for line in proc.stdout:
            if "performer's page at" in line:
                break
        m = re.search(r"(http://127\.0\.0\.1:\d+/\S*)", line)
        assert m, f"no page announced: {line!r}"
        with urllib.request.urlopen(m.group(1), timeout=20) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
    finally:
        proc.terminate()
        proc.wait(60)
