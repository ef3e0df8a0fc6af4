"""A box unplugged and plugged back again and again under `puppet live`: what the take records for it
strictly alternates (connected, lost, connected...), starting with the first time it really opened
(its first contact fails here: the show starts and retries it without claiming it connected), and
every cycle's dial turn arrives between its connected and its lost."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "devices"))

from emulators import SgiBoxEmulator  # noqa: E402

CYCLES = 50


class TakeTail:
    """Reads a take's records as the running show writes them (each tick's records are flushed)."""

    def __init__(self, path: Path) -> None:
        self.path, self.records, self._pos, self._part = path, [], 0, ""

    def poll(self) -> list[dict[str, Any]]:
        if not self.path.exists():
            return []
        with open(self.path, encoding="utf-8") as fh:
            fh.seek(self._pos)
            text = fh.read()
            self._pos = fh.tell()
        lines = (self._part + text).split("\n")
        self._part = lines.pop()
        new = [json.loads(line) for line in lines if line]
        self.records += new
        return new

    def wait(self, pred: Any, proc: subprocess.Popen[str], timeout: float = 20.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        seen = len(self.records)
        while time.monotonic() < deadline:
            self.poll()
            for rec in self.records[seen:]:
                if pred(rec):
                    return rec
            seen = len(self.records)
            assert proc.poll() is None, f"puppet live ended early: {proc.communicate()[1][-2000:]}"
            time.sleep(0.01)
        raise AssertionError(f"not in the take within {timeout} s; last records: {self.records[-5:]}")


def test_fifty_replugs_alternate_in_the_take_and_every_cycle_reaches_it(tmp_path: Path) -> None:
    link = tmp_path / "ttySGI"
    box = SgiBoxEmulator(link, hang_up_first=True)
    spec = f"sgi://{link}"
    take = tmp_path / "take.jsonl"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--device", spec, "--headless", "--no-panel",
                             "--record", str(take), "--duration", "600"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    tail = TakeTail(take)
    turned: list[tuple[int, int]] = []
    try:
        for cycle in range(CYCLES):
            tail.wait(lambda r: r.get("t") == "st" and r["status"] == "connected", proc)
            box.wait_ready()
            dial, counts = cycle % 8, 1 + cycle % 5
            box.turn(dial, counts)
            turned.append((dial, counts))
            tail.wait(lambda r, c=f"dial{dial}": r.get("t") == "ev" and r["ctl"] == c, proc)
            box.unplug()
            tail.wait(lambda r: r.get("t") == "st" and r["status"] == "lost", proc)
            time.sleep(0.02 * (cycle % 3))  # unplugged for a moment of varying length
            box.replug()
        tail.wait(lambda r: r.get("t") == "st" and r["status"] == "connected", proc)
        proc.send_signal(signal.SIGINT)  # a clean end: the take gets its end record
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        box.port.close()
    assert proc.returncode == 0, err[-2000:]
    assert "did not open" in err  # the first contact failed, and the show started anyway
    tail.poll()
    recs = [r for r in tail.records if r.get("dev") == spec]
    states = "".join(r["status"][0].upper() for r in recs if r["t"] == "st")
    assert states == "C" + "LC" * CYCLES
    assert [r["detail"] for r in recs if r["t"] == "st"][0] == "opened"  # never claimed before it was
    # each cycle: the turn arrives after the cycle's connected and before its lost, whole
    cycle, got = -1, {}
    for r in recs:
        if r["t"] == "st":
            cycle += r["status"] == "connected"
        else:
            got.setdefault(cycle, []).append((int(r["ctl"][4:]), int(r["delta"])))
    assert [got.get(c) for c in range(CYCLES)] == [[t] for t in turned]
    ticks = [r["tick"] for r in tail.records if "tick" in r]
    assert ticks == sorted(ticks)
    assert tail.records[-1]["t"] == "end"
