"""Where a warm start of `puppet live` spends its CPU before the first tick, part by part.

Runs `puppet live --headless` on the mock box in a child process whose named functions (the face's
load, the simulators, the kernels' warm-up, ...) are wrapped to record their thread's CPU time
(`time.thread_time`) and wall time; the child stops at the end of its first tick and prints the
parts that ended by then, each thread's nested calls indented, with the process's CPU time by then
(the command's own functions, still running, are not listed). CPU time is the
figure to read on a shared machine (the wall time is mostly waiting for a core there); the two
threads take turns on the interpreter's lock, so their sum is about what the start costs an idle
machine. The face cache is filled first by one untimed start (in a temporary folder); numba's cache
is the tree's own (a first run compiles).

Run:  .venv/bin/python benchmarks/start_parts.py [--runs 3] [--min-ms 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"

#: module -> the functions (or Class.method) timed in it
PARTS = {
    "puppet.cmd_live": ["_run", "_open_devices", "_open_panel", "_perform"],
    "puppet.live": ["load_face", "prepare_kernels", "LiveCore.__init__", "build_mapping", "LiveCore.tick"],
    "puppet.face_cache": ["load_entry", "cached_model", "scan_model", "source_digest"],
    "sim.rig": ["_parse"],
    "sim.integrator": ["Simulator.__init__", "Simulator.step", "Simulator.prepare", "_jaw_arrays", "_jaw_grid",
                       "warm_up", "kernels_cached"],
    "sim.implicit": ["ImplicitStepper.__init__", "ImplicitStepper.turn_basis"],
    "sim.prepared": ["prepared"],
    "sim.wrinkles.kernels": ["warm_up"],
    "puppet.tick_rate": ["live_tick_rate"],
}

CHILD = r"""
import functools, importlib.abc, json, os, sys, threading, time
PARTS, MIN = json.loads(os.environ["START_PARTS"]), float(os.environ["START_PARTS_MIN"])
W0, OUT, depth = time.perf_counter(), [], threading.local()

def report():
    lines = [f"first tick: process CPU {time.process_time():.3f} s, wall {time.perf_counter() - W0:.3f} s "
             "since the interpreter ran this"]
    for th, w, dw, dc, d, q in sorted(OUT, key=lambda o: (o[0], o[1])):
        if dc * 1e3 >= MIN:
            lines.append(f"  {th[:14]:14s} at {w * 1e3:6.0f} ms  {dc * 1e3:6.1f} ms CPU {dw * 1e3:7.1f} ms wall  {'  ' * d}{q}")
    sys.stderr.write("\n".join(lines) + "\n")
    sys.stderr.flush()
    os._exit(0)

def wrap(qual, f):
    @functools.wraps(f)
    def timed(*a, **k):
        d = getattr(depth, "d", 0)
        depth.d = d + 1
        w, c = time.perf_counter(), time.thread_time()
        try:
            return f(*a, **k)
        finally:
            depth.d = d
            OUT.append((threading.current_thread().name, w - W0, time.perf_counter() - w, time.thread_time() - c, d, qual))
            if qual == "puppet.live.LiveCore.tick":
                report()
    return timed

class Hook(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name not in PARTS:
            return None
        for finder in sys.meta_path:
            spec = None if finder is self else getattr(finder, "find_spec", lambda *a: None)(name, path, target)
            if spec is not None:
                run = spec.loader.exec_module
                def exec_module(module, run=run):
                    run(module)
                    for q in PARTS[module.__name__]:
                        owner, parts = module, q.split(".")
                        for p in parts[:-1]:
                            owner = getattr(owner, p)
                        setattr(owner, parts[-1], wrap(f"{module.__name__}.{q}", getattr(owner, parts[-1])))
                spec.loader.exec_module = exec_module
                return spec
        return None

sys.meta_path.insert(0, Hook())
from puppet.cli import main
sys.argv = ["puppet", *sys.argv[1:]]
main()
"""


def run(cache: Path, min_ms: float, timed: bool = True) -> str:
    import json

    env = {**os.environ, "PYTHONPATH": str(ROOT), "PUPPET_CACHE_DIR": str(cache), "PUPPET_LIBRARY": "off",
           "START_PARTS": json.dumps(PARTS if timed else {}), "START_PARTS_MIN": str(min_ms)}
    with tempfile.TemporaryDirectory(prefix="puppet-start-parts-") as work:
        r = subprocess.run([sys.executable, "-c", CHILD, "live", "--headless", "--device", f"mock://{SCRIPT}?speed=1",
                            "--record", str(Path(work) / "take.jsonl"), "--duration", "0.5"],
                           env=env, cwd=work, capture_output=True, text=True, timeout=600)
    return "\n".join(line for line in r.stderr.splitlines() if not line.startswith("puppet:"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--min-ms", type=float, default=3.0, help="leave out parts under this much CPU")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="puppet-start-parts-cache-") as cache:
        run(Path(cache), args.min_ms, timed=False)  # fills the face cache (and numba's, on a first run)
        for i in range(args.runs):
            print(f"run {i + 1} (load average {os.getloadavg()[0]:.1f})")
            print(run(Path(cache), args.min_ms))
    return 0


if __name__ == "__main__":
    sys.exit(main())
