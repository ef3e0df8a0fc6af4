"""`puppet live --realtime` (and its default, wherever real-time scheduling is permitted; `--no-realtime`
keeps the ordinary): the live loop's thread runs under SCHED_FIFO a step above the devices'
reader threads and the recording's writer (which the loop waits for at a hand-over: at the ordinary
priority other programs kept it, and the loop, waiting), while the threads the loop starts during
the show (the page's server, the wrinkle layer's build) keep the ordinary scheduling (at FIFO they
would hold a core against the loop); where real-time scheduling is not permitted the show says so in
one line and runs as usual."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"

PROBE = """
import json, os, sys, threading
from puppet import live
seen = {}
_tick = live.LiveCore.tick
def tick(self, events):
    _tick(self, events)
    if self.tick_count == int(0.8 * self.rate):  # the page is served after the first frame: up by now
        seen["loop"] = os.sched_getscheduler(0)
        seen["loop_priority"] = os.sched_getparam(0).sched_priority
        seen["threads"] = {t.name: os.sched_getscheduler(t.native_id) for t in threading.enumerate()
                           if t is not threading.current_thread() and t.native_id}
        seen["priority"] = {t.name: os.sched_getparam(t.native_id).sched_priority for t in threading.enumerate()
                            if t is not threading.current_thread() and t.native_id}
live.LiveCore.tick = tick
from puppet.cli import main
code = main(sys.argv[1:])
seen["after"] = os.sched_getscheduler(0)
json.dump(seen, open(os.environ["PROBE_OUT"], "w"))
sys.exit(code)
"""


def run_show(tmp_path: Path, *extra: str, flag: tuple[str, ...] = ("--realtime",)) -> tuple[subprocess.CompletedProcess[str], dict]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PROBE_OUT": str(tmp_path / "p.json")}
    env.pop("PUPPET_REALTIME_DEVICES", None)
    r = subprocess.run([sys.executable, "-c", PROBE, "live", "--headless", *flag, "--device",
                        f"mock://{SCRIPT}?speed=1", "--duration", "1.2", "--record", "take.jsonl", *extra],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return r, json.loads((tmp_path / "p.json").read_text())


def permitted() -> bool:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except (OSError, AttributeError):
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


@pytest.mark.skipif(not permitted(), reason="real-time scheduling is not permitted to this user")
def test_the_loop_runs_real_time_above_the_readers_and_the_page_does_not(tmp_path: Path) -> None:
    r, seen = run_show(tmp_path, "--panel", "0")
    assert seen["loop"] == os.SCHED_FIFO and seen["loop_priority"] == 11
    readers = {n: p for n, p in seen["threads"].items() if n.startswith("device mock://")}
    assert readers and set(readers.values()) == {os.SCHED_FIFO}, seen["threads"]
    assert all(seen["priority"][n] < 11 for n in readers)
    assert seen["threads"]["recording-writer"] == os.SCHED_FIFO and seen["priority"]["recording-writer"] < 11
    others = {n: p for n, p in seen["threads"].items() if not n.startswith("device ") and n != "recording-writer"}
    assert any(n == "panel server" for n in others), others  # the page, started by the loop's thread
    assert set(others.values()) == {os.SCHED_OTHER}, others
    assert seen["after"] == os.SCHED_OTHER  # the show is over: what follows runs as usual
    assert (tmp_path / "take.jsonl").stat().st_size > 0


@pytest.mark.skipif(not permitted(), reason="real-time scheduling is not permitted to this user")
def test_by_default_real_time_is_used_where_permitted_and_no_realtime_keeps_the_ordinary(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    r, seen = run_show(tmp_path / "a", flag=())
    assert seen["loop"] == os.SCHED_FIFO and seen["loop_priority"] == 11
    readers = {n: p for n, p in seen["threads"].items() if n.startswith("device mock://")}
    assert readers and set(readers.values()) == {os.SCHED_FIFO}, seen["threads"]
    assert "--realtime" not in r.stderr
    (tmp_path / "b").mkdir()
    r, seen = run_show(tmp_path / "b", flag=("--no-realtime",))
    assert seen["loop"] == os.SCHED_OTHER
    assert set(p for n, p in seen["threads"].items() if n.startswith("device mock://")) == {os.SCHED_OTHER}


def show_without_the_right(tmp_path: Path, flag: tuple[str, ...]) -> tuple[subprocess.CompletedProcess[str], dict]:
    """A show run as a user without CAP_SYS_NICE or an rtprio limit (the capability dropped when
    this user has it)."""
    if not permitted():
        return run_show(tmp_path, flag=flag)
    if subprocess.run(["which", "setpriv"], capture_output=True).returncode != 0:
        pytest.skip("setpriv is not installed")
    probe = tmp_path / "probe.py"
    probe.write_text(PROBE)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PROBE_OUT": str(tmp_path / "p.json")}
    env.pop("PUPPET_REALTIME_DEVICES", None)
    r = subprocess.run(["setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice", sys.executable,
                        str(probe), "live", "--headless", *flag, "--device", f"mock://{SCRIPT}?speed=1",
                        "--duration", "0.9", "--record", "take.jsonl"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return r, json.loads((tmp_path / "p.json").read_text())


def test_without_the_right_to_real_time_the_show_says_so_and_runs(tmp_path: Path) -> None:
    r, seen = show_without_the_right(tmp_path, ("--realtime",))
    lines = [ln for ln in r.stderr.splitlines() if "--realtime" in ln]
    assert len(lines) == 1 and "not permitted" in lines[0], r.stderr
    assert seen["loop"] == os.SCHED_OTHER
    assert (tmp_path / "take.jsonl").stat().st_size > 0


def test_without_the_right_the_default_runs_quietly(tmp_path: Path) -> None:
    r, seen = show_without_the_right(tmp_path, ())
    assert "realtime" not in r.stderr and "real-time" not in r.stderr, r.stderr
    assert seen["loop"] == os.SCHED_OTHER
    assert (tmp_path / "take.jsonl").stat().st_size > 0
