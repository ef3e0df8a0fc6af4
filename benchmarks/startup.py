"""Start-up of `puppet live`: process spawn -> its first tick, measured from outside.

Each run starts `python -m puppet live --headless --device mock://...?speed=1 --record FILE` and
polls FILE (every 1 ms) until the first tick's values record is there: records reach the operating
system when their tick is done, so that line appearing is the first tick, seen by another process.
Three cases, each with its own empty or filled caches in a temporary folder:

- warm:  the face cache (PUPPET_CACHE_DIR) and numba's cache already hold this build;
- cold face: the face cache is empty (the first start after installing or editing the face code);
- cold all:  the face cache and numba's cache (NUMBA_CACHE_DIR) are both empty (a first install);
- window (with --window): warm, but in a window on a private Xvfb server (started and stopped here
  by PID): the first tick there is taken in the first frame's callback, so it includes creating the
  window, the GL context on Mesa's software rasterizer and the renderer.

The CPU time the process had used by its first tick is printed too: on a shared, busy machine the
wall time is mostly waiting for a core, and CPU time is what the start costs an idle one.
Reference floors measured in the same run: `python -c pass`, `python -c "import numpy, scipy.sparse"`
and `import numpy, numba, scipy.linalg` (numba's own start, below which a warm start cannot go).
The budget is 1 s to the first tick on a warm machine; ratios are printed against it.

Run:  .venv/bin/python benchmarks/startup.py [--runs 5] [--cold-runs 2] [--no-cold-all] [--window] [--compare DIR] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from xvfb_server import start_xvfb, stop_xvfb  # noqa: E402  (tests/xvfb_server.py)
SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"
BUDGET_S = 1.0


def _env(cache: Path, numba_cache: Path | None, root: Path = ROOT) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(root), "PUPPET_CACHE_DIR": str(cache)}
    if numba_cache is not None:
        env["NUMBA_CACHE_DIR"] = str(numba_cache)
    return env


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system, all threads) the process has used so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def first_tick_seconds(env: dict[str, str], work: Path, timeout: float = 120.0,
                       window: bool = False) -> tuple[float, float]:
    """Seconds from spawning `puppet live` until its recording holds tick 0's values, and the CPU
    seconds the process had used by then (what the start costs on an idle machine). `window`: in a
    window on env's DISPLAY instead of headless."""
    rec = work / "startup.jsonl"
    if rec.exists():
        rec.unlink()
    t0 = time.monotonic()
    mode = [] if window else ["--headless"]
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", *mode, "--device",
                             f"mock://{SCRIPT}?speed=1", "--record", str(rec), "--duration", "30"],
                            env=env, cwd=work, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        while time.monotonic() - t0 < timeout:
            try:
                if b'"t":"v","tick":0' in rec.read_bytes():
                    return time.monotonic() - t0, cpu_seconds(proc.pid)
            except OSError:
                pass
            if proc.poll() is not None:
                raise RuntimeError(f"puppet live exited early: {proc.stderr.read().decode()[-500:]}")
            time.sleep(0.001)
        raise RuntimeError("no first tick within the timeout")
    finally:
        stop_process(proc)


def stop_process(proc: subprocess.Popen, timeout: float = 60.0) -> None:  # type: ignore[type-arg]
    """SIGTERM (a show stops cleanly on it), then SIGKILL if it has not gone after `timeout`."""
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _floor(code: str, runs: int) -> float:
    out = []
    for _ in range(runs):
        t0 = time.monotonic()
        subprocess.run([sys.executable, "-c", code], check=True)
        out.append(time.monotonic() - t0)
    return statistics.median(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5, help="warm runs")
    ap.add_argument("--cold-runs", type=int, default=2, help="runs of each cold case")
    ap.add_argument("--no-cold-all", action="store_true", help="skip the empty-numba-cache case (slow)")
    ap.add_argument("--window", action="store_true", help="also the warm start in a window (on a private Xvfb)")
    ap.add_argument("--compare", metavar="DIR", type=Path,
                    help="also time the warm start of another checkout (e.g. one before a change), "
                    "run for run alternating with this one so both see the same load")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    results: dict[str, list[tuple[float, float]]] = {"warm": [], "cold face": [], "cold all": [], "window": []}
    with tempfile.TemporaryDirectory(prefix="puppet-startup-") as tmp:
        base = Path(tmp)
        warm_cache = base / "warm-cache"
        first_tick_seconds(_env(warm_cache, None), base)  # fills the face cache
        if args.compare:
            results[f"warm, {args.compare}"] = []
            first_tick_seconds(_env(base / "other-cache", None, args.compare), base)
        for _ in range(args.runs):
            results["warm"].append(first_tick_seconds(_env(warm_cache, None), base))
            if args.compare:
                results[f"warm, {args.compare}"].append(
                    first_tick_seconds(_env(base / "other-cache", None, args.compare), base))
        for i in range(args.cold_runs):
            results["cold face"].append(first_tick_seconds(_env(base / f"cold-{i}", None), base))
        if args.window:
            xvfb, display = start_xvfb()
            try:
                wenv = {**_env(warm_cache, None), "DISPLAY": display}
                first_tick_seconds(wenv, base, window=True)  # the first window stores the head shell
                for _ in range(args.runs):
                    results["window"].append(first_tick_seconds(wenv, base, window=True))
            finally:
                stop_xvfb(xvfb)
        if not args.no_cold_all:
            for i in range(args.cold_runs):
                results["cold all"].append(
                    first_tick_seconds(_env(base / f"all-{i}", base / f"numba-{i}"), base))
    floors = {"python -c pass": _floor("pass", 3),
              "import numpy, scipy.sparse": _floor("import numpy, scipy.sparse", 3),
              # what numba costs any process before its first cached kernel runs (its first call
              # also imports scipy.linalg, for its BLAS check)
              "import numpy, numba, scipy.linalg": _floor("import numpy, numba, scipy.linalg", 3)}
    load = os.getloadavg()[0]
    if args.json:
        print(json.dumps({"first_tick_s": results, "floors_s": floors, "load1": load}))
        return 0
    print(f"puppet live, spawn -> first tick (load average {load:.2f}, {os.cpu_count()} cores)")
    for name, pairs in results.items():
        if pairs:
            wall, cpu = [w for w, _ in pairs], [c for _, c in pairs]
            med = statistics.median(wall)
            print(f"  {name:10s}  median {med:6.3f} s  max {max(wall):6.3f} s  ({len(wall)} runs)  "
                  f"= {med / BUDGET_S:.2f} x the 1 s budget;  CPU used by then: median {statistics.median(cpu):.2f} s")
    for name, val in floors.items():
        print(f"  floor: {name:34s} {val:6.3f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
