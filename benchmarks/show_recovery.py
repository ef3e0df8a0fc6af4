"""What a crash costs the show, measured from outside.

1. SIGKILL loss: tests/puppet/show_child.py performs live at 60 Hz (the real LiveCore and writer, a
   dial turned every tick) and writes the number of the tick it starts to shared memory; it is
   killed at a random moment 0.5-3 s into the show. Lost = ticks started before the one in
   progress that the file does not hold (the budget: 0, i.e. only the tick in progress).
2. Power-cut loss: one show of --seconds; the writer's fsync thread logs (time it returned, bytes
   covered, ticks covered). A power cut just before fsync i+1 returns leaves the bytes of fsync i:
   the file cut there is read back, and the loss is the time from the start of the first tick it
   lacks to the moment fsync i+1 returned (the budget: about 1 s).
3. Supervisor: `puppet live --supervise` with a mock box in real time; the show process is killed
   (SIGKILL) at random moments; crash-to-first-tick = from the kill until the recording holds a
   tick of the new segment. Then once more with the standby killed first (a cold restart), and
   once with an exception raised in the loop (the PUPPET_CRASH_AT_TICK hook, 15 s into a show).

Run:  .venv/bin/python benchmarks/show_recovery.py [--kills 8] [--seconds 20] [--restarts 4] [--no-exception] [--json]
"""

from __future__ import annotations

import argparse
import json
import mmap
import os
import random
import signal
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from puppet.session import read_session  # noqa: E402
from puppet.supervise import QUICK_S  # noqa: E402
from startup import cpu_seconds, stop_process  # noqa: E402  (benchmarks/startup.py)

CHILD = ROOT / "tests" / "puppet" / "show_child.py"
SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def _ticks(path: Path) -> int:
    try:
        return read_session(path).ticks
    except Exception:  # noqa: BLE001 - not there yet
        return -1


