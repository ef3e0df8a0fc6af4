"""The farm's scheduler gone mid-batch: one line saying so and what to do, exit 2 (not a
FutureCancelledError repeated for every take, as if each take were at fault)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from farm import Farm
from takes import write_take


def test_a_scheduler_lost_mid_batch_is_one_line(tmp_path: Path) -> None:
    shoot = tmp_path / "shoot"
    for k in range(3):
        write_take(shoot / f"long{k}.jsonl", ticks=420, seed=40 + k)
    (tmp_path / "farm").mkdir()
    farm = Farm(tmp_path / "farm", workers=1)
    try:
        batch = subprocess.Popen([sys.executable, "-m", "puppet", "batch", "export", str(shoot), "--out",
                                  str(tmp_path / "out"), "--to", "pc2", "--scheduler", farm.address],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        with farm.client() as c:
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and batch.poll() is None:
                if any(str(k).startswith("export-") for keys in c.processing().values() for k in keys):
                    break
                time.sleep(0.05)
        assert batch.poll() is None, "the batch ended before a task was seen running"
        os.killpg(farm.procs[0].pid, signal.SIGKILL)  # the scheduler
        _, stderr = batch.communicate(timeout=180)
    finally:
        farm.stop()
    lines = [line for line in stderr.replace("\r", "\n").splitlines() if line.startswith("puppet:")]
    assert batch.returncode == 2, stderr
    assert len(lines) == 1 and "scheduler" in lines[0] and "again" in lines[0], stderr
    assert "Traceback" not in stderr and "CancelledError" not in stderr, stderr