def sigkill_losses(work: Path, kills: int, rng: random.Random) -> list[int]:
    lost = []
    for i in range(kills):
        rec, counter = work / f"kill{i}.jsonl", work / f"counter{i}"
        counter.write_bytes(struct.pack("q", -1))
        proc = subprocess.Popen([sys.executable, str(CHILD), str(rec), str(counter)], env=ENV,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        with open(counter, "r+b") as fh:
            shared = mmap.mmap(fh.fileno(), 8)
        while struct.unpack_from("q", shared, 0)[0] < 1:
            time.sleep(0.005)
        time.sleep(rng.uniform(0.5, 3.0))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        started = struct.unpack_from("q", shared, 0)[0]
        lost.append(max(0, started - read_session(rec).ticks))
    return lost


def power_cut_losses(work: Path, seconds: float) -> tuple[list[float], int]:
    rec, counter, log = work / "power.jsonl", work / "pcounter", work / "fsync.json"
    counter.write_bytes(struct.pack("q", -1))
    proc = subprocess.Popen([sys.executable, str(CHILD), str(rec), str(counter), str(log)], env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(counter, "r+b") as fh:
        shared = mmap.mmap(fh.fileno(), 8)
    while struct.unpack_from("q", shared, 0)[0] < 1:
        time.sleep(0.01)
    time.sleep(seconds)
    proc.send_signal(signal.SIGTERM)
    proc.wait(60)
    data = json.loads(log.read_text())
    fsyncs, starts = data["fsyncs"], data["tick_starts"]
    whole = rec.read_bytes()
    cut = work / "cut.jsonl"
    losses, short = [], 0
    for (_, size, ticks), (t_next, _, _) in zip(fsyncs, fsyncs[1:]):
        cut.write_bytes(whole[:size])
        held = read_session(cut).ticks
        short += held < ticks  # the bytes of an fsync always hold the ticks it logged
        if held < len(starts):
            losses.append(t_next - starts[held])
    return losses, short


def _children(pid: int) -> list[tuple[int, str]]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
                cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except (OSError, ValueError, IndexError):
                continue
            if ppid == pid:
                out.append((int(d.name), cmd))
    return out


def _writes(pid: int, path: Path) -> bool:
    """The process has `path` open for writing: the show. (A standby opens it too, read-only, each
    time it follows the take, so an open file alone does not tell them apart.)"""
    try:
        for f in Path(f"/proc/{pid}/fd").iterdir():
            if os.readlink(f) == str(path):
                flags = int(Path(f"/proc/{pid}/fdinfo/{f.name}").read_text().split("flags:")[1].split()[0], 8)
                if flags & os.O_ACCMODE != os.O_RDONLY:
                    return True
    except (OSError, IndexError, ValueError):
        return False
    return False


def _wait_idle(pid: int, timeout: float = 120.0) -> None:
    """Until the process uses (almost) no CPU for half a second: a standby that is ready."""
    deadline = time.monotonic() + timeout
    last = cpu_seconds(pid)
    while time.monotonic() < deadline:
        time.sleep(0.5)
        now = cpu_seconds(pid)
        if now - last < 0.03:
            return
        last = now
    raise RuntimeError("the standby never settled")


def _wait(cond, timeout: float = 60.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise RuntimeError("timed out")
        time.sleep(0.001)


def _first_tick_after(rec: Path, offset: int, timeout: float = 120.0) -> float:
    """When a tick of a new segment reached the file: a `seg` record after `offset` (where the
    file was at the kill), then a values or sync record (the restarted show's first tick).
    Only the new bytes are read, so the watcher costs the machine next to nothing."""
    deadline = time.monotonic() + timeout
    start = max(0, offset - 4096)  # the restart cuts the file back to its last complete tick
    with open(rec, "rb") as fh:
        while time.monotonic() < deadline:
            fh.seek(start)
            seen = fh.read()
            i = seen.find(b'"t":"seg"')
            if i >= 0 and (seen.find(b'"t":"v"', i) >= 0 or seen.find(b'"t":"sync"', i) >= 0):
                return time.monotonic()
            time.sleep(0.002)
    raise RuntimeError("the show did not come back")


def supervisor_restarts(work: Path, restarts: int, rng: random.Random) -> tuple[list[float], float]:
    rec = work / "supervised.jsonl"
    sup = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--supervise", "--headless", "--device",
                            f"mock://{SCRIPT}?speed=1", "--record", str(rec)], env=ENV,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    times: list[float] = []
    cold = float("nan")
    t_start = time.monotonic()
    try:
        for i in range(restarts + 1):
            want_standby = i < restarts
            _wait(lambda: _ticks(rec) > 0 and len(_children(sup.pid)) == 2)
            kids = [pid for pid, _ in _children(sup.pid)]
            shows = [pid for pid in kids if _writes(pid, rec)]
            for pid in kids:
                if pid not in shows:
                    _wait_idle(pid)  # the standby is ready (imports, face, kernels), waiting
            # a show killed within QUICK_S of its start counts as a crash loop, and MAX_QUICK of those
            # in a row make the supervisor give up (as it should): let each show live past it
            time.sleep(max(0.0, QUICK_S + 0.2 - (time.monotonic() - t_start)))
            time.sleep(rng.uniform(0.0, 1.0))
            if not want_standby:
                for pid in kids:
                    if pid not in shows:
                        os.kill(pid, signal.SIGKILL)
                _wait(lambda: len(_children(sup.pid)) == 1)
            if not shows:
                raise RuntimeError(f"no show process among {kids}")
            show = shows[0]
            offset = rec.stat().st_size
            t_kill = time.monotonic()
            os.kill(show, signal.SIGKILL)
            t_start = _first_tick_after(rec, offset)
            dt = t_start - t_kill
            if want_standby:
                times.append(dt)
            else:
                cold = dt
    finally:
        stop_process(sup)
    return times, cold


def exception_restart(work: Path, crash_tick: int = 900) -> float:
    """--supervise with the test hook raising at `crash_tick` (15 s in: the standby is ready):
    seconds from the hook's line on stderr (just before the raise) to the new segment's first tick."""
    import threading

    rec = work / "exception.jsonl"
    env = {**ENV, "PUPPET_CRASH_AT_TICK": str(crash_tick)}
    sup = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--supervise", "--headless", "--device",
                            f"mock://{SCRIPT}?speed=1", "--record", str(rec)], env=env,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    crashed: list[float] = []

    def watch() -> None:
        assert sup.stderr is not None
        for line in sup.stderr:
            if b"crashing at tick" in line and not crashed:
                crashed.append(time.monotonic())

    threading.Thread(target=watch, daemon=True).start()
    try:
        _wait(lambda: rec.exists() and _ticks(rec) > 0, timeout=120)
        _wait(lambda: bool(crashed), timeout=crash_tick / 60 + 120)
        back = _first_tick_after(rec, max(0, rec.stat().st_size - 2048))
        return back - crashed[0]
    finally:
        stop_process(sup)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--restarts", type=int, default=4)
    ap.add_argument("--no-exception", action="store_true", help="skip the injected-exception restart")
    ap.add_argument("--seed", type=int, default=14)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    with tempfile.TemporaryDirectory(prefix="puppet-recovery-") as tmp:
        work = Path(tmp)
        ENV["PUPPET_CACHE_DIR"] = str(work / "cache")
        subprocess.run([sys.executable, "-c", "from puppet import live; live.load_face()"], env=ENV, check=True)
        lost = sigkill_losses(work, args.kills, rng) if args.kills else []
        power, short = power_cut_losses(work, args.seconds) if args.seconds else ([], 0)
        restarts, cold = supervisor_restarts(work, args.restarts, rng) if args.restarts else ([], float("nan"))
        exc = float("nan") if args.no_exception else exception_restart(work)
    load = os.getloadavg()[0]
    if args.json:
        print(json.dumps({"sigkill_lost_ticks": lost, "power_cut_loss_s": power, "fsync_short": short,
                          "crash_to_first_tick_s": restarts, "cold_restart_s": cold,
                          "exception_to_first_tick_s": exc, "load1": load}))
        return 0
    print(f"show recovery (load average {load:.2f}, {os.cpu_count()} cores)")
    if lost:
        print(f"  SIGKILL at {len(lost)} random moments: ticks lost beyond the one in progress: "
              f"max {max(lost)}, total {sum(lost)}")
    if power:
        print(f"  power cut before each of {len(power)} fsyncs: loss p50 {statistics.median(power):.3f} s, "
              f"max {max(power):.3f} s (= {max(power) / 1.0:.2f} x the 1 s budget); "
              f"fsyncs whose bytes held fewer ticks than logged: {short}")
    if restarts:
        print(f"  --supervise, SIGKILL -> first tick of the new segment ({len(restarts)} restarts from standby): "
              f"median {statistics.median(restarts) * 1e3:.0f} ms, max {max(restarts) * 1e3:.0f} ms "
              f"(= {max(restarts):.2f} x the 1 s budget)")
    if restarts:
        print(f"  --supervise without a standby (a cold restart): {cold * 1e3:.0f} ms")
    if not args.no_exception:
        print(f"  --supervise, an exception in the loop (PUPPET_CRASH_AT_TICK) -> first tick of the new "
              f"segment: {exc * 1e3:.0f} ms (the dying process closes the recording and devices first)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
